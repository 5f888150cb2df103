"""Network file formats: YAML, GeoJSON and GraphML load and save, round trips, and file errors."""

import copy
import json
import pickle
from pathlib import Path

import numpy as np
import pytest
import yaml

from uam_planner.network import (NetworkError, load_network, network_to_dict, save_network_geojson,
                                 save_network_graphml, save_network_yaml)
from uam_planner.synthetic import generate_network

CONFIG = Path(__file__).resolve().parents[3] / "config" / "networks"


def _assert_same(a, b, exact=True):
    assert a.name == b.name
    assert a.node_ids == b.node_ids
    assert a.names == b.names
    assert np.array_equal(a.is_aerodrome, b.is_aerodrome)
    assert np.array_equal(a.edges, b.edges)
    assert a.origin_lat_lon_alt == b.origin_lat_lon_alt
    assert a.no_fly_zones == b.no_fly_zones
    if exact:
        assert np.array_equal(a.lat_lon_alt, b.lat_lon_alt)
        assert np.array_equal(a.enu_m, b.enu_m)
        assert np.array_equal(a.edge_length_m, b.edge_length_m)
    else:
        assert np.allclose(a.lat_lon_alt, b.lat_lon_alt, rtol=0, atol=1e-9)
        assert np.allclose(a.enu_m, b.enu_m, rtol=0, atol=1e-6)
        assert np.allclose(a.edge_length_m, b.edge_length_m, rtol=0, atol=1e-6)


def test_tiny_example_loads_with_documented_contents():
    net = load_network(CONFIG / "tiny.yaml")
    assert net.name == "tiny"
    assert net.aerodrome_ids == ("A", "B", "C")
    assert net.n_nodes == 10 and net.n_edges == 13
    assert net.origin_lat_lon_alt == (1.29, 103.85, 0.0)
    # W7 sits on the origin at 120 m: ENU is (0, 0, 120) up to float rounding
    assert net.enu_m[net.node_index("W7")] == pytest.approx([0.0, 0.0, 120.0], abs=1e-6)


@pytest.mark.parametrize("fmt", ["graphml", "yaml", "geojson"])
def test_tiny_round_trip_is_exact(tmp_path, fmt):
    net = load_network(CONFIG / "tiny.yaml")
    save = {"graphml": save_network_graphml, "yaml": save_network_yaml,
            "geojson": save_network_geojson}[fmt]
    out = tmp_path / f"net.{fmt}"
    save(net, out)
    _assert_same(load_network(out), net)


def test_singapore_yaml_to_graphml_to_yaml_is_the_same_network(tmp_path):
    net = load_network(CONFIG / "singapore.yaml")
    save_network_graphml(net, tmp_path / "sg.graphml")
    via_graphml = load_network(tmp_path / "sg.graphml")
    _assert_same(via_graphml, net)
    save_network_yaml(via_graphml, tmp_path / "sg.yaml")
    _assert_same(load_network(tmp_path / "sg.yaml"), net)


def test_committed_singapore_graphml_matches_the_yaml():
    _assert_same(load_network(CONFIG / "singapore.graphml"), load_network(CONFIG / "singapore.yaml"))


def test_synthetic_network_round_trips_through_all_formats(tmp_path):
    # synthetic networks are built from ENU; the files hold lat/lon, so ENU is recomputed
    net = generate_network(60, 5, seed=4)
    for save, ext in ((save_network_yaml, "yaml"), (save_network_graphml, "graphml"),
                      (save_network_geojson, "json")):
        save(net, tmp_path / f"s.{ext}")
        _assert_same(load_network(tmp_path / f"s.{ext}"), net, exact=False)


def test_yaml_writer_keeps_header_routes_and_extra_fields(tmp_path):
    net = load_network(CONFIG / "tiny.yaml")
    routes = [f"r{k}" for k in range(net.n_edges)]
    save_network_yaml(net, tmp_path / "t.yaml", header="line one\nline two", corridor_routes=routes,
                      extra={"cruise_alt_m": 120.0})
    text = (tmp_path / "t.yaml").read_text()
    assert text.startswith("# line one\n# line two\n")
    doc = yaml.safe_load(text)
    assert doc["cruise_alt_m"] == 120.0
    assert [c["route"] for c in doc["corridors"]] == routes
    with pytest.raises(NetworkError, match="corridor_routes: 2 labels for 13 corridors"):
        save_network_yaml(net, tmp_path / "u.yaml", corridor_routes=["a", "b"])


def test_geojson_layout(tmp_path):
    net = load_network(CONFIG / "tiny.yaml")
    save_network_geojson(net, tmp_path / "t.geojson")
    doc = json.loads((tmp_path / "t.geojson").read_text())
    points = [f for f in doc["features"] if f["geometry"]["type"] == "Point"]
    lines = [f for f in doc["features"] if f["geometry"]["type"] == "LineString"]
    assert len(points) == 10 and len(lines) == 13
    a = points[0]
    assert a["properties"]["id"] == "A" and a["properties"]["aerodrome"] is True
    assert a["geometry"]["coordinates"] == [103.84, 1.28, 5.0]  # [lon, lat, alt_m]
    assert lines[0]["properties"]["from"] == "A" and lines[0]["properties"]["to"] == "W1"


def test_geojson_errors_name_the_feature(tmp_path):
    doc = {"type": "FeatureCollection", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": []}, "properties": {}}]}
    (tmp_path / "bad.geojson").write_text(json.dumps(doc))
    with pytest.raises(NetworkError, match=r"features\[0\]\.geometry\.type: 'Polygon' is not"):
        load_network(tmp_path / "bad.geojson")
    doc["features"][0] = {"type": "Feature", "geometry": {"type": "Point", "coordinates": [1]},
                          "properties": {"id": "A"}}
    (tmp_path / "bad.geojson").write_text(json.dumps(doc))
    with pytest.raises(NetworkError, match=r"features\[0\]\.geometry\.coordinates: \[1\]"):
        load_network(tmp_path / "bad.geojson")


def test_file_level_errors(tmp_path):
    with pytest.raises(NetworkError, match=r"path: '.*missing\.yaml' does not exist"):
        load_network(tmp_path / "missing.yaml")
    (tmp_path / "net.csv").write_text("x")
    with pytest.raises(NetworkError, match=r"path: extension '\.csv'"):
        load_network(tmp_path / "net.csv")
    (tmp_path / "bad.yaml").write_text("nodes: [\n")
    with pytest.raises(NetworkError, match="not valid YAML"):
        load_network(tmp_path / "bad.yaml")
    (tmp_path / "list.yaml").write_text("- 1\n- 2\n")
    with pytest.raises(NetworkError, match="document: expected a mapping"):
        load_network(tmp_path / "list.yaml")
    # a YAML error inside the file names the field, as for dictionaries
    doc = network_to_dict(load_network(CONFIG / "tiny.yaml"))
    doc["nodes"][4]["lat"] = 95.2
    (tmp_path / "lat.yaml").write_text(yaml.safe_dump(doc))
    with pytest.raises(NetworkError, match=r"nodes\[4\] \(id 'W2'\)\.lat: 95\.2 is out of range"):
        load_network(tmp_path / "lat.yaml")


def test_pickle_and_deepcopy_keep_a_valid_read_only_network():
    net = load_network(CONFIG / "singapore.yaml")
    for other in (pickle.loads(pickle.dumps(net)), copy.deepcopy(net)):
        _assert_same(other, net)
        assert not other.enu_m.flags.writeable
        assert other.index == net.index
        assert other.graph.number_of_edges() == net.n_edges
