"""What peer USSs tell this USS over F3548's USS-USS interface (docs/f3548.md, "Peers"):
their operational intents and constraints (``POST /uss/v1/operational_intents``,
``POST /uss/v1/constraints``) and their reports (``POST /uss/v1/reports``).

:class:`PeerInbox` validates each notification with ``uas_standards``' types
(``PutOperationalIntentDetailsParameters``, ``PutConstraintDetailsParameters``, ``ErrorReport``),
keeps the newest version of every peer entity, and hands every change to its ``listener`` as
the planner's constraint updates (:func:`constraint_updates`): a peer's intent becomes the prisms
``constraints_from_f3548`` makes of it (widened by our half-separation), added, changed (a new
version) or withdrawn (a deletion, or volumes it no longer has). No ROS: the node or a test wires
the listener to a planner (``Planner.update_constraint``). Thread-safe (one lock).
"""

from __future__ import annotations

import threading
import uuid
from collections import deque


class NotificationError(ValueError):
    """A notification refused: ``status`` (400 / 403 / 409) and a message naming the field and
    value."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


def parse_typed(body, kind, error=None, what: str = "an F3548 "):
    """``body`` (decoded JSON) parsed as the ``uas_standards`` type ``kind``; otherwise
    ``error(400, message)`` (default NotificationError) naming the body and the type."""
    from implicitdict import ImplicitDict
    error = NotificationError if error is None else error
    if not isinstance(body, dict):
        raise error(400, f"body: {type(body).__name__} is not a JSON object {kind.__name__}")
    try:
        return ImplicitDict.parse(body, kind)
    except (ValueError, KeyError, TypeError) as exc:
        raise error(400, f"body: not {what}{kind.__name__}: {str(exc)[:300]}") from None



def constraint_updates(old: dict, new: list) -> list:
    """[(action, Constraint or id)] taking the constraints ``old`` (id -> Constraint) to ``new``:
    'add' for a new id, 'change' for a known id at a higher version, 'withdraw' for an id gone
    (as ``Planner.update_constraint`` takes them)."""
    out = []
    seen = set()
    for c in new:
        seen.add(c.constraint_id)
        before = old.get(c.constraint_id)
        if before is None:
            out.append(("add", c))
        elif int(c.version) > int(before.version):
            out.append(("change", c))
    out += [("withdraw", cid) for cid in sorted(set(old) - seen)]
    return out


#: UpdateConstraint's actions (uam_planner.live_constraints)
_ACTION_CODES = {"add": 0, "change": 1, "withdraw": 2}


class PlannerForwarder:
    """Peers' changes as updates of the planner's live constraints, signed by the USS's own
    airspace authority (``uam_planner.authority``; run_fleet.sh makes it, not an admin, so it
    may change only what it added): each :func:`constraint_updates` pair becomes one request with
    UpdateConstraint's fields (a plain object the node copies into the message). ``seq0``: the
    first sequence number (each request takes the next)."""

    def __init__(self, authority_id: str, private_key_pem: bytes, seq0: int):
        self.authority_id, self.key = str(authority_id), bytes(private_key_pem)
        self.seq = int(seq0)
        self.sent: dict[str, int] = {}   # constraint id -> the version last sent

    def requests(self, updates) -> list:
        import json
        from types import SimpleNamespace

        from uam_planner.authority import sign_update
        from uam_planner.live_constraints import constraint_feature

        out = []
        for action, what in updates:
            if action == "withdraw":
                cid = str(what)
                req = SimpleNamespace(action=_ACTION_CODES[action], constraint_id=cid,
                                      version=self.sent.get(cid, 0) + 1, reason="withdrawn by the peer", geojson="")
            else:
                req = SimpleNamespace(action=_ACTION_CODES[action], constraint_id=what.constraint_id,
                                      version=int(what.version), reason=str(what.reason),
                                      geojson=json.dumps(constraint_feature(what)))
            self.seq += 1
            req.authorization = sign_update(req, action, self.authority_id, self.key, self.seq)
            self.sent[req.constraint_id] = int(req.version)
            out.append(req)
        return out


class PeerInbox:
    """Peers' intents and constraints (the newest version of each) and their reports.

    ``network`` places their volumes in our frame; ``spec`` (a VolumeSpec) widens their intents
    by our half-separation; ``listener(updates, kind, entity_id)`` is called with the
    :func:`constraint_updates` of every accepted change (outside the lock); ``log(text)`` gets one
    line per notification and report.

    Who may say what (the caller is the ``sub`` of its verified token, F3548's manager): a
    notification's document must name its caller as ``reference.manager`` (a USS notifies of
    its own intents and constraints, never of another's), and an entity already held changes or
    goes only by a notification of the manager that holds it. ``peers``: the managers this USS
    takes notifications from at all (None: any caller with a valid token and scope). Without
    token checks (the server's ``auth off``) there is no caller to check.
    """

    def __init__(self, network, spec, scenario_start_utc: str, listener=None, log=None,
                 max_reports: int = 1000, peers=None):
        self.network, self.spec, self.start = network, spec, scenario_start_utc
        self.listener, self.log = listener, log or (lambda text: None)
        self.peers = None if peers is None else frozenset(str(x) for x in peers)
        self._lock = threading.Lock()
        self._docs: dict[str, tuple] = {}            # (kind, id) -> (version, document)
        self._constraints: dict[str, dict] = {}      # (kind, id) -> {constraint id: Constraint}
        self.reports: deque = deque(maxlen=int(max_reports))

    def _apply(self, kind: str, entity_id: str, doc) -> list:
        from uam_planner.f3548 import constraints_from_f3548
        key = f"{kind}:{entity_id}"
        new = [] if doc is None else constraints_from_f3548(
            {kind: doc}, self.network, self.start, spec=self.spec)
        with self._lock:
            held = self._docs.get(key)
            version = -1 if doc is None else int(doc["reference"]["version"])
            if doc is not None and held is not None and held[0] >= version:
                return []  # an older or the same version: nothing changes
            old = self._constraints.get(key, {})
            if doc is None:
                self._docs.pop(key, None)
                self._constraints.pop(key, None)
            else:
                self._docs[key] = (version, doc)
                self._constraints[key] = {c.constraint_id: c for c in new}
        updates = constraint_updates(old, new)
        if updates and self.listener is not None:
            self.listener(updates, kind, entity_id)
        return updates

    def notify(self, body, kind: str, manager: str = "") -> list:
        """One notification (JSON) of ``kind`` 'operational_intent' or 'constraint': validated,
        applied (the newest version wins; without the entity, a deletion). Returns the updates
        made. Raises NotificationError (400) naming the field."""
        from uas_standards.astm.f3548.v21 import api

        from uam_planner.f3548 import F3548Error
        params = parse_typed(body, api.PutOperationalIntentDetailsParameters if kind == "operational_intent"
                        else api.PutConstraintDetailsParameters)
        entity_id = str(params[f"{kind}_id"]).lower()
        doc = body.get(kind)
        if doc is not None:
            ref = doc["reference"]
            if str(ref["id"]).lower() != entity_id:
                raise NotificationError(400, f"{kind}.reference.id: {ref['id']!r} is not {kind}_id "
                                             f"{entity_id!r}")
            if not ref.get("ovn"):
                raise NotificationError(400, f"{kind}.reference.ovn: missing (F3548: a notification "
                                             f"carries the OVN)")
        self._check_caller(kind, entity_id, doc, manager)
        try:
            updates = self._apply(kind, entity_id, doc)
        except F3548Error as exc:
            raise NotificationError(400, f"{kind}: {exc}") from None
        what = "deleted" if doc is None else f"version {doc['reference']['version']} of {doc['reference'].get('manager', '?')}"
        self.log(f"peer {kind} {entity_id} ({what}, from {manager or '?'}): {len(updates)} constraint updates")
        return updates

    def _check_caller(self, kind: str, entity_id: str, doc, manager: str) -> None:
        """NotificationError 403 unless ``manager`` may send this notification (class doc)."""
        if not manager:
            return
        if self.peers is not None and manager not in self.peers:
            raise NotificationError(403, f"manager: {manager!r} is not a peer this USS takes "
                                         f"notifications from")
        if doc is not None and str(doc["reference"].get("manager", "")) != manager:
            raise NotificationError(403, f"{kind}.reference.manager: {doc['reference'].get('manager')!r} "
                                         f"is not the caller {manager!r} (a USS notifies of its own)")
        with self._lock:
            held = self._docs.get(f"{kind}:{entity_id}")
        owner = None if held is None else str(held[1]["reference"].get("manager", ""))
        if owner is not None and owner != manager:
            raise NotificationError(403, f"{kind}_id: {entity_id!r} is managed by {owner!r}, not by "
                                         f"the caller {manager!r}")

    def report(self, body, manager: str = "") -> dict:
        """A peer's ErrorReport: validated, kept (the newest ``max_reports``), logged; returned with
        the ``report_id`` assigned here."""
        from uas_standards.astm.f3548.v21 import api
        parse_typed(body, api.ErrorReport)
        out = dict(body, report_id=str(uuid.uuid4()))
        with self._lock:
            self.reports.append(out)
        ex = body.get("exchange", {})
        self.log(f"peer report {out['report_id']} from {manager or '?'}: {ex.get('method', '?')} "
                 f"{str(ex.get('url', '?'))[:200]} -> {ex.get('response_code', '?')}: "
                 f"{str(ex.get('problem', ''))[:200]}")
        return out

    def entity_ids(self) -> list:
        with self._lock:
            return sorted(self._docs)
