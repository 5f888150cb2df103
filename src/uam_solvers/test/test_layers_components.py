"""ComponentSplit and Reduce layers never change the optimum; trivial components are answered
directly; the default pipeline nests them around any backend."""
import numpy as np
import pytest

import uam_solvers
from uam_solvers.base import Backend, MwisProblem, brute_force_mwis, make_result
from uam_solvers.layers import ComponentSplit, Reduce, induced_subproblem


class BruteForce(Backend):
    """Reference backend; records the size of every problem it is given."""

    name = "brute"
    description = "test: enumerate all subsets"

    def __init__(self):
        self.calls = []

    def solve(self, problem, *, time_limit_s, seed, options):
        self.calls.append((problem.n, time_limit_s))
        sel, _ = brute_force_mwis(problem)
        return make_result(problem, sel, proven_optimal=True, solve_time_s=0.0, backend=self.name,
                           stats={"inner_n": problem.n})


def _random_problem(rng, n):
    groups, v = [], 0
    while v < n:
        k = int(rng.integers(1, 6))
        groups.append(list(range(v, min(v + k, n))))
        v += k
    e = rng.integers(0, n, size=(int(rng.integers(0, n + 2)), 2))
    e = e[e[:, 0] != e[:, 1]]
    w = rng.integers(0, 4, n).astype(float) if rng.random() < 0.5 else rng.uniform(0, 1, n)
    return MwisProblem.from_arrays(w, e, groups)


def test_component_split_answers_isolated_vertices_and_cliques_without_the_child():
    # Components: {0} alone, clique {1,2,3} (a request nobody conflicts with), path 4-5-6.
    p = MwisProblem.from_arrays([0.3, 0.5, 0.9, 0.9, 1.0, 3.0, 1.0], [[4, 5], [5, 6]],
                                groups=[[1, 2, 3]])
    child = BruteForce()
    r = ComponentSplit(child).solve(p, time_limit_s=1.0, seed=0, options={})
    assert r.selected.tolist() == [0, 2, 5]  # tie 2 vs 3 -> lowest index
    assert r.proven_optimal and r.backend == "brute"
    assert r.stats["components"] == 3 and r.stats["trivial_components"] == 2
    assert child.calls == [(3, pytest.approx(1.0, rel=0.1))]


def test_component_split_shares_time_by_size():
    # Two paths of 3 and 6 vertices: the smaller goes first with about a third of the budget.
    e = [[0, 1], [1, 2]] + [[3 + i, 4 + i] for i in range(5)]
    p = MwisProblem.from_arrays(np.ones(9), e)
    child = BruteForce()
    ComponentSplit(child, batch_below=0).solve(p, time_limit_s=9.0, seed=0, options={})
    assert [c[0] for c in child.calls] == [3, 6]
    assert child.calls[0][1] == pytest.approx(3.0, rel=0.05)
    assert child.calls[1][1] == pytest.approx(9.0, rel=0.05)  # whatever is left


def test_small_or_batching_children_get_one_call_for_all_components():
    e = [[0, 1], [1, 2]] + [[3 + i, 4 + i] for i in range(5)]
    p = MwisProblem.from_arrays(np.ones(9), e)
    child = BruteForce()
    r = ComponentSplit(child).solve(p, time_limit_s=1.0, seed=0, options={})  # 9 <= 64 vertices
    assert [c[0] for c in child.calls] == [9] and r.objective == 5.0
    batching = BruteForce()
    batching.batch_components = True
    r = ComponentSplit(batching, batch_below=0).solve(p, time_limit_s=1.0, seed=0, options={})
    assert [c[0] for c in batching.calls] == [9] and r.objective == 5.0


def test_induced_subproblem_keeps_edges_and_groups():
    p = MwisProblem.from_arrays(np.arange(6, dtype=float), [[0, 5], [2, 4]], groups=[[1, 2, 3], [4, 5]])
    sub = induced_subproblem(p, np.array([2, 3, 4]))
    assert sub.weights.tolist() == [2.0, 3.0, 4.0]
    assert sub.edges.tolist() == [[0, 2]]
    assert [g.tolist() for g in sub.groups] == [[0, 1]]


@pytest.mark.parametrize("layer", ["components", "split-each", "reduce", "both"])
def test_layers_never_change_the_optimum(layer):
    rng = np.random.default_rng({"components": 1, "split-each": 4, "reduce": 2, "both": 3}[layer])
    for trial in range(150):
        p = _random_problem(rng, int(rng.integers(1, 15)))
        child = BruteForce()
        wrapped = {"components": ComponentSplit(child), "reduce": Reduce(child),
                   "split-each": ComponentSplit(child, batch_below=0),
                   "both": Reduce(ComponentSplit(child))}[layer]
        r = wrapped.solve(p, time_limit_s=5.0, seed=0, options={})
        assert p.is_independent(r.selected), trial
        assert r.objective == pytest.approx(brute_force_mwis(p)[1], abs=1e-12), trial
        assert r.objective == pytest.approx(p.objective(r.selected), abs=0)
        assert r.proven_optimal


def test_reduce_reports_counts_and_skips_child_on_empty_kernel():
    p = MwisProblem.from_arrays([1.0, 0.5, 0.2], [[0, 1], [1, 2]])  # 0 simplicial & heaviest
    child = BruteForce()
    r = Reduce(child).solve(p, time_limit_s=1.0, seed=0, options={})
    assert r.selected.tolist() == [0, 2] and r.proven_optimal
    assert child.calls == [] and r.stats["kernel_vertices"] == 0


def test_default_pipeline_on_hand_checked_graph_for_each_builtin_backend():
    # Two requests of three candidates, candidate 0 of request A conflicts with candidate 3 of B.
    # Optimum: 0 (1.0) + 4 (0.9) = 1.9.
    w = [1.0, 0.8, 0.5, 1.0, 0.9, 0.4]
    groups = [[0, 1, 2], [3, 4, 5]]
    edges = [[0, 3], [1, 3]]
    for backend in ("greedy", "exact", "kamis", "chils"):
        r = uam_solvers.solve(w, edges, groups, backend=backend, time_limit_s=0.2)
        assert r.objective == pytest.approx(1.9), backend
        assert r.selected.tolist() == [0, 4], backend
        assert not r.fallback
    r = uam_solvers.solve(w, edges, groups, backend="exact", layers=False)
    assert r.objective == pytest.approx(1.9) and r.proven_optimal


def test_label_propagation_components_match_scipy():
    from scipy.sparse.csgraph import connected_components

    from uam_solvers.layers import _components

    rng = np.random.default_rng(8)
    for _ in range(30):
        p = _random_problem(rng, int(rng.integers(1, 120)))
        count, labels = _components(p)
        ref_count, ref = connected_components(p.adjacency(), directed=False)
        assert count == ref_count
        # Same partition: labels map one-to-one onto scipy's.
        pairs = set(zip(labels.tolist(), ref.tolist()))
        assert len(pairs) == count


def test_reduce_hands_large_graphs_to_self_reducing_backends_unchanged():
    child = BruteForce()
    child.reduces_itself = True
    # Path 0-1-2 plus an isolated vertex 3: reducible, but above the threshold it is passed on.
    p = MwisProblem.from_arrays([1.0, 3.0, 1.0, 0.5], [[0, 1], [1, 2]])
    r = Reduce(ComponentSplit(child), self_reduce_above=2).solve(p, time_limit_s=1.0, seed=0, options={})
    assert r.objective == 3.5
    assert child.calls[0][0] == 3  # ComponentSplit took the isolated vertex, Reduce did nothing
    assert "kernel_vertices" not in r.stats
    child.calls.clear()
    r = Reduce(ComponentSplit(child)).solve(p, time_limit_s=1.0, seed=0, options={})
    assert r.objective == 3.5 and r.stats["kernel_vertices"] == 3
