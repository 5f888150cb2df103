"""sa and tabu backends on hand-checked graphs and against brute force."""

import numpy as np
import pytest

from uam_solvers.annealing import SimulatedAnnealingBackend, TabuBackend
from uam_solvers.base import MwisInputError, MwisProblem
from uam_solvers.instances import paper_instance
from uam_solvers.qubo import feasible_mask
from uam_solvers.registry import get_backend

BACKENDS = [SimulatedAnnealingBackend, TabuBackend]

# (weights, edges, groups, optimal selection) worked by hand
HAND_CASES = {
    # path 0-1-2-3: {1,3} = 1.5 beats {0,2} = 1.3 and {0,3} = 1.1
    "path": ([0.6, 1.0, 0.7, 0.5], [[0, 1], [1, 2], [2, 3]], None, [1, 3]),
    # two requests of three candidates; conflicts 0-3 and 1-4: {0,4} = 1.9 beats {1,3} = 1.8
    "two requests": ([1.0, 0.8, 0.6, 1.0, 0.9, 0.5], [[0, 3], [1, 4]],
                     [[0, 1, 2], [3, 4, 5]], [0, 4]),
    # star: the heavy centre 1.0 loses to four leaves of 0.3
    "star": ([1.0, 0.3, 0.3, 0.3, 0.3], [[0, 1], [0, 2], [0, 3], [0, 4]], None, [1, 2, 3, 4]),
    # no edges: everything
    "isolated": ([0.2, 0.4, 0.1], [], None, [0, 1, 2]),
}


def brute_force(problem):
    n = problem.n
    x = ((np.arange(2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)
    ok = feasible_mask(x, problem.all_edges())
    return float(np.where(ok, x @ problem.weights, -np.inf).max())


@pytest.mark.parametrize("backend_cls", BACKENDS)
@pytest.mark.parametrize("case", sorted(HAND_CASES))
def test_hand_checked_optimum(backend_cls, case):
    weights, edges, groups, expected = HAND_CASES[case]
    problem = MwisProblem.from_arrays(weights, edges, groups=groups)
    result = backend_cls().solve(problem, time_limit_s=5.0, seed=1, options={"num_reads": 10})
    assert result.selected.tolist() == expected
    assert result.objective == pytest.approx(sum(weights[i] for i in expected))
    assert result.proven_optimal is False
    assert result.backend == backend_cls.name
    assert result.stats["reads"] == 10


@pytest.mark.parametrize("backend_cls", BACKENDS)
def test_paper_instances_reach_brute_force_optimum(backend_cls):
    for seed in range(3):
        problem = paper_instance(3, seed=seed, n_vertices=14)
        optimum = brute_force(problem)
        result = backend_cls().solve(problem, time_limit_s=5.0, seed=seed,
                                     options={"num_reads": 20, "optimum": optimum})
        assert problem.is_independent(result.selected)
        assert result.objective == pytest.approx(optimum)
        stats = result.stats
        assert 0 < stats["optimal_fraction"] <= 1
        assert 0 <= stats["feasible_fraction_raw"] <= 1
        assert stats["feasible_fraction"] == 1.0  # lambda = 2 > max weight 1
        assert stats["best_objective"] == pytest.approx(result.objective)


@pytest.mark.parametrize("backend_cls", BACKENDS)
def test_same_seed_same_answer(backend_cls):
    problem = paper_instance(5, seed=9)
    a = backend_cls().solve(problem, time_limit_s=5.0, seed=4, options={"num_reads": 8})
    b = backend_cls().solve(problem, time_limit_s=5.0, seed=4, options={"num_reads": 8})
    assert np.array_equal(a.selected, b.selected)
    assert a.stats["mean_objective"] == b.stats["mean_objective"]


@pytest.mark.parametrize("backend_cls", BACKENDS)
def test_heavy_weights_still_give_an_independent_set(backend_cls):
    # weights above lambda = 2: the QUBO minimum is infeasible, repair fixes every read
    problem = MwisProblem.from_arrays([3.0, 3.0, 5.0], [[0, 1], [1, 2]])
    result = backend_cls().solve(problem, time_limit_s=5.0, seed=0, options={"num_reads": 5})
    assert problem.is_independent(result.selected)
    assert result.objective == pytest.approx(8.0)
    assert result.stats["lambda_exceeds_max_weight"] is False


@pytest.mark.parametrize("backend_cls", BACKENDS)
def test_empty_graph_and_bad_options(backend_cls):
    empty = MwisProblem.from_arrays([], [])
    result = backend_cls().solve(empty, time_limit_s=1.0, seed=0, options={})
    assert result.selected.tolist() == [] and result.objective == 0.0
    problem = MwisProblem.from_arrays([1.0, 1.0], [[0, 1]])
    with pytest.raises(MwisInputError, match="num_reads"):
        backend_cls().solve(problem, time_limit_s=1.0, seed=0, options={"num_reads": 0})
    with pytest.raises(MwisInputError, match="lambda"):
        backend_cls().solve(problem, time_limit_s=1.0, seed=0, options={"lambda": -1})
    # issue 11: an unknown option is an error for every backend, no longer silently ignored
    with pytest.raises(MwisInputError, match="not_an_option"):
        backend_cls().solve(problem, time_limit_s=1.0, seed=0,
                            options={"num_reads": 2, "not_an_option": 1})


def test_sa_options_reach_the_sampler():
    problem = paper_instance(2, seed=1)
    result = SimulatedAnnealingBackend().solve(
        problem, time_limit_s=5.0, seed=0,
        options={"num_reads": 3, "num_sweeps": 17, "beta_range": (0.5, 4.0)})
    assert result.stats["num_sweeps"] == 17 and result.stats["beta_range"] == "0.5,4"
    with pytest.raises(MwisInputError, match="beta_range"):
        SimulatedAnnealingBackend().solve(problem, time_limit_s=1.0, seed=0,
                                          options={"beta_range": (5.0, 1.0)})


def test_registry_names_resolve_to_these_classes():
    assert isinstance(get_backend("sa"), SimulatedAnnealingBackend)
    assert isinstance(get_backend("tabu"), TabuBackend)
    assert get_backend("sa").available() == (True, "")


@pytest.mark.parametrize("backend_cls", BACKENDS)
def test_an_expired_time_limit_stops_after_the_first_reads(backend_cls):
    problem = paper_instance(8, seed=2)  # 40 vertices: tabu makes calls of 50 reads
    result = backend_cls().solve(problem, time_limit_s=1e-9, seed=0, options={"num_reads": 100})
    assert result.stats["interrupted"] is True
    assert 1 <= result.stats["reads"] < 100
    assert problem.is_independent(result.selected)


def test_tabu_decomposes_graphs_above_its_dense_matrix_limit():
    # issue 11: no longer refused; decomposed into subproblems that fit the dense matrix
    problem = paper_instance(2, seed=0)  # 10 vertices
    result = TabuBackend().solve(problem, time_limit_s=0.5, seed=0,
                                 options={"max_vertices": 9, "subproblem_size": 5})
    assert result.stats["decomposed"] is True and result.stats["subproblem_vertices"] == 5
    assert problem.is_independent(result.selected)
