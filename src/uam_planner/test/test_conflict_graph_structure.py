"""Conflict graph: deconfliction against active flights, cliques, conflict edges."""

import itertools

import numpy as np
import pytest

from uam_planner.candidates import CandidateCache
from uam_planner.conflict_graph import build_conflict_graph
from uam_planner.separation import min_separation_m
from uam_planner.synthetic import generate_network


def scenario(seed, n_requests=8, n_active=10):
    net = generate_network(50, 6, seed=seed)
    cache = CandidateCache(net, k=5, penalty_factor=5.0, speed_mps=10.0)
    rng = np.random.default_rng(seed)
    t = 600.0
    trajs, req, idx, w = [], [], [], []
    for r in range(n_requests):
        o, d = rng.choice(net.aerodrome_indices, 2, replace=False)
        for tp in cache.templates(o, d):
            trajs.append(tp.trajectory(t))
            req.append(r)
            idx.append(tp.route.candidate_index)
            w.append(tp.route.weight)
    active = []
    for _ in range(n_active):
        o, d = rng.choice(net.aerodrome_indices, 2, replace=False)
        active.append(cache.templates(o, d)[0].trajectory(t - float(rng.uniform(0.0, 300.0))))
    return trajs, np.array(req), np.array(idx), np.array(w), n_requests, active


@pytest.mark.parametrize("seed", range(5))
def test_graph_matches_brute_force(seed):
    trajs, req, idx, w, n_req, active = scenario(seed)
    g = build_conflict_graph(trajs, req, idx, w, n_req, active, separation_m=100.0)
    discarded = np.array([any(min_separation_m(c, a) < 100.0 for a in active) for c in trajs])
    assert g.discarded.tolist() == discarded.tolist()
    assert g.n_candidates == len(trajs) and g.n_discarded == int(discarded.sum())
    keep = np.flatnonzero(~discarded)
    assert g.vertex_source.tolist() == keep.tolist()
    assert g.vertex_request.tolist() == req[keep].tolist()
    assert g.vertex_candidate.tolist() == idx[keep].tolist()
    assert g.weights.dtype == np.float64 and g.weights.tolist() == w[keep].tolist()
    assert g.edges.dtype == np.int32 and g.edges.shape[1] == 2
    assert np.all(g.edges[:, 0] < g.edges[:, 1])
    assert len({tuple(e) for e in g.edges.tolist()}) == g.n_edges
    edge_set = {tuple(e) for e in g.edges.tolist()}
    expect = set()
    for u, v in itertools.combinations(range(len(keep)), 2):
        same = req[keep[u]] == req[keep[v]]
        if same or min_separation_m(trajs[keep[u]], trajs[keep[v]]) < 100.0:
            expect.add((u, v))
    assert edge_set == expect
    # Each request's vertices form a complete clique, and groups list them.
    for r, grp in enumerate(g.groups):
        assert sorted(grp.tolist()) == [v for v in range(len(keep)) if req[keep[v]] == r]
        for u, v in itertools.combinations(sorted(grp.tolist()), 2):
            assert (u, v) in edge_set
    assert g.n_clique_edges == sum(len(x) * (len(x) - 1) // 2 for x in g.groups)
    assert g.n_clique_edges + g.n_conflict_edges == g.n_edges


def test_scenarios_exercise_discards_and_conflicts():
    # Guard against the structure test passing vacuously.
    total_disc = total_conf = 0
    for seed in range(5):
        trajs, req, idx, w, n_req, active = scenario(seed)
        g = build_conflict_graph(trajs, req, idx, w, n_req, active, separation_m=100.0)
        total_disc += g.n_discarded
        total_conf += g.n_conflict_edges
    assert total_disc > 0 and total_conf > 0


def test_empty_inputs():
    g = build_conflict_graph([], np.zeros(0), np.zeros(0), np.zeros(0), 0, [], 100.0)
    assert g.n_vertices == 0 and g.n_edges == 0 and g.edges.shape == (0, 2)


# ---- the rolling horizon's pair cache ----------------------------------------------------------------

def test_candidate_pair_cache_gives_the_pairs_of_a_full_check():
    """Two calls whose candidates overlap (the second drops some and adds new ones, in another
    order): each answer is the brute-force set of conflicting pairs of different requests, and the
    second reuses the pairs among the candidates both calls share."""
    from uam_planner.conflict_graph import CandidatePairCache

    trajs, req, _, _, _, _ = scenario(3, n_requests=10, n_active=0)
    n = len(trajs)
    cache = CandidatePairCache()

    def brute(ix):
        return sorted((u, v) for u, v in itertools.combinations(range(len(ix)), 2)
                      if req[ix[u]] != req[ix[v]] and min_separation_m(trajs[ix[u]], trajs[ix[v]]) < 100.0)

    first = list(range(0, 2 * n // 3))
    second = list(range(n // 3, n))  # shares n/3 .. 2n/3 with the first, in the same order
    for ix in (first, second):
        got = cache.conflicts([("r", i) for i in ix], [trajs[i] for i in ix], req[ix], 100.0, 120.0)
        assert [tuple(p) for p in got.tolist()] == brute(ix)
    shared = set(first) & set(second)
    expect_reused = sum(1 for u, v in brute(first) if first[u] in shared and first[v] in shared)
    assert expect_reused > 0 and cache.reused_pairs == expect_reused
    assert cache.checked_new == len(first) + len(set(second) - shared)


def test_candidate_pair_cache_refuses_keys_that_do_not_name_the_candidates():
    from uam_planner.conflict_graph import CandidatePairCache

    trajs, req, _, _, _, _ = scenario(0, n_requests=2, n_active=0)
    with pytest.raises(ValueError, match=r"keys: 1 keys for 2 candidates"):
        CandidatePairCache().conflicts([0], trajs[:2], req[:2], 100.0, 120.0)
    with pytest.raises(ValueError, match=r"keys: 1 of 2 keys repeat an earlier one"):
        CandidatePairCache().conflicts([0, 0], trajs[:2], req[:2], 100.0, 120.0)


@pytest.mark.parametrize("layered", [False, True], ids=["sphere", "levels-cylinder"])
def test_planner_horizon_builds_the_same_graphs_with_and_without_the_pair_cache(layered):
    """A rolling horizon (H = 3, 5 s slots) over 6 epochs of a synthetic network, once with the
    planner's pair cache and once without: every epoch's graph (weights, edges) and approvals are
    the same, and the cache did reuse pairs. ``layered``: 4 levels 30 m apart, 4 pads, the
    cylinder (V = 30 m): the cache's z cells in the keys, where levels touch exactly."""
    from uam_planner.planning import AirspaceConfig, FlightRequest, Planner, PlanningConfig

    if layered:
        net = generate_network(50, 6, seed=1, levels_m=[60.0, 90.0, 120.0, 150.0], pads_per_vertiport=4)
        air = AirspaceConfig("cylinder", 30.0, 5.0)
    else:
        net = generate_network(50, 6, seed=1)
        air = AirspaceConfig(departure_slot_s=5.0)
    ids = [net.node_ids[i] for i in net.aerodrome_indices]
    cfg = PlanningConfig(horizon_epochs=3, objective="count", airspace=air)

    def greedy(weights, edges, groups):
        from uam_solvers.greedy import greedy_mwis

        class Answer:
            selected = greedy_mwis(weights, edges)
        return Answer()

    def run(cached):
        p = Planner(net, cfg, solve_mwis=greedy)
        if not cached:
            p.pair_cache = None
        rng = np.random.default_rng(4)
        out = []
        for e in range(6):
            t = 30.0 * e
            for j in range(6):
                o, d = rng.choice(len(ids), 2, replace=False)
                assert p.submit(FlightRequest(f"r{e}_{j}", ids[o], ids[d], t, t + 30.0, t + 120.0)) is None
            res = p.plan(t, e)
            out.append((res.report.weights.tolist(), res.report.edges_array.tolist(),
                        [(f.request_id, f.departure_s) for f in res.approved]))
        return out, p

    with_cache, planner = run(True)
    without, _ = run(False)
    assert with_cache == without
    assert planner.pair_cache.reused_pairs > 0
    assert sum(len(a) for _, _, a in without) > 0 and max(len(e) for _, e, _ in without) > 0
