"""Exact reductions: each rule on a hand-checked graph, and the optimum never changes
(property test against brute force over many seeded random graphs with clique groups)."""
import numpy as np
import pytest

from uam_solvers.base import MwisProblem, brute_force_mwis
from uam_solvers.reductions import complete_maximal, reduce_problem


def _lifted_optimum(p):
    red = reduce_problem(p)
    sel_k, _ = brute_force_mwis(red.kernel)
    sel = np.concatenate([red.forced, red.kept[sel_k]]).astype(np.int64)
    return red, sel


def test_isolated_and_zero_weight_vertices():
    p = MwisProblem.from_arrays([1.0, 0.0, 2.0, 0.5], [[1, 2]])
    red = reduce_problem(p)
    assert red.counts["reduce_zero_weight"] == 1
    assert red.forced.tolist() == [0, 2, 3]  # 2 becomes isolated once 1 (weight 0) is gone
    assert red.kernel.n == 0


def test_simplicial_vertex_with_maximal_weight_is_forced():
    # Triangle 0-1-2 plus pendant edge 2-3. Vertex 0: N(0) = {1, 2} is a clique, w(0)=5 is max.
    p = MwisProblem.from_arrays([5.0, 1.0, 4.0, 3.0], [[0, 1], [0, 2], [1, 2], [2, 3]])
    red = reduce_problem(p)
    assert 0 in red.forced.tolist() and 3 in red.forced.tolist()
    assert red.counts["reduce_simplicial"] >= 1
    assert red.kernel.n == 0


def test_simplicial_vertex_that_is_not_heaviest_is_kept():
    # Path 0-1-2 weights 1, 3, 1: leaves are simplicial but lighter than the middle; the middle
    # dominates nothing (N[1] = {0,1,2} is not inside N[0]) -> kernel keeps all three.
    p = MwisProblem.from_arrays([1.0, 3.0, 1.0], [[0, 1], [1, 2]])
    red = reduce_problem(p)
    assert red.kernel.n == 3 and red.forced.size == 0


DOM_EDGES = [[0, 1], [1, 2], [0, 3], [1, 3], [2, 3], [3, 4]]


def test_domination_removes_the_vertex_with_the_larger_neighbourhood():
    # N[1] = {0,1,2,3} is inside N[3] = {0,1,2,3,4} and w(1) = 2 >= w(3) = 1.5 -> remove 3.
    # No vertex is simplicial-and-heaviest at first (N(1) and N(3) are not cliques; 0, 2 and 4
    # are lighter than a neighbour), so it is the domination rule that fires.
    p = MwisProblem.from_arrays([1.0, 2.0, 1.0, 1.5, 1.0], DOM_EDGES)
    red = reduce_problem(p)
    assert red.counts["reduce_dominated"] == 1
    assert 3 not in red.kept.tolist() and 3 not in red.forced.tolist()
    assert red.forced.tolist() == [4]  # isolated once 3 is gone
    assert red.kept.tolist() == [0, 1, 2]
    _, sel = _lifted_optimum(p)
    assert p.objective(sel) == pytest.approx(brute_force_mwis(p)[1])


def test_domination_direction_lighter_small_neighbourhood_removes_nothing():
    # Same graph with w(1) = 1.4 < w(3) = 1.5: 1 does not dominate 3 (and 3 does not dominate 1,
    # its neighbourhood is larger) -> nothing removed by domination in the first round.
    p = MwisProblem.from_arrays([1.0, 1.4, 1.0, 1.5, 1.0], DOM_EDGES)
    red = reduce_problem(p)
    assert 3 in red.kept.tolist() or 3 in red.forced.tolist()
    _, sel = _lifted_optimum(p)
    assert p.objective(sel) == pytest.approx(brute_force_mwis(p)[1])


def test_twins_with_equal_weight_keep_one():
    # Two identical candidates (same closed neighbourhood, same weight): only one may be removed.
    p = MwisProblem.from_arrays([1.0, 1.0, 1.5], [[0, 1], [0, 2], [1, 2]])
    reduce_problem(p)
    _, sel = _lifted_optimum(p)
    assert p.objective(sel) == 1.5
    q = MwisProblem.from_arrays([1.0, 1.0], [[0, 1]])
    _, sel = _lifted_optimum(q)
    assert q.objective(sel) == 1.0 and q.is_independent(sel)


def _random_problem(rng, n):
    # Paper-like: requests of up to 5 candidates as clique groups plus random conflicts; small
    # integer weights make ties (and so the tie rules) common; some weights are 0.
    groups, v = [], 0
    while v < n:
        k = int(rng.integers(1, 6))
        groups.append(list(range(v, min(v + k, n))))
        v += k
    m = int(rng.integers(0, 2 * n + 1))
    e = rng.integers(0, n, size=(m, 2))
    e = e[e[:, 0] != e[:, 1]]
    if rng.random() < 0.5:
        w = rng.integers(0, 4, n).astype(float)
    else:
        w = rng.uniform(0, 1, n)
    return MwisProblem.from_arrays(w, e, groups)


def test_reductions_never_change_the_optimum():
    rng = np.random.default_rng(2026)
    for trial in range(300):
        p = _random_problem(rng, int(rng.integers(1, 15)))
        red, sel = _lifted_optimum(p)
        assert p.is_independent(sel), trial
        assert p.objective(sel) == pytest.approx(brute_force_mwis(p)[1], abs=1e-12), trial
        done = complete_maximal(p, sel)
        assert p.is_independent(done) and p.objective(done) >= p.objective(sel) - 1e-12


def test_sparse_path_matches_dense_path(monkeypatch):
    import uam_solvers.reductions as red_mod

    rng = np.random.default_rng(5)
    for _ in range(80):
        p = _random_problem(rng, int(rng.integers(5, 60)))
        dense = reduce_problem(p)
        monkeypatch.setattr(red_mod, "_DENSE_MAX", 0)
        sparse = reduce_problem(p)
        monkeypatch.setattr(red_mod, "_DENSE_MAX", 256)
        assert dense.kept.tolist() == sparse.kept.tolist()
        assert dense.forced.tolist() == sparse.forced.tolist()
