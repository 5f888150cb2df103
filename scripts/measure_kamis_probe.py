#!/usr/bin/env python3
"""Issue 20, twelfth stop: ``auto``'s KaMIS probe before CP-SAT, as it was and as it is.

    .venv/bin/python scripts/measure_kamis_probe.py --limit 1

On the graphs of the committed corpora that go to CP-SAT (the horizon corpus and the layered
corpus's graphs above 600 vertices that do), ``auto`` end to end (``uam_solvers.solve`` from the
arrays) with the probe as it was (0.01 of the limit, at least 0.05 s, then the tie-break's
re-run of 3 x that after a CP-SAT proof: ``KAMIS_PROBE_MAX_SHARE`` = 0) and as it is (the probe
given the re-run's budget at once), alternately, each the best of ``--repeats``. Prints per
graph the two walls, whether both returned the same set and proof, and each one's method and
tie-break. Walls depend on the machine's load (printed); the sets do not.
"""

from __future__ import annotations

import argparse
import os
import time


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--limit", type=float, default=1.0, help="auto's time limit [s]")
    ap.add_argument("--repeats", type=int, default=3)
    args = ap.parse_args(argv)

    import uam_solvers.auto as auto_mod
    from uam_solvers import solve
    from uam_solvers.instances import HORIZON_CORPUS, load_corpus, real_corpus_path

    entries = load_corpus(real_corpus_path(HORIZON_CORPUS)) + [
        e for e in load_corpus(real_corpus_path()) if e.problem.n > 600]
    auto = auto_mod.AutoBackend()
    opts = auto.validate_options({})
    entries = [e for e in entries
               if auto._cpsat_suits(e.problem, None, int(e.problem.all_edges().shape[0]), opts)]
    keep = auto_mod.KAMIS_PROBE_MAX_SHARE

    def run(p):
        t = time.perf_counter()
        r = solve(p.weights, p.edges, list(p.groups), backend="auto", time_limit_s=args.limit, seed=0)
        return time.perf_counter() - t, r

    run(entries[0].problem)  # warm-up (imports, the first CP-SAT model)
    print(f"load before {os.getloadavg()[0]:.1f}; limit {args.limit:g} s, best of {args.repeats}")
    print("| graph | vertices | before ms | now ms | same set and proof | before: method, tie-break "
          "| now: method, tie-break |")
    print("|---|---:|---:|---:|---|---|---|")
    for e in entries:
        p = e.problem
        old, new = [], []
        for _ in range(max(1, args.repeats)):
            auto_mod.KAMIS_PROBE_MAX_SHARE = 0.0
            d, ro = run(p)
            old.append(d)
            auto_mod.KAMIS_PROBE_MAX_SHARE = keep
            d, rn = run(p)
            new.append(d)
        same = ro.selected.tolist() == rn.selected.tolist() and ro.proven_optimal == rn.proven_optimal
        print(f"| {e.name} | {p.n} | {min(old) * 1e3:.0f} | {min(new) * 1e3:.0f} | {same} | "
              f"{ro.stats.get('auto_method')}, {ro.stats.get('tie_break', '-')} | "
              f"{rn.stats.get('auto_method')}, {rn.stats.get('tie_break', '-')} |")
    print(f"load after {os.getloadavg()[0]:.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
