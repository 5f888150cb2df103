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
``random_seed``. The solver is hinted with the greedy GWMIN answer.
"""
from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np

from .base import Backend, MwisProblem, MwisResult, integer_weights, make_result
from .greedy import greedy_mwis

__all__ = ["CpSatBackend", "uncovered_edges"]


def uncovered_edges(problem: MwisProblem) -> np.ndarray:
    """Listed edges whose two ends are not in a common clique group. O(m log m + sum |g|^2)."""
    e = problem.edges.astype(np.int64)
    if not problem.groups or e.shape[0] == 0:
        return e
    n = problem.n
    pairs = []
    for g in problem.groups:
        iu, ju = np.triu_indices(g.size, k=1)
        pairs.append(g[iu].astype(np.int64) * n + g[ju])
    covered = np.concatenate(pairs)
    return e[~np.isin(e[:, 0] * n + e[:, 1], covered)]


class CpSatBackend(Backend):
    """OR-Tools CP-SAT; options ``num_workers`` (1), ``resolution`` (10**6), ``hint`` (True)."""

    name = "exact"
    description = "OR-Tools CP-SAT exact MWIS (at-most-one per group and edge), proves optimality"

    def available(self) -> tuple[bool, str]:
        try:
            import ortools.sat.python.cp_model  # noqa: F401
        except ImportError as exc:
            return False, f"ortools is not installed ({exc})"
        return True, ""

    def solve(self, problem: MwisProblem, *, time_limit_s: float = 10.0, seed: int = 0,
              options: Mapping[str, Any] | None = None) -> MwisResult:
        self.require_available()
        from ortools.sat.python import cp_model

        options = dict(options or {})
        num_workers = int(options.pop("num_workers", 1))
        resolution = int(options.pop("resolution", 10**6))
        hint = bool(options.pop("hint", True))
        if options:
            raise ValueError(f"options: unknown option(s) {sorted(options)} for backend 'exact' "
                             "(known: num_workers, resolution, hint)")
        t0 = time.perf_counter()
        n = problem.n
        wi, scale = integer_weights(problem.weights, resolution)
        model = cp_model.CpModel()
        x = [model.NewBoolVar(f"x{v}") for v in range(n)]
        for g in problem.groups:
            model.AddAtMostOne([x[v] for v in g.tolist()])
        rest = uncovered_edges(problem)
        for u, v in rest.tolist():
            model.AddAtMostOne((x[u], x[v]))
        model.Maximize(cp_model.LinearExpr.WeightedSum(x, wi.tolist()))
        if hint and n:
            start = np.zeros(n, dtype=bool)
            start[greedy_mwis(problem.weights, problem.all_edges())] = True
            for v, val in enumerate(start.tolist()):
                model.AddHint(x[v], val)
        solver = cp_model.CpSolver()
        solver.parameters.max_time_in_seconds = max(float(time_limit_s), 1e-3)
        solver.parameters.num_workers = num_workers
        solver.parameters.random_seed = int(seed) % (2**31)
        status = solver.Solve(model)
        if status in (cp_model.OPTIMAL, cp_model.FEASIBLE):
            sel = [v for v in range(n) if solver.BooleanValue(x[v])]
        else:
            # No solution within the limit (only on huge graphs): greedy is a valid answer.
            sel = greedy_mwis(problem.weights, problem.all_edges())
        dt = time.perf_counter() - t0
        stats = {
            "status": solver.StatusName(status),
            "weight_scale": scale,
            "integer_objective": float(solver.ObjectiveValue()) if status in (cp_model.OPTIMAL, cp_model.FEASIBLE) else float("nan"),
            "best_bound_float": float(solver.BestObjectiveBound()) / scale if status in (cp_model.OPTIMAL, cp_model.FEASIBLE) else float("nan"),
            "at_most_one_groups": len(problem.groups),
            "at_most_one_edges": int(rest.shape[0]),
            "cpsat_wall_time_s": float(solver.WallTime()),
        }
        return make_result(problem, sel, proven_optimal=status == cp_model.OPTIMAL, solve_time_s=dt,
                           backend=self.name, stats=stats)
