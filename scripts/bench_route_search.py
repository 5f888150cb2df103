#!/usr/bin/env python3
"""CPU of a route search (one origin-destination pair's candidate templates) on a synthetic city,
and what the route cache costs the cyclic garbage collector.

    python scripts/bench_route_search.py                      # city-30k, 1,000 pairs
    python scripts/bench_route_search.py --city layered-city --pairs 2000

``--pairs`` distinct ordered pairs of vertiports, drawn with ``--seed``, are searched into one
``CandidateCache`` (k = 5 penalised searches each, then one template per route and allowed level:
up to 12 levels x 5 routes on city-30k); prints the CPU per pair (median of ``--repeat`` fresh
caches), the objects the collector tracks once they are cached, and the CPU of one full
collection then (it walks every one of them; at steady state on city-30k at 30,000 requests/h
the cache holds ~10,000 pairs). Prints the load average before and after.
"""

from __future__ import annotations

import argparse
import gc
import os
import statistics
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for pkg in ("uam_contract", "uam_planner"):
    sys.path.insert(0, str(ROOT / "src" / pkg))

from uam_planner.candidates import CandidateCache  # noqa: E402
from uam_planner.synthetic import CITIES, generate_city  # noqa: E402


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--city", default="city-30k", choices=sorted(CITIES))
    ap.add_argument("--pairs", type=int, default=1000)
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=1)
    args = ap.parse_args(argv)
    if args.pairs < 1 or args.repeat < 1:
        raise SystemExit(f"--pairs and --repeat must be >= 1, got {args.pairs}, {args.repeat}")
    load0 = os.getloadavg()[0]
    net = generate_city(args.city, 0)
    ai = np.asarray(net.aerodrome_indices)
    n_max = len(ai) * (len(ai) - 1)
    if args.pairs > n_max:
        raise SystemExit(f"--pairs {args.pairs}: the city has {n_max} ordered pairs")
    rng = np.random.default_rng(args.seed)
    pairs: set = set()
    while len(pairs) < args.pairs:
        o, d = rng.choice(ai, 2, replace=False)
        pairs.add((int(o), int(d)))
    ordered = sorted(pairs)
    per_pair = []
    cache = None
    for _ in range(args.repeat):
        cache = None   # a fresh cache each time, the last one kept for what follows
        gc.collect()
        cache = CandidateCache(net)
        c = time.process_time()
        cache.precompute(ordered)
        per_pair.append((time.process_time() - c) / len(ordered))
    gc.collect()
    c = time.process_time()
    gc.collect()
    full_s = time.process_time() - c
    n_tpl = sum(len(cache.templates(o, d)) for o, d in ordered)
    base = len(gc.get_objects())
    cache = None
    gc.collect()
    tracked = base - len(gc.get_objects())
    print(f"city {args.city}: {args.pairs} pairs, {n_tpl / args.pairs:.1f} templates per pair")
    print(f"| CPU per pair, median of {args.repeat} | tracked objects per pair | a full "
          f"collection with them cached (whole process) |")
    print(f"| {1e3 * statistics.median(per_pair):.2f} ms | {tracked / args.pairs:.1f} | "
          f"{1e3 * full_s:.0f} ms |")
    print(f"load average {load0:.2f} before, {os.getloadavg()[0]:.2f} after")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
