"""Seeded synthetic corridor networks: determinism, size, shape and argument errors."""

import numpy as np
import pytest
import scipy.sparse.csgraph

from uam_planner.network import NetworkError
from uam_planner.synthetic import generate_network


def test_same_seed_and_size_give_the_same_network():
    a = generate_network(300, 12, seed=7)
    b = generate_network(300, 12, seed=7)
    assert a.node_ids == b.node_ids
    assert np.array_equal(a.enu_m, b.enu_m)
    assert np.array_equal(a.edges, b.edges)
    assert np.array_equal(a.lat_lon_alt, b.lat_lon_alt)
    c = generate_network(300, 12, seed=8)
    assert not np.array_equal(a.enu_m, c.enu_m)


@pytest.mark.parametrize("n_nodes,n_aerodromes", [(3, 2), (10, 2), (120, 10), (2000, 40)])
def test_size_altitudes_and_reachability(n_nodes, n_aerodromes):
    net = generate_network(n_nodes, n_aerodromes, seed=1)
    assert net.n_nodes == n_nodes
    assert len(net.aerodrome_ids) == n_aerodromes
    assert net.aerodrome_indices.tolist() == list(range(n_aerodromes))
    assert np.all(net.enu_m[net.is_aerodrome, 2] == 0.0)
    assert np.all(net.enu_m[~net.is_aerodrome, 2] == 120.0)
    # the whole network is one component, so every aerodrome reaches every other
    n_comp, _ = scipy.sparse.csgraph.connected_components(net.adjacency_m, directed=False)
    assert n_comp == 1


def test_average_corridor_length_and_degree():
    net = generate_network(2000, 40, seed=3)
    corridor = ~net.is_aerodrome[net.edges].any(axis=1)
    mean_m = net.edge_length_m[corridor].mean()
    assert 500.0 <= mean_m <= 1000.0
    degree = np.bincount(net.edges.ravel(), minlength=net.n_nodes)[~net.is_aerodrome]
    assert 2.5 < degree.mean() < 6.0


def test_corridor_layer_is_planar():
    # Delaunay edges never cross: check every pair of corridor segments by brute force
    net = generate_network(150, 5, seed=11)
    corridor = ~net.is_aerodrome[net.edges].any(axis=1)
    e = net.edges[corridor]
    p, q = net.enu_m[e[:, 0], :2], net.enu_m[e[:, 1], :2]

    def orient(a, b, c):
        return np.sign((b[..., 0] - a[..., 0]) * (c[..., 1] - a[..., 1])
                       - (b[..., 1] - a[..., 1]) * (c[..., 0] - a[..., 0]))

    P, Q = p[:, None], q[:, None]
    R, S = p[None, :], q[None, :]
    cross = (orient(P, Q, R) * orient(P, Q, S) < 0) & (orient(R, S, P) * orient(R, S, Q) < 0)
    assert not cross.any()


def test_extent_sets_the_area():
    net = generate_network(401, 2, seed=0, extent_m=10000.0)
    xy = net.enu_m[:, :2]
    assert np.all(np.abs(xy) <= 5000.0)
    assert np.ptp(xy[~net.is_aerodrome, 0]) > 8000.0


@pytest.mark.parametrize("kwargs,pattern", [
    (dict(n_nodes=10, n_aerodromes=1, seed=0), r"n_aerodromes: 1 is below the minimum 2"),
    (dict(n_nodes=3, n_aerodromes=3, seed=0), r"n_nodes: 3 must exceed n_aerodromes \(3\)"),
    (dict(n_nodes=10.5, n_aerodromes=2, seed=0), r"n_nodes: 10\.5 is not an integer"),
    (dict(n_nodes=10, n_aerodromes=2, seed=0, extent_m=-1.0), r"extent_m: -1\.0 is not a positive"),
    (dict(n_nodes=10, n_aerodromes=2, seed=0, cruise_alt_m=float("nan")), r"cruise_alt_m: nan"),
])
def test_bad_arguments_are_named(kwargs, pattern):
    with pytest.raises(NetworkError, match=pattern):
        generate_network(**kwargs)
def test_named_cities_are_their_generator_arguments():
    """``generate_city``: the named city is generate_network with its arguments and the seed
    (the benchmarks' layered city is the one the studies fly); an unknown name is refused
    naming the known ones."""
    from uam_planner.synthetic import CITIES, generate_city
    got = generate_city("layered-city", seed=3)
    want = generate_network(seed=3, **CITIES["layered-city"])
    assert got.name == "layered-city-s3" and got.layered
    assert got.node_ids == want.node_ids
    assert np.array_equal(got.enu_m, want.enu_m) and np.array_equal(got.edges, want.edges)
    with pytest.raises(NetworkError, match="city: 'nowhere' is not one of"):
        generate_city("nowhere")
