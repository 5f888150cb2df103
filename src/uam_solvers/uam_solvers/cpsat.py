"""Exact MWIS with OR-Tools CP-SAT.

Model: a Boolean x_v per vertex; one ``AddAtMostOne`` per clique group and one per listed edge
not already inside a group; maximise sum_v W_v x_v with integer weights
``W = round(w * 10^6 / max(w))`` (:func:`uam_solvers.base.integer_weights`, option
``resolution``): each weight is rounded to a multiple of max(w) / 10^6, so the integer optimum is
within n * max(w) / (2 * 10^6) of the float optimum (for the paper's weights in (0, 1] and 50
vertices: 2.5e-5). ``proven_optimal`` is ``status == OPTIMAL``, i.e. optimal for the integer
weights; the objective is recomputed in float64 from the original weights.

Determinism: one search worker (``num_workers=1``, option ``num_workers`` to change it; more
workers are faster on big graphs but their interleaving depends on timing) and a fixed
``random_seed``. Above 200 vertices the solver is hinted with the greedy GWMIN answer and
CP-SAT's own presolve is on; below, both are off (presolve costs ~4 ms and the hint ~1 ms, more
than the search itself on a reduced 50-vertex kernel).
"""
from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np

from .base import Backend, MwisProblem, MwisResult, integer_proof_holds, integer_weights, make_result
from .greedy import greedy_mwis
from .options import Option

__all__ = ["CpSatBackend", "uncovered_edges", "PRESOLVE_MIN_VERTICES"]

PRESOLVE_MIN_VERTICES = 200


def uncovered_edges(problem: MwisProblem) -> np.ndarray:
    """Listed edges whose two ends are not in a common clique group. O(m + sum |g|) when the
    groups are disjoint (one group per request, the usual case), else O(m log m + sum |g|^2)."""
    e = problem.edges.astype(np.int64)
    if not problem.groups or e.shape[0] == 0:
        return e
    n = problem.n
    sizes = np.fromiter((g.size for g in problem.groups), dtype=np.int64, count=len(problem.groups))
    members = np.concatenate(problem.groups).astype(np.int64)
    gid = np.full(n, -1, dtype=np.int64)
    gid[members] = np.repeat(np.arange(sizes.size), sizes)
    if np.count_nonzero(gid >= 0) == members.size:  # disjoint groups: one label per vertex
        same = (gid[e[:, 0]] == gid[e[:, 1]]) & (gid[e[:, 0]] >= 0)
        return e[~same]
    pairs = []
    for g in problem.groups:
        iu, ju = np.triu_indices(g.size, k=1)
        pairs.append(g[iu].astype(np.int64) * n + g[ju])
    covered = np.concatenate(pairs)
    return e[~np.isin(e[:, 0] * n + e[:, 1], covered)]


class _ProtoModel:
    """The one attribute CpSolver.solve uses of a CpModel."""

    __slots__ = ("proto",)

    def __init__(self, proto):
        self.proto = proto


class CpSatBackend(Backend):
    """OR-Tools CP-SAT; options ``num_workers`` (1), ``resolution`` (10**6), ``hint`` (None: on above PRESOLVE_MIN_VERTICES),
    ``presolve`` (None: on above PRESOLVE_MIN_VERTICES vertices)."""

    name = "exact"
    description = "OR-Tools CP-SAT exact MWIS (at-most-one per group and edge), proves optimality"
    inline_max_vertices = 64  # after reductions: well under 10 ms (CP-SAT stops at its limit)
    # the model is built in Python and CP-SAT releases the GIL while it searches, to its limit
    bounded_in_process = True
    warm_up_by_solving = True  # importing OR-Tools and its first solve: ~0.3 s
    options_spec = {
        "num_workers": Option("num_workers", "int", 1, "CP-SAT search workers (1: deterministic)",
                              lo=1, hi=64),
        "resolution": Option("resolution", "int", 10**6,
                             "integer weight of the heaviest vertex (weights scaled to integers)",
                             lo=1, hi=10**12),
        "hint": Option("hint", "bool", None, "greedy solution hint (None: on above "
                       f"{PRESOLVE_MIN_VERTICES} vertices)", nullable=True),
        "presolve": Option("presolve", "bool", None, "CP-SAT presolve (None: on above "
                           f"{PRESOLVE_MIN_VERTICES} vertices)", nullable=True),
    }

    def available(self) -> tuple[bool, str]:
        try:
            import ortools.sat.python.cp_model  # noqa: F401
        except ImportError as exc:
            return False, f"ortools is not installed ({exc})"
        return True, ""

    def solve(self, problem: MwisProblem, *, time_limit_s: float = 10.0, seed: int = 0,
              options: Mapping[str, Any] | None = None) -> MwisResult:
        self.require_available()
        from ortools.sat.python import cp_model, cp_model_helper

        opts = self.validate_options(options)
        num_workers, resolution = opts["num_workers"], opts["resolution"]
        hint, presolve = opts["hint"], opts["presolve"]
        t0 = time.perf_counter()
        n = problem.n
        wi, scale = integer_weights(problem.weights, resolution)
        # The model proto is filled directly: the Python builder API costs ~3x more per
        # constraint, which dominates on the 5-50 vertex graphs of one planning epoch.
        # CpSolver.solve only reads ``model.proto``; cp_model.CpModel() itself costs ~0.5 ms
        # (it installs its deprecated camel-case aliases on every construction).
        model = _ProtoModel(cp_model_helper.CpModelProto())
        proto = model.proto
        for _ in range(n):
            proto.variables.add().domain.extend((0, 1))
        for g in problem.groups:
            proto.constraints.add().at_most_one.literals.extend(g.tolist())
        rest = uncovered_edges(problem)
        for u, v in rest.tolist():
            proto.constraints.add().at_most_one.literals.extend((u, v))
        # CP-SAT minimises: minimise -sum W x, reported back as +sum W x via scaling_factor -1.
        proto.objective.vars.extend(range(n))
        proto.objective.coeffs.extend((-wi).tolist())
        proto.objective.scaling_factor = -1.0
        if (n > PRESOLVE_MIN_VERTICES if hint is None else bool(hint)) and n:
            start = np.zeros(n, dtype=np.int64)
            start[greedy_mwis(problem.weights, problem.all_edges())] = 1
            proto.solution_hint.vars.extend(range(n))
            proto.solution_hint.values.extend(start.tolist())
        solver = cp_model.CpSolver()
        # The limit covers model building too (a 10,000-vertex model takes ~0.5 s in Python).
        solver.parameters.max_time_in_seconds = max(float(time_limit_s) - (time.perf_counter() - t0), 1e-3)
        solver.parameters.num_workers = num_workers
        # CP-SAT otherwise installs its own SIGINT handler for the solve and leaves SIGINT at its
        # default afterwards, so a later Ctrl-C kills the host process (a ROS node) outright.
        solver.parameters.catch_sigint_signal = False
        solver.parameters.random_seed = int(seed) % (2**31)
        # CP-SAT's presolve costs ~4 ms even on 30 vertices, several times the search itself on
        # an already reduced kernel; it pays off on big graphs.
        solver.parameters.cp_model_presolve = bool(n > PRESOLVE_MIN_VERTICES if presolve is None else presolve)
        status = solver.solve(model)
        found = status in (cp_model.OPTIMAL, cp_model.FEASIBLE)
        if found:
            sel = np.flatnonzero(np.asarray(solver.response_proto.solution, dtype=np.int64) > 0)
        else:
            # No solution within the limit (only on huge graphs): greedy is a valid answer.
            sel = greedy_mwis(problem.weights, problem.all_edges())
        dt = time.perf_counter() - t0
        stats = {
            "status": solver.status_name(status),
            "weight_scale": scale,
            "integer_objective": float(solver.objective_value) if found else float("nan"),
            "best_bound_float": float(solver.best_objective_bound) / scale if found else float("nan"),
            "at_most_one_groups": len(problem.groups),
            "at_most_one_edges": int(rest.shape[0]),
            "cpsat_wall_time_s": float(solver.wall_time),
        }
        # OPTIMAL proves the integer optimum (the bound); claimed only when the returned set
        # has that integer objective and its own weights agree (integer_proof_holds)
        proven = status == cp_model.OPTIMAL and integer_proof_holds(
            problem, sel, wi, scale, float(solver.best_objective_bound))
        return make_result(problem, sel, proven_optimal=proven, solve_time_s=dt,
                           backend=self.name, stats=stats)
