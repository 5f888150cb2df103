"""ValidateFallback catches deliberately broken backends: no caller gets a non-independent set."""
import logging
import time

import numpy as np
import pytest

import uam_solvers
from uam_solvers.base import Backend, MwisProblem, MwisResult, make_result
from uam_solvers.layers import ValidateFallback

# Two requests (groups) of two candidates plus a conflict 0-2. Greedy GWMIN answer: {0, 3}.
W = [1.0, 0.6, 0.9, 0.8]
GROUPS = [[0, 1], [2, 3]]
EDGES = [[0, 2]]


class Broken(Backend):
    description = "test: misbehaves on purpose"

    def __init__(self, mode):
        self.mode = mode
        self.name = f"broken-{mode}"

    def solve(self, problem, *, time_limit_s, seed, options):
        if self.mode == "conflict":
            return make_result(problem, [0, 2], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        if self.mode == "group-conflict":
            return make_result(problem, [0, 1], proven_optimal=True, solve_time_s=0.0, backend=self.name)
        if self.mode == "out-of-range":
            return MwisResult(np.array([0, 7], np.int32), 1.0, True, 0.0, self.name, {})
        if self.mode == "raises":
            raise RuntimeError("solver crashed")
        if self.mode == "sleeps":
            time.sleep(3.0)
            return make_result(problem, [0, 3], proven_optimal=True, solve_time_s=3.0, backend=self.name)
        if self.mode == "not-a-result":
            return [0, 3]
        if self.mode == "wrong-objective":
            return MwisResult(np.array([3, 0], np.int32), 99.0, False, 0.0, self.name, {})
        raise AssertionError(self.mode)


def _problem():
    return MwisProblem.from_arrays(W, EDGES, GROUPS)


@pytest.mark.parametrize("mode, reason", [
    ("conflict", "vertices 0 and 2 conflict"),
    ("group-conflict", "vertices 0 and 1 conflict"),
    ("out-of-range", "vertex 7 is out of range"),
    ("raises", "raised RuntimeError: solver crashed"),
    ("not-a-result", "returned list, not MwisResult"),
])
def test_invalid_answers_fall_back_to_greedy(mode, reason, caplog):
    p = _problem()
    with caplog.at_level(logging.WARNING, logger="uam_solvers"):
        r = ValidateFallback(Broken(mode)).solve(p, time_limit_s=1.0, seed=0, options={})
    assert r.fallback and reason in r.message and f"broken-{mode}" in r.message
    assert r.backend == "greedy" and r.stats["requested_backend"] == f"broken-{mode}"
    assert p.is_independent(r.selected) and r.selected.tolist() == [0, 3]
    assert r.objective == pytest.approx(1.8)
    assert any(reason in rec.getMessage() for rec in caplog.records)


def test_overrunning_backend_is_abandoned_and_falls_back():
    p = _problem()
    layer = ValidateFallback(Broken("sleeps"), margin_s=0.05, margin_fraction=0.0)
    r = layer.solve(p, time_limit_s=0.05, seed=0, options={})
    assert r.fallback and "exceeded its time limit" in r.message
    assert p.is_independent(r.selected) and r.backend == "greedy"


def test_valid_answer_passes_with_objective_recomputed():
    p = _problem()
    r = ValidateFallback(Broken("wrong-objective")).solve(p, time_limit_s=1.0, seed=0, options={})
    assert not r.fallback and r.message == ""
    assert r.selected.tolist() == [0, 3] and r.selected.dtype == np.int32
    assert r.objective == pytest.approx(1.8) and r.stats["reported_objective"] == 99.0
    assert r.backend == "broken-wrong-objective"


def test_public_solve_validates_every_backend_instance():
    for mode in ("conflict", "raises"):
        r = uam_solvers.solve(W, EDGES, GROUPS, backend=Broken(mode), time_limit_s=1.0)
        assert r.fallback and _problem().is_independent(r.selected)
        r = uam_solvers.solve(W, EDGES, GROUPS, backend=Broken(mode), layers=False)
        assert r.fallback and _problem().is_independent(r.selected)


def test_broken_fallback_degrades_to_the_empty_set():
    p = _problem()
    r = ValidateFallback(Broken("raises"), fallback=Broken("conflict")).solve(
        p, time_limit_s=1.0, seed=0, options={})
    assert r.fallback and r.selected.size == 0 and "empty set" in r.message


def test_bad_input_and_time_limit_are_refused_before_solving():
    with pytest.raises(uam_solvers.MwisInputError, match=r"edges\[0\]: \(1, 1\) is a self-loop"):
        uam_solvers.solve(W, [[1, 1]])
    with pytest.raises(uam_solvers.MwisInputError, match="time_limit_s"):
        uam_solvers.solve(W, EDGES, time_limit_s=0.0)
    with pytest.raises(uam_solvers.MwisInputError, match="max_vertices=3"):
        uam_solvers.solve(W, EDGES, max_vertices=3)
