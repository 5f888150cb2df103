"""The MWIS QUBO, steepest descent and repair, against brute force on small graphs."""


import numpy as np
import pytest

from uam_solvers.base import MwisProblem
from uam_solvers.instances import paper_instance
from uam_solvers.qubo import (
    QuboArrays,
    feasible_mask,
    mwis_bqm,
    mwis_qubo,
    refine_and_repair,
    repair,
    steepest_descent,
)


def all_states(n):
    """(2^n, n) int8: every 0/1 vector."""
    return ((np.arange(2**n)[:, None] >> np.arange(n)) & 1).astype(np.int8)


def random_problem(rng, n, p=0.3, groups=True, w_max=1.0):
    iu, ju = np.triu_indices(n, 1)
    keep = rng.random(len(iu)) < p
    edges = np.stack([iu[keep], ju[keep]], axis=1)
    grp = [np.arange(0, min(3, n))] if groups and n >= 3 else None
    return MwisProblem.from_arrays(rng.uniform(0.05, w_max, n), edges, groups=grp)


def brute_force_mwis(problem):
    x = all_states(problem.n)
    ok = feasible_mask(x, problem.all_edges())
    objectives = np.where(ok, x @ problem.weights, -np.inf)
    return float(objectives.max())


def test_energy_is_minus_objective_on_independent_sets():
    rng = np.random.default_rng(0)
    for _ in range(5):
        p = random_problem(rng, 9)
        q = mwis_qubo(p)
        x = all_states(p.n)
        ok = feasible_mask(x, p.all_edges())
        assert np.allclose(q.energies(x[ok]), -(x[ok] @ p.weights))
        # each violated edge costs lambda = 2
        violated = (x[:, p.all_edges()[:, 0]] & x[:, p.all_edges()[:, 1]]).sum(axis=1)
        assert np.allclose(q.energies(x), -(x @ p.weights) + 2.0 * violated)


def test_bqm_matches_arrays_and_round_trips():
    p = paper_instance(3, seed=2)
    q = mwis_qubo(p)
    bqm = mwis_bqm(p)
    x = all_states(p.n)[::997]
    assert np.allclose(bqm.energies((x, range(p.n))), q.energies(x))
    back = QuboArrays.from_bqm(bqm)
    assert np.allclose(back.energies(x), q.energies(x))


def test_qubo_minimum_is_the_mwis_and_every_local_minimum_is_independent():
    """lambda = 2 > max weight: brute force over all 2^n states of random graphs."""
    rng = np.random.default_rng(1)
    for n in (6, 8, 10, 11):
        p = random_problem(rng, n, p=0.35)
        q = mwis_qubo(p)
        x = all_states(n)
        energy = q.energies(x)
        assert np.isclose(energy.min(), -brute_force_mwis(p))
        minimisers = x[np.isclose(energy, energy.min())]
        assert feasible_mask(minimisers, p.all_edges()).all()
        # one-flip local minima: no single flip lowers the energy
        flips = x[:, None, :] ^ np.eye(n, dtype=np.int8)[None]
        flip_energy = q.energies(flips.reshape(-1, n)).reshape(len(x), n)
        local = (flip_energy >= energy[:, None] - 1e-12).all(axis=1)
        assert feasible_mask(x[local], p.all_edges()).all()


def test_lambda_not_above_max_weight_can_make_the_minimum_infeasible():
    # two conflicting vertices of weight 3: E(both) = -6 + 2 = -4 < E(one) = -3
    p = MwisProblem.from_arrays([3.0, 3.0], [[0, 1]])
    q = mwis_qubo(p, lam=2.0)
    x = all_states(2)
    best = x[np.argmin(q.energies(x))]
    assert best.tolist() == [1, 1]
    # the repaired answer is still an independent set of the best weight
    selected, stats = refine_and_repair(p, q, best[None])
    assert len(selected) == 1 and stats["best_objective"] == 3.0
    assert stats["lambda_exceeds_max_weight"] is False


def test_steepest_descent_never_increases_energy_and_ends_in_a_local_minimum():
    rng = np.random.default_rng(2)
    p = paper_instance(6, seed=3)
    q = mwis_qubo(p)
    x = rng.integers(0, 2, size=(64, p.n))
    before = q.energies(x)
    after_x, after = steepest_descent(q, x)
    assert np.all(after <= before + 1e-12)
    assert np.allclose(after, q.energies(after_x))
    # no single flip improves any read, and (lambda > max w) every read is independent
    for read in after_x[:8]:
        flips = read[None, :] ^ np.eye(p.n, dtype=np.int8)
        assert np.all(q.energies(flips) >= q.energies(read)[0] - 1e-12)
    assert feasible_mask(after_x, p.all_edges()).all()
    again, _ = steepest_descent(q, x)
    assert np.array_equal(again, after_x)


def test_steepest_descent_on_a_hand_example():
    # path 0-1-2, weights 0.5, 1.0, 0.4, all selected: E = -1.9 + 4 = 2.1.
    # flip gains: x0 -> 0: 0.5 - 2 = -1.5, x1 -> 0: 1 - 4 = -3, x2 -> 0: 0.4 - 2 = -1.6;
    # steepest drops 1 (E = -0.9), then nothing improves.
    p = MwisProblem.from_arrays([0.5, 1.0, 0.4], [[0, 1], [1, 2]])
    x, e = steepest_descent(mwis_qubo(p), [1, 1, 1])
    assert x.tolist() == [[1, 0, 1]] and np.isclose(e[0], -0.9)


def test_repair_hand_examples():
    w = np.array([0.5, 1.0, 0.3, 0.9])
    edges = np.array([[0, 1], [1, 2], [2, 3]])
    # violated 0-1 drops 0 (lighter); then 2 is blocked by 1, 3 is free -> added
    assert repair([1, 1, 0, 0], w, edges).tolist() == [[0, 1, 0, 1]]
    # nothing selected: greedy by weight picks 1, then 3
    assert repair([0, 0, 0, 0], w, edges).tolist() == [[0, 1, 0, 1]]
    # equal weights on a violated edge: the higher index is dropped
    assert repair([1, 1], [1.0, 1.0], [[0, 1]]).tolist() == [[1, 0]]


def test_repair_gives_maximal_independent_sets_and_keeps_feasible_reads():
    rng = np.random.default_rng(4)
    for _ in range(5):
        p = random_problem(rng, 12, p=0.3)
        e = p.all_edges()
        x = rng.integers(0, 2, size=(200, p.n))
        fixed = repair(x, p.weights, e)
        assert feasible_mask(fixed, e).all()
        # maximal: every unselected vertex has a selected neighbour
        adjacency = p.adjacency().toarray()
        blocked = fixed @ adjacency
        assert np.all((fixed == 1) | (blocked > 0))
        # a feasible read keeps all its vertices, so its objective never drops
        ok = feasible_mask(x, e)
        assert np.all(fixed[ok] >= x[ok])
        assert np.all(fixed[ok] @ p.weights >= x[ok] @ p.weights - 1e-12)


def test_refine_and_repair_statistics():
    p = MwisProblem.from_arrays([0.6, 1.0, 0.7, 0.5], [[0, 1], [1, 2], [2, 3]])  # path
    q = mwis_qubo(p)
    reads = np.array([[0, 1, 0, 1],    # optimum 1.5, feasible
                      [1, 0, 1, 0],    # 1.3, feasible
                      [1, 1, 1, 1]])   # infeasible raw
    selected, stats = refine_and_repair(p, q, reads, optimum=1.5)
    assert selected.tolist() == [1, 3]
    assert stats["reads"] == 3
    assert stats["best_objective"] == pytest.approx(1.5)
    assert stats["feasible_fraction_raw"] == pytest.approx(2 / 3)
    assert stats["feasible_fraction"] == 1.0  # descent already fixes the violated read
    # [1,1,1,1] descends to [1,1,0,1] (drops 2, the largest gain) then to [0,1,0,1]
    assert stats["optimal_fraction"] == pytest.approx(2 / 3)
    assert stats["energy_min"] == pytest.approx(-1.5)
