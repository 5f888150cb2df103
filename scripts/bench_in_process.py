#!/usr/bin/env python3
"""CPU of the paper scenario planned in process, the denominator of the node graph's cost.

    python scripts/bench_in_process.py        # beside: bash scripts/bench_graph.sh --rerun off

The same scenario as scripts/bench_graph.sh (Singapore, rate 10 requests per 30 s, seed 0,
3,500 s, exact MWIS), run by the in-process runner (``uam_sim.runner.scenario.run_scenario``):
prints this process's CPU for the run and for its imports, and the approvals, which must equal
the graph's. The solve service's worker processes are not counted (their CPU is the solver
node's in the graph).
"""

from __future__ import annotations

import os
import sys
import time
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("uam_contract", "uam_planner", "uam_solvers", "uam_sim"):
    sys.path.insert(0, str(ROOT / "src" / pkg))


def main() -> int:
    c0 = time.process_time()
    from uam_planner.network import load_network
    from uam_sim.runner.experiment_config import ExperimentConfig
    from uam_sim.runner.scenario import run_scenario
    imports = time.process_time() - c0
    net = load_network(ROOT / "config" / "networks" / "singapore.yaml")
    c = time.process_time()
    r = run_scenario(net, "exact", 10, 0, 3500.0, ExperimentConfig(time_limit_s=10.0))
    run = time.process_time() - c
    print(f"in process: run {run:.2f} CPU-s, imports {imports:.2f} CPU-s, total {run + imports:.2f}; "
          f"approved {r.summary.get('approved')}; load average {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
