"""KaMIS branch-and-reduce and CHILS through the ``chszlablib`` wheel (MIT, Heidelberg).

Both take integer vertex weights. Float weights are scaled with
:func:`uam_solvers.base.integer_weights`: ``W = round(w * R / max(w))`` (positive weights never
round to 0). KaMIS's weighted branch-and-reduce stores weights and their sums as 32-bit ints, so
its resolution is ``R = min(10^6, (2^31 - 1) // n)`` (the sum of all weights stays below 2^31);
CHILS uses 64-bit weights and ``R = 10^6``. Each weight is off by at most max(w) / (2R). The
answer is checked to be an independent set (a violation raises, so the validation layer falls
back) and its objective is recomputed in float64 from the original weights.

- ``kamis``: exact branch-and-reduce. chszlablib does not say whether the search finished, so
  ``proven_optimal`` is True only when the call returned before ``finish_fraction`` (0.9) of the
  time limit: a search stopped by the limit runs to it. Optimal then means optimal for the
  integer weights.
- ``chils``: concurrent iterated local search; it always runs until its time limit (plus ~70 ms of
  set-up), never proves optimality, and with more than one concurrent search or a time-bounded
  run its answer depends on machine speed (so it is deterministic only in distribution).
"""
from __future__ import annotations

import time
from typing import Any, Mapping

import numpy as np

from .base import (Backend, MwisInputError, MwisProblem, MwisResult, check_selection,
                   integer_proof_holds, integer_weights, make_result)
from .options import Option

__all__ = ["KamisBackend", "ChilsBackend"]


def _csr(problem: MwisProblem) -> tuple[np.ndarray, np.ndarray]:
    return problem.csr()


def _available() -> tuple[bool, str]:
    try:
        import chszlablib._chils  # noqa: F401
        import chszlablib._kamis_wmis  # noqa: F401
    except ImportError as exc:
        return False, f"chszlablib is not installed ({exc}); pip install chszlablib"
    return True, ""


def _checked(problem: MwisProblem, vertices: Any, backend: str) -> np.ndarray:
    """The solver's vertices, sorted, checked against ``problem`` (RuntimeError if invalid):
    the sorted int64 set the validation layer then finds checked (its int32 copy)."""
    sel = np.sort(np.asarray(vertices, dtype=np.int64).reshape(-1))
    ok, why = check_selection(problem, sel)
    if not ok:
        raise RuntimeError(f"{backend}: chszlablib returned an invalid answer: {why}")
    return sel


class KamisBackend(Backend):
    """KaMIS weighted branch-and-reduce; options ``resolution``, ``finish_fraction`` (0.9)."""

    name = "kamis"
    reduces_itself = True
    description = "KaMIS branch-and-reduce (chszlablib), exact when it finishes within the limit"
    # in-process only while tiny: KaMIS ignored its time limit on a dense 250-vertex graph (42 s
    # with 5 s); up to 64 vertices it returned within ~50 ms on every graph measured
    inline_max_vertices = 64
    warm_up_by_solving = True
    options_spec = {
        "resolution": Option("resolution", "int", None, "integer weight of the heaviest vertex "
                             "(None: min(10**6, (2**31 - 1) // n), KaMIS sums weights in 32 bits)",
                             lo=1, hi=2**31 - 1, nullable=True),
        "finish_fraction": Option("finish_fraction", "float", 0.9, "a call returning before this "
                                  "fraction of the limit finished its search (proven optimal)",
                                  lo=0.01, hi=1.0),
    }

    def available(self) -> tuple[bool, str]:
        return _available()

    def solve(self, problem: MwisProblem, *, time_limit_s: float = 10.0, seed: int = 0,
              options: Mapping[str, Any] | None = None) -> MwisResult:
        self.require_available()
        from chszlablib._kamis_wmis import branch_reduce

        opts = self.validate_options(options)
        n = problem.n
        resolution = opts["resolution"] or min(10**6, (2**31 - 1) // max(n, 1))
        finish_fraction = opts["finish_fraction"]
        if n * resolution >= 2**31:
            raise MwisInputError(f"options['resolution']: {resolution} x {n} vertices overflows "
                                 "KaMIS's 32-bit weights")
        t0 = time.perf_counter()
        if n == 0:
            return make_result(problem, [], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        wi, scale = integer_weights(problem.weights, resolution)
        indptr, indices = _csr(problem)
        budget_s = max(float(time_limit_s) - (time.perf_counter() - t0), 1e-3)
        # (copies: the binding refuses the problem's read-only CSR arrays)
        int_obj, verts = branch_reduce(indptr.astype(np.int32), indices.astype(np.int32),
                                       wi.astype(np.int32), budget_s, int(seed) % (2**31))
        dt = time.perf_counter() - t0
        sel = _checked(problem, verts, self.name)
        finished = dt < finish_fraction * time_limit_s
        # a finished search proves the integer optimum int_obj; it is claimed only when the
        # returned set has exactly that integer objective and its own weights agree with it
        proven = finished and integer_proof_holds(problem, sel, wi, scale, int(int_obj))
        # the set was checked (distinct, in range, independent) and sorted: not np.unique'd,
        # built once (make_result's second pass cost ~5 us of a 190 us solve)
        sel = sel.astype(np.int32)
        return MwisResult(selected=sel, objective=problem.objective(sel), proven_optimal=proven,
                          solve_time_s=float(dt), backend=self.name,
                          stats={"weight_scale": scale, "integer_objective": int(int_obj),
                                 "finished_before_limit": int(finished)})


class ChilsBackend(Backend):
    """CHILS concurrent local search; options ``num_concurrent`` (1), ``resolution`` (10**6)."""

    name = "chils"
    batch_components = True  # ~70 ms set-up per call
    # (it holds the GIL for its whole run, so it is not bounded_in_process)
    warm_up_by_solving = True
    reduces_itself = True
    description = "CHILS concurrent local search (chszlablib), best heuristic for large graphs"
    options_spec = {
        "num_concurrent": Option("num_concurrent", "int", 1, "concurrent local searches (threads)",
                                 lo=1, hi=64),
        "resolution": Option("resolution", "int", 10**6, "integer weight of the heaviest vertex",
                             lo=1, hi=10**12),
    }

    def available(self) -> tuple[bool, str]:
        return _available()

    def solve(self, problem: MwisProblem, *, time_limit_s: float = 10.0, seed: int = 0,
              options: Mapping[str, Any] | None = None) -> MwisResult:
        self.require_available()
        from chszlablib._chils import mwis

        opts = self.validate_options(options)
        num_concurrent, resolution = opts["num_concurrent"], opts["resolution"]
        t0 = time.perf_counter()
        if problem.n == 0:
            return make_result(problem, [], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        wi, scale = integer_weights(problem.weights, resolution)
        indptr, indices = _csr(problem)
        budget_s = max(float(time_limit_s) - (time.perf_counter() - t0), 1e-3)
        int_obj, verts = mwis(indptr.astype(np.int64), indices.astype(np.int32), wi.astype(np.int64),
                              budget_s, num_concurrent, int(seed) % (2**31))
        dt = time.perf_counter() - t0
        sel = _checked(problem, verts, self.name)
        return make_result(problem, sel, proven_optimal=problem.all_edges().shape[0] == 0,
                           solve_time_s=dt, backend=self.name,
                           stats={"weight_scale": scale, "integer_objective": int(int_obj),
                                  "num_concurrent": num_concurrent})
