"""The parameters of the paper's study (:class:`ExperimentConfig`), read from YAML and flags and
checked: a bad value raises :class:`ExperimentError` naming the field and the value."""

from __future__ import annotations

import math
from dataclasses import dataclass, field, replace
from pathlib import Path
from typing import Annotated, Any, Literal, Optional, Union

import yaml
from pydantic import ConfigDict, Field, Strict

from uam_contract import defaults
from uam_contract.validation import parse
from uam_planner.planning import AirspaceConfig, PlanningConfig

DEFAULT_METHODS = ("fifo", "firstfit", "greedy", "exact", "sa", "tabu", "qpu-emulator")
# methods that are planner policies, not MWIS backends (firstfit: uam_planner.first_fit)
BASELINES = ("fifo", "firstfit")
DEFAULT_RATES = (1, 2, 4, 6, 8, 10, 15, 20)
# Airspace modes of the capacity study: the paper's airspace, + departure slots, + flight levels,
# + both. Each mode is a preset of the airspace fields (filled in where the configuration does not
# give them) and says whether the network is the layered one (cruise levels, vertiport pads).
# Levels need the cylinder model: a 100 m sphere would make levels 30 m apart conflict.
AIRSPACE_MODES = ("paper", "slots", "levels", "both")
AVAILABLE_AIRSPACE_MODES = AIRSPACE_MODES
#: the departure slot [s] of the slot modes unless departure_slot_s is given
MODE_SLOT_S = 5.0
#: cruise levels [m] and pads per vertiport that a synthetic network gets in the layered modes
MODE_LEVELS_M = (60.0, 90.0, 120.0, 150.0)
MODE_PADS_PER_VERTIPORT = 4
AIRSPACE_PRESETS = {
    "paper": {"layered": False, "separation_model": "sphere", "departure_slot_s": 0.0},
    "slots": {"layered": False, "separation_model": "sphere", "departure_slot_s": MODE_SLOT_S},
    "levels": {"layered": True, "separation_model": "cylinder", "departure_slot_s": 0.0},
    "both": {"layered": True, "separation_model": "cylinder", "departure_slot_s": MODE_SLOT_S},
}
REPO_ROOT = Path(__file__).resolve().parents[4]


class ExperimentError(ValueError):
    """Bad experiment configuration; the message names the field and the value."""


# The schema of an experiment file (pydantic, docs/architecture.md): the annotations of
# ExperimentConfig's fields are what make_config validates (uam_contract.validation.parse: unknown
# keys, types, ranges; a refusal names the field and the value). The values are kept as given (a
# duration of 3500 stays the int 3500), since a cell's key hashes them. Ranges owned elsewhere
# (k, the airspace, the buffers: PlanningConfig; the demand mix: RequestGenerator; disturbance and
# conformance fields) are checked there, after the schema.
Str = Annotated[str, Strict()]
Int = Annotated[int, Strict()]
Float = Annotated[float, Strict()]  # an int is a number too (strict refuses True and "5")
Positive = Annotated[float, Strict(), Field(gt=0)]
Bool = Annotated[bool, Strict()]
List = list  # a tuple is a list too
Mapping = Annotated[dict, Strict()]


@dataclass
class ExperimentConfig:
    """Every parameter of a sweep (paper defaults). Times in seconds, distances in metres.

    Attributes:
        network: path of a network file (e.g. config/networks/singapore-layered.yaml), or
            {"synthetic": {n_nodes, n_aerodromes, seed, ...}} with any argument of
            ``uam_planner.synthetic.generate_network`` (levels_m, pads_per_vertiport, ...).
                methods: "fifo" (shortest FIFO), "firstfit" (first conflict-free candidate in arrival
            order) or an MWIS backend name per entry.
        include_qpu: add the "qpu" backend when it is available (a D-Wave token is configured).
        rates: requests per interval (the swept variable).
        seeds: seed list (an int n in YAML or flags means seeds 0..n-1).
        duration_s: simulated time per run; epochs at 0, epoch_s, ... < duration_s.
        epoch_s, interval_s, window_s: planning epoch, demand interval, departure window.
        separation_m, k, penalty_factor, speed_mps: planning parameters.
        separation_model, vertical_separation_m, departure_slot_s, climb_rate_mps,
            descent_rate_mps: the airspace mode (``uam_planner.planning.AirspaceConfig``; the
            defaults are the paper's model: sphere, departure at the epoch time).
        time_limit_s: MWIS time budget per epoch.
        solver_options: backend name -> options mapping passed to uam_solvers.solve.
        demand_file: optional demand file replayed instead of random demand (rates then only label
            the cells).
        constraints_file: optional airspace constraints (GeoJSON or ED-269, docs/constraints.md)
            every planner plans around from t = 0.
        corpus_max_vertices: MWIS instances up to this size are kept for the corpus.
        audit: run the independent exact separation audit on every cell.
        out: output directory.
        workers: processes for the cells (1 = serial in this process); with more than one, a
            Dask LocalCluster of that many single-threaded worker processes.
        scheduler: None or "local" (a LocalCluster of ``workers`` processes; serial when
            workers = 1), or a Dask scheduler address "tcp://HOST:8786" whose workers run the
            cells (uam_sim.runner.dask_cluster). Does not affect results, so not part of a cell's key.
        airspace_mode: the airspace of every cell (``AIRSPACE_PRESETS``): "paper" (the paper's
            model: one cruise altitude, 100 m sphere, departure at the epoch time); "slots" (+
            departure slots every ``MODE_SLOT_S`` s of the window); "levels" (+ the layered
            network: cruise levels, vertiport pads, cylinder separation); "both". The preset fills
            separation_model and departure_slot_s where they are not given (given values must
            agree with the mode), and the network becomes its layered form in "levels"/"both"
            (see :func:`mode_network`). A mode other than "paper" becomes part of each cell's key.
        objective: what the MWIS maximises ("paper", "count", "delay", "priority", "fair";
            ``uam_planner.objectives``, docs/objectives.md).
        baseline_order: the order of FIFO and first-fit: "arrival" (the paper's) or "priority"
            (class, then earliest latest departure, then arrival).
        priority_share, priority_class: the generator's priority mix (share of requests of that
            class, e.g. 0.05 and 1; 0 = none, the paper's).
        operators: operator ids the generator draws each request's operator from (none: "").
        horizon_epochs: epochs the MWIS plans jointly (rolling horizon; 1 = the paper's).
        fair_window_s: the "fair" objective's shares over a sliding window of the run [s]
            (0 = the whole run).
        commit_ahead: with horizon_epochs > 1, commit the later epochs' selected departures at
            once as reservations (never re-optimised) instead of planning them again.
        lead_time_s: requests are filed this long before their earliest departure [s].
        operator_lead_times_s: extra lead time [s] per operator (filing habits), as ``operators``.
        spatial_buffer_m, temporal_buffer_s: planning buffers on the separation
            (0 = none); audits keep the true minimum.
        disturbance: fields of ``uam_sim.world.disturbance.DisturbanceConfig`` (wind, gusts, speed
            error, departure delay, path following); {} = none, the plans flown exactly. The
            flights' draws are seeded by the cell's seed (the ``seed`` field is ignored).
        conformance: fields of ``uam_sim.world.conformance.ConformanceBounds`` ({} = the defaults).
        reaction: the planner reacts to nonconforming flights
            (``uam_planner.nonconformance``): the runner's monitor reports them, the planner
            checks each report against its own view and updates the intent; false (default) =
            no reaction. Needs ``disturbance``.
        reaction_period_s: with ``reaction``, the runner's monitor also reports, and the
            planner reacts, every this many seconds between epochs (``Planner.react_between``;
            F3548 asks an update within 5 s); 0 (default) = only at the epochs.
        conflict_probe_s: with ``reaction``, the planner's conflict probe look-ahead [s]
            (``PlanningConfig.conflict_probe_s``: conforming flights predicted to lose the
            minimum at their observed speeds are updated too); 0 (default) = no probe.
        conflict_probe_margin_m: with the probe, its margin [m]
            (``PlanningConfig.conflict_probe_margin_m``); 0 (default) = the true minimum.
        intent_volume_piece_s: F3548 mode: the published volumes' longest window [s]; > 0 keeps
            every two flights' volumes disjoint too (``PlanningConfig.intent_volume_piece_s``);
            0 (default) = the separation only.
        metrics_warmup_s: the decision metrics (delay, shares, ...) leave out requests whose
            earliest departure is before it (the warm-up); 0 = none.
        cumulative_rates: rates shown in the cumulative-approvals figure (default: up to 4 spread).
        tts: TTS study settings: enabled, instances (sampled from the runs' MWIS instances),
            min_vertices, max_vertices, reads (per annealing run), repetitions (runs per instance
            and backend), backends, backend_instances (backend -> a smaller seeded sub-sample
            for slow backends), seed, time_limit_s (per run); TTS(0.99) via uam_solvers.tts.
    """

    network: Union[Str, Path, dict] = "config/networks/singapore.yaml"
    methods: Union[Str, List] = field(default_factory=lambda: list(DEFAULT_METHODS))
    include_qpu: Bool = True
    rates: Any = field(default_factory=lambda: list(DEFAULT_RATES))  # a list or "1,2,4": _num_list
    seeds: Any = field(default_factory=lambda: list(range(5)))  # a count, a list or "3,7": _seeds
    duration_s: Positive = 3500.0
    epoch_s: Positive = defaults.EPOCH_S          # the paper's values, from uam_contract.defaults
    interval_s: Positive = defaults.INTERVAL_S
    window_s: Positive = defaults.WINDOW_S
    separation_m: Positive = defaults.SEPARATION_M
    k: Int = defaults.K
    penalty_factor: Float = defaults.PENALTY_FACTOR
    speed_mps: Positive = defaults.SPEED_MPS
    separation_model: Str = "sphere"
    vertical_separation_m: Float = AirspaceConfig.vertical_separation_m
    departure_slot_s: Float = defaults.DEPARTURE_SLOT_S
    climb_rate_mps: Float = AirspaceConfig.climb_rate_mps
    descent_rate_mps: Float = AirspaceConfig.descent_rate_mps
    time_limit_s: Positive = 10.0
    solver_options: Mapping = field(default_factory=dict)
    demand_file: Optional[Union[Str, Path]] = None
    constraints_file: Optional[Union[Str, Path]] = None
    corpus_max_vertices: Int = 60
    audit: Bool = True
    out: Union[Str, Path] = "results"
    workers: Annotated[int, Strict(), Field(ge=1)] = 2
    scheduler: Optional[Str] = None  # "local" or tcp://HOST:PORT: dask_cluster.validate_scheduler
    airspace_mode: Literal[AIRSPACE_MODES] = "paper"
    cumulative_rates: Any = None  # None, a list or "1,4": _num_list
    objective: Str = "paper"  # the choices: PlanningConfig
    baseline_order: Str = "arrival"
    priority_share: Float = 0.0  # ranges of the demand mix: RequestGenerator
    priority_class: Int = 1
    operators: Union[Str, List] = field(default_factory=list)
    horizon_epochs: Int = 1
    commit_ahead: Bool = False
    fair_window_s: Float = 0.0
    lead_time_s: Float = 0.0
    operator_lead_times_s: List = field(default_factory=list)
    metrics_warmup_s: Float = 0.0
    spatial_buffer_m: Float = 0.0  # ranges of the buffers: PlanningConfig
    temporal_buffer_s: Float = 0.0
    disturbance: Mapping = field(default_factory=dict)  # fields: DisturbanceConfig
    conformance: Mapping = field(default_factory=dict)  # fields: ConformanceBounds
    reaction: Bool = False
    reaction_period_s: Float = 0.0
    conflict_probe_s: Float = 0.0  # with the reaction: PlanningConfig.conflict_probe_s
    conflict_probe_margin_m: Float = 0.0  # with the probe: PlanningConfig.conflict_probe_margin_m
    intent_volume_piece_s: Float = 0.0  # F3548 mode: PlanningConfig.intent_volume_piece_s
    tts: Optional[Mapping] = field(default_factory=lambda: {
        "enabled": True, "instances": 629, "min_vertices": 5, "max_vertices": 50, "reads": 100,
        "repetitions": 5, "backend_instances": {"qpu-emulator": 60},
        "backends": ["exact", "greedy", "sa", "tabu", "qpu-emulator"], "p": 0.99, "seed": 0,
        "time_limit_s": 10.0})

    __pydantic_config__ = ConfigDict(extra="forbid", allow_inf_nan=False)

    def airspace(self) -> AirspaceConfig:
        """The AirspaceConfig of these parameters (raises ValueError naming a bad field)."""
        return AirspaceConfig(separation_model=self.separation_model,
                              vertical_separation_m=self.vertical_separation_m,
                              departure_slot_s=self.departure_slot_s,
                              climb_rate_mps=self.climb_rate_mps,
                              descent_rate_mps=self.descent_rate_mps)

    @property
    def paper_airspace(self) -> bool:
        """True for the paper's airspace model (sphere, departure at the epoch time)."""
        return self.airspace() == AirspaceConfig()

    def separation(self):
        """The run's SeparationModel (what the planner keeps and the audit checks)."""
        return self.planning_config("greedy", 0).minimum_separation  # never the buffered one

    def planning_config(self, backend: str, seed: int) -> PlanningConfig:
        return PlanningConfig(epoch_s=self.epoch_s, separation_m=self.separation_m, k=self.k,
                              penalty_factor=self.penalty_factor, speed_mps=self.speed_mps,
                              backend=backend, time_limit_s=self.time_limit_s, seed=int(seed),
                              airspace=self.airspace(), objective=self.objective,
                              baseline_order=self.baseline_order,
                              horizon_epochs=self.horizon_epochs,
                              commit_ahead=self.commit_ahead, fair_window_s=self.fair_window_s,
                              spatial_buffer_m=self.spatial_buffer_m,
                              temporal_buffer_s=self.temporal_buffer_s,
                              conformance=self.conformance_bounds() if self.reaction else None,
                              conflict_probe_s=self.conflict_probe_s if self.reaction else 0.0,
                              conflict_probe_margin_m=self.conflict_probe_margin_m
                              if self.reaction and self.conflict_probe_s else 0.0,
                              intent_volume_piece_s=self.intent_volume_piece_s)

    def disturbance_config(self):
        """The DisturbanceConfig of ``disturbance`` (off when empty); its seed is the cell's."""
        from ..world.disturbance import DisturbanceConfig
        return DisturbanceConfig.from_mapping(self.disturbance)

    def conformance_bounds(self):
        from ..world.conformance import ConformanceBounds
        return ConformanceBounds(**dict(self.conformance or {}))


def _num_list(name: str, value, cast=float) -> list:
    if isinstance(value, str):
        value = [v for v in value.split(",") if v.strip()]
    if not isinstance(value, (list, tuple)) or not value:
        raise ExperimentError(f"{name}: {value!r} must be a non-empty list")
    out = []
    for v in value:
        try:
            x = cast(v)
        except (TypeError, ValueError):
            raise ExperimentError(f"{name}: item {v!r} is not a number") from None
        if isinstance(x, float) and (not math.isfinite(x) or x < 0):
            raise ExperimentError(f"{name}: item {v!r} must be finite and >= 0")
        out.append(x)
    return out


def _seeds(value) -> list:
    if isinstance(value, bool):
        raise ExperimentError(f"seeds: {value!r} is not a count or a list")
    if isinstance(value, int) or (isinstance(value, str) and value.strip().isdigit()):
        n = int(value)
        if n < 1:
            raise ExperimentError(f"seeds: {value!r} must be >= 1")
        return list(range(n))
    seeds = _num_list("seeds", value, int)
    if any(s < 0 for s in seeds):
        raise ExperimentError(f"seeds: {value!r} must be >= 0")
    return seeds


def rate_label(x: float):
    return int(x) if float(x).is_integer() else float(x)


def make_config(data: dict | None = None, **overrides) -> ExperimentConfig:
    """An ExperimentConfig from a mapping (the YAML file) and overrides (flags; None = unset)."""
    data = dict(data or {})
    data.update({k: v for k, v in overrides.items() if v is not None})
    parse(ExperimentConfig, data, error=ExperimentError)  # unknown keys, types, ranges
    cfg = ExperimentConfig()
    tts = dict(cfg.tts)
    tts.update(data.pop("tts", None) or {})
    cfg = replace(cfg, **data, tts=tts)
    methods = cfg.methods.split(",") if isinstance(cfg.methods, str) else list(cfg.methods)
    if not methods or not all(isinstance(m, str) and m for m in methods):
        raise ExperimentError(f"methods: {cfg.methods!r} must be a non-empty list of names")
    cfg.methods = [m.strip() for m in methods]
    from uam_solvers.registry import backend_names
    known = list(BASELINES) + backend_names()
    for m in cfg.methods:
        if m not in known:
            raise ExperimentError(f"methods: {m!r} is not a method (known: {', '.join(known)})")
    if isinstance(cfg.network, (str, Path)) and not resolve_path(str(cfg.network)).is_file():
        raise ExperimentError(f"network: file {str(cfg.network)!r} does not exist")
    if cfg.demand_file and not resolve_path(str(cfg.demand_file)).is_file():
        raise ExperimentError(f"demand_file: file {str(cfg.demand_file)!r} does not exist")
    if cfg.constraints_file and not resolve_path(str(cfg.constraints_file)).is_file():
        raise ExperimentError(f"constraints_file: file {str(cfg.constraints_file)!r} does not exist")
    rp = cfg.reaction_period_s
    if not (math.isfinite(rp) and 0.0 <= rp <= cfg.epoch_s):
        raise ExperimentError(f"reaction_period_s: {rp!r} is not in [0, epoch_s = {cfg.epoch_s:g}] s")
    cfg.rates = [rate_label(r) for r in _num_list("rates", cfg.rates)]
    cfg.seeds = _seeds(cfg.seeds)
    from .dask_cluster import validate_scheduler
    try:
        cfg.scheduler = validate_scheduler(cfg.scheduler)
    except ValueError as exc:
        raise ExperimentError(str(exc)) from None
    if cfg.airspace_mode != "paper":
        cfg = _apply_mode(cfg, given=set(data))
    if cfg.cumulative_rates is not None:
        cfg.cumulative_rates = [rate_label(r) for r in _num_list("cumulative_rates", cfg.cumulative_rates)]
    if isinstance(cfg.operators, str):
        cfg.operators = [o.strip() for o in cfg.operators.split(",") if o.strip()]
    try:
        from ..world.demand import DemandError, RequestGenerator
        RequestGenerator(["a", "b"], 0, priority_share=cfg.priority_share,
                         priority_class=cfg.priority_class, operators=cfg.operators,
                         lead_time_s=cfg.lead_time_s,
                         operator_lead_times_s=cfg.operator_lead_times_s)
    except DemandError as exc:
        raise ExperimentError(str(exc)) from None
    try:
        cfg.disturbance_config()
        cfg.conformance_bounds()
    except (TypeError, ValueError) as exc:
        raise ExperimentError(str(exc).replace("DisturbanceConfig.", "disturbance.")
                              .replace("ConformanceBounds.", "conformance.")) from None
    try:
        cfg.planning_config("greedy", 0)  # validates k, penalty_factor and the airspace
    except ValueError as exc:
        raise ExperimentError(str(exc).replace("AirspaceConfig.", "").replace("PlanningConfig.", "")) from None
    return cfg


def mode_network(network, mode: str):
    """The network a mode flies on: the flat one for "paper"/"slots", the layered one for
    "levels"/"both". A synthetic spec gets (or must not have) ``levels_m`` and pads; a file
    ``X.yaml`` is replaced by its layered sibling ``X-layered.yaml`` (a file that already declares
    levels is kept). Raises ExperimentError naming the network when no such form exists."""
    layered = AIRSPACE_PRESETS[mode]["layered"]
    if isinstance(network, dict):
        spec = dict(network.get("synthetic") or {})
        if layered:
            spec.setdefault("levels_m", list(MODE_LEVELS_M))
            spec.setdefault("pads_per_vertiport", MODE_PADS_PER_VERTIPORT)
        elif spec.get("levels_m"):
            raise ExperimentError(f"network: {network!r} declares levels_m, which airspace_mode "
                                  f"{mode!r} does not fly (use 'levels' or 'both')")
        return {"synthetic": spec}
    from uam_planner.network import load_network
    path = resolve_path(str(network))
    if not path.exists():
        raise ExperimentError(f"network: file {str(network)!r} does not exist")
    is_layered = bool(load_network(path).levels_m)
    if layered == is_layered:
        return str(network)
    if layered:
        sibling = Path(str(network)).with_name(Path(str(network)).stem + "-layered.yaml")
        if resolve_path(str(sibling)).exists():
            return str(sibling)
        raise ExperimentError(f"network: {str(network)!r} has no cruise levels and no layered form "
                              f"{str(sibling)!r} exists, which airspace_mode {mode!r} needs")
    raise ExperimentError(f"network: {str(network)!r} is a layered network; airspace_mode {mode!r} "
                          f"flies the flat one (give that file)")


def _apply_mode(cfg: ExperimentConfig, given: set) -> ExperimentConfig:
    """Fill the airspace fields from the mode's preset and check the given ones agree with it."""
    mode = cfg.airspace_mode
    preset = AIRSPACE_PRESETS[mode]
    changes = {}
    if "separation_model" in given:
        if cfg.separation_model != preset["separation_model"]:
            raise ExperimentError(f"separation_model: {cfg.separation_model!r} disagrees with "
                                  f"airspace_mode {mode!r} (which flies {preset['separation_model']!r})")
    else:
        changes["separation_model"] = preset["separation_model"]
    slots = preset["departure_slot_s"] > 0
    if "departure_slot_s" in given:
        if (float(cfg.departure_slot_s) > 0) != slots:
            raise ExperimentError(f"departure_slot_s: {cfg.departure_slot_s!r} disagrees with "
                                  f"airspace_mode {mode!r} ({'slots' if slots else 'no slots'})")
    else:
        changes["departure_slot_s"] = preset["departure_slot_s"]
    changes["network"] = mode_network(cfg.network, mode)
    return replace(cfg, **changes)


def load_config(path, **overrides) -> ExperimentConfig:
    """Read a YAML experiment file (see config/experiment.yaml) and apply overrides."""
    path = Path(path)
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if not isinstance(data, dict):
        raise ExperimentError(f"{path}: expected a mapping of parameters, got {type(data).__name__}")
    return make_config(data, **overrides)


def resolve_path(path: str) -> Path:
    p = Path(path)
    if not p.is_absolute() and not p.exists() and (REPO_ROOT / p).exists():
        p = REPO_ROOT / p
    return p
