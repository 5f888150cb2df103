"""Network construction, ENU conversion and validation errors (each names the field and value)."""

import copy
import math
import re

import numpy as np
import pytest

from uam_planner.geo import enu_to_geodetic, geodetic_to_ecef, geodetic_to_enu
from uam_planner.network import (Network, NetworkError, build_network, network_from_dict,
                                 network_from_enu)


def _doc():
    """A small valid network: aerodromes A, B at ground level, corridor W1-W2-W3 at 120 m."""
    return {
        "name": "t",
        "origin": {"lat": 1.35, "lon": 103.80, "alt_m": 0.0},
        "nodes": [
            {"id": "A", "lat": 1.3500, "lon": 103.8000, "alt_m": 5.0, "aerodrome": True,
             "name": "Alpha"},
            {"id": "B", "lat": 1.3500, "lon": 103.8300, "alt_m": 5.0, "aerodrome": True},
            {"id": "W1", "lat": 1.3510, "lon": 103.8050, "alt_m": 120.0},
            {"id": "W2", "lat": 1.3510, "lon": 103.8150, "alt_m": 120.0},
            {"id": "W3", "lat": 1.3510, "lon": 103.8250, "alt_m": 120.0},
        ],
        "corridors": [
            {"from": "A", "to": "W1"}, {"from": "W2", "to": "W1"}, {"from": "W2", "to": "W3"},
            {"from": "W3", "to": "B"},
        ],
    }


# -- ENU conversion ------------------------------------------------------------------------------
def test_enu_of_small_offsets_near_singapore_matches_hand_computed_radii():
    # Hand computation, WGS84 at latitude 1.35 deg:
    #   meridional radius M = a(1-e^2)/(1-e^2 sin^2 phi)^1.5 = 6335474.0 m -> 0.001 deg = 110.5749 m
    #   prime vertical N = a/sqrt(1-e^2 sin^2 phi) = 6378148.6 m; N cos(phi) 0.001 deg = 111.2888 m
    enu = geodetic_to_enu([[1.351, 103.800, 0.0], [1.350, 103.801, 0.0],
                           [1.350, 103.800, 100.0]], (1.35, 103.80, 0.0))
    assert enu[0] == pytest.approx([0.0, 110.5749, 0.0], abs=1e-3)
    assert enu[1] == pytest.approx([111.2888, 0.0, 0.0], abs=1e-3)
    assert enu[2] == pytest.approx([0.0, 0.0, 100.0], abs=1e-6)


def test_enu_up_drops_with_earth_curvature_far_from_the_origin():
    # A point 20 km east at altitude 0 lies below the tangent plane by about d^2 / (2R) = 31.4 m.
    d_lon = math.degrees(20000.0 / (6378148.6 * math.cos(math.radians(1.35))))
    e, n, u = geodetic_to_enu([1.35, 103.80 + d_lon, 0.0], (1.35, 103.80, 0.0))
    assert e == pytest.approx(20000.0, rel=1e-4)
    assert u == pytest.approx(-20000.0**2 / (2 * 6378148.6), rel=1e-2)


def test_ecef_of_the_equator_and_enu_round_trip():
    assert geodetic_to_ecef(0.0, 0.0, 0.0) == pytest.approx([6378137.0, 0.0, 0.0])
    assert geodetic_to_ecef(90.0, 0.0, 0.0)[2] == pytest.approx(6356752.314245, abs=1e-6)
    rng = np.random.default_rng(0)
    lla = np.column_stack([rng.uniform(1.2, 1.5, 50), rng.uniform(103.6, 104.0, 50),
                           rng.uniform(0, 500, 50)])
    back = enu_to_geodetic(geodetic_to_enu(lla, (1.3521, 103.8198, 0.0)), (1.3521, 103.8198, 0.0))
    assert np.abs(back[:, :2] - lla[:, :2]).max() < 1e-10
    assert np.abs(back[:, 2] - lla[:, 2]).max() < 1e-6


# -- construction ------------------------------------------------------------------------------
def test_build_network_fields_are_canonical():
    net = network_from_dict(_doc())
    assert net.node_ids == ("A", "B", "W1", "W2", "W3")
    assert net.names == ("Alpha", "", "", "", "")
    assert net.aerodrome_ids == ("A", "B")
    assert net.aerodrome_indices.tolist() == [0, 1]
    assert net.edges.dtype == np.int32
    # (u < v), sorted lexicographically: A-W1 (0,2), B-W3 (1,4), W1-W2 (2,3), W2-W3 (3,4)
    assert net.edges.tolist() == [[0, 2], [1, 4], [2, 3], [3, 4]]
    expected = np.linalg.norm(net.enu_m[net.edges[:, 1]] - net.enu_m[net.edges[:, 0]], axis=1)
    assert np.allclose(net.edge_length_m, expected)
    # W1-W2: 0.01 deg of longitude at 120 m = 1112.9 m (N cos phi * 0.01 deg, plus 120 m radius)
    assert net.edge_length_m[2] == pytest.approx(1112.91, abs=0.05)
    assert net.origin_lat_lon_alt == (1.35, 103.80, 0.0)
    assert net.index == {"A": 0, "B": 1, "W1": 2, "W2": 3, "W3": 4}
    g = net.graph
    assert sorted(g.nodes) == [0, 1, 2, 3, 4]
    assert g.edges[2, 3]["length_m"] == pytest.approx(net.edge_length_m[2])
    assert g.edges[3, 2]["edge_index"] == 2
    assert net.adjacency_m[2, 3] == pytest.approx(net.edge_length_m[2])
    assert not net.enu_m.flags.writeable and not net.edges.flags.writeable


def test_default_origin_is_the_node_centroid_at_zero_altitude():
    doc = _doc()
    del doc["origin"]
    net = network_from_dict(doc)
    lat = np.mean([n["lat"] for n in doc["nodes"]])
    lon = np.mean([n["lon"] for n in doc["nodes"]])
    assert net.origin_lat_lon_alt == pytest.approx((lat, lon, 0.0))


def test_node_index_and_path_length():
    net = network_from_dict(_doc())
    assert net.node_index("W2") == 3
    with pytest.raises(NetworkError, match="node id 'Nope' is not in network 't'"):
        net.node_index("Nope")
    path = [net.node_index(i) for i in ("A", "W1", "W2", "W3", "B")]
    assert net.path_length_m(path) == pytest.approx(net.edge_length_m.sum())
    assert net.path_length_m([3]) == 0.0
    with pytest.raises(NetworkError, match=r"path\[0\]->path\[1\]: no corridor between 'A' and 'W2'"):
        net.path_length_m([0, 3])
    assert net.edge_index(4, 3) == 3
    with pytest.raises(NetworkError):
        net.edge_index(0, 1)


def test_network_from_enu_builds_the_same_geometry():
    enu = np.array([[0, 0, 0], [3000, 0, 0], [500, 0, 120], [1500, 0, 120], [2500, 0, 120.0]])
    net = network_from_enu("e", ["A", "B", "W1", "W2", "W3"], enu, [1, 1, 0, 0, 0],
                           [("W1", "A"), ("W1", "W2"), ("W3", "W2"), ("B", "W3")])
    assert net.edges.tolist() == [[0, 2], [1, 4], [2, 3], [3, 4]]
    assert net.edge_length_m[2] == pytest.approx(1000.0)
    assert np.array_equal(net.enu_m, enu)
    # lat/lon/alt are the exact inverse transform of the ENU coordinates
    assert np.allclose(geodetic_to_enu(net.lat_lon_alt, net.origin_lat_lon_alt), enu, atol=1e-6)
    assert net.origin_lat_lon_alt == (1.3521, 103.8198, 0.0)


# -- validation errors: (mutation of the document, regex the message must match) ------------------
def _set(path, value):
    def mutate(doc):
        obj = doc
        for key in path[:-1]:
            obj = obj[key]
        if value is _DELETE:
            del obj[path[-1]]
        else:
            obj[path[-1]] = value
    return mutate


_DELETE = object()

CASES = {
    "lat out of range": (_set(["nodes", 3, "lat"], 95.2),
                         r"nodes\[3\] \(id 'W2'\)\.lat: 95\.2 is out of range \[-90, 90\]"),
    "lon out of range": (_set(["nodes", 2, "lon"], 190.0),
                         r"nodes\[2\] \(id 'W1'\)\.lon: 190\.0 is out of range \[-180, 180\]"),
    "alt out of range": (_set(["nodes", 4, "alt_m"], 20000.0),
                         r"nodes\[4\] \(id 'W3'\)\.alt_m: 20000\.0 is out of range"),
    "lat nan": (_set(["nodes", 3, "lat"], float("nan")),
                r"nodes\[3\] \(id 'W2'\)\.lat: nan is not finite"),
    "alt inf": (_set(["nodes", 3, "alt_m"], float("inf")),
                r"nodes\[3\] \(id 'W2'\)\.alt_m: inf is not finite"),
    "lat string": (_set(["nodes", 3, "lat"], "north"),
                   r"nodes\[3\] \(id 'W2'\)\.lat: 'north' is not a number"),
    "missing lon": (_set(["nodes", 1, "lon"], _DELETE), r"nodes\[1\] \(id 'B'\)\.lon: missing"),
    "missing id": (_set(["nodes", 1, "id"], _DELETE), r"nodes\[1\]\.id: missing"),
    "empty id": (_set(["nodes", 1, "id"], ""), r"nodes\[1\]\.id: '' is not a non-empty string"),
    "duplicate id": (_set(["nodes", 3, "id"], "W1"),
                     r"nodes\[3\] \(id 'W1'\)\.id: 'W1' duplicates nodes\[2\]"),
    "unknown node field": (_set(["nodes", 2, "altitude"], 100),
                           r"nodes\[2\] \(id 'W1'\)\.altitude: unknown field"),
    "aerodrome not bool": (_set(["nodes", 0, "aerodrome"], "yes"),
                           r"nodes\[0\] \(id 'A'\)\.aerodrome: 'yes' is not true/false"),
    "unknown corridor id": (_set(["corridors", 2, "to"], "W9"),
                            r"corridors\[2\]\.to: 'W9' is not a node id"),
    "missing corridor end": (_set(["corridors", 1, "from"], _DELETE),
                             r"corridors\[1\]\.from: missing"),
    "self loop": (_set(["corridors", 2, "to"], "W2"),
                  r"corridors\[2\]\.to: 'W2' equals from \(self loop\)"),
    "unknown top-level field": (_set(["edges"], []), r"edges: unknown field \(value \[\]; known: airspace, corridors"),
    "missing corridors": (_set(["corridors"], _DELETE), r"corridors: missing"),
    "bad origin": (_set(["origin", "lat"], -91.0), r"origin\.lat: -91\.0 is out of range"),
}


@pytest.mark.parametrize("case", sorted(CASES))
def test_each_validation_error_names_the_field_and_value(case):
    mutate, pattern = CASES[case]
    doc = copy.deepcopy(_doc())
    mutate(doc)
    with pytest.raises(NetworkError, match=pattern):
        network_from_dict(doc)


def test_duplicate_corridor_in_either_direction_is_rejected():
    doc = _doc()
    doc["corridors"].append({"from": "W1", "to": "W2"})  # corridors[1] is W2-W1
    with pytest.raises(NetworkError, match=r"corridors\[4\] \('W1'-'W2'\): duplicate of corridors\[1\]"):
        network_from_dict(doc)


def test_zero_length_corridor_is_rejected():
    doc = _doc()
    doc["nodes"].append({"id": "W2b", "lat": 1.3510, "lon": 103.8150, "alt_m": 120.0})
    doc["corridors"].append({"from": "W2", "to": "W2b"})
    with pytest.raises(NetworkError, match=r"corridors\[4\] \('W2'-'W2b'\): zero-length corridor"):
        network_from_dict(doc)


def test_unreachable_aerodromes_are_named():
    doc = _doc()
    doc["corridors"] = [c for c in doc["corridors"] if c != {"from": "W2", "to": "W3"}]
    with pytest.raises(NetworkError, match=r"aerodromes 'A' and 'B' cannot reach each other"):
        network_from_dict(doc)


def test_fewer_than_two_aerodromes_is_rejected():
    doc = _doc()
    doc["nodes"][1]["aerodrome"] = False
    with pytest.raises(NetworkError, match=r"1 aerodrome\(s\); at least 2 are needed"):
        network_from_dict(doc)


def test_no_fly_zone_violations_name_the_node_or_corridor_and_zone():
    doc = _doc()
    # a 300 m zone around W2 contains the node
    doc["no_fly_zones"] = [{"name": "Z", "lat": 1.3510, "lon": 103.8150, "radius_m": 300.0}]
    with pytest.raises(NetworkError, match=r"nodes\[3\] \(id 'W2'\): lies 0 m from the centre of "
                                           r"no-fly zone 'Z', inside its radius 300 m"):
        network_from_dict(doc)
    # a zone between W1 and W2 (1.11 km apart) that contains neither node, but the corridor
    doc["no_fly_zones"] = [{"name": "Z", "lat": 1.3510, "lon": 103.8100, "radius_m": 300.0}]
    with pytest.raises(NetworkError, match=r"corridor \('W1'-'W2'\): passes 0 m from the centre "
                                           r"of no-fly zone 'Z'"):
        network_from_dict(doc)
    doc["no_fly_zones"] = [{"name": "Z", "lat": 1.3510, "lon": 103.8100, "radius_m": -3.0}]
    with pytest.raises(NetworkError, match=r"no_fly_zones\[0\]\.radius_m: -3\.0 is not positive"):
        network_from_dict(doc)


def test_network_from_enu_errors_name_the_entry():
    enu = np.array([[0, 0, 0], [1000, 0, 0], [500, 0, 120.0]])
    with pytest.raises(NetworkError, match=r"edges_as_id_pairs\[1\]\[1\]: 'X' is not a node id"):
        network_from_enu("e", ["A", "B", "W"], enu, [1, 1, 0], [("A", "W"), ("W", "X")])
    with pytest.raises(NetworkError, match=r"node_ids\[2\]: 'A' duplicates node_ids\[0\]"):
        network_from_enu("e", ["A", "B", "A"], enu, [1, 1, 0], [])
    bad = enu.copy()
    bad[2, 1] = np.nan
    with pytest.raises(NetworkError, match=r"enu_m\[2\] \(id 'W'\): .* is not finite"):
        network_from_enu("e", ["A", "B", "W"], bad, [1, 1, 0], [("A", "W"), ("W", "B")])
    with pytest.raises(NetworkError, match=r"enu_m: shape \(3, 3\), expected \(2, 3\)"):
        network_from_enu("e", ["A", "B"], enu, [1, 1], [])


def test_direct_constructor_rejects_non_canonical_edges():
    net = network_from_dict(_doc())
    fields = dict(name=net.name, node_ids=net.node_ids, names=net.names,
                  is_aerodrome=net.is_aerodrome, lat_lon_alt=net.lat_lon_alt, enu_m=net.enu_m,
                  origin_lat_lon_alt=net.origin_lat_lon_alt)
    with pytest.raises(NetworkError, match=re.escape("edges[0] ('W1'-'A'): [2, 0] is not ordered u < v")):
        Network(**fields, edges=np.array([[2, 0]]), edge_length_m=np.array([1.0]))
    with pytest.raises(NetworkError, match=r"edge_length_m\[0\]: 5\.0 differs from the ENU distance"):
        Network(**fields, edges=net.edges, edge_length_m=np.r_[5.0, net.edge_length_m[1:]])
    ok = Network(**fields, edges=net.edges, edge_length_m=net.edge_length_m)
    assert ok.edges.tolist() == net.edges.tolist()


def test_build_network_from_plain_lists_with_an_origin_tuple():
    doc = _doc()
    net = build_network("direct", doc["nodes"], doc["corridors"], origin=(1.35, 103.80))
    assert net.name == "direct"
    assert net.origin_lat_lon_alt == (1.35, 103.80, 0.0)
    assert net.enu_m[0] == pytest.approx([0.0, 0.0, 5.0], abs=1e-6)
    with pytest.raises(NetworkError, match=r"name: '' is not a non-empty string"):
        build_network("", doc["nodes"], doc["corridors"])
    with pytest.raises(NetworkError, match=r"nodes: expected a list, got dict"):
        build_network("x", {"A": 1}, doc["corridors"])


def test_edge_indices_of_many_pairs_are_edge_index_of_each_and_name_a_missing_corridor():
    from uam_planner.synthetic import generate_network

    net = generate_network(200, 10, seed=3)
    rng = np.random.default_rng(0)
    pick = rng.integers(0, net.n_edges, 500)
    u, v = net.edges[pick, 0], net.edges[pick, 1]
    flip = rng.random(500) < 0.5          # either order
    u, v = np.where(flip, v, u), np.where(flip, u, v)
    got = net.edge_indices(u, v)
    assert got.tolist() == [net.edge_index(a, b) for a, b in zip(u, v)] == pick.tolist()
    assert net.edge_indices([], []).shape == (0,)
    a, b = (int(x) for x in net.edges[0])
    far = next(w for w in range(net.n_nodes) if w != a and net.graph.get_edge_data(a, w) is None)
    for bad_u, bad_v in (([a, a], [b, far]), ([a], [net.n_nodes]), ([-1], [b])):
        with pytest.raises(NetworkError, match="no corridor between node indices"):
            net.edge_indices(bad_u, bad_v)
    with pytest.raises(NetworkError, match=f"{a} and {far}"):
        net.edge_indices([a, a], [b, far])
