#!/usr/bin/env python3
"""The committed corpus of real planner MWIS instances of the layered modes (issue 20, Deliver 5).

    source scripts/env.sh
    nice -n 5 python scripts/make_mwis_corpus.py        # writes data/mwis/layered-mwis.jsonl.gz

Runs the in-process runner (``uam_sim.runner.scenario.run_scenario``: the planner the nodes run) on
each case of ``--cases`` in the expanded airspace (cylinder H 100 m / V 30 m, ``--slot-s`` 5 s
departure slots), for ``--duration`` (3,500) simulated seconds, demand seed ``--seed`` (0):

* ``singapore-layered``: ``config/networks/singapore-layered.yaml``, the paper's demand at 20
  requests per 30 s (``--rate``);
* ``city2000``: the synthetic city of scripts/measure_system_airspace.py (2,000 nodes, 100
  vertiports x 4 pads, levels 60/90/120/150 m), 3,000 requests per hour;

and keeps every epoch's MWIS instance exactly as the planner handed it to the solver (weights
d*/d, the conflict edges with the request cliques among them, one group per request). The
backend that answers the epochs is ``--method`` (default ``greedy``: deterministic whatever the
machine's load, so the same command writes the same bytes; with a time-limited backend later
epochs would depend on what each solve found in time).

Sampling: per case, the instances are put in size buckets (``uam_solvers.instances.
SIZE_BUCKETS``) and inside each bucket ``--per-bucket`` (10) are taken evenly spaced over the
run's epochs, so the steady state after the warm-up is in, not only the first epochs (the
largest instance of each run is always kept). The file is gzip-compressed JSON Lines
(``uam-mwis-corpus/1``, docs/mwis-corpus-format.md; gzip header without a time stamp);
``uam_solvers.instances.load_corpus`` reads it, ``python -m uam_solvers.bench --real-corpus``
benchmarks it. ``--max-bytes`` (default 1.8 MB): while the file is larger, the bucket of the
largest instances (the fuller one on a tie) gives up a sample (never its run's largest).

Each instance's ``source`` names the case, mode, rate, seed, method, epoch and simulated time.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import numpy as np

ROOT = Path(__file__).resolve().parents[1]

from uam_solvers.instances import REAL_CORPUS, SIZE_BUCKETS as BUCKETS  # noqa: E402
from uam_solvers.instances import size_bucket as bucket_of  # noqa: E402


#: the layered cases: (label, network spec, requests per 30 s)
CASES = {
    "singapore-layered": ("config/networks/singapore-layered.yaml", 20.0),
    # the city of scripts/measure_system_airspace.py: 2,000 nodes, 100 vertiports x 4 pads,
    # 4 levels, 3,000 requests per hour
    "city2000": ({"synthetic": {"n_nodes": 2000, "n_aerodromes": 100, "seed": 0,
                                "levels_m": [60.0, 90.0, 120.0, 150.0],
                                "pads_per_vertiport": 4}}, 25.0),
}

#: the planner's rolling-horizon graphs (issue 21's family, issue 20 item: ``auto`` must prove
#: them): the runs of scripts/bench_horizon.py with requests filed 120 s ahead, 120 s windows,
#: layered Singapore in mode "both", objective count, 20 requests per 30 s, horizon H epochs;
#: one request's candidates span up to H epochs as one group. Written to their own file:
#:
#:     python scripts/make_mwis_corpus.py --cases horizon-h5,horizon-h10 --duration 600 \
#:         --per-bucket 3 --max-vertices 2600 --max-bytes 1000000 \
#:         --out data/mwis/horizon-mwis.jsonl.gz
#:
#: (--max-vertices 2600: the runs answered by greedy leave more requests pending than CP-SAT's,
#: so their warm-up epochs reach 4,000 vertices; the steady state, and the 1,600-2,300 vertices
#: of the runs answered by CP-SAT, stay in)
HORIZON_CASES = {"horizon-h5": 5, "horizon-h10": 10}


def _horizon_config(args, h: int):
    from uam_sim.runner.experiment_config import make_config

    return make_config(airspace_mode="both", objective="count", horizon_epochs=h,
                       window_s=120.0, lead_time_s=120.0, time_limit_s=args.time_limit,
                       workers=1, duration_s=args.duration, audit=False)


def collect(args, label: str) -> tuple[list, dict]:
    """Every epoch's instance of one case's run: [(epoch, t_s, CorpusEntry)] and a summary."""
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import groups_from_ids, run_scenario
    from uam_solvers.base import MwisProblem
    from uam_solvers.instances import CorpusEntry

    if label in HORIZON_CASES:
        from uam_sim.runner.experiment_config import resolve_path

        cfg = _horizon_config(args, HORIZON_CASES[label])
        rate = 20.0
        net = load_network_spec(str(resolve_path(cfg.network)))
        what = (f"airspace both, horizon {HORIZON_CASES[label]} epochs, window 120 s, lead "
                f"120 s, objective count")
    else:
        spec, rate = CASES[label]
        if label == "singapore-layered" and args.rate is not None:
            rate = args.rate
        if isinstance(spec, str):
            spec = str(ROOT / spec)
        cfg = make_config({"network": spec, "duration_s": args.duration, "audit": False,
                           "time_limit_s": args.time_limit, "separation_model": "cylinder",
                           "vertical_separation_m": 30.0, "departure_slot_s": args.slot_s})
        net = load_network_spec(spec)
        what = f"cylinder 100/30 m, {args.slot_s:g} s slots"
    found = []

    def observer(t_s, epoch_index, submitted, refused, result) -> None:
        rep = result.report
        if rep.vertices < args.min_vertices or (args.max_vertices
                                                 and rep.vertices > args.max_vertices):
            return
        groups = groups_from_ids(rep.vertex_request_ids)
        edges = np.asarray(rep.edges_array, dtype=np.int64).reshape(-1, 2)
        problem = MwisProblem.from_arrays(np.asarray(rep.weights, dtype=np.float64), edges, groups)
        name = f"{label}-r{rate:g}-s{args.seed}-e{epoch_index:04d}-v{rep.vertices}"
        source = (f"scripts/make_mwis_corpus.py: run_scenario({label}, {what}, "
                  f"rate {rate:g}/30 s, seed {args.seed}, method "
                  f"{args.method}, {args.duration:g} s) epoch {epoch_index} t={t_s:g} s")
        found.append((epoch_index, t_s, CorpusEntry(name, problem, source)))

    t0 = time.perf_counter()
    res = run_scenario(net, args.method, rate, args.seed, args.duration, cfg,
                       observer=observer)
    summary = {"epochs": len(res.epochs), "requests": res.summary["requests"],
               "approved": res.summary["approved"], "wall_s": time.perf_counter() - t0}
    return found, summary


def sample(found: list, per_bucket: int) -> dict[int, list]:
    """Per bucket, up to ``per_bucket`` instances evenly spaced over the epochs (in epoch
    order); the run's largest instance is always among them."""
    by_bucket: dict[int, list] = {}
    for item in found:
        by_bucket.setdefault(bucket_of(item[2].problem.n), []).append(item)
    largest = max(found, key=lambda it: it[2].problem.n) if found else None
    out = {}
    for b, items in sorted(by_bucket.items()):
        items.sort(key=lambda it: it[0])
        if len(items) <= per_bucket:
            picked = list(items)
        else:
            idx = np.unique(np.round(np.linspace(0, len(items) - 1, per_bucket)).astype(int))
            picked = [items[i] for i in idx]
        if largest is not None and largest in items and largest not in picked:
            picked[-1] = largest
            picked.sort(key=lambda it: it[0])
        out[b] = picked
    return out


def write(path: Path, picked: dict[int, list]) -> int:
    from uam_solvers.instances import save_corpus

    entries = [it[2] for b in sorted(picked) for it in picked[b]]
    save_corpus(path, entries)
    return path.stat().st_size


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    ap.add_argument("--out", default=REAL_CORPUS)
    ap.add_argument("--cases", default="singapore-layered,city2000",
                    help=f"comma-separated cases of {sorted(CASES) + sorted(HORIZON_CASES)}")
    ap.add_argument("--rate", type=float, default=None,
                    help="singapore-layered: requests per 30 s (default 20)")
    ap.add_argument("--duration", type=float, default=3500.0, help="simulated seconds")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--slot-s", type=float, default=5.0, help="departure slot [s]")
    ap.add_argument("--method", default="greedy", help="backend answering the epochs")
    ap.add_argument("--time-limit", type=float, default=1.0, help="MWIS time limit [s]")
    ap.add_argument("--min-vertices", type=int, default=2)
    ap.add_argument("--max-vertices", type=int, default=0,
                    help="leave out instances above this size (0: none)")
    ap.add_argument("--per-bucket", type=int, default=10)
    ap.add_argument("--max-bytes", type=int, default=1_800_000)
    args = ap.parse_args(argv)
    picked = {}
    for label in [c for c in args.cases.split(",") if c]:
        if label not in CASES and label not in HORIZON_CASES:
            ap.error(f"--cases: {label!r} is not one of {sorted(CASES) + sorted(HORIZON_CASES)}")
        found, summary = collect(args, label)
        print(f"{label}: {summary['epochs']} epochs, {summary['requests']} requests, "
              f"{summary['approved']} approved, {len(found)} instances of >= "
              f"{args.min_vertices} vertices, wall {summary['wall_s']:.0f} s", flush=True)
        for b, (lo, hi) in enumerate(BUCKETS):
            eps = [it[0] for it in found if bucket_of(it[2].problem.n) == b]
            if eps:
                print(f"  bucket {lo}-{hi} vertices: {len(eps)} epochs ({min(eps)}-{max(eps)})")
        for b, items in sample(found, args.per_bucket).items():
            picked[(label, b)] = items
    out = ROOT / args.out if not Path(args.out).is_absolute() else Path(args.out)
    size = write(out, picked)
    while size > args.max_bytes:
        # the bucket of the largest instances gives up one sample (its largest stays)
        b = max((k for k, v in picked.items() if len(v) > 1),
                key=lambda k: (BUCKETS[k[1]][0], len(picked[k])), default=None)
        if b is None:
            break
        items = picked[b]
        keep = max(items, key=lambda it: it[2].problem.n)
        drop = next(it for it in items[len(items) // 2:] + items if it is not keep)
        items.remove(drop)
        size = write(out, picked)
    n_total = sum(len(v) for v in picked.values())
    print(f"wrote {out} ({size / 1e6:.2f} MB, {n_total} instances):")
    for key in sorted(picked):
        lo, hi = BUCKETS[key[1]]
        its = picked[key]
        print(f"  {key[0]} {lo}-{hi} vertices: {len(its)} instances, epochs "
              f"{', '.join(str(it[0]) for it in its)}; vertices "
              f"{', '.join(str(it[2].problem.n) for it in its)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
