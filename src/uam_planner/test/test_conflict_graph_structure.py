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
