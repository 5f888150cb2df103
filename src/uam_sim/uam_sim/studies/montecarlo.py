"""Monte-Carlo of flights that do not fly to plan: disturbance level x planning buffer.

    python -m uam_sim.montecarlo --speed-errors 0,0.05,0.1 --spatial-buffers 0,10,25,50 \
        --temporal-buffers 0,5,10 --seeds 4 --rate 10 --duration 1800 --workers 2 \
        --out results/montecarlo [--network SPEC] [--gust 1.0 --delay-mean 10 --wind 3]

Each *point* of the grid (speed error, spatial buffer, temporal buffer) is a set of seeded runs of
the in-process runner (:func:`uam_sim.runner.scenario.run_scenario`, one MWIS method) in which the
planner plans with the buffers and the aircraft fly the disturbance model
(:mod:`uam_sim.world.disturbance`). Every run of every point is one cell of the experiment runner, so
the cells run on its Dask scheduler (a LocalCluster of ``--workers`` processes, or
``--scheduler tcp://HOST:8786``), are written as they finish and are reused by a later call
(resumable). Per point it reports, over the point's runs: flights flown, approval rate, time in
conformance (F3548), excursions per flight hour, longest excursion, re-plans (by the reaction to
nonconformance, when it is on) and the **losses of separation in what flew**: the exact
closest approach between the flown tracks (:func:`uam_sim.audit.flown.flown_audit`) in the true
minimum, never the buffered one. Writes ``<out>/montecarlo.csv`` and prints the table.

The options it shares with the node graph (network, rate, wind, gusts, departure delay, the
reaction's period, the probe and its margin) default to run_fleet.sh's, from the launchers' one
table (``uam_contract.launch_options``; a test holds them equal): with no flag, the Singapore
network and no disturbance but the swept speed errors. The disturbance study's world is
``--network synthetic:n_nodes=400,n_aerodromes=30,seed=1 --gust 1`` (docs/disturbances.md).
Its own defaults: 4 seeds of 1,800 s and the greedy MWIS (a grid of points needs many runs).
"""

from __future__ import annotations

import argparse
import csv
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .experiment import key_values
from ..runner.experiment_config import ExperimentError, make_config
from ..runner.sweep import cell_key, cell_params, run_cell

#: the disturbance study's network (its commands name it: docs/disturbances.md)
STUDY_NETWORK = {"synthetic": {"n_nodes": 400, "n_aerodromes": 30, "seed": 1}}


def _shared_default(flag: str) -> str:
    """run_fleet.sh's default of ``flag`` (the launchers' one table)."""
    from uam_contract.launch_options import LAUNCH_OPTIONS
    return next(o.default for o in LAUNCH_OPTIONS if o.flag == flag)
COLUMNS = ("speed_error", "spatial_buffer_m", "temporal_buffer_s", "reaction", "runs", "requests", "flights",
           "approval_rate", "conformance_percent", "excursions_per_flight_hour", "longest_excursion_s",
           "nonconforming_flights", "replans", "flown_losses", "flown_min_separation_m",
           "planned_losses", "nonconforming_updates", "reaction_contingencies", "held_past_plan",
           "approval_ci95_low", "approval_ci95_high", "flown_losses_per_flight_upper95",
           "planned_losses_deconflicted", "flown_losses_with_contingency", "flown_losses_near_vertiport",
           "probe_updates")


def spread_ci95(values, bounds: tuple = (-math.inf, math.inf)) -> tuple[float, float]:
    """The 95 % confidence interval of the mean of per-run values (Student's t over the runs:
    the runs are independent, the flights of one run are not); (nan, nan) below 2 runs."""
    from scipy import stats
    v = np.asarray(list(values), dtype=np.float64)
    if v.size < 3:   # with 2 runs Student's t is 12.7 standard errors wide: no interval to speak of
        return math.nan, math.nan
    half = float(stats.t.ppf(0.975, v.size - 1) * v.std(ddof=1) / math.sqrt(v.size))
    return float(max(v.mean() - half, bounds[0])), float(min(v.mean() + half, bounds[1]))


def poisson_upper95(k: int, n: int) -> float:
    """The one-sided 95 % upper bound of a rate per flight from k events in n flights (exact
    Poisson: chi2(0.95, 2k + 2) / 2 / n; 0 events: 3.0 / n, the rule of three); nan for n = 0."""
    from scipy import stats
    if n <= 0:
        return math.nan
    return float(stats.chi2.ppf(0.95, 2 * int(k) + 2) / 2.0 / n)


def _num_list(text: str) -> list[float]:
    try:
        return [float(x) for x in text.split(",") if x.strip()]
    except ValueError:
        raise argparse.ArgumentTypeError(f"{text!r} is not a comma list of numbers") from None


def _reaction(text: str) -> list[bool]:
    opts = {"off": [False], "on": [True], "both": [False, True]}
    if text not in opts:
        raise argparse.ArgumentTypeError(f"--reaction: {text!r} is not one of off, on, both")
    return opts[text]


def _network(text: str):
    if text.startswith("synthetic:"):
        return {"synthetic": key_values(text.split(":", 1)[1])}
    return text


def point_disturbance(args, speed_error: float) -> dict:
    """The disturbance fields of a point at ``speed_error``: its flags', then ``--disturbance``'s
    (ExperimentError when that sets a field one of the flags sets)."""
    dist = {"speed_error": speed_error, "gust_std_mps": args.gust, "delay_mean_s": args.delay_mean,
            "wind_speed_mps": args.wind, "step_s": args.step, "time_gain_per_s": args.time_gain}
    more = dict(getattr(args, "disturbance", None) or {})
    taken = sorted(set(more) & set(dist))
    if taken:
        raise ExperimentError(f"--disturbance: {taken[0]} is set by a flag of its own")
    return {**dist, **more}


def point_configs(args) -> list[tuple[tuple, dict]]:
    """((speed error, spatial, temporal, reaction), config dict) of every grid point."""
    out = []
    if getattr(args, "axes", False):   # each buffer alone: spatial at 0 s, then temporal at 0 m
        combos = [(bs, 0.0) for bs in args.spatial_buffers] + \
                 [(0.0, bt) for bt in args.temporal_buffers if bt > 0]
    else:                              # the full product
        combos = [(bs, bt) for bs in args.spatial_buffers for bt in args.temporal_buffers]
    for e in args.speed_errors:
        for (bs, bt), react in ((c, r) for c in combos for r in args.reaction):
            dist = point_disturbance(args, e)
            cfg = make_config({"network": args.network, "methods": [args.method], "rates": [args.rate],
                               "seeds": args.seeds, "duration_s": args.duration,
                               "time_limit_s": args.time_limit, "spatial_buffer_m": bs,
                               "temporal_buffer_s": bt, "disturbance": dist,
                               "conformance": args.conformance or {}, "out": args.out,
                               "reaction": react,
                               "reaction_period_s": args.reaction_period if react else 0.0,
                               "conflict_probe_s": getattr(args, "probe", 0.0) if react else 0.0,
                               "conflict_probe_margin_m": getattr(args, "probe_margin", 0.0)
                               if react and getattr(args, "probe", 0.0) else 0.0,
                               "workers": args.workers, "scheduler": args.scheduler,
                               "corpus_max_vertices": 0})
            out.append(((e, bs, bt, react), asdict(cfg)))
    return out


def aggregate(point: tuple, cells: list[dict]) -> dict:
    """One row of the table from a point's cells (flight-time weighted conformance)."""
    s = [c["summary"] for c in cells]
    hours = sum(x["conf_flight_hours"] for x in s)
    req = sum(x["requests"] for x in s)
    appr = sum(x["approved"] for x in s)
    mins = [x["flown_min_separation_m"] for x in s if x["flown_min_separation_m"] is not None]
    return {"speed_error": point[0], "spatial_buffer_m": point[1], "temporal_buffer_s": point[2],
            "reaction": bool(point[3]) if len(point) > 3 else False, "runs": len(cells), "requests": req, "flights": appr,
            "approval_rate": appr / req if req else float("nan"),
            "conformance_percent": (sum(x["conf_conformance_percent"] * x["conf_flight_hours"] for x in s)
                                    / hours if hours else 100.0),
            "excursions_per_flight_hour": sum(x["conf_excursions"] for x in s) / hours if hours else 0.0,
            "longest_excursion_s": max(x["conf_longest_excursion_s"] for x in s),
            "nonconforming_flights": sum(x["conf_nonconforming_flights"] for x in s),
            "replans": sum(x["replans"] for x in s),
            "flown_losses": sum(x["flown_losses"] for x in s),
            "flown_min_separation_m": min(mins) if mins else None,
            "planned_losses": sum(x["losses"] or 0 for x in s),
            # of which between plans the planner deconflicted (the reaction's contingencies left
            # out; without the reaction every plan is deconflicted)
            "planned_losses_deconflicted": sum((x["losses_deconflicted"] if "losses_deconflicted" in x
                                                else x["losses"]) or 0 for x in s),
            "nonconforming_updates": sum(x.get("nonconforming_updates", 0) for x in s),
            "reaction_contingencies": sum(x.get("reaction_contingencies", 0) for x in s),
            # flights the planner held past their plans (safety gap; 0 in cells run
            # before it)
            "held_past_plan": sum(x.get("held_past_plan", 0) for x in s),
            # uncertainty: the approval rate's spread over the runs, the flown-loss rate's bound
            **dict(zip(("approval_ci95_low", "approval_ci95_high"),
                       spread_ci95((x["approved"] / x["requests"] for x in s if x["requests"]),
                                   (0.0, 1.0)))),   # a share: the interval within [0, 1]
            "flown_losses_per_flight_upper95": poisson_upper95(sum(x["flown_losses"] for x in s), appr),
            # of the flown losses, those with a flight flown as a contingency (None: not known
            # for every run: cells from before the count, or more losses than listed)
            "flown_losses_with_contingency": (sum(x["flown_losses_with_contingency"] for x in s)
                                              if all(x.get("flown_losses_with_contingency") is not None
                                                     for x in s) else None),
            # of the flown losses, those near a vertiport both flights use (None: not known for
            # every run), scenario.VERTIPORT_AREA_M
            "flown_losses_near_vertiport": (sum(x["flown_losses_near_vertiport"] for x in s)
                                            if all(x.get("flown_losses_near_vertiport") is not None
                                                   for x in s) else None),
            # updates the planner's conflict probe asked for (0 without the probe)
            "probe_updates": sum(x.get("reaction_probe_updates", 0) for x in s)}


def run(args) -> list[dict]:
    cells_dir = Path(args.out) / "cells"
    cells_dir.mkdir(parents=True, exist_ok=True)
    points = point_configs(args)
    todo, keys, confs, found = [], {}, {}, {}
    for i, (_pt, conf) in enumerate(points):
        cfg = make_config(conf)
        for s in cfg.seeds:
            c = (i, args.method, cfg.rates[0], s)
            key = cell_key(cell_params(cfg, args.method, cfg.rates[0], s))
            path = cells_dir / f"{key}.json"
            if path.exists():
                import json
                cell = json.loads(path.read_text())
                if cell.get("key") == key:
                    found[c] = cell
                    continue
            todo.append(c)
            keys[c] = key
            confs[c] = conf
    todo.sort(key=lambda c: c[3])  # seeds outermost: an interrupted run has every point's first seeds
    if getattr(args, "existing_only", False):
        todo = []   # the table of the cells already there (an interrupted or a running study)
    if todo and args.workers <= 1 and args.scheduler in (None, "local"):
        for c in todo:
            found[c] = run_cell(confs[c], c[1], c[2], c[3], str(cells_dir))
    elif todo:
        from ..runner.dask_cluster import run_cells
        found.update(run_cells(points[0][1], todo, keys, cells_dir, run_cell,
                               scheduler=args.scheduler or "local", n_workers=args.workers,
                               cell_configs=confs))
    rows = []
    for i, (pt, conf) in enumerate(points):
        cells = [v for c, v in found.items() if c[0] == i]
        if cells:
            rows.append(aggregate(pt, cells))
    return rows


def format_table(rows: list[dict]) -> str:
    head = ("| speed error | buffer m | buffer s | reaction | runs | flights | approval | conformance | "
            "exc/h | longest exc s | updates | flown losses | flown min sep m | planned losses | "
            "of which deconflicted | approval 95 % CI (runs) | flown losses / flight, 95 % upper | "
            "flown losses near a vertiport |")
    out = [head, "|" + "---|" * 18]
    for r in rows:
        ms = r["flown_min_separation_m"]
        lo, hi = r.get("approval_ci95_low", math.nan), r.get("approval_ci95_high", math.nan)
        ci = "-" if not (math.isfinite(lo) and math.isfinite(hi)) else f"{100 * lo:.1f}-{100 * hi:.1f} %"
        up = r.get("flown_losses_per_flight_upper95", math.nan)
        out.append(f"| {100 * r['speed_error']:.0f} % | {r['spatial_buffer_m']:g} | {r['temporal_buffer_s']:g} | "
                   f"{'on' if r['reaction'] else 'off'} | "
                   f"{r['runs']} | {r['flights']} | {100 * r['approval_rate']:.1f} % | "
                   f"{r['conformance_percent']:.2f} % | {r['excursions_per_flight_hour']:.2f} | "
                   f"{r['longest_excursion_s']:.0f} | {r['nonconforming_updates']} | {r['flown_losses']} | "
                   f"{'-' if ms is None else f'{ms:.1f}'} | {r['planned_losses']} | "
                   f"{r.get('planned_losses_deconflicted', r['planned_losses'])} | {ci} | "
                   f"{'-' if not math.isfinite(up) else f'{up:.4f}'} | "
                   f"{'-' if r.get('flown_losses_near_vertiport') is None else r['flown_losses_near_vertiport']} |")
    return "\n".join(out)


def figure(rows: list[dict], path) -> Path:
    """Approval rate, conformance and flown losses against the buffer, one line per speed error
    (spatial buffers at temporal 0, then temporal buffers at spatial 0 on the same axis as
    'b m' and 'tau s' ticks)."""
    import matplotlib
    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    def label(r):
        return (f"{r['spatial_buffer_m']:g} m" if r["temporal_buffer_s"] == 0 else
                f"{r['spatial_buffer_m']:g} m+{r['temporal_buffer_s']:g} s")
    buffers = []
    for r in sorted(rows, key=lambda r: (r["temporal_buffer_s"], r["spatial_buffer_m"])):
        if label(r) not in buffers:
            buffers.append(label(r))
    fig, axes = plt.subplots(1, 3, figsize=(14, 4.2))
    for e, react in sorted({(r["speed_error"], bool(r.get("reaction"))) for r in rows}):
        pts = {label(r): r for r in rows if r["speed_error"] == e and bool(r.get("reaction")) == react}
        xs = [i for i, b in enumerate(buffers) if b in pts]
        name = f"speed error {100 * e:.0f} %" + (", reaction" if react else "")
        for ax, key, scale in ((axes[0], "approval_rate", 100.0), (axes[1], "conformance_percent", 1.0),
                               (axes[2], "flown_losses", 1.0)):
            ax.plot(xs, [pts[buffers[i]][key] * scale for i in xs], marker="o", ls="--" if react else "-",
                    label=name)
    for ax, title in zip(axes, ("approval rate [%]", "time in conformance [%] (F3548: >= 95)",
                                "losses of separation in what flew [pairs]")):
        ax.set_xticks(range(len(buffers)))
        ax.set_xticklabels(buffers, rotation=30)
        ax.set_xlabel("planning buffer (spatial m + temporal s)")
        ax.set_title(title)
        ax.grid(alpha=0.3)
    axes[1].axhline(95.0, color="grey", ls="--", lw=1)
    axes[0].legend()
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return path


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="montecarlo", description=__doc__.split("\n\n")[0], allow_abbrev=False)
    p.add_argument("--network", type=_network, default=_shared_default("--network"),
                   help="network file or synthetic:n_nodes=N,n_aerodromes=A,seed=S (default: run_fleet.sh's, "
                        f"{_shared_default('--network')}; the disturbance study's: "
                        "synthetic:n_nodes=400,n_aerodromes=30,seed=1)")
    p.add_argument("--speed-errors", type=_num_list, default=[0.0, 0.05, 0.1])
    p.add_argument("--spatial-buffers", type=_num_list, default=[0.0, 10.0, 25.0, 50.0])
    p.add_argument("--temporal-buffers", type=_num_list, default=[0.0, 5.0, 10.0])
    p.add_argument("--axes", action="store_true",
                   help="each buffer alone (spatial buffers at 0 s, temporal at 0 m) instead of every pair")
    p.add_argument("--gust", type=float, default=float(_shared_default("--gust")),
                   help="gust std per component [m/s] (default run_fleet.sh's, 0; the disturbance study's: 1)")
    p.add_argument("--wind", type=float, default=float(_shared_default("--wind")),
                   help="steady wind [m/s] (default run_fleet.sh's, 0)")
    p.add_argument("--delay-mean", type=float, default=float(_shared_default("--delay-mean")),
                   help="mean departure delay [s] (default run_fleet.sh's, 0)")
    p.add_argument("--time-gain", type=float, default=0.0,
                   help="along-track (4D) guidance gain [1/s]; 0 = airspeed held, no time control (default)")
    p.add_argument("--step", type=float, default=1.0, help="disturbance model step [s] (default 1)")
    p.add_argument("--disturbance", type=key_values, metavar="K=V,...",
                   help="more disturbance fields for every point: DisturbanceConfig fields without a flag "
                        "here, or a registered effect's own (docs/extending.md), e.g. "
                        "vertical_gust_std_mps=0.5,altitude_error_m=10")
    p.add_argument("--reaction", type=_reaction, default=[False],
                   help="the planner's reaction to nonconforming flights: off (default), on or both")
    p.add_argument("--reaction-period", type=float, default=float(_shared_default("--reaction-period")), metavar="S",
                   help="with the reaction on, also react every S seconds between epochs "
                        "(0 = at the epochs only)")
    p.add_argument("--probe", type=float, default=float(_shared_default("--probe")), metavar="S",
                   help="with the reaction on, the planner's conflict probe look-ahead [s] "
                        "(PlanningConfig.conflict_probe_s; 0 = no probe, default)")
    p.add_argument("--probe-margin", type=float, default=float(_shared_default("--probe-margin")), metavar="M",
                   help="with the probe, its margin [m]: it predicts losses of the minimum + M and "
                        "deconflicts its own updates with at least that (PlanningConfig."
                        "conflict_probe_margin_m; 0 = the true minimum, default)")
    p.add_argument("--conformance", type=key_values, help="conformance bounds, e.g. lateral_m=30,time_s=10")
    p.add_argument("--seeds", default="4", help="a count n (seeds 0..n-1) or a comma list")
    p.add_argument("--rate", type=float, default=float(_shared_default("--rate")),
                   help="requests per 30 s (default run_fleet.sh's, 10)")
    p.add_argument("--duration", type=float, default=1800.0, help="simulated seconds per run (default 1800)")
    p.add_argument("--method", default="greedy", help="MWIS backend or fifo/firstfit (default greedy)")
    p.add_argument("--time-limit", type=float, default=5.0, help="MWIS time limit [s]")
    p.add_argument("--workers", type=int, default=2)
    p.add_argument("--scheduler", default=None, help="'local' or tcp://HOST:8786")
    p.add_argument("--out", default="results/montecarlo")
    p.add_argument("--figure", help="also write the figure (PNG) here")
    p.add_argument("--existing-only", action="store_true",
                   help="run nothing: the table (and figure) of the cells already in --out, seeds "
                        "that are not there left out (a point without any is not listed)")
    return p


def main(argv=None) -> int:
    args = build_parser().parse_args(argv)
    t0 = time.perf_counter()
    try:
        rows = run(args)
    except ExperimentError as exc:
        print(f"montecarlo: {exc}", file=sys.stderr)
        return 2
    out = Path(args.out) / "montecarlo.csv"
    with out.open("w", newline="") as fh:
        w = csv.DictWriter(fh, fieldnames=COLUMNS)
        w.writeheader()
        w.writerows(rows)
    print(format_table(rows))
    if args.figure:
        print(f"figure: {figure(rows, args.figure)}")
    print(f"{len(rows)} points in {time.perf_counter() - t0:.1f} s; table in {out}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
