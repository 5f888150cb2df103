"""The large graphs' fallback (local maxima of the GWMIN key) reads clique groups as groups: the
same selection, to the vertex, as on the listed edges plus every group pair."""
import numpy as np
import pytest

from uam_solvers.base import MwisProblem
from uam_solvers.greedy import _local_max, _local_max_grouped, fallback_selection


def _grouped(n, edges, groups, weights):
    e = np.asarray(edges, dtype=np.int64).reshape(-1, 2)
    return _local_max_grouped(n, np.concatenate([e[:, 0], e[:, 1]]),
                              np.concatenate([e[:, 1], e[:, 0]]), groups, weights)


def _listed_pairs_answer(n, edges, groups, weights):
    """The reference: every group pair listed beside the edges, both directions, duplicates kept."""
    parts = [np.asarray(edges, dtype=np.int64).reshape(-1, 2)]
    for g in groups:
        g = np.asarray(g, dtype=np.int64)
        iu, ju = np.triu_indices(g.size, k=1)
        parts.append(np.stack([g[iu], g[ju]], axis=1))
    e = np.concatenate(parts)
    return _local_max(n, np.concatenate([e[:, 0], e[:, 1]]), np.concatenate([e[:, 1], e[:, 0]]),
                      weights)


def _case(rng, n, n_groups, m, overlap, ties):
    weights = rng.integers(0, 4, n).astype(float) if ties else rng.random(n)
    groups = []
    for _ in range(n_groups):
        k = int(rng.integers(2, 12))
        if overlap:
            groups.append(np.sort(rng.choice(n, size=min(k, n), replace=False)))
    if not overlap:  # disjoint consecutive groups, as the planner's requests
        bounds = np.sort(rng.choice(np.arange(1, n), size=min(n_groups, n - 1), replace=False))
        groups = [g for g in np.split(np.arange(n), bounds) if g.size >= 2]
    u, v = rng.integers(0, n, m), rng.integers(0, n, m)
    keep = u != v
    edges = np.stack([np.minimum(u, v), np.maximum(u, v)], axis=1)[keep]
    return weights, edges, groups


@pytest.mark.parametrize("seed", range(40))
def test_grouped_local_max_equals_the_listed_pairs(seed):
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 300))
    weights, edges, groups = _case(rng, n, int(rng.integers(0, 40)), int(rng.integers(0, 3 * n)),
                                   overlap=bool(seed % 2), ties=seed % 3 == 0)
    got = _grouped(n, edges, groups, weights)
    assert got.tolist() == _listed_pairs_answer(n, edges, groups, weights).tolist()
    # through the problem (edges normalised, groups deduplicated) as the solve service calls it
    prob = MwisProblem.from_arrays(weights, edges, groups)
    ref = _listed_pairs_answer(prob.n, prob.edges, prob.groups, prob.weights)
    assert _grouped(prob.n, prob.edges, prob.groups, prob.weights).tolist() == ref.tolist()
    assert MwisProblem.from_arrays(weights, edges, groups).is_independent(got)


def test_the_fallback_of_a_large_grouped_graph_is_independent_and_maximal():
    rng = np.random.default_rng(3)
    size, requests = 60, 120   # 7,200 vertices: the fast fallback's side of the threshold
    n = size * requests
    groups = [np.arange(k * size, (k + 1) * size) for k in range(requests)]
    u, v = rng.integers(0, n, 20_000), rng.integers(0, n, 20_000)
    keep = (u // size) != (v // size)
    prob = MwisProblem.from_arrays(rng.random(n), np.stack([u[keep], v[keep]], axis=1), groups)
    sel, rule = fallback_selection(prob)
    assert rule == "local-max gwmin key"
    assert prob.is_independent(sel)
    assert sel.tolist() == _listed_pairs_answer(prob.n, prob.edges, prob.groups, prob.weights).tolist()
    # maximal: every vertex left out has a selected neighbour
    chosen = np.zeros(n, dtype=bool)
    chosen[sel] = True
    e = prob.all_edges()
    covered = chosen.copy()
    covered[e[chosen[e[:, 0]], 1]] = True
    covered[e[chosen[e[:, 1]], 0]] = True
    assert covered.all()
