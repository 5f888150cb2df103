"""One scenario in process (a cell of the study): the seeded request generator feeding one
:class:`~uam_planner.planning.Planner` epoch by epoch, with one method, audited at the end."""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from uam_planner import separation
from uam_planner.planning import Planner

from ..audit.record import PlanVersion
from ..audit.separation import sweep_audit
from ..world.flights import run_metrics
from ..world.demand import RequestGenerator
from .experiment_config import BASELINES, ExperimentConfig, ExperimentError, rate_label


@dataclass
class ScenarioResult:
    """One cell's outcome.

    Attributes:
        method, rate, seed, duration_s: the cell.
        summary: one tidy row (counts, average aircraft in the air, solve-time stats, audit, the
            objective and the flight metrics of ``uam_sim.world.flights.run_metrics``: delay mean,
            p95 and delayed share from the earliest departure, detour, per-priority p95 delay,
            per-operator approval shares and Jain index, route lengths).
        epochs: one row per epoch (t_s, counts so far, MWIS size, solve time, fallback, ...).
        flights: one row per approved flight (ids, epoch, earliest departure, departure/arrival,
            route, weight, priority, operator, shortest candidate route length).
        audit: the exact separation audit over all flown flights (min_separation_m, losses,
            pairs_checked) or {} when disabled.
        instances: MWIS instances (weights, edges incl. clique edges, groups) of this run with
            1..corpus_max_vertices vertices, with their epoch index.
        rejections: (request_id, reason) of requests the planner refused at submission.
        wall_s: wall time of the run.
        replans: one row per plan update (``uam_planner.replanning``): t_s,
            request_id, kind, version, constraint ids, added delay, airborne (bool); empty
            when no constraint changed during the run.
    """

    method: str
    rate: float
    seed: int
    duration_s: float
    summary: dict
    epochs: list
    flights: list
    audit: dict
    instances: list
    rejections: list
    wall_s: float
    replans: list = field(default_factory=list)
    #: every request submitted (id, earliest / latest departure, operator, priority): the
    #: decision study's steady-state window and per-operator shares
    requests: list = field(default_factory=list)
    #: the run's record (``uam_sim.audit.record.RunRecord``): what was in force; not stored
    #: with the study's cells
    record: object = field(default=None, repr=False, compare=False)

    def decisions(self) -> dict:
        """request id -> (epoch, candidate) of each approval: what must match across runs."""
        return {f["request_id"]: (f["epoch"], f["candidate_index"]) for f in self.flights}


def _solver(method: str, cfg: ExperimentConfig, seed: int):
    import uam_solvers
    options = dict(cfg.solver_options.get(method) or {})

    from uam_solvers.executor import shared_service

    shared_service()  # workers started and warmed now, not in the first epoch

    def solve(weights, edges, groups):
        # the solver node's deadline mechanism (uam_solvers.executor): limit + ~0.5 s at most
        return uam_solvers.solve_bounded(weights, edges, groups=groups, backend=method,
                                         time_limit_s=cfg.time_limit_s, seed=int(seed),
                                         options=options)
    return solve


def average_airborne(departures_s, arrivals_s, duration_s: float) -> float:
    """Time-average number of aircraft in the air over [0, duration_s], integrated exactly.

    Each flight counts for the part of [departure, arrival] inside the window. O(F).
    """
    d = np.asarray(departures_s, dtype=np.float64)
    a = np.asarray(arrivals_s, dtype=np.float64)
    if d.size == 0:
        return 0.0
    inside = np.clip(np.minimum(a, duration_s) - np.maximum(d, 0.0), 0.0, None)
    return float(inside.sum() / duration_s)


def problem_from_report(report):
    """The MWIS instance an epoch's report describes (weights, edges, one group per request), or
    None for an empty epoch: what the studies record from a run's observer."""
    from uam_solvers.base import MwisProblem
    if report.vertices < 1:
        return None
    edges = np.asarray(report.edges_array, dtype=np.int64).reshape(-1, 2)
    return MwisProblem.from_arrays(np.asarray(report.weights, dtype=np.float64), edges,
                                   groups_from_ids(report.vertex_request_ids))


def groups_from_ids(ids: Sequence[str]) -> list:
    groups: dict = {}
    for v, rid in enumerate(ids):
        groups.setdefault(rid, []).append(v)
    return [g for g in groups.values() if len(g) > 1]


def epoch_statistics(epochs: Sequence[dict]) -> dict:
    """Per-run means of the epoch rows (graph size, selection, eligible requests) and the solve
    times of the epochs that had a conflict graph; shared by in-process runs and recordings."""
    st = np.array([r["solve_time_s"] for r in epochs if r["vertices"] > 0], dtype=np.float64)
    return {
        "mean_vertices": float(np.mean([r["vertices"] for r in epochs])) if epochs else 0.0,
        "max_vertices": int(max((r["vertices"] for r in epochs), default=0)),
        "mean_selected": float(np.mean([r["selected"] for r in epochs])) if epochs else 0.0,
        "mean_eligible": float(np.mean([r["eligible"] for r in epochs])) if epochs else 0.0,
        "solve_time_mean_s": float(st.mean()) if st.size else 0.0,
        "solve_time_max_s": float(st.max()) if st.size else 0.0,
    }


def _apply_plan_updates(updates, by_id: dict, replans: list, t: float) -> None:
    """Fold one epoch's plan updates (uam_planner.replanning.PlanUpdate) into the flight rows:
    a new version replaces the row's route, destination and times and splices what flies (old
    trajectory before its effective instant, new after); a cancellation marks the row."""
    from uam_planner.replanning import spliced
    for u in updates:
        row = by_id.get(u.request_id)
        replans.append({"t_s": t, "request_id": u.request_id, "kind": u.kind, "version": u.version,
                        "constraints": " ".join(u.constraint_ids),
                        "added_delay_s": u.added_delay_s,
                        "airborne": bool(u.previous.departure_s < u.effective_s)})
        if row is None:
            continue
        row["version"] = u.version
        row["replan"] = u.kind
        _record_version(row, u, u.effective_s)
        if u.flight is None:
            row["cancelled"] = True
            continue
        f = u.flight
        row["_traj"] = spliced(row["_traj"], f.trajectory, u.effective_s)
        row.update(destination=f.destination_id, departure_s=f.departure_s, arrival_s=f.arrival_s,
                   length_m=f.length_m, route=" ".join(f.route_node_ids), level_m=float(f.level_m))


def _record_version(row, u, effective_s: float) -> None:
    """Keep plan update ``u`` as the row's next version in the run's record
    (``uam_sim.audit.record.PlanVersion``), as the recording keeps its FlightPlan."""
    f = u.flight
    row["_versions"].append(PlanVersion.of(
        u.version, effective_s, None if f is None else f.trajectory, update_kind=str(u.kind),
        origin_id=row["origin"], destination_id=row["destination"] if f is None else f.destination_id,
        constraint_ids=tuple(u.constraint_ids), reason=str(u.reason)))


def _apply_reaction_updates(updates, by_id, reaction, replans, t) -> None:
    """The reaction's plan updates of one epoch, or of a reaction between epochs: the
    runner's row of each flight takes the new version and arrival, the flight flies on from
    where it is at its observed rate (``ReactionUpdate.observed_rate``), and the update is
    listed with the run's re-plans."""
    for u in updates:
        row = by_id.get(u.request_id)
        if row is not None and _is_reaction(u):
            row["version"], row["replan"] = u.version, u.kind
            row["arrival_s"] = u.flight.arrival_s
            other_pad = u.flight.destination_id != u.previous.destination_id
            if other_pad or tuple(u.flight.route_node_ids) != tuple(u.previous.route_node_ids):
                # diverted or re-routed to its destination (fourteenth)
                row.update(destination=u.flight.destination_id, route=" ".join(u.flight.route_node_ids),
                           length_m=u.flight.length_m)
            reaction.apply(u, row, u.observed_rate)
            replans.append({"t_s": t, "request_id": u.request_id, "kind": u.kind,
                            "version": u.version, "constraints": "",
                            "added_delay_s": u.added_delay_s, "airborne": True,
                            **({"probe": True} if "conflict probe" in u.reason else {}),
                            **({"diverted": True} if other_pad else {})})

def _apply_disturbed_updates(updates, by_id, reaction, replans, t) -> None:
    """One batch of plan updates of a disturbed run with the reaction on (an epoch's, a reaction
    between epochs, one after the end): the reaction's updates fly on from where each aircraft is
    (:func:`_apply_reaction_updates`); every other one (a constraint re-plan, a neighbour that
    yields to a nonconforming flight: ``uam_planner.nonconformance.KIND_YIELD``) replaces the
    row's plan from its effective instant and the spliced plan is flown again, as the simulator
    node flies it."""
    from ..world.disturbance import fly_plans
    _apply_reaction_updates(updates, by_id, reaction, replans, t)
    _apply_plan_updates([u for u in updates if not _is_reaction(u)], by_id, replans, t)
    for u in updates:   # a re-plan that is not the reaction's: what flies changes now
        row = by_id.get(u.request_id)
        if row is None or _is_reaction(u) or row.get("cancelled") or "_flown" not in row:
            continue
        if row.get("_t0") is not None:
            reaction.refly(row)
        else:
            row["_flown"] = fly_plans([row["_traj"]], [row["request_id"]], reaction.dcfg, reaction.wind)[0]


def _is_reaction(u) -> bool:
    """A plan update of the reaction to nonconformance (``uam_planner.nonconformance``)."""
    return u.flight is not None and str(u.flight.method).startswith("nonconforming")


class _Reaction:
    """The in-process runner's side of the reaction to nonconformance, doing
    what the node graph's conformance monitor and fleet state do for the planner node:

    - before each epoch at t, every airborne flight's flown track is compared with its newest
      plan version at every model sample in (t - epoch, t] (``uam_sim.world.conformance``, the
      monitor's test); a flight nonconforming at a sample is *reported* to the planner
      (``Planner.report_nonconforming``, a claim it checks itself);
    - the planner *observes* every airborne flight (``Planner.observe``: the fleet state) at
      t - 20, t - 10 and t: its own view, which the claims are checked against and its progress
      rate estimated from;
    - a nonconforming update (its trajectory starts where the aircraft is at t) is flown from
      there by the path-following model with the aircraft's airspeed unchanged: the speed error
      against the new plan becomes (1 + e) / f - 1 for the observed rate f (the aircraft flies
      as it flew; the intent now predicts it); what flew before t is kept.
    """

    OBSERVE_BACK_S = (20.0, 10.0, 0.0)

    def __init__(self, planner, dcfg, wind, bounds, epoch_s: float, report: bool = True,
                 period_s: float = 0.0):
        self.planner, self.dcfg, self.wind, self.bounds = planner, dcfg, wind, bounds
        self.epoch_s = float(epoch_s)
        self.period_s = float(period_s)   # > 0: react between epochs too (reaction_period_s)
        #: False: only the observations (the fleet state the planner sees, so it holds a late
        #: flight past its plan: safety gap), no conformance reports (reaction off)
        self.report = bool(report)

    def _report(self, row, fl, t: float, window_s: float) -> None:
        """The monitor's look at ``row``'s samples in (t - window_s, t] after its newest version
        began: the first nonconforming one, if any, is reported to the planner."""
        from ..world.conformance import conforming, deviations
        ts, ps = fl.times_s, fl.points_m
        # the window by bisection (times strictly increasing: Trajectory checks it); a mask over
        # the whole track was a fifth of a Monte-Carlo run's time (BENCHMARKS.md)
        lo = max(t - window_s, row.get("_t0", -math.inf))
        i0, i1 = np.searchsorted(ts, lo, side="right"), np.searchsorted(ts, t, side="right")
        if i1 <= i0:
            return
        lat, ver, terr = deviations(row["_traj"], ts[i0:i1], ps[i0:i1])
        bad = np.flatnonzero(~conforming(lat, ver, terr, self.bounds))
        if bad.size:
            self.planner.report_nonconforming(row["request_id"], float(ts[i0 + bad[0]]), "runner monitor")

    def before_epoch(self, t: float, rows) -> None:
        for row in rows:
            fl = row.get("_flown")
            if fl is None or row.get("cancelled") or not fl.departure_s < t < fl.arrival_s:
                continue
            rid = row["request_id"]
            for back in self.OBSERVE_BACK_S:
                tb = t - back
                if fl.departure_s <= tb:
                    self.planner.observe(rid, tb, fl.position_at(tb))
            if self.report:
                self._report(row, fl, t, self.epoch_s)

    def between(self, t0: float, t1: float, rows, epoch_index: int, by_id, replans) -> None:
        """The reaction between epochs (``reaction_period_s``): every ``period`` seconds in
        (t0, t1) the planner observes every airborne flight, the monitor reports what it saw
        since the last look (samples after the flight's newest version began), and the planner
        reacts at once (``Planner.react_between``); the updates are flown from there."""
        k = 1
        while True:
            tk = t0 + k * self.period_s
            if tk >= t1 - 1e-9:
                return
            for row in rows:
                fl = row.get("_flown")
                if fl is None or row.get("cancelled") or not fl.departure_s < tk < fl.arrival_s:
                    continue
                self.planner.observe(row["request_id"], tk, fl.position_at(tk))
                self._report(row, fl, tk, self.period_s)
            _apply_disturbed_updates(self.planner.react_between(tk, epoch_index), by_id, self, replans, tk)
            k += 1

    def apply(self, u, row, rate: float) -> None:
        """Fly a nonconforming update of ``row`` from where the aircraft is."""
        from ..world.disturbance import flight_draws, fly_on
        new = u.flight.trajectory
        t0 = float(new.departure_s)
        e = row.get("_e")
        if e is None:
            e = flight_draws(self.dcfg, row["request_id"]).speed_error
        row["_flown"], row["_e"] = fly_on(row["_flown"], new, e, rate, self.dcfg, self.wind)
        row["_t0"] = t0
        _record_version(row, u, t0)
        row.setdefault("_pieces", [(float(row["_traj"].departure_s), row["_traj"])])
        row["_pieces"].append((t0, new))
        row.setdefault("_kinds", ["plan"]).append(u.kind)   # each piece's kind, for the audit
        row["_traj"] = new

    def refly(self, row) -> None:
        """After a constraint re-plan of a row the reaction changed before: fly its spliced plan
        from the last nonconforming update on."""
        from ..world.disturbance import fly_from
        # (the spliced plan starts where that update did: at row["_t0"])
        row["_flown"] = fly_from(row["_flown"], row["_traj"], row["_e"], self.dcfg, self.wind)
        row["_pieces"][-1] = (row["_pieces"][-1][0], row["_traj"])


def run_record(flights: list, timeline=()):
    """The run's record (:class:`uam_sim.audit.record.RunRecord`) of the runner's flight rows
    (each row's versions, kept as the planner issued them) and the planner's constraint
    timeline: the same model, and so the same audits, as the analysis builds from a recording."""
    from ..audit.record import RunRecord
    return RunRecord.from_versions([(f["request_id"], f["_versions"]) for f in flights], timeline)


#: a flown loss counts as "near a vertiport" when both aircraft are within this horizontal
#: distance [m] of a vertiport (a first or last point of a track) that both flights use:
#: twice the paper's 100 m separation, the area where one departs or lands beside the other
VERTIPORT_AREA_M = 200.0


def near_shared_vertiport(a, b, t: float, radius_m: float, ends_a, ends_b) -> bool:
    """True when flights ``a`` and ``b`` (flown tracks) share a vertiport (one of ``ends_a``,
    the xy of ``a``'s planned origin and destination, within 1 m of one of ``ends_b``) and at
    ``t`` both are within ``radius_m`` of it horizontally. The ends come from the plans: a flown
    track ends wherever the lateral drift left the aircraft, metres off the vertiport."""
    pa, pb = a.position_at(t, clamp=True)[:2], b.position_at(t, clamp=True)[:2]
    for va in ends_a:
        for vb in ends_b:
            if math.dist(va, vb) <= 1.0 and math.dist(pa, va) <= radius_m \
                    and math.dist(pb, va) <= radius_m:
                return True
    return False


def planned_ends(row) -> tuple:
    """The xy of a flight row's planned origin (its first version's first point) and
    destination (its newest version's last point)."""
    pieces = row.get("_pieces")
    first = pieces[0][1] if pieces else row["_traj"]
    return (tuple(first.points_m[0, :2]), tuple(row["_traj"].points_m[-1, :2]))


def _flown_summary(flights: list, cfg: ExperimentConfig, dcfg) -> dict:
    """What flew: the exact audit of the flown tracks in the true minimum
    (:func:`uam_sim.audit.flown.flown_audit`) and the F3548 conformance statistics of the run."""
    from ..world.conformance import f3548_statistics, track_conformance, versioned_conformance
    from ..audit.flown import flown_audit

    bounds = cfg.conformance_bounds()
    tracks = {f["request_id"]: f["_flown"] for f in flights}
    # the simulated aircraft flies the interpolation of the model's samples: no sampling error
    audit = flown_audit(tracks, cfg.separation())
    stats = f3548_statistics(
        versioned_conformance(f["request_id"], f["_pieces"], f["_flown"], bounds) if f.get("_pieces")
        else track_conformance(f["request_id"], f["_traj"], f["_flown"], bounds) for f in flights)
    out = {f"conf_{k}": v for k, v in stats.as_dict().items()}
    out.update({"flown_min_separation_m": audit["min_separation_m"], "flown_losses": audit["losses"],
                "replans": 0})
    if cfg.reaction:
        # which flown losses involve a flight the reaction flew as a contingency (its plan not
        # deconflicted): the listed pairs (the closest 20; exact while there are no more)
        cont = {f["request_id"] for f in flights if "contingency" in (f.get("_kinds") or ())}
        pairs = audit.get("loss_pairs") or []
        out["flown_losses_with_contingency"] = sum(1 for a, b, *_ in pairs if a in cont or b in cont) \
            if len(pairs) == audit["losses"] else None
        out["nonconforming_updates"] = sum(1 for f in flights if f.get("_pieces"))
        # every flight flown as a contingency at some time (not only those whose newest version
        # was one)
        out["reaction_contingencies"] = len(cont)
    # where the flown losses are: near a vertiport both flights use (where no airborne buffer
    # reaches: the synthetic city's vertiports are single points, no pads) or en route
    pairs = audit.get("loss_pairs") or []
    ends = {f["request_id"]: planned_ends(f) for f in flights} if pairs else {}
    out["flown_losses_near_vertiport"] = sum(
        1 for a, b, _d, t in pairs
        if near_shared_vertiport(tracks[a], tracks[b], float(t), VERTIPORT_AREA_M,
                                 ends[a], ends[b])) \
        if len(pairs) == audit["losses"] else None
    return out


def run_scenario(network, method: str, rate: float, seed: int, duration_s: float,
                 config: ExperimentConfig | None = None, demand=None,
                 observer=None, before_epoch=None) -> ScenarioResult:
    """Run one scenario in process: requests from the seeded generator, one planner, one method.

    Args:
        network: a uam_planner Network.
        method: "fifo" / "firstfit" for the baselines, else an MWIS backend name.
        rate: requests per interval (see RequestGenerator; fractional allowed).
        seed: demand seed (also the solver seed); the same seed gives the same requests whatever
            the method, so methods are compared on identical demand.
        duration_s: simulated time; epochs run at t = i * epoch_s < duration_s, and the requests of
            every demand instant at or before t are submitted before the epoch at t is planned.
        config: ExperimentConfig (planning parameters, time limit, solver options).
        demand: optional object with ``requests_at(t_s, interval_index)`` replacing the generator.
        observer: optional callable(t_s, epoch_index, submitted, rejected, EpochResult) called
            after each epoch with the requests submitted before it and the (request, reason)
            pairs refused (e.g. to record the run as the node graph would).
        before_epoch: optional callable(planner, t_s, epoch_index) called before each epoch is
            planned (after its requests are submitted), e.g. to announce a constraint with
            ``planner.update_constraint`` where the traffic is (scripts/measure_replanning.py).
    Returns: ScenarioResult. Cost: one planning cycle per epoch plus an O(F^2) audit.

    Constraint updates (a file's ``announce_s``, or ``before_epoch``): each epoch's
    ``plan_updates`` replace the flight rows' plans (``ScenarioResult.replans`` lists them), the
    audit checks what flew (every version from the instant it took effect; cancelled flights
    flew nothing) and, when any constraint was in force, the summary adds ``replans``,
    ``replan_<kind>`` counts and ``incursions`` (``uam_sim.audit.flown_audit.incursions``, as for a recording).
    """
    cfg = config if config is not None else ExperimentConfig()
    t_wall = time.perf_counter()
    run = _ScenarioRun(network, method, rate, seed, duration_s, cfg, demand)
    n_epochs = int(math.ceil(duration_s / cfg.epoch_s - 1e-9))
    for e in range(n_epochs):
        run.epoch(e, before_epoch, observer)
    run.react_to_the_end(n_epochs)
    audit, extra, flown = run.audit()
    flown_summary = run.flown_summary(flown)
    run.drop_private_keys()
    summary = run.summary(rate, n_epochs, audit, extra, flown)
    summary.update({k: v for k, v in flown_summary.items() if k not in extra})  # replans: count
    wall = time.perf_counter() - t_wall
    summary["wall_s"] = wall
    summary["real_time_factor"] = duration_s / wall if wall > 0 else float("inf")
    return ScenarioResult(method, rate_label(rate), int(seed), float(duration_s), summary, run.epochs,
                          run.flights, audit, run.instances, run.rejections, wall, run.replans, run.asked,
                          run.record)


def _planner(network, method: str, cfg: ExperimentConfig, seed: int, policy: str) -> Planner:
    """The run's planner: the method's policy (a baseline or the MWIS with the method's solver)
    and the constraints file's constraints."""
    pcfg = cfg.planning_config("greedy" if method in BASELINES else method, seed)
    planner = Planner(network, pcfg, policy=policy,
                      solve_mwis=None if policy in BASELINES else _solver(method, cfg, seed))
    separation.warm_up()  # the compiled check that decides, compiled or loaded now, not in epoch 0
    if cfg.constraints_file:
        from uam_planner.airspace_files import load_airspace
        from .experiment_config import resolve_path
        try:  # the run starts at t = 0: a window over by then is refused as in the past
            planner.set_constraints(load_airspace(resolve_path(str(cfg.constraints_file)), network,
                                                     now_s=0.0))
        except ValueError as exc:
            raise ExperimentError(f"constraints_file: {exc}") from None
    return planner


class _ScenarioRun:
    """One in-process run as its epochs go by (:func:`run_scenario`): the planner, the demand,
    the flight rows and counters, and, with a disturbance, what flies and the reaction."""

    def __init__(self, network, method: str, rate: float, seed: int, duration_s: float,
                 cfg: ExperimentConfig, demand):
        self.network, self.method, self.seed, self.duration_s, self.cfg = network, method, seed, duration_s, cfg
        self.policy = method if method in BASELINES else "mwis"
        self.planner = _planner(network, method, cfg, seed, self.policy)
        if demand is None:
            demand = RequestGenerator(network.aerodrome_ids, rate, cfg.interval_s, cfg.window_s, seed,
                                      priority_share=cfg.priority_share,
                                      priority_class=cfg.priority_class, operators=cfg.operators,
                                      lead_time_s=cfg.lead_time_s,
                                      operator_lead_times_s=cfg.operator_lead_times_s)
        self.demand = demand
        self._disturbance()
        self.epochs, self.flights, self.instances, self.rejections, self.replans = [], [], [], [], []
        self.by_id: dict = {}
        self.n_requests = self.approved_cum = self.expired_cum = 0
        self.next_interval = 0
        self.earliest_s: dict = {}
        self.latest_s: dict = {}
        self.asked: list = []         # every request submitted, for the decision metrics
        self.held_ids: set = set()    # flights the planner held past their plans
        self.record = None

    def _disturbance(self) -> None:
        """With a disturbance, what flies is the model's: its config (seeded by the run's seed),
        the wind field, the reaction to nonconformance when on, and what the planner watches."""
        cfg = self.cfg
        self.disturbed = bool(cfg.disturbance)
        self.dcfg = self.wind = self.reaction = self.watch = None
        if self.disturbed:
            from dataclasses import replace
            from ..world.disturbance import WindField
            self.dcfg = replace(cfg.disturbance_config(), seed=int(self.seed))
            self.wind = WindField(self.dcfg)
            if cfg.reaction:
                self.reaction = _Reaction(self.planner, self.dcfg, self.wind, cfg.conformance_bounds(),
                                          cfg.epoch_s, period_s=cfg.reaction_period_s)
            # what flies is not the plan: the planner sees the fleet (as the node sees
            # /uam/fleet_state), so it holds a flight that flies past its plan (the safety gap)
            self.watch = self.reaction if self.reaction is not None else \
                _Reaction(self.planner, self.dcfg, self.wind, cfg.conformance_bounds(), cfg.epoch_s, report=False)
        self.between = self.reaction is not None and 0.0 < cfg.reaction_period_s < cfg.epoch_s

    def epoch(self, e: int, before_epoch, observer) -> None:
        """Epoch ``e``: its requests submitted, the planner's plan, its updates and approvals
        folded into the flight rows (and flown), the reaction until the next epoch, its row."""
        cfg, planner = self.cfg, self.planner
        t = e * cfg.epoch_s
        submitted, refused = self._submit(t)
        if before_epoch is not None:
            before_epoch(planner, t, e)
        if self.watch is not None:
            self.watch.before_epoch(t, self.flights)
        res = planner.plan(t, e)
        self.held_ids.update(res.report.overruns)
        if res.plan_updates:
            if self.reaction is not None:
                _apply_disturbed_updates(res.plan_updates, self.by_id, self.reaction, self.replans, t)
            else:
                _apply_plan_updates(res.plan_updates, self.by_id, self.replans, t)
        if observer is not None:
            observer(t, e, submitted, refused, res)
        rep = res.report
        self.approved_cum += len(res.approved)
        self.expired_cum += len(res.expired)
        for f in res.approved:
            self.flights.append(self._flight_row(f, e))
            self.by_id[f.request_id] = self.flights[-1]
        if self.disturbed and res.approved:
            self._fly(self.flights[len(self.flights) - len(res.approved):])
        if self.between:   # the reaction between this epoch and the next
            self.reaction.between(t, t + cfg.epoch_s, self.flights, e, self.by_id, self.replans)
        self.epochs.append(self._epoch_row(e, t, res))
        if self.policy == "mwis" and 0 < rep.vertices <= cfg.corpus_max_vertices:
            self.instances.append({"epoch": e, "weights": [float(w) for w in rep.weights],
                                   "edges": np.asarray(rep.edges_array).reshape(-1, 2).tolist(),
                                   "groups": groups_from_ids(rep.vertex_request_ids)})

    def _submit(self, t: float) -> tuple[list, list]:
        """The requests of every demand instant up to ``t``, in time order (equal spacing when
        interval_s == epoch_s), submitted to the planner: (submitted, (request, reason) refused)."""
        cfg, planner = self.cfg, self.planner
        submitted, refused = [], []
        while self.next_interval * cfg.interval_s <= t + 1e-9 and \
                self.next_interval * cfg.interval_s < self.duration_s:
            for req in self.demand.requests_at(self.next_interval * cfg.interval_s, self.next_interval):
                self.n_requests += 1
                submitted.append(req)
                self.earliest_s[req.request_id] = req.earliest_departure_s  # for the delay analysis
                self.latest_s[req.request_id] = req.latest_departure_s
                self.asked.append({"request_id": req.request_id,
                                   "earliest_departure_s": req.earliest_departure_s,
                                   "latest_departure_s": req.latest_departure_s,
                                   "operator": req.operator_id, "priority": int(req.priority)})
                reason = planner.submit(req)
                if reason is not None:
                    self.rejections.append((req.request_id, reason))
                    refused.append((req, reason))
            self.next_interval += 1
        return submitted, refused

    def _flight_row(self, f, e: int) -> dict:
        """The row of the approved flight ``f`` (epoch ``e``), its plan as its first version."""
        network = self.network
        return {"request_id": f.request_id, "origin": f.origin_id,
                "destination": f.destination_id, "epoch": e,
                "earliest_departure_s": self.earliest_s.get(f.request_id),
                "latest_departure_s": self.latest_s.get(f.request_id),
                "departure_s": f.departure_s, "arrival_s": f.arrival_s,
                "length_m": f.length_m, "weight": f.weight,
                "candidate_index": int(f.candidate_index),
                "route_index": int(f.route_index), "level_m": float(f.level_m),
                "route": " ".join(f.route_node_ids), "_traj": f.trajectory,
                "_versions": [PlanVersion.of(1, -math.inf, f.trajectory, origin_id=f.origin_id,
                                             destination_id=f.destination_id)],
                "priority": int(f.priority), "operator": f.operator_id,
                "shortest_length_m": min(
                    tp.route.length_m for tp in self.planner.cache.templates(
                        network.node_index(f.origin_id),
                        network.node_index(f.destination_id)))}

    def _epoch_row(self, e: int, t: float, res) -> dict:
        """Epoch ``e``'s row: its graph, selection, counts so far, objective and times."""
        rep = res.report
        return {"epoch": e, "t_s": t, "requests_cum": self.n_requests, "pending": rep.pending,
                "eligible": rep.eligible, "candidates": rep.candidates,
                "discarded": rep.discarded, "vertices": rep.vertices, "edges": rep.edges,
                "conflict_edges": rep.conflict_edges, "selected": len(res.approved),
                "approved_cum": self.approved_cum, "expired": len(res.expired),
                "expired_cum": self.expired_cum, "active": rep.active_flights,
                "objective": rep.objective, "solve_time_s": rep.solve_time_s,
                "planning_time_s": rep.planning_time_s,
                "proven_optimal": bool(rep.proven_optimal), "fallback": bool(rep.fallback),
                "backend_used": rep.backend_used}

    def _fly(self, rows: list) -> None:
        """What ``rows`` fly: their plans flown by the disturbance model."""
        from ..world.disturbance import fly_plans
        for f, track in zip(rows, fly_plans([f["_traj"] for f in rows], [f["request_id"] for f in rows],
                                            self.dcfg, self.wind)):
            f["_flown"] = track

    def react_to_the_end(self, n_epochs: int) -> None:
        """With the reaction on, the flights approved by the end fly on after it: the reaction
        goes on (no new requests, none planned: the requests still pending are dropped) until the
        last one has landed, so every flight is monitored and updated to its end."""
        if self.reaction is None:
            return
        cfg, planner = self.cfg, self.planner
        planner.pending = []
        e = n_epochs
        while any(f.get("_flown") is not None and f["_flown"].arrival_s >= e * cfg.epoch_s
                  for f in self.flights if not f.get("cancelled")):
            t = e * cfg.epoch_s
            self.reaction.before_epoch(t, self.flights)
            res = planner.plan(t, e)
            self.held_ids.update(res.report.overruns)
            _apply_disturbed_updates(res.plan_updates, self.by_id, self.reaction, self.replans, t)
            if self.between:
                self.reaction.between(t, t + cfg.epoch_s, self.flights, e, self.by_id, self.replans)
            e += 1

    def audit(self) -> tuple[dict, dict, list]:
        """The run's record (what was in force: every approval's versions, a cancellation ending
        its flight as planned) and its separation audit, the constraint columns when any
        constraint was in force, and the flights that flew: (audit, columns, flights)."""
        cfg, planner = self.cfg, self.planner
        audit = {}
        flown = [f for f in self.flights if not f.get("cancelled")]
        timeline = ()
        if planner.constraint_log or planner.initial_constraints:
            from uam_planner.replanning import constraint_timeline
            timeline = constraint_timeline(planner.initial_constraints, planner.constraint_log)
        self.record = record = run_record(self.flights, timeline)
        if cfg.audit:
            # in the run's separation model (the paper's sphere, or the cylinder), the parts of one
            # flight never a pair
            in_force = record.in_force()
            audit = sweep_audit(in_force.parts_as_trajectories(), cfg.separation(), groups=in_force.groups)
            if self.reaction is not None:
                # the plans the planner deconflicted (every version but the reaction's contingencies,
                # which are flown, announced and deconflicted against by later plans, but not
                # themselves deconflicted: docs/disturbances.md, section 3): their losses must be 0
                dec = in_force.select([not c for c in in_force.contingent])
                audit["losses_deconflicted"] = audit["losses"] if len(dec.parts) == len(in_force.parts) else \
                    sweep_audit(dec.parts_as_trajectories(), cfg.separation(), groups=dec.groups)["losses"]
        extra = {}
        if timeline:
            from uam_planner.replanning import KINDS
            found = record.incursions(self.network)[0] if cfg.audit else []
            labels = {(c.constraint_id, c.version): c.label() for c, _a, _b in timeline}
            inc = [(i.key, labels[(i.constraint_id, i.constraint_version)], float(i.t_s)) for i in found]
            extra = {"replans": len(self.replans), **{f"replan_{k}": sum(r["kind"] == k for r in self.replans)
                                                      for k in KINDS},
                     "incursions": len(inc) if cfg.audit else None}
            audit = dict(audit, incursions=[list(x) for x in inc[:20]])
        return audit, extra, flown

    def flown_summary(self, flown: list) -> dict:
        """With a disturbance, what flew (:func:`_flown_summary`) and the reaction's counts; {}
        without. A re-planned flight flies its spliced plan (old version before the switch, new
        after)."""
        if not self.disturbed:
            return {}
        cfg, replans = self.cfg, self.replans
        self._fly([f for f in flown if f.get("replan") and "_flown" in f and f.get("_t0") is None])
        out = _flown_summary(flown, cfg, self.dcfg)
        if out:
            out["replans"] = len(replans)
            if cfg.reaction:   # flights re-timed so that a nonconforming one keeps separation
                out["reaction_yields"] = sum(1 for r in replans if r["kind"] == "yielded")
                # nonconforming flights diverted to another vertiport
                out["reaction_diversions"] = sum(1 for r in replans if r.get("diverted"))
                if cfg.conflict_probe_s:   # updates the planner's conflict probe asked for
                    out["reaction_probe_updates"] = sum(1 for r in replans if r.get("probe"))
            out["held_past_plan"] = len(self.held_ids)
        return out

    def drop_private_keys(self) -> None:
        """The flight rows as the result holds them: without their trajectories and the
        disturbance model's state."""
        for f in self.flights:
            del f["_traj"]
            for k in ("_flown", "_pieces", "_e", "_t0", "_kinds", "_versions"):
                f.pop(k, None)

    def summary(self, rate: float, n_epochs: int, audit: dict, extra: dict, flown: list) -> dict:
        """The run's summary row (without what flew and the wall time)."""
        cfg, epochs = self.cfg, self.epochs
        approved, n_requests = self.approved_cum, self.n_requests
        mwis_epochs = [r for r in epochs if r["vertices"] > 0]
        return {
            "method": self.method, "rate": rate_label(rate), "seed": int(self.seed),
            "duration_s": float(self.duration_s), "epochs": n_epochs, "requests": n_requests,
            "rejected": len(self.rejections), "approved": approved, "expired": self.expired_cum,
            "pending_end": n_requests - len(self.rejections) - approved - self.expired_cum,
            "approval_rate": approved / n_requests if n_requests else float("nan"),
            "avg_airborne": average_airborne([f["departure_s"] for f in flown],
                                             [f["arrival_s"] for f in flown], self.duration_s),
            **epoch_statistics(epochs),
            "proven_optimal_share": (float(np.mean([r["proven_optimal"] for r in mwis_epochs]))
                                     if mwis_epochs and self.policy == "mwis" else float("nan")),
            "fallbacks": int(sum(r["fallback"] for r in epochs)),
            "min_separation_m": audit.get("min_separation_m"),
            "losses": audit.get("losses"),
            **({"losses_deconflicted": audit.get("losses_deconflicted")} if self.reaction is not None else {}),
            "objective": cfg.objective,
            # requests still within their window at the end (filed ahead) are left out
            **{k: v for k, v in run_metrics(self.flights, self.asked, warmup_s=cfg.metrics_warmup_s or None,
                                            end_s=self.duration_s).items() if k != "flights"},
            **extra,
        }
