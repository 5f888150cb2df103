#!/usr/bin/env python3
"""F3548 mode against the plain separation: what keeping the published volumes disjoint costs.

    python scripts/bench_intent_volumes.py
    python scripts/bench_intent_volumes.py --rates 6,10 --duration 600 --seeds 0,1

The Singapore layered network (cylinder H 100 m / V 30 m, 5 s departure slots, greedy MWIS), the
paper's demand at each ``--rates`` (requests per 30 s), storms announced ahead of flights at
epochs 3-7 so that plans get new versions (as the test of our own intents does), planned in
process by the runner twice: the separation only, and F3548 mode
(``PlanningConfig.intent_volume_piece_s`` = 5 s, the USS's pieces). Prints per run the approved
and decided requests, the plan versions, the process CPU of the run and the planner's
``planning_time_s`` p50 / p99 per epoch, and the pairs of our own published intents that
intersect as a peer checks them (``uam_planner.f3548.published_intersections``, 1 cm), with the
load average before and after.
"""

from __future__ import annotations

import argparse
import os
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("uam_contract", "uam_planner", "uam_solvers", "uam_sim"):
    sys.path.insert(0, str(ROOT / "src" / pkg))

from uam_planner.constraints import Constraint  # noqa: E402
from uam_planner.f3548 import IntentContext, VolumeSpec, published_intersections  # noqa: E402
from uam_planner.network import load_network  # noqa: E402
from uam_planner.separation import SeparationModel  # noqa: E402
from uam_sim.runner.experiment_config import make_config  # noqa: E402
from uam_sim.runner.scenario import run_scenario  # noqa: E402

LAYERED = str(ROOT / "config" / "networks" / "singapore-layered.yaml")


def run(rate: float, seed: int, duration_s: float, piece_s: float) -> dict:
    net = load_network(LAYERED)
    cfg = make_config(network=LAYERED, separation_model="cylinder", separation_m=100.0,
                      vertical_separation_m=30.0, departure_slot_s=5.0, audit=False, time_limit_s=5.0,
                      intent_volume_piece_s=piece_s)
    decided, plan_s = [], []

    def before(planner, t, k):
        if 3 <= k <= 7:  # a storm 60 s ahead of a flight still in the air in 2 min
            going = sorted((fl for fl, _ in decided if fl.arrival_s > t + 120.0), key=lambda fl: fl.request_id)
            if going:
                p = going[0].trajectory.position_at(t + 60.0, clamp=True)
                planner.update_constraint("add", Constraint(f"storm{k}", 1, "storm", t + 30.0, 900.0,
                                                            center_m=(float(p[0]), float(p[1])),
                                                            radius_m=700.0, lower_m=0.0, upper_m=500.0), t)

    def keep(t, k, submitted, rejected, result):
        decided.extend((f, t) for f in result.approved)
        decided.extend((u.flight, t) for u in result.plan_updates if u.flight is not None)
        plan_s.append(result.report.planning_time_s)

    cpu = time.process_time()
    res = run_scenario(net, "greedy", rate, seed, duration_s, cfg, observer=keep, before_epoch=before)
    cpu = time.process_time() - cpu
    spec = VolumeSpec.for_separation(SeparationModel("cylinder", 100.0, 30.0))
    pairs, hits = published_intersections(decided, IntentContext.for_network(net, spec), net.origin_lat_lon_alt)
    s = res.summary
    return {"approved": s.get("approved"), "decided": s.get("approved", 0) + s.get("rejected", 0),
            "versions": len(decided), "cpu_s": cpu, "plan_p50_ms": 1e3 * float(np.percentile(plan_s, 50)),
            "plan_p99_ms": 1e3 * float(np.percentile(plan_s, 99)), "pairs": pairs, "intersecting": len(hits)}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--rates", default="6,10", help="requests per 30 s, comma-separated (default 6,10)")
    ap.add_argument("--seeds", default="4", help="seeds, comma-separated (default 4)")
    ap.add_argument("--duration", type=float, default=300.0, help="simulated seconds per run (default 300)")
    args = ap.parse_args(argv)
    print(f"load average before: {os.getloadavg()[0]:.2f}")
    print("rate seed mode        approved/decided versions  cpu_s  plan p50/p99 ms  intersecting/pairs")
    for rate in (float(r) for r in args.rates.split(",")):
        for seed in (int(x) for x in args.seeds.split(",")):
            for piece, name in ((0.0, "separation"), (5.0, "F3548")):
                r = run(rate, seed, args.duration, piece)
                print(f"{rate:4g} {seed:4d} {name:11s} {r['approved']:5d}/{r['decided']:<5d}   {r['versions']:5d}  "
                      f"{r['cpu_s']:6.1f}  {r['plan_p50_ms']:6.1f}/{r['plan_p99_ms']:<7.1f}  "
                      f"{r['intersecting']}/{r['pairs']}", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
