"""InterUSS's flight_planning automated-testing interface (v1: the API whose types and operation
table ``uas_standards.interuss.automated_testing.flight_planning.v1`` holds) over this USS's
planner (docs/f3548.md, "The flight_planning interface"). No ROS; no wall clock in a decision.

- :func:`parse_body` validates a request body with the library's types, then the fields this
  USS reads, raising :class:`FlightPlanningError` (400) naming the field and its value;
- :func:`flight_request` turns a flight plan into the planner's ``FlightRequest``: its priority
  (``astm_f3548_21.priority``), its origin and destination vertiports (``additional_information``
  ``origin_id`` / ``destination_id``, else the aerodromes nearest to its first and last volumes),
  its departure window (the area's time window, from the planner's next epoch on);
- :class:`FlightPlanning` answers the four operations (status, upsert, delete, clear area) with
  a *decider*: whatever puts a request to the planner and waits for its decision;
- :class:`InProcessDecider` is the decider of a ``Planner`` object (the library path, and the
  tests): it plans the planner's next epochs itself. The uss node's decider hands the request to
  the planner node over ROS and waits for the decision of the next epoch, up to a bound.

The decision rule is the planner's next epoch (docs/f3548.md says why): a flight plan is one
more request of that epoch, decided in its MWIS with every other request and deconflicted
against every active flight and constraint, so it gets exactly what any other request would.
"""

from __future__ import annotations

import re
import threading
from collections import OrderedDict
from dataclasses import dataclass, field

from uas_standards.interuss.automated_testing.flight_planning.v1 import api
from uas_standards.interuss.automated_testing.flight_planning.v1.constants import Scope

API_NAME = "Flight Planning Automated Testing Interface"
API_VERSION = f"v{api.API_VERSION}"
#: where the interface is served (InterUSS's clients append the operation paths to it)
PREFIX = "/flight_planning/v1"
SCOPE_PLAN = Scope.Plan.value
SCOPE_DIRECT = Scope.DirectAutomatedTest.value
Op = api.OperationID
#: the scopes each operation takes (any one will do). The interface's OpenAPI gives the status
#: and clear area to the test director (direct_automated_test), the upsert to the virtual user
#: (plan); the delete is the director's in the OpenAPI and the user's in InterUSS's own client
#: and mock USS, so either is taken.
SCOPES = {
    Op.GetStatus: (SCOPE_DIRECT,),
    Op.UpsertFlightPlan: (SCOPE_PLAN,),
    Op.DeleteFlightPlan: (SCOPE_PLAN, SCOPE_DIRECT),
    Op.ClearArea: (SCOPE_DIRECT,),
}
#: the operations served (QueryUserNotifications is not: no notifications reach a virtual user here)
SERVED = tuple(SCOPES)
#: FlightPlanID: a UUIDv4 (the interface's pattern)
FLIGHT_PLAN_ID = re.compile(r"^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-4[0-9a-fA-F]{3}-[89abAB][0-9a-fA-F]{3}-"
                            r"[0-9a-fA-F]{12}$")
MAX_REQUEST_ID_CHARS = 256
#: answers kept for repeated request ids (the interface: a repeat gets the first answer)
MAX_ANSWERS = 1000
MAX_VOLUMES = 100
#: the operator under which flight plans are planned when none is configured
DEFAULT_OPERATOR = "flight_planning"


def route(op: Op) -> tuple:
    """(HTTP verb, Flask rule) of ``op`` from the library's operation table, under PREFIX."""
    o = api.OPERATIONS[op]
    return o.verb, PREFIX + re.sub(r"\{(\w+)\}", r"<\1>", o.path)


class FlightPlanningError(ValueError):
    """A request refused before planning: ``status`` (400, 404, 409) and a message naming the
    field and its value."""

    def __init__(self, status: int, message: str):
        super().__init__(message)
        self.status, self.message = status, message


def _shown(value) -> str:
    text = repr(value)
    return text if len(text) <= 80 else text[:77] + "..."


def parse_body(body, kind):
    """``body`` (JSON) as the library's ``kind``; FlightPlanningError 400 naming the field."""
    from .peers import parse_typed
    return parse_typed(body, kind, FlightPlanningError, "a ")


def check_flight_plan_id(flight_plan_id: str) -> str:
    """The id in lower case (UUIDs are read without case), or FlightPlanningError 400."""
    if len(flight_plan_id) > 36 or not FLIGHT_PLAN_ID.match(flight_plan_id):
        raise FlightPlanningError(400, f"flight_plan_id: {_shown(flight_plan_id[:64])} is not a FlightPlanID "
                                       "(a UUIDv4)")
    return flight_plan_id.lower()


def _request_id(body) -> str:
    rid = body.get("request_id")
    if not isinstance(rid, str) or not rid or len(rid) > MAX_REQUEST_ID_CHARS:
        raise FlightPlanningError(400, f"request_id: {_shown(rid)} is not a string of 1 to "
                                       f"{MAX_REQUEST_ID_CHARS} characters")
    return rid


# ---- a flight plan as a request of the planner ------------------------------------------------

@dataclass(frozen=True)
class Area:
    """A flight plan's area in the network's frame: one prism Constraint per volume, and the
    window [start_s, end_s] of the whole (simulation seconds)."""
    prisms: tuple
    start_s: float
    end_s: float


def area_prisms(volumes, network, scenario_start_utc: str, where: str, buffer_h_m: float = 0.0,
                buffer_v_m: float = 0.0) -> Area:
    """The Volume4Ds ``volumes`` (JSON) as an Area; each must have a start and an end time.
    FlightPlanningError 400 naming ``where[k]`` and the field."""
    from uam_planner.f3548 import F3548Error, volume_prism

    if not isinstance(volumes, list) or not volumes:
        raise FlightPlanningError(400, f"{where}: {_shown(volumes)}: this USS plans a flight from its area, "
                                       "at least one Volume4D")
    if len(volumes) > MAX_VOLUMES:
        raise FlightPlanningError(400, f"{where}: {len(volumes)} volumes, more than {MAX_VOLUMES}")
    prisms = []
    for k, v4 in enumerate(volumes):
        at = f"{where}[{k}]"
        for name in ("time_start", "time_end"):
            if not isinstance(v4, dict) or not v4.get(name):
                raise FlightPlanningError(400, f"{at}.{name}: missing (the planner needs the time window)")
        try:
            c = volume_prism(v4, network, scenario_start_utc, f"area:{k}", at, buffer_h_m, buffer_v_m)
        except F3548Error as exc:
            raise FlightPlanningError(400, str(exc)) from None
        if not c.end_s > c.start_s:
            raise FlightPlanningError(400, f"{at}.time_end: {v4['time_end'].get('value')!r} is not after "
                                           f"time_start {v4['time_start'].get('value')!r}")
        prisms.append(c)
    return Area(tuple(prisms), min(c.start_s for c in prisms), max(c.end_s for c in prisms))


def _centre_m(c):
    import numpy as np
    if c.center_m is not None:
        return np.asarray(c.center_m, dtype=float)
    return np.asarray(c.rings_m[0], dtype=float).mean(axis=0)


def nearest_aerodrome(network, xy_m, exclude: str = "") -> str:
    """The aerodrome of ``network`` nearest (horizontally) to ``xy_m`` (east, north) [m], other
    than ``exclude``; ties go to the first in the network's order."""
    import numpy as np
    ids = [a for a in network.aerodrome_ids if a != exclude]
    if not ids:
        raise FlightPlanningError(400, f"network {network.name!r} has no aerodrome other than {exclude!r}")
    pos = np.array([network.enu_m[network.index[a]][:2] for a in ids], dtype=float)
    return ids[int(np.argmin(np.hypot(*(pos - np.asarray(xy_m, dtype=float)[:2]).T)))]


def _ends(plan: dict, area: Area, network) -> tuple:
    """(origin, destination) aerodrome ids: ``additional_information`` ``origin_id`` and
    ``destination_id`` if given, else the aerodromes nearest to the centre of the volume that
    starts first and (another one) to the centre of the volume that ends last."""
    extra = plan.get("additional_information") or {}
    given = [extra.get("origin_id"), extra.get("destination_id")]
    if any(v is not None for v in given):
        for name, v in zip(("origin_id", "destination_id"), given):
            if not isinstance(v, str) or network.index.get(v) is None or not network.is_aerodrome[network.index[v]]:
                raise FlightPlanningError(400, f"flight_plan.additional_information.{name}: {_shown(v)} is not "
                                               f"an aerodrome of network {network.name!r}")
        return given[0], given[1]
    first = min(area.prisms, key=lambda c: (c.start_s, c.constraint_id))
    last = max(area.prisms, key=lambda c: (c.end_s, c.constraint_id))
    origin = nearest_aerodrome(network, _centre_m(first))
    return origin, nearest_aerodrome(network, _centre_m(last), exclude=origin)


def _priority(plan: dict) -> int:
    from uam_planner.grants import MAX_CLASS
    value = (plan.get("astm_f3548_21") or {}).get("priority", 0)
    if isinstance(value, bool) or not isinstance(value, int) or not 0 <= value <= MAX_CLASS:
        raise FlightPlanningError(400, f"flight_plan.astm_f3548_21.priority: {_shown(value)} is not a priority "
                                       f"class 0..{MAX_CLASS}")
    return int(value)


@dataclass(frozen=True)
class Translation:
    """What a flight plan asks the planner: the request, and the area it came from."""
    request: object          # uam_planner.planning.FlightRequest
    area: Area


def flight_request(request_id: str, plan: dict, network, scenario_start_utc: str, now_s: float,
                   operator_id: str = DEFAULT_OPERATOR) -> Translation:
    """The planner's FlightRequest for ``plan`` (a FlightPlan as JSON) planned from ``now_s`` [s]
    (the planner's next epoch): departure window [max(area start, now), area end]; a window
    already over is kept as it is (the planner refuses it, naming it). FlightPlanningError 400
    naming the field."""
    from uam_planner.planning import FlightRequest

    area = area_prisms((plan.get("basic_information") or {}).get("area"), network, scenario_start_utc,
                       "flight_plan.basic_information.area")
    origin, destination = _ends(plan, area, network)
    earliest = max(area.start_s, float(now_s))
    return Translation(FlightRequest(request_id, origin, destination, float(now_s), earliest, area.end_s,
                                     priority=_priority(plan), operator_id=operator_id), area)


# ---- the decider: whatever puts a request to the planner --------------------------------------

@dataclass(frozen=True)
class Decision:
    """The planner's decision on one request: ``outcome`` 'approved' (``flight`` is the Flight),
    'rejected' (refused on arrival, ``reason`` naming the field), 'expired' (no conflict-free
    departure in its window) or 'failed' (no decision: the planner did not answer in time)."""
    outcome: str
    reason: str = ""
    flight: object = None


class InProcessDecider:
    """Decisions of a ``Planner`` object in this process (the library path: no simulator, no ROS):
    the caller is the clock. ``decide`` submits a request and plans the planner's next epochs
    itself (at ``t_s``, ``t_s + epoch_s``, ...) until the request is decided; ``now_s`` is then
    the time of the epoch that decided it (the instant states and cancellations are taken at).
    Each EpochResult goes to ``store`` (an IntentStore: approvals and new versions served,
    cancellations ended) and to ``on_result``. ``max_epochs`` bounds one decision (then
    'failed', the request withdrawn). A flight plan whose area starts after the next epoch is
    approved ahead of its departure only with the planner's ``horizon_epochs`` > 1 and
    ``commit_ahead`` (reservations); otherwise it departs at the epoch that approves it."""

    def __init__(self, planner, t_s: float = 0.0, epoch_index: int = 0, store=None, on_result=None,
                 max_epochs: int = 240):
        self.planner, self.store, self.on_result = planner, store, on_result
        self.t_s, self.epoch_index, self.max_epochs = float(t_s), int(epoch_index), int(max_epochs)
        self.now_s = float(t_s)
        self.results: list = []

    def ready(self) -> bool:
        return True

    def _epoch(self):
        result = self.planner.plan(self.t_s, self.epoch_index)
        self.results.append(result)
        if self.store is not None:
            self.store.set_time(self.t_s)
            for f in result.approved:
                self.store.put_flight(f)
            for u in result.plan_updates:
                if u.flight is None:
                    self.store.end(u.operator_id, u.request_id)
                elif u.kind != "kept":
                    self.store.put_flight(u.flight)
        if self.on_result is not None:
            self.on_result(result)
        self.now_s = self.t_s
        self.epoch_index += 1
        self.t_s += float(self.planner.config.epoch_s)
        return result

    def decide(self, request) -> Decision:
        reason = self.planner.submit(request)
        if reason is not None:
            return Decision("rejected", reason)
        for _ in range(self.max_epochs):
            result = self._epoch()
            for f in result.approved:
                if f.request_id == request.request_id:
                    return Decision("approved", flight=f)
            for r in result.expired:
                if r.request_id == request.request_id:
                    why = result.report.constraint_refusals.get(r.request_id) if hasattr(
                        result.report, "constraint_refusals") else None
                    return Decision("expired", why or f"no conflict-free departure found by latest_departure "
                                                      f"{r.latest_departure_s:g} s")
        self.planner.cancel(request.request_id, self.now_s)
        return Decision("failed", f"no decision in {self.max_epochs} epochs; the request is withdrawn")

    def cancel(self, request_id: str, operator_id: str, reason: str) -> str | None:
        problem = self.planner.cancel(request_id, self.now_s, reason)
        if problem is None and self.store is not None:
            self.store.end(operator_id, request_id)
        return problem

    def modify(self, request) -> Decision:
        """A new version of the approved flight ``request.request_id`` (``Planner.modify``),
        decided at the next epoch: 'approved' (``flight`` the new version), 'rejected' (refused
        at once; ``flight`` the version in force, unchanged) or 'expired' (no conflict-free
        candidate at that epoch; ``flight`` the previous version if it stays in force, else None)."""
        reason = self.planner.modify(request, self.t_s)
        if reason is not None:
            return Decision("rejected", reason, self.planner.flight(request.request_id))
        result = self._epoch()
        from uam_planner.replanning import KIND_MODIFIED
        rid = request.request_id
        for u in result.plan_updates:
            if u.request_id == rid and u.kind == KIND_MODIFIED:
                return Decision("approved", flight=u.flight)
        why, kept = result.refused_modifications.get(rid, ("not decided at the next epoch", False))
        return Decision("expired", why, self.planner.flight(rid) if kept else None)

    def flight(self, request_id: str):
        """The planner's flight of ``request_id`` in force (its newest version), or None."""
        return self.planner.flight(request_id)


# ---- the interface ----------------------------------------------------------------------------

@dataclass
class _Plan:
    """One flight plan of the interface: the planner request in force and how it was asked."""
    request_id: str                      # the planner's request id (the flight plan's id)
    version: int                         # 1, 2, ...: the flight plan's versions asked and approved
    asked: tuple                         # (origin, destination, earliest, latest, priority)
    answered: dict = field(default_factory=dict)


def _status_of(flight, t_s: float) -> str:
    from uam_planner.replanning import flight_state
    if flight is None:
        return api.FlightPlanStatus.Closed.value
    state = flight_state(flight, t_s)
    return {"Accepted": api.FlightPlanStatus.Planned, "Activated": api.FlightPlanStatus.OkToFly,
            "Nonconforming": api.FlightPlanStatus.OffNominal, "Contingent": api.FlightPlanStatus.OffNominal,
            "Ended": api.FlightPlanStatus.Closed}[state].value


def _upsert_answer(result: str, status: str, notes: str = "", as_planned=None) -> dict:
    doc = {"planning_result": result, "flight_plan_status": status,
           "includes_advisories": api.AdvisoryInclusion.NoAdvisoriesOrConditions.value}
    if notes:
        doc["notes"] = notes
    if as_planned is not None:
        doc["as_planned"] = as_planned
    return doc


class FlightPlanning:
    """The flight_planning interface of one USS over a decider (module docstring).

    ``network`` and ``ctx`` (an IntentContext: the scenario clock, the volume spec) place the
    areas; flight plans are planned as requests of operator ``operator_id`` (whose priority
    grant applies), with the planner request id ``<flight_plan_id>``; a modification is a new
    version of the same request (``Planner.modify``), so of the same operational intent. Each operation returns ``(HTTP status, JSON
    document)``; one operation at a time (a lock). Requests repeated with the same
    ``request_id`` get the first answer (the newest :data:`MAX_ANSWERS` are kept).
    """

    def __init__(self, decider, network, ctx, operator_id: str = DEFAULT_OPERATOR, log=None):
        self.decider, self.network, self.ctx = decider, network, ctx
        self.operator_id = str(operator_id)
        self.log = log or (lambda text: None)
        self._lock = threading.Lock()
        self.plans: dict[str, _Plan] = {}
        self._tries: dict[str, int] = {}   # flight plan id -> planner requests made for it
        self._answers: OrderedDict = OrderedDict()

    # ---- status --------------------------------------------------------------------------------
    def status(self) -> tuple:
        ready = api.StatusResponseStatus.Ready if self.decider.ready() else api.StatusResponseStatus.Starting
        return 200, {"status": ready.value, "api_name": API_NAME, "api_version": API_VERSION}

    # ---- answers to repeated requests ----------------------------------------------------------
    def _remember(self, key: tuple, answer: tuple) -> tuple:
        self._answers[key] = answer
        while len(self._answers) > MAX_ANSWERS:
            self._answers.popitem(last=False)
        return answer

    # ---- upsert --------------------------------------------------------------------------------
    def upsert(self, flight_plan_id: str, body) -> tuple:
        """PUT /flight_plans/{flight_plan_id}: 200 UpsertFlightPlanResponse, 400 naming the field,
        409 for a request_id repeated with another flight plan id."""
        try:
            fid = check_flight_plan_id(flight_plan_id)
            parse_body(body, api.UpsertFlightPlanRequest)
            rid = _request_id(body)
            with self._lock:
                key = ("upsert", rid)
                if key in self._answers:
                    seen_fid, answer = self._answers[key]
                    if seen_fid != fid:
                        raise FlightPlanningError(409, f"request_id: {rid!r} was used for flight plan {seen_fid}, "
                                                       f"not {fid}")
                    return answer
                answer = self._upsert(fid, body)
                self._remember(key, (fid, answer))
                return answer
        except FlightPlanningError as exc:
            return exc.status, {"message": exc.message}

    def _not_supported(self, fid: str, why: str) -> tuple:
        plan = self.plans.get(fid)
        status = _status_of(self.decider.flight(plan.request_id), self.decider.now_s) if plan else \
            api.FlightPlanStatus.NotPlanned.value
        return 200, _upsert_answer(api.PlanningActivityResult.NotSupported.value, status, why)

    def _upsert(self, fid: str, body: dict) -> tuple:
        style = body["execution_style"]
        plan_doc = body["flight_plan"]
        info = plan_doc["basic_information"]
        if style != api.ExecutionStyle.IfAllowed.value:
            return self._not_supported(fid, f"execution_style: {style!r}: this USS plans only IfAllowed requests "
                                            "(no hypothetical plans, no reports of what already flies)")
        if info.get("uas_state", "Nominal") not in ("Nominal", "NotSpecified"):
            return self._not_supported(fid, f"flight_plan.basic_information.uas_state: {info['uas_state']!r}: an "
                                            "operator's report of an off-nominal aircraft is not taken here (the "
                                            "planner's own observations decide)")
        if info["usage_state"] == api.BasicFlightPlanInformationUsageState.Closed.value:
            return self._close(fid, as_upsert=True)
        now = self.decider.t_s
        old = self.plans.get(fid)
        current = self.decider.flight(old.request_id) if old is not None else None
        if current is not None:
            tr = flight_request(old.request_id, plan_doc, self.network, self.ctx.scenario_start_utc, now,
                                self.operator_id)
            r = tr.request
            asked = (r.origin_id, r.destination_id, tr.area.start_s, tr.area.end_s, r.priority)
            if old.asked == asked:
                # the same plan asked again (e.g. usage_state Planned -> InUse): nothing to re-plan;
                # the aircraft flies from its planned departure
                return 200, _upsert_answer(api.PlanningActivityResult.Completed.value,
                                           _status_of(current, self.decider.now_s),
                                           self._notes(current, "unchanged"), self._as_planned(plan_doc, current))
            return self._modify(fid, old, tr, asked, plan_doc)
        if old is not None:   # its flight ended (landed, cancelled): planned anew
            del self.plans[fid]
        tr = flight_request(self._new_request_id(fid), plan_doc, self.network, self.ctx.scenario_start_utc, now,
                            self.operator_id)
        r = tr.request
        asked = (r.origin_id, r.destination_id, tr.area.start_s, tr.area.end_s, r.priority)
        return self._plan(fid, tr, asked, plan_doc, 1)

    def _new_request_id(self, fid: str) -> str:
        """The planner request id of a new request for flight plan ``fid``: ``fid`` the first
        time, ``<fid>.<n>`` for the n-th (the planner never takes an id twice: a plan refused at
        its epoch, or whose flight ended, is asked anew under a new id)."""
        n = self._tries.get(fid, 0) + 1
        self._tries[fid] = n
        return fid if n == 1 else f"{fid}.{n}"

    def _notes(self, flight, what: str) -> str:
        return (f"{what}: {flight.origin_id} -> {flight.destination_id}, departs at t = {flight.departure_s:g} s, "
                f"arrives at t = {flight.arrival_s:g} s (simulation time; operational intent version "
                f"{flight.version})")

    def _as_planned(self, plan_doc: dict, flight) -> dict:
        """The flight plan as planned: its area replaced by the operational intent's volumes."""
        from uam_planner.f3548 import as_json, operational_intent
        doc = {k: v for k, v in plan_doc.items()}
        intent = operational_intent(flight, self.decider.now_s, self.ctx, state="Accepted")
        info = dict(doc["basic_information"])
        info["area"] = as_json(intent.details.volumes) if intent is not None else []
        doc["basic_information"] = info
        return doc

    def _plan(self, fid: str, tr: Translation, asked: tuple, plan_doc: dict, version: int) -> tuple:
        d = self.decider.decide(tr.request)
        self.log(f"flight plan {fid}: {tr.request.request_id} {tr.request.origin_id} -> "
                 f"{tr.request.destination_id}, priority {tr.request.priority}: {d.outcome} {d.reason}".rstrip())
        if d.outcome == "approved":
            self.plans[fid] = _Plan(tr.request.request_id, version, asked)
            return 200, _upsert_answer(api.PlanningActivityResult.Completed.value,
                                       _status_of(d.flight, self.decider.now_s), self._notes(d.flight, "planned"),
                                       self._as_planned(plan_doc, d.flight))
        result = api.PlanningActivityResult.Failed if d.outcome == "failed" else api.PlanningActivityResult.Rejected
        return 200, _upsert_answer(result.value, api.FlightPlanStatus.NotPlanned.value,
                                   f"{d.outcome}: {d.reason}")

    def _modify(self, fid: str, old: _Plan, tr: Translation, asked: tuple, plan_doc: dict) -> tuple:
        """A new version of the same flight (``decider.modify``: the same request id, so the same
        operational intent, version + 1). Not approved, the previous version stays in force if it
        still keeps separation (the answer says so), else it is cancelled and the answer says why."""
        d = self.decider.modify(tr.request)
        self.log(f"flight plan {fid}: modification {tr.request.origin_id} -> {tr.request.destination_id}, "
                 f"priority {tr.request.priority}: {d.outcome} {d.reason}".rstrip())
        R, S = api.PlanningActivityResult, api.FlightPlanStatus
        if d.outcome == "approved":
            self.plans[fid] = _Plan(old.request_id, old.version + 1, asked)
            return 200, _upsert_answer(R.Completed.value, _status_of(d.flight, self.decider.now_s),
                                       self._notes(d.flight, "modified"), self._as_planned(plan_doc, d.flight))
        result = R.Failed if d.outcome == "failed" else R.Rejected
        # (the planner's reason may say already what became of the previous version)
        if d.flight is not None:
            kept = "the previous version stays in force"
            return 200, _upsert_answer(result.value, _status_of(d.flight, self.decider.now_s),
                                       f"{d.outcome}: {d.reason}" + ("" if kept in d.reason else f"; {kept}"))
        del self.plans[fid]
        lost = "the previous version is no longer in force"
        return 200, _upsert_answer(result.value, S.Closed.value,
                                   f"{d.outcome}: {d.reason}" + ("" if "previous version" in d.reason else f"; {lost}"))

    # ---- delete --------------------------------------------------------------------------------
    def delete(self, flight_plan_id: str) -> tuple:
        """DELETE /flight_plans/{flight_plan_id}: 200 DeleteFlightPlanResponse; 404 (with one
        too, as InterUSS's client reads it) for a plan this USS does not hold."""
        try:
            fid = check_flight_plan_id(flight_plan_id)
        except FlightPlanningError as exc:
            return exc.status, {"message": exc.message}
        with self._lock:
            return self._close(fid, as_upsert=False)

    def _close(self, fid: str, as_upsert: bool) -> tuple:
        R, S = api.PlanningActivityResult, api.FlightPlanStatus
        plan = self.plans.get(fid)
        if plan is None:
            notes = f"flight_plan_id: {fid} is not a flight plan of this USS (never planned, or closed)"
            if as_upsert:
                return 200, _upsert_answer(R.Completed.value, S.Closed.value, notes)
            return 404, {"planning_result": R.Failed.value, "flight_plan_status": S.NotPlanned.value,
                         "notes": notes, "message": notes}
        flight = self.decider.flight(plan.request_id)
        problem = None if flight is None else self.decider.cancel(plan.request_id, self.operator_id,
                                                                   "closed through the flight_planning interface")
        if problem is not None:
            doc = {"planning_result": R.NotSupported.value, "flight_plan_status": _status_of(flight, self.decider.now_s),
                   "notes": problem}
            return 200, (_upsert_answer(doc["planning_result"], doc["flight_plan_status"], problem) if as_upsert else doc)
        del self.plans[fid]
        notes = "cancelled before departure" if flight is not None else "already ended"
        self.log(f"flight plan {fid}: {plan.request_id} closed ({notes})")
        return 200, (_upsert_answer(R.Completed.value, S.Closed.value, notes) if as_upsert else
                     {"planning_result": R.Completed.value, "flight_plan_status": S.Closed.value, "notes": notes})

    # ---- clear area ----------------------------------------------------------------------------
    def clear_area(self, body) -> tuple:
        """POST /clear_area_requests: 200 ClearAreaResponse. Every flight plan of this interface
        whose flight comes within our half-separation of the extent (so that its published
        volumes would meet it) during the extent's window is closed; one already airborne
        cannot be, and ``success`` is then false with the plans named."""
        try:
            parse_body(body, api.ClearAreaRequest)
            rid = _request_id(body)
            with self._lock:
                key = ("clear", rid)
                if key in self._answers:
                    return self._answers[key]
                return self._remember(key, self._clear(body["extent"]))
        except FlightPlanningError as exc:
            return exc.status, {"message": exc.message}

    def _clear(self, extent: dict) -> tuple:
        from uam_planner.constraints import ConstraintSet
        spec = self.ctx.spec
        area = area_prisms([extent], self.network, self.ctx.scenario_start_utc, "extent",
                           spec.horizontal_buffer_m, spec.vertical_buffer_m)
        cset = ConstraintSet(area.prisms, self.network)
        ids = sorted(self.plans)
        flights = [self.decider.flight(self.plans[fid].request_id) for fid in ids]
        held = [(fid, f) for fid, f in zip(ids, flights) if f is not None]
        which, _ = cset.violations([f.trajectory for _, f in held])
        inside = [fid for (fid, _), w in zip(held, which) if w >= 0]
        closed, kept = [], []
        for fid in inside:
            status, doc = self._close(fid, as_upsert=False)
            (closed if doc["planning_result"] == api.PlanningActivityResult.Completed.value else kept).append(
                (fid, doc.get("notes", "")))
        for fid, f in zip(ids, flights):   # plans whose flights ended: nothing left to clear
            if f is None and fid in self.plans:
                del self.plans[fid]
        message = (f"{len(closed)} flight plan(s) in the area closed" +
                   (f"; {len(kept)} could not be: " + "; ".join(f"{fid}: {why}" for fid, why in kept) if kept else ""))
        self.log(f"clear area: {message}")
        outcome = {"success": not kept, "message": message,
                   "details": {"closed": [fid for fid, _ in closed], "not_closed": [fid for fid, _ in kept]}}
        return 200, {"outcome": outcome}


__all__ = ["API_NAME", "API_VERSION", "Area", "Decision", "FlightPlanning", "FlightPlanningError",
           "InProcessDecider", "PREFIX", "SCOPES", "SCOPE_DIRECT", "SCOPE_PLAN", "SERVED", "Translation",
           "area_prisms", "check_flight_plan_id", "flight_request", "nearest_aerodrome", "parse_body", "route"]
