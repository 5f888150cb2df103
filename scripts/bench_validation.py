#!/usr/bin/env python3
"""What validation costs (issue 19, one validation style): loading the network files, the demand
files (the example and a 10,000-request list, the per-request hot path), the experiment and
capacity-study configs, and the per-call checks of node parameters and backend options.

    source scripts/env.sh && nice -n 5 python scripts/bench_validation.py

Imports whatever ``uam_*`` packages are on the path, so the same script measures another checkout
(``PYTHONPATH=<checkout>/src/uam_contract:<checkout>/src/uam_solvers:... python
scripts/bench_validation.py --repo <checkout>``). Prints the median and the best wall time of the
repeats and the median CPU time in ms, with the total CPU time and the load average: a shared machine, numbers to compare paired.
"""

from __future__ import annotations

import argparse
import copy
import os
import statistics
import time
from pathlib import Path


def _time(fn, repeats: int) -> tuple[float, float, float]:
    fn()  # warm (imports, caches)
    walls, cpus = [], []
    for _ in range(repeats):
        c0, t0 = time.process_time(), time.perf_counter()
        fn()
        walls.append(time.perf_counter() - t0)
        cpus.append(time.process_time() - c0)
    return statistics.median(walls) * 1e3, min(walls) * 1e3, statistics.median(cpus) * 1e3


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("--repo", default=str(Path(__file__).resolve().parents[1]),
                    help="checkout whose config/ files are read (default: this one)")
    ap.add_argument("--repeats", type=int, default=20)
    args = ap.parse_args(argv)
    repo = Path(args.repo)
    os.chdir(repo)

    from uam_contract.params import PLANNER
    from uam_planner.network import load_network, network_from_dict, network_to_dict
    from uam_planner.synthetic import generate_network
    from uam_sim.studies.capacity_study import load_capacity_config
    from uam_sim.world.demand import load_demand, parse_demand
    from uam_sim.runner.experiment_config import load_config
    from uam_solvers.options import parse_options
    from uam_solvers.registry import get_backend

    sg = load_network("config/networks/singapore.yaml")
    city = network_to_dict(generate_network(n_nodes=400, n_aerodromes=40, seed=0))
    aero = list(sg.aerodrome_ids)
    big = [{"t_s": float(i % 3600), "origin": aero[i % len(aero)],
            "destination": aero[(i + 1) % len(aero)], "id": f"q{i}", "priority": i % 3,
            "operator": f"op{i % 7}"} for i in range(10_000)]
    k = next(p for p in PLANNER if p.name == "k")
    sa = get_backend("sa").options_spec

    cases = [
        ("load_network singapore.yaml (241 nodes)", lambda: load_network("config/networks/singapore.yaml")),
        ("load_network singapore-layered.yaml", lambda: load_network("config/networks/singapore-layered.yaml")),
        ("load_network singapore.graphml", lambda: load_network("config/networks/singapore.graphml")),
        ("network_from_dict synthetic city (400 nodes)", lambda: network_from_dict(copy.deepcopy(city))),
        ("load_demand config/demand_example.yaml", lambda: load_demand("config/demand_example.yaml", aero)),
        ("parse_demand 10,000 requests", lambda: parse_demand(big, aero)),
        ("load_config config/experiment.yaml (ExperimentConfig)", lambda: load_config("config/experiment.yaml")),
        ("load_capacity_config config/capacity-study.yaml", lambda: load_capacity_config("config/capacity-study.yaml")),
        ("1,000 x Param.validate (node parameter k)", lambda: [k.validate(5) for _ in range(1000)]),
        ("1,000 x parse_options sa {num_reads, seed}", lambda: [parse_options("sa", sa, {"num_reads": 10})
                                                                   for _ in range(1000)]),
    ]
    c0 = time.process_time()
    w0 = time.perf_counter()
    print("| case | median ms | best ms | median CPU ms |\n|---|---|---|---|")
    for name, fn in cases:
        med, best, cpu = _time(fn, args.repeats)
        print(f"| {name} | {med:.2f} | {best:.2f} | {cpu:.2f} |")
    print(f"\nwall {time.perf_counter() - w0:.1f} s, CPU {time.process_time() - c0:.1f} s, "
          f"load average {' '.join(f'{x:.2f}' for x in os.getloadavg())}, repeats {args.repeats}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
