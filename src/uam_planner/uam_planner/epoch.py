"""The planning cycle (framework steps 1-7) and the shortest-FIFO baseline, free of ROS.

One epoch at time t:

1. eligible requests: pending with earliest_departure_s <= t <= latest_departure_s;
2. candidate routes (cached per origin-destination pair);
3. trajectories departing at t;
4. discard candidates that lose separation with an active flight;
5. conflicts between candidates of different requests;
6. conflict graph, solved by an injected MWIS function whose answer is checked here (independent,
   at most one per request, indices in range) and replaced by greedy if it fails or is invalid;
7. the selected candidates become flights departing at t; an unapproved request whose latest
   departure comes before the next epoch (t + epoch_s) expires now; the others wait.

A rolling horizon (``PlanningConfig.horizon_epochs`` H > 1, MWIS policy only): steps 1-6 take
the departures of the next H epochs (a request is eligible when one lies in its window), and
step 7 commits only the selected candidates that depart in this epoch; the other requests wait
and are planned again at the next epoch with what is known then. H = 1 is the rule above.
What the MWIS maximises is ``PlanningConfig.objective`` (``uam_planner.objectives``).

``plan_epoch_fifo`` is the paper's baseline with the same inputs and outputs: in arrival order,
each eligible request gets its shortest route if that route keeps separation with every active
flight and every flight approved before it in this epoch; otherwise it waits (until it expires).

Airspace with room (``AirspaceConfig``; the defaults are the paper's model): the separation
model (the paper's sphere or a cylinder), departure slots and, on a layered network (one that
declares flight levels), vertiports as terminals, one cruise level per flight and vertical climb
and descent (see ``uam_planner.candidates``). With ``departure_slot_s > 0`` a candidate is
(route, level, departure time): the departure times of a request at epoch t are
``lo, lo + slot, lo + 2 slot, ...`` up to ``hi``, with ``lo = max(t, earliest_departure_s)`` and
``hi = min(t + epoch_s, latest_departure_s)``, and a request is eligible when that window is not
empty. ``departure_slot_s = 0`` is the paper's rule: depart at the epoch time t.

Weights: in the paper's model w = d*/d (d* the request's shortest route length). With levels or
slots a candidate's weight is w = T* / (T + delay): T its flight time (climb, cruise, descent),
T* the least T among the request's candidates at this epoch, delay its departure minus ``lo``. So
the best candidate has w = 1, and w falls with detour (a longer route or a higher level makes T
longer) and with delay, both measured in the same unit (seconds of the passenger's arrival
later than the best), so a 30 s detour and a 30 s wait cost the same; w = d*/d again when levels
and slots cost nothing (one level, no climb, slot 0). The MWIS then prefers many flights to few,
then early and direct ones.

The configuration is :mod:`uam_planner.planning_config`; :class:`uam_planner.planning.Planner`
drives the epochs.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Callable, Sequence

import numpy as np

from .candidates import CandidateCache, RouteTemplate
from .conflict_graph import (
    CandidatePairCache,
    ConflictGraph,
    ShiftedCandidates,
    _unique_pairs,
    build_conflict_graph,
)
from .constraints import refuse_candidates
from .first_fit import first_fit_select
from .intent_volumes import graph_for_config, intent_pairs
from .objectives import OperatorShares, epoch_weights, order_requests
from .planning_config import Flight, FlightRequest, PlanningConfig
from .separation import SegmentSet, any_conflict, conflicting_pairs
from .trajectory import Trajectory


@dataclass
class EpochReport:
    """Every count of one planning epoch (mirrors uam_msgs/PlanningReport) and the MWIS instance."""

    epoch_index: int
    t_s: float
    policy: str
    pending: int = 0
    eligible: int = 0
    candidates: int = 0
    discarded: int = 0
    vertices: int = 0
    edges: int = 0
    conflict_edges: int = 0
    approved: int = 0
    rejected: int = 0
    expired: int = 0
    active_flights: int = 0
    objective: float = 0.0
    solve_time_s: float = 0.0
    planning_time_s: float = 0.0
    proven_optimal: bool = False
    backend_requested: str = ""
    backend_used: str = ""
    fallback: bool = False
    fallback_reason: str = ""
    weights: np.ndarray = field(default_factory=lambda: np.zeros(0, np.float64))
    edges_array: np.ndarray = field(default_factory=lambda: np.zeros((0, 2), np.int32))
    vertex_request_ids: list = field(default_factory=list)
    vertex_candidate_index: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int64))
    selected: np.ndarray = field(default_factory=lambda: np.zeros(0, np.int32))
    phase_times_s: dict = field(default_factory=dict)
    #: request id -> reason naming the constraint(s), for each eligible request all of whose
    #: candidates entered a constraint this epoch (uam_planner.constraints)
    constraint_refusals: dict = field(default_factory=dict)
    #: the batch re-plan of this epoch (``uam_planner.replanning.ReplanReport``), or None when
    #: no constraint update was applied at this epoch
    replan: object = None
    #: the reaction to nonconforming flights of this epoch (``uam_planner.nonconformance.react``'s
    #: report dict, plus ``refused``: [(request_id, reason)] of the claims not acted on), or None
    nonconformance: object = None
    #: the flights held past their plans at this epoch (seen later than planned by the
    #: planner's own observations): request id -> until when [s] (uam_planner.nonconformance
    #: .overruns); empty when none
    overruns: dict = field(default_factory=dict)


@dataclass
class EpochResult:
    """Approvals, expiries and the requests left waiting after one epoch, with the report.

    ``plan_updates``: the new versions and cancellations of flights approved before, decided at
    this epoch because constraints changed, an operator modified or cancelled its flight, or the
    reaction acted (``uam_planner.replanning.PlanUpdate``, one per affected flight; empty when
    nothing changed). ``refused_modifications``: request id -> (why, whether the previous
    version stays in force) of each modification (``Planner.modify``) this epoch did not approve."""

    approved: list
    expired: list
    waiting: list
    report: EpochReport
    plan_updates: list = field(default_factory=list)
    refused_modifications: dict = field(default_factory=dict)


# ---- MWIS answer checking ---------------------------------------------------------------------

def _fallback_greedy(weights: np.ndarray, edges: np.ndarray) -> np.ndarray:
    """The solve service's own fallback (GWMIN, or its vectorised form on large or dense
    graphs: bounded time, 27 ms on a clique of 1,000 with pendants where GWMIN took 2.2 s)."""
    from uam_solvers.base import MwisProblem
    from uam_solvers.greedy import fallback_selection, greedy_mwis, needs_fast_fallback
    problem = MwisProblem.from_arrays(weights, edges)
    if needs_fast_fallback(problem):
        return np.asarray(fallback_selection(problem)[0], dtype=np.int64)
    return np.asarray(greedy_mwis(weights, edges), dtype=np.int64)


def check_selection(selected, graph: ConflictGraph) -> str:
    """Why ``selected`` is not a valid answer for ``graph`` ('' when valid).

    The one answer checker is ``uam_solvers.check_selection`` (vertex indices in range, no
    repeats, no edge, at most one candidate per request: the request cliques are groups).
    """
    from uam_solvers.base import MwisProblem
    from uam_solvers.base import check_selection as check

    problem = MwisProblem.from_arrays(graph.weights, graph.edges, graph.groups)
    return check(problem, selected)[1]


def call_solver(solve_mwis: Callable, graph: ConflictGraph):
    """Call the injected solve function on ``graph``; an exception is returned, not raised."""
    try:
        return solve_mwis(graph.weights, graph.edges, graph.groups)
    except Exception as exc:  # any solver failure must not stop planning; commit reports it
        return exc


def checked_selection(graph: ConflictGraph, answer, report: EpochReport) -> np.ndarray:
    """The one place a solver answer is checked and replaced by greedy; fills the report.

    ``answer``: what the solve function returned (an object with ``selected`` and optionally
    backend, proven_optimal, fallback, message), or the exception it raised / a reason string
    (e.g. from the planner node: the service is absent or late). An invalid or missing answer
    is replaced by the greedy MWIS, marked as a fallback with the reason.
    """
    if graph.n_vertices == 0:
        return np.zeros(0, dtype=np.int64)
    selected = None
    if isinstance(answer, BaseException):
        reason = f"solver raised {type(answer).__name__}: {answer}"
    elif isinstance(answer, str):
        reason = answer or "no solver answer"
    else:
        selected = getattr(answer, "selected", None)
        if selected is None:
            reason = f"solver answer {type(answer).__name__} has no 'selected'"
        else:
            reason = check_selection(selected, graph)
    if reason:
        selected = _fallback_greedy(graph.weights, graph.edges)
        report.backend_used = "greedy"
        report.fallback = True
        report.fallback_reason = reason
        report.proven_optimal = False
        assert check_selection(selected, graph) == "", "greedy fallback returned an invalid set"
    else:
        selected = np.asarray(selected, dtype=np.int64)
        report.backend_used = str(getattr(answer, "backend", "") or report.backend_requested)
        report.proven_optimal = bool(getattr(answer, "proven_optimal", False))
        report.fallback = bool(getattr(answer, "fallback", False))
        if report.fallback:
            report.fallback_reason = str(getattr(answer, "message", "") or "solver fell back")
    return np.sort(selected)


def default_solve_mwis(config: PlanningConfig) -> Callable:
    """A solve function calling ``uam_solvers.solve_bounded`` with the config's backend, limit
    and seed: the solver node's deadline mechanism (a solve past the limit + ~0.5 s is killed
    and answered by the fallback), whose workers start and warm up here, not in the first
    epoch."""
    import uam_solvers
    from uam_solvers.executor import shared_service

    shared_service()

    def solve(weights, edges, groups):
        return uam_solvers.solve_bounded(weights, edges, groups=groups, backend=config.backend,
                                         time_limit_s=config.time_limit_s, seed=config.seed)
    return solve


def replan_selector(solve_mwis: Callable, config: PlanningConfig, epoch_index: int = 0,
                    t_s: float = 0.0) -> Callable:
    """The ``select(graph, policy[, answer])`` of ``uam_planner.replanning.replan``: policy
    "mwis" checks ``answer`` (the solver service's, sent by the planner node) or, without one,
    calls ``solve_mwis`` (either checked, greedy if invalid or failed), "firstfit" walks the
    vertices (``uam_planner.first_fit``); returns (selected, an EpochReport with backend_used,
    fallback and fallback_reason)."""
    from .replanning import SOLVE_HERE

    def select(graph, policy, answer=SOLVE_HERE):
        rep = EpochReport(epoch_index=int(epoch_index), t_s=float(t_s), policy=policy,
                          backend_requested=config.backend if policy == "mwis" else "firstfit")
        if policy == "firstfit":
            answer = first_fit_select(graph.weights, graph.edges)
        elif answer is SOLVE_HERE:
            answer = call_solver(solve_mwis, graph)
        return checked_selection(graph, answer, rep), rep
    return select


# ---- the two policies ---------------------------------------------------------------------------

def _eligible(t_s: float, pending: Sequence[FlightRequest], config: PlanningConfig,
              order: str = "arrival", horizon: int = 1) -> list:
    """The requests that may depart in this epoch (or, with a ``horizon`` of H epochs, in one of
    the next H), in arrival order or (``order``, for the baselines) in
    ``uam_planner.objectives.order_requests`` order."""
    if config.airspace.departure_slot_s > 0.0:
        # any departure in [max(t, earliest), min(t + H epoch_s, latest)]
        hi = t_s + horizon * config.epoch_s
        out = [r for r in pending if r.earliest_departure_s <= hi and r.latest_departure_s >= t_s
               and max(t_s, r.earliest_departure_s) <= min(hi, r.latest_departure_s)]
    elif horizon == 1:
        out = [r for r in pending if r.earliest_departure_s <= t_s <= r.latest_departure_s]
    else:
        out = [r for r in pending if _horizon_epoch_times(t_s, r, config, horizon).size]
    return order_requests(out, order)


def _horizon_epoch_times(t_s: float, request: FlightRequest, config: PlanningConfig,
                         horizon: int) -> np.ndarray:
    """Paper rule with a horizon: the epoch times t + j epoch_s (j < H) inside the window."""
    ts = float(t_s) + config.epoch_s * np.arange(horizon, dtype=np.float64)
    return ts[(ts >= request.earliest_departure_s) & (ts <= request.latest_departure_s)]


def departure_slots_s(t_s: float, request: FlightRequest, config: PlanningConfig,
                      horizon: int = 1) -> np.ndarray:
    """Departure times [s] a request may take at the epoch at ``t_s``.

    Paper rule (``departure_slot_s == 0``): [t_s]. Otherwise lo, lo + slot, ... <= hi with
    lo = max(t_s, earliest_departure_s), hi = min(t_s + epoch_s, latest_departure_s); empty when
    lo > hi. E.g. t = 0, epoch 30 s, slot 5 s, window [0, 60]: 0, 5, ..., 30 (7 slots).
    With a ``horizon`` of H epochs: hi = min(t_s + H epoch_s, latest_departure_s), every slot of
    this epoch (up to t_s + epoch_s) and, of each later epoch, its first slot only; the paper
    rule's departures are the epoch times t_s + j epoch_s (j < H) inside the window. E.g.
    t = 0, epoch 30 s, slot 10 s, H = 3, window [0, 200]: 0, 10, 20, 30, 40, 70.
    """
    slot = float(config.airspace.departure_slot_s)
    if slot <= 0.0:
        return np.array([float(t_s)]) if horizon == 1 else \
            _horizon_epoch_times(t_s, request, config, horizon)
    lo = max(float(t_s), float(request.earliest_departure_s))
    hi = min(float(t_s) + horizon * config.epoch_s, float(request.latest_departure_s))
    if lo > hi:
        return np.zeros(0)
    n = int(math.floor((hi - lo) / slot + 1e-9)) + 1
    grid = lo + slot * np.arange(n, dtype=np.float64)
    if horizon == 1:
        return grid
    # Later epochs of the horizon are planned again before they are committed: one departure
    # each (the first slot after the epoch's start) bounds the graph (every slot of a 300 s
    # window at 5 s gave 17,500 vertices and 4.7 million edges at H = 10, rate 20).
    end = float(t_s) + config.epoch_s
    later = grid > end + 1e-9
    epoch_of = np.ceil((grid[later] - float(t_s)) / config.epoch_s - 1e-9)
    _, first = np.unique(epoch_of, return_index=True)
    return np.concatenate((grid[~later], grid[later][first]))


@dataclass
class _Candidates:
    """The flat candidate list of one epoch: template, departure time, weight and request."""

    tmpls: list
    departures_s: list
    weights: list
    req_of: list
    index_in_request: list
    refusals: dict = field(default_factory=dict)  # request id -> reason (constraints)

    def trajectories(self) -> list:
        return [tp.trajectory(dep) for tp, dep in zip(self.tmpls, self.departures_s)]

    def shifted(self, exact: bool = False) -> ShiftedCandidates:
        """The same candidates as one base trajectory per template (at its first slot) and
        departure shifts: the slots of one template are consecutive. ``exact``: a candidate's
        trajectory is built from its template and departure (the same floats in every epoch,
        as the horizon's pair cache needs), not shifted from the base."""
        n = len(self.tmpls)
        starts = [c for c in range(n) if c == 0 or self.tmpls[c] is not self.tmpls[c - 1]]
        first = np.asarray(starts + [n], dtype=np.int64)
        deps = np.asarray(self.departures_s, dtype=np.float64)
        base = _Departures([self.tmpls[c] for c in starts], [self.departures_s[c] for c in starts])
        shift = deps - np.repeat(deps[first[:-1]], np.diff(first)) if n else deps
        build = (lambda c: self.tmpls[c].trajectory(self.departures_s[c])) if exact else None
        return ShiftedCandidates(base, first, shift, exact=build)


class _Departures:
    """Trajectories of templates flown from given departures [s], each built on access; their
    SegmentSet comes straight from the templates' arrays (most of a busy epoch's candidates are
    discarded against the active flights, and only the survivors' trajectories are needed)."""

    def __init__(self, tmpls: list, departures_s: list):
        self.tmpls = tmpls
        self.departures_s = departures_s

    def __len__(self) -> int:
        return len(self.tmpls)

    def __getitem__(self, j) -> Trajectory:
        return self.tmpls[j].trajectory(self.departures_s[j])

    def segment_set(self) -> SegmentSet:
        """The SegmentSet of every trajectory: the same floats as
        ``SegmentSet.from_trajectories`` over them (each time is the template's relative time
        plus the departure, one addition as in ``RouteTemplate.trajectory``)."""
        n = len(self.tmpls)
        if n == 0:
            return SegmentSet.from_trajectories([])
        segs = [tp.segments_rel for tp in self.tmpls]
        counts = np.fromiter((s[0].shape[0] for s in segs), dtype=np.int64, count=n)
        dep = np.repeat(np.asarray(self.departures_s, dtype=np.float64), counts)
        t0 = np.concatenate([s[0] for s in segs])
        t0 += dep
        t1 = np.concatenate([s[1] for s in segs])
        t1 += dep
        return SegmentSet(np.repeat(np.arange(n, dtype=np.int64), counts), t0, t1,
                          np.concatenate([s[2] for s in segs]),
                          np.concatenate([s[3] for s in segs]), n)


def _paper_weights(config: PlanningConfig, network) -> bool:
    return config.airspace.departure_slot_s <= 0.0 and not network.layered


def _epoch_candidates(t_s: float, eligible: Sequence[FlightRequest], network, config,
                      cache: CandidateCache, best_only: bool = False,
                      shares: OperatorShares | None = None, horizon: int = 1) -> _Candidates:
    """Every (template, departure) candidate of the eligible requests, in request order; with
    ``best_only`` only each request's best one (shortest route, lowest allowed level, first
    slot: weight 1). Weights: ``config.objective`` (``uam_planner.objectives``) from the paper's
    weights, the departures and flight times; ``shares`` are the running operator counts for
    the "fair" objective. ``horizon``: the departures of the next H epochs (the paper's
    weights then count the delay, T*/(T + delay), as with slots)."""
    paper = _paper_weights(config, network) and horizon == 1
    out = _Candidates([], [], [], [], [])
    for i, r in enumerate(eligible):
        ts = cache.templates(network.node_index(r.origin_id), network.node_index(r.destination_id))
        slots = departure_slots_s(t_s, r, config, horizon)
        if best_only:
            ts = ts[:1]
            slots = slots[:1]
        durations = [tp.duration_s for tp in ts]
        best_t = min(durations)
        deps = slots.tolist()
        n_c = len(ts) * len(deps)
        # per template, its slots in order (the same floats as one candidate at a time)
        for tp, dur in zip(ts, durations):
            out.tmpls.extend([tp] * len(deps))
            out.departures_s.extend(deps)
            if paper:
                out.weights.extend([tp.route.weight] * len(deps))
            else:
                out.weights.extend([best_t / (dur + (dep - deps[0])) for dep in deps])
        out.req_of.extend([i] * n_c)
        out.index_in_request.extend(range(n_c))
    if config.objective != "paper" and out.tmpls:
        # with a horizon, "not approved now" means not within the H epochs
        w = epoch_weights(config.objective, t_s, horizon * config.epoch_s, eligible, out.req_of,
                          out.departures_s, [tp.duration_s for tp in out.tmpls], out.weights,
                          shares)
        out.weights = w.weights.tolist()
    if config.constraints is not None and len(config.constraints):
        out = _without_constrained(out, eligible, network, config.constraints)
    return out


def _without_constrained(cands: _Candidates, eligible, network, cset) -> _Candidates:
    """The one constraint hook: drop the candidates that enter a constraint during
    its window (``uam_planner.constraints``), before any separation check or graph; weights are
    kept as computed against the unconstrained best, so a detour still costs its detour."""
    reqs = [eligible[i] for i in cands.req_of]
    refused, reasons = refuse_candidates(
        cset, network, cands.trajectories(), [r.origin_id for r in reqs],
        [r.destination_id for r in reqs], [tp.level_index for tp in cands.tmpls], cands.req_of,
        [r.request_id for r in eligible])
    keep = np.flatnonzero(~refused).tolist()
    return _Candidates(*([lst[k] for k in keep] for lst in
                         (cands.tmpls, cands.departures_s, cands.weights, cands.req_of,
                          cands.index_in_request)), refusals=reasons)


def _finish(t_s, config, pending, approved, active_count, report) -> EpochResult:
    done = {f.request_id for f in approved}
    horizon = t_s + config.epoch_s
    expired, waiting = [], []
    for r in pending:
        if r.request_id in done:
            continue
        (expired if r.latest_departure_s < horizon else waiting).append(r)
    report.approved = len(approved)
    report.expired = len(expired)
    report.active_flights = active_count + len(approved)
    report.objective = float(sum(f.weight for f in approved))
    return EpochResult(approved=approved, expired=expired, waiting=waiting, report=report)


def _flight(req: FlightRequest, tmpl: RouteTemplate, traj: Trajectory, method: str, backend: str,
            epoch_index: int, weight: float, candidate_index: int) -> Flight:
    r = tmpl.route
    return Flight(request_id=req.request_id, origin_id=req.origin_id,
                  destination_id=req.destination_id, route_node_ids=tmpl.node_ids,
                  trajectory=traj, departure_s=traj.departure_s, arrival_s=traj.arrival_s,
                  length_m=r.length_m, weight=float(weight), candidate_index=int(candidate_index),
                  method=method, backend=backend, epoch_index=int(epoch_index),
                  route_index=int(r.candidate_index), level_m=float(tmpl.level_m),
                  priority=int(getattr(req, "priority", 0)), operator_id=req.operator_id)


def _airborne(active: Sequence[Flight], t_s: float) -> list:
    return [f for f in active if f.arrival_s >= t_s]


@dataclass
class PreparedEpoch:
    """An epoch prepared up to its conflict graph; :func:`commit_epoch` turns an answer into
    approvals. For the FIFO policy (no solver) everything is decided in prepare (``result``)."""

    t_s: float
    epoch_index: int
    pending: list
    report: EpochReport
    graph: ConflictGraph | None = None
    eligible: list = field(default_factory=list)
    tmpls: list = field(default_factory=list)
    trajs: list = field(default_factory=list)
    req_of: list = field(default_factory=list)
    weights: list = field(default_factory=list)
    index_in_request: list = field(default_factory=list)
    airborne_count: int = 0
    prepare_s: float = 0.0
    phases: dict = field(default_factory=dict)
    result: EpochResult | None = None
    horizon: int = 1
    epoch_s: float = 0.0
    slots: bool = False
    commit_ahead: bool = False

    @property
    def needs_solver(self) -> bool:
        """True when commit needs an MWIS answer for ``graph``."""
        return self.result is None and self.graph is not None and self.graph.n_vertices > 0


def prepare_epoch_mwis(t_s: float, epoch_index: int, pending: Sequence[FlightRequest],
                       active: Sequence[Flight], network, config: PlanningConfig,
                       cache: CandidateCache, active_index=None,
                       shares: OperatorShares | None = None,
                       order: str = "arrival", horizon: int | None = None,
                       pair_cache: CandidatePairCache | None = None) -> PreparedEpoch:
    """Steps 1-6 of an MWIS epoch at ``t_s`` [s]: eligible requests, candidates, trajectories,
    deconfliction and the conflict graph (``PreparedEpoch.graph``), still to be solved.

    Arguments as :func:`plan_epoch_mwis`; ``active_index``: optional ActiveFlightIndex holding
    ``active`` (kept across epochs by the Planner, so the active flights' segments are not
    rebuilt every epoch); ``shares``: running operator counts (objective "fair"); ``order``:
    the vertex order by request ("arrival", or "priority" for first-fit's walk); ``horizon``:
    the epochs planned jointly (default ``config.horizon_epochs``); ``pair_cache``: with a
    horizon H > 1, the previous epoch's conflicts among candidates (kept by the Planner, valid
    while ``cache`` is: candidates are keyed by request, template identity and departure), so
    only pairs with a new candidate are checked (the same graph).
    """
    horizon = int(config.horizon_epochs if horizon is None else horizon)
    t_start = time.perf_counter()
    phases = {}
    report = EpochReport(epoch_index=int(epoch_index), t_s=float(t_s), policy="mwis",
                         pending=len(pending), backend_requested=config.backend)
    eligible = _eligible(t_s, pending, config, order, horizon)
    airborne = _airborne(active, t_s)
    t1 = time.perf_counter()
    phases["eligible_s"] = t1 - t_start

    cands = _epoch_candidates(t_s, eligible, network, config, cache, shares=shares, horizon=horizon)
    tmpls, req_of = cands.tmpls, cands.req_of
    report.constraint_refusals = cands.refusals
    t2 = time.perf_counter()
    phases["candidates_s"] = t2 - t1
    # With slots, the candidates of one template differ only by a time shift: deconflict them
    # per template (ShiftedCandidates) and build trajectories only for the survivors.
    trajs = cands.shifted(exact=horizon > 1) if config.airspace.departure_slot_s > 0.0 or horizon > 1 \
        else cands.trajectories()
    t3 = time.perf_counter()
    phases["trajectories_s"] = t3 - t2

    active_set = active_index.segments(airborne, t_s) if active_index is not None \
        else [f.trajectory for f in airborne]
    use_cache = pair_cache is not None and horizon > 1
    # a candidate: its request (requests of one origin and destination share templates), its
    # template and its departure
    keys = [(eligible[r].request_id, id(tp), dep) for r, tp, dep in
            zip(req_of, tmpls, cands.departures_s)] if use_cache else None
    graph = build_conflict_graph(
        trajs, np.asarray(req_of, dtype=np.int64),
        np.asarray(cands.index_in_request, dtype=np.int64),
        np.asarray(cands.weights, dtype=np.float64),
        len(eligible), active_set, config.separation, timings=phases, keys=keys,
        pair_cache=pair_cache if use_cache else None,
        bucket_s=_horizon_bucket_s(config) if horizon > 1 else None)
    graph = _with_intent_volumes(graph, trajs, airborne, config, t_s, phases)
    return PreparedEpoch(t_s=float(t_s), epoch_index=int(epoch_index), pending=list(pending), report=report,
                         graph=graph, eligible=eligible, tmpls=tmpls, trajs=trajs, req_of=req_of,
                         weights=cands.weights, index_in_request=cands.index_in_request,
                         airborne_count=len(airborne), prepare_s=time.perf_counter() - t_start,
                         phases=phases, horizon=horizon, epoch_s=float(config.epoch_s),
                         slots=config.airspace.departure_slot_s > 0.0,
                         commit_ahead=bool(config.commit_ahead))


def _with_intent_volumes(graph, trajs, airborne, config: PlanningConfig, t_s: float, phases: dict):
    """In F3548 mode, ``graph`` with the published volumes kept disjoint too
    (``uam_planner.intent_volumes.restrict_graph``; timed as ``volumes_s``); else ``graph``."""
    if config.intent_volumes is None:
        return graph
    t = time.perf_counter()
    # the flights' pieces that ended more than a second before the epoch meet no candidate
    graph = graph_for_config(graph, trajs, [f.trajectory for f in airborne], config, float(t_s) - 1.0)
    phases["volumes_s"] = time.perf_counter() - t
    return graph


def _horizon_bucket_s(config: PlanningConfig) -> float:
    """The broad phase's time bucket among a horizon's candidates: the separation module's
    default (one cell's flight time) at the cruise speed, fixed rather than from each call's
    median speed, so that a pair's verdict does not depend on the other candidates."""
    from .separation import DEFAULT_BUCKET_CELLS, DEFAULT_CELL_SEPARATIONS
    return DEFAULT_BUCKET_CELLS * DEFAULT_CELL_SEPARATIONS * float(config.separation_m) / \
        float(config.speed_mps)


def commit_epoch(prep: PreparedEpoch, answer, config: PlanningConfig, solve_s: float = 0.0) -> EpochResult:
    """Step 7: the checked answer (see :func:`checked_selection`) becomes flights departing at t.

    ``answer``: the solver's answer, an exception or a reason string (ignored when the graph is
    empty or for FIFO); ``solve_s``: wall time spent getting it [s], for the report.
    """
    if prep.result is not None:
        return prep.result
    graph, report, phases, eligible = prep.graph, prep.report, prep.phases, prep.eligible
    t4 = time.perf_counter()
    selected = checked_selection(graph, answer, report)
    if prep.horizon > 1 and selected.size and not prep.commit_ahead:
        # rolling horizon: commit what departs in this epoch (before the next epoch time in the
        # paper's rule; up to and including it with slots, whose window is [t, t + epoch_s]);
        # the rest waits and is planned again (with commit_ahead everything selected is
        # committed now: the later departures are reservations)
        deps = np.array([prep.trajs[int(graph.vertex_source[v])].departure_s for v in selected.tolist()])
        end = prep.t_s + prep.epoch_s
        selected = selected[deps <= end + 1e-9 if prep.slots else deps < end - 1e-9]
    t5 = time.perf_counter()
    phases["solve_s"] = float(solve_s) + (t5 - t4)
    report.solve_time_s = phases["solve_s"]

    approved = []
    for v in selected.tolist():
        src = int(graph.vertex_source[v])
        approved.append(_flight(eligible[prep.req_of[src]], prep.tmpls[src], prep.trajs[src], "mwis",
                                report.backend_used, prep.epoch_index, prep.weights[src],
                                prep.index_in_request[src]))
    # Vertices follow the eligible order, so sorted vertices give approvals in arrival order.

    report.eligible = len(eligible)
    report.candidates = graph.n_candidates
    report.discarded = graph.n_discarded
    report.vertices = graph.n_vertices
    report.edges = graph.n_edges
    report.conflict_edges = graph.n_conflict_edges
    report.weights = graph.weights
    report.edges_array = graph.edges
    report.vertex_request_ids = [eligible[i].request_id for i in graph.vertex_request.tolist()]
    report.vertex_candidate_index = graph.vertex_candidate
    report.selected = selected.astype(np.int32)
    result = _finish(prep.t_s, config, prep.pending, approved, prep.airborne_count, report)
    t6 = time.perf_counter()
    phases["finish_s"] = t6 - t5
    # planning time: prepare and finish; waiting between them (e.g. for the service) is solve time
    report.planning_time_s = prep.prepare_s + (t6 - t5)
    report.phase_times_s = phases
    return result


def plan_epoch_mwis(t_s: float, epoch_index: int, pending: Sequence[FlightRequest],
                    active: Sequence[Flight], network, config: PlanningConfig,
                    solve_mwis: Callable, cache: CandidateCache,
                    active_index=None, shares: OperatorShares | None = None,
                    order: str = "arrival", horizon: int | None = None) -> EpochResult:
    """One MWIS planning epoch at time ``t_s`` [s]: prepare, solve, commit.

    Args:
        t_s: epoch time [s]; approved flights depart at t_s (paper rule) or at a departure
            slot in [t_s, t_s + epoch_s] (``config.airspace.departure_slot_s > 0``).
        epoch_index: epoch number, copied to the report and the flights.
        pending: requests not yet decided, in arrival order.
        active: approved flights (those that landed before t_s are ignored).
        network: the Network (ids in requests are its node ids).
        config: PlanningConfig.
        solve_mwis: callable(weights, edges, groups) -> object with ``selected`` (and optionally
            backend, proven_optimal, fallback, message); its answer is checked, and replaced by
            greedy (marked as a fallback in the report) if it raises or is invalid.
        cache: CandidateCache built for this network and config.
        active_index: optional ActiveFlightIndex holding ``active`` (kept across epochs by the
            Planner, so the active flights' segments are not rebuilt every epoch).
        shares: running operator counts for the "fair" objective (OperatorShares).
        order: the request (and so vertex) order: "arrival", or "priority" (first-fit's walk
            with ``baseline_order`` "priority").
        horizon: the epochs planned jointly (default ``config.horizon_epochs``; only the
            selected flights departing by t_s + epoch_s are committed).
    Returns: EpochResult. Approved flights never lose separation (in ``config.separation``)
    with each other or with ``active``: every conflict is an edge and the answer is checked to
    be independent.
    """
    prep = prepare_epoch_mwis(t_s, epoch_index, pending, active, network, config, cache,
                              active_index, shares, order, horizon)
    t = time.perf_counter()
    answer = call_solver(solve_mwis, prep.graph) if prep.needs_solver else None
    return commit_epoch(prep, answer, config, time.perf_counter() - t)


def plan_epoch_fifo(t_s: float, epoch_index: int, pending: Sequence[FlightRequest],
                    active: Sequence[Flight], network, config: PlanningConfig,
                    solve_mwis: Callable | None, cache: CandidateCache,
                    active_index=None, shares: OperatorShares | None = None) -> EpochResult:
    """One shortest-FIFO epoch; same inputs and outputs as :func:`plan_epoch_mwis`.

    In the order of ``pending`` (arrival order; with ``config.baseline_order`` "priority": by
    priority class, then earliest latest departure, then arrival), each eligible request gets its shortest route if
    it keeps separation with every active flight and every flight approved before it in this
    epoch; otherwise it waits. ``solve_mwis`` is ignored. The report's instance is empty;
    ``vertices`` counts the shortest routes that survive the active flights and ``edges`` /
    ``conflict_edges`` the conflicting pairs among them. With levels or slots the "shortest
    route" is each request's best candidate (shortest route, lowest allowed level, first slot).
    """
    t_start = time.perf_counter()
    phases = {}
    report = EpochReport(epoch_index=int(epoch_index), t_s=float(t_s), policy="fifo",
                         pending=len(pending))
    eligible = _eligible(t_s, pending, config, config.baseline_order)
    airborne = _airborne(active, t_s)
    t1 = time.perf_counter()
    phases["eligible_s"] = t1 - t_start
    cands = _epoch_candidates(t_s, eligible, network, config, cache, best_only=True, shares=shares)
    tmpls = cands.tmpls
    report.constraint_refusals = cands.refusals
    t2 = time.perf_counter()
    phases["candidates_s"] = t2 - t1
    trajs = cands.trajectories()
    t3 = time.perf_counter()
    phases["trajectories_s"] = t3 - t2
    cand_set = SegmentSet.from_trajectories(trajs)
    active_set = active_index.segments(airborne, t_s) if active_index is not None \
        else SegmentSet.from_trajectories([f.trajectory for f in airborne])
    sep = config.separation
    discarded = np.zeros(len(trajs), dtype=bool)
    if len(trajs) and len(active_set):
        discarded = any_conflict(cand_set, active_set, sep)
    spec = config.intent_volumes
    if spec is not None and len(trajs) and airborne:   # F3548 mode: the published volumes too
        discarded[intent_pairs(trajs, [f.trajectory for f in airborne], spec, float(t_s) - 1.0)[:, 0]] = True
    t4 = time.perf_counter()
    phases["deconfliction_s"] = t4 - t3
    surv = np.flatnonzero(~discarded)
    conflicts = conflicting_pairs([trajs[i] for i in surv], None, sep) \
        if surv.size > 1 else np.zeros((0, 2), dtype=np.int64)
    if spec is not None and surv.size > 1:
        conflicts = _unique_pairs(np.concatenate(
            [conflicts, intent_pairs([trajs[i] for i in surv], None, spec)]), surv.size)
    t5 = time.perf_counter()
    phases["conflicts_s"] = t5 - t4
    partners: dict[int, list[int]] = {}
    for a, b in conflicts.tolist():
        partners.setdefault(int(surv[b]), []).append(int(surv[a]))  # a < b: a arrived first
    taken = np.zeros(len(trajs), dtype=bool)
    approved = []
    for i in surv.tolist():
        if any(taken[j] for j in partners.get(i, ())):
            continue
        taken[i] = True
        approved.append(_flight(eligible[cands.req_of[i]], tmpls[i], trajs[i], "fifo", "", epoch_index,
                                cands.weights[i], cands.index_in_request[i]))
    t6 = time.perf_counter()
    phases["graph_s"] = t6 - t5
    phases["solve_s"] = 0.0
    report.eligible = len(eligible)
    report.candidates = len(trajs)
    report.discarded = int(discarded.sum())
    report.vertices = int(surv.size)
    report.edges = report.conflict_edges = int(conflicts.shape[0])
    result = _finish(t_s, config, pending, approved, len(airborne), report)
    t7 = time.perf_counter()
    phases["finish_s"] = t7 - t6
    report.planning_time_s = t7 - t_start
    report.phase_times_s = phases
    return result


