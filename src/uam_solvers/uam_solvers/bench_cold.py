"""Cold-start solve times per backend: ``python -m uam_solvers.bench_cold``.

Each (API, backend, graph) runs in a fresh Python process (``python -m
uam_solvers.bench_cold --one ...``: the package itself is imported, no backend), then

* **cold**: the first call, ``uam_solvers.solve`` or ``uam_solvers.solve_bounded``, with the
  time limit (1 s by default): nothing warmed, the backend's imports and set-up inside it;
* **warm**: the same call again, after ``uam_solvers.warm_up([backend], service=True)`` for
  ``solve_bounded`` (its shared service started and warm) and as it is for ``solve``.

Printed as a Markdown table: wall time of the call [s], proven or not, the objective (weight),
how it ran (``stats["executor"]``, ``F`` for a fallback answer). Every wall must be at most the
limit + 0.5 s. Graphs are G(n, p) (uniform weights in [0.5, 1.5), seed 0): by default
G(300, 0.5), dense (KaMIS ran past 95 s with a 1 s limit) and G(250, 0.1), sparse; or, written
``RxK+M``, the shape of a planning epoch: R requests of K candidates each (clique groups) and M
random edges between requests (``250x420+5500000``: 105,000 vertices and 27.5 M conflict
pairs, the size of the large city's first epochs at 30,000 requests/h).

Options: ``--backends a,b`` (default: every available one), ``--graphs 300:0.5,250:0.1``,
``--apis solve,solve_bounded``, ``--limit 1.0``.
"""
from __future__ import annotations

import argparse
import json
import os
import re
import subprocess
import sys
import time

import numpy as np

__all__ = ["gnp", "grouped", "main"]

#: a run that has not ended after this long is reported as hung [s]
RUN_TIMEOUT_S = 120.0


def gnp(n: int, p: float, seed: int = 0) -> tuple[np.ndarray, np.ndarray]:
    """(weights, edges) of G(n, p): each pair an edge with probability ``p``, weights uniform in
    [0.5, 1.5), from ``numpy.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    a, b = np.triu_indices(n, 1)
    keep = rng.random(a.size) < p
    return rng.random(n) + 0.5, np.stack([a[keep], b[keep]], 1)


def grouped(requests: int, size: int, m: int, seed: int = 0) -> tuple:
    """(weights, edges, groups): ``requests`` clique groups of ``size`` consecutive vertices and
    up to ``m`` random edges between different groups (duplicates and pairs inside a group
    dropped), weights uniform in [0.5, 1.5), from ``numpy.random.default_rng(seed)``."""
    rng = np.random.default_rng(seed)
    n = requests * size
    u, v = rng.integers(0, n, m), rng.integers(0, n, m)
    keep = (u // size) != (v // size)
    groups = [np.arange(k * size, (k + 1) * size) for k in range(requests)]
    return rng.random(n) + 0.5, np.stack([u[keep], v[keep]], 1), groups


_GRAPH_SPEC = re.compile(r"\d+:(0|1|0?\.\d+)|\d+x\d+\+\d+")


def _label(spec: str) -> str:
    if "x" in spec:
        rk, _, m = spec.partition("+")
        r, _, k = rk.partition("x")
        return f"{r} x {k} grouped + {int(m):,}"
    n, _, p = spec.partition(":")
    return f"G({n}, {float(p):g})"


def _graph(spec: str) -> tuple:
    """(weights, edges, groups or None) of ``n:p`` or ``RxK+M``."""
    if "x" in spec:
        rk, _, m = spec.partition("+")
        r, _, k = rk.partition("x")
        return grouped(int(r), int(k), int(m))
    n, _, p = spec.partition(":")
    return (*gnp(int(n), float(p)), None)


def _call(api, weights, edges, groups, backend: str, limit_s: float) -> dict:
    t0 = time.perf_counter()
    r = api(weights, edges, groups, backend=backend, time_limit_s=limit_s)
    wall = time.perf_counter() - t0
    return {"wall_s": wall, "proven": bool(r.proven_optimal), "weight": float(r.objective),
            "executor": str(r.stats.get("executor", "in process")), "fallback": bool(r.fallback)}


def run_one(api_name: str, backend: str, spec: str, limit_s: float) -> dict:
    """The cold and the warm call in this process (which must be fresh for the cold one)."""
    import uam_solvers

    weights, edges, groups = _graph(spec)
    api = getattr(uam_solvers, api_name)
    out = {"cold": _call(api, weights, edges, groups, backend, limit_s)}
    if api_name == "solve_bounded":
        uam_solvers.warm_up([backend], service=True)
    out["warm"] = _call(api, weights, edges, groups, backend, limit_s)
    return out


def _fresh(api: str, backend: str, spec: str, limit_s: float) -> dict:
    cmd = [sys.executable, "-m", "uam_solvers.bench_cold", "--one", api, backend, spec,
           str(limit_s)]
    try:
        done = subprocess.run(cmd, capture_output=True, text=True, timeout=RUN_TIMEOUT_S)
    except subprocess.TimeoutExpired:
        return {"error": f"no answer after {RUN_TIMEOUT_S:g} s"}
    lines = [ln for ln in done.stdout.splitlines() if ln.startswith("{")]
    if done.returncode or not lines:
        return {"error": f"exit {done.returncode}: {done.stderr.strip()[-200:]}"}
    return json.loads(lines[-1])


def _cell(r: dict) -> str:
    how = r["executor"] + (", F" if r["fallback"] else "")
    return f"{r['wall_s']:.2f} | {'yes' if r['proven'] else 'no'} | {r['weight']:.3f} | {how}"


def _available_backends() -> list[str]:
    from .registry import list_backends

    return [name for name, _, ok, _ in list_backends() if ok]


def _load() -> str:
    return " ".join(f"{x:.2f}" for x in os.getloadavg())


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="python -m uam_solvers.bench_cold", description=__doc__,
                                 formatter_class=argparse.RawDescriptionHelpFormatter)
    ap.add_argument("--backends", default="", help="comma-separated (default: every available)")
    ap.add_argument("--graphs", default="300:0.5,250:0.1",
                    help="n:p (G(n, p)) or RxK+M (grouped), comma-separated")
    ap.add_argument("--apis", default="solve,solve_bounded", help="solve and/or solve_bounded")
    ap.add_argument("--limit", type=float, default=1.0, help="time limit of every call [s]")
    ap.add_argument("--one", nargs=4, metavar=("API", "BACKEND", "GRAPH", "LIMIT"),
                    help=argparse.SUPPRESS)
    args = ap.parse_args(argv)
    if args.one:
        api, backend, spec, limit = args.one
        print(json.dumps(run_one(api, backend, spec, float(limit))), flush=True)
        # the shared service's workers die with this process; no wait for their shutdown
        os._exit(0)
    backends = [b for b in args.backends.split(",") if b] or _available_backends()
    apis = [a for a in args.apis.split(",") if a]
    for a in apis:
        if a not in ("solve", "solve_bounded"):
            ap.error(f"--apis: {a!r} is neither solve nor solve_bounded")
    graphs = [g for g in args.graphs.split(",") if g]
    for g in graphs:
        if not _GRAPH_SPEC.fullmatch(g):
            ap.error(f"--graphs: {g!r} is neither n:p (G(n, p)) nor RxK+M (grouped)")
    print(f"# Cold-start solve times, limit {args.limit:g} s (target: every wall <= "
          f"{args.limit + 0.5:g} s)\n")
    print(f"load average before: {_load()}; {os.cpu_count()} cores\n")
    print("| API | backend | graph | cold wall s | proven | weight | how | "
          "warm wall s | proven | weight | how |")
    print("|---|---|---|---:|---|---:|---|---:|---|---:|---|")
    worst = 0.0
    for api in apis:
        for backend in backends:
            for spec in graphs:
                r = _fresh(api, backend, spec, args.limit)
                label = _label(spec)
                if "error" in r:
                    print(f"| {api} | {backend} | {label} | {r['error']} ||||||||")
                    worst = float("inf")
                    continue
                worst = max(worst, r["cold"]["wall_s"], r["warm"]["wall_s"])
                print(f"| {api} | {backend} | {label} | {_cell(r['cold'])} | "
                      f"{_cell(r['warm'])} |", flush=True)
    print(f"\nload average after: {_load()}. Worst wall {worst:.2f} s with a {args.limit:g} s "
          f"limit: {'met' if worst <= args.limit + 0.5 else 'NOT met'} (<= "
          f"{args.limit + 0.5:g} s). how: stats['executor'] ('in process': the caller's "
          "process; child: a forked child; killed: still running at the limit + margin, "
          "killed; starting: the backend's start-up outlived the limit; worker/inline: the "
          "shared service), F = the greedy fallback answered.")
    return 0 if worst <= args.limit + 0.5 else 1


if __name__ == "__main__":
    sys.exit(main())
