"""CP-SAT exact backend: hand-checked graphs and agreement with brute force up to 16 vertices."""
import numpy as np
import pytest

from uam_solvers.base import MwisProblem, brute_force_mwis
from uam_solvers.cpsat import CpSatBackend, uncovered_edges


def _solve(p, **options):
    return CpSatBackend().solve(p, time_limit_s=10.0, seed=0, options=options)


def test_hand_checked_graphs():
    # 5-cycle, unit weights: optimum 2.
    c5 = MwisProblem.from_arrays(np.ones(5), [[i, (i + 1) % 5] for i in range(5)])
    r = _solve(c5)
    assert r.objective == 2.0 and r.proven_optimal and c5.is_independent(r.selected)
    # Star with light leaves: 3 leaves (6) beat the centre (5).
    star = MwisProblem.from_arrays([5.0, 2.0, 2.0, 2.0], [[0, 1], [0, 2], [0, 3]])
    assert _solve(star).selected.tolist() == [1, 2, 3]
    # Groups only: best of each clique.
    g = MwisProblem.from_arrays([0.2, 0.9, 0.5, 0.7], [], groups=[[0, 1], [2, 3]])
    r = _solve(g)
    assert r.selected.tolist() == [1, 3] and r.objective == pytest.approx(1.6)
    assert r.stats["status"] == "OPTIMAL" and r.backend == "exact"


def test_edges_inside_groups_are_not_duplicated_as_constraints():
    p = MwisProblem.from_arrays(np.ones(5), [[0, 1], [1, 2], [3, 4]], groups=[[0, 1, 2]])
    assert uncovered_edges(p).tolist() == [[3, 4]]
    # Overlapping groups take the general path.
    q = MwisProblem.from_arrays(np.ones(5), [[0, 1], [1, 3], [2, 4], [0, 4]],
                                groups=[[0, 1, 2], [2, 3, 4], [1, 3]])
    assert uncovered_edges(q).tolist() == [[0, 4]]


def test_objective_is_recomputed_from_float_weights():
    w = np.array([1 / 3, 1 / 7, 2 / 9])
    p = MwisProblem.from_arrays(w, [[0, 1]])
    r = _solve(p)
    assert r.selected.tolist() == [0, 2]
    assert r.objective == p.objective([0, 2])


def test_agrees_with_brute_force_on_random_graphs_up_to_16_vertices():
    rng = np.random.default_rng(16)
    for trial in range(120):
        n = int(rng.integers(1, 17))
        density = rng.uniform(0.05, 0.6)
        iu, ju = np.triu_indices(n, 1)
        keep = rng.random(iu.size) < density
        e = np.stack([iu[keep], ju[keep]], 1)
        groups = [list(range(s, min(s + 5, n))) for s in range(0, n, 5)] if trial % 2 else None
        w = rng.uniform(0, 1, n)
        p = MwisProblem.from_arrays(w, e, groups)
        r = _solve(p)
        assert r.proven_optimal and p.is_independent(r.selected), trial
        # Integer scaling at 10^6 resolution: within n * max(w) / 2e6 of the float optimum.
        assert r.objective == pytest.approx(brute_force_mwis(p)[1], abs=n * 1e-6), trial


def test_is_deterministic_for_a_seed():
    rng = np.random.default_rng(3)
    n = 40
    e = rng.integers(0, n, size=(120, 2))
    e = e[e[:, 0] != e[:, 1]]
    p = MwisProblem.from_arrays(rng.integers(1, 3, n).astype(float), e)  # many equal optima
    runs = [CpSatBackend().solve(p, time_limit_s=10.0, seed=5, options={}).selected.tolist() for _ in range(3)]
    assert runs[0] == runs[1] == runs[2]


def test_unknown_option_is_refused():
    p = MwisProblem.from_arrays([1.0], [])
    with pytest.raises(ValueError, match="unknown option"):
        CpSatBackend().solve(p, time_limit_s=1.0, seed=0, options={"workers": 2})
