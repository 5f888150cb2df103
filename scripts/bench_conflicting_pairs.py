"""conflicting_pairs with and without its broad-phase shortcuts, on the calls of a study cell.

    python scripts/bench_conflicting_pairs.py [--duration 1200] [--reps 3] [--mode both|slots]

Runs one decision-study cell (config/decision-study.yaml's E1 sg-both arm, first-fit, rate 20,
seed 0, shortened to --duration s; --mode slots flies the flat network with the sphere) and
records every conflicting_pairs call of its planner, then times the calls again in this process,
with the shortcuts (the default) and without (``separation._CYLINDER_Z_KEYS`` and
``_SKIP_OWN_RUNS`` off: the plain path they replaced), checking that both give the same pairs
and the same distances bit for bit. Prints CPU seconds (process time) of each. Issue 24 item 2.
"""

from __future__ import annotations

import argparse
import sys
import time
from dataclasses import asdict
from pathlib import Path
from tempfile import TemporaryDirectory

import numpy as np


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--duration", type=float, default=1200.0)
    ap.add_argument("--reps", type=int, default=3)
    ap.add_argument("--mode", choices=("both", "slots"), default="both")
    args = ap.parse_args(argv)

    import uam_planner.separation as sep
    from uam_planner import conflict_graph, nonconformance, planning, replanning
    from uam_sim.studies.decision_study import capacity_config, load_decision_config
    from uam_sim.runner.experiment_config import AIRSPACE_PRESETS
    from uam_sim.runner.sweep import run_cell

    calls = []
    orig = sep.conflicting_pairs

    def record(trajs_a, trajs_b=None, *a, **kw):
        sa = sep._as_segment_set(trajs_a)
        sb = None if trajs_b is None else sep._as_segment_set(trajs_b)
        calls.append((sa, sb, a, kw))
        return orig(sa, sb, *a, **kw)

    mods = [m for m in (conflict_graph, planning, nonconformance, replanning)
            if hasattr(m, "conflicting_pairs")]
    for m in mods:
        m.conflicting_pairs = record
    cfg = load_decision_config("config/decision-study.yaml")
    cfg["base"]["duration_s"] = args.duration
    with TemporaryDirectory() as tmp:
        cc, _ = capacity_config(cfg, [0], Path(tmp), ["E1"])
        ecfg = next(c for arm, _m, c in cc.combos() if "sg-both" in arm.name)
        d = asdict(ecfg)
        if args.mode == "slots":
            d.update({k: v for k, v in AIRSPACE_PRESETS["slots"].items() if k in d})
            d.update(airspace_mode="slots", network="config/networks/singapore.yaml")
        run_cell(d, "firstfit", 20, 0, tmp)
    for m in mods:
        m.conflicting_pairs = orig
    print(f"{len(calls)} conflicting_pairs calls recorded ({args.mode}, {args.duration:.0f} s)")

    cpu = {}
    results = {}
    for on in (True, False):
        sep._CYLINDER_Z_KEYS = on
        sep._SKIP_OWN_RUNS = on
        t0 = time.process_time()
        for _ in range(args.reps):
            results[on] = [orig(sa, sb, *a, **{**kw, "return_distances": True})
                           for sa, sb, a, kw in calls]
        cpu[on] = time.process_time() - t0
    sep._CYLINDER_Z_KEYS = sep._SKIP_OWN_RUNS = True
    for (p1, d1), (p0, d0) in zip(results[True], results[False]):
        if not (np.array_equal(p1, p0) and d1.tobytes() == d0.tobytes()):
            print("DIFFERENT results with and without the shortcuts", file=sys.stderr)
            return 1
    print(f"same pairs and distances bit for bit in all {len(calls)} calls")
    print(f"CPU x{args.reps}: with shortcuts {cpu[True]:.2f} s, without {cpu[False]:.2f} s "
          f"(ratio {cpu[True] / cpu[False]:.3f})")
    return 0


if __name__ == "__main__":
    sys.exit(main())
