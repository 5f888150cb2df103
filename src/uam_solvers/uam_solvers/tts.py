"""Time-to-solution (TTS) study of MWIS backends, as in the paper's solver comparison.

    python -m uam_solvers.tts --corpus corpus.jsonl --backends greedy,exact,sa,tabu \\
        --repetitions 10 --out results/tts
    python -m uam_solvers.tts --generate 100 --corpus corpus.jsonl --out results/tts

For every instance of the corpus and every backend, R runs are made (seeds seed, seed+1, ...),
each a direct call of the backend on the instance's conflict graph (no reductions, no component
split, no fallback: the solver itself is measured, as in the paper). Definitions:

* one *run* of an annealing backend (sa, tabu, qpu, qpu-emulator) is one call with num_reads
  reads (paper: 10,000 reads per annealing run in its TTS study, so that is the default here; use
  --num-reads to shrink it); its answer is the best of its reads after descent and repair;
* t_c: mean wall time of one run in seconds (time.perf_counter around the call; each backend
  makes one untimed warm-up call first, so imports and one-time set-up are not counted);
* p_opt: fraction of the R runs whose answer is a valid independent set reaching the proven
  optimum (objective >= optimum - 1e-9 relative). The optimum comes from the corpus field
  "optimum" or else from the `exact` backend (CP-SAT), which must prove optimality; instances
  without a proven optimum are reported and skipped. CP-SAT proves optimality for weights
  rounded to 10^-6 of the largest; its answer is a real independent set, so any answer at least
  as heavy in float counts as optimal;
* per read (the paper's definition, annealers only): the trial is one read; p_read = share of
  all reads (R runs x num_reads) whose repaired answer reaches the optimum, with a 95 % Wilson
  score interval (p_read_lo, p_read_hi); t_read = the anneal time per read where the sampler
  reports one (QPU), else the wall time per read; TTS99/read = t_read log(0.01) / log(1 -
  p_read) with the interval from p_read's bounds. ``ci_within_factor`` says whether the
  interval lies within a factor CI_FACTOR (1.5) of p_read; for p_read near 1 % that needs
  2,454 reads (:func:`reads_needed`), so the default 10 runs of 10,000 reads have ample;
* per call (kept beside it): TTS(0.99) = t_c * log(1 - 0.99) / log(1 - p_opt), the expected time to see the optimum at least
  once with 99 % probability. When p_opt >= 0.99 one run already meets the target, so TTS = t_c
  (p_opt = 1 gives t_c). A deterministic backend (greedy, exact, kamis, gurobi) that misses the
  optimum in any run counts 10 s, as in the paper. A stochastic backend with p_opt = 0 has no TTS:
  it is "not reached", counted separately and left out of the box plot (never shown as a number).
  For annealers the per-read fraction of optimal answers is also written (read_opt_fraction).

Outputs in --out: tts.csv (tidy, one row per instance and backend: instance, n_vertices,
n_edges, backend, repetitions, num_reads, t_c_s, p_opt, tts99_s, reached, rule, optimum,
best_objective, read_opt_fraction, invalid_runs), tts_boxplot.png (TTS per backend, log scale,
not-reached counts under the labels), tts_meta.json (arguments, corpus, machine), and a summary
printed to stdout.
"""

from __future__ import annotations

import argparse
import csv
import json
import math
import os
import platform
import sys
import time
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np

from uam_solvers.base import MwisInputError, MwisProblem, check_selection
from uam_solvers.registry import sampling_backends
from uam_solvers.instances import (
    CorpusEntry,
    generate_corpus_entries,
    read_instances,
    save_corpus,
)

TARGET_PROBABILITY = 0.99
DETERMINISTIC_PENALTY_S = 10.0
DEFAULT_STUDY_NUM_READS = 10_000
#: the sampling backends (``Backend.samples``, read through the registry): a new sampler is in
#: the TTS study by its class alone
ANNEALING_BACKENDS = frozenset(sampling_backends())
DETERMINISTIC_BACKENDS = frozenset({"greedy", "exact", "kamis", "gurobi"})

CSV_COLUMNS = ["instance", "n_vertices", "n_edges", "backend", "repetitions", "num_reads",
               "t_c_s", "p_opt", "tts99_s", "reached", "rule", "optimum", "best_objective",
               "read_opt_fraction", "invalid_runs",
               "reads_total", "read_hits", "p_read", "p_read_lo", "p_read_hi", "t_read_s",
               "trial_time", "tts99_read_s", "tts99_read_lo_s", "tts99_read_hi_s",
               "ci_within_factor"]

#: confidence level of the intervals on p_read (Wilson score interval)
CI_LEVEL = 0.95
_Z = 1.959963984540054  # two-sided 95 % normal quantile
#: the study wants p_read near this value estimated within CI_FACTOR
CI_REFERENCE_P = 0.01
CI_FACTOR = 1.5

__all__ = [
    "ANNEALING_BACKENDS",
    "CSV_COLUMNS",
    "DETERMINISTIC_BACKENDS",
    "TtsRow",
    "main",
    "plot_tts",
    "proven_optimum",
    "run_study",
    "time_to_solution",
    "write_csv",
]


def wilson_interval(hits: int, trials: int, z: float = _Z) -> tuple[float, float]:
    """Wilson score interval (default 95 %) for a binomial proportion hits / trials.

    Unlike the normal approximation it stays inside [0, 1] and is usable for p near 0 or 1
    (Brown, Cai and DasGupta 2001). trials = 0 gives (0, 1). No hits gives a lower bound of
    exactly 0 and all hits an upper bound of exactly 1 (the formula leaves a rounding residue
    such as 5.6e-17 there, a "probability" too small for log(1 - p) to tell from 0).
    """
    if trials <= 0:
        return 0.0, 1.0
    p = hits / trials
    z2 = z * z
    denom = 1.0 + z2 / trials
    centre = (p + z2 / (2 * trials)) / denom
    half = z * math.sqrt(p * (1 - p) / trials + z2 / (4 * trials * trials)) / denom
    lo = 0.0 if hits <= 0 else max(0.0, centre - half)
    hi = 1.0 if hits >= trials else min(1.0, centre + half)
    return lo, hi


def reads_needed(p: float = CI_REFERENCE_P, factor: float = CI_FACTOR, z: float = _Z) -> int:
    """Fewest reads N such that, with hits = p N, the Wilson interval lies within
    [p / factor, p * factor]. For p = 1 % and factor 1.5: 2,454 reads."""
    lo_n, hi_n = 1, 1 << 30
    while lo_n < hi_n:
        mid = (lo_n + hi_n) // 2
        lo, hi = wilson_interval(int(round(p * mid)), mid, z)
        if lo >= p / factor and hi <= p * factor:
            hi_n = mid
        else:
            lo_n = mid + 1
    return lo_n


def time_to_solution(t_c_s: float, p_opt: float, deterministic: bool = False,
                     target: float = TARGET_PROBABILITY,
                     penalty_s: float = DETERMINISTIC_PENALTY_S) -> tuple[float | None, str]:
    """TTS(target) = t_c log(1 - target) / log(1 - p_opt), with the paper's conventions.

    Args:
        t_c_s: mean wall time of one run, seconds (>= 0).
        p_opt: fraction of runs that reached the optimum, in [0, 1].
        deterministic: the backend gives the same answer every run.
        target: the success probability aimed at (0.99).
        penalty_s: what a deterministic backend that misses the optimum counts (paper: 10 s).

    Returns:
        (tts_s, rule): rule is "optimal every run" (p_opt = 1: t_c), "single run suffices"
        (target <= p_opt < 1: t_c), "formula", "deterministic miss penalty" (penalty_s), or
        "not reached" (stochastic, p_opt = 0: tts_s is None).
    """
    if not (t_c_s >= 0 and math.isfinite(t_c_s)):
        raise MwisInputError(f"t_c_s must be a finite number >= 0, got {t_c_s!r}")
    if not (0.0 <= p_opt <= 1.0):
        raise MwisInputError(f"p_opt must lie in [0, 1], got {p_opt!r}")
    if not (0.0 < target < 1.0):
        raise MwisInputError(f"target must lie in (0, 1), got {target!r}")
    if p_opt >= 1.0:
        return float(t_c_s), "optimal every run"
    if deterministic:
        return float(penalty_s), "deterministic miss penalty"
    if p_opt <= 0.0:
        return None, "not reached"
    if p_opt >= target:
        return float(t_c_s), "single run suffices"
    return float(t_c_s * math.log(1.0 - target) / math.log(1.0 - p_opt)), "formula"


@dataclass
class TtsRow:
    """One instance x backend result of the study (a CSV row)."""

    instance: str
    n_vertices: int
    n_edges: int
    backend: str
    repetitions: int
    num_reads: int | None
    t_c_s: float
    p_opt: float
    tts99_s: float | None
    reached: bool
    rule: str
    optimum: float
    best_objective: float
    read_opt_fraction: float | None
    invalid_runs: int
    reads_total: int | None = None
    read_hits: int | None = None
    p_read: float | None = None
    p_read_lo: float | None = None
    p_read_hi: float | None = None
    t_read_s: float | None = None
    trial_time: str = ""
    tts99_read_s: float | None = None
    tts99_read_lo_s: float | None = None
    tts99_read_hi_s: float | None = None
    ci_within_factor: bool | None = None


def proven_optimum(problem: MwisProblem, time_limit_s: float = 600.0) -> float | None:
    """The optimum proven by the `exact` backend (CP-SAT), or None if it cannot prove it."""
    from uam_solvers.registry import get_backend

    result = get_backend("exact").solve(problem, time_limit_s=time_limit_s, seed=0, options={})
    return float(result.objective) if result.proven_optimal else None


def _reaches(objective: float, optimum: float) -> bool:
    return objective >= optimum - 1e-9 * max(1.0, abs(optimum))


def _backend_options(name: str, num_reads: int, optimum: float,
                     extra: Mapping[str, Mapping] | None = None) -> dict:
    options = {}
    if name in ANNEALING_BACKENDS:
        options = {"num_reads": int(num_reads), "optimum": float(optimum)}
    options.update((extra or {}).get(name, {}))
    return options


def _repeated_calls(problem: MwisProblem, backend, options: dict, optimum: float, repetitions: int,
                    time_limit_s: float, seed: int) -> dict:
    """``repetitions`` timed calls of ``backend`` on ``problem`` (seeds ``seed``, ``seed`` + 1,
    ...): each call's wall time [s], the calls that reached ``optimum``, the invalid answers,
    the best objective, and what the annealers report per read (optimal fractions, reads and
    their hits, anneal time per sample [us])."""
    times, hits, invalid, best, read_fractions = [], 0, 0, -math.inf, []
    reads_total = read_hits = 0
    anneal_us = []
    for rep in range(repetitions):
        start = time.perf_counter()
        result = backend.solve(problem, time_limit_s=time_limit_s, seed=seed + rep,
                               options=options)
        times.append(time.perf_counter() - start)
        ok, _ = check_selection(problem, result.selected)
        if not ok:
            invalid += 1
            continue
        objective = problem.objective(result.selected)
        best = max(best, objective)
        hits += _reaches(objective, optimum)
        if "optimal_fraction" in result.stats:
            read_fractions.append(float(result.stats["optimal_fraction"]))
            reads = int(result.stats.get("reads", 0))
            reads_total += reads
            read_hits += int(round(float(result.stats["optimal_fraction"]) * reads))
        if "qpu_anneal_time_per_sample_us" in result.stats:
            anneal_us.append(float(result.stats["qpu_anneal_time_per_sample_us"]))
    return {"times": times, "hits": hits, "invalid": invalid, "best": best,
            "read_fractions": read_fractions, "reads_total": reads_total, "read_hits": read_hits,
            "anneal_us": anneal_us}


def _tts_row(entry: CorpusEntry, optimum: float, name: str, calls: dict, repetitions: int,
             num_reads: int, deterministic: bool) -> TtsRow:
    """The TTS row of backend ``name`` on ``entry`` from its repeated ``calls``: the mean call
    time t_c [s], the share of calls at the optimum, TTS(0.99) [s] by its rule, and per read."""
    problem = entry.problem
    t_c = float(np.mean(calls["times"]))
    p_opt = calls["hits"] / repetitions
    tts, rule = time_to_solution(t_c, p_opt, deterministic=deterministic)
    per_read = _per_read(calls["reads_total"], calls["read_hits"], calls["times"], calls["anneal_us"])
    read_fractions = calls["read_fractions"]
    return TtsRow(
        instance=entry.name, n_vertices=problem.n, n_edges=len(problem.all_edges()),
        backend=name, repetitions=repetitions,
        num_reads=num_reads if name in ANNEALING_BACKENDS else None,
        t_c_s=t_c, p_opt=p_opt, tts99_s=tts,
        reached=rule not in ("not reached", "deterministic miss penalty"),
        rule=rule, optimum=float(optimum), best_objective=float(calls["best"]),
        read_opt_fraction=float(np.mean(read_fractions)) if read_fractions else None,
        invalid_runs=calls["invalid"], **per_read)


def run_study(entries: Sequence[CorpusEntry], backends: Sequence[str], repetitions: int,
              num_reads: int = DEFAULT_STUDY_NUM_READS, time_limit_s: float = 60.0,
              seed: int = 0, optimum_time_limit_s: float = 600.0,
              deterministic: Iterable[str] = DETERMINISTIC_BACKENDS,
              backend_options: Mapping[str, Mapping] | None = None,
              log=print) -> tuple[list[TtsRow], list[str]]:
    """Run every backend R times on every instance; return (rows, skipped instance names).

    backend_options: extra options per backend name, e.g. {"sa": {"num_sweeps": 1000}}
    (annealers always get num_reads and the instance's optimum).

    Backends are looked up with uam_solvers.registry.get_backend and must be available.
    Complexity: instances x backends x repetitions backend calls, plus one CP-SAT solve per
    instance without a stored optimum.
    """
    from uam_solvers.registry import get_backend

    if repetitions < 1:
        raise MwisInputError(f"repetitions must be >= 1, got {repetitions}")
    if num_reads < 1:
        raise MwisInputError(f"num_reads must be >= 1, got {num_reads}")
    deterministic = set(deterministic)
    solvers = {}
    for name in backends:
        backend = get_backend(name)
        backend.require_available()
        solvers[name] = backend
    rows: list[TtsRow] = []
    skipped: list[str] = []
    warmed: set[str] = set()
    for index, entry in enumerate(entries):
        problem = entry.problem
        optimum = entry.optimum
        if optimum is None:
            optimum = proven_optimum(problem, optimum_time_limit_s)
            if optimum is None:
                log(f"skip {entry.name}: exact could not prove the optimum within "
                    f"{optimum_time_limit_s} s")
                skipped.append(entry.name)
                continue
        for name, backend in solvers.items():
            options = _backend_options(name, num_reads, optimum, backend_options)
            if name not in warmed:  # imports and one-time set-up are not part of t_c
                backend.solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)
                warmed.add(name)
            calls = _repeated_calls(problem, backend, options, optimum, repetitions, time_limit_s, seed)
            rows.append(_tts_row(entry, optimum, name, calls, repetitions, num_reads,
                                 name in deterministic))
        if (index + 1) % 10 == 0 or index + 1 == len(entries):
            log(f"[{index + 1}/{len(entries)}] instances done")
    return rows, skipped


def _per_read(reads_total: int, read_hits: int, call_times_s: Sequence[float],
              anneal_us: Sequence[float]) -> dict:
    """The paper's TTS: trial = one read. p_read = hits / reads with its Wilson interval;
    t_read = anneal time per read where the sampler reports one (QPU), else the wall time per
    read (calls' total time / reads); TTS(0.99) = t_read log(0.01) / log(1 - p_read), with
    the interval from p_read's bounds (TTS falls as p rises)."""
    if reads_total <= 0:
        return {}
    p = read_hits / reads_total
    lo, hi = wilson_interval(read_hits, reads_total)
    if anneal_us:
        t_read, trial = float(np.mean(anneal_us)) * 1e-6, "read (QPU anneal time)"
    else:
        t_read, trial = float(np.sum(call_times_s)) / reads_total, "read (wall time per read)"

    def tts_at(q: float) -> float | None:
        if q <= 0.0:
            return None
        if q >= TARGET_PROBABILITY:
            return t_read
        # log1p: exact for small q, where log(1.0 - q) rounds to 0
        return t_read * math.log1p(-TARGET_PROBABILITY) / math.log1p(-q)

    within = None
    if read_hits > 0:
        within = bool(lo >= p / CI_FACTOR and hi <= p * CI_FACTOR)
    return {"reads_total": reads_total, "read_hits": read_hits, "p_read": p, "p_read_lo": lo,
            "p_read_hi": hi, "t_read_s": t_read, "trial_time": trial, "tts99_read_s": tts_at(p),
            "tts99_read_lo_s": tts_at(hi), "tts99_read_hi_s": tts_at(lo),
            "ci_within_factor": within}


def write_csv(path: str | Path, rows: Sequence[TtsRow]) -> Path:
    """Tidy CSV of the rows (CSV_COLUMNS); missing values are empty cells."""
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    with path.open("w", newline="", encoding="utf-8") as handle:
        writer = csv.DictWriter(handle, fieldnames=CSV_COLUMNS)
        writer.writeheader()
        for row in rows:
            record = asdict(row)
            writer.writerow({k: ("" if record[k] is None else record[k]) for k in CSV_COLUMNS})
    return path


def _by_backend(rows: Sequence[TtsRow], backends: Sequence[str]) -> dict[str, list[TtsRow]]:
    grouped = {name: [] for name in backends}
    for row in rows:
        grouped.setdefault(row.backend, []).append(row)
    return grouped


def plot_tts(path: str | Path, rows: Sequence[TtsRow], backends: Sequence[str]) -> Path:
    """Box plot of TTS(0.99) per backend on a log scale, like the paper's figure.

    Deterministic misses are drawn at their 10 s penalty; not-reached instances are not drawn,
    their count is written under the backend's label.
    """
    import matplotlib

    matplotlib.use("Agg")
    import matplotlib.pyplot as plt

    grouped = _by_backend(rows, backends)
    names = list(grouped)
    data, labels = [], []
    for name in names:
        values = [r.tts99_s for r in grouped[name] if r.tts99_s is not None]
        missing = sum(r.tts99_s is None for r in grouped[name])
        data.append(values if values else [np.nan])
        labels.append(name + (f"\n({missing} not reached)" if missing else ""))
    fig, ax = plt.subplots(figsize=(1.6 + 1.4 * len(names), 4.2))
    ax.boxplot(data, showfliers=True)
    ax.set_xticks(range(1, len(names) + 1), labels)
    ax.set_yscale("log")
    ax.set_ylabel("TTS(0.99) [s]")
    n_instances = len({r.instance for r in rows})
    ax.set_title(f"Time to solution, {n_instances} instances")
    ax.axhline(DETERMINISTIC_PENALTY_S, color="0.6", lw=0.8, ls="--",
               label=f"{DETERMINISTIC_PENALTY_S:g} s: deterministic miss (paper's convention)")
    ax.set_ylim(top=DETERMINISTIC_PENALTY_S * 4)
    ax.legend(loc="upper right", fontsize=8, frameon=False)
    ax.grid(True, axis="y", which="major", alpha=0.3)
    fig.tight_layout()
    path = Path(path)
    path.parent.mkdir(parents=True, exist_ok=True)
    fig.savefig(path, dpi=120)
    plt.close(fig)
    return path


def _read_cells(group: Sequence[TtsRow]) -> str:
    per_read = [r for r in group if r.reads_total]
    if not per_read:
        return f"{'-':>17}{'-':>15}{'-':>7}"
    tts = [r.tts99_read_s for r in per_read if r.tts99_read_s is not None]
    ok = sum(bool(r.ci_within_factor) for r in per_read)
    med = f"{np.median(tts):.4g} s" if tts else "-"
    return (f"{med:>17}{np.median([r.p_read for r in per_read]):>15.4f}"
            f"{f'{ok}/{len(per_read)}':>7}")


def summary_table(rows: Sequence[TtsRow], backends: Sequence[str]) -> str:
    """One line per backend: instances, median and p95 TTS, not reached, mean p_opt, t_c."""
    lines = [f"{'backend':<14}{'inst':>6}{'median TTS':>13}{'p95 TTS':>11}{'not reached':>13}"
             f"{'10 s pen.':>10}{'mean p_opt':>12}{'median t_c':>13}"
             f"{'median TTS/read':>17}{'median p_read':>15}{'CI ok':>7}"]
    for name, group in _by_backend(rows, backends).items():
        if not group:
            continue
        tts = np.array([r.tts99_s for r in group if r.tts99_s is not None], dtype=float)
        missing = sum(r.tts99_s is None for r in group)
        penalty = sum(r.rule == "deterministic miss penalty" for r in group)
        med = f"{np.median(tts):.4g} s" if tts.size else "-"
        p95 = f"{np.percentile(tts, 95):.4g} s" if tts.size else "-"
        lines.append(f"{name:<14}{len(group):>6}{med:>13}{p95:>11}{missing:>13}{penalty:>10}"
                     f"{np.mean([r.p_opt for r in group]):>12.3f}"
                     f"{np.median([r.t_c_s for r in group]) * 1e3:>10.2f} ms"
                     + _read_cells(group))
    return "\n".join(lines)


def _parse_args(argv: Sequence[str] | None) -> argparse.Namespace:
    parser = argparse.ArgumentParser(allow_abbrev=False,
        prog="python -m uam_solvers.tts",
        description="Time-to-solution study of MWIS backends (paper's TTS(0.99)).")
    parser.add_argument("--corpus", type=Path,
                        help="corpus file (JSON Lines, docs/mwis-corpus-format.md); with "
                             "--generate it is written first (default OUT/corpus.jsonl)")
    parser.add_argument("--backends", default="greedy,exact,sa,tabu",
                        help="comma-separated backend names (default greedy,exact,sa,tabu)")
    parser.add_argument("--repetitions", type=int, default=10, help="runs per instance (R)")
    parser.add_argument("--num-reads", type=int, default=DEFAULT_STUDY_NUM_READS,
                        help="reads per annealing run (paper: 10000)")
    parser.add_argument("--time-limit-s", type=float, default=60.0,
                        help="time limit handed to each run (s)")
    parser.add_argument("--seed", type=int, default=0, help="first run's seed")
    parser.add_argument("--out", type=Path, required=True, help="output directory")
    parser.add_argument("--generate", type=int, metavar="N",
                        help="generate N seeded paper-shaped instances first")
    parser.add_argument("--generate-seed", type=int, default=0, help="seed of --generate")
    parser.add_argument("--min-vertices", type=int, default=5)
    parser.add_argument("--max-vertices", type=int, default=50)
    parser.add_argument("--limit", type=int, help="use only the first N instances")
    parser.add_argument("--backend-options", type=json.loads, default={},
                        help='JSON object of extra options per backend, e.g. '
                             '\'{"sa": {"num_sweeps": 1000}}\'')
    parser.add_argument("--generate-only", action="store_true",
                        help="write the generated corpus (with proven optima) and stop")
    args = parser.parse_args(argv)
    if args.generate is None and args.corpus is None:
        parser.error("give --corpus FILE, or --generate N")
    if not isinstance(args.backend_options, dict) or not all(
            isinstance(v, dict) for v in args.backend_options.values()):
        parser.error("--backend-options must be a JSON object of objects, "
                     f"got {args.backend_options!r}")
    return args


def main(argv: Sequence[str] | None = None) -> int:
    args = _parse_args(argv)
    out = Path(args.out)
    out.mkdir(parents=True, exist_ok=True)
    backends = [b.strip() for b in args.backends.split(",") if b.strip()]
    if args.generate is not None:
        corpus_path = args.corpus or out / "corpus.jsonl"
        entries = generate_corpus_entries(args.generate, args.min_vertices, args.max_vertices,
                                          seed=args.generate_seed)
        # store proven optima so later studies on the same corpus skip CP-SAT
        with_optima = []
        for entry in entries:
            optimum = proven_optimum(entry.problem)
            with_optima.append(CorpusEntry(entry.name, entry.problem, entry.source, optimum))
        save_corpus(corpus_path, with_optima)
        print(f"wrote {len(with_optima)} instances ({args.min_vertices}-{args.max_vertices} "
              f"vertices, seed {args.generate_seed}) to {corpus_path}")
        if args.generate_only:
            return 0
    else:
        corpus_path = args.corpus
    entries = read_instances(corpus_path)
    if args.limit is not None:
        entries = entries[:args.limit]
    started = time.perf_counter()
    rows, skipped = run_study(entries, backends, args.repetitions, num_reads=args.num_reads,
                              time_limit_s=args.time_limit_s, seed=args.seed,
                              backend_options=args.backend_options,
                              log=lambda msg: print(msg, file=sys.stderr))
    csv_path = write_csv(out / "tts.csv", rows)
    png_path = plot_tts(out / "tts_boxplot.png", rows, backends)
    meta = {
        "corpus": str(corpus_path), "instances": len(entries), "skipped": skipped,
        "backends": backends, "repetitions": args.repetitions, "num_reads": args.num_reads,
        "time_limit_s": args.time_limit_s, "seed": args.seed,
        "backend_options": args.backend_options,
        "target_probability": TARGET_PROBABILITY,
        "deterministic_penalty_s": DETERMINISTIC_PENALTY_S,
        "machine": {"platform": platform.platform(), "python": platform.python_version(),
                    "cpus": os.cpu_count(), "processor": platform.processor()},
        "wall_time_s": time.perf_counter() - started,
    }
    (out / "tts_meta.json").write_text(json.dumps(meta, indent=2) + "\n")
    sizes = [e.problem.n for e in entries]
    print(f"TTS(0.99) study: {len(entries)} instances ({min(sizes, default=0)}-"
          f"{max(sizes, default=0)} vertices), R = {args.repetitions}, "
          f"{args.num_reads} reads per annealing run")
    print(summary_table(rows, backends))
    need = reads_needed()
    if args.num_reads * args.repetitions < need:
        print(f"note: {args.num_reads * args.repetitions} reads per instance; p_read near "
              f"{CI_REFERENCE_P:.0%} needs {need} for a {CI_LEVEL:.0%} interval within a factor "
              f"{CI_FACTOR:g}")
    if skipped:
        print(f"skipped (no proven optimum): {len(skipped)}")
    print(f"wrote {csv_path} and {png_path}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
