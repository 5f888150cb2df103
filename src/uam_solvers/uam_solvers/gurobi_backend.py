"""Exact MWIS with Gurobi (the paper's exact solver), only when ``gurobipy`` is importable.

Model: binary x_v, one clique constraint ``sum_{v in g} x_v <= 1`` per group, ``x_u + x_v <= 1``
per listed edge not inside a group, maximise sum w_v x_v with the float weights directly (no
scaling). ``proven_optimal`` is ``status == OPTIMAL`` (within Gurobi's default MIPGap 1e-4 unless
option ``mip_gap`` is given; the default here is 0 so OPTIMAL means optimal). Single thread
(option ``threads``) and ``Seed`` for determinism.
"""
from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np

from .base import Backend, BackendUnavailable, MwisProblem, MwisResult, make_result
from .cpsat import uncovered_edges
from .options import Option

__all__ = ["GurobiBackend"]


class GurobiBackend(Backend):
    """Gurobi MIP; options ``threads`` (1), ``mip_gap`` (0.0)."""

    name = "gurobi"
    description = "Gurobi MIP exact MWIS (needs gurobipy and a licence), the paper's exact solver"
    options_spec = {
        "threads": Option("threads", "int", 1, "Gurobi threads", lo=1, hi=64),
        "mip_gap": Option("mip_gap", "float", 0.0, "relative MIP gap (0: proven optimal)",
                          lo=0.0, hi=1.0),
    }

    def available(self) -> tuple[bool, str]:
        try:
            import gurobipy  # noqa: F401
        except ImportError:
            return False, "gurobipy is not installed"
        return True, ""

    def solve(self, problem: MwisProblem, *, time_limit_s: float = 10.0, seed: int = 0,
              options: Mapping[str, Any] | None = None) -> MwisResult:
        ok, reason = self.available()
        if not ok:
            raise BackendUnavailable(f"backend 'gurobi' is unavailable: {reason}")
        import gurobipy as gp
        from gurobipy import GRB

        opts = self.validate_options(options)
        threads, mip_gap = opts["threads"], opts["mip_gap"]
        t0 = time.perf_counter()
        n = problem.n
        with gp.Env(empty=True) as env:
            env.setParam("OutputFlag", 0)
            env.start()
            with gp.Model("mwis", env=env) as model:
                model.Params.TimeLimit = max(float(time_limit_s), 1e-3)
                model.Params.Threads = threads
                model.Params.Seed = int(seed) % (2**31)
                model.Params.MIPGap = mip_gap
                x = model.addMVar(n, vtype=GRB.BINARY)
                model.setObjective(problem.weights @ x, GRB.MAXIMIZE)
                for g in problem.groups:
                    model.addConstr(x[g].sum() <= 1)
                rest = uncovered_edges(problem)
                if rest.shape[0]:
                    model.addConstr(x[rest[:, 0]] + x[rest[:, 1]] <= 1)
                model.optimize()
                status = int(model.Status)
                if model.SolCount > 0:
                    sel = np.flatnonzero(np.asarray(x.X) > 0.5)
                else:
                    sel = np.zeros(0, dtype=np.int64)
                stats = {"status": status, "mip_gap": float(model.MIPGap) if model.SolCount else float("nan"),
                         "node_count": float(model.NodeCount)}
        return make_result(problem, sel, proven_optimal=status == GRB.OPTIMAL,
                           solve_time_s=time.perf_counter() - t0, backend=self.name, stats=stats)
