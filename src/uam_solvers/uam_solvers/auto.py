"""The ``auto`` backend: exact where a proof is affordable, CHILS where it is not.

Inside the default pipeline (``ValidateFallback(Reduce(ComponentSplit(auto)))``) the graph is
first reduced by the exact rules of :mod:`uam_solvers.reductions` (up to ``self_reduce_above``
= 256 vertices, where they pay; on large paper-shaped graphs they remove ~2 % of the vertices
for ~0.4 s at 10,000 vertices, so large graphs skip them) and split into connected components;
``auto`` then gets each non-trivial component (kernel) and chooses by its size:

* at most ``kamis_max_vertices`` (64) vertices (the whole graph: no Python reductions or split
  below 65 vertices, KaMIS reduces and splits faster itself): KaMIS branch-and-reduce, which
  returns before its time limit only when its search is complete; a return within half the
  limit is taken as the proof. Measured: 0.2 ms at 15 and up to 47 ms at 50 paper-shaped
  vertices (under load);
* at most ``exact_max_vertices`` (200) vertices: CP-SAT (:class:`uam_solvers.cpsat.CpSatBackend`),
  which honours its time limit and proves optimality (for the integer-scaled weights, see
  :func:`uam_solvers.base.integer_weights`). When CP-SAT has not proven the optimum within
  ``exact_fraction`` (0.5) of the component's time share, the rest of the share goes to CHILS
  seeded nowhere (its own search) and the better answer is kept (unproven).
* larger: CHILS (:class:`uam_solvers.chszla.ChilsBackend`, local search, never proven) for the
  whole share minus ``safety_s``, so the answer is back within the limit.

KaMIS is not used above 64 vertices: measured here it ignores its time limit on dense
paper-shaped graphs (42 s with a 5 s limit on a 250-vertex ``paper_instance``); and
chszlablib's LearnAndReduce kernelisation removed little of these graphs (about 5 % of a
10,000-vertex ``large_instance``, 0.5-1 s) and costs up to 0.4 s on some 5-50 vertex ones, so it
is not used either (BENCHMARKS.md).

``proven_optimal`` is True only when KaMIS finished or CP-SAT reported OPTIMAL for every
component.
"""
from __future__ import annotations

import time
from typing import Any, Mapping

from .base import Backend, MwisProblem, MwisResult, make_result
from .cliquebb import SMALL_MAX_VERTICES, clique_branch_and_bound
from .options import Option

__all__ = ["AutoBackend"]

#: CHILS's set-up beyond its time limit: fixed part [s] and per edge [s]
CHILS_SETUP_S = 0.12
CHILS_SETUP_S_PER_EDGE = 1.5e-7
#: search nodes of :func:`uam_solvers.cliquebb.clique_branch_and_bound` per second of time
#: limit it may use (measured ~5 us per node at 50 vertices under load: 2e5 nodes/s keeps it
#: inside the limit)
BB_NODES_PER_S = 2e5
#: default node limit of the clique branch and bound (~0.1 s; 600 corpus graphs of 5-50
#: vertices needed at most 525 nodes)
BB_NODE_LIMIT = 20_000


def bb_node_limit(time_limit_s: float, cap: int = BB_NODE_LIMIT) -> int:
    """Search nodes the clique branch and bound may visit within ``time_limit_s`` [s]."""
    return max(1, min(int(cap), int(time_limit_s * BB_NODES_PER_S)))


class AutoBackend(Backend):
    """KaMIS on small graphs, CP-SAT on medium kernels (both prove optimality), CHILS above."""

    name = "auto"
    description = ("exact reductions + component split, CP-SAT on kernels up to 200 vertices "
                   "(proves optimality), CHILS above; the default")
    reduces_itself = True  # the Reduce layer skips graphs above 256 vertices
    #: up to kamis_max_vertices the graph goes to KaMIS whole: it reduces and splits itself
    #: faster than the Python layers (their ~1-4 ms would dominate a 50-vertex solve)
    reduce_min_vertices = split_min_vertices = 65
    #: larger graphs go to CHILS whole (it reduces itself; one call saves its set-up per
    #: component and the Python split's cost)
    split_max_vertices = 2000
    #: in-process in the solve service up to this size (KaMIS / CP-SAT: milliseconds here)
    inline_max_vertices = 64
    options_spec = {
        "bb_max_vertices": Option("bb_max_vertices", "int", SMALL_MAX_VERTICES, "graphs up to this size try "
                                  "the exact clique branch and bound first", lo=0, hi=1000),
        "bb_node_limit": Option("bb_node_limit", "int", BB_NODE_LIMIT, "search nodes before the clique "
                                "branch and bound gives up (then KaMIS)", lo=1, hi=10**8),
        "kamis_max_vertices": Option("kamis_max_vertices", "int", 64, "graphs up to this "
                                     "size go to KaMIS branch-and-reduce whole", lo=0, hi=1000),
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
        from .chszla import ChilsBackend, KamisBackend
        from .cpsat import CpSatBackend

        self._exact = CpSatBackend()
        self._chils = ChilsBackend()
        self._kamis = KamisBackend()

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
        if n <= opts["bb_max_vertices"]:
            # exact branch and bound over the requests' cliques, no extension call; it gives up
            # (None) past its node limit and KaMIS below takes over
            node_limit = bb_node_limit(time_limit_s, opts["bb_node_limit"])
            sel, nodes = clique_branch_and_bound(problem, node_limit)
            if sel is not None:
                return make_result(problem, sel, proven_optimal=True,
                                   solve_time_s=time.perf_counter() - t0, backend=self.name,
                                   stats={"auto_method": "clique-bb", "bb_nodes": nodes})
        if n <= opts["kamis_max_vertices"]:
            # branch-and-reduce only returns before its time limit once its search is complete,
            # so a return well inside the limit is a proof (finish_fraction 0.5 of the limit)
            res = self._kamis.solve(problem, time_limit_s=time_limit_s, seed=seed,
                                    options={"finish_fraction": 0.5})
            if res.proven_optimal or n > opts["exact_max_vertices"]:
                return make_result(problem, res.selected, proven_optimal=res.proven_optimal,
                                   solve_time_s=time.perf_counter() - t0, backend=self.name,
                                   stats={**res.stats, "auto_method": "kamis"})
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
        # CHILS runs past its limit by its set-up (measured ~0.15 s at 10^4 and ~0.25 s at 10^5
        # vertices under load), and the CSR costs ~0.8 s at 10^6 edges: both are kept back
        m = int(problem.all_edges().shape[0])
        overhead = CHILS_SETUP_S + CHILS_SETUP_S_PER_EDGE * m
        problem.csr()
        budget = time_limit_s - (time.perf_counter() - t0) - opts["safety_s"] - overhead
        if budget < 0.02:
            from .greedy import fallback_selection

            sel, rule = fallback_selection(problem)
            return make_result(problem, sel, proven_optimal=False,
                               solve_time_s=time.perf_counter() - t0, backend=self.name,
                               stats={"auto_method": f"greedy ({rule}): no time left for CHILS"})
        res = self._chils.solve(problem, time_limit_s=budget, seed=seed, options=chils_opts)
        return make_result(problem, res.selected, proven_optimal=res.proven_optimal,
                           solve_time_s=time.perf_counter() - t0, backend=self.name,
                           stats={**res.stats, "auto_method": "chils"})
