"""Flight requests a USS puts to the planner node in its operators' names, signed by the USS's
airspace authority (docs/f3548.md, "The flight_planning interface in the node graph").

Anyone on the ROS domain can publish a FlightRequest on ``uam/requests`` under any operator id
(docs/security.md); a USS's flight plans must not be forgeable that way. So a USS puts them on
the service ``uam/uss_flight_plan``, whose type is ``uam_msgs/srv/UpdateConstraint`` (the
signed-update type, reused: no new interface), field by field:

============== ============================================================================
action         ACTION_ADD: plan a new request; ACTION_CHANGE: modify (a new version of its
               approved flight, ``Planner.modify``); ACTION_WITHDRAW: cancel
constraint_id  the request id (of the operator in ``geojson``)
version        plan: 1; modify: the version asked for; cancel: 0
reason         why (cancel); else ''
geojson        the request as JSON (:func:`request_json`; cancel: its operator only)
authorization  a JWT (ES256) of the USS's authority (``uam_planner.authority``) with ``act``
               ``flight_plan:<op>``: never a constraint action, so a flight-plan token never
               passes as a constraint update, nor the other way round; its ``seq`` counts on its
               own (channel ``flight_plan``)
============== ============================================================================

The answer: ``accepted`` when done (approved, modified or cancelled), else ``error`` naming the
field and value; ``effective_time`` the epoch that decided. The planner answers plan and modify
once its epoch has decided them. An answer is not proof (anyone may serve a service): the USS
takes an approval only from the planner's journal. The planner takes requests of an operator
that an authority holds (``operators`` in the authorities file) only this way, signed by that
authority, and refuses them on ``uam/requests``. rclpy-free.
"""

from __future__ import annotations

import json
import math
from types import SimpleNamespace

from uam_contract.ids import echo

from .constraints import ConstraintError

#: the operations, in the order of UpdateConstraint's action codes (ADD, CHANGE, WITHDRAW)
OPS = ("plan", "modify", "cancel")
#: the prefix of a flight-plan operation's ``act`` claim
ACT_PREFIX = "flight_plan:"
#: the sequence (``Authorities.verify``'s channel) of flight-plan operations
CHANNEL = "flight_plan"
#: the longest request JSON taken [characters]
MAX_JSON_CHARS = 4096
_TIMES = ("request_time_s", "earliest_departure_s", "latest_departure_s")


def op_of(action) -> str:
    """The operation of UpdateConstraint action code ``action``; ConstraintError naming it."""
    if isinstance(action, bool) or not isinstance(action, int) or not 0 <= action < len(OPS):
        raise ConstraintError(f"action: {echo(action)} is not a flight-plan operation (0 plan, 1 modify, 2 cancel)")
    return OPS[action]


def request_json(request) -> str:
    """A FlightRequest (the planner library's) as the ``geojson`` field's JSON."""
    doc = {"operator_id": request.operator_id, "origin_id": request.origin_id,
           "destination_id": request.destination_id, "priority": int(request.priority)}
    doc.update({name: float(getattr(request, name)) for name in _TIMES})
    return json.dumps(doc, sort_keys=True)


def request_fields(text: str, op: str) -> dict:
    """The fields of a request's JSON (``operator_id`` only for a cancel), checked: ConstraintError
    naming ``geojson.<field>`` and the value."""
    if not isinstance(text, str) or len(text) > MAX_JSON_CHARS:
        raise ConstraintError(f"geojson: {echo(text)} is not a request of at most {MAX_JSON_CHARS} characters")
    try:
        doc = json.loads(text)
    except ValueError as exc:
        raise ConstraintError(f"geojson: not JSON ({exc})") from None
    if not isinstance(doc, dict):
        raise ConstraintError(f"geojson: {echo(doc)} is not a JSON object")
    names = ("operator_id",) if op == "cancel" else ("operator_id", "origin_id", "destination_id")
    for name in names:
        if not isinstance(doc.get(name), str) or not doc[name]:
            raise ConstraintError(f"geojson.{name}: {echo(doc.get(name))} is not an id")
    if op == "cancel":
        return {"operator_id": doc["operator_id"]}
    for name in _TIMES:
        v = doc.get(name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v < 0:
            raise ConstraintError(f"geojson.{name}: {echo(v)} is not a time [s]")
    p = doc.get("priority", 0)
    if isinstance(p, bool) or not isinstance(p, int) or not 0 <= p <= 255:
        raise ConstraintError(f"geojson.priority: {echo(p)} is not a priority class 0..255")
    return {name: doc[name] for name in (*names, *_TIMES)} | {"priority": p}


class FlightPlanSigner:
    """A USS's signed flight-plan operations: each :meth:`operation` is UpdateConstraint's fields
    (a plain object the node copies into the request), signed by ``authority_id``'s private key
    (PEM) with the next ``seq`` from ``seq0``."""

    def __init__(self, authority_id: str, private_key_pem: bytes, seq0: int):
        self.authority_id, self.key, self.seq = str(authority_id), bytes(private_key_pem), int(seq0)

    def operation(self, op: str, request=None, request_id: str = "", operator_id: str = "", version: int = 0,
                  reason: str = "") -> SimpleNamespace:
        """``op`` 'plan' or 'modify' of ``request`` (a FlightRequest; version 1 for a plan), or
        'cancel' of ``request_id`` of ``operator_id``."""
        from .authority import sign_update
        if op == "cancel":
            body, rid = json.dumps({"operator_id": operator_id}), str(request_id)
        else:
            body, rid = request_json(request), str(request.request_id)
        req = SimpleNamespace(action=OPS.index(op), constraint_id=rid, version=int(version), reason=str(reason),
                              geojson=body)
        self.seq += 1
        req.authorization = sign_update(req, ACT_PREFIX + op, self.authority_id, self.key, self.seq)
        return req


__all__ = ["ACT_PREFIX", "CHANNEL", "FlightPlanSigner", "OPS", "op_of", "request_fields", "request_json"]
