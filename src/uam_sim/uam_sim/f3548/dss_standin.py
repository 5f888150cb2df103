"""A **stand-in** for an F3548-21 DSS, for tests of :mod:`uam_sim.f3548.dss` (docs/f3548.md,
"The stand-in DSS"). It is not a DSS: one process, references in memory, no persistence, no
pooling with other DSS instances, no S2 cells; InterUSS's DSS (``interuss/dss``) is the real one.

A Flask (WSGI) app, :func:`create_app`, serving the DSS operations of
:data:`uam_sim.f3548.dss.DSS_OPERATIONS` at the paths of ``uas_standards``' ``OPERATIONS``:

- every request: a bearer token verified with a :class:`uam_sim.f3548.auth.TokenVerifier` for the
  operation's scopes (:data:`uam_sim.f3548.dss.SCOPES`; 401 / 403), path ids in F3548's UUIDv4
  format (400 naming the parameter), the body parsed as the operation's request type
  (``ImplicitDict.parse``; 400 naming what failed) and the fields the DSS needs checked (every
  extent has its times, a window that ends after it starts, ...);
- every answer is built as, and checked against, the type the operation gives for its status
  (``ImplicitDict.parse`` of the JSON sent) and each reference against the restated schema of
  :mod:`uam_planner.f3548_schema` (UUIDv4 ids, OVN length, times); an answer that fails is a 500
  naming the check, so a stand-in bug never passes as a DSS answer;
- OVNs and versions: a create on an id that exists, an update or delete naming an OVN that is not
  the current one, and a subscription change naming another version answer 409; an update of an
  unknown id 404. A reference's version starts at 1 and grows by one with every update; a new
  OVN is issued with every change;
- the key: a create or update of a reference in state Accepted or Activated must name in ``key``
  the OVN of every other operational intent reference (and constraint reference) whose extents
  intersect its own (in time, altitude and area; touching counts), else 409
  ``AirspaceConflictResponse`` listing the references whose OVNs are missing;
- OVNs are shown only to the reference's manager (the token's ``sub``); another USS reads them
  from the manager's details endpoint, as F3548 has it;
- subscriptions: explicit ones (create, update, delete, with versions) and the implicit one a
  reference makes with ``new_subscription`` (deleted with its last reference); a change to a
  reference answers the subscribers whose subscriptions intersect it, each notification index
  advanced by one.

What it does not do: USS availability, DSS reports, ``requested_ovn_suffix`` (400),
subscription queries, subscriptions' own limits (duration, count per area), intersection by S2
cells (it tests the polygons and circles themselves, in degrees of latitude and longitude), and
notification of anyone (it only names the subscribers, as a DSS does). Every log line says
"stand-in DSS". Thread-safe (one lock).
"""

from __future__ import annotations

import json
import logging
import math
import re
import threading
import uuid
from dataclasses import dataclass, field
from datetime import datetime

from implicitdict import ImplicitDict
from uas_standards.astm.f3548.v21 import api

from .dss import DSS_OPERATIONS, SCOPES, Op

log = logging.getLogger("uam_sim.dss_standin")
LOG_PREFIX = "stand-in DSS"
UUID4 = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}$")
#: states whose references must hold the key of every intersecting reference (F3548: the USS
#: has deconflicted against them)
KEYED_STATES = ("Accepted", "Activated")
M_PER_DEG = 111_320.0
MAX_BODY_BYTES = 1 << 20


class StandInError(Exception):
    """A refused request: HTTP ``status`` and its message (naming the field and value); ``body``
    replaces the ErrorResponse (a 409's AirspaceConflictResponse)."""

    def __init__(self, status: int, message: str, body=None):
        super().__init__(message)
        self.status, self.message, self.body = status, message, body


# ---- geometry: does a Volume4D meet another ------------------------------------------------

def _time_s(t, where: str) -> float:
    try:
        return datetime.fromisoformat(str(t.value).replace("Z", "+00:00")).timestamp()
    except (ValueError, AttributeError) as exc:
        raise StandInError(400, f"{where}: {t!r} is not an RFC 3339 time ({exc})") from None


def _shape(vol3, where: str):
    """The Volume3D's area as a shapely geometry in (longitude, latitude) degrees."""
    from shapely import affinity
    from shapely.geometry import Point, Polygon

    if vol3.get("outline_polygon"):
        pts = [(float(p.lng), float(p.lat)) for p in vol3.outline_polygon.vertices]
        if len(pts) < 3:
            raise StandInError(400, f"{where}.outline_polygon.vertices: {len(pts)} vertices, fewer than 3")
        return Polygon(pts)
    if vol3.get("outline_circle"):
        c = vol3.outline_circle
        units = c.radius.units
        if units != "M":
            raise StandInError(400, f"{where}.outline_circle.radius.units: {units!r} is not 'M'")
        lat = float(c.center.lat)
        disc = Point(float(c.center.lng), lat).buffer(float(c.radius.value) / M_PER_DEG, 32)
        return affinity.scale(disc, xfact=1.0 / max(math.cos(math.radians(lat)), 1e-6), yfact=1.0)
    raise StandInError(400, f"{where}: neither outline_polygon nor outline_circle")


@dataclass(frozen=True)
class Extent:
    """A Volume4D as the stand-in compares them: [t0, t1] s, [z0, z1] m, the area."""
    t0: float
    t1: float
    z0: float
    z1: float
    area: object

    def meets(self, other: "Extent") -> bool:
        return (self.t0 <= other.t1 and other.t0 <= self.t1 and self.z0 <= other.z1 and other.z0 <= self.z1
                and self.area.intersects(other.area))


def extent(v4, where: str, need_times: bool = True) -> Extent:
    """A parsed Volume4D as an :class:`Extent`; 400 naming the field for one the DSS cannot use."""
    vol3 = v4.volume
    lo, hi = vol3.get("altitude_lower"), vol3.get("altitude_upper")
    for name, alt in (("altitude_lower", lo), ("altitude_upper", hi)):
        if alt is not None and (alt.reference != "W84" or alt.units != "M"):
            raise StandInError(400, f"{where}.volume.{name}: {alt.reference} / {alt.units} is not W84 / M")
    z0 = float(lo.value) if lo is not None else -math.inf
    z1 = float(hi.value) if hi is not None else math.inf
    if z1 < z0:
        raise StandInError(400, f"{where}.volume: altitude_upper {z1} is below altitude_lower {z0}")
    times = []
    for name in ("time_start", "time_end"):
        t = v4.get(name)
        if t is None:
            if need_times:
                raise StandInError(400, f"{where}.{name}: missing (the DSS needs every extent's times)")
            times.append(-math.inf if name == "time_start" else math.inf)
        else:
            times.append(_time_s(t, f"{where}.{name}"))
    if times[1] < times[0]:
        raise StandInError(400, f"{where}: time_end {v4.time_end.value} is before time_start {v4.time_start.value}")
    return Extent(times[0], times[1], z0, z1, _shape(vol3, f"{where}.volume"))


def _meets(a: list, b: list) -> bool:
    return any(x.meets(y) for x in a for y in b)


# ---- the store -----------------------------------------------------------------------------

@dataclass
class _Entity:
    """An operational intent or constraint reference (``doc``: the reference's fields) or a
    subscription (``doc``: the Subscription's fields)."""
    doc: dict
    extents: list
    manager: str = ""
    dependents: set = field(default_factory=set)


def _new_ovn() -> str:
    return uuid.uuid4().hex + uuid.uuid4().hex[:8]  # 40 characters (F3548: 16 to 128)


def _bounds(extents_json: list) -> tuple:
    starts = sorted(v["time_start"]["value"] for v in extents_json)
    ends = sorted(v["time_end"]["value"] for v in extents_json)
    return {"value": starts[0], "format": "RFC3339"}, {"value": ends[-1], "format": "RFC3339"}


class StandInDss:
    """The stand-in's state and rules (module docstring); :func:`create_app` serves it."""

    def __init__(self):
        self._lock = threading.Lock()
        self.intents: dict[str, _Entity] = {}
        self.constraints: dict[str, _Entity] = {}
        self.subscriptions: dict[str, _Entity] = {}

    # ---- subscriptions -------------------------------------------------------------------
    def _subscribers(self, extents: list, kind: str) -> list:
        """The subscriptions notified of a change over ``extents`` (their index advanced), as
        SubscriberToNotify documents grouped by USS."""
        flag = "notify_for_operational_intents" if kind == "intent" else "notify_for_constraints"
        by_url: dict[str, list] = {}
        for sid, s in self.subscriptions.items():
            if s.doc.get(flag) and _meets(s.extents, extents):
                s.doc["notification_index"] += 1
                by_url.setdefault(s.doc["uss_base_url"], []).append(
                    {"subscription_id": sid, "notification_index": s.doc["notification_index"]})
        return [{"uss_base_url": u, "subscriptions": subs} for u, subs in sorted(by_url.items())]

    def put_subscription(self, sid: str, version: str | None, body, manager: str) -> dict:
        ext = extent(body.extents, "extents", need_times=False)
        with self._lock:
            old = self.subscriptions.get(sid)
            if version is None and old is not None:
                raise StandInError(409, f"subscriptionid: {sid} exists (version {old.doc['version']}); "
                                        "update it at its version")
            if version is not None:
                if old is None:
                    raise StandInError(404, f"subscriptionid: {sid} is not a subscription here")
                if old.doc["version"] != version:
                    raise StandInError(409, f"version: {version!r} is not subscription {sid}'s current version "
                                            f"{old.doc['version']!r}")
            doc = {"id": sid, "version": _new_ovn()[:16], "notification_index": old.doc["notification_index"] if old else 0,
                   "uss_base_url": body.uss_base_url,
                   "notify_for_operational_intents": bool(body.get("notify_for_operational_intents") or False),
                   "notify_for_constraints": bool(body.get("notify_for_constraints") or False),
                   "implicit_subscription": False, "dependent_operational_intents": []}
            for name in ("time_start", "time_end"):
                if body.extents.get(name) is not None:
                    doc[name] = json.loads(json.dumps(body.extents[name], default=str))
            self.subscriptions[sid] = _Entity(doc, [ext], manager)
            refs = [self._shown(e, manager) for e in self.intents.values() if _meets(e.extents, [ext])]
            cons = [self._shown(e, manager) for e in self.constraints.values() if _meets(e.extents, [ext])]
        log.info("%s: subscription %s %s by %s", LOG_PREFIX, sid, "updated" if old else "created", manager)
        return {"subscription": doc, "operational_intent_references": refs, "constraint_references": cons}

    def delete_subscription(self, sid: str, version: str) -> dict:
        with self._lock:
            old = self.subscriptions.get(sid)
            if old is None:
                raise StandInError(404, f"subscriptionid: {sid} is not a subscription here")
            if old.doc["version"] != version:
                raise StandInError(409, f"version: {version!r} is not subscription {sid}'s current version "
                                        f"{old.doc['version']!r}")
            if old.dependents:
                raise StandInError(400, f"subscriptionid: {sid} still has operational intents "
                                        f"({', '.join(sorted(old.dependents))})")
            del self.subscriptions[sid]
        log.info("%s: subscription %s deleted", LOG_PREFIX, sid)
        return {"subscription": old.doc}

    # ---- references ------------------------------------------------------------------------
    @staticmethod
    def _shown(e: _Entity, reader: str) -> dict:
        """A reference as ``reader`` sees it: the OVN only to its manager."""
        doc = dict(e.doc)
        if e.manager != reader:
            doc.pop("ovn", None)
        return doc

    def _check_key(self, eid: str, exts: list, key: list) -> None:
        """409 AirspaceConflictResponse if ``key`` lacks the OVN of a reference meeting ``exts``."""
        held = set(key)
        missing_oi = [e for oid, e in self.intents.items()
                      if oid != eid and _meets(e.extents, exts) and e.doc["ovn"] not in held]
        missing_c = [e for e in self.constraints.values() if _meets(e.extents, exts) and e.doc["ovn"] not in held]
        if missing_oi or missing_c:
            names = [e.doc["id"] for e in missing_oi + missing_c]
            message = f"key: lacks the OVNs of {len(names)} intersecting reference(s): {', '.join(names)}"
            raise StandInError(409, message, {
                "message": message,
                "missing_operational_intents": [self._shown(e, "") for e in missing_oi],
                "missing_constraints": [self._shown(e, "") for e in missing_c]})

    def _checked_change(self, table: dict, eid: str, ovn: str | None, what: str):
        """The reference a create (``ovn`` None) or an update / delete (``ovn``) may change, or
        the 404 / 409 of the OVN rules."""
        old = table.get(eid)
        if ovn is None and old is not None:
            raise StandInError(409, f"entityid: {what} {eid} exists (version {old.doc['version']}); "
                                    "an update names its current OVN")
        if ovn is not None:
            if old is None:
                raise StandInError(404, f"entityid: {what} {eid} is not here")
            if old.doc["ovn"] != ovn:
                raise StandInError(409, f"ovn: {ovn!r} is not the current OVN of {what} {eid}")
        return old

    def put_intent(self, eid: str, ovn: str | None, body, manager: str) -> tuple:
        if body.get("requested_ovn_suffix"):
            raise StandInError(400, f"requested_ovn_suffix: {body.requested_ovn_suffix!r}: not supported by the "
                                    "stand-in DSS")
        if not body.extents:
            raise StandInError(400, "extents: empty (a reference needs at least one Volume4D)")
        exts = [extent(v, f"extents[{i}]") for i, v in enumerate(body.extents)]
        state = getattr(body.state, "value", str(body.state))
        with self._lock:
            old = self._checked_change(self.intents, eid, ovn, "operational intent reference")
            if old is not None and old.manager != manager:
                raise StandInError(403, f"entityid: {eid} is managed by {old.manager!r}, not {manager!r}")
            if state in KEYED_STATES:
                self._check_key(eid, exts, list(body.get("key") or []))
            sid = self._subscription_for(eid, body, exts, manager)
            extents_json = json.loads(json.dumps(body.extents, default=str))
            t0, t1 = _bounds(extents_json)
            doc = {"id": eid, "manager": manager, "uss_availability": "Unknown",
                   "version": old.doc["version"] + 1 if old else 1, "state": state, "ovn": _new_ovn(),
                   "time_start": t0, "time_end": t1, "uss_base_url": body.uss_base_url, "subscription_id": sid}
            if old is not None and old.doc["subscription_id"] != sid:
                self._release(eid, old.doc["subscription_id"])
            self.intents[eid] = _Entity(doc, exts, manager)
            subscribers = self._subscribers(exts + (old.extents if old else []), "intent")
        log.info("%s: operational intent reference %s %s by %s: version %d, %s", LOG_PREFIX, eid,
                 "updated" if old else "created", manager, doc["version"], state)
        return (200 if old else 201), {"operational_intent_reference": doc, "subscribers": subscribers}

    def _subscription_for(self, eid: str, body, exts: list, manager: str) -> str:
        """The subscription the reference is tied to: the one named (it must exist), or a new
        implicit one (``new_subscription``)."""
        sid = body.get("subscription_id")
        if sid:
            sub = self.subscriptions.get(str(sid))
            if sub is None:
                raise StandInError(400, f"subscription_id: {sid!r} is not a subscription here")
            sub.dependents.add(eid)
            return str(sid)
        new = body.get("new_subscription")
        if new is None:
            raise StandInError(400, "subscription_id, new_subscription: neither given (the stand-in DSS ties "
                                    "every reference to a subscription)")
        sid = str(uuid.uuid4())
        doc = {"id": sid, "version": _new_ovn()[:16], "notification_index": 0, "uss_base_url": new.uss_base_url,
               "notify_for_operational_intents": True,
               "notify_for_constraints": bool(new.get("notify_for_constraints") or False),
               "implicit_subscription": True, "dependent_operational_intents": [eid]}
        self.subscriptions[sid] = _Entity(doc, exts, manager, {eid})
        return sid

    def _release(self, eid: str, sid: str) -> None:
        sub = self.subscriptions.get(sid)
        if sub is None:
            return
        sub.dependents.discard(eid)
        if sub.doc.get("implicit_subscription") and not sub.dependents:
            del self.subscriptions[sid]

    def delete_intent(self, eid: str, ovn: str, manager: str) -> dict:
        with self._lock:
            old = self._checked_change(self.intents, eid, ovn, "operational intent reference")
            if old.manager != manager:
                raise StandInError(403, f"entityid: {eid} is managed by {old.manager!r}, not {manager!r}")
            del self.intents[eid]
            self._release(eid, old.doc["subscription_id"])
            subscribers = self._subscribers(old.extents, "intent")
        log.info("%s: operational intent reference %s deleted by %s", LOG_PREFIX, eid, manager)
        return {"operational_intent_reference": old.doc, "subscribers": subscribers}

    def put_constraint(self, eid: str, ovn: str | None, body, manager: str) -> tuple:
        if not body.extents:
            raise StandInError(400, "extents: empty (a reference needs at least one Volume4D)")
        exts = [extent(v, f"extents[{i}]") for i, v in enumerate(body.extents)]
        with self._lock:
            old = self._checked_change(self.constraints, eid, ovn, "constraint reference")
            t0, t1 = _bounds(json.loads(json.dumps(body.extents, default=str)))
            doc = {"id": eid, "manager": manager, "uss_availability": "Unknown",
                   "version": old.doc["version"] + 1 if old else 1, "ovn": _new_ovn(),
                   "time_start": t0, "time_end": t1, "uss_base_url": body.uss_base_url}
            self.constraints[eid] = _Entity(doc, exts, manager)
            subscribers = self._subscribers(exts, "constraint")
        log.info("%s: constraint reference %s %s by %s", LOG_PREFIX, eid, "updated" if old else "created", manager)
        return (200 if old else 201), {"constraint_reference": doc, "subscribers": subscribers}

    def delete_constraint(self, eid: str, ovn: str, manager: str) -> dict:
        with self._lock:
            old = self._checked_change(self.constraints, eid, ovn, "constraint reference")
            del self.constraints[eid]
            subscribers = self._subscribers(old.extents, "constraint")
        return {"constraint_reference": old.doc, "subscribers": subscribers}

    def query(self, table: str, body, reader: str) -> list:
        area = body.get("area_of_interest")
        if area is None:
            raise StandInError(400, "area_of_interest: missing")
        ext = [extent(area, "area_of_interest", need_times=False)]
        with self._lock:
            src = self.intents if table == "intent" else self.constraints
            return [self._shown(e, reader) for e in src.values() if _meets(e.extents, ext)]

    def get(self, table: str, eid: str, reader: str) -> dict:
        with self._lock:
            e = (self.intents if table == "intent" else self.constraints).get(eid)
            if e is None:
                raise StandInError(404, f"entityid: {eid} is not here")
            return self._shown(e, reader)


# ---- HTTP ----------------------------------------------------------------------------------

def _check_answer(op: Op, status: int, doc) -> None:
    """The answer is the type the operation gives for ``status`` and its references pass the
    restated schema, else StandInError 500 naming the check."""
    from uam_planner.f3548_schema import errors

    kind = api.OPERATIONS[op].response_body_type.get(status)
    if kind is None:
        raise StandInError(500, f"stand-in DSS bug: {op.value} has no answer of status {status}")
    try:
        ImplicitDict.parse(json.loads(json.dumps(doc)), kind)
    except (ValueError, KeyError, TypeError) as exc:
        raise StandInError(500, f"stand-in DSS bug: its {op.value} answer is not a {kind.__name__}: {exc}") from None
    refs = [doc[k] for k in ("operational_intent_reference",) if k in doc]
    refs += list(doc.get("operational_intent_references") or []) + list(doc.get("missing_operational_intents") or [])
    for ref in refs:
        errs = errors(ref, "OperationalIntentReference")
        if errs:
            raise StandInError(500, f"stand-in DSS bug: {op.value}: reference {ref.get('id')} fails the schema: "
                                    f"{errs[:3]}")


def _json_reply(status: int, doc):
    """A Flask response carrying ``doc`` as JSON with HTTP ``status``."""
    from flask import Response

    return Response(json.dumps(doc), status=status, mimetype="application/json")


def _checked_request(op: Op, verifier, params: dict) -> tuple[str, dict, object]:
    """The checks every request passes before its handler: body size, a token for the
    operation's scopes, UUIDv4 path ids (lower-cased) and the body parsed as the operation's
    request type. Returns (the caller's identity, the path parameters, the body or None);
    StandInError names what failed."""
    from flask import request

    from .auth import AuthError

    spec = api.OPERATIONS[op]
    if (request.content_length or 0) > MAX_BODY_BYTES:
        raise StandInError(413, f"body: {request.content_length} bytes, more than {MAX_BODY_BYTES}")
    try:
        grant = verifier.verify(request.headers.get("Authorization"), SCOPES[op])
    except AuthError as exc:
        raise StandInError(exc.status, exc.message) from None
    for name, value in params.items():
        if name in ("entityid", "subscriptionid") and not UUID4.match(value.lower()):
            raise StandInError(400, f"{name}: {value[:64]!r} is not a UUIDv4")
    params = {k: (v.lower() if k in ("entityid", "subscriptionid") else v) for k, v in params.items()}
    body = None
    if spec.request_body_type is not None:
        raw = request.get_json(silent=True)
        if not isinstance(raw, dict):
            raise StandInError(400, f"body: not a JSON object {spec.request_body_type.__name__}")
        try:
            body = ImplicitDict.parse(raw, spec.request_body_type)
        except (ValueError, KeyError, TypeError) as exc:
            raise StandInError(400, f"body: not a {spec.request_body_type.__name__}: "
                                    f"{str(exc)[:300]}") from None
    return grant.sub or "", params, body


def _answer(op: Op, verifier, handle, params: dict):
    """One request of ``op`` answered: checked, handled, and the answer checked against the
    operation's type for its status (a refusal logged, a failed check a 500)."""
    from flask import request

    try:
        who, params, body = _checked_request(op, verifier, params)
        status, doc = handle(body, who, **params)
    except StandInError as exc:
        status, doc = exc.status, exc.body if exc.body is not None else {"message": exc.message}
        if status >= 500:
            log.error("%s: %s", LOG_PREFIX, exc.message)
        else:
            log.info("%s: %s %s refused: %d %s", LOG_PREFIX, request.method, request.path, status, exc.message)
    try:
        _check_answer(op, status, doc)
    except StandInError as exc:
        log.error("%s: %s", LOG_PREFIX, exc.message)
        status, doc = 500, {"message": exc.message}
    return _json_reply(status, doc)


def _add_endpoint(app, verifier, op: Op, handle) -> None:
    """Serve ``op`` on ``app`` at its F3548 path and verb, answered by ``handle``."""
    spec = api.OPERATIONS[op]

    def view(**params):
        return _answer(op, verifier, handle, params)

    view.__name__ = f"dss_{op.value}"
    app.add_url_rule(re.sub(r"\{(\w+)\}", r"<\1>", spec.path), view_func=view, methods=[spec.verb])


def _handlers(dss: StandInDss) -> dict:
    """Each served operation's handler: (body, caller, path parameters) -> (status, answer)."""
    return {
        Op.CreateOperationalIntentReference: lambda b, who, entityid: dss.put_intent(entityid, None, b, who),
        Op.UpdateOperationalIntentReference: lambda b, who, entityid, ovn: dss.put_intent(entityid, ovn, b, who),
        Op.DeleteOperationalIntentReference: lambda b, who, entityid, ovn: (200, dss.delete_intent(entityid, ovn, who)),
        Op.GetOperationalIntentReference:
            lambda b, who, entityid: (200, {"operational_intent_reference": dss.get("intent", entityid, who)}),
        Op.QueryOperationalIntentReferences:
            lambda b, who: (200, {"operational_intent_references": dss.query("intent", b, who)}),
        Op.CreateConstraintReference: lambda b, who, entityid: dss.put_constraint(entityid, None, b, who),
        Op.UpdateConstraintReference: lambda b, who, entityid, ovn: dss.put_constraint(entityid, ovn, b, who),
        Op.DeleteConstraintReference:
            lambda b, who, entityid, ovn: (200, dss.delete_constraint(entityid, ovn, who)),
        Op.GetConstraintReference:
            lambda b, who, entityid: (200, {"constraint_reference": dss.get("constraint", entityid, who)}),
        Op.QueryConstraintReferences:
            lambda b, who: (200, {"constraint_references": dss.query("constraint", b, who)}),
        Op.CreateSubscription:
            lambda b, who, subscriptionid: (200, dss.put_subscription(subscriptionid, None, b, who)),
        Op.UpdateSubscription:
            lambda b, who, subscriptionid, version: (200, dss.put_subscription(subscriptionid, version, b, who)),
        Op.DeleteSubscription:
            lambda b, who, subscriptionid, version: (200, dss.delete_subscription(subscriptionid, version)),
    }


def create_app(verifier, dss: StandInDss | None = None):
    """The stand-in's Flask app over ``dss`` (a new :class:`StandInDss` if None); ``verifier``: a
    :class:`uam_sim.f3548.auth.TokenVerifier` (every DSS call needs a token; its ``sub`` is the
    caller's identity, a reference's manager). ``app.dss`` is the state."""
    from flask import Flask, request
    from werkzeug.exceptions import HTTPException

    dss = dss or StandInDss()
    app = Flask("uam_dss_standin")
    app.dss = dss
    handlers = _handlers(dss)
    for op, handle in handlers.items():
        _add_endpoint(app, verifier, op, handle)
    served = set(handlers) & set(DSS_OPERATIONS)

    @app.errorhandler(HTTPException)
    def _http_error(exc):
        return _json_reply(exc.code or 500, {"message": f"stand-in DSS: {exc.name}: {request.method} {request.path[:200]}"})

    log.info("%s: serving %d DSS operations (in memory, not a DSS)", LOG_PREFIX, len(served))
    return app
