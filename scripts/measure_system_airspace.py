#!/usr/bin/env python3
"""Issue 10's system-level measurements through the in-process runner (uam_sim.runner.scenario).

    nice -n 5 .venv/bin/python scripts/measure_system_airspace.py singapore
    nice -n 5 .venv/bin/python scripts/measure_system_airspace.py city --instances results/city-mwis.jsonl

Both go through ``uam_sim.runner.scenario.run_scenario`` with an ``ExperimentConfig`` (the runner's
airspace options, the same ones ``python -m uam_sim.experiment`` and ``scripts/run_fleet.sh``
take), and the runner's own audit (``uam_sim.audit.separation.sweep_audit``) in the run's separation model.

``singapore``: the paper's demand (``--rate`` requests per 30 s, window 60 s, seed ``--seed``)
for ``--duration`` s, once in paper mode (config/networks/singapore.yaml, sphere 100 m, departure
at the epoch) and once in the expanded airspace (singapore-layered.yaml, cylinder H 100 m /
V 30 m, ``--slot-s`` departure slots): the same requests (the files share aerodrome ids and the
generator is seeded). ``city``: ``generate_network(--nodes, --vertiports, seed 0, levels
60/90/120/150 m, 4 pads)`` offered ``--per-hour`` requests per hour in the expanded airspace.

Prints per run: requests, approved (share), expired, airborne at peak (sampled every 5 s) and
time-average, MWIS vertices (median, max), the planning cycle without the solve (median, max:
the report's ``planning_time_s``, i.e. prepare + commit without waiting for the solver), the
solve time, and the audit. CPU time of the cycle without the solve is measured too (the
process's CPU time per epoch, from one observer call to the next, minus the CPU time spent inside
``uam_solvers.solve``), because on this shared machine wall times are inflated by other load. ``--instances FILE`` writes the expanded run's MWIS instances with at
least ``--instances-min-vertices`` vertices as a uam-mwis-corpus/1 JSON Lines file
(``uam_solvers.instances.load_corpus`` reads it). Wall times depend on the machine's load; the
approvals do not.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from uam_sim.studies.capacity_study import airborne_peak  # noqa: E402
from uam_sim.runner.experiment_config import make_config  # noqa: E402
from uam_sim.runner.network_spec import load_network_spec  # noqa: E402
from uam_sim.runner.scenario import groups_from_ids, run_scenario  # noqa: E402

LEVELS_M = [60.0, 90.0, 120.0, 150.0]


class CpuClock:
    """CPU seconds per epoch without the solve: wraps ``uam_solvers.solve`` (which the runner's
    solve function calls) to sum its CPU time, and takes the process CPU time at each epoch's
    observer call. ``time.process_time`` counts every thread of the process."""

    def __init__(self):
        import uam_solvers

        self.solve_cpu_s = 0.0
        self._last = time.process_time()
        self._last_solve = 0.0
        self.per_epoch_s = []
        inner = uam_solvers.solve

        def solve(*a, **kw):
            t = time.process_time()
            try:
                return inner(*a, **kw)
            finally:
                self.solve_cpu_s += time.process_time() - t
        uam_solvers.solve = solve

    def tick(self) -> None:
        now = time.process_time()
        self.per_epoch_s.append((now - self._last) - (self.solve_cpu_s - self._last_solve))
        self._last, self._last_solve = now, self.solve_cpu_s


class InstanceWriter:
    """Observer of run_scenario keeping the MWIS instances of at least ``min_vertices`` (and
    ticking the CPU clock)."""

    def __init__(self, min_vertices: int, source: str, clock: CpuClock | None = None):
        self.min_vertices = min_vertices
        self.source = source
        self.entries = []
        self.clock = clock

    def __call__(self, t_s, epoch_index, submitted, refused, result) -> None:
        from uam_solvers.base import MwisProblem
        from uam_solvers.instances import CorpusEntry

        if self.clock is not None:
            self.clock.tick()
        rep = result.report
        if self.min_vertices is None or rep.vertices < self.min_vertices:
            return
        groups = groups_from_ids(rep.vertex_request_ids)
        edges = np.asarray(rep.edges_array, dtype=np.int64).reshape(-1, 2)
        problem = MwisProblem.from_arrays(np.asarray(rep.weights, dtype=np.float64), edges, groups)
        self.entries.append(CorpusEntry(f"{self.source}-e{epoch_index:04d}-v{rep.vertices}", problem,
                                        f"{self.source} epoch {epoch_index} t={t_s:g}s"))


def run(label: str, network_spec, rate: float, args, airspace: dict, observer=None) -> dict:
    cfg = make_config({"network": network_spec, "duration_s": args.duration, "audit": True,
                       "time_limit_s": args.time_limit, **airspace})
    net = load_network_spec(network_spec)
    if observer is None:
        observer = InstanceWriter(None, "")
    observer.clock = CpuClock()
    t0 = time.perf_counter()
    res = run_scenario(net, args.method, rate, args.seed, args.duration, cfg, observer=observer)
    wall = time.perf_counter() - t0
    s, a = res.summary, res.audit
    cycles = [e["planning_time_s"] for e in res.epochs]
    solves = [e["solve_time_s"] for e in res.epochs if e["vertices"] > 0]
    verts = [e["vertices"] for e in res.epochs]
    out = {"label": label, "requests": s["requests"], "approved": s["approved"],
           "expired": s["expired"], "share": s["approved"] / max(s["requests"], 1),
           "peak": airborne_peak(res.flights, args.duration), "mean": s["avg_airborne"],
           "v_median": statistics.median(verts), "v_max": max(verts),
           "cycle_median_ms": 1e3 * statistics.median(cycles), "cycle_max_ms": 1e3 * max(cycles),
           "solve_median_ms": 1e3 * statistics.median(solves) if solves else 0.0,
           "losses": a.get("losses"), "min_sep": a.get("min_separation_m"),
           "pairs": a.get("pairs_checked"), "model": a.get("separation_model", "sphere"),
           "wall_s": wall, "fallbacks": s["fallbacks"],
           "cpu_median_ms": 1e3 * statistics.median(observer.clock.per_epoch_s),
           "cpu_max_ms": 1e3 * max(observer.clock.per_epoch_s)}
    print(f"{label}: {out['requests']} requests, {out['approved']} approved "
          f"({100 * out['share']:.1f} %), {out['expired']} expired; airborne peak {out['peak']}, "
          f"mean {out['mean']:.0f}; MWIS vertices median {out['v_median']:.0f}, max {out['v_max']}; "
          f"cycle without solve median {out['cycle_median_ms']:.0f} ms, max {out['cycle_max_ms']:.0f} ms wall, "
          f"CPU median {out['cpu_median_ms']:.0f} ms, max {out['cpu_max_ms']:.0f} ms; "
          f"solve median {out['solve_median_ms']:.0f} ms ({args.method}, {out['fallbacks']} fallbacks); "
          f"audit ({out['model']}): {out['losses']} losses in {out['pairs']} pairs, min "
          f"{out['min_sep'] if out['min_sep'] is None else round(out['min_sep'], 1)} m; "
          f"wall {wall:.0f} s", flush=True)
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", choices=["singapore", "city"])
    ap.add_argument("--rate", type=float, default=20.0, help="requests per 30 s (singapore)")
    ap.add_argument("--duration", type=float, default=3500.0, help="simulated seconds")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--slot-s", type=float, default=5.0, help="departure slot [s]")
    ap.add_argument("--method", default="greedy", help="fifo or an MWIS backend (default greedy)")
    ap.add_argument("--time-limit", type=float, default=10.0, help="MWIS time limit [s]")
    ap.add_argument("--nodes", type=int, default=2000)
    ap.add_argument("--vertiports", type=int, default=100)
    ap.add_argument("--per-hour", type=float, default=3000.0, help="requests per hour (city)")
    ap.add_argument("--skip-paper", action="store_true", help="singapore: the layered run only")
    ap.add_argument("--instances", default=None, help="corpus file for the expanded run's MWIS instances")
    ap.add_argument("--instances-min-vertices", type=int, default=1000)
    args = ap.parse_args(argv)
    expanded = {"separation_model": "cylinder", "vertical_separation_m": 30.0,
                "departure_slot_s": args.slot_s}
    print(f"{args.case}: {args.duration:g} s, seed {args.seed}, method {args.method}, "
          f"slot {args.slot_s:g} s", flush=True)
    if args.case == "singapore":
        src = "singapore-layered"
        if not args.skip_paper:
            paper = run("paper mode (singapore.yaml, sphere 100 m, depart at the epoch)",
                        "config/networks/singapore.yaml", args.rate, args, {})
        writer = InstanceWriter(args.instances_min_vertices, src) if args.instances else None
        layered = run(f"layered (singapore-layered.yaml, cylinder 100/30 m, {args.slot_s:g} s slots)",
                      "config/networks/singapore-layered.yaml", args.rate, args, expanded, writer)
        if not args.skip_paper:
            print(f"approvals layered / paper: {layered['approved'] / max(paper['approved'], 1):.2f}x")
    else:
        spec = {"synthetic": {"n_nodes": args.nodes, "n_aerodromes": args.vertiports, "seed": 0,
                              "levels_m": LEVELS_M, "pads_per_vertiport": 4}}
        rate = args.per_hour * 30.0 / 3600.0
        src = f"city{args.nodes}-{args.vertiports}"
        writer = InstanceWriter(args.instances_min_vertices, src) if args.instances else None
        run(f"city ({args.nodes} nodes, {args.vertiports} vertiports, 4 levels, 4 pads; "
            f"{args.per_hour:g} requests/h = {rate:g} per 30 s; cylinder 100/30 m, {args.slot_s:g} s slots)",
            spec, rate, args, expanded, writer)
    if args.instances:
        from uam_solvers.instances import corpus_summary, save_corpus
        path = Path(args.instances)
        path.parent.mkdir(parents=True, exist_ok=True)
        save_corpus(path, writer.entries)
        print(f"instances: {path} {corpus_summary(writer.entries)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
