"""Classical annealing backends on the MWIS QUBO: simulated annealing ("sa") and tabu ("tabu").

Both build the QUBO of `uam_solvers.qubo` (lambda = 2 by default) as a dimod BQM, sample it
with dwave-samplers (SimulatedAnnealingSampler / TabuSampler), refine every read by one-flip
steepest descent, repair it into an independent set, and return the best read. They never prove
optimality (proven_optimal is always False).

Options (all optional, declared in each backend's ``options_spec``; an unknown key or a
malformed value is an MwisInputError naming it):

* num_reads (int, default 100): reads per solve (the paper: 100 in the simulation loop, 10,000
  in the time-to-solution study).
* lambda (float, default 2.0): QUBO penalty per conflicting pair.
* optimum (float): the known optimum of *this* problem; adds stats["optimal_fraction"]. Layers that
  change the graph (reductions, component split) change the optimum, so pass it only when calling
  the backend directly.
* sa: num_sweeps (int, default `SA_DEFAULT_SWEEPS` = 300), beta_range ((hot, cold) inverse
  temperatures; default `SA_DEFAULT_BETA_RANGE` = (1, 10) scaled by 2 / max(lambda, max weight),
  tuned for this QUBO; "auto" uses dwave-samplers' own default range).
* tabu: tenure (int; default the sampler's min(20, n / 4) up to 200 vertices, n / 10 above),
  num_restarts (int, default 0), lower_bound_z (int, default
  `TABU_DEFAULT_LOWER_BOUND_Z`, the number of variable updates of each tabu search), timeout_ms
  (per read; default: the time limit shared over the reads), max_vertices (default
  `TABU_MAX_VERTICES` = 200: larger graphs are decomposed, see below).

Large graphs: above SA_DECOMPOSE_ABOVE (sa) or max_vertices (tabu) vertices, 200 by
default, the graph is decomposed (`uam_solvers.decompose`): the greedy answer is improved by
subproblems of `subproblem_size` (200) vertices sampled by the same sampler until the time
limit, so the answer is never worse than greedy and more time buys a better one. (Sampled
whole, tabu and the emulator ended 7-16 % below greedy on 250-500 vertices at 10 s, and tabu's
dense n x n matrix refused graphs above 3,000 vertices.) The paper's 5-50 vertex instances are
sampled whole as before.

Time limit: simulated annealing stops between reads once time_limit_s has passed (the reads done
so far are used; stats["interrupted"] says so, and only then is the answer not reproducible);
tabu runs its reads in calls of TABU_READ_BUDGET // n reads (all 100 at once up to 20 vertices)
and stops between calls when another call as long as the last would end past time_limit_s; each
read also gets a timeout of time_limit_s / num_reads. With the default search length neither
binds on instances up to a few hundred vertices, so results are reproducible.

Statistics: those of `uam_solvers.qubo.refine_and_repair` (reads, best_objective,
feasible_fraction_raw, feasible_fraction, optimal_fraction, energies) plus sampler settings and
times (sample_time_s for the sampler call, postprocess_time_s for descent and repair).
"""

from __future__ import annotations

import time
from typing import Any, Mapping

import dimod
import numpy as np

try:  # imported here so the first solve does not pay for it
    from dwave.samplers import SimulatedAnnealingSampler, TabuSampler
    _SAMPLERS_IMPORT_ERROR = None
except ImportError as exc:  # pragma: no cover - dwave-samplers is a dependency
    SimulatedAnnealingSampler = TabuSampler = None
    _SAMPLERS_IMPORT_ERROR = exc

from uam_solvers.base import Backend, MwisInputError, MwisProblem, MwisResult, make_result
from uam_solvers.options import Option
from uam_solvers.qubo import DEFAULT_LAMBDA, mwis_qubo, refine_and_repair

__all__ = [
    "SA_DEFAULT_BETA_RANGE",
    "SA_DEFAULT_SWEEPS",
    "SimulatedAnnealingBackend",
    "TABU_DEFAULT_LOWER_BOUND_Z",
    "TabuBackend",
    "sampleset_to_array",
]

DEFAULT_NUM_READS = 100
SA_DEFAULT_SWEEPS = 300
#: (hot, cold) inverse temperatures for an energy scale of 1 (paper weights <= 1, lambda = 2);
#: scaled by 2 / max(lambda, max weight) for other scales. Tuned on 600 generated 5-50 vertex
#: instances: every instance solved with 100 reads, about 20 % of reads optimal, where the
#: sampler's own default range (about (0.03, 8) here) needs 1000 sweeps for the same hit rate.
SA_DEFAULT_BETA_RANGE = (1.0, 10.0)
TABU_DEFAULT_LOWER_BOUND_Z = 10000
TABU_DEFAULT_RESTARTS = 0
#: reads per TabuSampler call are TABU_READ_BUDGET // n (at least 1): a fraction of a second each
TABU_READ_BUDGET = 2000
#: larger graphs are decomposed (options["max_vertices"]); TabuSampler builds a dense n x n matrix
TABU_MAX_VERTICES = 200

_COMMON_OPTIONS = {"num_reads", "lambda", "optimum"}


def _positive(value):
    if not value > 0:
        raise ValueError("must be > 0")
    return value


def _beta_range(value):
    if isinstance(value, str):
        if value != "auto":
            raise ValueError("must be 'auto' or (hot, cold)")
        return value
    try:
        hot, cold = (float(b) for b in value)
    except (TypeError, ValueError):
        raise ValueError("must be two numbers (hot, cold)") from None
    if not (0 < hot <= cold and np.isfinite(cold)):
        raise ValueError("must satisfy 0 < hot <= cold")
    return value


#: Options every QUBO backend declares (sa, tabu, qpu, qpu-emulator).
COMMON_OPTIONS_SPEC = {
    "num_reads": Option("num_reads", "int", DEFAULT_NUM_READS, "reads (samples) per solve",
                        lo=1, hi=1_000_000),
    "lambda": Option("lambda", "float", DEFAULT_LAMBDA, "QUBO penalty per conflicting pair",
                     validator=_positive),
    "optimum": Option("optimum", "float", None, "known optimum of this problem: adds "
                      "stats['optimal_fraction'] (share of reads reaching it)", nullable=True),
    "subproblem_size": Option("subproblem_size", "int", None, "variables per subproblem when a "
                              "large graph is decomposed (None: the backend's default)",
                              lo=2, hi=100_000, nullable=True),
}

#: sa samples graphs up to this size whole; larger ones are decomposed (uam_solvers.decompose)
SA_DECOMPOSE_ABOVE = 200
#: default subproblem size of the decomposition for sa and tabu
DEFAULT_SUBPROBLEM_SIZE = 200


def given(options: Mapping[str, Any]) -> dict:
    """Validated options without the None ("backend decides") entries."""
    return {k: v for k, v in options.items() if v is not None}


def _int_option(options: Mapping[str, Any], key: str, default: int | None, minimum: int
                ) -> int | None:
    value = options.get(key, default)
    if value is None:
        return None
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise MwisInputError(f"options[{key!r}] must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _float_option(options: Mapping[str, Any], key: str, default: float | None,
                  positive: bool = True) -> float | None:
    value = options.get(key, default)
    if value is None:
        return None
    try:
        number = float(value)
    except (TypeError, ValueError):
        raise MwisInputError(f"options[{key!r}] must be a number, got {value!r}") from None
    if not np.isfinite(number) or (positive and number <= 0):
        raise MwisInputError(f"options[{key!r}] must be a finite number > 0, got {value!r}")
    return number


def common_options(options: Mapping[str, Any], known: set[str]) -> dict:
    """Parse num_reads, lambda and optimum (unknown keys were refused by validate_options;
    ``known`` is kept for callers). Raises MwisInputError."""
    parsed = {
        "num_reads": _int_option(options, "num_reads", DEFAULT_NUM_READS, 1),
        "lambda": _float_option(options, "lambda", DEFAULT_LAMBDA),
        "optimum": _float_option(options, "optimum", None, positive=False),
    }
    return parsed


def sampleset_to_array(sampleset, n: int) -> np.ndarray:
    """(R, n) int8 0/1 reads of a BINARY or SPIN sampleset over variables 0..n-1.

    Rows with num_occurrences > 1 are repeated, so R is the number of reads. Variables missing
    from the sampleset (none for the samplers here) are 0.
    """
    record = sampleset.record
    values = np.asarray(record.sample)
    if sampleset.vartype is dimod.SPIN:
        values = (values > 0).astype(np.int8)
    columns = np.asarray(list(sampleset.variables), dtype=np.int64)
    out = np.zeros((values.shape[0], n), dtype=np.int8)
    if columns.size:
        out[:, columns] = values
    counts = np.asarray(record.num_occurrences, dtype=np.int64)
    if counts.size and np.any(counts != 1):
        out = np.repeat(out, counts, axis=0)
    return out


def empty_result(problem: MwisProblem, backend: str, started: float) -> MwisResult:
    """The answer for a graph without vertices (no sampler call)."""
    return make_result(problem, np.zeros(0, dtype=np.int32), proven_optimal=True,
                       solve_time_s=time.perf_counter() - started, backend=backend,
                       stats={"reads": 0})


class _QuboSamplerBackend(Backend):
    """Shared pipeline: QUBO -> sampler -> steepest descent -> repair -> best read."""

    samples = True
    # dwave-samplers releases the GIL while it samples; reads stop near the time limit
    bounded_in_process = True
    warm_up_by_solving = True

    backend_options: set[str] = set()

    def _decompose_above(self, options: Mapping[str, Any]) -> int:
        """Graphs with more vertices are decomposed (subclasses)."""
        return 10**9

    def _sample_sub(self, sub_bqm, seed: int, remaining_s: float, num_reads: int,
                    options: Mapping[str, Any]):
        """Sample one subproblem BQM of the decomposition (subclasses)."""
        raise NotImplementedError

    def _decomposed(self, problem, parsed, options, time_limit_s, seed, started):
        from uam_solvers.decompose import decomposed_solve

        size = options.get("subproblem_size", DEFAULT_SUBPROBLEM_SIZE)
        reads = min(parsed["num_reads"], 10)  # per subproblem: the best of a few reads is kept
        # the final refine/repair costs ~0.1 s at 10^4 vertices: keep it inside the limit
        budget = max(time_limit_s - (time.perf_counter() - started) - 0.05 - 1e-5 * problem.n, 1e-3)
        selected, stats = decomposed_solve(
            problem, lambda sub, s, rem: self._sample_sub(sub, s, rem, reads, options),
            size=size, time_limit_s=budget, seed=int(seed) % 2**32, lam=parsed["lambda"])
        stats.update({"lambda": parsed["lambda"], "num_reads_per_subproblem": reads})
        return make_result(problem, selected, proven_optimal=False,
                           solve_time_s=time.perf_counter() - started, backend=self.name,
                           stats=stats)

    def _sample(self, bqm, num_reads: int, seed: int, time_limit_s: float,
                options: Mapping[str, Any]) -> tuple[Any, dict]:
        raise NotImplementedError

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        started = time.perf_counter()
        options = given(self.validate_options(options))
        parsed = common_options(options, self.backend_options)
        if problem.n == 0:
            return empty_result(problem, self.name, started)
        if problem.n > self._decompose_above(options):
            return self._decomposed(problem, parsed, options, time_limit_s, seed, started)
        qubo = mwis_qubo(problem, parsed["lambda"])
        bqm = qubo.to_bqm()
        sample_start = time.perf_counter()
        sampleset, sampler_stats = self._sample(bqm, parsed["num_reads"], int(seed) % 2**32,
                                                float(time_limit_s), options)
        sample_time = time.perf_counter() - sample_start
        raw = sampleset_to_array(sampleset, problem.n)
        post_start = time.perf_counter()
        selected, stats = refine_and_repair(problem, qubo, raw, optimum=parsed["optimum"])
        stats.update(sampler_stats)
        stats.update({
            "lambda": parsed["lambda"],
            "num_reads": parsed["num_reads"],
            "sample_time_s": sample_time,
            "postprocess_time_s": time.perf_counter() - post_start,
        })
        return make_result(problem, selected, proven_optimal=False,
                           solve_time_s=time.perf_counter() - started, backend=self.name,
                           stats=stats)


class SimulatedAnnealingBackend(_QuboSamplerBackend):
    """dwave-samplers simulated annealing on the MWIS QUBO, reads refined and repaired."""

    name = "sa"
    description = ("simulated annealing on the MWIS QUBO (dwave-samplers), 100 reads, "
                   "steepest descent + repair; heuristic")
    backend_options = {"num_sweeps", "beta_range"}
    options_spec = {
        **COMMON_OPTIONS_SPEC,
        "num_sweeps": Option("num_sweeps", "int", SA_DEFAULT_SWEEPS, "sweeps per read",
                             lo=1, hi=10**7),
        "beta_range": Option("beta_range", "any", None, "(hot, cold) inverse temperatures or "
                             "'auto' (None: the tuned range scaled to the QUBO)", nullable=True,
                             validator=_beta_range),
    }

    def available(self) -> tuple[bool, str]:
        if _SAMPLERS_IMPORT_ERROR is not None:
            return False, f"dwave-samplers is not installed ({_SAMPLERS_IMPORT_ERROR})"
        return True, ""

    @staticmethod
    def _energy_scale(bqm) -> float:
        """max(lambda, max weight) of an MWIS QUBO: the largest |bias|."""
        linear, (_, _, quadratic), _ = bqm.to_numpy_vectors()
        return float(max(np.abs(linear).max(initial=0.0), np.abs(quadratic).max(initial=0.0)))

    def _decompose_above(self, options):
        return SA_DECOMPOSE_ABOVE

    def _sample_sub(self, sub_bqm, seed, remaining_s, num_reads, options):
        num_sweeps = options.get("num_sweeps", SA_DEFAULT_SWEEPS)
        scale = 2.0 / max(self._energy_scale(sub_bqm), 1e-12)
        deadline = time.perf_counter() + remaining_s
        return SimulatedAnnealingSampler().sample(
            sub_bqm, num_reads=num_reads, num_sweeps=num_sweeps,
            beta_range=tuple(b * scale for b in SA_DEFAULT_BETA_RANGE), seed=seed,
            interrupt_function=lambda: time.perf_counter() > deadline)

    def _sample(self, bqm, num_reads, seed, time_limit_s, options):
        num_sweeps = _int_option(options, "num_sweeps", SA_DEFAULT_SWEEPS, 1)
        beta_range = options.get("beta_range")
        if beta_range is None:
            # the tuned range is for energy scale 1 (lambda = 2, weights <= 1)
            scale = 2.0 / max(self._energy_scale(bqm), 1e-12)
            beta_range = tuple(b * scale for b in SA_DEFAULT_BETA_RANGE)
        if isinstance(beta_range, str):
            if beta_range != "auto":
                raise MwisInputError(
                    f"options['beta_range'] must be 'auto' or (hot, cold), got {beta_range!r}")
            beta_range = None
        else:
            try:
                hot, cold = (float(b) for b in beta_range)
            except (TypeError, ValueError):
                raise MwisInputError(
                    f"options['beta_range'] must be two numbers (hot, cold), got {beta_range!r}"
                ) from None
            if not (0 < hot <= cold and np.isfinite(cold)):
                raise MwisInputError(
                    f"options['beta_range'] must satisfy 0 < hot <= cold, got {beta_range!r}")
            beta_range = (hot, cold)
        deadline = time.perf_counter() + time_limit_s
        interrupted = []

        def past_deadline() -> bool:
            # checked by the sampler between reads; a time limit needs the wall clock
            late = time.perf_counter() > deadline
            if late:
                interrupted.append(True)
            return late

        sampleset = SimulatedAnnealingSampler().sample(
            bqm, num_reads=num_reads, num_sweeps=num_sweeps, beta_range=beta_range, seed=seed,
            interrupt_function=past_deadline)
        used_beta = sampleset.info.get("beta_range", beta_range)
        stats = {
            "num_sweeps": num_sweeps,
            "beta_range": ",".join(f"{b:.6g}" for b in used_beta) if used_beta is not None
            else "default",
            "interrupted": bool(interrupted),
        }
        return sampleset, stats


class TabuBackend(_QuboSamplerBackend):
    """dwave-samplers multistart tabu search on the MWIS QUBO, reads refined and repaired."""

    name = "tabu"
    description = ("tabu search on the MWIS QUBO (dwave-samplers), 100 reads, "
                   "steepest descent + repair; heuristic")
    backend_options = {"tenure", "num_restarts", "lower_bound_z", "timeout_ms", "max_vertices"}
    options_spec = {
        **COMMON_OPTIONS_SPEC,
        "tenure": Option("tenure", "int", None, "tabu tenure (None: min(20, n/4) up to 200 "
                         "vertices, n/10 above)", lo=0, hi=10**6, nullable=True),
        "num_restarts": Option("num_restarts", "int", TABU_DEFAULT_RESTARTS, "restarts per read",
                               lo=0, hi=10**6),
        "lower_bound_z": Option("lower_bound_z", "int", TABU_DEFAULT_LOWER_BOUND_Z,
                                "variable updates per tabu search", lo=1, hi=10**9),
        "timeout_ms": Option("timeout_ms", "int", None, "per-read timeout (None: the time limit "
                             "shared over the reads)", lo=1, hi=10**8, nullable=True),
        "max_vertices": Option("max_vertices", "int", TABU_MAX_VERTICES, "largest graph tabu "
                               "samples whole (dense n x n matrix); larger graphs are "
                               "decomposed into subproblems", lo=1, hi=10**6),
    }

    def available(self) -> tuple[bool, str]:
        if _SAMPLERS_IMPORT_ERROR is not None:
            return False, f"dwave-samplers is not installed ({_SAMPLERS_IMPORT_ERROR})"
        return True, ""

    def _decompose_above(self, options):
        # TabuSampler works on a dense n x n matrix (8 n^2 bytes, several copies): larger
        # graphs are decomposed into subproblems instead
        return options.get("max_vertices", TABU_MAX_VERTICES)

    def _sample_sub(self, sub_bqm, seed, remaining_s, num_reads, options):
        n = sub_bqm.num_variables
        tenure = options.get("tenure", max(1, min(20, n // 4)))
        timeout_ms = max(1, int(min(100.0, remaining_s * 1000.0 / (2 * num_reads))))
        return TabuSampler().sample(sub_bqm, num_reads=num_reads, seed=seed,
                                    tenure=min(tenure, max(n - 1, 0)), timeout=timeout_ms,
                                    num_restarts=options.get("num_restarts", TABU_DEFAULT_RESTARTS))

    def _sample(self, bqm, num_reads, seed, time_limit_s, options):
        n = bqm.num_variables
        # the sampler's default tenure, min(20, n / 4), is too short for large graphs: n / 10
        # above 200 vertices gains ~10 % objective on 1,000-vertex paper-shaped graphs
        tenure = _int_option(options, "tenure", n // 10 if n > 200 else None, 0)
        num_restarts = _int_option(options, "num_restarts", TABU_DEFAULT_RESTARTS, 0)
        lower_bound_z = _int_option(options, "lower_bound_z", TABU_DEFAULT_LOWER_BOUND_Z, 1)
        default_timeout = max(1, int(time_limit_s * 1000.0 / num_reads))
        timeout_ms = _int_option(options, "timeout_ms", default_timeout, 1)
        if tenure is not None and tenure >= n:
            tenure = max(0, n - 1)  # TabuSampler requires tenure < n
        # Reads go in calls of a size fixed by n (about 0.1 s of work each), seeded seed + call
        # index, so the answer does not depend on timing unless the time limit stops the calls.
        per_call = max(1, min(num_reads, TABU_READ_BUDGET // max(n, 1)))
        deadline = time.perf_counter() + time_limit_s
        samplesets = []
        done = 0
        call = 0
        while done < num_reads:
            reads = min(per_call, num_reads - done)
            call_start = time.perf_counter()
            # coefficient_z_first = 1 makes lower_bound_z the search length on instances up to
            # lower_bound_z variables (the sampler's default is 10,000 updates per variable)
            samplesets.append(TabuSampler().sample(
                bqm, num_reads=reads, seed=(seed + call) % 2**32, tenure=tenure,
                num_restarts=num_restarts, lower_bound_z=lower_bound_z, coefficient_z_first=1,
                coefficient_z_restart=1, timeout=timeout_ms))
            done += reads
            call += 1
            # stop when the next call, as long as this one, would end past the deadline
            now = time.perf_counter()
            if now + (now - call_start) > deadline:
                break
        sampleset = dimod.concatenate(samplesets) if len(samplesets) > 1 else samplesets[0]
        stats = {
            "num_restarts": num_restarts,
            "lower_bound_z": lower_bound_z,
            "timeout_ms_per_read": timeout_ms,
            "tenure": -1 if tenure is None else tenure,
            "sampler_calls": call,
            "interrupted": done < num_reads,
        }
        return sampleset, stats
