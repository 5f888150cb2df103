"""Exact MWIS reductions: shrink the conflict graph without losing the optimum.

Every rule below maps an optimal independent set of the reduced graph (plus the vertices the rule
forced into the answer) to an optimal one of the input graph. N(v) is the open and N[v] = N(v) + v
the closed neighbourhood in the graph that is left (clique groups count as edges).

1. Zero-weight vertices are removed. Safe: dropping a weight-0 vertex from any independent set
   keeps it independent and its weight unchanged; the final completion pass adds such vertices
   back when they are free.
2. Isolated vertices (degree 0) are forced in. Safe: they conflict with nothing, w >= 0.
3. Simplicial vertices: if N(v) is a clique and w(v) >= w(u) for all u in N(v), force v in and
   remove N[v]. Safe: an optimum holds at most one vertex of the clique N[v]; exchanging it for v
   keeps independence (v's neighbours are all in N[v]) and does not lower the weight.
4. Neighbourhood weight domination: if u and v are adjacent, N[u] is a subset of N[v] and
   w(u) >= w(v), remove v. Safe: an independent set containing v holds nothing else of
   N[v], hence nothing of N[u] but v; exchanging v for u keeps it independent and does not lower
   the weight. When N[u] = N[v] and w(u) = w(v) only the higher index is removed, which keeps the
   relation acyclic (and transitive), so all dominated vertices of one round can go at once:
   every removed vertex has a dominator that stays.

Each round computes the neighbourhoods once, applies the simplicial rule, then domination on
the pairs the simplicial removals did not touch (their neighbourhoods are unchanged, so the
inclusion still holds); rounds repeat until nothing changes or ``max_rounds`` is reached (stopping early is safe, it only reduces less). Neighbourhood
inclusion comes from one matrix product C = (A + I)^2: for an edge (u, v), N[u] is in N[v] iff
C[u, v] = deg(u) + 1. Cost per round: O(sum_v deg(v)^2) (dense O(n^3 / word) below 256 vertices).
"""
from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np
import scipy.sparse as sp

from .base import MwisProblem, induced_subproblem

__all__ = ["Reduction", "reduce_problem", "complete_maximal"]

_DENSE_MAX = 256


@dataclass
class Reduction:
    """Result of :func:`reduce_problem`.

    Attributes:
        kernel: the reduced problem (re-indexed 0..k-1; listed edges and groups restricted).
        kept: (k,) int64 original index of each kernel vertex.
        forced: int64 original indices forced into the answer.
        counts: how many vertices each rule handled, plus rounds and kernel size.
    """

    kernel: MwisProblem
    kept: np.ndarray
    forced: np.ndarray
    counts: dict = field(default_factory=dict)


class _Neighbourhoods:
    """Per-round neighbourhood data of the alive subgraph: dense numpy below ``_DENSE_MAX``
    vertices (no scipy overhead for the 5-50 vertex graphs of one planning epoch), sparse above."""

    def __init__(self, problem: MwisProblem):
        self.problem = problem
        self.dense = None
        if problem.n <= _DENSE_MAX:
            e = problem.all_edges()
            d = np.zeros((problem.n, problem.n), dtype=np.int32)
            d[e[:, 0], e[:, 1]] = 1
            d[e[:, 1], e[:, 0]] = 1
            self.dense = d

    def neighbours(self, mask: np.ndarray) -> np.ndarray:
        """Boolean mask of the vertices adjacent to any vertex of ``mask`` (full graph). O(m)."""
        e = self.problem.all_edges()
        out = np.zeros(mask.size, dtype=bool)
        out[e[mask[e[:, 0]], 1]] = True
        out[e[mask[e[:, 1]], 0]] = True
        return out

    def round(self, alive: np.ndarray, focus: np.ndarray | None):
        """Neighbourhood data of the alive subgraph.

        Returns ``(rows, cols, common, deg, idx, in_focus)``: directed edges (r, c) in local
        indices, sorted by r, for every r in ``focus`` (all alive vertices when None or on the
        dense path); ``common[k] = |N[r] & N[c]|``; ``deg`` local degrees of all alive vertices;
        ``idx`` local -> original index; ``in_focus`` local mask of the rows covered.
        """
        idx = np.flatnonzero(alive)
        k = idx.size
        if self.dense is not None:
            a = self.dense[np.ix_(idx, idx)]
            deg = a.sum(axis=1)
            b = a + np.eye(k, dtype=np.int32)
            c = b @ b
            rows, cols = np.nonzero(a)
            return rows, cols, c[rows, cols], deg, idx, np.ones(k, dtype=bool)
        a = self.problem.adjacency()[idx][:, idx].tocsr().astype(np.int32)
        a.sort_indices()
        deg = np.diff(a.indptr)
        in_focus = np.ones(k, dtype=bool) if focus is None else focus[idx]
        sel = np.flatnonzero(in_focus)
        a_rows = a[sel]
        b = (a + sp.identity(k, dtype=np.int32, format="csr")).tocsr()
        # Only C = B @ B on the focus rows' edges is needed: (B[sel] @ B) masked by A[sel].
        c = (b[sel] @ b).multiply(a_rows).tocsr()
        c.sort_indices()
        coo = a_rows.tocoo()
        # Same pattern in the same row-major order (C >= 2 on every edge).
        return sel[coo.row], coo.col, c.tocoo().data.astype(np.int64), deg, idx, in_focus


def _simplicial(rows: np.ndarray, cols: np.ndarray, sub_rc: np.ndarray, wl: np.ndarray,
                deg: np.ndarray, in_focus: np.ndarray) -> np.ndarray:
    """Rule 3's candidates (local indices): v in focus, not isolated, with N[v] in N[u] for every
    neighbour u and w(v) maximal over N[v]."""
    not_simp = ~in_focus
    np.logical_or.at(not_simp, rows, ~sub_rc | (wl[cols] > wl[rows]))
    return np.flatnonzero(~not_simp & (deg > 0))


def _take_simplicial(simp: np.ndarray, rows: np.ndarray, cols: np.ndarray,
                     k: int) -> tuple[np.ndarray, np.ndarray]:
    """Rule 3 applied to the candidates in index order: the vertices forced in and the local
    mask of every vertex removed (them and their neighbours)."""
    local_alive = np.ones(k, dtype=bool)
    starts = np.searchsorted(rows, np.arange(k + 1))  # rows are sorted
    took = []
    for v in simp.tolist():  # sequential: a removed neighbour may be simplicial too
        if not local_alive[v]:
            continue
        # Earlier removals only shrink N(v): still a clique, w(v) still maximal.
        nb = cols[starts[v]:starts[v + 1]]
        took.append(v)
        local_alive[v] = False
        local_alive[nb] = False
    return np.asarray(took, dtype=np.int64), ~local_alive


def _dominated(rows: np.ndarray, cols: np.ndarray, common: np.ndarray, deg: np.ndarray,
               wl: np.ndarray, sub_rc: np.ndarray, touched: np.ndarray) -> np.ndarray | None:
    """Rule 4: the dominated vertices (local, unique), None when there are none.

    r dominates c; on exact ties (same N[], same weight) the lower index wins. Only pairs
    untouched by this round's simplicial removals: their closed neighbourhoods did not
    change, so the inclusion computed this round still holds."""
    sub_cr = common == deg[cols] + 1
    mutual_tie = sub_cr & (wl[cols] >= wl[rows]) & (cols < rows)
    dom = sub_rc & (wl[rows] >= wl[cols]) & ~mutual_tie & ~touched[rows] & ~touched[cols]
    if not dom.any():
        return None
    return np.unique(cols[dom])


def reduce_problem(problem: MwisProblem, max_rounds: int = 64) -> Reduction:
    """Apply the exact reductions of this module until none applies.

    Input: a validated problem. Output: a :class:`Reduction`; an optimal answer of ``kernel``
    mapped through ``kept`` plus ``forced`` is optimal for ``problem``.

    On the sparse path (large graphs), after a round that examined both rules only vertices
    within two hops of a removal are re-examined: the inclusion N[u] in N[v] can only change when
    N[u] or N[v] lost a vertex, so elsewhere nothing new can apply. Dense and sparse paths give
    the same reduction (tested).
    """
    n = problem.n
    w = problem.weights
    hoods = _Neighbourhoods(problem)
    alive = np.ones(n, dtype=bool)
    forced: list[np.ndarray] = []
    counts = {"reduce_zero_weight": 0, "reduce_isolated": 0, "reduce_simplicial": 0,
              "reduce_dominated": 0, "reduce_rounds": 0}
    zero = w <= 0.0
    counts["reduce_zero_weight"] = int(zero.sum())
    alive &= ~zero
    focus = None
    for _ in range(max_rounds):
        if not alive.any():
            break
        counts["reduce_rounds"] += 1
        before = alive.copy()
        rows, cols, common, deg, idx, in_focus = hoods.round(alive, focus)
        k = idx.size
        # Rule 2: isolated vertices.
        iso = deg == 0
        if iso.any():
            forced.append(idx[iso])
            alive[idx[iso]] = False
            counts["reduce_isolated"] += int(iso.sum())
        if rows.size == 0:
            break
        wl = w[idx]
        # sub_rc: N[r] is a subset of N[c].
        sub_rc = common == deg[rows] + 1
        simp = _simplicial(rows, cols, sub_rc, wl, deg, in_focus)
        removed_any = bool(iso.any())
        touched = np.zeros(k, dtype=bool)  # removed this round or adjacent to a removal
        if simp.size:
            took, gone = _take_simplicial(simp, rows, cols, k)
            forced.append(idx[took])
            counts["reduce_simplicial"] += int(took.size)
            alive[idx[gone]] = False
            removed_any = True
            touched = gone
            gone_rows = touched[rows]
            touched[cols[gone_rows]] = True  # neighbours of removed vertices
        victims = _dominated(rows, cols, common, deg, wl, sub_rc, touched)
        if victims is not None:
            alive[idx[victims]] = False
            counts["reduce_dominated"] += int(victims.size)
            removed_any = True
        if not removed_any:
            break
        if hoods.dense is None:
            # Next round: vertices within two hops of a removal; pairs skipped above because a
            # simplicial removal touched them are within one hop, so they are covered too.
            dirty = hoods.neighbours(before & ~alive) & alive
            focus = (dirty | hoods.neighbours(dirty)) & alive
    kept = np.flatnonzero(alive)
    kernel = induced_subproblem(problem, kept)
    counts["kernel_vertices"] = int(kept.size)
    f = np.concatenate(forced).astype(np.int64) if forced else np.zeros(0, dtype=np.int64)
    return Reduction(kernel=kernel, kept=kept, forced=np.sort(f), counts=counts)


def complete_maximal(problem: MwisProblem, selected: np.ndarray) -> np.ndarray:
    """Add free vertices (no selected neighbour) to an independent set, heaviest first (lowest
    index on ties), so the answer is maximal. Never lowers the weight. O(n log n + m)."""
    indptr, indices = problem.csr()
    sel = np.zeros(problem.n, dtype=bool)
    sel[np.asarray(selected, dtype=np.int64)] = True
    blocked = sel.copy()
    e = problem.all_edges()
    if sel.any() and e.shape[0]:
        blocked[e[sel[e[:, 0]], 1]] = True
        blocked[e[sel[e[:, 1]], 0]] = True
    free = np.flatnonzero(~blocked)
    if free.size == 0:
        return np.flatnonzero(sel).astype(np.int32)
    order = free[np.lexsort((free, -problem.weights[free]))]
    for v in order.tolist():
        if blocked[v]:
            continue
        sel[v] = True
        blocked[v] = True
        blocked[indices[indptr[v]:indptr[v + 1]]] = True
    return np.flatnonzero(sel).astype(np.int32)
