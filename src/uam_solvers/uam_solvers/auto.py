"""The ``auto`` backend: exact where a proof is affordable, CHILS where it is not.

The outer layers of the default pipeline (Reduce, ComponentSplit) pass every graph through;
``auto`` chooses by size and structure itself:

* up to ``bb_max_vertices`` (64): the exact clique branch and bound of
  :mod:`uam_solvers.cliquebb` (Python-int bitsets, one branch per request; ``solve()`` runs it
  straight from clean arrays). Measured: 0.6 ms median end to end on the 5-50 vertex corpus
  against 1.6 ms for KaMIS called directly (BENCHMARKS.md). Past its node limit (~0.1 s),
  KaMIS with the whole limit (it returned within ~50 ms on every such graph measured).
* up to ``kamis_max_vertices`` (2,000) unless the conflict graph is dense (mean degree, group
  cliques included, above ``kamis_max_degree`` = 32; :func:`conflict_degree`): KaMIS
  branch-and-reduce on the whole graph first (it reduces and splits faster than the Python
  layers; a denser graph too when it is clustered like the planner's, :func:`triangle_ratio`
  >= ``kamis_min_triangle_ratio`` = 0.5 and >= twice the edge density, up to 150,000 conflict
  pairs: the layered runs' graphs of 250-1,750 vertices have mean degree 35-90 and KaMIS proves
  every one, in 1-700 ms; such a graph gets ``kamis_clustered_fraction`` = 0.85 of the limit,
  and KaMIS's best set is kept when the split below finds no better); the others
  get ``kamis_fraction`` (0.2) of the limit, at most ``kamis_max_share_s`` (1 s); a return before 0.9 of that share is its completed search, a proof, returned at once. The
  groups do not enter the choice (the earlier "interacting partners" score rose with
  the groups and kept KaMIS from graphs it proves in 1-2 ms). Denser graphs are kept from it
  because KaMIS overran even a 0.05 s limit on them (1-2 s at mean degree 40-44, past 8 s at
  100-150) and it holds the GIL; :func:`uam_solvers.solve` (a forked child),
  :func:`uam_solvers.solve_bounded` and the solve service bound any such overrun by a kill.
* CP-SAT on the whole graph (the groups as at-most-one, no greedy hint) with
  ``cpsat_fraction`` (0.9) of the time left, when KaMIS did not prove it and the graph is a
  union of large cliques by structure (:meth:`AutoBackend._cpsat_suits`: the groups' clique
  cover has >= ``cpsat_min_clique_cover`` = 8 vertices per clique, the triangle ratio is >=
  0.25 and twice the edge density, at most 200,000 conflict pairs): the planner's
  rolling-horizon graphs (one request's candidates over ten epochs), on which KaMIS
  runs to its limit and CP-SAT proves in 0.1-0.5 s CPU. On such graphs KaMIS first gets only a
  probe (``kamis_probe_fraction`` 0.01 of the limit, at least 0.05 s; with the tie-break on,
  the tie-break's budget, 3 x that, at most a quarter of the limit: see below). Above 2,000 vertices this
  comes before LearnAndReduce. The paper-shaped, stress and planner-shaped synthetic graphs
  (5 candidates per request) never take it.
* otherwise, up to 2,000 vertices: auto's own ``Reduce(ComponentSplit(...))`` (exact
  reductions up to 256 vertices, connected components) and per component: branch and bound,
  KaMIS up to 64 vertices, CP-SAT up to ``exact_max_vertices`` (200; it honours its limit and
  proves optimality for the integer-scaled weights, CHILS gets the rest of the share when it
  has not proven within ``exact_fraction``), CHILS above.
* above 2,000 vertices: chszlablib's LearnAndReduce exact kernelisation, first a probe with
  ``lr_probe_fraction`` (0.01) of the limit: when it removed less than ``lr_min_probe_removed``
  (10 %) of the vertices, CHILS gets the whole graph and the rest of the limit at once (
  the 10,000-vertex stress graph loses 0.6-2.4 % in the probe and 4 % in a full 0.2 s
  kernelisation, which took 0.3-0.43 s under load); otherwise LearnAndReduce goes on with the
  probe's kernel up to ``lr_fraction`` (0.2) of the limit, then KaMIS branch-and-reduce on a
  kernel of at most ``kamis_max_vertices`` and mean degree ``kamis_max_degree`` with its share
  (a completed search proves the optimum), CHILS with the rest on the kernel when it holds at
  most ``lr_max_kernel_fraction`` (25 %) of the vertices, else on the whole graph (proven when
  the kernel is empty: planner-shaped 10,000 vertices in 0.13-0.2 s).

Tied optima: every path is deterministic for its seed, but which one proves first
depends on the machine's speed (KaMIS's share is wall time), and tied optima differ between
them. So when KaMIS was stopped by its share and CP-SAT or the split then proved the optimum,
KaMIS runs again with at most ``tie_break_factor`` (3) times that share (at least
``tie_break_min_s`` = 0.05 s, at most the time left) and its completed search's set is the
answer, the set a faster machine returns (:meth:`AutoBackend._canonical`). So the proven set
does not depend on the speed as long as KaMIS's search fits in that re-run; beyond it the first
proof's set is returned with ``stats["tie_break"] = "kamis unfinished"``. Nothing is added when
KaMIS proves first or nothing is proven. Limits, measured: KaMIS's completed set can depend on
the limit it is given (it spends ~1 % of the limit in a time-bounded local search: one of 269
comparisons over limits of 0.05-60 s differed, 10 s against 30 s on a 671-vertex corpus graph);
on the horizon graphs, where KaMIS never finishes, the re-run cost 0.13-0.17 s of CPU
(3 x the 0.05 s probe). So on the graphs that go to CP-SAT (``_cpsat_suits``) the probe is
given that budget up front (at most a quarter of the limit): the same canonical
set (KaMIS's, whenever it completes within the budget), without the re-run: a graph KaMIS
proves in 0.05-0.15 s is answered by KaMIS alone (the layered corpus's 671- and 1,274-vertex
graphs: 55-70 ms; before, probe + CP-SAT + re-run, 2.4-3.8x KaMIS's time), and one it does not
prove pays the budget once, not probe + budget. Above 2,000 vertices (LearnAndReduce) this
is not done.

``proven_optimal`` is True only when the branch and bound completed, KaMIS finished, CP-SAT
reported OPTIMAL on the whole graph or for every component, or LearnAndReduce left nothing or a kernel KaMIS finished
(checked: the lifted set's integer weight is the reductions' offset plus the kernel optimum).
"""
from __future__ import annotations

import math
import time
from typing import Any, Mapping

import numpy as np

from .base import Backend, MwisProblem, MwisResult, make_result, sorted_unique
from .cliquebb import (SMALL_MAX_COVER, SMALL_MAX_VERTICES, clique_branch_and_bound,
                       clique_cover_size)
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


#: KaMIS gets the whole graph first up to this mean degree (see :func:`conflict_degree`)
KAMIS_MAX_DEGREE = 32.0

#: up to this size KaMIS gets the whole graph or component with the whole limit (it returned
#: within ~50 ms on every such graph measured), after the clique branch and bound
SMALL_KAMIS_VERTICES = 64


def interacting_partners(problem: MwisProblem) -> float:
    """Mean number of other requests a request conflicts with (a vertex outside every group
    counts as a request of its own). A description of the instance only: ``auto`` no longer
    routes by it, because with the groups given the same graph scores higher (10.7-11.7 against
    6.5-7.0 without them on paper-shaped graphs of 500 vertices), which kept KaMIS from graphs
    it proves in milliseconds. O(n + m)."""
    n = problem.n
    gid = np.arange(n, dtype=np.int64) + len(problem.groups)
    for i, g in enumerate(problem.groups):
        gid[g] = i
    nreq = int(sorted_unique(gid).size)
    e = problem.edges
    a, b = gid[e[:, 0]], gid[e[:, 1]]
    cross = a != b
    if not cross.any():
        return 0.0
    a, b = a[cross], b[cross]
    nid = n + len(problem.groups)
    pairs = int(sorted_unique(np.minimum(a, b) * nid + np.maximum(a, b)).size)
    return 2.0 * pairs / max(nreq, 1)


def conflict_degree(problem: MwisProblem) -> float:
    """Mean degree of the full conflict graph (listed edges plus every pair inside a group):
    what decides whether KaMIS gets the whole graph first. The groups are a hint about the
    same graph, so they cannot change it: the planner lists its group cliques among the edges,
    and a group whose pairs are not listed adds exactly those pairs to the graph. Measured with
    a 0.05 s limit, KaMIS returned within 0.14 s on G(n, p) of mean degree <= 30 (n = 100-2,000)
    and overran to 1-2 s at 40-44 (paper_instance(30), G(150, 0.3)) and past 8 s at 100-150.
    O(1) once ``all_edges`` is built (the CSR every backend needs)."""
    return 2.0 * problem.all_edges().shape[0] / max(problem.n, 1)


#: a conflict graph denser than kamis_max_degree still goes to KaMIS first when at least this
#: share of its two-paths close into triangles (:func:`triangle_ratio`) and that share is at
#: least KAMIS_MIN_TRIANGLE_EXCESS times its edge density (in G(n, p) both are p): measured
#: 0.59-0.99 (7-20x the density) on the planner graphs of the layered Singapore and city runs
#: above mean degree 32 (KaMIS direct proved every one, in 0.5-80 ms on Singapore's), against
#: 0.10-0.50 (1.0-1.6x) on the G(n, p), paper_instance and large_instance graphs KaMIS
#: overran its limit on (0.5-160 s with a 0.05 s limit)
KAMIS_MIN_TRIANGLE_RATIO = 0.5
KAMIS_MIN_TRIANGLE_EXCESS = 2.0
#: ... and when it has at most this many conflict pairs: the planner graphs above have at most
#: 67,000 (1,673 vertices); on K1000 with pendants (500,500 pairs, ratio 0.998) KaMIS needed
#: 0.24-0.9 s and under load the rest of a 1 s limit no longer sufficed (killed at 1.37 s)
KAMIS_CLUSTERED_MAX_PAIRS = 150_000
#: two-paths :func:`triangle_ratio` samples (standard error at most 0.008)
TRIANGLE_SAMPLES = 4096
#: the route's first estimate (:func:`gate_triangle_ratio`) draws this many (standard error at
#: most 0.016) and is drawn again with TRIANGLE_SAMPLES only when it lies within
#: TRIANGLE_CLOSE_SE standard errors of a threshold the route compares it with: on the dense
#: corpus graphs (city r25, 360-485 vertices, mean degree 25-39, ratio 0.88-0.98) the 4,096 took
#: 0.4-0.7 ms of auto's ~2 ms, 1,024 0.14-0.27 ms
TRIANGLE_FIRST_SAMPLES = 1024
TRIANGLE_CLOSE_SE = 4.0
#: CP-SAT on the whole graph after KaMIS did not prove it, for graphs that are unions of
#: cliques (rolling-horizon graphs of the planner: 1,100-3,600 vertices, 85-100
#: requests whose 20-90 candidates each span ten epochs, triangle ratio 0.31-0.60 at 10-30x the
#: edge density; KaMIS branch-and-reduce ran to its limit on every one, CP-SAT with the groups
#: as at-most-one proved them in 0.1-0.5 s CPU, 1.3-2.3 s wall at load 15). CP-SAT also proved
#: every layered-corpus graph of 250-1,750 vertices (0.06-1.2 s wall at load 15) where KaMIS
#: needed 0.001-2.4 s, so KaMIS first gets only a probe on these graphs.
CPSAT_FRACTION = 0.9
CPSAT_MIN_TRIANGLE_RATIO = 0.25
CPSAT_MAX_PAIRS = 200_000
CPSAT_MIN_CLIQUE_COVER = 8.0
#: CPU seconds per conflict pair of building the CP-SAT model in Python (measured 2.7 us on
#: 27,000 uncovered pairs): CP-SAT is skipped when building would take more than a quarter of
#: its budget (at load 20 a 145,000-pair model took ~3 s to build and load, and CP-SAT overran a
#: 3.6 s budget to 6.8 s without a solution)
CPSAT_BUILD_S_PER_PAIR = 3e-6
CPSAT_MAX_BUILD_SHARE = 0.25
KAMIS_PROBE_FRACTION = 0.01
KAMIS_PROBE_MIN_S = 0.05
#: the probe is given the tie-break's re-run budget (tie_break_factor x the probe above, at
#: least tie_break_min_s: 0.15 s at a 1 s limit) up front, but at most this share of the limit
KAMIS_PROBE_MAX_SHARE = 0.25
#: the canonical tie-break (AutoBackend._canonical): when KaMIS's first share ran
#: out and CP-SAT or the split proved the optimum, KaMIS runs again with at most this many
#: times that share (at least TIE_BREAK_MIN_S, at most the time left): its completed search is
#: the canonical set. A CP-SAT re-solve maximising a tie key with the objective fixed was
#: measured instead and is not cheap: 6-600 ms at 100-250 vertices against KaMIS's 3-50 ms,
#: unproven in 5 s on 3 of 6 graphs of 500 vertices (grouped_random_instance, load ~12)
TIE_BREAK_FACTOR = 3.0
TIE_BREAK_MIN_S = 0.05
#: integer weight of the heaviest vertex for LearnAndReduce (see learn_and_reduce_kernel)
LR_RESOLUTION = 10**6


def triangle_ratio(problem: MwisProblem, samples: int = TRIANGLE_SAMPLES) -> float:
    """Share of the two-paths a-v-b of the full conflict graph (groups included, so the groups
    change nothing) whose ends a, b conflict too (the transitivity; G(n, p): about p). The
    planner's graphs are unions of cliques (a request's candidates, and the candidates of
    several requests that use one corridor segment at one time) and score 0.59-0.99; random
    graphs of the same density, on which KaMIS overruns its limit, 0.1-0.5 (K1000 with
    pendants, which KaMIS proves, 0.998). Estimated on ``samples`` two-paths drawn uniformly
    with a fixed seed (deterministic). O(n + m + samples log m)."""
    n = problem.n
    indptr, indices = problem.csr()
    deg = np.diff(indptr)
    wv = deg.astype(np.float64) * (deg - 1)
    total = float(wv.sum())
    if n < 3 or total <= 0:
        return 0.0
    u1, u2, u3 = _triangle_draws(samples)
    v = np.searchsorted(np.cumsum(wv), u1 * total, side="right")  # ascending, as u1
    v = np.minimum(v, n - 1)
    d = deg[v]
    i = (u2 * d).astype(np.int64)
    j = (u3 * (d - 1)).astype(np.int64)
    j += j >= i
    start = indptr[v]
    a = indices[start + i]
    b = indices[start + j]
    # a pair conflicts when its key u * n + v (u < v) is among the conflict pairs' sorted keys
    # (problem.edge_keys(), cached: half the CSR's entries, nothing rebuilt per call)
    q = np.minimum(a, b).astype(np.int64) * n + np.maximum(a, b)
    keys = problem.edge_keys()
    # the count does not depend on the queries' order; sorted, the binary searches walk the
    # keys in order (0.35-0.4 -> ~0.13 ms of the 1 ms this took at 500-1,000 vertices,
    # as much as KaMIS needs to prove such a graph)
    q.sort()
    pos = np.minimum(np.searchsorted(keys, q), keys.size - 1)
    return float(np.count_nonzero(keys[pos] == q)) / samples


#: the uniform draws of :func:`triangle_ratio` per sample count, from default_rng(0): the same
#: numbers every call, drawn once (a new generator and its draws cost ~40 us a call)
_TRIANGLE_DRAWS: dict = {}


def _triangle_draws(samples: int) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """The three uniform draws of ``samples`` two-paths (vertex, first and second neighbour),
    reordered together so that the first ascends: the same two-paths, the count does not
    depend on their order, and the binary search over the vertices runs ~3x faster on sorted
    queries."""
    draws = _TRIANGLE_DRAWS.get(samples)
    if draws is None:
        rng = np.random.default_rng(0)
        draws = tuple(rng.random(samples) for _ in range(3))
        order = np.argsort(draws[0], kind="stable")
        draws = tuple(x[order] for x in draws)
        for x in draws:
            x.setflags(write=False)
        if len(_TRIANGLE_DRAWS) < 16:
            _TRIANGLE_DRAWS[samples] = draws
    return draws


def gate_triangle_ratio(problem: MwisProblem, thresholds) -> float:
    """:func:`triangle_ratio` for a comparison with each of ``thresholds``: from
    TRIANGLE_FIRST_SAMPLES two-paths, or from TRIANGLE_SAMPLES when the first estimate is within
    TRIANGLE_CLOSE_SE standard errors (binomial, p clipped to [0.05, 0.95]) of a threshold.
    Deterministic (fixed seeds)."""
    tri = triangle_ratio(problem, TRIANGLE_FIRST_SAMPLES)
    p = min(max(tri, 0.05), 0.95)
    se = math.sqrt(p * (1.0 - p) / TRIANGLE_FIRST_SAMPLES)
    if any(abs(tri - float(t)) <= TRIANGLE_CLOSE_SE * se for t in thresholds):
        tri = triangle_ratio(problem, TRIANGLE_SAMPLES)
    return tri


class LrKernel:
    """A LearnAndReduce kernel in exact integer weights (see :func:`learn_and_reduce`).

    ``indptr``, ``indices``: the kernel's CSR; ``int_weights``: its integer weights (in the
    units of the input's ``int_weights``; folded vertices can exceed the input's largest);
    ``offset``: the integer weight the reductions fixed, so that for any kernel set K the lifted
    set L has ``input_int_weights[L].sum() == offset + int_weights[K].sum()`` (an optimum of the
    kernel lifts to an optimum); ``lift(kernel_selection) -> selection`` of the input."""

    __slots__ = ("indptr", "indices", "int_weights", "offset", "lift", "n")

    def __init__(self, indptr, indices, int_weights, offset, lift):
        self.indptr, self.indices, self.int_weights = indptr, indices, int_weights
        self.offset, self.lift = int(offset), lift
        self.n = int(int_weights.size)

    def problem(self, scale: float) -> MwisProblem:
        """The kernel as an MwisProblem in the input's float units (``int_weights / scale``)."""
        rows = np.repeat(np.arange(self.n, dtype=np.int64), np.diff(self.indptr))
        keep = rows < self.indices
        edges = np.stack([rows[keep], self.indices[keep]], axis=1)
        return MwisProblem.from_arrays(self.int_weights.astype(np.float64) / scale, edges)


def learn_and_reduce(indptr: np.ndarray, indices: np.ndarray, int_weights: np.ndarray,
                     time_limit_s: float, seed: int) -> LrKernel | None:
    """chszlablib's LearnAndReduce exact kernelisation (config ``cyclic_fast``, GNN filter
    ``initial_tight``) of the graph ``(indptr, indices)`` with the integer weights
    ``int_weights`` within ``time_limit_s`` [s] (it overran that by 0.05-0.2 s on 10,000
    vertices under load). The integers are taken as they are, so a kernel can be reduced again
    (``learn_and_reduce(k.indptr, k.indices, k.int_weights, ...)``) with no rounding. Returns
    an :class:`LrKernel`, or None when LearnAndReduce is not installed."""
    try:
        import importlib.resources

        from chszlablib._learnandreduce import LearnAndReduceKernel
    except ImportError:
        return None
    models = str(importlib.resources.files("chszlablib").joinpath("models")) + "/"
    lr = LearnAndReduceKernel(np.asarray(indptr).astype(np.uint32),
                              np.asarray(indices).astype(np.uint32),
                              np.asarray(int_weights).astype(np.uint64),
                              "cyclic_fast", "initial_tight", max(float(time_limit_s), 1e-3),
                              int(seed) % (2**31), models)
    kxadj, kadj, kw, offset, kn = lr.kernelize()
    kn = int(kn)
    if kn:
        kxadj = np.asarray(kxadj, dtype=np.int64)
        kadj = np.asarray(kadj, dtype=np.int64)
        kw = np.asarray(kw, dtype=np.int64)
    else:
        kxadj, kadj, kw = np.zeros(1, dtype=np.int64), np.zeros(0, dtype=np.int64), \
            np.zeros(0, dtype=np.int64)

    lifted = []

    def lift(kernel_selection: np.ndarray) -> np.ndarray:
        # lift_solution undoes the reductions inside the kernelizer: a second call on the same
        # object worked on an undone graph and crashed the process (SIGSEGV, measured), so it
        # is refused
        if lifted:
            raise RuntimeError("learn_and_reduce: a kernel can be lifted only once")
        lifted.append(True)
        _, verts = lr.lift_solution(np.asarray(kernel_selection, dtype=np.int32))
        return np.asarray(verts, dtype=np.int64)

    return LrKernel(kxadj, kadj, kw, int(offset), lift)


def reduce_again(first: LrKernel, time_limit_s: float, seed: int) -> LrKernel:
    """``first`` reduced further by LearnAndReduce within ``time_limit_s`` [s], composed so that
    the result lifts to the original graph and its offset counts both steps' fixed weight."""
    second = learn_and_reduce(first.indptr, first.indices, first.int_weights, time_limit_s, seed)
    lift1, lift2 = first.lift, second.lift
    return LrKernel(second.indptr, second.indices, second.int_weights,
                    first.offset + second.offset, lambda sel: lift1(lift2(sel)))


def learn_and_reduce_kernel(problem: MwisProblem, time_limit_s: float, seed: int):
    """:func:`learn_and_reduce` of ``problem`` with its weights rounded to max(w) / 10^6.

    Returns ``(kernel, lift, removed)``: the kernel as an MwisProblem (weights in the units of
    ``problem.weights``), ``lift(kernel_selection) -> selection`` of ``problem`` and the number
    of vertices the reductions removed; None when LearnAndReduce is not installed. The
    reductions are exact: an optimum of the kernel lifts to an optimum.
    """
    from .base import integer_weights

    # 10^6 as for CHILS: with 10^9 LearnAndReduce returned an empty kernel whose lifted set
    # was 6.7 % below CHILS's on a 10,500-vertex city instance (an overflow inside, measured)
    wi, scale = integer_weights(problem.weights, LR_RESOLUTION)
    ip, ix = problem.csr()
    k = learn_and_reduce(ip, ix, wi, time_limit_s, seed)
    if k is None:
        return None
    return k.problem(scale), k.lift, problem.n - k.n


def bb_node_limit(time_limit_s: float, cap: int = BB_NODE_LIMIT) -> int:
    """Search nodes the clique branch and bound may visit within ``time_limit_s`` [s]."""
    return max(1, min(int(cap), int(time_limit_s * BB_NODES_PER_S)))


class AutoBackend(Backend):
    """KaMIS on small graphs, CP-SAT on medium kernels (both prove optimality), CHILS above."""

    name = "auto"
    description = ("exact reductions + component split, CP-SAT on kernels up to 200 vertices "
                   "(proves optimality), CHILS above")
    reduces_itself = True
    #: the outer Reduce and ComponentSplit layers pass every graph through: auto tries KaMIS
    #: on the whole graph first (it reduces and splits faster than the Python layers) and
    #: splits itself (``self._parts``) only when that gives no proof
    reduce_min_vertices = split_min_vertices = 1 << 62
    split_max_vertices = 1 << 62
    #: up to this size auto's own split runs (exact reductions up to 256 vertices, components,
    #: each by :meth:`_solve_part`); larger graphs: LearnAndReduce + CHILS (:meth:`_solve_large`)
    split_max_vertices_parts = 2000
    #: in-process in the solve service up to this size (branch and bound / KaMIS: milliseconds)
    inline_max_vertices = 64
    #: up to 2,000 vertices the first step is KaMIS, which holds the GIL (the guard thread
    #: could not abandon it), then CP-SAT and the branch and bound, which honour their limits:
    #: the hand-off to the guard thread (~1 ms here under load) is skipped
    thread_inline_max_vertices = 2000
    options_spec = {
        "bb_max_vertices": Option("bb_max_vertices", "int", SMALL_MAX_VERTICES, "graphs up to "
                                  "this size try the exact clique branch and bound first",
                                  lo=0, hi=1000),
        "bb_max_cover": Option("bb_max_cover", "int", SMALL_MAX_COVER, "the clique branch "
                               "and bound is tried only when the groups' clique cover (a vertex "
                               "outside every group counted as one) has at most this many "
                               "cliques (a graph given without groups: its vertices; 40 of them "
                               "took the search past its node limit, 70 ms, against 0.1 ms for "
                               "KaMIS)", lo=0, hi=10**6),
        "bb_node_limit": Option("bb_node_limit", "int", BB_NODE_LIMIT, "search nodes before the "
                                "clique branch and bound gives up (then KaMIS)", lo=1, hi=10**8),
        "kamis_max_vertices": Option("kamis_max_vertices", "int", 2000, "graphs up to this size "
                                     "go to KaMIS branch-and-reduce whole first (when their "
                                     "graph is not dense, see kamis_max_degree)",
                                     lo=0, hi=100_000),
        "kamis_fraction": Option("kamis_fraction", "float", 0.2, "share of the limit KaMIS gets "
                                 "on a whole graph above 64 vertices (0: never)", lo=0.0, hi=1.0),
        "kamis_clustered_fraction": Option("kamis_clustered_fraction", "float", 0.85, "share "
                                           "of the limit KaMIS gets on a graph denser than "
                                           "kamis_max_degree that passed the triangle test "
                                           "(planner graphs: KaMIS proved every one measured, "
                                           "one of 966 vertices needed 0.5-0.7 s under load; "
                                           "its best set is kept when the rest finds worse)",
                                           lo=0.0, hi=1.0),
        "kamis_max_share_s": Option("kamis_max_share_s", "float", 1.0, "most time KaMIS gets on "
                                    "a whole graph above 64 vertices [s] (the planner's graphs "
                                    "took at most 0.7 s)", lo=0.0, hi=86_400.0),
        "kamis_max_degree": Option("kamis_max_degree", "float", KAMIS_MAX_DEGREE, "largest mean "
                                   "degree of the conflict graph (group cliques included, so "
                                   "the groups change nothing) for which KaMIS gets the whole "
                                   "graph first (denser random graphs made it overrun its "
                                   "limit); denser graphs get it too when their triangle ratio "
                                   "is at least kamis_min_triangle_ratio",
                                   lo=0.0, hi=1e9),
        "kamis_min_triangle_ratio": Option("kamis_min_triangle_ratio", "float",
                                           KAMIS_MIN_TRIANGLE_RATIO, "graphs denser than "
                                           "kamis_max_degree go to KaMIS whole first when this "
                                           "share of their two-paths closes into triangles, and "
                                           "twice their edge density (planner graphs: "
                                           "0.59-0.99; random graphs KaMIS overran on: 0.1-0.5; "
                                           "above 1: never)",
                                           lo=0.0, hi=2.0),
        "cpsat_fraction": Option("cpsat_fraction", "float", CPSAT_FRACTION, "share of the "
                                 "time left CP-SAT gets on the whole graph when KaMIS did not "
                                 "prove it and the graph is a union of cliques (triangle test "
                                 "cpsat_min_triangle_ratio; the planner's rolling-horizon graphs: "
                                 "KaMIS ran to its limit, CP-SAT with the groups as at-most-one "
                                 "proved them in 0.1-0.5 s CPU); 0: never", lo=0.0, hi=1.0),
        "cpsat_min_triangle_ratio": Option("cpsat_min_triangle_ratio", "float",
                                           CPSAT_MIN_TRIANGLE_RATIO, "graphs above 64 vertices "
                                           "whose triangle ratio is at least this and twice "
                                           "their edge density go to CP-SAT whole when KaMIS did "
                                           "not prove them (horizon graphs 0.31-0.60, layered "
                                           "0.59-0.99; G(n, p): about p, at 1x the density; "
                                           "above 1: never)", lo=0.0, hi=2.0),
        "cpsat_min_clique_cover": Option("cpsat_min_clique_cover", "float",
                                         CPSAT_MIN_CLIQUE_COVER, "least mean size of the "
                                         "cliques of the groups' clique cover (vertices per "
                                         "group, a vertex outside every group counted as one) "
                                         "for CP-SAT on the whole graph", lo=0.0, hi=1e9),
        "cpsat_max_pairs": Option("cpsat_max_pairs", "int", CPSAT_MAX_PAIRS, "most conflict "
                                  "pairs of a graph CP-SAT gets whole (its model is built in "
                                  "Python, ~3 us per pair, and that cannot be interrupted)",
                                  lo=0, hi=10**8),
        "kamis_probe_fraction": Option("kamis_probe_fraction", "float", KAMIS_PROBE_FRACTION,
                                       "share of the limit KaMIS gets first when CP-SAT follows "
                                       "(a clique-structured graph, see cpsat_min_triangle_"
                                       "ratio), at least kamis_probe_min_s (with tie_break "
                                       "on, tie_break_factor x that, at most a quarter of the "
                                       "limit, and no re-run after): KaMIS proves the "
                                       "layered runs' graphs in 1-70 ms, CP-SAT the rest", lo=0.0,
                                       hi=1.0),
        "kamis_probe_min_s": Option("kamis_probe_min_s", "float", KAMIS_PROBE_MIN_S, "least "
                                    "time of that first KaMIS probe [s]", lo=0.0, hi=86_400.0),
        "exact_max_vertices": Option("exact_max_vertices", "int", 200, "largest component solved "
                                     "by CP-SAT (larger: CHILS)", lo=0, hi=100_000),
        "exact_fraction": Option("exact_fraction", "float", 0.5, "share of a kernel's time "
                                 "CP-SAT may use before CHILS gets the rest", lo=0.05, hi=1.0),
        "lr_fraction": Option("lr_fraction", "float", 0.2, "share of the limit LearnAndReduce's "
                              "kernelisation gets above 2,000 vertices (0: CHILS on the whole "
                              "graph)", lo=0.0, hi=0.9),
        "lr_probe_fraction": Option("lr_probe_fraction", "float", 0.01, "share of the limit "
                                    "of LearnAndReduce's first, short kernelisation above 2,000 "
                                    "vertices: when it removes less than lr_min_probe_removed "
                                    "of the graph, CHILS gets the whole graph and the rest of "
                                    "the limit at once (10,000-vertex stress graph: 0.6-2.4 % "
                                    "removed, planner-shaped: 62-66 %)", lo=0.0, hi=0.9),
        "lr_min_probe_removed": Option("lr_min_probe_removed", "float", 0.1, "share of the "
                                       "vertices the probe must remove for LearnAndReduce to "
                                       "go on (up to lr_fraction of the limit); a probe that "
                                       "removed none did not start and LearnAndReduce goes on",
                                       lo=0.0, hi=1.0),
        "lr_max_kernel_fraction": Option("lr_max_kernel_fraction", "float", 0.25, "largest "
                                         "kernel (share of the vertices) CHILS gets instead of "
                                         "the whole graph", lo=0.0, hi=1.0),
        "tie_break": Option("tie_break", "bool", True, "canonical set among tied optima: "
                            "when KaMIS was stopped by its share and another path proved the "
                            "optimum, KaMIS runs again (tie_break_factor) and its completed "
                            "search's set is returned, the set a faster machine gets", ),
        "tie_break_factor": Option("tie_break_factor", "float", TIE_BREAK_FACTOR, "that KaMIS "
                                   "re-run gets at most this many times KaMIS's first share "
                                   "(at least tie_break_min_s, at most the time left)",
                                   lo=0.0, hi=1e6),
        "tie_break_min_s": Option("tie_break_min_s", "float", TIE_BREAK_MIN_S, "least time of "
                                  "that KaMIS re-run [s] (capped by the time left)",
                                  lo=0.0, hi=86_400.0),
        "num_concurrent": Option("num_concurrent", "int", 1, "CHILS concurrent searches",
                                 lo=1, hi=64),
        "safety_s": Option("safety_s", "float", 0.05, "time kept back from CHILS's limit for "
                           "lifting and checking the answer [s]", lo=0.0, hi=10.0),
    }

    def __init__(self, _parts: bool = True) -> None:
        from .chszla import ChilsBackend, KamisBackend
        from .cpsat import CpSatBackend

        self._exact = CpSatBackend()
        self._chils = ChilsBackend()
        self._kamis = KamisBackend()
        self._with_parts = _parts
        self._parts_pipeline = None

    @property
    def _parts(self):
        """auto's own ``Reduce(ComponentSplit(...))`` (None inside it), built on first use: the
        registry makes a fresh backend per solve and most solves never need it (KaMIS or the
        branch and bound proves them), and building it cost ~0.1 ms of a 0.5 ms solve."""
        if not self._with_parts:
            return None
        if self._parts_pipeline is None:
            from .layers import ComponentSplit, Reduce

            self._parts_pipeline = Reduce(ComponentSplit(_AutoPart()))
        return self._parts_pipeline

    def available(self) -> tuple[bool, str]:
        ok, why = self._exact.available()
        if not ok:
            return ok, why
        return self._chils.available()

    def warm_up(self) -> None:
        """The first-call costs of every path: CP-SAT, KaMIS and CHILS (a tiny solve each)
        and LearnAndReduce's library and models (0.4-0.75 s of the first solve above 2,000
        vertices under load)."""
        if not self.available()[0]:
            return
        for part in (self._exact, self._kamis, self._chils):
            part.warm_up()
        ip, ix = MwisProblem.from_arrays([1.0, 2.0, 1.5, 1.0], [[0, 1], [1, 2], [2, 3]]).csr()
        learn_and_reduce(ip, ix, np.array([2, 4, 3, 2]), 0.01, 0)

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        t0 = time.perf_counter()
        opts = self.validate_options(options)
        n = problem.n
        if n == 0:
            return make_result(problem, [], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        if n <= opts["bb_max_vertices"] and \
                clique_cover_size(n, problem.groups) <= opts["bb_max_cover"]:
            res = self._solve_bb(problem, time_limit_s, opts, t0)
            if res is not None:
                return res
        if n <= SMALL_KAMIS_VERTICES:
            return self._solve_part(problem, time_limit_s, seed, opts, t0)
        if self._parts is None:  # a component handed over by the split below
            return self._solve_part(problem, time_limit_s, seed, opts, t0)
        degree = conflict_degree(problem)
        pairs = int(problem.all_edges().shape[0])
        # share: KaMIS's first share on the whole graph (0: KaMIS did not run); tie_budget_s:
        # the tie-break's re-run budget (_tie_budget of that share)
        proven, incumbent, tri, share, tie_budget_s = self._kamis_first(
            problem, time_limit_s, seed, opts, t0, degree, pairs)
        if proven is not None:
            return proven
        if n <= self.split_max_vertices_parts:
            res = self._cpsat_whole(problem, time_limit_s, seed, opts, t0, tri, pairs)
            if res is not None and (res.proven_optimal or _little_left(time_limit_s, t0)):
                res = _better(res, incumbent)
                res.backend, res.solve_time_s = self.name, time.perf_counter() - t0
                return self._canonical(problem, res, share, time_limit_s, seed, opts, t0,
                                       tie_budget_s)
            incumbent = _better(incumbent, res)
            rest_s = max(time_limit_s - (time.perf_counter() - t0), 1e-3)
            # exact reductions and component split, each component by _solve_part
            res = self._parts.solve(problem, time_limit_s=rest_s, seed=seed, options=opts)
            if incumbent is not None and incumbent.objective > res.objective:
                res = make_result(problem, incumbent.selected, proven_optimal=False,
                                  solve_time_s=0.0, backend=self.name,
                                  stats={**incumbent.stats,
                                         "after": res.stats.get("auto_method", "")})
            res.solve_time_s = time.perf_counter() - t0
            return self._canonical(problem, res, share, time_limit_s, seed, opts, t0,
                                       tie_budget_s)
        return self._solve_large(problem, time_limit_s, seed, opts, t0)

    def _solve_bb(self, problem: MwisProblem, time_limit_s: float, opts: dict,
                  t0: float) -> MwisResult | None:
        """The proven answer of the exact branch and bound over the requests' cliques (no
        extension call), or None when it gave up past its node limit (KaMIS then takes over)."""
        node_limit = bb_node_limit(time_limit_s, opts["bb_node_limit"])
        sel, nodes = clique_branch_and_bound(problem, node_limit)
        if sel is None:
            return None
        return make_result(problem, sel, proven_optimal=True,
                           solve_time_s=time.perf_counter() - t0, backend=self.name,
                           stats={"auto_method": "clique-bb", "bb_nodes": nodes})

    def _kamis_gate(self, problem: MwisProblem, degree: float, pairs: int,
                    opts: dict) -> tuple[float | None, bool, bool]:
        """For a graph above ``kamis_max_degree`` with few enough pairs: whether it is
        clustered (a union of cliques by the triangle ratio, so KaMIS still gets it first) and
        whether CP-SAT suits it after KaMIS. Returns (triangle ratio, None when not sampled;
        clustered; CP-SAT next)."""
        n = problem.n
        tri = None
        clustered = False
        cpsat_next = False
        if degree > opts["kamis_max_degree"] and pairs <= max(KAMIS_CLUSTERED_MAX_PAIRS,
                                                               opts["cpsat_max_pairs"]):
            density = degree / max(n - 1, 1)
            tri = gate_triangle_ratio(problem, (opts["kamis_min_triangle_ratio"],
                                                opts["cpsat_min_triangle_ratio"],
                                                KAMIS_MIN_TRIANGLE_EXCESS * density))
            clustered = (opts["kamis_min_triangle_ratio"] <= 1.0
                         and pairs <= KAMIS_CLUSTERED_MAX_PAIRS
                         and tri >= opts["kamis_min_triangle_ratio"]
                         and tri >= KAMIS_MIN_TRIANGLE_EXCESS * density)
            cpsat_next = self._cpsat_suits(problem, tri, pairs, opts)
        return tri, clustered, cpsat_next

    def _kamis_share(self, time_limit_s: float, opts: dict, clustered: bool,
                     cpsat_next: bool) -> tuple[float, float]:
        """KaMIS's first share of the limit on the whole graph and the tie-break's re-run
        budget: a small share, at most kamis_max_share_s, a probe when CP-SAT follows."""
        fraction = opts["kamis_clustered_fraction" if clustered else "kamis_fraction"]
        cap = max(min(time_limit_s * fraction, opts["kamis_max_share_s"]), 1e-3)
        share = cap
        if cpsat_next:
            share = min(cap, max(time_limit_s * opts["kamis_probe_fraction"],
                                 opts["kamis_probe_min_s"]))
        tie_budget_s = self._tie_budget(share, opts)
        if cpsat_next and opts["tie_break"]:
            # the probe is given the tie-break's budget at once: the
            # re-run after a CP-SAT proof would spend it anyway, so the canonical set is
            # the same; a graph KaMIS proves within it (the layered corpus's 671 and
            # 1,274 vertices: 55-70 ms, past the 0.05 s probe) needs no CP-SAT and no
            # re-run, and one it does not (the horizon graphs) pays the budget once
            share = max(share, min(tie_budget_s, time_limit_s * KAMIS_PROBE_MAX_SHARE, cap))
        return share, tie_budget_s

    def _kamis_first(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                     t0: float, degree: float, pairs: int
                     ) -> tuple[MwisResult | None, MwisResult | None, float | None, float, float]:
        """KaMIS on the whole graph first, where it suits. Returns (its proven answer or None;
        its unproven answer kept as the incumbent or None; the triangle ratio or None; its
        share [s], 0 when it did not run; the tie-break's re-run budget [s])."""
        if not (problem.n <= opts["kamis_max_vertices"] and opts["kamis_fraction"] > 0):
            return None, None, None, 0.0, 0.0
        tri, clustered, cpsat_next = self._kamis_gate(problem, degree, pairs, opts)
        if not (degree <= opts["kamis_max_degree"] or clustered):
            return None, None, tri, 0.0, 0.0
        # what proves first: KaMIS branch-and-reduce on the whole graph (its exact
        # reductions are faster than the Python layers, and it splits itself) with a
        # small share of the limit, at most kamis_max_share_s (a probe when CP-SAT
        # follows); a return before 0.9 of the share is its completed search, a proof
        # (a search stopped by the limit runs to it, as for the kamis backend), returned
        # at once; otherwise CP-SAT (clique-structured graphs) and the split below
        # (CP-SAT per component, CHILS) get the rest of the limit
        share, tie_budget_s = self._kamis_share(time_limit_s, opts, clustered, cpsat_next)
        res = self._kamis.solve(problem, time_limit_s=share, seed=seed,
                                options={"finish_fraction": 0.9})
        if res.proven_optimal:
            # KaMIS's result on this same problem, already checked and its objective
            # recomputed by make_result: relabelled, not rebuilt (~10 us)
            res.backend, res.solve_time_s = self.name, time.perf_counter() - t0
            res.stats = {**res.stats, "auto_method": "kamis", "conflict_degree": degree,
                         **({} if tri is None else {"triangle_ratio": round(tri, 4)})}
            return res, None, tri, share, tie_budget_s
        incumbent = res  # KaMIS's best set when its share ran out: kept if better
        incumbent.stats = {**res.stats, "auto_method": "kamis (limit)"}
        return None, incumbent, tri, share, tie_budget_s

    @staticmethod
    def _tie_budget(share: float, opts: dict) -> float:
        """The most time the tie-break's KaMIS re-run gets after a first share of ``share`` s
        (before the time left caps it): ``tie_break_factor`` x ``share``, at least
        ``tie_break_min_s``."""
        return max(opts["tie_break_factor"] * share, opts["tie_break_min_s"])

    def _canonical(self, problem: MwisProblem, res: MwisResult, share: float,
                   time_limit_s: float, seed: int, opts: dict, t0: float,
                   tie_budget_s: float) -> MwisResult:
        """The canonical tie-break among proven optima: ``res`` was proven by CP-SAT
        or the split after KaMIS's first share (``share`` [s], 0: KaMIS did not run) ran out.
        On a faster machine KaMIS would have finished and answered, and tied optima differ
        between the paths, so KaMIS runs again on the same graph with the same seed, with at
        most ``tie_break_factor`` x ``share`` (at least ``tie_break_min_s``, at most the time
        left less ``safety_s``); when its search completes, its set is the answer (what the
        faster machine returns: KaMIS's completed search does not depend on its limit). So
        whenever KaMIS's search fits in that re-run the proven set does not depend on the
        machine's speed; beyond it ``res`` is returned with ``stats["tie_break"]`` =
        "kamis unfinished". Costs nothing when KaMIS proved first (the fast path) or nothing
        was proven."""
        if not (res.proven_optimal and share > 0 and opts["tie_break"]):
            return res
        left = time_limit_s - (time.perf_counter() - t0) - opts["safety_s"]
        if tie_budget_s <= share:  # the first share had the whole re-run budget: unfinished
            res.stats = {**res.stats, "tie_break": "kamis unfinished"}
            return res
        budget = min(left, tie_budget_s)
        if budget <= share:  # not even the first share again: it cannot finish
            res.stats = {**res.stats, "tie_break": "no time left"}
            return res
        k = self._kamis.solve(problem, time_limit_s=budget, seed=seed,
                              options={"finish_fraction": 0.9})
        if not k.proven_optimal:
            res.stats = {**res.stats, "tie_break": "kamis unfinished"}
            return res
        k.backend, k.solve_time_s = self.name, time.perf_counter() - t0
        k.stats = {**k.stats, "auto_method": "kamis", "tie_break": "kamis",
                   "proven_first_by": res.stats.get("auto_method", "")}
        return k

    def _cpsat_suits(self, problem: MwisProblem, tri: float | None, pairs: int,
                     opts: dict) -> bool:
        """Whether CP-SAT gets the whole graph when KaMIS did not prove it: above 64 vertices,
        at most ``cpsat_max_pairs`` conflict pairs, cliques of at least ``cpsat_min_clique_cover``
        vertices on average in the cover the groups give (CP-SAT's at-most-one constraints; the
        horizon graphs: 12-45, the layered runs' 5-70, the synthetic paper-shaped, stress and
        planner-shaped graphs 5: unchanged; without groups CP-SAT needed 1.5-5x longer on these
        graphs), and a union of cliques by structure (the triangle ratio of the full graph, groups included so they change nothing, at least
        ``cpsat_min_triangle_ratio`` and twice the edge density; G(n, p) scores 1x)."""
        if opts["cpsat_fraction"] <= 0 or problem.n <= SMALL_KAMIS_VERTICES \
                or pairs > opts["cpsat_max_pairs"] or opts["cpsat_min_triangle_ratio"] > 1.0:
            return False
        grouped = sum(int(g.size) for g in problem.groups)
        cover = len(problem.groups) + problem.n - grouped
        if problem.n < opts["cpsat_min_clique_cover"] * max(cover, 1):
            return False
        density = 2.0 * pairs / max(problem.n * (problem.n - 1), 1)
        if tri is None:
            tri = gate_triangle_ratio(problem, (opts["cpsat_min_triangle_ratio"],
                                                KAMIS_MIN_TRIANGLE_EXCESS * density))
        return tri >= opts["cpsat_min_triangle_ratio"] and tri >= KAMIS_MIN_TRIANGLE_EXCESS * density

    def _cpsat_whole(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                     t0: float, tri: float | None, pairs: int) -> MwisResult | None:
        """CP-SAT on the whole graph (the groups as at-most-one, no greedy hint: on the horizon
        graphs the hint's greedy cost 0.05-0.09 s CPU and the search was no faster with it) with
        ``cpsat_fraction`` of the time left, when :meth:`_cpsat_suits`; None otherwise. Its
        proof is the exact backend's (OPTIMAL, checked by ``integer_proof_holds``)."""
        if not self._cpsat_suits(problem, tri, pairs, opts):
            return None
        budget = (time_limit_s - (time.perf_counter() - t0)) * opts["cpsat_fraction"]
        if budget < 0.02 or pairs * CPSAT_BUILD_S_PER_PAIR > CPSAT_MAX_BUILD_SHARE * budget:
            return None
        res = self._exact.solve(problem, time_limit_s=budget, seed=seed,
                                options={"hint": False})
        return make_result(problem, res.selected, proven_optimal=res.proven_optimal,
                           solve_time_s=time.perf_counter() - t0, backend=self.name,
                           stats={**res.stats, "auto_method": "cpsat (whole graph)"})

    def _solve_part(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                    t0: float) -> MwisResult:
        """One graph or component: KaMIS up to 64 vertices, CP-SAT up to exact_max_vertices
        (CHILS after it when unproven), CHILS above."""
        n = problem.n
        chils_opts = {"num_concurrent": opts["num_concurrent"]}
        if n <= SMALL_KAMIS_VERTICES:
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
        return self._solve_chils(problem, time_limit_s, seed, opts, t0)

    def _solve_chils(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                     t0: float, method: str = "chils") -> MwisResult:
        """CHILS with the time left, its set-up and the CSR kept back; greedy when none is."""
        chils_opts = {"num_concurrent": opts["num_concurrent"]}
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
                           stats={**res.stats, "auto_method": method})

    def _solve_large(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                     t0: float) -> MwisResult:
        """Above split_max_vertices: CP-SAT on the whole graph first when it is a union of
        large cliques (:meth:`_cpsat_suits`: the planner's rolling-horizon graphs of 2,000-3,600
        vertices, where LearnAndReduce removed 10-25 % and left CHILS a kernel too large),
        returned when proven; otherwise :meth:`_solve_large_lr` with the time left, and the
        better of the two answers."""
        cp = self._cpsat_whole(problem, time_limit_s, seed, opts, t0, None,
                               int(problem.all_edges().shape[0]))
        if cp is not None and (cp.proven_optimal or _little_left(time_limit_s, t0)):
            return cp
        res = self._solve_large_lr(problem, time_limit_s, seed, opts, t0)
        if cp is not None and cp.objective > res.objective:
            cp.stats = {**cp.stats, "after": res.stats.get("auto_method", "")}
            cp.solve_time_s = time.perf_counter() - t0
            return cp
        return res

    def _solve_large_lr(self, problem: MwisProblem, time_limit_s: float, seed: int, opts: dict,
                        t0: float) -> MwisResult:
        """Above split_max_vertices: a short LearnAndReduce probe (``lr_probe_fraction`` of the
        limit); when it removed some but less than ``lr_min_probe_removed`` of the graph, CHILS
        on the whole graph with the rest of the limit (on the 10,000-vertex stress
        graph the full kernelisation took 0.3-0.43 s of a 1 s limit to remove 4 %); otherwise
        LearnAndReduce again on the probe's kernel up to ``lr_fraction`` of the limit, then
        KaMIS branch-and-reduce on a small sparse kernel (a completed search is a proof), CHILS
        on the kernel (or on the whole graph when the kernel keeps more than
        ``lr_max_kernel_fraction`` of it) with what is left. A proof (empty kernel, or KaMIS
        finished on the kernel) is claimed only when the lifted set's integer weight equals the
        reductions' offset plus the kernel's optimum and its own weights agree
        (:func:`uam_solvers.base.integer_proof_holds`)."""
        from .base import integer_proof_holds, integer_weights

        if opts["lr_fraction"] <= 0:
            return self._solve_chils(problem, time_limit_s, seed, opts, t0)
        wi, scale = integer_weights(problem.weights, LR_RESOLUTION)
        ip, ix = problem.csr()
        lr_share = time_limit_s * opts["lr_fraction"]
        probe_s = min(time_limit_s * opts["lr_probe_fraction"], lr_share)
        k = learn_and_reduce(ip, ix, wi, probe_s if probe_s > 0 else lr_share, seed)
        if k is None:
            return self._solve_chils(problem, time_limit_s, seed, opts, t0)
        stats = {"lr_probe_kernel_vertices": k.n}
        # a probe that removed nothing at all did not get past LearnAndReduce's set-up (a cold
        # process under load: 4 of 8 fresh runs on the planner-shaped 10,000-vertex graph,
        # which the full kernelisation empties): the kernelisation then goes on as without one
        if probe_s > 0 and problem.n > k.n > (1.0 - opts["lr_min_probe_removed"]) * problem.n:
            res = self._solve_chils(problem, time_limit_s, seed, opts, t0)
            res.stats = {**res.stats, **stats, "lr_kernel_vertices": k.n,
                         "lr_removed_vertices": problem.n - k.n}
            return res
        rest = lr_share - (time.perf_counter() - t0)
        if probe_s > 0 and k.n and rest > 1e-3:
            k = reduce_again(k, rest, seed)
        stats.update(lr_kernel_vertices=k.n, lr_removed_vertices=problem.n - k.n)
        if k.n == 0:
            sel = k.lift(np.zeros(0, dtype=np.int64))
            proven = integer_proof_holds(problem, sel, wi, scale, k.offset)
            return make_result(problem, sel, proven_optimal=proven,
                               solve_time_s=time.perf_counter() - t0, backend=self.name,
                               stats={**stats, "auto_method": "learn-and-reduce"})
        if k.n > opts["lr_max_kernel_fraction"] * problem.n:
            # little removed: CHILS on the whole graph did better than on such kernels (7,026-
            # vertex city graph, kernel 34 %: 0.096 % below the best known against 0.007 %)
            res = self._solve_chils(problem, time_limit_s, seed, opts, t0)
            res.stats = {**res.stats, **stats}
            return res
        kernel = k.problem(scale)
        # incumbent: KaMIS's kernel set when it did not finish (lifted once, at the end)
        proven_res, incumbent = self._kernel_kamis(problem, k, kernel, wi, scale, time_limit_s,
                                                   seed, opts, t0, stats)
        if proven_res is not None:
            return proven_res
        return self._kernel_chils(problem, k, kernel, incumbent, time_limit_s, seed, opts, t0,
                                  stats)

    def _kernel_kamis(self, problem: MwisProblem, k: LrKernel, kernel: MwisProblem,
                      wi: np.ndarray, scale: float, time_limit_s: float, seed: int, opts: dict,
                      t0: float, stats: dict) -> tuple[MwisResult | None, np.ndarray | None]:
        """KaMIS branch-and-reduce on a small sparse LearnAndReduce kernel. Returns (the lifted
        answer when its search completed, proven when the integer weights agree, else None;
        its independent kernel set when it did not complete, else None)."""
        from .base import integer_proof_holds

        if not (k.n <= opts["kamis_max_vertices"] and opts["kamis_fraction"] > 0
                and conflict_degree(kernel) <= opts["kamis_max_degree"]
                and int(k.int_weights.sum()) < 2**31):
            return None, None
        # the kernel's own integer weights (no second rounding), which KaMIS sums in 32 bits
        from chszlablib._kamis_wmis import branch_reduce

        share = max(min(time_limit_s * opts["kamis_fraction"], opts["kamis_max_share_s"]),
                    1e-3)
        tk = time.perf_counter()
        int_obj, verts = branch_reduce(k.indptr.astype(np.int32), k.indices.astype(np.int32),
                                       k.int_weights.astype(np.int32), share,
                                       int(seed) % (2**31))
        finished = time.perf_counter() - tk < 0.9 * share
        ksel = np.asarray(verts, dtype=np.int64)
        if not kernel.is_independent(ksel):
            return None, None
        if not finished:
            return None, ksel
        sel = k.lift(ksel)
        proven = integer_proof_holds(problem, sel, wi, scale, k.offset + int(int_obj))
        return make_result(problem, sel, proven_optimal=proven,
                           solve_time_s=time.perf_counter() - t0,
                           backend=self.name,
                           stats={**stats, "auto_method": "learn-and-reduce+kamis"}), None

    def _kernel_chils(self, problem: MwisProblem, k: LrKernel, kernel: MwisProblem,
                      incumbent: np.ndarray | None, time_limit_s: float, seed: int, opts: dict,
                      t0: float, stats: dict) -> MwisResult:
        """CHILS on the kernel with the time left; the better of its set and KaMIS's unfinished
        one (``incumbent``), lifted to ``problem`` (never claimed optimal)."""
        kres = self._solve_chils(kernel, time_limit_s, seed, opts, t0,
                                 method="learn-and-reduce+chils")
        ksel = np.asarray(kres.selected, dtype=np.int64)
        if incumbent is not None and int(k.int_weights[incumbent].sum()) > \
                int(k.int_weights[ksel].sum()):
            # the kernel's integer weights order the lifted sets exactly (same offset)
            ksel, kres.stats = incumbent, {**kres.stats,
                                           "auto_method": "learn-and-reduce+kamis (limit)"}
        sel = k.lift(ksel)
        return make_result(problem, sel, proven_optimal=False,
                           solve_time_s=time.perf_counter() - t0, backend=self.name,
                           stats={**kres.stats, **stats})


#: after an unproven whole-graph CP-SAT, the rest of the pipeline (split, LearnAndReduce,
#: CHILS: set-up 0.1-0.3 s under load) runs only when at least this much of the limit is left;
#: otherwise CP-SAT's best set is the answer (at load 22 the follow-up with ~0.5 s left ran the
#: in-process solve to 7.6 s of a 5 s limit)
CPSAT_MIN_FOLLOW_S = 0.5


def _little_left(time_limit_s: float, t0: float) -> bool:
    return time_limit_s - (time.perf_counter() - t0) < CPSAT_MIN_FOLLOW_S


def _better(a: MwisResult | None, b: MwisResult | None) -> MwisResult | None:
    """The one of two answers (either may be None) with the larger objective; ``a`` on a tie."""
    if b is None:
        return a
    if a is None or b.objective > a.objective:
        return b
    return a


class _AutoPart(AutoBackend):
    """``auto`` on one graph handed over by its own split: the per-component choice
    (:meth:`AutoBackend._solve_part`) behind the Reduce and ComponentSplit layers, which apply
    from 65 vertices (below, KaMIS on the whole graph is faster than they are)."""

    reduce_min_vertices = split_min_vertices = 65
    split_max_vertices = 2000

    def __init__(self) -> None:
        super().__init__(_parts=False)
