"""Conversions of the MWIS service (uam_msgs/SolveMwis) to and from uam_solvers' types. rclpy-free.

The solver node reads requests with :func:`problem_from_solve_request`; the planner node builds
them with :func:`solve_request` and reads answers with :func:`solve_answer`.
"""

from __future__ import annotations

from typing import Any

import numpy as np


def solve_request(weights, edges, groups, backend: str, time_limit_s: float, seed: int):
    """uam_msgs/SolveMwis.Request of a conflict graph (``groups``: vertex lists, one per request)."""
    from uam_msgs.srv import SolveMwis

    vertex_group = np.full(len(weights), -1, dtype=np.int64)
    for gid, members in enumerate(groups or ()):
        vertex_group[np.asarray(members, dtype=np.int64)] = gid
    edges = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    return SolveMwis.Request(
        weights=[float(w) for w in weights], edges_u=[int(u) for u in edges[:, 0]],
        edges_v=[int(v) for v in edges[:, 1]], vertex_group=[int(g) for g in vertex_group],
        backend=backend, time_limit_s=float(time_limit_s), seed=int(seed))


def problem_from_solve_request(request: Any, max_vertices: int):
    """Validate a SolveMwis request into a uam_solvers.MwisProblem; MwisInputError names the field."""
    from uam_solvers import MwisInputError, MwisProblem

    n = len(request.weights)
    if len(request.edges_u) != len(request.edges_v):
        raise MwisInputError(
            f"edges_u/edges_v: lengths differ ({len(request.edges_u)} != {len(request.edges_v)})")
    if len(request.vertex_group) not in (0, n):
        raise MwisInputError(
            f"vertex_group: length {len(request.vertex_group)} must be 0 or len(weights) = {n}")
    edges = np.stack([np.asarray(request.edges_u, dtype=np.int64),
                      np.asarray(request.edges_v, dtype=np.int64)], axis=1).reshape(-1, 2)
    groups = None
    if len(request.vertex_group):
        g = np.asarray(request.vertex_group, dtype=np.int64)
        groups = [np.flatnonzero(g == gid) for gid in np.unique(g[g >= 0])]
    return MwisProblem.from_arrays(np.asarray(request.weights, dtype=np.float64), edges, groups,
                                   max_vertices=max_vertices)


def solve_answer(response: Any):
    """The planning cycle's view of a successful SolveMwis response (selected, objective, ...).

    The answer is not trusted here: the planning cycle checks it against the graph it sent.
    """
    from types import SimpleNamespace

    return SimpleNamespace(selected=np.asarray(response.selected, dtype=np.int64), objective=response.objective,
                           proven_optimal=response.proven_optimal, backend=response.backend_used,
                           fallback=response.fallback, message=response.message,
                           solve_time_s=response.solve_time_s)
