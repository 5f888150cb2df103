"""MWIS backend benchmark: ``python -m uam_solvers.bench [--quick]``.

Part 1 (small, the paper's sizes): a seeded corpus of paper-structured conflict graphs of 5 to 50
vertices (``uam_solvers.instances.generate_corpus_entries``, H4's generator: a clique group of up
to k = 5 candidates per request plus conflict edges). The optimum of each comes from ``exact``
(CP-SAT, checked proven). Every backend then solves every instance through the public
``uam_solvers.solve`` (validation, reductions, component split, backend, validation: end to end
from the arrays) and the table shows median and p95 wall time, the fraction solved optimally,
the fraction proven, fallbacks, and the fraction the reductions alone solved (kernel empty).
``qpu-emulator`` runs on a subset (``--qpu-subset``, limit ``--qpu-limit`` 10 s: its minorminer
embedding alone can take more than a second). ``chils`` runs with a 0.1 s limit (it
always runs until its limit; with 0.02 s it misses optima even on 6-vertex graphs), the others
with ``--small-limit`` (1 s).

Part 2 (scale): paper-shaped instances of 1,000 and 10,000 vertices
(``uam_solvers.instances.large_instance``): the objective each backend reaches with a 1 s and a
10 s limit (end-to-end wall time shown), the gap to the best value any backend found, and
whether the large-graph default (``chils``) is within 0.5 % of that best in 1 s.

Speed is machine- and load-dependent: the header prints the machine, load average and commit.
"median CPU ms" is the process CPU time (all threads) per solve: on a shared, loaded machine wall
time includes waiting for a core, CPU time does not.
"""
from __future__ import annotations

import argparse
import os
import platform
import subprocess
import sys
import time
from dataclasses import dataclass, field

import numpy as np

from . import solve
from .base import MwisProblem
from .registry import get_backend

SMALL_BACKENDS = ("greedy", "exact", "kamis", "chils", "sa", "tabu", "qpu-emulator")
LARGE_BACKENDS = ("greedy", "exact", "kamis", "chils", "sa", "tabu")
LARGE_DEFAULT = "chils"
CHILS_SMALL_LIMIT_S = 0.1


@dataclass
class Row:
    backend: str
    times_s: list = field(default_factory=list)
    cpu_s: list = field(default_factory=list)
    optimal: int = 0
    proven: int = 0
    fallbacks: int = 0
    kernel_empty: int = 0
    count: int = 0
    note: str = ""


def _machine() -> str:
    try:
        commit = subprocess.run(["git", "rev-parse", "--short", "HEAD"], capture_output=True,
                                text=True, cwd=os.path.dirname(__file__), check=False).stdout.strip()
    except OSError:
        commit = "?"
    cpu = platform.processor() or platform.machine()
    try:
        with open("/proc/cpuinfo") as fh:
            for line in fh:
                if line.startswith("model name"):
                    cpu = line.split(":", 1)[1].strip()
                    break
    except OSError:
        pass
    load = os.getloadavg() if hasattr(os, "getloadavg") else (float("nan"),) * 3
    return (f"machine: {cpu}, {os.cpu_count()} cores, Python {platform.python_version()}, "
            f"load average {load[0]:.2f} {load[1]:.2f} {load[2]:.2f}; commit {commit or '?'}; "
            f"{time.strftime('%Y-%m-%d %H:%M UTC', time.gmtime())}")


def _usable(name: str) -> tuple[bool, str]:
    try:
        return get_backend(name).available()
    except Exception as exc:  # noqa: BLE001 - a missing module is reported, not fatal
        return False, f"{type(exc).__name__}: {exc}"


def _corpus(n_instances: int, seed: int):
    try:
        from .instances import generate_corpus_entries
    except ImportError as exc:  # pragma: no cover - H4's module is part of the package
        raise SystemExit(f"uam_solvers.instances is missing ({exc})")
    return [e.problem for e in generate_corpus_entries(n_instances, 5, 50, seed=seed)]


def _solve_arrays(p: MwisProblem, backend: str, limit_s: float, seed: int, layers: bool = True,
                  cpu: list | None = None):
    """Solve from plain arrays (end to end) and return (result, wall_s); appends CPU s to cpu."""
    groups = [g for g in p.groups]
    c0 = time.process_time()
    t0 = time.perf_counter()
    r = solve(p.weights, p.edges, groups, backend=backend, time_limit_s=limit_s, seed=seed, layers=layers)
    dt = time.perf_counter() - t0
    if cpu is not None:
        cpu.append(time.process_time() - c0)
    return r, dt


def small_benchmark(n_instances: int, seed: int, backends, small_limit_s: float, qpu_subset: int,
                    qpu_limit_s: float = 10.0, out=print) -> list[Row]:
    problems = _corpus(n_instances, seed)
    sizes = [p.n for p in problems]
    out(f"\n## Small instances: {len(problems)} paper-structured graphs, {min(sizes)}-{max(sizes)} "
        f"vertices (generate_corpus_entries(n={n_instances}, 5, 50, seed={seed}))")
    optimum = []
    unproven = 0
    for p in problems:
        r, _ = _solve_arrays(p, "exact", 30.0, 0, layers=False)
        optimum.append(r.objective)
        unproven += not r.proven_optimal
    out(f"optimum: exact (CP-SAT, layers off, 30 s limit) proved {len(problems) - unproven}/"
        f"{len(problems)}")
    # Warm up imports and thread pools so the first instance does not pay them.
    warm = problems[0]
    rows = []
    runs = [(b, True) for b in backends] + ([("exact", False)] if "exact" in backends else [])
    for name, layers in runs:
        label = name if layers else f"{name} (layers off)"
        ok, reason = _usable(name)
        if not ok:
            rows.append(Row(label, note=f"unavailable: {reason}"))
            continue
        limit = CHILS_SMALL_LIMIT_S if name == "chils" else small_limit_s
        if name.startswith("qpu"):
            limit = qpu_limit_s  # embedding (minorminer) alone can take over a second
        subset = problems[:qpu_subset] if name.startswith("qpu") else problems
        _solve_arrays(warm, name, limit, 0, layers)
        row = Row(label)
        for i, p in enumerate(subset):
            r, dt = _solve_arrays(p, name, limit, i, layers, cpu=row.cpu_s)
            row.count += 1
            row.times_s.append(dt)
            tol = 1e-6 * max(1.0, p.n * float(p.weights.max(initial=0.0)))
            row.optimal += r.objective >= optimum[i] - tol
            row.proven += r.proven_optimal
            row.fallbacks += r.fallback
            row.kernel_empty += r.stats.get("kernel_vertices", -1) == 0
        if name == "chils":
            row.note = f"limit {CHILS_SMALL_LIMIT_S} s"
        elif name.startswith("qpu"):
            row.note = f"first {len(subset)} instances, limit {qpu_limit_s:g} s"
        rows.append(row)
    out("")
    out("| backend | instances | median ms | p95 ms | median CPU ms | optimal | proven | fallbacks | solved by reductions | note |")
    out("|---|---:|---:|---:|---:|---:|---:|---:|---:|---|")
    for r in rows:
        if not r.count:
            out(f"| {r.backend} | 0 | - | - | - | - | - | - | - | {r.note} |")
            continue
        t = np.asarray(r.times_s) * 1e3
        cpu_ms = np.median(np.asarray(r.cpu_s)) * 1e3
        out(f"| {r.backend} | {r.count} | {np.median(t):.2f} | {np.percentile(t, 95):.2f} | {cpu_ms:.2f} | "
            f"{100 * r.optimal / r.count:.1f} % | {100 * r.proven / r.count:.1f} % | {r.fallbacks} | "
            f"{100 * r.kernel_empty / r.count:.1f} % | {r.note} |")
    return rows


def large_benchmark(sizes, limits, seed: int, backends, out=print) -> dict:
    from .instances import large_instance

    results = {}
    for n in sizes:
        p = large_instance(n, seed)
        out(f"\n## Large instance: large_instance({n}, seed={seed}): {p.n} vertices, "
            f"{p.all_edges().shape[0]} edges (groups included), {len(p.groups)} requests")
        per = {}
        for name in backends:
            ok, reason = _usable(name)
            if not ok:
                per[name] = {"note": f"unavailable: {reason}"}
                continue
            per[name] = {}
            for limit in limits:
                r, dt = _solve_arrays(p, name, limit, 0)
                per[name][limit] = (r.objective, dt, r.proven_optimal, r.fallback, r.message)
        best = max((v[limit][0] for v in per.values() for limit in limits if limit in v), default=0.0)
        head = " | ".join(f"objective {lim:g} s | gap {lim:g} s | wall {lim:g} s" for lim in limits)
        out(f"\nbest objective any backend found: {best:.6f}\n")
        out(f"| backend | {head} | notes |")
        out("|---|" + "---:|" * (3 * len(limits)) + "---|")
        for name, v in per.items():
            if "note" in v:
                out(f"| {name} | " + " | ".join("-" for _ in range(3 * len(limits))) + f" | {v['note']} |")
                continue
            cells, notes = [], []
            for lim in limits:
                obj, dt, proven, fb, msg = v[lim]
                gap = 100.0 * (best - obj) / best if best > 0 else 0.0
                cells += [f"{obj:.4f}", f"{gap:.3f} %", f"{dt:.2f} s"]
                if proven:
                    notes.append(f"proven at {lim:g} s")
                if fb:
                    notes.append(f"fallback at {lim:g} s: {msg[:80]}")
            out(f"| {name} | " + " | ".join(cells) + f" | {'; '.join(notes)} |")
        if LARGE_DEFAULT in per and "note" not in per[LARGE_DEFAULT] and limits:
            obj = per[LARGE_DEFAULT][limits[0]][0]
            gap = 100.0 * (best - obj) / best if best > 0 else 0.0
            verdict = "within" if gap <= 0.5 else "NOT within"
            out(f"\nlarge-graph default `{LARGE_DEFAULT}` at {limits[0]:g} s: gap {gap:.3f} % "
                f"({verdict} 0.5 % of the best found)")
        results[n] = (best, per)
    return results


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m uam_solvers.bench", description=__doc__.split("\n")[0])
    ap.add_argument("--quick", action="store_true",
                    help="60 small instances, qpu subset 10, large 1,000 vertices at 1 s only")
    ap.add_argument("--instances", type=int, default=600, help="small corpus size (default 600)")
    ap.add_argument("--seed", type=int, default=0)
    ap.add_argument("--small-limit", type=float, default=1.0, help="time limit per small solve, s")
    ap.add_argument("--qpu-subset", type=int, default=60)
    ap.add_argument("--qpu-limit", type=float, default=10.0, help="time limit per qpu-emulator solve, s")
    ap.add_argument("--backends", default=",".join(SMALL_BACKENDS))
    ap.add_argument("--large-sizes", default="1000,10000")
    ap.add_argument("--large-limits", default="1,10")
    ap.add_argument("--large-backends", default=",".join(LARGE_BACKENDS))
    ap.add_argument("--skip-small", action="store_true")
    ap.add_argument("--skip-large", action="store_true")
    args = ap.parse_args(argv)
    if args.quick:
        args.instances, args.qpu_subset = 60, 10
        args.large_sizes, args.large_limits = "1000", "1"
    print("# MWIS solver benchmark (python -m uam_solvers.bench " + " ".join(argv or sys.argv[1:]) + ")")
    print(_machine())
    if not args.skip_small:
        small_benchmark(args.instances, args.seed, [b for b in args.backends.split(",") if b],
                        args.small_limit, args.qpu_subset, args.qpu_limit)
    if not args.skip_large:
        large_benchmark([int(s) for s in args.large_sizes.split(",") if s],
                        [float(s) for s in args.large_limits.split(",") if s], args.seed,
                        [b for b in args.large_backends.split(",") if b])
    return 0


if __name__ == "__main__":
    sys.exit(main())
