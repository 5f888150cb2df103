"""The clique branch and bound of ``auto`` (uam_solvers.cliquebb) and solve()'s small-graph fast
path: optimal against brute force, the same answer as through the pipeline, bad input still
named by the full validation, and the KaMIS path taking over past the node limit."""
import numpy as np
import pytest

import uam_solvers
from uam_solvers import MwisInputError
from uam_solvers.base import MwisProblem, brute_force_mwis
from uam_solvers.cliquebb import clique_branch_and_bound, exact_integer_weights, solve_small_arrays
from uam_solvers.instances import generate_corpus_entries


def _random_problem(rng, n):
    """Random graph with clique groups (some overlapping), free vertices, repeated edges, ties
    and zero weights."""
    weights = rng.choice([0.0, 0.25, 0.5, 1.0, 1.0, rng.random()], size=n)
    m = int(rng.integers(0, 2 * n + 1))
    edges = rng.integers(0, n, size=(m, 2))
    edges = edges[edges[:, 0] != edges[:, 1]]
    groups = []
    perm = rng.permutation(n)
    start = 0
    while start < n - 2:
        k = int(rng.integers(1, 5))
        groups.append(perm[start:start + k].tolist())
        start += k
    if n >= 4 and rng.random() < 0.5:
        groups.append([int(perm[0]), int(perm[-1])])  # overlaps an earlier group
    return weights, edges, groups


@pytest.mark.parametrize("seed", range(40))
def test_branch_and_bound_is_optimal_against_brute_force(seed):
    rng = np.random.default_rng(seed)
    w, e, g = _random_problem(rng, int(rng.integers(1, 15)))
    p = MwisProblem.from_arrays(w, e, g)
    sel, nodes = clique_branch_and_bound(p)
    assert sel is not None and nodes >= 1
    assert p.is_independent(sel)
    assert p.objective(sel) == pytest.approx(brute_force_mwis(p)[1], abs=1e-12)
    # the fast path from the raw arrays (repeated edges, unsorted groups) gives the same set
    fast = uam_solvers.solve(w, e, g, backend="auto", time_limit_s=1.0)
    assert fast.selected.tolist() == sel and fast.proven_optimal
    assert fast.stats["auto_method"] == "clique-bb"


def test_corpus_fast_path_matches_pipeline_and_exact_objective():
    # warm first: a cold 'auto' in a loaded process can spend its 1 s on imports and answer
    # with the flagged greedy fallback (the limit holds cold, by design); this test compares
    # the two paths' answers, not the cold start
    uam_solvers.warm_up(["auto", "exact"])
    for entry in generate_corpus_entries(40, 5, 50, seed=3):
        p = entry.problem
        fast = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="auto",
                                 time_limit_s=1.0)
        through = uam_solvers.solve_problem(p, backend="auto", time_limit_s=1.0)
        exact = uam_solvers.solve_problem(p, backend="exact", time_limit_s=30.0, layers=False)
        assert exact.proven_optimal
        assert fast.selected.tolist() == through.selected.tolist()
        assert through.stats["auto_method"] == "clique-bb" and through.proven_optimal
        assert fast.objective == pytest.approx(exact.objective, abs=1e-9)


def test_exact_integer_weights_keep_differences_below_any_rounding():
    # {1, 2} beats {0} by 1e-12: invisible to integer weights at resolution 10^6, not here
    assert exact_integer_weights([1.0, 0.5, 0.5 + 1e-12]) != [2, 1, 1]
    res = uam_solvers.solve([1.0, 0.5, 0.5 + 1e-12], [[0, 1], [0, 2]], backend="auto")
    assert res.selected.tolist() == [1, 2] and res.proven_optimal


def test_node_limit_hands_over_to_kamis_without_claiming_anything():
    p = generate_corpus_entries(1, 50, 50, seed=1)[0].problem
    assert clique_branch_and_bound(p, node_limit=1) == (None, 2)
    assert solve_small_arrays(p.weights, p.edges, list(p.groups), node_limit=1) is None
    # a generous limit: KaMIS gets a fifth of it (at most 1 s) and finishes in milliseconds on a
    # quiet machine, but a loaded one can take longer than 0.2 s and hand over to CP-SAT
    res = uam_solvers.solve_problem(p, backend="auto", time_limit_s=10.0,
                                    options={"bb_node_limit": 1})
    assert res.stats["auto_method"] == "kamis" and p.is_independent(res.selected)
    best = uam_solvers.solve_problem(p, backend="auto", time_limit_s=1.0)
    assert res.objective == pytest.approx(best.objective, abs=1e-5)


@pytest.mark.parametrize("weights, edges, groups, field", [
    ([1.0, float("nan"), 1.0], [[0, 1]], None, "weights[1]"),
    ([1.0, -1.0], [], None, "weights[1]"),
    ([1.0, 1.0], [[0, 2]], None, "edges[0]"),
    ([1.0, 1.0], [[1, 1]], None, "edges[0]"),
    ([1.0, 1.0, 1.0], [[0, 1]], [[0, 1], [2, 5]], "groups[1]"),
    ([1.0, 1.0, 1.0], [[0, 1]], [[0, 1], [0.5, 2]], "groups[1]"),
])
def test_bad_input_is_still_named_by_the_full_validation(weights, edges, groups, field):
    with pytest.raises(MwisInputError, match=field.replace("[", r"\[").replace("]", r"\]")):
        uam_solvers.solve(weights, edges, groups, backend="auto")


def test_options_and_sizes_outside_the_fast_path_take_the_pipeline():
    p = generate_corpus_entries(1, 20, 20, seed=2)[0].problem
    with pytest.raises(MwisInputError, match="options"):
        uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="auto", options=[])
    with pytest.raises(MwisInputError, match="max_vertices"):
        uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="auto", max_vertices=10)
    # numpy integers inside a list group are valid input: same answer through either path
    groups = [[np.int64(v) for v in g] for g in p.groups]
    a = uam_solvers.solve(p.weights, p.edges, groups, backend="auto")
    b = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="auto")
    assert a.selected.tolist() == b.selected.tolist()


def test_a_graph_without_useful_groups_goes_to_kamis_not_the_search():
    # issue 20: 50 vertices given without groups are 50 one-vertex cliques; the search ran past
    # its node limit (70 ms) before KaMIS (0.1 ms) took over. Both paths (the arrays' fast path
    # and the pipeline) skip it alike, and the answer is the same optimum either way.
    from uam_solvers.cliquebb import SMALL_MAX_COVER, clique_cover_size
    from uam_solvers.instances import grouped_random_instance

    p = grouped_random_instance(50, seed=0)
    bare = MwisProblem.from_arrays(p.weights, p.edges)
    assert clique_cover_size(p.n, p.groups) <= SMALL_MAX_COVER < clique_cover_size(bare.n, ())
    assert solve_small_arrays(bare.weights, bare.edges, None, node_limit=10**6) is None
    through = uam_solvers.solve(bare.weights, bare.edges, None, backend="auto", time_limit_s=60.0)
    assert through.stats["auto_method"] == "kamis" and through.proven_optimal
    grouped = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="auto",
                                time_limit_s=60.0)
    assert grouped.stats["auto_method"] == "clique-bb"
    assert through.objective == pytest.approx(grouped.objective, abs=1e-9)
    # the option lets the search take it again
    forced = uam_solvers.solve_problem(bare, backend="auto", time_limit_s=60.0,
                                       options={"bb_max_cover": 64, "bb_node_limit": 10**7})
    assert forced.stats["auto_method"] == "clique-bb"
    assert forced.objective == pytest.approx(through.objective, abs=1e-9)


def test_the_search_keeps_its_tie_break_on_tied_corpus_graphs():
    """The paper mode's answers depend on which of several tied optima the search returns (the
    first in its order). Pinned: the selections and node counts on 120 corpus graphs, each with
    its own weights, rounded to 0.1 (ties) and all 1.0, as the implementation at 45274a7 (before
    the set-up was rebuilt for speed, issue 20) returned them. A change of search order fails
    here even when every answer is still optimal."""
    import hashlib

    h = hashlib.sha256()
    for entry in generate_corpus_entries(120, 5, 50, seed=11):
        p = entry.problem
        for w in (p.weights, np.round(p.weights, 1), np.ones(p.n)):
            q = MwisProblem(weights=np.asarray(w, dtype=float), edges=p.edges, groups=p.groups)
            h.update(repr(clique_branch_and_bound(q)).encode())
    assert h.hexdigest() == "ef8b9b9487f76d067b2cddd77084959ec109142eac95e7313433a46758040c40"
