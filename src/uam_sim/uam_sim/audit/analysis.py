"""Analysis of a recorded run: the run's summary and an independent safety audit.

``python -m uam_sim.analysis run.mcap`` (installed as ``ros2 run uam_sim analyze run.mcap``)
prints the summary; ``--json`` prints :class:`RunSummary` as JSON instead.

What it reads (topics as the node graph publishes them):

- ``/uam/requests`` (FlightRequest): the requests, counted once per ``operator_id/request_id``
  (:func:`request_key`, the key the simulator names its vehicles by);
- ``/uam/flight_plans`` (FlightPlan): every distinct decision (approved / rejected / expired),
  whatever its id: an id decided more than one way is flagged, and every approved plan is
  audited; the approved plans' waypoints are the flights as flown (the simulator moves each
  vehicle along its plan's piecewise-linear 4D trajectory);
- ``/uam/fleet_state`` (FleetState): airborne vehicles per step, for the time-average of the
  number of active aircraft and to check that every vehicle flown has an approved plan;
- ``/uam/planning_reports`` (PlanningReport): per-epoch MWIS sizes, selections, solve times.

The safety audit takes the approved plans' waypoints and finds the exact closest point of
approach over the common time of pairs of flights (piecewise-linear in 4D), with
``uam_planner.audit.pair_min_distance`` (a brute-force kernel separate from the planner's
separation code); pairs are visited in order of a bounding-box lower bound so that far-apart
pairs are skipped without changing the result (see :func:`uam_sim.audit.separation.audit_trajectories`).
The audit uses the run's separation model: the sphere of the paper or the cylinder (horizontal
H while vertically closer than V), as recorded in the ``uam_airspace`` metadata record
(:data:`uam_sim.audit.separation.AIRSPACE_METADATA`; recordings without it: the sphere of 100 m), unless
the caller names a model (``--separation``, ``--separation-m``, ``--vertical-separation-m``).

It refuses to call a recording "OK" that lacks plans it should hold (:func:`integrity_problems`:
reports announcing approvals whose plans are missing, vehicles flown without a plan, aircraft
airborne together with no pair checked, conflicting decisions, or the recorder's own check
failing), or whose run did not end as planned (:func:`run_problems`: no end announced by the
simulator, an end with an error or before the duration, epochs without a planning report, two
simulators or an unbound planner announcing, plans of epochs no report of the run holds, which
are listed as forged and not audited, approvals never flown, the recorder's check or the run's
airspace record missing, a file recovered after a crash): the verdict is then NOT VERIFIED and
the command exits 3.

Two decoders: ``reader="rclpy"`` (mcap's reader + ``rclpy.serialization``; tolerates a file cut
short by a crash) and ``reader="rosbags"`` (the independent ``rosbags`` library, types built from
the definitions embedded in the file; needs a complete file). The summary code only reads fields,
so both must give the same summary.

The audit itself is :mod:`uam_sim.audit.separation`; decoding is :func:`uam_sim.recording.mcap_reader.iter_decoded`;
the recorded MWIS instances are :mod:`uam_sim.recording.recorded_instances`.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import re
import sys
from dataclasses import asdict, dataclass, field
from pathlib import Path
from typing import Any, Iterable

import numpy as np

from uam_contract.defaults import SEPARATION_M

from .separation import AIRSPACE_METADATA, SafetyAudit, audit_plans, separation_from_metadata
from ..world.flights import run_metrics, shortest_route_lengths_m
from ..recording.mcap_reader import is_complete, iter_decoded, read_metadata, recorded_topics, require_mcap
from ..recording.mcap_recover import RECOVERED_METADATA
from uam_contract.stamps import stamp_s
from uam_contract import names
from uam_contract.names import resolved

#: the MCAP metadata record the recorder node writes with its check of what it received
RECORDER_CHECK = "uam_recorder_check"
#: the run's planning and flight choices as the launcher started the nodes with them (the
#: recorder's ``run_choices`` parameter; values JSON-encoded)
RUN_METADATA = "uam_run"

OUTCOME_APPROVED, OUTCOME_REJECTED, OUTCOME_EXPIRED = 0, 1, 2
OUTCOME_DUPLICATE = 3  # not a decision: a reused (operator_id, request_id) was refused
#: Between operator_id and request_id in a request's key, as the node graph scopes ids (and names
#: vehicles); uam_contract.wire.scoped_id uses the same (a test holds them equal).
SCOPE_SEPARATOR = "/"
# the topics as recordings of the default namespace carry them (uam_contract.names)
TOPIC_REQUESTS = resolved(names.TOPIC_REQUESTS)
TOPIC_PLANS = resolved(names.TOPIC_PLANS)
TOPIC_REPORTS = resolved(names.TOPIC_REPORTS)
TOPIC_FLEET = resolved(names.TOPIC_FLEET)
TOPIC_SYNC = resolved(names.TOPIC_SYNC)
TOPIC_CONSTRAINTS = resolved(names.TOPIC_CONSTRAINTS)
TOPIC_PARAMETER_CHANGES = resolved(names.TOPIC_PARAMETER_CHANGES)
ANALYSED_TOPICS = (TOPIC_REQUESTS, TOPIC_PLANS, TOPIC_REPORTS, TOPIC_FLEET, TOPIC_SYNC, TOPIC_CONSTRAINTS,
                   TOPIC_PARAMETER_CHANGES)



@dataclass
class EpochStats:
    """One planning epoch as reported. Times in seconds (t_s: simulation time)."""

    epoch_index: int
    t_s: float
    eligible_requests: int
    vertices: int
    edges: int
    selected: int
    approved: int
    expired: int
    rejected: int
    active_flights: int
    objective: float
    solve_time_s: float
    backend_used: str
    fallback: bool
    policy: str = ""  # "mwis", "fifo" or "firstfit": only mwis epochs solve an MWIS


@dataclass
class RunSummary:
    """A run's numbers; ``to_json()`` / ``asdict`` give plain JSON types."""

    path: str
    reader: str
    complete_file: bool
    sim_start_s: float
    sim_end_s: float
    requests: int
    approved: int
    rejected: int
    expired: int
    undecided: int                   # requests without any plan in the recording
    duplicate_decisions: int         # plans beyond the first for a request (identical repeats included)
    plans_without_request: int       # request ids with a plan but no request in the recording
    average_active_aircraft: float   # time-average of airborne vehicles over the fleet states
    max_active_aircraft: int
    fleet_steps: int
    epochs: list = field(default_factory=list)        # EpochStats
    mwis_vertices: dict = field(default_factory=dict)  # min/median/max over epochs with an instance
    mwis_selected: dict = field(default_factory=dict)
    solve_time_s: dict = field(default_factory=dict)
    fallbacks: int = 0
    rejection_reasons: dict = field(default_factory=dict)  # reason (numbers as N) -> count
    audit: SafetyAudit | None = None
    #: request id -> its distinct decisions in order ("approved", "rejected", "expired"), for every
    #: id decided more than one way (a re-sent or forged id); every approved plan is audited
    conflicting_decisions: dict = field(default_factory=dict)
    #: why the recording cannot be trusted to hold the whole run (then the audit is not "OK")
    problems: list = field(default_factory=list)
    #: what the recorder itself found (its ``uam_recorder_check`` metadata), {} if none
    recorder_check: dict = field(default_factory=dict)
    #: the run's choices as launched (``uam_run`` metadata: objective, priority share, horizon,
    #: lead time, buffers, reaction, probe, disturbances), {} if the recording has none
    run_choices: dict = field(default_factory=dict)
    #: requests refused as reusing a taken (operator_id, request_id): OUTCOME_DUPLICATE answers,
    #: which are not decisions (the earlier request's decision stands)
    duplicate_requests_refused: int = 0
    #: approved plans of epochs that no planning report of the run holds: not audited as flown
    forged_plans: list = field(default_factory=list)
    #: how the run ended, as the simulator announced it ("" when no end is recorded)
    run_end: str = ""
    #: rejection reason as in ``rejection_reasons`` -> [min, max] of the number each N stands for
    rejection_values: dict = field(default_factory=dict)
    #: the approved flights as the experiment's flights table has them (uam_sim.world.flights): request,
    #: operator, route, length_m, weight, candidate_index, earliest_departure_s, departure_s, ...
    #: (shortest_length_m when the network is known)
    flights: list = field(default_factory=list)
    #: uam_sim.world.flights.run_metrics of the flights and requests, as the in-process runner's
    #: summary has them: delay mean/p95/delayed share from the earliest departure, per-priority
    #: p95 delay, detour (in m when the network is given), per-operator approval share and Jain
    #: index; requests still within their window at the end are left out ({} if none)
    flight_stats: dict = field(default_factory=dict)
    #: the same per operator_id, when more than one operator had a flight approved
    flight_stats_by_operator: dict = field(default_factory=dict)

    @property
    def decision_metrics(self) -> dict:
        """The runner's decision metrics: ``flight_stats`` (one implementation, one set)."""
        return self.flight_stats

    #: plan versions after the approval (version >= 2): update kind -> count ("rerouted", ...)
    plan_updates: dict = field(default_factory=dict)
    #: entries of flown trajectories into constraints in force (uam_sim.audit.flown_audit.Incursion.describe)
    incursions: list = field(default_factory=list)
    #: entries into a constraint version after the authority announced it and before the planner
    #: applied it (at its next epoch): no plan could avoid them; reported apart
    incursions_before_applied: list = field(default_factory=list)
    #: constraint versions the planner had in force during the run (from uam/constraints)
    constraints_in_force: int = 0
    #: who changed the airspace and when: each constraint version in force (its author, when
    #: announced, in force from .. until) and each withdrawal (who, when asked, when applied)
    airspace_changes: list = field(default_factory=list)
    #: constraint sets on uam/constraints that no planning report names (not the planner's):
    #: left out of the audit
    forged_constraint_sets: list = field(default_factory=list)
    #: every parameter change a node accepted while the run went on (uam/parameter_changes)
    parameter_changes: list = field(default_factory=list)
    #: priority class -> (approved, requested), over every request of the recording
    approvals_by_class: dict = field(default_factory=dict)
    #: the audit of what flew (uam_sim.audit.flown.recording_flown): the fleet states' tracks,
    #: their exact closest approach in the true minimum with the sampling bound, and their F3548
    #: conformance with the approved plans ({} when no fleet positions were recorded)
    flown: dict = field(default_factory=dict)
    #: pairs closer than the minimum where at least one plan in force is a contingency (F3548
    #: Contingent: not deconflicted by design): [label a, label b, distance m, t s, inside the
    #: run (t <= the last fleet state)]; reported, not a loss between deconflicted plans
    contingency_conflicts: list = field(default_factory=list)

    @property
    def verified(self) -> bool:
        """True when the recording holds every plan it should (no entry in ``problems``)."""
        return not self.problems

    def to_dict(self) -> dict:
        d = asdict(self)
        if self.audit is not None:
            d["audit"]["ok"] = self.audit.ok
        d["verified"] = self.verified
        return _jsonable(d)

    def to_json(self, **kw: Any) -> str:
        return json.dumps(self.to_dict(), **kw)


def _jsonable(x: Any) -> Any:
    if isinstance(x, dict):
        return {str(k): _jsonable(v) for k, v in x.items()}
    if isinstance(x, (list, tuple)):
        return [_jsonable(v) for v in x]
    if isinstance(x, float) and not math.isfinite(x):
        return None  # JSON has no inf/nan: null means "none" (e.g. no pair ever airborne together)
    if isinstance(x, np.generic):
        return _jsonable(x.item())
    return x


_REASON_NUMBER = re.compile(r"(?<![\w'.])\d+(?:\.\d+)?(?![\w'])")


def _stats(values: list[float]) -> dict:
    if not values:
        return {"count": 0, "min": None, "median": None, "max": None, "mean": None}
    a = np.asarray(values, dtype=np.float64)
    return {"count": int(a.size), "min": float(a.min()), "median": float(np.median(a)),
            "max": float(a.max()), "mean": float(a.mean())}


# --------------------------------------------------------------------------------------------
# Summary
# --------------------------------------------------------------------------------------------

_OUTCOME_NAMES = {OUTCOME_APPROVED: "approved", OUTCOME_REJECTED: "rejected", OUTCOME_EXPIRED: "expired"}


def request_key(msg: Any) -> str:
    """A request's or plan's key: ``operator_id/request_id`` (ids are unique per operator), or the
    bare request_id for messages without an operator (recordings made before operators)."""
    operator = str(getattr(msg, "operator_id", "") or "")
    return f"{operator}{SCOPE_SEPARATOR}{msg.request_id}" if operator else str(msg.request_id)


def _plan_key(p: Any) -> tuple:
    """What makes two plan messages the same decision (a latched plan delivered twice)."""
    return (request_key(p), int(p.outcome), str(p.reason), int(p.epoch_index),
            tuple((stamp_s(w.time), float(w.position.x), float(w.position.y), float(w.position.z))
                  for w in p.waypoints))


def _vehicle_ids(msg: Any) -> list:
    ids = getattr(msg, "vehicle_ids", None)  # a digest read from the CDR (uam_sim.recording.cdr)
    return list(ids) if ids is not None else [str(v.vehicle_id) for v in msg.vehicles]


def _few(ids, n: int = 5) -> str:
    ids = sorted(ids)
    return ", ".join(repr(i) for i in ids[:n]) + (f" and {len(ids) - n} more" if len(ids) > n else "")


def missing_steps(step_indices, first: int = 10) -> tuple[int, list[int]]:
    """How many step indices are missing between the first and the last of ``step_indices``, and
    the first ``first`` of them (fleet states are published at every step, 0, 1, 2, ...; a
    recording may start late or end early, but a gap means states were lost on the way). The
    indices are uint64 from the wire: a forged one far ahead is counted, never listed."""
    steps = np.unique(np.asarray(list(step_indices), dtype=np.uint64))
    if steps.size < 2:
        return 0, []
    gap = np.diff(steps) - np.uint64(1)
    at = np.flatnonzero(gap > 0)
    listed: list[int] = []
    for g in at[:first]:
        listed += range(int(steps[g]) + 1, int(steps[g]) + 1 + min(int(gap[g]), first - len(listed)))
    return sum(int(gap[g]) for g in at), listed[:first]


def format_steps(count: int, listed: list[int]) -> str:
    """The listed missing steps, "..." when there are more (for :func:`missing_steps`)."""
    return ", ".join(map(str, listed)) + (" ..." if count > len(listed) else "")


def integrity_problems(epochs: list, approved: list, flown_ids: set, max_active: int,
                       audit: SafetyAudit | None, conflicting: dict, fleet_steps=()) -> list[str]:
    """Why a recording cannot be trusted to hold the whole run (empty when it can).

    ``approved``: (request id, epoch index) of every approved plan held. Checks: ids decided more
    than one way; the planning reports' announced approvals against the approved plans held,
    epoch by epoch; vehicles in the fleet states with no approved plan; flights that
    flew together while the audit checked no pair; fleet states missing between the first and the
    last held (``fleet_steps``: their step indices).
    """
    problems = []
    if conflicting:
        problems.append(f"{len(conflicting)} request id(s) have conflicting decisions ({_few(conflicting)}); "
                        "every approved plan is audited")
    announced = sum(e.approved for e in epochs)
    if epochs and announced != len(approved):
        per_epoch: dict[int, list] = {}
        for rid, epoch in approved:
            per_epoch.setdefault(epoch, []).append(rid)
        reported = {e.epoch_index: e.approved for e in epochs}
        detail = [f"epoch {k}: {reported.get(k, 0)} announced, {len(per_epoch.get(k, []))} held"
                  + (f" ({_few(per_epoch[k])})" if per_epoch.get(k) else "")
                  for k in sorted(set(reported) | set(per_epoch))
                  if reported.get(k, 0) != len(per_epoch.get(k, []))]
        problems.append(f"planning reports announce {announced} approvals but the recording holds "
                        f"{len(approved)} approved plans ({'; '.join(detail[:5])})")
    unplanned = flown_ids - {rid for rid, _epoch in approved}
    if unplanned:
        problems.append(f"{len(unplanned)} vehicle(s) in the fleet states have no approved plan in the "
                        f"recording: {_few(unplanned)}")
    if audit is not None and max_active >= 2 and audit.pairs_checked == 0:
        problems.append(f"the fleet states show {max_active} aircraft airborne together, but 0 pairs "
                        "of approved plans were checked")
    lost, listed = missing_steps(fleet_steps)
    if lost:
        problems.append(f"{lost} fleet state(s) are missing between the first and the last held "
                        f"(steps {format_steps(lost, listed)}): lost on the way to the recorder")
    return problems


def run_problems(syncs: list, reports: dict, approved: list, flown_ids: set, fleet_end_s: float) -> tuple[list, list, str]:
    """Whether the recorded run ended as planned: (problems, forged plan keys, how it ended).

    ``syncs``: the EpochSync announcements; ``reports``: epoch index -> the distinct planning
    reports of that epoch (their approved counts); ``approved``: (key, epoch index, departure s)
    of every approved plan; ``flown_ids``: vehicles in the fleet states. The run's duration and
    epoch length come from the simulator's announcements; every epoch k with k x epoch_s below
    the duration must have exactly one report; plans of other epochs are forged (not audited);
    approvals that should have departed before the last fleet state must have flown.
    """
    problems: list[str] = []
    sim = [m for m in syncs if str(m.sender) == "simulator"]
    if not sim:
        return (["the simulator's epoch announcements (/uam/epoch_sync) are missing: the run's "
                 "duration and end are unknown"], [], "")
    sessions = sorted({str(getattr(m, "session", "")) for m in sim})
    if len(sessions) > 1:
        problems.append(f"{len(sessions)} simulators announced epochs (sessions {_few(sessions)}): "
                        "a second simulator was on the run's domain")
    # the run's simulator: the session that announced the most epochs (a rogue's few
    # announcements, its end among them, are not the run's)
    counts: dict[str, int] = {}
    for m in sim:
        counts[str(getattr(m, "session", ""))] = counts.get(str(getattr(m, "session", "")), 0) + 1
    own = max(sessions, key=lambda x: (counts[x], x == str(getattr(sim[0], "session", ""))))
    sim = [m for m in sim if str(getattr(m, "session", "")) == own]
    duration = max(float(getattr(m, "duration_s", 0.0)) for m in sim)
    epoch_s = max(float(getattr(m, "epoch_s", 0.0)) for m in sim)
    ends = [m for m in sim if m.finished]
    run_end = ""
    if not ends:
        problems.append("the simulator never announced the end of the run: the recording was cut short")
    else:
        end = ends[0]
        t_end = stamp_s(end.epoch_time)
        error = str(getattr(end, "error", ""))
        run_end = f"ended at t = {t_end:g} s" + (f" on an error: {error}" if error else "")
        if error:
            problems.append(f"the run ended early on an error: {error}")
        elif duration > 0 and t_end < duration - 1e-6:
            problems.append(f"the run ended at t = {t_end:g} s, before its duration {duration:g} s")
    planners = {str(getattr(m, "session", "")) for m in syncs if str(m.sender) == "planner"}
    bound = {str(p).partition("=")[2] for m in sim for p in getattr(m, "partners", ())
             if str(p).startswith("planner=")}
    if bound and planners - bound:
        problems.append(f"a planner the simulator was not bound to announced epochs (sessions "
                        f"{_few(planners - bound)}): a second planner was on the run's domain")
    twice = sorted(k for k, rs in reports.items() if len(rs) > 1)
    if twice:
        problems.append(f"{len(twice)} epoch(s) have two different planning reports (epochs {_few(twice)})")
    announced = {int(m.epoch_index) for m in sim if not m.finished}
    forged = []
    if duration > 0 and epoch_s > 0:
        n_epochs = int(math.ceil(duration / epoch_s - 1e-9))
        if ends and not problems:  # ended as planned: every epoch of the run has its report
            unreported = [k for k in range(n_epochs) if k not in reports]
            if unreported:
                problems.append(f"{len(unreported)} epoch(s) of the run have no planning report "
                                f"(epochs {format_steps(len(unreported), unreported[:10])})")
        beyond = sorted(k for k in reports if k >= n_epochs or k not in announced)
        if beyond:
            problems.append(f"planning reports for epochs the simulator never asked for ({_few(beyond)}): forged")
        forged = sorted(key for key, k, _dep in approved if k >= n_epochs or k not in reports or k not in announced)
        if forged:
            problems.append(f"{len(forged)} approved plan(s) belong to no planning report of the run "
                            f"({_few(forged)}): listed as forged, not audited as flown")
    never = sorted(key for key, k, dep in approved if key not in flown_ids and dep < fleet_end_s - 1e-6
                   and key not in set(forged))
    if never:
        problems.append(f"{len(never)} approved plan(s) never flew although they depart before the last "
                        f"fleet state ({_few(never)})")
    return problems, forged, run_end


def _epoch_stats(msg) -> EpochStats:
    """One planning report as a row of the epoch table."""
    return EpochStats(
        epoch_index=int(msg.epoch_index), t_s=stamp_s(msg.header.stamp),
        eligible_requests=int(msg.eligible_requests), vertices=int(msg.vertices),
        edges=int(msg.edges), selected=len(msg.instance.selected),
        approved=int(msg.approved), expired=int(msg.expired), rejected=int(msg.rejected),
        active_flights=int(msg.active_flights), objective=float(msg.objective),
        solve_time_s=float(msg.solve_time_s), backend_used=str(msg.backend_used),
        fallback=bool(msg.fallback), policy=str(getattr(msg, "policy", "")))


def _rejection_reasons(plans: list) -> tuple[dict, dict]:
    """The refusals' reasons grouped with their numbers as N (count per group), and each number's
    range per group ("... by 270 s" and "... by 300 s" are one group, 270..300)."""
    reasons: dict[str, int] = {}
    values: dict[str, list] = {}
    for p in plans:
        if int(p.outcome) != OUTCOME_APPROVED:
            key = _REASON_NUMBER.sub("N", str(p.reason))
            reasons[key] = reasons.get(key, 0) + 1
            numbers = [float(x) for x in _REASON_NUMBER.findall(str(p.reason))]
            ranges = values.setdefault(key, [[x, x] for x in numbers])
            for r, x in zip(ranges, numbers):
                r[0], r[1] = min(r[0], x), max(r[1], x)
    return reasons, values


@dataclass
class _Stream:
    """What one pass over a run's messages gathers, topic by topic, before any audit: the
    requests, the distinct decisions, the fleet's steps, the planning reports and the constraint
    sets as published (times in seconds of log time)."""
    request_ids: set = field(default_factory=set)
    request_rows: dict = field(default_factory=dict)  # request key -> the first request's times, class, operator
    decisions: dict = field(default_factory=dict)  # request id -> distinct plans, in arrival order
    seen: set = field(default_factory=set)
    duplicates: int = 0
    refused_duplicates: int = 0
    fleet_t: list = field(default_factory=list)
    fleet_n: list = field(default_factory=list)
    fleet_steps: list = field(default_factory=list)
    flown: set = field(default_factory=set)
    epochs: list = field(default_factory=list)
    syncs: list = field(default_factory=list)
    reports: dict = field(default_factory=dict)
    updates: dict = field(default_factory=dict)  # request key -> {plan key: plan} of its versions >= 2
    constraint_sets: list = field(default_factory=list)  # (t_s, [(constraint, effective_s)]) as the planner published them
    constraint_problems: list = field(default_factory=list)
    withdrawals: dict = field(default_factory=dict)  # (id, version) -> the withdrawal as the planner published it
    parameter_changes: list = field(default_factory=list)  # every run-time parameter change a node accepted
    published: list = field(default_factory=list)  # (sha256, log time, set, withdrawals) of each set on uam/constraints
    named_sets: set = field(default_factory=set)  # the sets the planning reports name (the planner's own)
    t_min: float = math.inf
    t_max: float = -math.inf

    def add(self, topic: str, log_ns: int, msg: Any) -> None:
        """Take one message of ``topic`` logged at ``log_ns`` [ns]."""
        if topic == TOPIC_SYNC:  # announcements: not part of the run's time span
            self.syncs.append(msg)
            return
        if topic == TOPIC_PARAMETER_CHANGES:
            self.parameter_changes.append(_parameter_change(msg.data, log_ns * 1e-9))
            return
        if topic == TOPIC_CONSTRAINTS:
            self._add_constraints(log_ns, msg)
            return
        self.t_min, self.t_max = min(self.t_min, log_ns * 1e-9), max(self.t_max, log_ns * 1e-9)
        if topic == TOPIC_REQUESTS:
            key = request_key(msg)
            self.request_ids.add(key)
            self.request_rows.setdefault(key, {
                "earliest_departure_s": stamp_s(msg.earliest_departure),
                "latest_departure_s": stamp_s(msg.latest_departure),
                "priority": int(getattr(msg, "priority", 0)),  # recordings without priorities: 0
                "operator": str(getattr(msg, "operator_id", "") or "")})
        elif topic == TOPIC_PLANS:
            self._add_plan(msg)
        elif topic == TOPIC_FLEET:
            ids = _vehicle_ids(msg)
            self.fleet_t.append(stamp_s(msg.header.stamp))
            self.fleet_n.append(len(ids))
            self.fleet_steps.append(int(msg.step_index))
            self.flown.update(ids)
        elif topic == TOPIC_REPORTS:
            self._add_report(msg)

    def decided(self) -> tuple[list, list, dict, list]:
        """Every distinct plan decided, their outcomes, the ids decided more than one way (each
        with its outcomes' names) and the approvals as (request key, plan)."""
        plans = [p for ps in self.decisions.values() for p in ps]
        outcomes = [int(p.outcome) for p in plans]
        conflicting = {rid: [_OUTCOME_NAMES.get(int(p.outcome), str(int(p.outcome))) for p in ps]
                       for rid, ps in self.decisions.items() if len(ps) > 1}
        all_approved = [(rid, p) for rid, ps in self.decisions.items() for p in ps
                        if int(p.outcome) == OUTCOME_APPROVED]
        return plans, outcomes, conflicting, all_approved

    def _add_constraints(self, log_ns: int, msg: Any) -> None:
        """A constraint set as published on the constraints topic, with its SHA-256; one that
        cannot be read is a problem of the run."""
        from uam_planner.live_constraints import constraints_from_text, withdrawals_from_text
        digest = hashlib.sha256(msg.data.encode("utf-8")).hexdigest()
        try:
            self.published.append((digest, log_ns * 1e-9, constraints_from_text(msg.data),
                                   withdrawals_from_text(msg.data)))
        except ValueError as exc:
            self.constraint_problems.append(f"a constraint set on {TOPIC_CONSTRAINTS} cannot be read: {exc}")

    def _add_plan(self, msg: Any) -> None:
        """A plan: a refused duplicate is counted, a later version kept apart as an update, and a
        first decision kept once per distinct plan."""
        if int(msg.outcome) == OUTCOME_DUPLICATE:
            self.refused_duplicates += 1
            return
        rid = request_key(msg)
        if int(getattr(msg, "version", 0) or 0) > 1:  # a new version of an approved plan
            self.updates.setdefault(rid, {})[(int(msg.version),) + _plan_key(msg)] = msg
            return
        if rid in self.decisions:
            self.duplicates += 1
        key = _plan_key(msg)
        if key not in self.seen:
            self.seen.add(key)
            self.decisions.setdefault(rid, []).append(msg)

    def _add_report(self, msg: Any) -> None:
        """A planning report: the constraint sets it names, and its epoch's row (once per epoch)."""
        self.named_sets.update(str(getattr(msg, "constraint_set_sha256", "") or "").split())
        self.reports.setdefault(int(msg.epoch_index), set()).add(
            (int(msg.approved), int(msg.expired), int(msg.eligible_requests), int(msg.vertices)))
        if len(self.reports[int(msg.epoch_index)]) > 1 or any(e.epoch_index == int(msg.epoch_index)
                                                              for e in self.epochs):
            return  # a repeat (or a second report) of an epoch counts once in the table
        self.epochs.append(_epoch_stats(msg))


def _average_active(fleet_t: list, fleet_n: list) -> float:
    """The time-averaged number of aircraft in the air over the fleet's steps (times ``fleet_t``
    [s], counts ``fleet_n``); 0.0 without a step."""
    avg_active = 0.0
    if fleet_t:
        order = np.argsort(fleet_t, kind="stable")
        t = np.asarray(fleet_t)[order]
        n = np.asarray(fleet_n, dtype=np.float64)[order]
        if len(t) > 1 and t[-1] > t[0]:
            # each step's count holds until the next step (sample-and-hold time average)
            avg_active = float(np.sum(n[:-1] * np.diff(t)) / (t[-1] - t[0]))
        else:
            avg_active = float(n.mean())
    return avg_active


def _flight_rows(record, request_rows: dict, network) -> tuple[list, list, list]:
    """The approved plans of the run's ``record`` (each flight's first version), their labels and
    their flight rows; given the ``network``, each row's shortest route length [m]."""
    approved_plans = [f.versions[0] for f in record.flights]
    labels = [f.key for f in record.flights]
    flights = [_flight_row(p, label, request_rows.get(request_key(p)))
               for p, label in zip(approved_plans, labels)]
    if network is not None:  # the detour in metres, as the runner measures it
        shortest = shortest_route_lengths_m(network, [(f["origin"], f["destination"]) for f in flights])
        for f in flights:
            f["shortest_length_m"] = shortest.get((f["origin"], f["destination"]))
    return approved_plans, labels, flights


def _epochs_end_s(epochs: list) -> float | None:
    """The run's end as the epochs show it [s]: the last epoch's time + the epoch length (the
    median step between epochs); None with fewer than two epochs."""
    ts = sorted({e.t_s for e in epochs})
    return ts[-1] + float(np.median(np.diff(ts))) if len(ts) > 1 else None


def _metrics_by_operator(flights: list, requests: list, end_s: float | None) -> dict:
    """The flight metrics per operator, when more than one operator flew; else {}."""
    by_operator = {}
    if len({f["operator_id"] for f in flights}) > 1:
        for op in sorted({f["operator_id"] for f in flights}):
            by_operator[op] = run_metrics([f for f in flights if f["operator_id"] == op],
                                          [r for r in requests if r["operator"] == op], end_s=end_s)
    return by_operator


def _run_record(s: _Stream, all_approved: list, fleet_end: float) -> tuple:
    """The run's record from the approvals ``all_approved`` ((request key, plan)) and their
    updates: (every approval's record, the record without the forged ones, the run's problems,
    the forged plans, the run's end as ``run_problems`` reads it); ``fleet_end`` [s]: the last
    fleet state's time."""
    from .record import RunRecord
    everything = RunRecord.from_plans(all_approved, s.updates, s.constraint_sets)
    flown_by_key = everything.by_key()
    run, forged, run_end = run_problems(
        s.syncs, s.reports, [(rid, int(p.epoch_index), _departure_flown(rid, p, flown_by_key))
                             for rid, p in all_approved], s.flown, fleet_end)
    # the record of the run: every approval but the forged ones, each flight's versions in force
    record = everything.without(forged)
    return everything, record, run, forged, run_end


def _audit_record(record, approved_plans: list, labels: list, separation_m) -> tuple:
    """The separation audit of the plans in force and the conflicts involving a contingency
    ([label a, label b, distance m, t s]): of each flight's versions when a plan was updated,
    else of the approved plans as they are (the paper's runs)."""
    if record.updated:
        return record.audit_plans(separation_m)
    return audit_plans(approved_plans, separation_m, labels=labels), []


def summarize_messages(messages: Iterable[tuple[str, int, Any]], separation_m=SEPARATION_M,
                       path: str = "", reader: str = "", complete_file: bool = True,
                       network=None) -> RunSummary:
    """The summary of a stream of (topic, log_time_ns, message), e.g. from :func:`iter_decoded`.

    Every distinct plan counts, whatever its id: identical repeats (a latched plan delivered
    twice) are counted once; an id decided more than one way is listed in
    ``conflicting_decisions`` and each of its approved plans is audited (labelled ``id#2``, ...).
    ``separation_m``: the audit's separation model (a number: the sphere; or a SeparationModel).
    Complexity: linear in the messages, plus the audit (quadratic in overlapping flights).
    """
    s = _Stream()
    for topic, log_ns, msg in messages:
        s.add(topic, log_ns, msg)
    forged_sets = _planners_sets(s.published, s.named_sets, s.constraint_sets, s.withdrawals,
                                 s.constraint_problems)
    plans, outcomes, conflicting, all_approved = s.decided()
    fleet_end = max(s.fleet_t) if s.fleet_t else -math.inf
    everything, record, run, forged, run_end = _run_record(s, all_approved, fleet_end)
    reasons, values = _rejection_reasons(plans)
    approved_plans, labels, flights = _flight_rows(record, s.request_rows, network)
    avg_active = _average_active(s.fleet_t, s.fleet_n)
    # a FIFO or first-fit epoch reports its graph but solves no MWIS: its selection is not one
    with_instance = [e for e in s.epochs if e.vertices > 0 and e.policy in ("", "mwis")]
    max_active = int(max(s.fleet_n)) if s.fleet_n else 0
    audit, contingency_conflicts = _audit_record(record, approved_plans, labels, separation_m)
    found_incursions, gap_incursions = record.incursions(network)
    # requests still within their window at the run's end are left out, as in the runner
    end_s = _epochs_end_s(s.epochs)
    requests = list(s.request_rows.values())
    by_operator = _metrics_by_operator(flights, requests, end_s)
    summary = RunSummary(
        path=str(path), reader=reader, complete_file=complete_file,
        sim_start_s=s.t_min if math.isfinite(s.t_min) else 0.0,
        sim_end_s=s.t_max if math.isfinite(s.t_max) else 0.0,
        requests=len(s.request_ids),
        approved=outcomes.count(OUTCOME_APPROVED),
        rejected=outcomes.count(OUTCOME_REJECTED),
        expired=outcomes.count(OUTCOME_EXPIRED),
        undecided=len(s.request_ids - set(s.decisions)),
        duplicate_decisions=s.duplicates,
        plans_without_request=len(set(s.decisions) - s.request_ids),
        average_active_aircraft=avg_active,
        max_active_aircraft=max_active,
        fleet_steps=len(s.fleet_t),
        epochs=sorted(s.epochs, key=lambda e: e.epoch_index),
        mwis_vertices=_stats([e.vertices for e in with_instance]),
        mwis_selected=_stats([e.selected for e in with_instance]),
        solve_time_s=_stats([e.solve_time_s for e in with_instance]),
        fallbacks=sum(e.fallback for e in s.epochs),
        rejection_reasons=reasons,
        rejection_values=values,
        flights=flights,
        flight_stats=run_metrics(flights, requests, end_s=end_s),
        flight_stats_by_operator=by_operator,
        audit=audit,
        conflicting_decisions=conflicting,
        duplicate_requests_refused=s.refused_duplicates,
        problems=integrity_problems(s.epochs, [(request_key(p), int(p.epoch_index)) for p in approved_plans],
                                    s.flown, max_active, audit, conflicting, s.fleet_steps) + run
        + s.constraint_problems + everything.problems,
        forged_plans=forged,
        run_end=run_end,
        plan_updates=_update_counts(s.updates),
        incursions=[i.describe() for i in found_incursions],
        incursions_before_applied=[i.describe() for i in gap_incursions],
        contingency_conflicts=[[a, b, d, w, bool(w <= fleet_end)] for a, b, d, w in contingency_conflicts],
        constraints_in_force=len(record.applied),
        airspace_changes=_airspace_changes(record.applied, s.withdrawals.values()),
        forged_constraint_sets=forged_sets,
        parameter_changes=s.parameter_changes,
        approvals_by_class=_approvals_by_class(s.request_rows, flights),
    )
    # the run's record (uam_sim.audit.record): what the flown audit reads; not part of the JSON
    summary.record = record
    # the SHA-256 of the constraint sets taken as the planner's (what a view of the recording draws)
    summary.constraint_sets_taken = {d for d, *_ in s.published if not s.named_sets or d in s.named_sets}
    return summary


def _planners_sets(published, named_sets, constraint_sets: list, withdrawals: dict, problems: list) -> list:
    """Of the sets on uam/constraints, those the planning reports name (the planner's) go into
    ``constraint_sets`` (and their withdrawals into ``withdrawals``); the others are forged: left
    out of the audit, listed (returned) and a problem of the record. Recordings made before the
    reports named their sets take every set."""
    forged = [f"t = {t:g} s (set time {cs[0]:g} s, sha256 {d[:12]})" for d, t, cs, _w in published
              if named_sets and d not in named_sets]
    if forged:
        problems.append(f"{len(forged)} constraint set(s) on {TOPIC_CONSTRAINTS} named by no planning report "
                        f"({'; '.join(forged[:3])}): not the planner's, listed as forged, not audited")
    for d, _t, cs, ws in published:
        if not named_sets or d in named_sets:
            constraint_sets.append(cs)
            for w in ws:
                withdrawals.setdefault((str(w.get("id")), w.get("version")), w)
    return forged


def _approvals_by_class(request_rows: dict, flights: list) -> dict:
    """priority class -> (approved, requested): each request's class from its request, an
    approval counted once per request."""
    asked: dict = {}
    for row in request_rows.values():
        c = int(row.get("priority", 0))
        asked[c] = asked.get(c, 0) + 1
    got: dict = {}
    for f in flights:
        if "#" in str(f.get("request_id", "")):
            continue   # a second approval of one request (reported as conflicting) counts once
        c = int(f.get("priority", 0))
        got[c] = got.get(c, 0) + 1
    return {c: (got.get(c, 0), asked.get(c, 0)) for c in sorted(set(asked) | set(got))}


def _parameter_change(text: str, t_s: float) -> str:
    """One accepted parameter change as the summary names it."""
    try:
        d = json.loads(text)
        return f"t = {t_s:g} s: {d['node']} {d['parameter']} = {d['value']!r}"
    except (ValueError, KeyError, TypeError):
        return f"t = {t_s:g} s: unreadable ({text[:80]!r})"


def _airspace_changes(applied, withdrawals) -> list[str]:
    """Who changed the airspace and when, one line per constraint version in force and per
    withdrawal, in time order."""
    def t(x):
        return "start" if x == -math.inf else ("end" if x == math.inf else f"{x:g} s")
    rows = []
    for c, since, until in applied:
        ann = getattr(c, "announce_s", -math.inf)
        rows.append((since, f"{c.constraint_id} v{c.version} by {getattr(c, 'author', '') or 'the start set'}: "
                            + (f"announced {t(ann)}, " if math.isfinite(ann) else "")
                            + f"in force {t(since)} .. {t(until)}"))
    for w in withdrawals:
        when = float(w.get("applied_s", math.nan))
        rows.append((when, f"{w.get('id')} v{w.get('version')} withdrawn by {w.get('by') or '?'}: asked "
                           f"{t(float(w.get('t_s', math.nan)))}, applied {t(when)}"))
    return [text for _k, text in sorted(rows, key=lambda r: (r[0], r[1]))]


def _departure_flown(key: str, plan: Any, flights: dict) -> float:
    """When a flight departs as flown: its plan's first waypoint, or its path in force's when it
    has later versions (inf when a cancellation left nothing flown). ``flights``: label ->
    ``uam_sim.audit.record.FlightRecord``."""
    f = flights.get(key)
    if f is not None and f.updated:
        return float(f.flown.times_s[0]) if len(f.flown.times_s) >= 2 else math.inf
    return stamp_s(plan.waypoints[0].time) if plan.waypoints else 0.0


def _update_counts(updates: dict) -> dict:
    counts: dict[str, int] = {}
    for versions in updates.values():
        seen = {}
        for p in versions.values():
            seen[int(p.version)] = str(getattr(p, "update_kind", "") or "update")
        for kind in seen.values():
            counts[kind] = counts.get(kind, 0) + 1
    return dict(sorted(counts.items()))


def _flight_row(plan: Any, label: str, request: dict | None) -> dict:
    """An approved plan as a row of the experiment's flights table (what uam_sim.world.flights reads),
    with its request's window, class and operator (None: a plan without its request)."""
    r = request or {}
    return {"request_id": label, "operator_id": str(plan.operator_id), "operator": str(plan.operator_id),
            "origin": str(plan.origin_id),
            "destination": str(plan.destination_id), "epoch": int(plan.epoch_index),
            "earliest_departure_s": r.get("earliest_departure_s"),
            "latest_departure_s": r.get("latest_departure_s"), "priority": int(r.get("priority", 0)),
            "departure_s": stamp_s(plan.departure_time), "arrival_s": stamp_s(plan.arrival_time),
            "length_m": float(plan.length_m), "weight": float(plan.weight),
            "candidate_index": int(plan.candidate_index), "route": " ".join(plan.route_node_ids)}


def summarize(path: str | Path, separation_m=None, reader: str = "rclpy",
              default_separation=SEPARATION_M, network=None, flown: bool = True) -> RunSummary:
    """Read a recording and return its :class:`RunSummary` (see the module docstring).

    ``separation_m``: the audit's model (number = sphere, or a SeparationModel); None = the
    run's own, from the recording's ``uam_airspace`` metadata, else ``default_separation``.
    ``network``: the run's network (a Network or a network file), for the flights' detour in
    metres over the shortest route, as the runner measures it (None: no detour in metres).
    ``flown``: False leaves out the audit of what flew (``summary.flown`` stays {}): for the
    readers that need only the run's record (the F3548 export, the view of a recording).
    """
    path = Path(path)
    if not path.is_file():
        raise FileNotFoundError(f"recording: no file at {path}")
    require_mcap(path)
    airspace = read_metadata(path, AIRSPACE_METADATA)
    given = separation_m is not None
    if separation_m is None:
        separation_m = separation_from_metadata(airspace, default_separation)
    recovered = read_metadata(path, RECOVERED_METADATA)
    complete = is_complete(path) and not recovered
    if isinstance(network, (str, Path)):
        from uam_planner.network import load_network
        network = load_network(Path(network))
    summary = summarize_messages(iter_decoded(path, reader, ANALYSED_TOPICS, fleet_digest_only=True),
                                 separation_m, str(path), reader, complete, network=network)
    summary.recorder_check = read_metadata(path, RECORDER_CHECK)
    summary.run_choices = _decoded(read_metadata(path, RUN_METADATA))
    from .flown import recording_flown
    if flown:
        summary.flown = recording_flown(path, separation_m, record=getattr(summary, "record", None))
    if summary.recorder_check.get("ok") == "false":
        summary.problems.append(f"the recorder found: {summary.recorder_check.get('verdict', '?')}")
    if recovered:
        summary.problems.append(f"the file was rebuilt from a recording cut short ({recovered.get('source', '?')}): "
                                "the end of the run is not in it")
    elif not summary.recorder_check:
        summary.problems.append("the recorder's check (metadata uam_recorder_check) is missing: the recorder "
                                "did not close this file")
    if not airspace:
        summary.problems.append("the run's airspace record (metadata uam_airspace) is missing: the separation "
                                "model the run planned with is unknown"
                                + (" (audited with the model given)" if given else
                                   f" (audited with {default_separation!r})"))
    return summary


# --------------------------------------------------------------------------------------------
# Command line
# --------------------------------------------------------------------------------------------

def _fmt_stats(s: dict, unit: str = "", scale: float = 1.0, digits: int = 1) -> str:
    if not s.get("count"):
        return "-"
    f = f"{{:.{digits}f}}"
    return (f"min {f.format(s['min'] * scale)}{unit}, median {f.format(s['median'] * scale)}{unit}, "
            f"max {f.format(s['max'] * scale)}{unit} over {s['count']} epochs")


def _reason_with_values(reason: str, ranges) -> str:
    """A grouped reason with each N replaced by its value, or by the range of its values."""
    if not ranges:
        return reason
    parts = iter(f"{lo:g}" if lo == hi else f"{lo:g}..{hi:g}" for lo, hi in ranges)
    return re.sub(r"(?<![\w'.])N(?![\w'])", lambda m: next(parts, "N"), reason)


def _flight_lines(whose: str, stats: dict) -> list[str]:
    """Departure delay and route detour of the approved flights (uam_sim.world.flights.run_metrics):
    one delay row (mean, p95, per priority class, delayed share: one set of flights)."""
    if not stats or not stats.get("flights"):
        return []
    delay, detour, detour_m = stats["delay_mean_s"], stats["detour_mean_pct"], stats["detour_mean_m"]
    if math.isnan(delay):
        delay_line = f"Departure delay{whose}  - (no request with its earliest departure recorded)"
    else:
        classes = "".join(f", p95 class {k[len('delay_p95_s_prio'):]} {v:.1f} s" for k, v in stats.items()
                          if k.startswith("delay_p95_s_prio"))
        delay_line = (f"Departure delay{whose}  mean {delay:.1f} s after the earliest departure, p95 "
                      f"{stats['delay_p95_s']:.1f} s{classes}, {100 * stats['delayed_share']:.0f} % of "
                      f"{stats['flights']} flights delayed")
    parts = []
    if not math.isnan(detour_m):
        parts.append(f"mean {detour_m:.0f} m over the shortest route")
    if not math.isnan(detour):
        parts.append(f"mean {detour:.1f} % over the shortest route (from the plans' weights)")
    if parts:
        detour_line = (f"Route detour{whose}     {', '.join(parts)}, "
                       f"{100 * stats['shortest_share']:.0f} % on the best candidate, mean length "
                       f"{stats['route_length_mean_m'] / 1000:.2f} km")
    else:
        detour_line = (f"Route detour{whose}     - (no plan with a weight in (0, 1]; "
                       f"give --network for the detour in metres)")
    return [delay_line, detour_line]


def _decoded(meta: dict) -> dict:
    """Metadata values written as JSON, decoded (a value that is not JSON is kept as text)."""
    out = {}
    for k, v in meta.items():
        try:
            out[k] = json.loads(v)
        except (TypeError, ValueError):
            out[k] = v
    return out


_UNITS = (("_mps", "m/s"), ("_deg", "deg"), ("_s", "s"), ("_m", "m"))


def format_choices(choices: dict) -> str:
    """The run's choices in one line, ``name value unit`` in the order given (the unit from the
    name's suffix: ``lead_time_s`` 300 -> "lead time 300 s")."""
    parts = []
    for k, v in choices.items():
        suffix, unit = next(((s, u) for s, u in _UNITS if k.endswith(s)), ("", ""))
        name = k[: len(k) - len(suffix)].replace("_", " ")
        text = str(v).lower() if isinstance(v, bool) else f"{v:g}" if isinstance(v, float) else str(v)
        parts.append(f"{name} {text}{' ' + unit if unit else ''}")
    return ", ".join(parts)


def _airspace_lines(s: RunSummary) -> list[str]:
    """The summary's lines on the airspace: plan updates, who changed it, incursions as applied
    and between announcement and application."""
    lines: list[str] = []
    if s.plan_updates or s.constraints_in_force:
        kinds = ", ".join(f"{n} {k}" for k, n in s.plan_updates.items()) or "none"
        lines.append(f"Plan updates     {kinds}; {s.constraints_in_force} constraint version(s) in force")
        if s.airspace_changes:
            lines.append("Airspace changes " + "; ".join(s.airspace_changes[:10])
                         + (f"; ... {len(s.airspace_changes) - 10} more" if len(s.airspace_changes) > 10 else ""))
        n_in = sum("unavoidable)" in x for x in s.incursions)
        verdict = "OK: no incursion" if not s.incursions else f"{len(s.incursions)} INCURSION(S)" + \
            (f", {n_in} of them by flights already inside when it came into force (unavoidable)" if n_in else "")
        lines.append(f"Constraint audit {verdict} (every flown version from the instant it took effect)")
        for text in s.incursions[:20]:
            lines.append(f"    {text}")
        if s.incursions_before_applied:
            lines.append(f"Constraint gap   {len(s.incursions_before_applied)} entry(ies) after the authority "
                         "announced a constraint and before the planner applied it (its next epoch)")
            for text in s.incursions_before_applied[:20]:
                lines.append(f"    {text}")
    return lines


def _decision_lines(s: RunSummary) -> list[str]:
    """The recording, its run choices, its time span [s] and the requests by outcome, with the
    duplicates, conflicting decisions and rejection reasons."""
    lines = [
        f"Recording        {s.path}{'' if s.complete_file else '  (INCOMPLETE: cut short, read what was written)'}",
        f"Run choices      {format_choices(s.run_choices)} (as launched)" if s.run_choices else
        "Run choices      not recorded (a recorder without run_choices)",
        f"Simulation time  {s.sim_start_s:.1f} s .. {s.sim_end_s:.1f} s",
        f"Requests         {s.requests}",
        f"  approved       {s.approved}",
        f"  rejected       {s.rejected}",
        f"  expired        {s.expired}",
        f"  undecided      {s.undecided}",
    ]
    if s.duplicate_decisions or s.plans_without_request:
        lines.append(f"  (duplicate decisions {s.duplicate_decisions}, plans without request "
                     f"{s.plans_without_request})")
    if s.duplicate_requests_refused:
        lines.append(f"  (requests refused as reusing a taken id: {s.duplicate_requests_refused})")
    for rid, outs in sorted(s.conflicting_decisions.items())[:20]:
        lines.append(f"    CONFLICTING decisions for {rid!r}: {', '.join(outs)}")
    for reason, n in sorted(s.rejection_reasons.items(), key=lambda kv: -kv[1]):
        lines.append(f"    {n:5d} x {_reason_with_values(reason, s.rejection_values.get(reason)) or '(no reason given)'}")
    return lines


def _fleet_and_flight_lines(s: RunSummary) -> list[str]:
    """The active aircraft, the MWIS instances (vertices, selected, solve time [ms]), the flight
    metrics (overall and per operator), the operators' shares and the approvals per class."""
    lines = [
        f"Active aircraft  average {s.average_active_aircraft:.2f} (time-average over "
        f"{s.fleet_steps} fleet states), max {s.max_active_aircraft}",
    ]
    policies = {e.policy for e in s.epochs}
    if s.epochs and not policies & {"", "mwis"}:
        lines.append(f"MWIS             none solved (policy {', '.join(sorted(policies))})")
    else:
        lines += [f"MWIS vertices    {_fmt_stats(s.mwis_vertices, digits=0)}",
                  f"MWIS selected    {_fmt_stats(s.mwis_selected, digits=0)}",
                  f"Solve time       {_fmt_stats(s.solve_time_s, ' ms', 1e3, 2)}",
                  f"Fallbacks        {s.fallbacks}"]
    lines += _flight_lines("", s.flight_stats)
    for op, stats in s.flight_stats_by_operator.items():
        lines += _flight_lines(f" of {op}", stats)
    shares = ", ".join(f"{k[6:]} {v:.3f}" for k, v in s.flight_stats.items() if k.startswith("share_"))
    if shares:
        lines.append(f"Operators        approved of requested, per operator (requests whose window closed in the run): "
                     f"{shares}; Jain index {s.flight_stats['jain_index']:.3f}")
    if len(s.approvals_by_class) > 1:
        lines.append("Classes          " + "; ".join(
            f"class {c}: {a} of {r} approved" + (f" ({100.0 * a / r:.1f} %)" if r else "")
            for c, (a, r) in sorted(s.approvals_by_class.items())) + " (every request of the recording)")
    return lines


def _planned_audit_lines(s: RunSummary) -> list[str]:
    """The safety audit of the plans (verdict, minimum separation [m], losses) and the conflicts
    of contingency plans, each pair with its distance [m] and time [s]."""
    lines = []
    a = s.audit
    if a is not None:
        pair = f" ({a.closest_pair[0]} / {a.closest_pair[1]})" if a.closest_pair else ""
        dist = "no two flights airborne together" if not math.isfinite(a.min_separation_m) \
            else f"{a.min_separation_m:.1f} m{pair}"
        verdict = (f"LOSS OF SEPARATION in {len(a.losses)} pair(s)" if not a.ok
                   else "OK" if s.verified else "NOT VERIFIED (see the recording checks below)")
        lines.append(f"Safety audit     {verdict}: minimum separation {dist}, required "
                     f"{a.describe_minimum()}, {a.pairs_checked} overlapping pairs checked")
        for rid_a, rid_b, d, t in a.losses[:20]:
            lines.append(f"    {rid_a} / {rid_b}: {d:.1f} m at t = {t:.1f} s")
    if s.contingency_conflicts:
        inside = sum(1 for c in s.contingency_conflicts if c[4])
        lines.append(f"Contingencies    {len(s.contingency_conflicts)} conflict(s) of a contingency plan (F3548 "
                     f"Contingent, not deconflicted by design: what flew is audited below), {inside} of them "
                     f"inside the run, {len(s.contingency_conflicts) - inside} after its end")
        for a_, b_, d, when, within in s.contingency_conflicts[:20]:
            lines.append(f"    {a_} / {b_}: {d:.1f} m at t = {when:.1f} s{'' if within else ' (after the run)'}")
    return lines


def _flown_lines(fl: dict) -> list[str]:
    """The audit of what flew (``RunSummary.flown``): its verdict, minimum [m], losses, unresolved
    pairs and sampling bounds [m], then the F3548 conformance line; [] when it was not run."""
    if not fl:
        return []
    lines = []
    ms = fl["min_separation_m"]
    verdict = flown_verdict(fl)
    exact = (f"{fl.get('pieces_exact', 0):,} of {fl.get('pieces', 0):,} pieces exact (flown straight, "
             f"{fl.get('pieces_straight', 0):,} of them, or on a straight part of their plan)")
    lines.append(f"Flown audit      {verdict} (what flew: the fleet states, samples {fl['sample_step_s']:g} s "
                 f"apart; the audit above is of the plans): minimum " + ("-" if ms is None else f"{ms:.1f} m") + f" (the chords); "
                 f"{fl['losses']} loss(es) proven, {fl.get('unresolved', 0)} pair(s) unresolved; {exact}, "
                 f"elsewhere a sampling bound per pair of at most {fl['sampling_bound_m']:.1f} m horizontal, "
                 f"{fl.get('sampling_bound_v_m', 0.0):.2f} m vertical; "
                 f"{fl.get('samples_off_plan', '-')} sample(s) off their plan as flown")
    for a_, b_, d, t_ in fl.get("loss_pairs", [])[:20]:
        lines.append(f"    loss {a_} / {b_}: {d:.1f} m at t = {t_:.1f} s")
    for a_, b_, d, t_ in fl.get("unresolved_pairs", [])[:20]:
        lines.append(f"    unresolved {a_} / {b_}: chords {d:.1f} m at t = {t_:.1f} s")
    cf = fl["conformance"]
    lines.append(f"Conformance      {conformance_verdict(cf)}: {cf['conformance_percent']:.2f} % of "
                 f"{cf['flight_hours']:.2f} flight hours, {cf['excursions']} excursions "
                 f"({cf['excursions_per_flight_hour']:.2f} per flight hour), longest "
                 f"{cf['longest_excursion_s']:.0f} s (F3548: >= 95 %, <= 18 per hour, <= 10 s)")
    return lines


def _check_lines(s: RunSummary) -> list[str]:
    """The parameters changed while running, the recording's problems, the recorder's check and
    how the run ended."""
    lines = []
    if s.parameter_changes:   # accepted while the run went on: the run was not launched as its header says
        lines.append(f"Parameters       {len(s.parameter_changes)} change(s) while running: "
                     + "; ".join(s.parameter_changes[:10]) + ("; ..." if len(s.parameter_changes) > 10 else ""))
    for problem in s.problems:
        lines.append(f"Recording check  {problem}")
    if s.recorder_check:
        lines.append(f"Recorder check   {s.recorder_check.get('verdict', '')}")
    if s.run_end:
        lines.append(f"Run              {s.run_end}")
    return lines


def _epoch_table(epochs: list) -> list[str]:
    """A blank line and one row per epoch: its time [s], the instance, the decisions and the
    solve time [ms]."""
    lines = [""]
    lines.append(f"{'epoch':>5} {'t [s]':>8} {'elig':>5} {'vert':>5} {'edges':>6} {'sel':>4} "
                 f"{'appr':>5} {'exp':>4} {'active':>6} {'solve [ms]':>10}  backend")
    for e in epochs:
        lines.append(f"{e.epoch_index:5d} {e.t_s:8.1f} {e.eligible_requests:5d} {e.vertices:5d} "
                     f"{e.edges:6d} {e.selected:4d} {e.approved:5d} {e.expired:4d} "
                     f"{e.active_flights:6d} {e.solve_time_s * 1e3:10.2f}  {e.backend_used}"
                     f"{' (fallback)' if e.fallback else ''}")
    return lines


def format_summary(s: RunSummary, epochs: bool = True) -> str:
    """A human-readable report of a RunSummary."""
    lines = _decision_lines(s)
    lines += _fleet_and_flight_lines(s)
    lines += _planned_audit_lines(s)
    lines += _airspace_lines(s)
    lines += _flown_lines(s.flown)  # the audit above is of what was planned; this one of what flew
    lines += _check_lines(s)
    if epochs and s.epochs:
        lines += _epoch_table(s.epochs)
    return "\n".join(lines)


#: ASTM F3548-21's conformance limits: the share of flight time in conformance, excursions per
#: flight hour, and the longest excursion [s]
F3548_CONFORMANCE_PERCENT, F3548_EXCURSIONS_PER_HOUR, F3548_LONGEST_EXCURSION_S = 95.0, 18.0, 10.0


def conformance_verdict(cf: dict) -> str:
    """Whether the run's conformance statistics meet F3548's limits, naming the ones missed."""
    missed = [name for name, bad in (
        (f"{cf['conformance_percent']:.2f} % < {F3548_CONFORMANCE_PERCENT:g} %",
         cf["conformance_percent"] < F3548_CONFORMANCE_PERCENT),
        (f"{cf['excursions_per_flight_hour']:.2f} excursions per hour > {F3548_EXCURSIONS_PER_HOUR:g}",
         cf["excursions_per_flight_hour"] > F3548_EXCURSIONS_PER_HOUR),
        (f"longest {cf['longest_excursion_s']:.1f} s > {F3548_LONGEST_EXCURSION_S:g} s",
         cf["longest_excursion_s"] > F3548_LONGEST_EXCURSION_S)) if bad]
    return "F3548 limits met" if not missed else "F3548 limits NOT MET (" + "; ".join(missed) + ")"


def flown_verdict(flown: dict) -> str:
    """The verdict on what flew: a loss the samples prove, pairs they can neither prove nor
    clear (unresolved: never OK), or OK."""
    if flown.get("losses"):
        return f"LOSS OF SEPARATION in {flown['losses']} pair(s)"
    if flown.get("unresolved"):
        return f"UNRESOLVED: {flown['unresolved']} pair(s) the samples can neither prove nor clear"
    return "OK"


def flown_failed(flown: dict) -> bool:
    """Whether what flew lost separation or may have (exit 2)."""
    return bool(flown) and flown_verdict(flown) != "OK"


def _separation_from_flags(args):
    """The model the flags name (their unset parts from the recording), or None (the run's)."""
    if args.separation is None and args.separation_m is None and args.vertical_separation_m is None:
        return None
    from uam_planner.separation import DEFAULT_VERTICAL_SEPARATION_M, SeparationModel

    recorded = separation_from_metadata(read_metadata(args.recording, AIRSPACE_METADATA)) \
        if Path(args.recording).is_file() else separation_from_metadata({})
    kind = args.separation or recorded.kind
    h = args.separation_m if args.separation_m is not None else recorded.separation_m
    v = args.vertical_separation_m if args.vertical_separation_m is not None else (
        recorded.vertical_separation_m if recorded.kind == "cylinder" else DEFAULT_VERTICAL_SEPARATION_M)
    return SeparationModel(kind, float(h), float(v))


def main(argv: list[str] | None = None) -> int:
    """Command line: print the summary of a recording (exit 2 if the audit finds a loss of
    separation between the plans or in what flew (or a flown pair it can neither prove nor
    clear), or a flown trajectory entering a constraint in force, 3 if the recording lacks plans
    it should hold or its plan versions do not chain, so its audit cannot be trusted)."""
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="analyze", description=__doc__.split("\n\n")[0])
    ap.add_argument("recording", help="the .mcap file of a run")
    ap.add_argument("--separation", choices=("sphere", "cylinder"), default=None,
                    help="separation model of the audit (default: the run's, from the recording's "
                         "uam_airspace metadata; recordings without it: sphere)")
    ap.add_argument("--separation-m", type=float, default=None,
                    help="separation minimum (the cylinder's horizontal H) [m] (default: the run's, else %g)" % SEPARATION_M)
    ap.add_argument("--vertical-separation-m", type=float, default=None,
                    help="the cylinder's vertical minimum V [m] (default: the run's, else 30)")
    ap.add_argument("--reader", choices=("rclpy", "rosbags"), default="rclpy",
                    help="decoder: rclpy (default, tolerates torn files) or rosbags (independent)")
    ap.add_argument("--network", default=None,
                    help="the run's network file: the flights' detour in metres over the shortest route")
    ap.add_argument("--json", action="store_true", help="print the summary as JSON")
    ap.add_argument("--no-epochs", action="store_true", help="leave out the per-epoch table")
    argv = list(sys.argv[1:] if argv is None else argv)
    if "--ros-args" in argv:  # ros2 run appends --ros-args ...: that part is not ours
        argv = argv[:argv.index("--ros-args")]
    args = ap.parse_args(argv)  # a misspelled option is an error (exit 2), not a file name
    try:
        require_mcap(args.recording)
        topics = recorded_topics(args.recording)
        if topics is not None and not topics & set(ANALYSED_TOPICS):
            raise ValueError(f"recording: {args.recording!r} holds none of the topics "
                             f"{', '.join(ANALYSED_TOPICS)} (not a recording of a run)")
    except ValueError as exc:  # not a recording of a run at all: nothing to judge, so no verdict
        print(f"analyze: {exc}", file=sys.stderr)
        return 2
    except FileNotFoundError:
        pass  # summarize says so
    try:
        separation = _separation_from_flags(args)
        summary = summarize(args.recording, separation, args.reader, network=args.network)
    except (FileNotFoundError, ValueError) as exc:
        print(f"analyze: {exc}", file=sys.stderr)
        return 1
    try:
        if args.json:
            print(summary.to_json(indent=2))
        else:
            print(format_summary(summary, epochs=not args.no_epochs))
    except BrokenPipeError:  # e.g. piped into `head`
        sys.stderr.close()
    if (summary.audit is not None and not summary.audit.ok) or summary.incursions or flown_failed(summary.flown):
        return 2
    return 0 if summary.verified else 3


if __name__ == "__main__":
    sys.exit(main())
