"""Exact MWIS of small conflict graphs by branch and bound over clique blocks (Python-int bitsets).

Why hand-written: at the 5-50 vertices of one paper-scale planning epoch, KaMIS called through
chszlablib took 2.5 ms median (up to ~50 ms on some 50-vertex graphs) and CP-SAT ~3.5 ms, while
the graph has at most ~10 requests of <= 5 candidates each. Branching per request (a clique:
at most one candidate is chosen) over bitsets held in Python ints proves those optima in a
fraction of a millisecond (BENCHMARKS.md), with no extension call.

The vertices are partitioned into cliques ("blocks"): each clique group (one request's
candidates) becomes a block (a vertex in several groups joins its first one), every other
vertex a block of its own. The search visits the blocks in a fixed order (most conflicted
first); at each it branches on every still available candidate (heaviest first), then on
taking none of them. The bound at a node is the value so far plus, for every block not yet
visited, its heaviest candidate still available (valid: at most one vertex per clique). Two
dominance rules cut branches without losing every optimum: a candidate whose conflicts with
the rest are a superset of a heavier tried candidate's is skipped, and a candidate conflicting
with nothing left ends the block's branching (lighter ones and "none" cannot do better).
Weights are compared as exact integers (every float64 is an integer multiple of a common power
of two), so "optimal" means optimal for the float weights themselves, not for a rounding.

Tie-breaking: among equal-weight optima, the first one found in this search order is kept (a
later solution replaces the incumbent only when strictly heavier). It is deterministic and the
same whether the graph comes as arrays (:func:`solve_small_arrays`) or as an MwisProblem
(:func:`clique_branch_and_bound`), but it is not the choice KaMIS or CP-SAT would make among
ties.
"""
from __future__ import annotations

import math
from typing import Any, Sequence

import numpy as np

from .base import MAX_TOTAL_WEIGHT, MwisProblem, MwisResult

__all__ = ["clique_branch_and_bound", "clique_cover_size", "exact_integer_weights",
           "solve_small_arrays", "SMALL_MAX_COVER", "SMALL_MAX_VERTICES"]

#: Largest graph :func:`solve_small_arrays` takes (the ``auto`` backend's default
#: ``bb_max_vertices``); larger ones go through the pipeline.
SMALL_MAX_VERTICES = 64
#: The search branches over the cliques of the cover the groups give (a vertex outside every
#: group is a clique of its own); above this many cliques it is not tried (the ``auto``
#: backend's default ``bb_max_cover``; KaMIS takes the graph). Measured on
#: grouped_random_instance graphs without their groups: 100-160 nodes (0.18 ms) at
#: 15 cliques, 400-500 (0.6 ms) at 20, 1,000-1,900 (2.5 ms) at 25, past the 20,000-node limit
#: (70 ms, then KaMIS) from 40; with the groups given, 13 cliques or fewer at 15-64 vertices,
#: 6-190 nodes. KaMIS direct needs 0.1 ms on those graphs.
SMALL_MAX_COVER = 16


def clique_cover_size(n: int, groups) -> int:
    """Cliques in the cover ``groups`` give a graph of ``n`` vertices: the groups, plus one for
    each vertex outside every group."""
    covered = set()
    for g in groups:
        covered.update(int(v) for v in g)
    return len(groups) + n - len(covered)


class _NodeLimit(Exception):
    """The search ran past its node limit."""


def exact_integer_weights(weights: Sequence[float]) -> list[int]:
    """Python ints proportional to ``weights`` (finite, >= 0) with no rounding at all.

    Every finite float64 is p / 2^q; multiplying by the largest 2^q makes all of them integers,
    so sums and comparisons of the results order subsets exactly as the real weights do.
    """
    ratios = [float(w).as_integer_ratio() for w in weights]
    den = max((d for _, d in ratios), default=1)
    return [p * (den // d) for p, d in ratios]


def _blocks(n: int, wint: list[int], us: list[int], vs: list[int], groups: list[list[int]],
            bit: list[int]) -> list[list[int]]:
    """The clique blocks in search order: each group's vertices not in an earlier group, then
    every other vertex alone; each block heaviest first, the most conflicted blocks first."""
    # closed neighbourhoods over the original indices: listed edges plus group cliques
    closed = bit[:]
    for u, v in zip(us, vs):
        closed[u] |= bit[v]
        closed[v] |= bit[u]
    owner = [-1] * n
    blocks: list[list[int]] = []
    for g in groups:
        gm = 0
        for v in g:
            gm |= bit[v]
        for v in g:
            closed[v] |= gm
        members = [v for v in g if owner[v] < 0]
        if members:
            for v in members:
                owner[v] = len(blocks)
            blocks.append(members)
    for v in range(n):
        if owner[v] < 0:
            blocks.append([v])
    deg = [c.bit_count() - 1 for c in closed]
    for b in blocks:
        b.sort(key=lambda v: (-wint[v], v))
    # Most conflicted blocks first: their choices decide most, so the bound bites early
    # (measured on 600 corpus graphs of 5-50 vertices: half the nodes of heaviest-first at
    # the 95th percentile, a third at the maximum).
    blocks.sort(key=lambda b: (-sum(deg[v] for v in b), b[0]))
    return blocks


def _search_bits(n: int, us: list[int], vs: list[int], groups: list[list[int]], bit: list[int],
                 blocks: list[list[int]]) -> tuple[list[int], list[int], list[int]]:
    """The search's bit order: (order, masks, cl) with bit i standing for vertex order[i],
    masks[j] the bits of block j and cl[i] the closed neighbourhood of bit i in that order."""
    # Bit i is vertex order[i]: blocks contiguous, each heaviest first, so the lowest set bit
    # of (block mask & available) is the block's heaviest available candidate.
    order = [v for b in blocks for v in b]
    pos = [0] * n
    for i, v in enumerate(order):
        pos[v] = i
    masks = []
    start = 0
    for b in blocks:
        masks.append(((1 << len(b)) - 1) << start)
        start += len(b)
    # the same closed neighbourhoods in the search's bit order, built again from the pairs
    # (cheaper than moving every set bit of ``closed``: ~45 of 117 us of set-up at
    # 50 vertices)
    pbit = [bit[p] for p in pos]
    cl = [bit[i] for i in range(n)]
    for u, v in zip(us, vs):
        cl[pos[u]] |= pbit[v]
        cl[pos[v]] |= pbit[u]
    for g in groups:
        gm = 0
        for v in g:
            gm |= pbit[v]
        for v in g:
            cl[pos[v]] |= gm
    return order, masks, cl


def _vertices(bits: int, order: list[int]) -> list[int]:
    """The sorted original vertices of a set of search bits."""
    sel = []
    while bits:
        low = bits & -bits
        sel.append(order[low.bit_length() - 1])
        bits ^= low
    sel.sort()
    return sel


def _search(n: int, wint: list[int], us: list[int], vs: list[int], groups: list[list[int]],
            node_limit: int) -> tuple[list[int] | None, int]:
    """The branch and bound on ``n`` vertices with exact integer weights ``wint``, conflict
    pairs ``(us[i], vs[i])`` (duplicates allowed) and clique groups (sorted, unique, size >= 2,
    in the caller's order). Returns (sorted optimum or None past ``node_limit``, nodes)."""
    bit = [1 << v for v in range(n)]
    blocks = _blocks(n, wint, us, vs, groups, bit)
    order, masks, cl = _search_bits(n, us, vs, groups, bit, blocks)
    w = [wint[v] for v in order]
    nblocks = len(blocks)
    best_val = -1
    best_set = 0
    nodes = 0

    def search(bi: int, avail: int, val: int, chosen: int) -> None:
        nonlocal best_val, best_set, nodes
        nodes += 1
        if nodes > node_limit:
            raise _NodeLimit
        ub = val
        for j in range(bi, nblocks):
            c = masks[j] & avail
            if c:
                ub += w[(c & -c).bit_length() - 1]
        if ub <= best_val:
            return
        while bi < nblocks and not masks[bi] & avail:
            bi += 1
        if bi == nblocks:
            best_val, best_set = val, chosen  # ub == val > best_val here
            return
        cand = masks[bi] & avail
        rest = avail & ~masks[bi]
        tried: list[int] = []
        while cand:
            low = cand & -cand
            i = low.bit_length() - 1
            cand ^= low
            ext = cl[i] & rest
            # a heavier (or equal) candidate already tried whose remaining conflicts are a
            # subset of this one's is at least as good in every completion
            if any(t & ext == t for t in tried):
                continue
            search(bi + 1, rest & ~ext, val + w[i], chosen | low)
            if not ext:
                return  # conflicts with nothing left: lighter candidates and "none" dominated
            tried.append(ext)
        search(bi + 1, rest, val, chosen)

    try:
        search(0, (1 << n) - 1, 0, 0)
    except _NodeLimit:
        return None, nodes
    return _vertices(best_set, order), nodes


def clique_branch_and_bound(problem: MwisProblem, node_limit: int = 20_000
                            ) -> tuple[list[int] | None, int]:
    """Maximum weight independent set of ``problem`` by branch and bound over clique blocks.

    Returns ``(selected, nodes)``: ``selected`` the sorted vertex indices of an optimum (proven:
    the search was complete), or None when the search needed more than ``node_limit`` nodes
    (nothing is claimed then; the caller solves another way); ``nodes`` the search nodes
    visited. Time O(nodes * blocks) at ~5 us per node; meant for graphs of up to ~100 vertices.
    """
    n = problem.n
    if n == 0:
        return [], 0
    e = problem.edges
    return _search(n, exact_integer_weights(problem.weights.tolist()), e[:, 0].tolist(),
                   e[:, 1].tolist(), [g.tolist() for g in problem.groups], node_limit)


def _int_list(values: Any, n: int) -> list[int] | None:
    """A group's vertices as a list of ints in [0, n), or None when the group is anything but
    a clean 1-D integer sequence (the full validation then names what is wrong)."""
    if isinstance(values, np.ndarray):
        if values.ndim != 1 or values.dtype.kind not in "iu":
            return None
        out = values.tolist()
    elif isinstance(values, (list, tuple)):
        out = list(values)
        if not all(type(x) is int for x in out):
            return None
    else:
        return None
    if out and (min(out) < 0 or max(out) >= n):
        return None
    return out


def solve_small_arrays(weights: Any, edges: Any, groups: Any, node_limit: int,
                       max_vertices: int = SMALL_MAX_VERTICES,
                       max_cover: int = SMALL_MAX_COVER) -> MwisResult | None:
    """The ``auto`` backend's answer for a small, clean graph straight from the arrays.

    This is the fast path of :func:`uam_solvers.solve` for the 5-50 vertex graphs of a planning
    epoch: it accepts only input the full validation (:meth:`MwisProblem.from_arrays`) accepts
    unchanged (float or integer ``weights`` (n,) finite, >= 0, n <= ``max_vertices``; integer
    ``edges`` (m, 2) in range without self-loops; ``groups`` lists/tuples of ints or 1-D
    integer arrays, in range) and returns None for anything else, for a search that passes
    ``node_limit`` nodes, or for an answer that fails the independence check against the input
    arrays; the caller then takes the full pipeline (which names the bad field, or solves with
    KaMIS). The selection is the one :class:`uam_solvers.auto.AutoBackend` returns through the
    pipeline for the same graph (the same search on the same normalised graph).
    """
    try:
        w = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError):
        return None
    if w.ndim != 1 or w.shape[0] > max_vertices or w.shape[0] == 0:
        return None
    n = int(w.shape[0])
    if not (np.isfinite(w).all() and (w >= 0).all()) or float(w.sum()) > MAX_TOTAL_WEIGHT:
        return None
    if edges is None:
        us = vs = []
        e = None
    else:
        try:
            e = np.asarray(edges)
        except (TypeError, ValueError):
            return None
        if e.size == 0:
            us = vs = []
            e = None
        else:
            if e.ndim != 2 or e.shape[1] != 2 or e.dtype.kind not in "iu":
                return None
            if int(e.min()) < 0 or int(e.max()) >= n or bool((e[:, 0] == e[:, 1]).any()):
                return None
            us, vs = e[:, 0].tolist(), e[:, 1].tolist()
    glists: list[list[int]] = []
    if groups is not None:
        if not isinstance(groups, (list, tuple)):
            return None
        for g in groups:
            gl = _int_list(g, n)
            if gl is None:
                return None
            if len(gl) >= 2:
                gl = sorted(set(gl))
                if len(gl) >= 2:
                    glists.append(gl)
    if clique_cover_size(n, glists) > max_cover:
        return None  # the pipeline's auto gives such a graph to KaMIS, not the search
    wl = w.tolist()
    sel, nodes = _search(n, exact_integer_weights(wl), us, vs, glists, node_limit)
    if sel is None:
        return None
    # the answer checked against the input arrays themselves, as the pipeline's validation does
    # (the groups on a bytearray: numpy scalars cost ~18 us of a 0.25 ms solve)
    flags = bytearray(n)
    for v in sel:
        flags[v] = 1
    if e is not None:
        chosen = np.frombuffer(flags, dtype=np.bool_)
        if bool((chosen[e[:, 0]] & chosen[e[:, 1]]).any()):
            return None
    if any(sum(flags[v] for v in g) > 1 for g in glists):
        return None
    return MwisResult(selected=np.asarray(sel, dtype=np.int32),
                      objective=float(math.fsum(wl[v] for v in sel)), proven_optimal=True,
                      solve_time_s=0.0, backend="auto",
                      stats={"auto_method": "clique-bb", "bb_nodes": nodes})
