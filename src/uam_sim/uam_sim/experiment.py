"""The paper's study, in process: methods x request rates x seeds, with results, figures and a report.

    python -m uam_sim.experiment --config config/experiment.yaml \
        [--rates 1,2 --methods fifo,greedy --seeds 1 --duration 600 --workers 2 --out results/]

Each *cell* (method, rate, seed) is one scenario run by :func:`run_scenario`: a
:class:`~uam_planner.planning.Planner` driven epoch by epoch with the requests of a
:class:`~uam_sim.demand.RequestGenerator` seeded by ``seed`` alone, so every method at one
(rate, seed) plans the *same* requests, and the ROS node graph with the same seed gets the same
stream. Cells run in parallel over processes (no shared RNG, each cell is a pure function of its
parameters; wall-clock solve times are the only fields that differ between runs). Each finished
cell is written to ``<out>/cells/<cell-key>.json`` atomically and skipped next time when its key
(a hash of every parameter that affects it) matches, so an interrupted sweep resumes.

After the cells: ``runs.csv`` (one row per cell), ``epochs.csv`` (one row per epoch per cell),
``flights.csv``, the MWIS instances of the runs as a corpus (``instances.jsonl``), the TTS study on
a sample of them (``tts.csv``, reused when its sample and settings are unchanged), the figures
(:mod:`uam_sim.figures`) and ``REPORT.md`` (:mod:`uam_sim.report`). Every run is audited for loss
of separation by :func:`sweep_audit` (exact, all flight pairs); the command exits 1 on any loss.

Other modes: ``--no-compute`` reports on the finished cells of a partial sweep; ``--from-mcap
FILES`` computes the same tables, figures and report from node-graph recordings (through
:mod:`uam_sim.analysis`). The cell key covers every parameter but not the code: after changing
the planning core or a backend, use a new ``--out`` (or delete ``<out>/cells``).
"""

from __future__ import annotations

import argparse
import csv
import hashlib
import json
import math
import os
import platform
import subprocess
import sys
import tempfile
import time
from concurrent.futures import ProcessPoolExecutor, as_completed
from dataclasses import asdict, dataclass, field, fields, replace
from pathlib import Path
from typing import Any, Sequence

import numpy as np
import yaml

from uam_planner.planning import Planner, PlanningConfig

from .demand import DemandSchedule, RequestGenerator, load_demand

CELL_FORMAT = "uam-experiment-cell/1"
DEFAULT_METHODS = ("fifo", "firstfit", "greedy", "exact", "sa", "tabu", "qpu-emulator")
# methods that are planner policies, not MWIS backends (firstfit: uam_planner.first_fit)
BASELINES = ("fifo", "firstfit")
DEFAULT_RATES = (1, 2, 4, 6, 8, 10, 15, 20)
REPO_ROOT = Path(__file__).resolve().parents[3]


class ExperimentError(ValueError):
    """Bad experiment configuration; the message names the field and the value."""


@dataclass
class ExperimentConfig:
    """Every parameter of a sweep (paper defaults). Times in seconds, distances in metres.

    Attributes:
        network: path of a network file, or {"synthetic": {n_nodes, n_aerodromes, seed}}.
        methods: "fifo" (shortest FIFO), "firstfit" (first conflict-free candidate in arrival
            order) or an MWIS backend name per entry.
        include_qpu: add the "qpu" backend when it is available (a D-Wave token is configured).
        rates: requests per interval (the swept variable).
        seeds: seed list (an int n in YAML or flags means seeds 0..n-1).
        duration_s: simulated time per run; epochs at 0, epoch_s, ... < duration_s.
        epoch_s, interval_s, window_s: planning epoch, demand interval, departure window.
        separation_m, k, penalty_factor, speed_mps: planning parameters.
        time_limit_s: MWIS time budget per epoch.
        solver_options: backend name -> options mapping passed to uam_solvers.solve.
        demand_file: optional demand file replayed instead of random demand (rates then only label
            the cells).
        corpus_max_vertices: MWIS instances up to this size are kept for the corpus.
        audit: run the independent exact separation audit on every cell.
        out: output directory.
        workers: processes for the cells (1 = serial in this process).
        cumulative_rates: rates shown in the cumulative-approvals figure (default: up to 4 spread).
        tts: TTS study settings: enabled, instances (sampled from the runs' MWIS instances),
            min_vertices, max_vertices, reads (per annealing run), repetitions (runs per instance
            and backend), backends, backend_instances (backend -> a smaller seeded sub-sample
            for slow backends), seed, time_limit_s (per run); TTS(0.99) via uam_solvers.tts.
    """

    network: Any = "config/networks/singapore.yaml"
    methods: list = field(default_factory=lambda: list(DEFAULT_METHODS))
    include_qpu: bool = True
    rates: list = field(default_factory=lambda: list(DEFAULT_RATES))
    seeds: list = field(default_factory=lambda: list(range(5)))
    duration_s: float = 3500.0
    epoch_s: float = 30.0
    interval_s: float = 30.0
    window_s: float = 60.0
    separation_m: float = 100.0
    k: int = 5
    penalty_factor: float = 5.0
    speed_mps: float = 10.0
    time_limit_s: float = 10.0
    solver_options: dict = field(default_factory=dict)
    demand_file: str | None = None
    corpus_max_vertices: int = 60
    audit: bool = True
    out: str = "results"
    workers: int = 2
    cumulative_rates: list | None = None
    tts: dict = field(default_factory=lambda: {
        "enabled": True, "instances": 629, "min_vertices": 5, "max_vertices": 50, "reads": 100,
        "repetitions": 5, "backend_instances": {"qpu-emulator": 60},
        "backends": ["exact", "greedy", "sa", "tabu", "qpu-emulator"], "p": 0.99, "seed": 0,
        "time_limit_s": 10.0})

    def planning_config(self, backend: str, seed: int) -> PlanningConfig:
        return PlanningConfig(epoch_s=self.epoch_s, separation_m=self.separation_m, k=self.k,
                              penalty_factor=self.penalty_factor, speed_mps=self.speed_mps,
                              backend=backend, time_limit_s=self.time_limit_s, seed=int(seed))


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


def _rate(x: float):
    return int(x) if float(x).is_integer() else float(x)


def make_config(data: dict | None = None, **overrides) -> ExperimentConfig:
    """An ExperimentConfig from a mapping (the YAML file) and overrides (flags; None = unset)."""
    data = dict(data or {})
    data.update({k: v for k, v in overrides.items() if v is not None})
    names = {f.name for f in fields(ExperimentConfig)}
    unknown = set(data) - names
    if unknown:
        raise ExperimentError(f"unknown parameter {sorted(unknown)[0]!r} (known: {sorted(names)})")
    cfg = ExperimentConfig()
    tts = dict(cfg.tts)
    tts.update(data.pop("tts", None) or {})
    cfg = replace(cfg, **data, tts=tts)
    methods = cfg.methods.split(",") if isinstance(cfg.methods, str) else list(cfg.methods)
    if not methods or not all(isinstance(m, str) and m for m in methods):
        raise ExperimentError(f"methods: {cfg.methods!r} must be a non-empty list of names")
    cfg.methods = [m.strip() for m in methods]
    cfg.rates = [_rate(r) for r in _num_list("rates", cfg.rates)]
    cfg.seeds = _seeds(cfg.seeds)
    for name in ("duration_s", "epoch_s", "interval_s", "window_s", "separation_m", "speed_mps",
                 "time_limit_s"):
        v = getattr(cfg, name)
        if isinstance(v, bool) or not isinstance(v, (int, float)) or not math.isfinite(v) or v <= 0:
            raise ExperimentError(f"{name}: {v!r} must be a positive finite number")
    if isinstance(cfg.workers, bool) or not isinstance(cfg.workers, int) or cfg.workers < 1:
        raise ExperimentError(f"workers: {cfg.workers!r} must be an integer >= 1")
    if cfg.cumulative_rates is not None:
        cfg.cumulative_rates = [_rate(r) for r in _num_list("cumulative_rates", cfg.cumulative_rates)]
    if not isinstance(cfg.solver_options, dict):
        raise ExperimentError(f"solver_options: {cfg.solver_options!r} must be a mapping")
    cfg.planning_config("greedy", 0)  # validates k, penalty_factor
    return cfg


def load_config(path, **overrides) -> ExperimentConfig:
    """Read a YAML experiment file (see config/experiment.yaml) and apply overrides."""
    path = Path(path)
    data = yaml.safe_load(path.read_text(encoding="utf-8")) or {}
    if not isinstance(data, dict):
        raise ExperimentError(f"{path}: expected a mapping of parameters, got {type(data).__name__}")
    return make_config(data, **overrides)


# ---- network -------------------------------------------------------------------------------------

def _resolve(path: str) -> Path:
    p = Path(path)
    if not p.is_absolute() and not p.exists() and (REPO_ROOT / p).exists():
        p = REPO_ROOT / p
    return p


def network_identity(spec) -> str:
    """A string that changes whenever the network would: file bytes hash or the synthetic spec."""
    if isinstance(spec, dict):
        return "synthetic:" + json.dumps(spec, sort_keys=True)
    p = _resolve(str(spec))
    if not p.exists():
        raise ExperimentError(f"network: file {str(spec)!r} does not exist")
    return "file:" + hashlib.sha256(p.read_bytes()).hexdigest()


_NETWORKS: dict = {}


def load_network_spec(spec):
    """Load (and cache per process) the network named by ``spec`` (a path or a synthetic spec)."""
    key = json.dumps(spec, sort_keys=True) if isinstance(spec, dict) else str(spec)
    if key not in _NETWORKS:
        if isinstance(spec, dict):
            if set(spec) != {"synthetic"} or not isinstance(spec["synthetic"], dict):
                raise ExperimentError(f"network: {spec!r} must be a path or {{synthetic: {{...}}}}")
            from uam_planner.synthetic import generate_network
            _NETWORKS[key] = generate_network(**spec["synthetic"])
        else:
            from uam_planner.network import load_network
            p = _resolve(str(spec))
            if not p.exists():
                raise ExperimentError(f"network: file {str(spec)!r} does not exist")
            _NETWORKS[key] = load_network(p)
    return _NETWORKS[key]


# ---- one scenario --------------------------------------------------------------------------------

@dataclass
class ScenarioResult:
    """One cell's outcome.

    Attributes:
        method, rate, seed, duration_s: the cell.
        summary: one tidy row (counts, average aircraft in the air, solve-time stats, audit).
        epochs: one row per epoch (t_s, counts so far, MWIS size, solve time, fallback, ...).
        flights: one row per approved flight (ids, epoch, departure/arrival, route, weight).
        audit: the exact separation audit over all flown flights (min_separation_m, losses,
            pairs_checked) or {} when disabled.
        instances: MWIS instances (weights, edges incl. clique edges, groups) of this run with
            1..corpus_max_vertices vertices, with their epoch index.
        rejections: (request_id, reason) of requests the planner refused at submission.
        wall_s: wall time of the run.
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

    def decisions(self) -> dict:
        """request id -> (epoch, candidate) of each approval: what must match across runs."""
        return {f["request_id"]: (f["epoch"], f["candidate_index"]) for f in self.flights}


def _solver(method: str, cfg: ExperimentConfig, seed: int):
    import uam_solvers
    options = dict(cfg.solver_options.get(method) or {})

    def solve(weights, edges, groups):
        return uam_solvers.solve(weights, edges, groups=groups, backend=method,
                                 time_limit_s=cfg.time_limit_s, seed=int(seed), options=options)
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


def sweep_audit(trajectories: Sequence, separation_m: float, labels: Sequence | None = None,
                chunk_pairs: int = 2_000_000, max_listed: int = 20) -> dict:
    """Exact minimum separation over every pair of flights, by a time sweep over segments.

    A third implementation, independent of the planner's separation kernel (space-time grid
    broad phase) and of ``uam_planner.audit`` (pure-Python pair walk, which is O(F^2 s) in
    Python and too slow for 3500 s runs with hundreds of long flights): every pair of straight
    segments of different flights whose time intervals overlap (touching counts) is checked
    exactly - relative position at the start of the overlap, relative velocity, closest approach
    clamped to the overlap - in numpy, chunked. No spatial pruning, so the minimum is the true
    global minimum. Tests hold it equal to ``uam_planner.audit.audit_flights``.

    Args:
        trajectories: objects with ``times_s`` (p,) and ``points_m`` (p, 3).
        separation_m: a loss is a distance strictly below it.
        labels: names for the pairs (default: indices).
    Returns: {"min_separation_m" (None if no two flights share time), "pair_of_min", "losses"
    (count of flight pairs with a loss), "loss_pairs" (up to max_listed, closest first: label,
    label, distance_m, t_s),
    "pairs_checked" (flight pairs with a common time), "segment_pairs"}.
    Complexity: O(S log S + P) for S segments and P time-overlapping segment pairs.
    """
    labels = list(labels) if labels is not None else list(range(len(trajectories)))
    t0s, t1s, p0s, vs, fl = [], [], [], [], []
    for k, tr in enumerate(trajectories):
        t = np.asarray(tr.times_s, dtype=np.float64)
        pts = np.asarray(tr.points_m, dtype=np.float64).reshape(-1, 3)
        dt = np.diff(t)
        t0s.append(t[:-1]); t1s.append(t[1:]); p0s.append(pts[:-1])
        vs.append((pts[1:] - pts[:-1]) / dt[:, None])
        fl.append(np.full(dt.size, k, dtype=np.int64))
    empty = {"min_separation_m": None, "pair_of_min": None, "losses": 0, "loss_pairs": [],
             "pairs_checked": 0, "segment_pairs": 0}
    if len(trajectories) < 2:
        return empty
    t0 = np.concatenate(t0s); t1 = np.concatenate(t1s)
    p0 = np.concatenate(p0s); v = np.concatenate(vs); f = np.concatenate(fl)
    order = np.argsort(t0, kind="stable")
    t0, t1, p0, v, f = t0[order], t1[order], p0[order], v[order], f[order]
    # segment i overlaps the later-starting segments i+1 .. end[i]-1 (t0[j] <= t1[i])
    end = np.searchsorted(t0, t1, side="right")
    counts = np.maximum(end - np.arange(t0.size) - 1, 0)
    best, best_pair, best_t = math.inf, None, math.nan
    loss: dict = {}
    flight_pairs = set()
    n_seg_pairs = 0
    start = 0
    cum = np.cumsum(counts)
    while start < t0.size:
        # segments [start, stop) whose pairs fit one chunk
        base = cum[start - 1] if start else 0
        stop = int(np.searchsorted(cum, base + chunk_pairs, side="right"))
        stop = max(stop, start + 1)
        c = counts[start:stop]
        i = np.repeat(np.arange(start, stop), c)
        j = i + 1 + (np.arange(c.sum()) - np.repeat(np.cumsum(c) - c, c))
        start = stop
        keep = f[i] != f[j]
        i, j = i[keep], j[keep]
        if i.size == 0:
            continue
        n_seg_pairs += i.size
        lo = np.maximum(t0[i], t0[j]); hi = np.minimum(t1[i], t1[j])
        r = (p0[i] + v[i] * (lo - t0[i])[:, None]) - (p0[j] + v[j] * (lo - t0[j])[:, None])
        dv = v[i] - v[j]
        dd = np.einsum("ij,ij->i", dv, dv)
        with np.errstate(invalid="ignore", divide="ignore"):
            tau = np.where(dd > 0, -np.einsum("ij,ij->i", r, dv) / dd, 0.0)
        tau = np.clip(tau, 0.0, hi - lo)
        d = np.linalg.norm(r + dv * tau[:, None], axis=1)
        a, b = np.minimum(f[i], f[j]), np.maximum(f[i], f[j])
        flight_pairs.update(zip(a.tolist(), b.tolist()))
        k = int(np.argmin(d))
        if d[k] < best:
            best, best_pair, best_t = float(d[k]), (labels[a[k]], labels[b[k]]), float(lo[k] + tau[k])
        for x in np.flatnonzero(d < separation_m).tolist():
            key = (int(a[x]), int(b[x]))
            if key not in loss or d[x] < loss[key][0]:
                loss[key] = (float(d[x]), float(lo[x] + tau[x]))
    if not flight_pairs:
        return empty
    loss_pairs = [[labels[a], labels[b], dist, tt] for (a, b), (dist, tt) in sorted(
        loss.items(), key=lambda kv: kv[1][0])]
    return {"min_separation_m": best, "pair_of_min": list(best_pair), "min_time_s": best_t,
            "losses": len(loss), "loss_pairs": loss_pairs[:max_listed], "pairs_checked": len(flight_pairs),
            "segment_pairs": n_seg_pairs}


def _groups_from_ids(ids: Sequence[str]) -> list:
    groups: dict = {}
    for v, rid in enumerate(ids):
        groups.setdefault(rid, []).append(v)
    return [g for g in groups.values() if len(g) > 1]


def _epoch_statistics(epochs: Sequence[dict]) -> dict:
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


def run_scenario(network, method: str, rate: float, seed: int, duration_s: float,
                 config: ExperimentConfig | None = None, demand=None,
                 observer=None) -> ScenarioResult:
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
    Returns: ScenarioResult. Cost: one planning cycle per epoch plus an O(F^2) audit.
    """
    cfg = config if config is not None else ExperimentConfig()
    t_wall = time.perf_counter()
    policy = method if method in BASELINES else "mwis"
    pcfg = cfg.planning_config("greedy" if method in BASELINES else method, seed)
    planner = Planner(network, pcfg, policy=policy,
                      solve_mwis=None if policy in BASELINES else _solver(method, cfg, seed))
    if demand is None:
        demand = RequestGenerator(network.aerodrome_ids, rate, cfg.interval_s, cfg.window_s, seed)
    n_epochs = int(math.ceil(duration_s / cfg.epoch_s - 1e-9))
    next_interval = 0
    epochs, flights, instances, rejections = [], [], [], []
    n_requests = approved_cum = expired_cum = 0
    earliest_s: dict = {}
    for e in range(n_epochs):
        t = e * cfg.epoch_s
        # every demand instant up to t, in time order (equal spacing when interval_s == epoch_s)
        submitted, refused = [], []
        while next_interval * cfg.interval_s <= t + 1e-9 and next_interval * cfg.interval_s < duration_s:
            for req in demand.requests_at(next_interval * cfg.interval_s, next_interval):
                n_requests += 1
                submitted.append(req)
                earliest_s[req.request_id] = req.earliest_departure_s  # for the delay analysis
                reason = planner.submit(req)
                if reason is not None:
                    rejections.append((req.request_id, reason))
                    refused.append((req, reason))
            next_interval += 1
        res = planner.plan(t, e)
        if observer is not None:
            observer(t, e, submitted, refused, res)
        rep = res.report
        approved_cum += len(res.approved)
        expired_cum += len(res.expired)
        for f in res.approved:
            flights.append({"request_id": f.request_id, "origin": f.origin_id,
                            "destination": f.destination_id, "epoch": e,
                            "earliest_departure_s": earliest_s.get(f.request_id),
                            "departure_s": f.departure_s, "arrival_s": f.arrival_s,
                            "length_m": f.length_m, "weight": f.weight,
                            "candidate_index": int(f.candidate_index),
                            "route": " ".join(f.route_node_ids), "_traj": f.trajectory})
        epochs.append({"epoch": e, "t_s": t, "requests_cum": n_requests, "pending": rep.pending,
                       "eligible": rep.eligible, "candidates": rep.candidates,
                       "discarded": rep.discarded, "vertices": rep.vertices, "edges": rep.edges,
                       "conflict_edges": rep.conflict_edges, "selected": len(res.approved),
                       "approved_cum": approved_cum, "expired": len(res.expired),
                       "expired_cum": expired_cum, "active": rep.active_flights,
                       "objective": rep.objective, "solve_time_s": rep.solve_time_s,
                       "planning_time_s": rep.planning_time_s,
                       "proven_optimal": bool(rep.proven_optimal), "fallback": bool(rep.fallback),
                       "backend_used": rep.backend_used})
        if policy == "mwis" and 0 < rep.vertices <= cfg.corpus_max_vertices:
            instances.append({"epoch": e, "weights": [float(w) for w in rep.weights],
                              "edges": np.asarray(rep.edges_array).reshape(-1, 2).tolist(),
                              "groups": _groups_from_ids(rep.vertex_request_ids)})

    audit = {}
    if cfg.audit:
        audit = sweep_audit([f["_traj"] for f in flights], cfg.separation_m,
                            labels=[f["request_id"] for f in flights])
    for f in flights:
        del f["_traj"]
    mwis_epochs = [r for r in epochs if r["vertices"] > 0]
    summary = {
        "method": method, "rate": _rate(rate), "seed": int(seed), "duration_s": float(duration_s),
        "epochs": n_epochs, "requests": n_requests, "rejected": len(rejections),
        "approved": approved_cum, "expired": expired_cum,
        "pending_end": n_requests - len(rejections) - approved_cum - expired_cum,
        "approval_rate": approved_cum / n_requests if n_requests else float("nan"),
        "avg_airborne": average_airborne([f["departure_s"] for f in flights],
                                         [f["arrival_s"] for f in flights], duration_s),
        **_epoch_statistics(epochs),
        "proven_optimal_share": (float(np.mean([r["proven_optimal"] for r in mwis_epochs]))
                                 if mwis_epochs and policy == "mwis" else float("nan")),
        "fallbacks": int(sum(r["fallback"] for r in epochs)),
        "min_separation_m": audit.get("min_separation_m"),
        "losses": audit.get("losses"),
    }
    wall = time.perf_counter() - t_wall
    summary["wall_s"] = wall
    summary["real_time_factor"] = duration_s / wall if wall > 0 else float("inf")
    return ScenarioResult(method, _rate(rate), int(seed), float(duration_s), summary, epochs,
                          flights, audit, instances, rejections, wall)


# ---- cells, resumption, parallel sweep ------------------------------------------------------------

def cell_params(cfg: ExperimentConfig, method: str, rate, seed: int) -> dict:
    """Every parameter that affects a cell's result (its key is the hash of this)."""
    params = {"format": CELL_FORMAT, "method": method, "rate": _rate(rate), "seed": int(seed),
              "network": network_identity(cfg.network)}
    for name in ("duration_s", "epoch_s", "interval_s", "window_s", "separation_m", "k",
                 "penalty_factor", "speed_mps", "corpus_max_vertices", "audit"):
        params[name] = getattr(cfg, name)
    if method not in BASELINES:
        params["time_limit_s"] = cfg.time_limit_s
        params["solver_options"] = cfg.solver_options.get(method) or {}
    if cfg.demand_file:
        params["demand"] = hashlib.sha256(_resolve(cfg.demand_file).read_bytes()).hexdigest()
    return params


def cell_key(params: dict) -> str:
    digest = hashlib.sha256(json.dumps(params, sort_keys=True).encode()).hexdigest()[:16]
    return f"{params['method']}_r{params['rate']}_s{params['seed']}_{digest}"


def _write_json_atomic(path: Path, obj) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    fd, tmp = tempfile.mkstemp(dir=path.parent, prefix=path.name, suffix=".tmp")
    try:
        with os.fdopen(fd, "w", encoding="utf-8") as fh:
            json.dump(obj, fh, separators=(",", ":"))
        os.replace(tmp, path)
    except BaseException:
        if os.path.exists(tmp):
            os.unlink(tmp)
        raise


def _read_cell(path: Path, key: str) -> dict | None:
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, json.JSONDecodeError):
        return None
    return data if data.get("key") == key else None


def run_cell(cfg_dict: dict, method: str, rate, seed: int, cells_dir: str) -> dict:
    """Run one cell and write it to ``cells_dir/<key>.json`` atomically; returns the cell dict.

    Top-level so a process pool can call it; loads (and caches) the network in the worker.
    """
    cfg = make_config(cfg_dict)
    params = cell_params(cfg, method, rate, seed)
    key = cell_key(params)
    net = load_network_spec(cfg.network)
    demand = None
    if cfg.demand_file:
        demand = DemandSchedule(load_demand(_resolve(cfg.demand_file), net.aerodrome_ids),
                                cfg.interval_s)
    res = run_scenario(net, method, rate, seed, cfg.duration_s, cfg, demand=demand)
    cell = {"key": key, "params": params, "summary": res.summary, "epochs": res.epochs,
            "flights": res.flights, "audit": res.audit, "instances": res.instances,
            "rejections": res.rejections}
    _write_json_atomic(Path(cells_dir) / f"{key}.json", cell)
    return cell


@dataclass
class SweepResult:
    """Cells in sweep order (method, rate, seed), and which were computed or reused."""

    config: ExperimentConfig
    cells: list
    computed: list
    reused: list
    wall_s: float
    missing: list = field(default_factory=list)


def sweep_methods(cfg: ExperimentConfig) -> list:
    """The configured methods, plus "qpu" when include_qpu and the backend is available here."""
    methods = list(cfg.methods)
    if cfg.include_qpu and "qpu" not in methods:
        try:
            from uam_solvers.registry import get_backend
            ok, _ = get_backend("qpu").available()
        except Exception:  # an absent or broken optional backend just stays out of the sweep
            ok = False
        if ok:
            methods.append("qpu")
    return methods


def run_sweep(cfg: ExperimentConfig, progress: bool = True, compute: bool = True) -> SweepResult:
    """Run every missing cell (parallel over cfg.workers processes), reuse the finished ones.

    ``compute=False`` only collects the finished cells (the missing ones are listed in
    ``SweepResult.missing``), e.g. to report on a sweep that is still running.
    """
    t0 = time.perf_counter()
    out = Path(cfg.out)
    cells_dir = out / "cells"
    cells_dir.mkdir(parents=True, exist_ok=True)
    cfg_dict = asdict(cfg)
    grid = [(m, r, s) for m in sweep_methods(cfg) for r in cfg.rates for s in cfg.seeds]
    found: dict = {}
    todo = []
    for m, r, s in grid:
        key = cell_key(cell_params(cfg, m, r, s))
        cell = _read_cell(cells_dir / f"{key}.json", key)
        if cell is not None:
            found[(m, r, s)] = cell
        else:
            todo.append((m, r, s))
    reused = list(found)
    # seeds outermost: an interrupted sweep has every (method, rate) for the first seeds
    seed_rank = {sd: i for i, sd in enumerate(cfg.seeds)}
    todo.sort(key=lambda c: seed_rank[c[2]])
    if not compute:
        return SweepResult(cfg, [found[c] for c in grid if c in found], [], reused,
                           time.perf_counter() - t0, missing=todo)
    bar = None
    if progress and todo:
        from tqdm import tqdm
        bar = tqdm(total=len(todo), desc="cells", unit="cell")
    if cfg.workers <= 1 or len(todo) <= 1:
        for m, r, s in todo:
            found[(m, r, s)] = run_cell(cfg_dict, m, r, s, str(cells_dir))
            if bar:
                bar.update(1)
    else:
        import multiprocessing as mp
        with ProcessPoolExecutor(max_workers=min(cfg.workers, len(todo)),
                                 mp_context=mp.get_context("spawn")) as pool:
            futs = {pool.submit(run_cell, cfg_dict, m, r, s, str(cells_dir)): (m, r, s)
                    for m, r, s in todo}
            for fut in as_completed(futs):
                found[futs[fut]] = fut.result()
                if bar:
                    bar.update(1)
    if bar:
        bar.close()
    return SweepResult(cfg, [found[c] for c in grid], list(todo), reused,
                       time.perf_counter() - t0)


# ---- tidy outputs ------------------------------------------------------------------------------

def _write_csv(path: Path, rows: list) -> None:
    path.parent.mkdir(parents=True, exist_ok=True)
    cols: list = []
    for r in rows:
        for k in r:
            if k not in cols:
                cols.append(k)
    with path.open("w", newline="", encoding="utf-8") as fh:
        w = csv.DictWriter(fh, fieldnames=cols)
        w.writeheader()
        for r in rows:
            w.writerow(r)


def write_tables(sweep: SweepResult) -> dict:
    """runs.csv, epochs.csv, flights.csv in cfg.out; returns their paths."""
    out = Path(sweep.config.out)
    runs, epochs, flights = [], [], []
    for c in sweep.cells:
        s = c["summary"]
        runs.append(dict(s))
        tag = {"method": s["method"], "rate": s["rate"], "seed": s["seed"]}
        epochs.extend({**tag, **r} for r in c["epochs"])
        flights.extend({**tag, **f} for f in c["flights"])
    paths = {"runs": out / "runs.csv", "epochs": out / "epochs.csv", "flights": out / "flights.csv"}
    _write_csv(paths["runs"], runs)
    _write_csv(paths["epochs"], epochs)
    _write_csv(paths["flights"], flights)
    return paths


def write_corpus(sweep: SweepResult) -> tuple[Path | None, list]:
    """Save every collected MWIS instance (deduplicated) to <out>/instances.jsonl."""
    from uam_solvers.instances import CorpusEntry, save_corpus
    from uam_solvers import MwisProblem
    entries, seen = [], set()
    for c in sweep.cells:
        s = c["summary"]
        for inst in c["instances"]:
            sig = hashlib.sha1(json.dumps([inst["weights"], inst["edges"]]).encode()).hexdigest()
            if sig in seen:
                continue
            seen.add(sig)
            prob = MwisProblem.from_arrays(inst["weights"], inst["edges"], groups=inst["groups"] or None)
            name = f"{s['method']}-r{s['rate']}-s{s['seed']}-e{inst['epoch']:04d}"
            entries.append(CorpusEntry(name=name, problem=prob,
                                       source=f"uam_sim.experiment cell {c['key']} epoch {inst['epoch']}"))
    if not entries:
        return None, []
    path = save_corpus(Path(sweep.config.out) / "instances.jsonl", entries)
    return path, entries


def sample_tts_corpus(entries: list, n: int, min_v: int, max_v: int, seed: int) -> list:
    """Up to n instances with min_v..max_v vertices, sampled without replacement (seeded)."""
    pool = [e for e in entries if min_v <= e.problem.n <= max_v]
    if len(pool) <= n:
        return pool
    idx = np.sort(np.random.default_rng(seed).choice(len(pool), size=n, replace=False))
    return [pool[i] for i in idx.tolist()]


def run_tts(cfg: ExperimentConfig, entries: list) -> dict:
    """The TTS(p) study on a sample of the collected instances, through uam_solvers.tts.

    ``tts.source_seeds`` (optional list) restricts the pool to the runs of those seeds, so the
    study can start before the other seeds' runs finish and its sample does not change with them.
    Returns {"status": "ok"|"skipped", "reason", "csv", "rows", "corpus", "instances", ...}.
    """
    t = cfg.tts
    if not t.get("enabled", True):
        return {"status": "skipped", "reason": "disabled in the configuration (tts.enabled: false)"}
    if t.get("source_seeds") is not None:
        wanted = {int(x) for x in t["source_seeds"]}
        entries = [e for e in entries if int(e.name.rsplit("-s", 1)[1].split("-")[0]) in wanted]
    sample = sample_tts_corpus(entries, int(t["instances"]), int(t["min_vertices"]),
                               int(t["max_vertices"]), int(t.get("seed", 0)))
    if not sample:
        return {"status": "skipped", "reason": "no collected MWIS instance in the size range"}
    from uam_solvers.instances import save_corpus
    out = Path(cfg.out)
    corpus = save_corpus(out / "tts_corpus.jsonl", sample)
    try:
        from uam_solvers import tts as tts_mod
        run_study = tts_mod.run_study
    except (ImportError, AttributeError) as exc:
        return {"status": "skipped", "reason": f"uam_solvers.tts is not available ({exc})",
                "corpus": str(corpus), "instances": len(sample)}
    from uam_solvers.registry import get_backend
    backends, unavailable = [], {}
    for b in t["backends"]:
        try:
            ok, why = get_backend(b).available()
        except Exception as exc:  # unknown/broken backend: leave it out and say so
            ok, why = False, str(exc)
        if ok:
            backends.append(b)
        else:
            unavailable[b] = why
    caps = dict(t.get("backend_instances") or {})
    # a finished study of the same sample and settings is reused (like a finished cell)
    study_key = hashlib.sha256(json.dumps(
        {"names": [e.name for e in sample], "backends": backends, "caps": caps,
         "reads": int(t["reads"]), "repetitions": int(t.get("repetitions", 5)),
         "seed": int(t.get("seed", 0)), "time_limit_s": float(t.get("time_limit_s", 10.0))},
        sort_keys=True).encode()).hexdigest()
    cache = out / "tts_study.json"
    if cache.exists():
        try:
            cached = json.loads(cache.read_text(encoding="utf-8"))
        except (OSError, json.JSONDecodeError):
            cached = {}
        if cached.get("key") == study_key:
            cached["result"]["reused"] = True
            return cached["result"]
    t0 = time.perf_counter()
    rows, skipped = [], []
    for b in backends:
        # a slow backend may be studied on a seeded sub-sample of the same sample
        sub = sample_tts_corpus(sample, int(caps[b]), 0, 10**9, int(t.get("seed", 0)) + 1) \
            if b in caps else sample
        r, sk = run_study(sub, [b], repetitions=int(t.get("repetitions", 5)),
                          num_reads=int(t["reads"]), time_limit_s=float(t.get("time_limit_s", 10.0)),
                          seed=int(t.get("seed", 0)), log=lambda *a, **k: None)
        rows.extend(r)
        skipped.extend(x for x in sk if x not in skipped)
    wall = time.perf_counter() - t0
    tts_mod.write_csv(out / "tts.csv", rows)
    rows = [asdict(r) if hasattr(r, "__dataclass_fields__") else dict(r) for r in rows]
    result = {"status": "ok", "rows": rows, "csv": str(out / "tts.csv"), "corpus": str(corpus),
              "instances": len(sample), "skipped": skipped, "backends": backends,
              "unavailable": unavailable, "reads": int(t["reads"]),
              "repetitions": int(t.get("repetitions", 5)), "p": 0.99, "wall_s": wall,
              "backend_instances": caps}
    _write_json_atomic(cache, {"key": study_key, "result": result})
    return result


def machine_info() -> dict:
    try:
        commit = subprocess.run(["git", "-C", str(REPO_ROOT), "rev-parse", "HEAD"],
                                capture_output=True, text=True, timeout=10).stdout.strip()
        dirty = subprocess.run(["git", "-C", str(REPO_ROOT), "status", "--porcelain", "--",
                                "src", "config"], capture_output=True, text=True,
                               timeout=10).stdout.strip() != ""
    except (OSError, subprocess.SubprocessError):
        commit, dirty = "unknown", False
    cpu = platform.processor() or ""
    try:
        for line in Path("/proc/cpuinfo").read_text().splitlines():
            if line.startswith("model name"):
                cpu = line.split(":", 1)[1].strip()
                break
    except OSError:
        pass
    return {"commit": commit + (" (with uncommitted changes)" if dirty else ""),
            "python": sys.version.split()[0], "platform": platform.platform(), "cpu": cpu,
            "cores": os.cpu_count()}


def run_experiment(cfg: ExperimentConfig, progress: bool = True, figures: bool = True,
                   report: bool = True, compute: bool = True) -> dict:
    """The whole study: sweep, tables, corpus, TTS, figures and REPORT.md. Returns the outputs.

    ``compute=False``: use only the cells already finished (see :func:`run_sweep`).
    """
    t0 = time.perf_counter()
    sweep = run_sweep(cfg, progress=progress, compute=compute)
    tables = write_tables(sweep)
    corpus_path, entries = write_corpus(sweep)
    tts = run_tts(cfg, entries) if entries else {"status": "skipped",
                                                 "reason": "no MWIS instance was collected"}
    figs = {}
    if figures:
        from .figures import make_figures
        figs = make_figures(sweep.cells, cfg, tts, Path(cfg.out))
    outputs = {"sweep": sweep, "tables": tables, "corpus": corpus_path, "tts": tts,
               "figures": figs, "wall_s": time.perf_counter() - t0}
    if report:
        from .report import write_report
        outputs["report"] = write_report(sweep, outputs, machine_info(), Path(cfg.out))
    return outputs


# ---- MCAP recordings --------------------------------------------------------------------------

def cell_from_summary(summary, instances=(), label: str = "", seed: int = 0,
                      interval_s: float = 30.0) -> dict:
    """A cell (the dict the figures and report read) from a recording's analysis RunSummary.

    The method is the backend the planner used (``fifo`` when no epoch names one, as the FIFO
    policy uses none); the rate is the requests per interval over the recorded epochs; ``seed``
    labels the recording. Flights are not listed (the audit holds their count).
    """
    eps = list(summary.epochs)
    used = [e.backend_used for e in eps if e.backend_used and e.vertices > 0]
    method = max(set(used), key=used.count) if used else "fifo"
    n_epochs = max(len(eps), 1)
    rate = _rate(round(summary.requests / n_epochs, 2))
    duration = (eps[-1].t_s + interval_s) if eps else max(summary.sim_end_s - summary.sim_start_s, 1.0)
    rows, cum, cum_exp = [], 0, 0
    for e in eps:
        cum += e.approved
        cum_exp += e.expired
        rows.append({"epoch": e.epoch_index, "t_s": e.t_s, "eligible": e.eligible_requests,
                     "vertices": e.vertices, "edges": e.edges, "selected": e.selected if method != "fifo" else e.approved,
                     "approved_cum": cum, "expired": e.expired, "expired_cum": cum_exp,
                     "active": e.active_flights, "objective": e.objective,
                     "solve_time_s": e.solve_time_s, "proven_optimal": False,
                     "fallback": bool(e.fallback), "backend_used": e.backend_used})
    a = summary.audit
    audit = {}
    if a is not None:
        ms = a.min_separation_m if a.min_separation_m is not None and math.isfinite(a.min_separation_m) else None
        audit = {"min_separation_m": ms, "pair_of_min": a.closest_pair, "losses": len(a.losses),
                 "loss_pairs": [list(x) for x in a.losses[:20]], "pairs_checked": a.pairs_checked}
    s = {"method": method, "rate": rate, "seed": int(seed), "duration_s": float(duration),
         "epochs": len(eps), "requests": summary.requests, "rejected": summary.rejected,
         "approved": summary.approved, "expired": summary.expired,
         "pending_end": summary.undecided,
         "approval_rate": summary.approved / summary.requests if summary.requests else float("nan"),
         "avg_airborne": summary.average_active_aircraft,
         **_epoch_statistics(rows),
         "proven_optimal_share": float("nan"), "fallbacks": summary.fallbacks,
         "min_separation_m": audit.get("min_separation_m"), "losses": audit.get("losses"),
         "wall_s": float("nan"), "real_time_factor": float("nan"), "source": summary.path}
    insts = [{"epoch": i, "weights": [float(w) for w in p.weights],
              "edges": np.asarray(p.edges).reshape(-1, 2).tolist(),
              "groups": [np.asarray(g).tolist() for g in p.groups]} for i, p in enumerate(instances)]
    return {"key": f"mcap_{label or Path(summary.path).stem}", "params": {"source": summary.path},
            "summary": s, "epochs": rows, "flights": [], "audit": audit, "instances": insts,
            "rejections": []}


def study_from_mcaps(paths: Sequence[str], cfg: ExperimentConfig, figures: bool = True) -> dict:
    """The same tables, corpus, TTS, figures and report from node-graph recordings.

    Needs uam_sim.analysis. Each recording becomes one cell (seed = its position in ``paths``).
    """
    try:
        from . import analysis
    except ImportError as exc:
        raise ExperimentError(f"--from-mcap needs uam_sim.analysis, which is not available ({exc})")
    t0 = time.perf_counter()
    cells = []
    for i, p in enumerate(paths):
        summary = analysis.summarize(p, separation_m=cfg.separation_m)
        inst = [x for x in analysis.instances_from_mcap(p) if x.n <= cfg.corpus_max_vertices]
        cells.append(cell_from_summary(summary, inst, label=Path(p).stem, seed=i,
                                       interval_s=cfg.interval_s))
    sweep = SweepResult(cfg, cells, [], [], time.perf_counter() - t0)
    Path(cfg.out).mkdir(parents=True, exist_ok=True)
    tables = write_tables(sweep)
    corpus_path, entries = write_corpus(sweep)
    tts = run_tts(cfg, entries) if entries else {"status": "skipped",
                                                 "reason": "no MWIS instance was recorded"}
    figs = {}
    if figures:
        from .figures import make_figures
        figs = make_figures(cells, cfg, tts, Path(cfg.out))
    outputs = {"sweep": sweep, "tables": tables, "corpus": corpus_path, "tts": tts,
               "figures": figs, "wall_s": time.perf_counter() - t0}
    if figures:
        from .report import write_report
        outputs["report"] = write_report(sweep, outputs, machine_info(), Path(cfg.out))
    return outputs


def format_timing_table(cells) -> str:
    """Per method and rate: cells, mean wall time per run [s], mean real-time factor."""
    lines = [f"{'method':<14}{'rate':>6}{'cells':>7}{'wall/run [s]':>14}{'real-time x':>13}"]
    groups: dict = {}
    for c in cells:
        s = c["summary"]
        groups.setdefault((s["method"], s["rate"]), []).append(s)
    for (m, r), ss in groups.items():
        w = [x["wall_s"] for x in ss if x.get("wall_s") == x.get("wall_s")]
        f = [x["real_time_factor"] for x in ss if x.get("real_time_factor") == x.get("real_time_factor")]
        lines.append(f"{m:<14}{r:>6}{len(ss):>7}{(np.mean(w) if w else float('nan')):>14.2f}"
                     f"{(np.mean(f) if f else float('nan')):>13.0f}")
    total = sum(x["summary"].get("wall_s") or 0.0 for x in cells)
    lines.append(f"sum of per-run wall times: {total:.1f} s")
    return "\n".join(lines)


# ---- command line --------------------------------------------------------------------------------

def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="experiment", description=__doc__.split("\n\n")[0])
    p.add_argument("--config", help="YAML experiment file (config/experiment.yaml)")
    p.add_argument("--network", help="network file (overrides the config)")
    p.add_argument("--rates", help="comma list of requests per interval, e.g. 1,2,4")
    p.add_argument("--methods", help="comma list: fifo and MWIS backend names")
    p.add_argument("--seeds", help="a count n (seeds 0..n-1) or a comma list of seeds")
    p.add_argument("--duration", type=float, dest="duration_s", help="simulated seconds per run")
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="MWIS time limit [s]")
    p.add_argument("--workers", type=int, help="processes (1 = serial)")
    p.add_argument("--out", help="output directory")
    p.add_argument("--demand", dest="demand_file", help="replay a demand file instead")
    p.add_argument("--tts-reads", type=int, help="reads per annealing run in the TTS study")
    p.add_argument("--tts-instances", type=int, help="instances in the TTS study")
    p.add_argument("--no-tts", action="store_true", help="skip the TTS study")
    p.add_argument("--no-figures", action="store_true", help="skip figures and report")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-compute", action="store_true",
                   help="only collect finished cells (report on a partial sweep)")
    p.add_argument("--from-mcap", nargs="+", metavar="FILE",
                   help="summarise node-graph recordings instead of running the sweep")
    return p


def main(argv: list | None = None) -> int:
    args = build_parser().parse_args(argv)
    over = {k: getattr(args, k) for k in ("network", "rates", "methods", "seeds", "duration_s",
                                          "time_limit_s", "workers", "out", "demand_file")}
    try:
        base = yaml.safe_load(Path(args.config).read_text()) if args.config else {}
        base = base or {}
        tts = dict(base.get("tts") or {})
        if args.tts_reads is not None:
            tts["reads"] = args.tts_reads
        if args.tts_instances is not None:
            tts["instances"] = args.tts_instances
        if args.no_tts:
            tts["enabled"] = False
        if tts:
            base["tts"] = tts
        cfg = make_config(base, **over)
    except (ExperimentError, OSError, yaml.YAMLError) as exc:
        print(f"experiment: {exc}", file=sys.stderr)
        return 2
    if args.from_mcap:
        outputs = study_from_mcaps(args.from_mcap, cfg, figures=not args.no_figures)
    else:
        outputs = run_experiment(cfg, progress=not args.no_progress, figures=not args.no_figures,
                                 report=not args.no_figures, compute=not args.no_compute)
    sweep = outputs["sweep"]
    print(format_timing_table(sweep.cells))
    print(f"{len(sweep.cells)} cells ({len(sweep.computed)} computed, {len(sweep.reused)} reused) "
          f"in {outputs['wall_s']:.1f} s; results in {cfg.out}")
    losses = sum((c["summary"].get("losses") or 0) for c in sweep.cells)
    if losses:
        print(f"experiment: SAFETY AUDIT FOUND {losses} LOSSES OF SEPARATION", file=sys.stderr)
        return 1
    if "report" in outputs:
        print(f"report: {outputs['report']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
