"""The ``auto`` backend: exact where a proof is affordable, CHILS where it is not.

Inside the default pipeline (``ValidateFallback(Reduce(ComponentSplit(auto)))``) the graph is
first reduced by the exact rules of :mod:`uam_solvers.reductions` (up to ``self_reduce_above``
= 256 vertices, where they pay; on large paper-shaped graphs they remove ~2 % of the vertices
for ~0.4 s at 10,000 vertices, so large graphs skip them) and split into connected components;
``auto`` then gets each non-trivial component (kernel) and chooses by its size:

* at most ``exact_max_vertices`` (200) vertices: CP-SAT (:class:`uam_solvers.cpsat.CpSatBackend`),
  which honours its time limit and proves optimality (for the integer-scaled weights, see
  :func:`uam_solvers.base.integer_weights`). When CP-SAT has not proven the optimum within
  ``exact_fraction`` (0.5) of the component's time share, the rest of the share goes to CHILS
  seeded nowhere (its own search) and the better answer is kept (unproven).
* larger: CHILS (:class:`uam_solvers.chszla.ChilsBackend`, local search, never proven) for the
  whole share minus ``safety_s``, so the answer is back within the limit.

KaMIS branch-and-reduce is not used: measured here it ignores its time limit on dense
paper-shaped kernels (42 s with a 5 s limit on a 250-vertex ``paper_instance``), and
chszlablib's LearnAndReduce kernelisation removed little of these graphs (BENCHMARKS.md).

``proven_optimal`` is True only when CP-SAT reported OPTIMAL for every component.
"""
from __future__ import annotations

import time
from typing import Any, Mapping

from .base import Backend, MwisProblem, MwisResult, make_result
from .options import Option

__all__ = ["AutoBackend"]


class AutoBackend(Backend):
    """CP-SAT on small kernels (proves optimality), CHILS on large ones."""

    name = "auto"
    description = ("exact reductions + component split, CP-SAT on kernels up to 200 vertices "
                   "(proves optimality), CHILS above; the default")
    reduces_itself = True  # the Reduce layer skips graphs above 256 vertices
    #: in-process in the solve service up to this size: CP-SAT stops at its limit
    inline_max_vertices = 64
    options_spec = {
        "exact_max_vertices": Option("exact_max_vertices", "int", 200, "largest kernel solved "
                                     "by CP-SAT (larger: CHILS)", lo=0, hi=100_000),
        "exact_fraction": Option("exact_fraction", "float", 0.5, "share of a kernel's time "
                                 "CP-SAT may use before CHILS gets the rest", lo=0.05, hi=1.0),
        "num_concurrent": Option("num_concurrent", "int", 1, "CHILS concurrent searches",
                                 lo=1, hi=64),
        "safety_s": Option("safety_s", "float", 0.05, "time kept back from CHILS's limit for "
                           "lifting and checking the answer [s]", lo=0.0, hi=10.0),
    }

    def __init__(self) -> None:
        from .chszla import ChilsBackend
        from .cpsat import CpSatBackend

        self._exact = CpSatBackend()
        self._chils = ChilsBackend()

    def available(self) -> tuple[bool, str]:
        ok, why = self._exact.available()
        if not ok:
            return ok, why
        return self._chils.available()

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        t0 = time.perf_counter()
        opts = self.validate_options(options)
        n = problem.n
        if n == 0:
            return make_result(problem, [], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        chils_opts = {"num_concurrent": opts["num_concurrent"]}
        if n <= opts["exact_max_vertices"]:
            budget = time_limit_s if n <= 64 else time_limit_s * opts["exact_fraction"]
            res = self._exact.solve(problem, time_limit_s=max(budget, 1e-3), seed=seed,
                                    options={})
            stats = {**res.stats, "auto_method": "cpsat"}
            if res.proven_optimal:
                return make_result(problem, res.selected, proven_optimal=True,
                                   solve_time_s=time.perf_counter() - t0, backend=self.name,
                                   stats=stats)
            rest = time_limit_s - (time.perf_counter() - t0) - opts["safety_s"]
            if rest > 0.1:  # CHILS has ~70 ms of set-up; below that it cannot help
                alt = self._chils.solve(problem, time_limit_s=rest, seed=seed, options=chils_opts)
                if alt.objective > res.objective:
                    res, stats = alt, {**stats, **alt.stats, "auto_method": "cpsat+chils"}
            return make_result(problem, res.selected, proven_optimal=False,
                               solve_time_s=time.perf_counter() - t0, backend=self.name,
                               stats=stats)
        budget = max(time_limit_s - (time.perf_counter() - t0) - opts["safety_s"], 1e-3)
        res = self._chils.solve(problem, time_limit_s=budget, seed=seed, options=chils_opts)
        return make_result(problem, res.selected, proven_optimal=res.proven_optimal,
                           solve_time_s=time.perf_counter() - t0, backend=self.name,
                           stats={**res.stats, "auto_method": "chils"})
