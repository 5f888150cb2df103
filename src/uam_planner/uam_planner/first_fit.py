"""The first-fit baseline: arrival order, the first conflict-free of the same k candidates.

A baseline between shortest FIFO and MWIS that separates the two sources of MWIS's gain over
FIFO: *having alternative routes* and *optimising over them*. In one epoch, in arrival order,
each eligible request gets the first of its candidate routes (in candidate order, 0 = shortest,
then the penalised-Dijkstra order) that keeps separation with every active flight and with every
flight approved before it in this epoch; if none does, it waits (until it expires), as in FIFO.

It works on exactly the MWIS policy's instance: the same candidates, the same discards against
active flights and the same conflict graph (:func:`uam_planner.planning.plan_epoch_mwis` builds
it). The graph's vertices are ordered by request (eligible = arrival order) and, within a
request, by candidate index, and each request's candidates form a clique. So walking the
vertices in index order and taking every vertex none of whose neighbours is taken yet is
first-fit exactly: a request's first free candidate is taken, and the clique then blocks its
other candidates. The answer is independent by construction and is checked again by the planning
cycle like any solver's. The Planner's "firstfit" policy is ``plan_epoch_mwis`` with
:func:`first_fit_select` as its solver, relabelled by :func:`as_firstfit`; this module imports
nothing of the planner, so the planner can import it without a cycle.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
import numpy as np

POLICY = "firstfit"


@dataclass
class FirstFitAnswer:
    """A first-fit selection in the shape the planning cycle expects of a solver's answer."""

    selected: np.ndarray
    backend: str = POLICY
    proven_optimal: bool = False
    fallback: bool = False
    message: str = ""


def first_fit_select(weights, edges, groups=None) -> FirstFitAnswer:
    """Walk the vertices in index order, taking each one with no neighbour taken yet.

    Args:
        weights: (v,) vertex weights; only their count is used (first-fit ignores weights).
        edges: (e, 2) vertex pairs (clique edges of each request included).
        groups: ignored (the clique edges already say which vertices share a request).
    Returns: FirstFitAnswer with ``selected`` sorted ascending. O(v + e).
    """
    n = int(np.asarray(weights).shape[0])
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    if e.size and (e.min() < 0 or e.max() >= n):
        raise ValueError(f"edges: vertex indices must lie in [0, {n - 1}], got "
                         f"[{int(e.min())}, {int(e.max())}]")
    # CSR adjacency (both directions) so each vertex looks at its own neighbours only
    src = np.concatenate((e[:, 0], e[:, 1]))
    dst = np.concatenate((e[:, 1], e[:, 0]))
    order = np.argsort(src, kind="stable")
    nbr = dst[order]
    ptr = np.concatenate(([0], np.cumsum(np.bincount(src, minlength=n))))
    taken = np.zeros(n, dtype=bool)
    for v in range(n):
        if not taken[nbr[ptr[v]:ptr[v + 1]]].any():
            taken[v] = True
    return FirstFitAnswer(selected=np.flatnonzero(taken).astype(np.int64))


def as_firstfit(res):
    """Label an EpochResult of ``plan_epoch_mwis(..., first_fit_select, ...)`` as first-fit: the
    report keeps the instance first-fit walked (vertices, edges) with ``policy`` and
    ``backend_requested`` "firstfit" (``backend_used`` is already "firstfit"); the flights'
    ``method`` and ``backend`` become "firstfit". Returns ``res``."""
    rep = res.report
    rep.policy = POLICY
    rep.backend_requested = POLICY
    res.approved = [replace(f, method=POLICY, backend=POLICY) for f in res.approved]
    return res
