"""The planning configuration: requests, flights, the airspace model and PlanningConfig (its
fields, defaults and the checks of their values), free of ROS."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
from uam_contract import defaults

from .candidates import DEFAULT_CLIMB_RATE_MPS, DEFAULT_DESCENT_RATE_MPS
from .constraints import ConstraintSet
from .nonconformance import ConformanceBounds
from .objectives import BASELINE_ORDERS, check_objective
from .separation import (
    DEFAULT_VERTICAL_SEPARATION_M,
    SEPARATION_MODELS,
    SeparationModel,
)
from .trajectory import Trajectory

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

    Plan versions (docs/replanning.md): ``version`` counts the plans of one request
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
        spatial_buffer_m, temporal_buffer_s: planning buffers on the separation
            (docs/disturbances.md); 0 = today's. The planner keeps ``separation`` (the minimum
            widened by both), every audit keeps ``minimum_separation``.
        conflict_probe_s: with ``conformance`` set, the conflict probe's look-ahead [s]
            (``uam_planner.nonconformance.predicted_conflicts``): at every reaction, flights
            whose rest of plan, flown from where the planner last saw them at their observed
            progress rate, loses the true minimum within it are updated as nonconforming ones
            are; 0 (default) = no probe (only reported, confirmed nonconformance is acted on).
        conflict_probe_margin_m: with the probe on, its margin [m]: it predicts
            losses of the true minimum widened by this much (``probe_separation``), and its own
            batches deconflict their updates with the wider of that and ``separation``: a
            tactical buffer kept only between the flights that are predicted to come close,
            beside the strategic buffer every plan keeps; 0 (default) = the true minimum.
        priority_grants: ``uam_planner.grants.PriorityGrants``: a request above its operator's
            granted class is refused naming the grant; None (default) takes every class.
        intent_volume_piece_s: F3548 mode: the longest time window of one published volume [s]
            (the USS's ``volume_piece_s``); > 0 keeps the published volumes of every two flights
            disjoint at F3548's 1 cm, beside the separation (``uam_planner.intent_volumes``;
            ``intent_volumes`` is the VolumeSpec); 0 (default) = the separation only.
        conformance: the reaction to nonconforming flights
            (``uam_planner.nonconformance``): a ConformanceBounds the planner checks each
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
    priority_grants: object = None   # uam_planner.grants.PriorityGrants; None: every class taken
    intent_volume_piece_s: float = 0.0

    @property
    def intent_volumes(self):
        """The VolumeSpec of the intents the USS publishes for these plans (r_h, r_v from the true
        minimum, as ``uam_sim``'s USS makes it), or None when ``intent_volume_piece_s`` is 0."""
        if not self.intent_volume_piece_s:
            return None
        from .f3548 import VolumeSpec   # uas_standards' types load only in F3548 mode
        return VolumeSpec.for_separation(self.minimum_separation, float(self.intent_volume_piece_s))

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
                     "conflict_probe_margin_m", "intent_volume_piece_s"):
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


