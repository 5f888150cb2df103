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

``Planner`` holds the pending requests and active flights between epochs; the ROS planner node and
the in-process experiment runner both drive it, so they approve the same flights for the same
inputs. Wall time is measured only for reports (``solve_time_s``, ``planning_time_s``); no
decision depends on it.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from uam_contract import defaults

from .candidates import (DEFAULT_CLIMB_RATE_MPS, DEFAULT_DESCENT_RATE_MPS, CandidateCache,
                         RouteTemplate)
from .constraints import ConstraintSet, refuse_candidates
from .conflict_graph import (ActiveFlightIndex, CandidatePairCache, ConflictGraph,
                             ShiftedCandidates, build_conflict_graph)
from .separation import (DEFAULT_VERTICAL_SEPARATION_M, SEPARATION_MODELS, SegmentSet,
                         SeparationModel, conflicting_pairs)
from .first_fit import as_firstfit, first_fit_select
from .objectives import (BASELINE_ORDERS, OperatorShares, check_objective, check_priority,
                         epoch_weights, operator_of, order_requests)
from .trajectory import Trajectory
from .nonconformance import (Claim, ConformanceBounds, PositionBook, deviations, overruns,
                             predicted_conflicts, react_steps, verify)

POLICIES = ("mwis", "fifo", "firstfit")  # firstfit: uam_planner.first_fit
REPLAN_POLICIES = ("mwis", "firstfit")  # uam_planner.replanning
MAX_HORIZON_EPOCHS = 100  # PlanningConfig.horizon_epochs


@dataclass(frozen=True)
class FlightRequest:
    """A request to fly from one aerodrome to another. Times are simulation seconds."""

    request_id: str
    origin_id: str
    destination_id: str
    request_time_s: float
    earliest_departure_s: float
    latest_departure_s: float
    priority: int = 0  # integer class (ASTM F3548 style), 0..255; higher is more important
    operator_id: str = ""  # who asks ('' = operator-scoped request_id "operator/request", or none)


@dataclass(frozen=True, eq=False)
class Flight:
    """An approved flight: a request with its chosen route and 4D trajectory.

    Plan versions (issue 22, docs/replanning.md): ``version`` counts the plans of one request
    (1 = the approval; a re-plan on a constraint update makes version + 1) and ``effective_s``
    is when this version took effect (the first version: its departure, the default when nan
    is given; a re-plan: the epoch time at which the update was applied). A new version flies
    the old trajectory before ``effective_s`` and its own after (an airborne re-plan keeps the
    old waypoints up to its branch point, so the two chain). ``contingent``: the plan is a
    contingency (flown, not deconflicted; F3548 state Contingent). The F3548 state at a time is
    :func:`uam_planner.replanning.flight_state`.
    """

    request_id: str
    origin_id: str
    destination_id: str
    route_node_ids: tuple[str, ...]
    trajectory: Trajectory
    departure_s: float
    arrival_s: float
    length_m: float
    weight: float
    candidate_index: int
    method: str
    backend: str
    epoch_index: int
    route_index: int = 0
    level_m: float = float("nan")
    priority: int = 0
    operator_id: str = ""
    version: int = 1
    effective_s: float = float("nan")
    contingent: bool = False

    def __post_init__(self):
        if math.isnan(self.effective_s):
            object.__setattr__(self, "effective_s", float(self.departure_s))


def _positive(owner: str, name: str, v, allow_zero: bool = False) -> None:
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v) or v < 0 or (v == 0 and not allow_zero):
        what = "finite and >= 0" if allow_zero else "a positive finite number"
        raise ValueError(f"{owner}.{name} must be {what}, got {v!r}")


@dataclass(frozen=True)
class AirspaceConfig:
    """The airspace mode; the defaults are the paper's model.

    Attributes:
        separation_model: ``'sphere'`` (the paper's single 3D minimum ``separation_m``) or
            ``'cylinder'`` (horizontal distance < ``PlanningConfig.separation_m`` while the
            vertical distance < ``vertical_separation_m``).
        vertical_separation_m: the cylinder's vertical minimum V [m] (unused by the sphere).
        departure_slot_s: slot width [s] of the departure times inside the epoch and the
            request's window; 0 = the paper's rule (depart at the epoch time).
        climb_rate_mps, descent_rate_mps: vertical speeds [m/s] at the vertiports of a layered
            network (unused otherwise).

    Levels, direction rule and pads come from the network (``Network.levels_m``, ...).
    """

    separation_model: str = "sphere"
    vertical_separation_m: float = DEFAULT_VERTICAL_SEPARATION_M
    departure_slot_s: float = defaults.DEPARTURE_SLOT_S
    climb_rate_mps: float = DEFAULT_CLIMB_RATE_MPS
    descent_rate_mps: float = DEFAULT_DESCENT_RATE_MPS

    def __post_init__(self):
        if self.separation_model not in SEPARATION_MODELS:
            raise ValueError(f"AirspaceConfig.separation_model must be one of "
                             f"{SEPARATION_MODELS}, got {self.separation_model!r}")
        for name in ("vertical_separation_m", "climb_rate_mps", "descent_rate_mps"):
            _positive("AirspaceConfig", name, getattr(self, name))
        _positive("AirspaceConfig", "departure_slot_s", self.departure_slot_s, allow_zero=True)


@dataclass(frozen=True)
class PlanningConfig:
    """Planner parameters (paper defaults).

    Attributes:
        epoch_s: time between planning epochs [s].
        separation_m: separation minimum [m].
        k: candidate routes per request (penalised Dijkstra searches).
        penalty_factor: penalised Dijkstra factor.
        speed_mps: cruise speed [m/s].
        backend: MWIS backend name asked of ``uam_solvers.solve`` by the default solve function.
        time_limit_s: MWIS time budget [s] for the default solve function.
        seed: seed for stochastic backends.
        precompute_routes: compute every aerodrome pair's candidate routes when the Planner is
            built (a(a-1) x k Dijkstra searches; about 1 s for the 26-aerodrome Singapore
            network), so that no epoch pays for a route search.
        airspace: AirspaceConfig (separation model, departure slots, vertical rates); default
            the paper's model.
        constraints: a ``uam_planner.constraints.ConstraintSet`` (volumes and vertiport
            closures; a candidate that enters one during its window is discarded before the
            conflict graph), or None (default: the paper's airspace, nothing is checked).
        objective: what the MWIS maximises (``uam_planner.objectives``, docs/objectives.md):
            "paper" (the paper's weights, the default), "count", "delay", "priority", "fair".
        baseline_order: the order in which FIFO and first-fit serve requests: "arrival" (the
            paper's) or "priority" (priority class, then earliest latest departure, then arrival).
        horizon_epochs: H, the epochs the MWIS policy plans jointly (rolling horizon): the
            candidates of a request at the departures of the next H epochs are vertices of one
            graph (one clique per request), and only the selected ones departing in this epoch
            (before t + epoch_s in the paper's rule; at most t + epoch_s with slots) are
            committed; the others wait and are planned again at the next epoch. 1 = today's
            (the paper's) one-epoch planning. The baselines ignore it.
        fair_window_s: the "fair" objective's operator shares count only the decisions of
            the epochs in the last fair_window_s seconds (a sliding window); 0 = the whole run.
        commit_ahead: with H > 1, commit every selected candidate at once, also those departing
            in a later epoch of the horizon: reservations, ordinary approved flights (active, so
            every later epoch is deconflicted against them) that are never re-optimised (only
            a constraint's re-planning may revoke one). False (default): the rolling horizon
            commits only this epoch's departures and plans the rest again.
        replan_policy: how the Planner re-plans the flights a constraint update affects
            (``uam_planner.replanning``, docs/replanning.md): "mwis" (one MWIS over every
            affected flight's alternatives), "firstfit" (the baseline: in approval order, each
            flight's first alternative in preference order that keeps separation), or ""
            (default: "mwis" for the MWIS policy, "firstfit" for FIFO and first-fit).
        spatial_buffer_m, temporal_buffer_s: planning buffers on the separation (issue 23,
            docs/disturbances.md); 0 = today's. The planner keeps ``separation`` (the minimum
            widened by both), every audit keeps ``minimum_separation``.
        conflict_probe_s: with ``conformance`` set, the conflict probe's look-ahead [s]
            (``uam_planner.nonconformance.predicted_conflicts``): at every reaction, flights
            whose rest of plan, flown from where the planner last saw them at their observed
            progress rate, loses the true minimum within it are updated as nonconforming ones
            are; 0 (default) = no probe (only reported, confirmed nonconformance is acted on).
        conflict_probe_margin_m: with the probe on, its margin [m] (thirteenth stop): it predicts
            losses of the true minimum widened by this much (``probe_separation``), and its own
            batches deconflict their updates with the wider of that and ``separation``: a
            tactical buffer kept only between the flights that are predicted to come close,
            beside the strategic buffer every plan keeps; 0 (default) = the true minimum.
        conformance: the reaction to nonconforming flights (issue 23 item 3,
            ``uam_planner.nonconformance``): a ConformanceBounds the planner checks each
            nonconformance report against (its own plan, its own observation) before it updates
            the flight's intent; None (default) = no reaction, reports are ignored.
    """

    epoch_s: float = defaults.EPOCH_S          # the paper's values, from uam_contract.defaults
    separation_m: float = defaults.SEPARATION_M
    k: int = defaults.K
    penalty_factor: float = defaults.PENALTY_FACTOR
    speed_mps: float = defaults.SPEED_MPS
    backend: str = "greedy"
    time_limit_s: float = 10.0
    seed: int = 0
    precompute_routes: bool = False
    airspace: AirspaceConfig = AirspaceConfig()
    constraints: ConstraintSet | None = None
    objective: str = "paper"
    baseline_order: str = "arrival"
    horizon_epochs: int = 1
    commit_ahead: bool = False
    fair_window_s: float = 0.0
    replan_policy: str = ""
    spatial_buffer_m: float = 0.0
    temporal_buffer_s: float = 0.0
    conformance: ConformanceBounds | None = None
    conflict_probe_s: float = 0.0
    conflict_probe_margin_m: float = 0.0

    @property
    def probe_separation(self) -> SeparationModel:
        """What the conflict probe predicts losses of: the true minimum widened by
        ``conflict_probe_margin_m`` (sphere: S + m; cylinder: H + m, V unchanged)."""
        m = float(self.conflict_probe_margin_m)
        base = self.minimum_separation
        if not m:
            return base
        return SeparationModel(base.kind, base.separation_m + m, base.vertical_separation_m)

    @property
    def minimum_separation(self) -> SeparationModel:
        """The true minimum (sphere of ``separation_m`` by default): what audits check."""
        a = self.airspace
        return SeparationModel(a.separation_model, float(self.separation_m),
                               float(a.vertical_separation_m))

    @property
    def separation(self) -> SeparationModel:
        """The separation the planner keeps: the minimum itself without buffers (the paper's),
        else widened by the spatial buffer b and v_max x the temporal buffer tau (sphere: radius
        S + b + v tau, v the largest of the cruise, climb and descent speeds; cylinder: H + b +
        v_h tau with v_h the cruise speed, V + v_z tau with v_z the largest vertical rate), so
        plans keep the minimum plus b between any two times tau apart (docs/disturbances.md)."""
        if not (self.spatial_buffer_m or self.temporal_buffer_s):
            return self.minimum_separation
        a = self.airspace
        tau = float(self.temporal_buffer_s)
        b = float(self.spatial_buffer_m)
        v_z = max(a.climb_rate_mps, a.descent_rate_mps)
        if a.separation_model == "sphere":
            v = max(self.speed_mps, v_z)
            return SeparationModel("sphere", float(self.separation_m) + b + v * tau,
                                   float(a.vertical_separation_m))
        return SeparationModel("cylinder", float(self.separation_m) + b + self.speed_mps * tau,
                               float(a.vertical_separation_m) + v_z * tau)

    def __post_init__(self):
        if not isinstance(self.airspace, AirspaceConfig):
            raise ValueError(f"PlanningConfig.airspace must be an AirspaceConfig, got "
                             f"{type(self.airspace).__name__}")
        if self.constraints is not None and not isinstance(self.constraints, ConstraintSet):
            raise ValueError(f"PlanningConfig.constraints must be a ConstraintSet or None, got "
                             f"{type(self.constraints).__name__}")
        for name in ("spatial_buffer_m", "temporal_buffer_s", "conflict_probe_s",
                     "conflict_probe_margin_m"):
            _positive("PlanningConfig", name, getattr(self, name), allow_zero=True)
        if self.conformance is not None and not isinstance(self.conformance, ConformanceBounds):
            raise ValueError(f"PlanningConfig.conformance must be a ConformanceBounds or None, got "
                             f"{self.conformance!r}")
        for name in ("epoch_s", "separation_m", "speed_mps", "time_limit_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
                raise ValueError(f"PlanningConfig.{name} must be a positive finite number, got {v!r}")
        if isinstance(self.k, bool) or not isinstance(self.k, (int, np.integer)) or self.k < 1:
            raise ValueError(f"PlanningConfig.k must be an integer >= 1, got {self.k!r}")
        pf = self.penalty_factor
        if isinstance(pf, bool) or not isinstance(pf, (int, float)) or not math.isfinite(pf) or pf < 0:
            raise ValueError(f"PlanningConfig.penalty_factor must be finite and >= 0, got {pf!r}")
        if not isinstance(self.backend, str) or not self.backend:
            raise ValueError(f"PlanningConfig.backend must be a non-empty string, got {self.backend!r}")
        try:
            check_objective(self.objective)
        except ValueError as exc:
            raise ValueError(f"PlanningConfig.{exc}") from None
        h = self.horizon_epochs
        if isinstance(h, bool) or not isinstance(h, (int, np.integer)) or not 1 <= h <= MAX_HORIZON_EPOCHS:
            raise ValueError(f"PlanningConfig.horizon_epochs must be an integer in [1, {MAX_HORIZON_EPOCHS}], "
                             f"got {h!r}")
        _positive("PlanningConfig", "fair_window_s", self.fair_window_s, allow_zero=True)
        if not isinstance(self.commit_ahead, (bool, np.bool_)):
            raise ValueError(f"PlanningConfig.commit_ahead must be a bool, got {self.commit_ahead!r}")
        if self.replan_policy not in ("",) + REPLAN_POLICIES:
            raise ValueError(f"PlanningConfig.replan_policy must be one of {('',) + REPLAN_POLICIES}, "
                             f"got {self.replan_policy!r}")
        if self.baseline_order not in BASELINE_ORDERS:
            raise ValueError(f"PlanningConfig.baseline_order must be one of {BASELINE_ORDERS}, "
                             f"got {self.baseline_order!r}")


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
    #: the flights held past their plans at this epoch (issue 23: seen later than planned by the
    #: planner's own observations): request id -> until when [s] (uam_planner.nonconformance
    #: .overruns); empty when none
    overruns: dict = field(default_factory=dict)


@dataclass
class EpochResult:
    """Approvals, expiries and the requests left waiting after one epoch, with the report.

    ``plan_updates``: the new versions and cancellations of flights approved before, decided at
    this epoch because constraints changed (``uam_planner.replanning.PlanUpdate``, one per
    affected flight; empty when nothing changed)."""

    approved: list
    expired: list
    waiting: list
    report: EpochReport
    plan_updates: list = field(default_factory=list)


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
        base = [self.tmpls[c].trajectory(self.departures_s[c]) for c in starts]
        shift = deps - np.repeat(deps[first[:-1]], np.diff(first)) if n else deps
        build = (lambda c: self.tmpls[c].trajectory(self.departures_s[c])) if exact else None
        return ShiftedCandidates(base, first, shift, exact=build)


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
        best_t = min(tp.duration_s for tp in ts)
        c = 0
        for tp in ts:
            for dep in slots.tolist():
                out.tmpls.append(tp)
                out.departures_s.append(dep)
                if paper:
                    out.weights.append(tp.route.weight)
                else:
                    out.weights.append(best_t / (tp.duration_s + (dep - float(slots[0]))))
                out.req_of.append(i)
                out.index_in_request.append(c)
                c += 1
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
    """The one constraint hook (issue 22): drop the candidates that enter a constraint during
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
    return PreparedEpoch(t_s=float(t_s), epoch_index=int(epoch_index), pending=list(pending), report=report,
                         graph=graph, eligible=eligible, tmpls=tmpls, trajs=trajs, req_of=req_of,
                         weights=cands.weights, index_in_request=cands.index_in_request,
                         airborne_count=len(airborne), prepare_s=time.perf_counter() - t_start,
                         phases=phases, horizon=horizon, epoch_s=float(config.epoch_s),
                         slots=config.airspace.departure_slot_s > 0.0,
                         commit_ahead=bool(config.commit_ahead))


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
        pairs = conflicting_pairs(cand_set, active_set, sep)
        discarded[pairs[:, 0]] = True
    t4 = time.perf_counter()
    phases["deconfliction_s"] = t4 - t3
    surv = np.flatnonzero(~discarded)
    conflicts = conflicting_pairs([trajs[i] for i in surv], None, sep) \
        if surv.size > 1 else np.zeros((0, 2), dtype=np.int64)
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


# ---- the stateful planner -----------------------------------------------------------------------

class Planner:
    """Pending requests and active flights between epochs, with one policy.

    Args:
        network: the Network.
        config: PlanningConfig (default: paper defaults).
        policy: "mwis", "fifo" or "firstfit" (uam_planner.first_fit).
        solve_mwis: callable(weights, edges, groups) for the MWIS policy; default calls
            ``uam_solvers.solve`` with ``config.backend``.

    ``submit`` validates and queues a request; ``plan(t_s, epoch_index)`` runs one epoch, keeps
    the waiting requests, adds the approvals to the active flights and drops flights that landed
    before t_s. Each request is decided once: approved, expired or rejected.
    """

    def __init__(self, network, config: PlanningConfig | None = None, policy: str = "mwis",
                 solve_mwis: Callable | None = None):
        if policy not in POLICIES:
            raise ValueError(f"policy must be one of {POLICIES}, got {policy!r}")
        self.network = network
        self._config = None
        self.config = config if config is not None else PlanningConfig()
        self.policy = policy
        # The default reads self.config at each call, so a new backend takes effect next epoch.
        self.solve_mwis = solve_mwis if solve_mwis is not None else self._default_solve
        self.pending: list[FlightRequest] = []
        self.active: list[Flight] = []
        # the active flights' segments, kept across epochs (rebuilt only if ``active`` is
        # replaced by a list that is not the previous one minus landed flights plus approvals)
        self.active_index = ActiveFlightIndex()
        self._known_ids: set[str] = set()
        self._rejected_since_plan = 0
        self._prepared: PreparedEpoch | None = None
        # requests decided (approved or expired) and approved per operator (the "fair"
        # objective's running shares, over the whole run or a sliding window)
        self.shares = OperatorShares(window_s=float(self.config.fair_window_s))
        # constraint updates (issue 22, uam_planner.replanning): queued ones are applied at the
        # first epoch at a time >= their t_s; applied ones are logged in order
        self._queued_updates: list = []
        self._update_seq = 0
        self.constraint_log: list = []          # ConstraintUpdate, with applied_s
        self.initial_constraints: tuple = ()    # the constraints in force from the start
        self._requests: dict = {}               # request_id -> FlightRequest of active flights
        self._plan_updates: list = []           # decided in prepare, returned by commit
        self._replan_report = None
        # the reaction to nonconformance (issue 23, uam_planner.nonconformance): the planner's
        # own observations of the vehicles and the reports (claims) not acted on yet
        self.positions = PositionBook()
        self._claims: list = []
        self._nonconformance_report = None
        # flights held past their plans (issue 23, the safety gap; uam_planner.nonconformance
        # .overruns): request id -> Overrun, deconflicted against until its projection lands
        self.overruns: dict = {}
        self.reaction_log: list = []   # the reports of the reactions between epochs

    @property
    def config(self) -> PlanningConfig:
        """The PlanningConfig; assigning a new one rebuilds the route cache only if k,
        penalty_factor, speed_mps or the vertical rates changed."""
        return self._config

    @config.setter
    def config(self, cfg: PlanningConfig) -> None:
        if not isinstance(cfg, PlanningConfig):
            raise TypeError(f"config must be a PlanningConfig, got {type(cfg).__name__}")
        old = self._config
        self._config = cfg
        # the horizon's conflicts between epochs (keyed by the route cache's templates, in this
        # config's separation): begun afresh with every config
        self.pair_cache = CandidatePairCache()
        route_fields = ("k", "penalty_factor", "speed_mps")
        vertical = ("climb_rate_mps", "descent_rate_mps")
        if old is None or any(getattr(old, f) != getattr(cfg, f) for f in route_fields) or \
                any(getattr(old.airspace, f) != getattr(cfg.airspace, f) for f in vertical):
            self.cache = CandidateCache(self.network, cfg.k, cfg.penalty_factor, cfg.speed_mps,
                                        cfg.airspace.climb_rate_mps,
                                        cfg.airspace.descent_rate_mps)
            if cfg.precompute_routes:
                self.cache.precompute()

    def set_constraints(self, constraints) -> None:
        """Plan from the next epoch on against ``constraints`` (a ConstraintSet, an iterable of
        Constraint checked against this planner's network, or None for none).

        A constraint with a finite ``announce_s`` is held back and added (an 'add' update, see
        :meth:`update_constraint`) at the first epoch at a time >= announce_s, when the flights
        it affects are re-planned; the others apply from the next epoch, and flights already
        approved are not revisited by this call. Replaces every constraint and every queued
        update given before."""
        from dataclasses import replace
        from .replanning import ConstraintUpdate
        if constraints is not None and not isinstance(constraints, ConstraintSet):
            constraints = ConstraintSet(constraints, self.network)
        now = [c for c in (constraints or ()) if not math.isfinite(c.announce_s)]
        later = sorted((c for c in (constraints or ()) if math.isfinite(c.announce_s)),
                       key=lambda c: c.announce_s)
        self._queued_updates = []
        for c in later:
            self._update_seq += 1
            self._queued_updates.append(ConstraintUpdate("add", c, float(c.announce_s), self._update_seq))
        if constraints is not None and later:
            constraints = ConstraintSet(now, self.network)
        self.initial_constraints = tuple(now)
        self.config = replace(self.config, constraints=constraints)

    def _projected_constraints(self) -> dict:
        """constraint id -> Constraint once every queued update is applied."""
        cur = {c.constraint_id: c for c in (self.config.constraints or ())}
        for u in sorted(self._queued_updates, key=lambda u: (u.t_s, u.seq)):
            if u.action == "withdraw":
                cur.pop(u.constraint.constraint_id, None)
            else:
                cur[u.constraint.constraint_id] = u.constraint
        return cur

    def update_constraint(self, action: str, constraint, t_s: float) -> str | None:
        """Queue a live constraint update; return None if accepted, else the reason (naming the
        field and value; nothing changes then).

        Args:
            action: 'add' (a new id), 'change' (a known id with a higher version) or
                'withdraw' (a known id; ``constraint`` may be the Constraint or its id).
            constraint: a ``uam_planner.constraints.Constraint`` (or an id for 'withdraw').
            t_s: when it is announced [s]; it is applied at the first epoch at a time >= t_s
                (or the next epoch, if that time has passed), before that epoch's requests are
                planned: the flights it affects are re-planned then (:mod:`uam_planner.replanning`)
                and the results are that epoch's ``EpochResult.plan_updates``. A constraint
                whose window has ended by t_s is refused.
        """
        from .replanning import ConstraintUpdate, check_update
        current = self._projected_constraints()
        reason = check_update(action, constraint, t_s, current, self.network)
        if reason is not None:
            return reason
        c = current[constraint if isinstance(constraint, str) else constraint.constraint_id] \
            if action == "withdraw" else constraint
        self._update_seq += 1
        self._queued_updates.append(ConstraintUpdate(action, c, float(t_s), self._update_seq))
        return None

    @property
    def queued_updates(self) -> list:
        """The constraint updates not applied yet, in the order they will be applied."""
        return sorted(self._queued_updates, key=lambda u: (u.t_s, u.seq))

    def replan_policy(self) -> str:
        """The re-plan policy in use: ``config.replan_policy``, or by default "mwis" for the MWIS
        policy and "firstfit" for the baselines."""
        return self.config.replan_policy or ("mwis" if self.policy == "mwis" else "firstfit")

    def _apply_constraint_updates(self, t_s: float, epoch_index: int):
        """The one place constraint updates take effect (issue 22): at the epoch at ``t_s``,
        after landed flights are dropped and before the epoch's requests are planned. Applies
        every queued update due by ``t_s`` and, if one added or changed a constraint,
        re-plans the affected flights (``uam_planner.replanning.replan_steps``) and replaces
        them in ``active`` by their new versions (cancelled ones removed). A generator: it
        yields the re-plan's MWIS graphs (see :meth:`prepare_steps`)."""
        from dataclasses import replace
        from .replanning import apply_updates, replan_steps
        self._plan_updates, self._replan_report = [], None
        due = [u for u in self._queued_updates if u.t_s <= t_s]
        if not due:
            return
        due.sort(key=lambda u: (u.t_s, u.seq))
        self._queued_updates = [u for u in self._queued_updates if u.t_s > t_s]
        cset = apply_updates(self.config.constraints, due, self.network)
        applied = [replace(u, applied_s=float(t_s)) for u in due]
        self.constraint_log.extend(applied)
        self.config = replace(self.config, constraints=cset)
        labels = [f"{u.action} {u.constraint.label()}" for u in applied]
        if not any(u.action != "withdraw" for u in applied):
            from .replanning import ReplanReport
            self._replan_report = ReplanReport(t_s=float(t_s), policy=self.replan_policy(), updates=labels)
            return
        cfg = self.config
        active, updates, report = yield from replan_steps(
            t_s, epoch_index, self.active, self._requests, self.network, cfg, self.cache, cset,
            replan_selector(self.solve_mwis, cfg, epoch_index, t_s),
            lambda t, r: departure_slots_s(t, r, cfg), self.replan_policy(), labels=labels,
            # the flights held past their plans (issue 23) are in the air: every re-planned
            # version avoids their projections as it avoids the other active flights
            held=[(k, h.trajectory) for k, o in self.overruns.items() for h in o.flights])
        self.active = active
        self._plan_updates, self._replan_report = updates, report

    def observe(self, request_id: str, t_s: float, position_m) -> str | None:
        """The planner's own observation of a vehicle (its position in the fleet state at
        ``t_s``); what a nonconformance report is checked against. Returns None, or why the
        observation was refused (naming the field and value)."""
        return self.positions.observe(request_id, t_s, position_m)

    def report_nonconforming(self, request_id: str, t_s: float, source: str = "") -> str | None:
        """A claim that ``request_id`` is nonconforming at ``t_s`` (from the conformance
        monitor). None if queued, else why it is refused (naming the field and value). Queued
        claims are checked at the first epoch at a time >= t_s against the planner's own plan and
        observation (:func:`uam_planner.nonconformance.verify`) and acted on only if they hold:
        a report can at worst cause one deconflicted update of a flight the planner itself sees
        outside its plan, never the removal of a flight."""
        if self.config.conformance is None:
            return "conformance: the reaction to nonconformance is off (PlanningConfig.conformance is None)"
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
                or not math.isfinite(t_s):
            return f"t_s: {t_s!r} is not a finite time"
        if not isinstance(request_id, str) or not (
                any(f.request_id == request_id for f in self.active) or request_id in self.overruns):
            return f"request_id: {request_id!r} is neither an active flight of this planner nor held past its plan"
        if any(c.request_id == request_id for c in self._claims):
            return None  # already queued: one update per flight and epoch
        self._claims.append(Claim(request_id, float(t_s), str(source)))
        return None

    def _react_to_nonconformance(self, t_s: float, epoch_index: int):
        """Step 2b of ``prepare`` (after the constraint re-plan, before new requests): the claims
        due by ``t_s`` that the planner's own view confirms get their intents updated from where
        the flights are (``uam_planner.nonconformance.react_steps``), deconflicted in one batch.
        A claim may be about a flight held past its plan (``self.overruns``: late, still in the
        air after its planned arrival): its newest version joins the batch like an active flight
        and, updated, is active again. A generator: it yields the batch's MWIS graph (see
        :meth:`prepare_steps`)."""
        self._nonconformance_report = None
        due = [c for c in self._claims if c.t_s <= t_s]
        probe_s = float(self.config.conflict_probe_s)
        if (not due and not probe_s) or self.config.conformance is None:
            return
        self._claims = [c for c in self._claims if c.t_s > t_s]
        where = {f.request_id: i for i, f in enumerate(self.active)}
        found, refused, readmitted = {}, [], set()
        for c in due:
            i = where.get(c.request_id)
            held = self.overruns.get(c.request_id) if i is None else None
            if i is None and held is None:
                refused.append((c.request_id, f"request_id: {c.request_id!r} is neither active "
                                              f"nor held past its plan"))
                continue
            flight = self.active[i] if held is None else held.plan
            obs = self.positions.latest(c.request_id, until=t_s)
            got, why = verify(flight, obs, self.config.conformance, t_s)
            if got is None:
                refused.append((c.request_id, why))
                continue
            if held is not None:
                # held past its plan (dropped from the active flights at this epoch, still in
                # the air): its plan is updated like an active one's, from where it is
                self.active.append(flight)
                i = len(self.active) - 1
                readmitted.add(id(flight))
            found[i] = (obs, got)
        updates, rep_ = yield from self._update_batch(t_s, epoch_index, found)
        if readmitted:   # one left without an update (nothing of its plan left) stays held only
            self.active = [f for f in self.active if id(f) not in readmitted]
        rep_["refused"] = refused
        self._nonconformance_report = rep_
        if probe_s:
            yield from self._probe(t_s, epoch_index, {u.request_id for u in updates})

    def _update_batch(self, t_s: float, epoch_index: int, found: dict, probed: dict | None = None,
                      held: Sequence = ()):
        """One batch of the reaction (``nonconformance.react_steps``) on the active flights,
        deconflicted against every other one and the held flights' projections; the new
        versions replace the old in ``self.active`` and join this epoch's plan updates.
        A generator (it yields the batch's MWIS graph); returns (updates, report)."""
        from .replanning import _Router
        cfg = self.config
        mine = {self.active[i].request_id for i in found}
        router = _Router(self.network, self.cache, cfg.constraints if cfg.constraints is not None
                         else (), t_s)
        active, updates, rep_ = yield from react_steps(
            t_s, epoch_index, self.active, found, self.positions, cfg,
            replan_selector(self.solve_mwis, cfg, epoch_index, t_s), self.replan_policy(), self.network,
            fixed=[h.trajectory for k, o in self.overruns.items() if k not in mine for h in o.flights],
            fixed_ids=[k for k, o in self.overruns.items() if k not in mine for _h in o.flights],
            probed=probed, held=held, router=router)
        for u in updates:   # the new version is drawn from where it is: its overrun is redrawn
            self.overruns.pop(u.request_id, None)
        self.active = active
        self._plan_updates = list(self._plan_updates) + list(updates)
        return updates, rep_

    def _probe(self, t_s: float, epoch_index: int, updated: set):
        """The conflict probe (``PlanningConfig.conflict_probe_s``, docs/disturbances.md), after
        the reaction to reported nonconformance: the airborne flights not updated just now whose
        rest of plan, flown from the planner's own newest sighting at their observed progress
        rate, loses the true minimum with another's within the look-ahead are updated from where
        they are, in one batch (each may also keep its plan: it conforms). A generator: it
        yields the batch's MWIS graph."""
        cfg = self.config
        skip = [i for i, f in enumerate(self.active) if f.request_id in updated]
        got = predicted_conflicts(self.active, self.positions, t_s, float(cfg.conflict_probe_s),
                                  cfg.probe_separation, exclude=skip)
        if not got:
            return
        found = {}
        for i, (obs, _ids) in got.items():   # the sighting the projection started from
            errs = deviations(self.active[i].trajectory, [obs.t_s], [obs.position_m])
            found[i] = (obs, tuple(float(x[0]) for x in errs))
        # the flights they are predicted to meet: those due to depart may be held on the pad
        # (``_probe_batch_steps`` keeps only those)
        where = {f.request_id: i for i, f in enumerate(self.active)}
        held = sorted({where[r] for _obs, ids in got.values() for r in ids if r in where})
        _updates, rep_ = yield from self._update_batch(
            t_s, epoch_index, found, probed={i: ids for i, (_obs, ids) in got.items()}, held=held)
        rep = self._nonconformance_report or {}
        rep["probe"] = {k: v for k, v in rep_.items() if k != "rates"}
        self._nonconformance_report = rep

    def react_between(self, t_s: float, epoch_index: int) -> list:
        """:meth:`react_between_steps` with the reaction's MWIS graph solved here (``solve_mwis``)."""
        from .replanning import SOLVE_HERE, run_steps
        return run_steps(self.react_between_steps(t_s, epoch_index), lambda _graph: SOLVE_HERE)

    def react_between_steps(self, t_s: float, epoch_index: int):
        """The reaction between epochs (issue 23 item 3; F3548 asks a nonconforming intent to be
        updated within 5 s, an epoch is 30 s): the claims due by ``t_s`` are checked and acted on
        now, exactly as at step 2b of :meth:`prepare` (the planner's own observations stamped up
        to ``t_s``, its newest plans; every update deconflicted against every other active flight
        and every held flight's projections from ``t_s`` on). Returns the PlanUpdates (also in
        ``self.reaction_log``); the active flights take the new versions at once. Nothing else
        changes: no request is planned, no flight dropped. Not while an epoch is prepared.
        A generator, as :meth:`prepare_steps`: it yields the reaction's MWIS graph and takes back
        the solver's answer (the planner node awaits the solver service for it); its return
        value is the list of PlanUpdates."""
        if self._prepared is not None:
            raise RuntimeError(f"epoch {self._prepared.epoch_index} is prepared but not committed")
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if self.config.conformance is None or (not self._claims and not self.config.conflict_probe_s):
            return []
        self._hold_overruns(t_s)
        saved, saved_rep = self._plan_updates, self._nonconformance_report
        self._plan_updates = []
        try:
            yield from self._react_to_nonconformance(t_s, epoch_index)
            updates, rep = list(self._plan_updates), self._nonconformance_report
        finally:
            self._plan_updates, self._nonconformance_report = saved, saved_rep
        if rep is not None and (updates or rep.get("refused")):
            self.reaction_log.append(rep)
        return updates

    def _default_solve(self, weights, edges, groups):
        return default_solve_mwis(self._config)(weights, edges, groups)

    def record_rejection(self) -> None:
        """Count a request rejected before ``submit`` (e.g. a malformed message) in the next
        epoch's report."""
        self._rejected_since_plan += 1

    def validate(self, request: FlightRequest) -> str | None:
        """Why ``request`` cannot be accepted (naming the field and value), or None."""
        rid = getattr(request, "request_id", None)
        if not isinstance(rid, str) or not rid:
            return f"request_id: {rid!r} is not a non-empty string"
        if rid in self._known_ids:
            return f"request_id: {rid!r} duplicates an earlier request"
        net = self.network
        for name in ("origin_id", "destination_id"):
            node = getattr(request, name)
            i = net.index.get(node) if isinstance(node, str) else None
            if i is None:
                return f"{name}: {node!r} is not a node of network {net.name!r}"
            if not net.is_aerodrome[i]:
                return f"{name}: {node!r} is not an aerodrome of network {net.name!r}"
        if request.origin_id == request.destination_id:
            return (f"destination_id: {request.destination_id!r} is the same as origin_id "
                    f"{request.origin_id!r}")
        for name in ("request_time_s", "earliest_departure_s", "latest_departure_s"):
            v = getattr(request, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not math.isfinite(v):
                return f"{name}: {v!r} is not a finite time"
        problem = check_priority(getattr(request, "priority", 0))
        if problem:
            return problem
        op = getattr(request, "operator_id", "")
        if not isinstance(op, str):
            return f"operator_id: {op!r} is not a string"
        if request.latest_departure_s < request.earliest_departure_s:
            return (f"latest_departure_s: {request.latest_departure_s!r} is before "
                    f"earliest_departure_s {request.earliest_departure_s!r}")
        if net.layered:
            # vertiports are terminals: a pair may have no route that avoids the others (the
            # Network only guarantees reachability through them); the routes are cached anyway
            try:
                self.cache.templates(net.index[request.origin_id], net.index[request.destination_id])
            except ValueError as exc:
                return f"destination_id: {exc}"
        return None

    def submit(self, request: FlightRequest) -> str | None:
        """Queue ``request``; return None if accepted, else the rejection reason."""
        reason = self.validate(request)
        if reason is not None:
            self._rejected_since_plan += 1
            return reason
        self._known_ids.add(request.request_id)
        self.pending.append(request)
        return None

    def prepare(self, t_s: float, epoch_index: int) -> PreparedEpoch:
        """Prepare the epoch at ``t_s`` [s] up to its conflict graph; finish with :meth:`commit`.

        Requests submitted between prepare and commit wait for the next epoch. One prepared
        epoch at a time. The re-plan's graphs (step 2) are solved with ``solve_mwis`` here;
        :meth:`prepare_steps` hands them to the caller instead.
        """
        from .replanning import SOLVE_HERE, run_steps
        return run_steps(self.prepare_steps(t_s, epoch_index), lambda _graph: SOLVE_HERE)

    def prepare_steps(self, t_s: float, epoch_index: int):
        """:meth:`prepare` as a generator: it yields each MWIS graph of step 2's batch re-plan
        (``uam_planner.replanning.replan_steps``) and of step 2b's reaction to nonconforming
        flights (``uam_planner.nonconformance.react_steps``), and takes back the solver's answer for it
        (``send``: the answer, a reason string, or ``replanning.SOLVE_HERE``); its return value
        is the PreparedEpoch. The planner node awaits the solver service between the steps, as
        it does for the epoch's own graph; the decisions are those of :meth:`prepare` given the
        same answers."""
        if not math.isfinite(t_s):
            raise ValueError(f"t_s must be finite, got {t_s!r}")
        if self._prepared is not None:
            raise RuntimeError(f"epoch {self._prepared.epoch_index} is prepared but not committed")
        self._hold_overruns(t_s)
        self.active = [f for f in self.active if f.arrival_s >= t_s]
        self.shares.advance(t_s)
        if self._requests:
            alive = {f.request_id for f in self.active}
            self._requests = {k: r for k, r in self._requests.items() if k in alive}
        yield from self._apply_constraint_updates(t_s, epoch_index)
        yield from self._react_to_nonconformance(t_s, epoch_index)
        # the traffic new requests are deconflicted against: the active flights, the held
        # flights' projections and, with the conflict probe, the airborne flights' projections
        # (new objects every epoch, after the active ones: the segment index stays incremental)
        held = [replace(h) for o in self.overruns.values() for h in o.flights]
        seen = self._projected_traffic(t_s)
        traffic = self.active + held + seen if held or seen else self.active
        if self.policy == "mwis":
            prep = prepare_epoch_mwis(t_s, epoch_index, self.pending, traffic, self.network, self.config,
                                      self.cache, self.active_index, self.shares,
                                      pair_cache=self.pair_cache)
        else:
            args = (t_s, epoch_index, self.pending, traffic, self.network, self.config)
            res = plan_epoch_fifo(*args, None, self.cache, self.active_index, self.shares) \
                if self.policy == "fifo" else \
                as_firstfit(plan_epoch_mwis(*args, first_fit_select, self.cache, self.active_index,
                                            self.shares, self.config.baseline_order,
                                            horizon=1))  # uam_planner.first_fit; myopic
            prep = PreparedEpoch(t_s=float(t_s), epoch_index=int(epoch_index), pending=list(self.pending),
                                 report=res.report, result=res)
        if held or seen:
            # each held flight is counted once (its plan, if still active, or one projection),
            # each projected one as its plan
            planned = {f.request_id for f in self.active}
            twice = sum(len(o.flights) - (k not in planned) for k, o in self.overruns.items())
            twice += len(seen)
            prep.airborne_count -= twice
            if prep.result is not None:
                prep.result.report.active_flights -= twice
            if held:
                prep.report.overruns = {k: o.until_s for k, o in self.overruns.items()}
        self._prepared = prep
        return prep

    def _projected_traffic(self, t_s: float) -> list:
        """With the conflict probe on (``conflict_probe_s``): every airborne flight's projection
        (from the planner's newest sighting at its observed progress rate, up to the look-ahead;
        ``nonconformance.projections``) as a Flight, traffic that new requests are deconflicted
        against beside its plan. Thirteenth stop: a flight approved to leave a vertiport at
        once kept the buffer from the plan of a flight landing there 15 s later, which landed
        4 s early (seen early by the probe): 91 m flown at a 25 m buffer. Empty otherwise."""
        cfg = self.config
        if cfg.conformance is None or not cfg.conflict_probe_s:
            return []
        from .nonconformance import projections
        return [replace(self.active[i], trajectory=pred, departure_s=float(pred.departure_s),
                        arrival_s=float(pred.arrival_s))
                for i, _obs, pred in projections(self.active, self.positions, t_s,
                                                 float(cfg.conflict_probe_s))]

    def _hold_overruns(self, t_s: float) -> None:
        """Step 1 of ``prepare``, before flights past their planned arrival are dropped: from
        the planner's own observations, the flights that fly past their plans and how long they
        are held (:func:`uam_planner.nonconformance.overruns`; docs/disturbances.md 2c). Then
        the held flights whose projection has landed by ``t_s`` are let go, and observations of
        flights the planner no longer holds are forgotten."""
        plans = {o.request_id: o.plan for o in self.overruns.values()}
        plans.update((f.request_id, f) for f in self.active)
        self.positions.prune(t_s)
        if self.overruns or self.positions:
            self.overruns = overruns(t_s, plans, self.positions, self.overruns)
        self.positions.forget(set(f.request_id for f in self.active if f.arrival_s >= t_s) |
                              set(self.overruns))

    def commit(self, prep: PreparedEpoch, answer=None, solve_s: float = 0.0) -> EpochResult:
        """Commit a prepared epoch with the solver's ``answer`` (checked here, greedy fallback)
        and update the planner's state: waiting requests stay, approvals become active."""
        if prep is not self._prepared:
            raise RuntimeError("commit: this epoch was not prepared by this planner (or is committed)")
        self._prepared = None
        result = commit_epoch(prep, answer, self.config, solve_s)
        result.plan_updates = list(self._plan_updates)
        result.report.replan = self._replan_report
        result.report.nonconformance = self._nonconformance_report
        self._plan_updates, self._replan_report, self._nonconformance_report = [], None, None
        if result.approved:
            by_id = {r.request_id: r for r in prep.pending}
            self._requests.update((f.request_id, by_id[f.request_id]) for f in result.approved
                                  if f.request_id in by_id)
        arrived_since = self.pending[len(prep.pending):]
        self.pending = list(result.waiting) + arrived_since
        self.active = self.active + list(result.approved)
        self.shares.record(prep.t_s, [operator_of(f) for f in result.approved],
                           [operator_of(r) for r in result.expired])
        result.report.rejected = self._rejected_since_plan
        self._rejected_since_plan = 0
        return result

    def plan(self, t_s: float, epoch_index: int) -> EpochResult:
        """Run one planning epoch at ``t_s`` [s] (prepare, solve with ``solve_mwis``, commit)."""
        prep = self.prepare(t_s, epoch_index)
        t = time.perf_counter()
        answer = call_solver(self.solve_mwis, prep.graph) if prep.needs_solver else None
        return self.commit(prep, answer, time.perf_counter() - t)

    def restore(self, flights: Sequence[Flight], decided_ids: Sequence[str] = ()) -> None:
        """Resume after a restart: ``flights`` are flying (they become active, their ids taken) and
        ``decided_ids`` were decided before (their ids are taken, nothing is planned for them).
        Adds only: a flight already active stays as it is, whatever ``flights`` says."""
        held = {f.request_id for f in self.active}
        new = [f for f in flights if f.request_id not in held]
        self.active = self.active + new
        for f in new:  # counted when they departed (the fair window's time)
            self.shares.record(f.departure_s, [operator_of(f)], [])
        self._known_ids.update(f.request_id for f in flights)
        self._known_ids.update(decided_ids)
        self.pending = [r for r in self.pending if r.request_id not in self._known_ids]

    def is_known(self, request_id: str) -> bool:
        """True once ``request_id`` was accepted (or restored): a later request with it is a duplicate."""
        return request_id in self._known_ids
