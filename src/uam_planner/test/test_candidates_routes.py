"""Candidate routes by penalised Dijkstra on small graphs."""

import networkx as nx
import numpy as np
import pytest

from uam_planner.candidates import CandidateCache, candidate_routes
from uam_planner.network import network_from_enu
from uam_planner.synthetic import generate_network


def ring_network():
    """A square ring A-n1-B-n2-A: exactly two simple routes from A to B (300 m and 500 m)."""
    ids = ["A", "n1", "B", "n2"]
    enu = [(0, 0, 0), (0, 150, 0), (0, 300, 0), (200, 150, 0)]
    # A-n1 150, n1-B 150 (300 total); A-n2 250, n2-B 250 (500 total).
    return network_from_enu("ring", ids, enu, [True, False, True, False],
                            [("A", "n1"), ("n1", "B"), ("A", "n2"), ("n2", "B")])


def test_ring_gives_both_routes_once_with_hand_computed_weights():
    net = ring_network()
    routes = candidate_routes(net, "A", "B", k=5, penalty_factor=5.0)
    assert [[net.node_ids[i] for i in r.node_indices] for r in routes] == [["A", "n1", "B"],
                                                                          ["A", "n2", "B"]]
    assert [r.length_m for r in routes] == pytest.approx([300.0, 500.0])
    assert [r.weight for r in routes] == pytest.approx([1.0, 0.6])
    assert [r.candidate_index for r in routes] == [0, 1]


def test_penalty_factor_zero_gives_only_the_shortest():
    net = ring_network()
    assert len(candidate_routes(net, "A", "B", k=5, penalty_factor=0.0)) == 1


@pytest.mark.parametrize("seed", range(4))
def test_routes_on_synthetic_networks(seed):
    net = generate_network(80, 6, seed=seed)
    rng = np.random.default_rng(seed)
    for _ in range(5):
        o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
        routes = candidate_routes(net, o, d, k=5, penalty_factor=5.0)
        shortest = nx.shortest_path_length(net.graph, net.index[o], net.index[d], weight="length_m")
        assert 1 <= len(routes) <= 5
        assert routes[0].length_m == pytest.approx(shortest, rel=1e-12)
        assert routes[0].weight == 1.0
        assert len({r.node_indices for r in routes}) == len(routes)
        for i, r in enumerate(routes):
            assert r.candidate_index == i
            assert r.node_indices[0] == net.index[o] and r.node_indices[-1] == net.index[d]
            assert r.length_m == pytest.approx(net.path_length_m(r.node_indices), rel=1e-12)
            assert 0.0 < r.weight <= 1.0
            assert r.weight == pytest.approx(shortest / r.length_m)
            assert len(set(r.node_indices)) == len(r.node_indices)  # simple path


def test_cache_matches_direct_generation_and_counts_hits():
    net = generate_network(80, 6, seed=1)
    cache = CandidateCache(net, k=5, penalty_factor=5.0, speed_mps=10.0)
    o, d = net.aerodrome_indices[0], net.aerodrome_indices[3]
    first = cache.templates(o, d)
    again = cache.templates(o, d)
    assert first is again and cache.hits == 1 and cache.misses == 1
    direct = candidate_routes(net, net.node_ids[o], net.node_ids[d])
    assert [t.route for t in first] == direct
    tr = first[0].trajectory(120.0)
    assert tr.departure_s == 120.0
    assert tr.arrival_s == pytest.approx(120.0 + direct[0].length_m / 10.0)
    assert tr.points_m == pytest.approx(net.enu_m[list(direct[0].node_indices)])


def test_bad_arguments_name_the_field():
    net = ring_network()
    with pytest.raises(ValueError, match="k must"):
        candidate_routes(net, "A", "B", k=0)
    with pytest.raises(ValueError, match="penalty_factor"):
        candidate_routes(net, "A", "B", penalty_factor=-1.0)
    with pytest.raises(ValueError, match="same node"):
        candidate_routes(net, "A", "A")
    with pytest.raises(ValueError, match="'Z'"):
        candidate_routes(net, "A", "Z")
