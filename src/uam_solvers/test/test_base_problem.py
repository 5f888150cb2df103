"""MwisProblem validation and normalisation, MwisResult helpers, integer weight scaling."""
import numpy as np
import pytest

from uam_solvers.base import (MwisInputError, MwisProblem, brute_force_mwis, check_selection,
                              csr_from_edges, integer_weights)


def test_edges_are_normalised_and_groups_expand_to_cliques():
    p = MwisProblem.from_arrays([1, 2, 3, 4], [[1, 0], [0, 1], [3, 2], [2, 3]], groups=[[3, 1, 1]])
    assert p.edges.dtype == np.int32 and p.weights.dtype == np.float64
    assert p.edges.tolist() == [[0, 1], [2, 3]]
    assert [g.tolist() for g in p.groups] == [[1, 3]]
    assert p.all_edges().tolist() == [[0, 1], [1, 3], [2, 3]]
    assert (p.n, p.m) == (4, 2)


@pytest.mark.parametrize("seed", range(30))
def test_all_edges_is_the_union_of_listed_pairs_and_group_cliques(seed):
    """Groups fully, partly or not listed among the edges (the planner lists them; a caller
    may not), disjoint or overlapping: all_edges() is always the set union."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    perm = rng.permutation(n).tolist()
    groups, start = [], 0
    while start < n:
        k = int(rng.integers(1, 6))
        groups.append(perm[start:start + k])
        start += k
    if rng.random() < 0.3:
        groups.append(rng.choice(n, size=min(n, 3), replace=False).tolist())  # overlaps
    pairs = {(min(u, v), max(u, v)) for g in groups for i, u in enumerate(g) for v in g[i + 1:]}
    listed = {e for e in pairs if rng.random() < [1.0, 0.9, 0.0][seed % 3]}
    extra = {(int(u), int(v)) for u, v in rng.integers(0, n, size=(n, 2)) if u < v}
    edges = sorted(listed | extra) or np.zeros((0, 2), dtype=np.int64)
    p = MwisProblem.from_arrays(np.ones(n), edges, groups)
    assert sorted(map(tuple, p.all_edges().tolist())) == sorted(pairs | listed | extra)


def test_empty_graph_and_empty_edges():
    p = MwisProblem.from_arrays([], [])
    assert p.n == 0 and p.all_edges().shape == (0, 2)
    q = MwisProblem.from_arrays([0.5, 0.25], np.zeros((0, 2)), groups=[[1]])
    assert q.groups == () and q.is_independent([0, 1]) and q.objective([0, 1]) == 0.75


@pytest.mark.parametrize(
    "weights, edges, groups, kwargs, expected",
    [
        ([1, 2, 3], [[0, 1], [1, 5]], None, {}, "edges[1]: (1, 5) has a vertex out of range [0, 3)"),
        ([1, 2, 3], [[0, 1], [2, 2]], None, {}, "edges[1]: (2, 2) is a self-loop"),
        ([1, 2, 3], [[-1, 1]], None, {}, "edges[0]: (-1, 1) has a vertex out of range"),
        ([1, float("nan"), 3], [], None, {}, "weights[1]: nan is not finite"),
        ([1, 2, float("inf")], [], None, {}, "weights[2]: inf is not finite"),
        ([1, -0.5, 3], [], None, {}, "weights[1]: -0.5 is negative"),
        ([1, float("-inf"), 3], [], None, {}, "weights[1]: -inf is not finite"),
        ([-1.0, float("nan")], [], None, {}, "weights[1]: nan is not finite"),  # finite first
        (np.array([1.0, 2.0]), np.array([[0, 1], [1, 2]], np.int32), None, {},
         "edges[1]: (1, 2) has a vertex out of range [0, 2)"),
        ([[1, 2]], [], None, {}, "weights: expected a 1-D array, got shape (1, 2)"),
        ([1, 2, 3], [[0, 1, 2]], None, {}, "edges: expected shape (m, 2), got (1, 3)"),
        ([1, 2, 3], [0, 1], None, {}, "edges: expected shape (m, 2), got (2,)"),
        ([1, 2, 3], [[0, 1.5]], None, {}, "edges[0]: (0.0, 1.5) is not a pair of integer vertex indices"),
        ([1, 2, 3], [], [[0, 1], [2, 7]], {}, "groups[1][1]: vertex 7 is out of range [0, 3)"),
        ([1, 2, 3], [], [np.array([0, 1]), np.array([2, 7])], {},
         "groups[1][1]: vertex 7 is out of range [0, 3)"),
        ([1, 2, 3], [], [np.array([0, 1]), np.array([-1, 2])], {}, "groups[1][0]: vertex -1"),
        ([1, 2, 3], [], None, {"max_vertices": 2}, "weights: 3 vertices exceed the limit max_vertices=2"),
        (["a", 2], [], None, {}, "weights: not numeric"),
    ],
)
def test_validation_errors_name_field_and_value(weights, edges, groups, kwargs, expected):
    with pytest.raises(MwisInputError) as err:
        MwisProblem.from_arrays(weights, edges, groups, **kwargs)
    assert expected in str(err.value)


def test_check_selection_reports_each_kind_of_bad_answer():
    p = MwisProblem.from_arrays([1, 1, 1, 1], [[0, 1]], groups=[[2, 3]])
    assert check_selection(p, [0, 2]) == (True, "")
    assert check_selection(p, []) == (True, "")
    assert check_selection(p, [0, 1])[1] == "selected: vertices 0 and 1 conflict"
    assert check_selection(p, [2, 3])[1] == "selected: vertices 2 and 3 conflict"  # group pair
    assert "out of range" in check_selection(p, [0, 4])[1]
    assert "out of range" in check_selection(p, [-1])[1]
    assert "duplicate" in check_selection(p, [0, 0])[1]
    assert "integer" in check_selection(p, [0.0, 2.0])[1]
    assert "1-D" in check_selection(p, [[0, 2]])[1]
    assert not p.is_independent([1, 0])


def test_objective_is_float_sum_of_selected_weights():
    p = MwisProblem.from_arrays([0.1, 0.2, 0.3], [])
    assert p.objective([0, 1, 2]) == pytest.approx(0.6, abs=1e-15)
    assert p.objective([]) == 0.0


def test_integer_weights_scale_to_resolution_and_keep_positive_weights_positive():
    wi, scale = integer_weights(np.array([1.0, 0.5, 1e-9, 0.0]), resolution=1000)
    assert scale == 1000.0
    assert wi.tolist() == [1000, 500, 1, 0]
    wi, scale = integer_weights(np.zeros(3))
    assert wi.tolist() == [0, 0, 0] and scale == 1.0


def test_brute_force_on_hand_checked_graphs():
    # Path 0-1-2 with a heavy middle: take the middle.
    p = MwisProblem.from_arrays([1, 3, 1], [[0, 1], [1, 2]])
    assert brute_force_mwis(p)[0].tolist() == [1]
    # 5-cycle with unit weights: optimum 2.
    c5 = MwisProblem.from_arrays(np.ones(5), [[i, (i + 1) % 5] for i in range(5)])
    assert brute_force_mwis(c5)[1] == 2.0


def test_whole_weights_within_resolution_are_scaled_by_a_whole_factor_without_rounding():
    # max 7, 1000 // 7 = 142: every sum is multiplied by 142 exactly, so the tie 2 + 2 + 3 = 7
    # stays a tie; the general rule (round(w / 7 * 1000)) gives 286 + 286 + 429 = 1001 != 1000
    wi, scale = integer_weights(np.array([2.0, 3.0, 4.0, 5.0, 7.0]), resolution=1000)
    assert scale == 142.0
    assert wi.tolist() == [284, 426, 568, 710, 994]
    assert wi[0] * 2 + wi[1] == wi[4]
    general = np.rint(np.array([2.0, 3.0, 7.0]) / 7.0 * 1000).astype(int)
    assert 2 * general[0] + general[1] != general[2]  # what the factor avoids
    # all ones: as before (the heaviest becomes the resolution)
    assert integer_weights(np.ones(3), resolution=1000)[0].tolist() == [1000] * 3
    # whole weights above the resolution: the general (rounding) rule
    wi, scale = integer_weights(np.array([3000.0, 1500.0]), resolution=1000)
    assert wi.tolist() == [1000, 500]


def test_normalised_groups_and_edges_are_the_set_definition_sorted_or_not():
    # the fast paths for input already sorted and duplicate-free (issue 20) must give what the
    # sort gives: random groups (with empty ones, duplicates, any order) and edge lists
    rng = np.random.default_rng(5)
    for _ in range(1500):
        n = 8
        groups = [rng.integers(0, n, rng.integers(0, 5)).tolist() for _ in range(rng.integers(0, 5))]
        if rng.random() < 0.5:
            groups = [sorted(set(g)) for g in groups]
        e = rng.integers(0, n, (int(rng.integers(0, 9)), 2))
        e = e[e[:, 0] != e[:, 1]]
        if rng.random() < 0.5 and len(e):
            e = np.unique(np.sort(e, axis=1), axis=0)
        p = MwisProblem.from_arrays(np.ones(n), e, groups)
        want_g = [sorted(set(g)) for g in groups if len(set(g)) >= 2]
        assert [g.tolist() for g in p.groups] == want_g, groups
        # the same groups as 1-D integer arrays (the planner's; base._clean_groups' fast path)
        dtype = (np.int32, np.int64, np.uint32)[int(rng.integers(0, 3))]
        pa = MwisProblem.from_arrays(np.ones(n), e, [np.asarray(g, dtype=dtype) for g in groups])
        assert [g.tolist() for g in pa.groups] == want_g, (groups, dtype)
        assert all(g.dtype == np.int32 for g in pa.groups)
        want_e = sorted({(int(min(a, b)), int(max(a, b))) for a, b in e})
        assert [tuple(r) for r in p.edges.tolist()] == want_e, e


def _reference_structure(n, pairs):
    """The sorted keys u * n + v and the CSR (neighbours sorted) of a set of pairs u < v,
    computed plainly."""
    keys = sorted(u * n + v for u, v in pairs)
    nbrs = [[] for _ in range(n)]
    for u, v in pairs:
        nbrs[u].append(v)
        nbrs[v].append(u)
    indptr = np.cumsum([0] + [len(x) for x in nbrs])
    return keys, indptr.tolist(), [w for x in nbrs for w in sorted(x)]


def _structure(p):
    indptr, indices = p.csr()
    return p.edge_keys().tolist(), indptr.tolist(), indices.tolist()


@pytest.mark.parametrize("seed", range(40))
def test_cached_pair_keys_and_csr_equal_a_fresh_computation(seed):
    """The structure MwisProblem computes once and shares (the pairs' keys kept by from_arrays,
    the listed-groups check on them, the CSR, the triangle gate's keys) equals the plain
    computation, for problems built by from_arrays and by the constructor, groups of
    consecutive vertices (the planner's) or not, listed, partly listed or overlapping."""
    rng = np.random.default_rng(seed)
    n = int(rng.integers(2, 40))
    order = np.arange(n) if seed % 2 else rng.permutation(n)
    groups, start = [], 0
    while start < n:
        k = int(rng.integers(1, 6))
        groups.append(sorted(order[start:start + k].tolist()))
        start += k
    if seed % 5 == 0:
        groups.append(sorted(rng.choice(n, size=min(n, 3), replace=False).tolist()))  # overlaps
    pairs = {(u, v) for g in groups for i, u in enumerate(g) for v in g[i + 1:]}
    listed = {e for e in pairs if rng.random() < [1.0, 0.9, 0.0][seed % 3]}
    extra = {(int(u), int(v)) for u, v in rng.integers(0, n, size=(n, 2)) if u < v}
    edges = sorted(listed | extra) or np.zeros((0, 2), dtype=np.int64)
    expected = _reference_structure(n, pairs | listed | extra)
    p = MwisProblem.from_arrays(rng.random(n), edges, groups)
    q = MwisProblem(weights=p.weights, edges=p.edges, groups=p.groups)
    assert _structure(p) == _structure(q) == expected
    # the keys from_arrays keeps are the ones used: a wrong one would show
    if listed | extra and seed % 3 == 0:
        bad = MwisProblem.from_arrays(p.weights, edges, groups)
        keys = bad.__dict__["_listed_keys"].copy()
        keys[-1] += 1
        bad.__dict__["_listed_keys"] = keys
        assert _structure(bad) != expected


def test_csr_of_unsorted_or_sorted_pairs_is_the_same():
    rng = np.random.default_rng(0)
    for _ in range(50):
        n = int(rng.integers(2, 30))
        pairs = {(int(u), int(v)) for u, v in rng.integers(0, n, size=(2 * n, 2)) if u < v}
        if not pairs:
            continue
        e = np.array(sorted(pairs))
        _, indptr, indices = _reference_structure(n, pairs)
        for arr in (e, e[rng.permutation(len(e))]):
            ip, ix = csr_from_edges(n, arr)
            assert (ip.tolist(), ix.tolist()) == (indptr, indices)
            assert ip.dtype == np.int64 and ix.dtype == np.int32


def test_a_remembered_valid_selection_never_passes_another():
    """check_selection answers a selection it found valid on this problem without checking it
    again; any other selection is checked in full."""
    p = MwisProblem.from_arrays(np.ones(5), [[0, 1], [1, 2], [3, 4]], groups=[[2, 3]])
    p.csr()
    assert check_selection(p, np.array([0, 2, 4])) == (True, "")
    assert check_selection(p, np.array([0, 2, 4], dtype=np.int32)) == (True, "")
    assert check_selection(p, np.array([0, 2, 3]))[1] == "selected: vertices 2 and 3 conflict"
    assert check_selection(p, np.array([0, 1, 4]))[1] == "selected: vertices 0 and 1 conflict"
    assert check_selection(p, np.array([0, 2, 4, 4]))[1] == "selected: contains duplicate vertices"
    assert check_selection(p, np.array([0, 2, 5]))[0] is False
    assert check_selection(p, np.array([0.0, 2.0, 4.0]))[0] is False
    assert check_selection(p, np.array([0, 2, 4])) == (True, "")
