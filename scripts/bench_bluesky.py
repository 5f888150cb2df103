#!/usr/bin/env python3
"""This project's conflict detection against BlueSky's C state-based detection, the same aircraft.

An optional benchmark in its own environment (BlueSky pulls in its own numpy, pandas and
matplotlib; it is not part of the project's environment or of ``make test``):

    python3.11 -m venv .venv-bluesky
    .venv-bluesky/bin/pip install -r requirements-bluesky.txt
    .venv-bluesky/bin/python scripts/bench_bluesky.py --sizes 1000,4000,16000

N aircraft fly straight for the look-ahead (300 s): uniform in a square whose side grows with
sqrt(N) (20 km at 1,000, so the density stays that of a busy city), 80 % cruising on four
levels 30 m apart (60-150 m), 20 % climbing or descending at 1-3 m/s, ground speed 15-25 m/s,
any heading. Separation: the cylinder H 100 m, V 30 m (BlueSky's rpz and hpz).

- BlueSky 1.1.1: ``bluesky.traffic.asas.cstatebased.detect`` (its C++ pairwise loop, O(N^2)), on
  latitude and longitude near Singapore (1.35 N), from the same local positions (equirectangular).
- This project: ``uam_planner.separation.conflicting_pairs`` on one 300 s segment per aircraft
  (its broad phase and exact kernel), the same cylinder.

Prints, per N, both wall times (best of ``--repeat``; load average beside them) and how far the
pair sets agree. BlueSky works on the sphere with a flat-earth distance and ours in a local plane:
the sets may differ by pairs whose closest approach lies within a fraction of a metre of 100 m (0.2 m
at 16,000 aircraft over 80 km; the check prints
how many pairs differ and the largest gap of a differing pair's distance from 100 m).
"""

from __future__ import annotations

import argparse
import math
import os
import sys
import time
from pathlib import Path
from types import SimpleNamespace

import numpy as np

ROOT = Path(__file__).resolve().parents[1]
for _pkg in ("uam_contract", "uam_planner"):
    sys.path.insert(0, str(ROOT / "src" / _pkg))

from uam_planner.separation import (SegmentSet, SeparationModel,  # noqa: E402
                                    conflicting_pairs)

LOOKAHEAD_S = 300.0
H_M, V_M = 100.0, 30.0
LAT0_DEG, LON0_DEG = 1.35, 103.82
EARTH_R_M = 6371000.0


def traffic(n: int, seed: int) -> dict:
    """n aircraft: local positions [m], velocities [m/s], the density of 1,000 in 20 km."""
    rng = np.random.default_rng(seed)
    side = 20000.0 * math.sqrt(n / 1000.0)
    xy = rng.uniform(0.0, side, (n, 2))
    z = rng.choice([60.0, 90.0, 120.0, 150.0], n)
    vs = np.zeros(n)
    moving = rng.random(n) < 0.2
    vs[moving] = rng.uniform(1.0, 3.0, int(moving.sum())) * rng.choice([-1.0, 1.0], int(moving.sum()))
    gs = rng.uniform(15.0, 25.0, n)
    trk = rng.uniform(0.0, 360.0, n)
    vx, vy = gs * np.sin(np.radians(trk)), gs * np.cos(np.radians(trk))
    return {"p": np.column_stack((xy, z)), "v": np.column_stack((vx, vy, vs)), "gs": gs,
            "trk": trk}


def ours(t: dict):
    n = t["p"].shape[0]
    s = SegmentSet(np.arange(n, dtype=np.int64), np.zeros(n), np.full(n, LOOKAHEAD_S), t["p"],
                   t["v"], n)
    pairs, dist = conflicting_pairs(s, None, SeparationModel("cylinder", H_M, V_M),
                                    return_distances=True)
    return {(int(a), int(b)) for a, b in pairs}, dict(zip(map(tuple, pairs.tolist()), dist))


def bluesky_pairs(t: dict):
    from bluesky.traffic.asas import cstatebased
    n = t["p"].shape[0]
    lat = LAT0_DEG + np.degrees(t["p"][:, 1] / EARTH_R_M)
    lon = LON0_DEG + np.degrees(t["p"][:, 0] / (EARTH_R_M * math.cos(math.radians(LAT0_DEG))))
    ac = SimpleNamespace(lat=lat, lon=lon, trk=t["trk"], gs=t["gs"], alt=t["p"][:, 2].copy(),
                         vs=t["v"][:, 2].copy(), id=list(range(n)))
    out = cstatebased.detect(ac, ac, np.full(n, H_M), np.full(n, V_M), np.full(n, LOOKAHEAD_S))
    return {(min(a, b), max(a, b)) for a, b in out[0]}


def best_of(fn, repeat: int):
    best, out = float("inf"), None
    for _ in range(repeat):
        t0 = time.perf_counter()
        out = fn()
        best = min(best, time.perf_counter() - t0)
    return best, out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--sizes", default="1000,4000,16000")
    ap.add_argument("--repeat", type=int, default=3)
    ap.add_argument("--seed", type=int, default=0)
    args = ap.parse_args(argv)
    try:
        bluesky_pairs(traffic(10, 0))   # imports and loads BlueSky before any timing
    except ImportError:
        raise SystemExit("bench_bluesky: BlueSky is not installed in this Python; make its "
                         "environment first (see this script's docstring)")
    print(f"cylinder H {H_M:g} m / V {V_M:g} m, look-ahead {LOOKAHEAD_S:g} s, seed {args.seed}, "
          f"best of {args.repeat}; load average {os.getloadavg()[0]:.2f}")
    print("| aircraft | BlueSky C [ms] | this project [ms] | ratio | pairs (BlueSky / ours) "
          "| in one set only | largest gap of those from 100 m [m] |")
    print("|---|---|---|---|---|---|---|")
    for n in (int(x) for x in args.sizes.split(",")):
        t = traffic(n, args.seed)
        bs_s, bs = best_of(lambda: bluesky_pairs(t), args.repeat)
        our_s, (mine, dist) = best_of(lambda: ours(t), args.repeat)
        only = bs ^ mine
        gaps = [abs(dist[p] - H_M) for p in only if p in dist]
        gap = f"{max(gaps):.3f}" if gaps else "-"
        print(f"| {n:,} | {bs_s * 1e3:,.1f} | {our_s * 1e3:,.1f} | {bs_s / our_s:,.1f} "
              f"| {len(bs):,} / {len(mine):,} | {len(only)} | {gap} |", flush=True)
    print(f"load average after: {os.getloadavg()[0]:.2f}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
