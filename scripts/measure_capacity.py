#!/usr/bin/env python3
"""Capacity of the airspace modes, library level (the planning cycle in process, no ROS).

    .venv/bin/python scripts/measure_capacity.py singapore      # paper mode vs layered + slots
    .venv/bin/python scripts/measure_capacity.py city           # synthetic city, 4 levels

``singapore``: the paper's demand (uam_sim.world.demand.RequestGenerator: ``--rate`` requests per 30 s
between random distinct aerodromes, window 60 s, seeded) over ``--duration`` s, planned once in
paper mode (config/networks/singapore.yaml, sphere 100 m, departure at the epoch) and once in
the expanded airspace (singapore-layered.yaml, cylinder H 100 m / V 30 m, ``--slot-s`` slots),
on the same requests (the two files have the same aerodrome ids). ``city``: a generated network
(``--nodes``, ``--vertiports``, 4 levels, 4 pads) offered ``--per-hour`` requests per hour.

Prints per mode: requests, approved (share), expired, peak and mean airborne, MWIS vertices
(median, max), planning cycle without the solve (median, max, ms) and the audit of every pair of
approved flights in the run's separation model (uam_planner.audit.sweep_audit: every time-overlapping segment pair, no spatial pruning). ``--instances
FILE`` writes each epoch's MWIS instance (weights, edges, groups) as JSON lines for the solver
study. Wall times depend on the machine's load; the approvals do not.
"""

from __future__ import annotations

import argparse
import json
import math
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("uam_planner", "uam_solvers", "uam_sim"):
    sys.path.insert(0, str(ROOT / "src" / pkg))

from uam_planner.audit import sweep_audit  # noqa: E402
from uam_planner.network import load_network  # noqa: E402
from uam_planner.planning import AirspaceConfig, Planner, PlanningConfig  # noqa: E402
from uam_sim.world.demand import RequestGenerator  # noqa: E402


def run(net, cfg: PlanningConfig, demand, duration_s: float, instances_path=None,
        audit: bool = True) -> dict:
    import uam_solvers
    solve_cpu = [0.0]

    def solve(weights, edges, groups):
        c = time.process_time()
        try:
            return uam_solvers.solve(weights, edges, groups=groups, backend=cfg.backend,
                                     time_limit_s=cfg.time_limit_s, seed=cfg.seed)
        finally:
            solve_cpu[0] += time.process_time() - c

    planner = Planner(net, cfg, "mwis", solve_mwis=solve)
    flights, cycles, vertices, cpus = [], [], [], []
    n_req = expired = 0
    out = open(instances_path, "w") if instances_path else None
    t_wall = time.perf_counter()
    for e in range(int(math.ceil(duration_s / cfg.epoch_s - 1e-9))):
        t = e * cfg.epoch_s
        for r in demand.requests_at(t, e):
            n_req += 1
            reason = planner.submit(r)
            if reason is not None:
                raise SystemExit(f"request {r.request_id} refused: {reason}")
        solve_cpu[0] = 0.0
        c = time.process_time()
        res = planner.plan(t, e)
        # CPU time of the cycle without the solve: far less sensitive than wall time to other
        # processes on the same cores
        cpus.append(time.process_time() - c - solve_cpu[0])
        rep = res.report
        flights += res.approved
        expired += len(res.expired)
        cycles.append(rep.planning_time_s)
        vertices.append(rep.vertices)
        if out is not None and rep.vertices:
            groups = {}
            for v, rid in enumerate(rep.vertex_request_ids):
                groups.setdefault(rid, []).append(v)
            out.write(json.dumps({"epoch": e, "t_s": t, "weights": rep.weights.tolist(),
                                  "edges": rep.edges_array.tolist(),
                                  "groups": [g for g in groups.values() if len(g) > 1]}) + "\n")
    wall = time.perf_counter() - t_wall
    if out is not None:
        out.close()
    dep = np.array([f.departure_s for f in flights])
    arr = np.array([f.arrival_s for f in flights])
    grid = np.arange(0.0, duration_s, 5.0)
    airborne = ((dep[None, :] <= grid[:, None]) & (arr[None, :] >= grid[:, None])).sum(axis=1) \
        if flights else np.zeros(1)
    t_audit = time.perf_counter()
    audit = sweep_audit(flights, cfg.separation) if audit else None
    return {"requests": n_req, "approved": len(flights), "expired": expired,
            "peak_airborne": int(airborne.max()), "mean_airborne": float(airborne.mean()),
            "vertices_median": statistics.median(vertices), "vertices_max": max(vertices),
            "cycle_median_ms": 1e3 * statistics.median(cycles), "cycle_max_ms": 1e3 * max(cycles),
            "cycle_cpu_median_ms": 1e3 * statistics.median(cpus),
            "cycle_cpu_max_ms": 1e3 * max(cpus),
            "losses": None if audit is None else len(audit.losses),
            "min_separation_m": math.nan if audit is None else audit.min_separation_m,
            "audit_pairs": 0 if audit is None else audit.pairs_checked,
            "audit_s": time.perf_counter() - t_audit, "wall_s": wall}


def show(label: str, r: dict) -> None:
    print(f"{label}: {r['requests']} requests, {r['approved']} approved "
          f"({100 * r['approved'] / max(r['requests'], 1):.1f} %), {r['expired']} expired; "
          f"airborne peak {r['peak_airborne']}, mean {r['mean_airborne']:.0f}; MWIS vertices "
          f"median {r['vertices_median']:.0f}, max {r['vertices_max']}; cycle without solve "
          f"median {r['cycle_median_ms']:.0f} ms, max {r['cycle_max_ms']:.0f} ms (CPU median "
          f"{r['cycle_cpu_median_ms']:.0f} ms, max {r['cycle_cpu_max_ms']:.0f} ms); audit: "
          f"{r['losses']} losses in {r['audit_pairs']} pairs (min {r['min_separation_m']:.1f} m, "
          f"{r['audit_s']:.0f} s); run {r['wall_s']:.0f} s; load average "
          f"{__import__('os').getloadavg()[0]:.1f}", flush=True)


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("case", choices=["singapore", "city"])
    ap.add_argument("--rate", type=float, default=20.0, help="requests per 30 s (singapore)")
    ap.add_argument("--duration", type=float, default=3500.0)
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--slot-s", type=float, default=5.0)
    ap.add_argument("--backend", default="greedy")
    ap.add_argument("--time-limit", type=float, default=10.0)
    ap.add_argument("--nodes", type=int, default=2000)
    ap.add_argument("--vertiports", type=int, default=100)
    ap.add_argument("--per-hour", type=float, default=3000.0)
    ap.add_argument("--instances", default=None, help="JSON lines of the expanded mode's MWIS instances")
    ap.add_argument("--skip-paper", action="store_true")
    ap.add_argument("--no-audit", action="store_true", help="skip the audit (timing re-runs)")
    args = ap.parse_args(argv)
    cylinder = AirspaceConfig("cylinder", 30.0, args.slot_s)
    common = dict(backend=args.backend, time_limit_s=args.time_limit, seed=args.seed)
    if args.case == "singapore":
        paper = load_network(ROOT / "config" / "networks" / "singapore.yaml")
        layered = load_network(ROOT / "config" / "networks" / "singapore-layered.yaml")
        assert paper.aerodrome_ids == layered.aerodrome_ids
        demand = lambda: RequestGenerator(paper.aerodrome_ids, args.rate, 30.0, 60.0, args.seed)  # noqa: E731
        print(f"Singapore, rate {args.rate:g} per 30 s, {args.duration:g} s, seed {args.seed}, "
              f"backend {args.backend}", flush=True)
        if not args.skip_paper:
            show("paper mode (singapore.yaml, sphere 100 m, slot 0)",
                 run(paper, PlanningConfig(**common), demand(), args.duration,
                     audit=not args.no_audit))
        show(f"layered (singapore-layered.yaml, cylinder 100/30 m, slots {args.slot_s:g} s)",
             run(layered, PlanningConfig(airspace=cylinder, **common), demand(), args.duration,
                 args.instances, not args.no_audit))
    else:
        from uam_planner.synthetic import generate_network
        net = generate_network(args.nodes, args.vertiports, seed=args.seed,
                               levels_m=[60.0, 90.0, 120.0, 150.0], pads_per_vertiport=4)
        rate = args.per_hour * 30.0 / 3600.0
        print(f"{net}, {args.per_hour:g} requests per hour ({rate:g} per 30 s), "
              f"{args.duration:g} s, backend {args.backend}", flush=True)
        show(f"city (cylinder 100/30 m, slots {args.slot_s:g} s)",
             run(net, PlanningConfig(airspace=cylinder, **common),
                 RequestGenerator(net.aerodrome_ids, rate, 30.0, 60.0, args.seed), args.duration,
                 args.instances, not args.no_audit))
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
