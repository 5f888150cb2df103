#!/usr/bin/env python3
"""CPU per planning epoch on the synthetic layered city, at steady state.

    python scripts/bench_epoch_cpu.py --per-hour 3000
    python scripts/bench_epoch_cpu.py --per-hour 10000
    python scripts/bench_epoch_cpu.py --per-hour 30000 --duration 1500 --steady-from 900
    python scripts/bench_epoch_cpu.py --city city-30k --per-hour 30000 --method auto --lazy-routes

The city is ``--city`` of ``uam_planner.synthetic.CITIES`` (default ``layered-city``:
``generate_network(2000, 100, seed, levels 60/90/120/150 m, 4 pads)``), cylinder
H 100 m / V 30 m, 5 s departure slots, the paper's demand generator (window 60 s) at
``--per-hour`` requests per hour, planned in process by ``Planner`` (policy MWIS, backend
greedy in process: the solve's CPU is left out, it is the solvers' figure, not the epoch's).
Routes are precomputed when the planner is made (``PlanningConfig.precompute_routes``; its
one-off CPU is printed as the set-up), or with ``--lazy-routes`` searched when a pair is first
requested.

CPU of one epoch = the process CPU time of that epoch's ``submit`` calls plus its ``plan``
call, minus the solve's: everything the planner spends on the epoch, wherever it happens (a
route search inside ``submit`` counts). Epochs before ``--steady-from`` [s] (the fleet filling
up) are left out of the percentiles. Prints p50 / p99 / max of the CPU and of the report's
``planning_time_s`` (wall), the airborne count, candidates and discarded per epoch, the
approvals (which must not depend on the code's speed), the full garbage collections inside the
steady epochs, the process's peak resident memory and the load average before and after.
CPU time is far less sensitive than wall time to other processes on the same cores.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import resource
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("uam_contract", "uam_planner", "uam_solvers", "uam_sim"):
    sys.path.insert(0, str(ROOT / "src" / pkg))

from uam_planner import separation  # noqa: E402
from uam_planner.planning import AirspaceConfig, Planner, PlanningConfig  # noqa: E402
from uam_planner.synthetic import CITIES, generate_city, generate_network  # noqa: E402
from uam_sim.world.demand import RequestGenerator  # noqa: E402


def run(per_hour: float, duration_s: float, steady_from_s: float, seed: int = 0,
        slot_s: float = 5.0, precompute: bool = True, city: str | dict = "layered-city",
        method: str = "greedy", time_limit_s: float = 1.0) -> dict:
    """Plan ``duration_s`` of the city at ``per_hour``; per-epoch CPU and counts. ``city``: a
    name of ``uam_planner.synthetic.CITIES`` or generate_network's arguments. ``method``:
    ``greedy`` (the greedy MWIS in process: its CPU is left out), ``auto`` (the bounded solver,
    ``time_limit_s``; its CPU is left out too, and part of it runs in a worker process) or
    ``firstfit`` (the first-fit baseline, no solve)."""
    from uam_solvers.greedy import greedy_mwis
    net = generate_city(city, seed) if isinstance(city, str) else generate_network(seed=seed, **city)
    cfg = PlanningConfig(airspace=AirspaceConfig("cylinder", 30.0, slot_s),
                         backend="auto" if method == "auto" else "greedy", seed=seed,
                         precompute_routes=precompute, time_limit_s=time_limit_s)
    solve_cpu = [0.0]

    class _Answer:
        backend = "greedy"

        def __init__(self, selected):
            self.selected = selected

    def solve(weights, edges, groups):
        c = time.process_time()
        try:
            if method == "auto":
                import uam_solvers
                return uam_solvers.solve_bounded(weights, edges, groups=groups, backend="auto",
                                                 time_limit_s=time_limit_s, seed=seed)
            return _Answer(greedy_mwis(weights, edges))
        finally:
            solve_cpu[0] += time.process_time() - c

    gc_cpu = _collector_clock()
    c_setup = time.process_time()
    if method == "auto":
        import uam_solvers
        uam_solvers.warm_up(["auto"], service=True)
    planner = Planner(net, cfg, "firstfit" if method == "firstfit" else "mwis", solve_mwis=solve)
    separation.warm_up()  # the compiled check that decides: part of the set-up, not of an epoch
    setup_cpu = time.process_time() - c_setup
    demand = RequestGenerator(net.aerodrome_ids, per_hour * 30.0 / 3600.0, 30.0, 60.0, seed)
    rows = []
    approved = 0
    for e in range(int(math.ceil(duration_s / cfg.epoch_s - 1e-9))):
        t = e * cfg.epoch_s
        solve_cpu[0] = 0.0
        gc_cpu[0] = 0.0
        c = time.process_time()
        for r in demand.requests_at(t, e):
            reason = planner.submit(r)
            if reason is not None:
                raise SystemExit(f"request {r.request_id} refused: {reason}")
        c_submit = time.process_time() - c
        res = planner.plan(t, e)
        cpu = time.process_time() - c - solve_cpu[0]
        rep = res.report
        approved += len(res.approved)
        rows.append((t, cpu, c_submit, rep.planning_time_s, rep.active_flights - rep.approved,
                     rep.candidates, rep.discarded, rep.approved, rep.expired, gc_cpu[0]))
    a = np.array(rows)
    steady = a[a[:, 0] >= steady_from_s]
    return {"all": a, "steady": steady, "approved": approved, "setup_cpu_s": setup_cpu}


def _collector_clock() -> list:
    """[CPU s] of the cyclic garbage collector's full (generation 2) collections since the
    caller last set it to 0: a full collection walks every tracked object of the process (the
    route cache's templates among them), so at city scale one costs a large share of an epoch."""
    import gc

    acc = [0.0, 0.0]   # total, start of the running collection

    def clock(phase, info):
        if info.get("generation") != 2:
            return
        if phase == "start":
            acc[1] = time.process_time()
        else:
            acc[0] += time.process_time() - acc[1]
    gc.callbacks.append(clock)
    return acc


def _pct(x, q):
    return float(np.percentile(x, q)) if len(x) else float("nan")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--per-hour", type=float, default=3000.0)
    ap.add_argument("--duration", type=float, default=None,
                    help="simulated seconds (default 1,800 s; 1,500 s at >= 20,000/h)")
    ap.add_argument("--steady-from", type=float, default=None,
                    help="first epoch time [s] counted (default: duration - 600 s)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--city", default="layered-city", choices=sorted(CITIES),
                    help="the synthetic city (uam_planner.synthetic.CITIES)")
    ap.add_argument("--city-json", default=None,
                    help="generate_network's arguments but the seed, as JSON (a city not in "
                         "CITIES, e.g. while sizing one); replaces --city")
    ap.add_argument("--method", default="greedy", choices=["greedy", "auto", "firstfit"],
                    help="greedy or auto MWIS (the solve's CPU left out), or the first-fit baseline")
    ap.add_argument("--lazy-routes", action="store_true",
                    help="search each origin-destination pair's routes when first requested "
                         "(in submit) instead of when the planner is made")
    args = ap.parse_args(argv)
    duration = args.duration if args.duration is not None else \
        (1500.0 if args.per_hour >= 20000 else 1800.0)
    steady_from = args.steady_from if args.steady_from is not None else duration - 600.0
    load0 = os.getloadavg()
    t_wall = time.perf_counter()
    r = run(args.per_hour, duration, steady_from, args.seed,
            precompute=not args.lazy_routes,
            city=json.loads(args.city_json) if args.city_json else args.city, method=args.method)
    wall = time.perf_counter() - t_wall
    load1 = os.getloadavg()
    s = r["steady"]
    ms = 1e3
    routes = "lazy routes" if args.lazy_routes else "routes precomputed"
    city = args.city_json or f"{args.city} ({CITIES[args.city]})"
    print(f"city {city}, method {args.method}, cylinder 100/30 m, 5 s slots, "
          f"{routes}, {args.per_hour:g} requests/h, {duration:g} s, seed {args.seed}; steady state "
          f"t >= {steady_from:g} s ({len(s)} epochs)")
    decided = s[:, 7].sum() + s[:, 8].sum()
    share = s[:, 7].sum() / decided if decided else float("nan")
    print("| CPU per epoch p50 / p99 / max | of it in submit, p50 / max | planning_time_s p50 / "
          "p99 (wall) | airborne mean | candidates mean | discarded mean | approved of decided, "
          "steady | approved (run) |")
    print(f"| {ms * _pct(s[:, 1], 50):.1f} / {ms * _pct(s[:, 1], 99):.1f} / "
          f"{ms * s[:, 1].max():.1f} ms | {ms * _pct(s[:, 2], 50):.1f} / {ms * s[:, 2].max():.1f} "
          f"ms | {ms * _pct(s[:, 3], 50):.1f} / {ms * _pct(s[:, 3], 99):.1f} ms | "
          f"{s[:, 4].mean():.0f} | {s[:, 5].mean():.0f} | {s[:, 6].mean():.0f} | "
          f"{100 * share:.1f} % | {r['approved']} |")
    print(f"steady epochs with a full garbage collection: {int((s[:, 9] > 0).sum())}; its CPU "
          f"{ms * s[:, 9].sum():.0f} ms in all, at most {ms * s[:, 9].max():.0f} ms in an epoch "
          f"(inside the CPU per epoch above)")
    # ru_maxrss: the process's resident peak [KiB on Linux], network, routes and fleet included
    peak_mib = resource.getrusage(resource.RUSAGE_SELF).ru_maxrss / 1024.0
    print(f"planner set-up CPU {r['setup_cpu_s']:.2f} s; run {wall:.0f} s wall; peak memory "
          f"(resident) {peak_mib:,.0f} MiB; load average {load0[0]:.2f} before, {load1[0]:.2f} after")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
