"""Properties of the default network config/networks/singapore.yaml, checked by brute force."""

from pathlib import Path

import numpy as np
import pytest
import scipy.sparse.csgraph

from uam_planner.geo import haversine_m
from uam_planner.network import load_network

CONFIG = Path(__file__).resolve().parents[3] / "config" / "networks"

# The airport zones the network must avoid, with their documented radii (docs/network-format.md).
AIRPORT_ZONES_M = {
    "Changi Airport": 5000.0,
    "Paya Lebar Air Base": 3000.0,
    "Seletar Airport": 3000.0,
    "Tengah Air Base": 3000.0,
}


@pytest.fixture(scope="module")
def net():
    return load_network(CONFIG / "singapore.yaml")


def test_size_and_named_places(net):
    assert len(net.aerodrome_ids) >= 20
    assert net.n_nodes >= 150
    names = set(net.names[i] for i in net.aerodrome_indices)
    for place in ("Jurong East", "Woodlands", "Punggol", "Marina Bay", "Bukit Panjang", "Sengkang",
                  "Yishun", "Singapore General Hospital"):
        assert place in names
    assert any(n.startswith("Tampines") for n in names)
    assert any(n.startswith("Tuas") for n in names)


def test_all_nodes_lie_within_singapore(net):
    lat, lon = net.lat_lon_alt[:, 0], net.lat_lon_alt[:, 1]
    assert lat.min() > 1.23 and lat.max() < 1.47
    assert lon.min() > 103.60 and lon.max() < 104.05


def test_every_aerodrome_reaches_every_other(net):
    dist = scipy.sparse.csgraph.dijkstra(net.adjacency_m, indices=net.aerodrome_indices)
    sub = dist[:, net.aerodrome_indices]
    assert np.isfinite(sub).all()
    # corridors follow the roads, so a route is longer than the straight line, but not absurdly
    a = net.lat_lon_alt[net.aerodrome_indices]
    crow = haversine_m(a[:, None, 0], a[:, None, 1], a[None, :, 0], a[None, :, 1])
    off = ~np.eye(len(a), dtype=bool)
    ratio = sub[off] / crow[off]
    assert ratio.min() >= 1.0
    assert np.median(ratio) < 1.6


def test_altitudes_ground_aerodromes_and_cruise_corridors(net):
    alt = net.lat_lon_alt[:, 2]
    assert np.all((alt[net.is_aerodrome] >= 0.0) & (alt[net.is_aerodrome] <= 10.0))
    assert np.all(alt[~net.is_aerodrome] == 120.0)


def test_corridor_spacing(net):
    # corridors between corridor nodes (not aerodrome access links): about 0.5-1.5 km
    corridor = ~net.is_aerodrome[net.edges].any(axis=1)
    length = net.edge_length_m[corridor]
    assert length.max() <= 1500.0
    assert np.mean(length < 500.0) < 0.05
    assert 800.0 < np.median(length) < 1200.0
    # every aerodrome has an access corridor, to nodes at cruise altitude
    deg = np.bincount(net.edges.ravel(), minlength=net.n_nodes)
    assert np.all(deg[net.aerodrome_indices] >= 1)


def test_no_node_or_corridor_inside_an_airport_zone(net):
    zones = {z.name: z for z in net.no_fly_zones}
    assert {name: z.radius_m for name, z in zones.items()} == AIRPORT_ZONES_M
    lat, lon = net.lat_lon_alt[:, 0], net.lat_lon_alt[:, 1]
    # corridors sampled every <= 10 m along their great-circle chord (in lat/lon, fine at this scale)
    u, v = net.edges[:, 0], net.edges[:, 1]
    t = np.linspace(0.0, 1.0, 200)[None, :]
    seg_lat = lat[u, None] + t * (lat[v] - lat[u])[:, None]
    seg_lon = lon[u, None] + t * (lon[v] - lon[u])[:, None]
    for z in zones.values():
        assert haversine_m(lat, lon, z.lat, z.lon).min() > z.radius_m, z.name
        assert haversine_m(seg_lat, seg_lon, z.lat, z.lon).min() > z.radius_m, z.name


def test_committed_files_are_what_the_generator_script_writes(tmp_path):
    # config/networks/singapore.* must not drift from scripts/build_singapore_network.py
    import importlib.util

    script = CONFIG.parents[1] / "scripts" / "build_singapore_network.py"
    spec = importlib.util.spec_from_file_location("build_singapore_network", script)
    module = importlib.util.module_from_spec(spec)
    spec.loader.exec_module(module)
    assert module.main(["--out-dir", str(tmp_path)]) == 0
    for name in ("singapore.yaml", "singapore.graphml"):
        assert (tmp_path / name).read_text() == (CONFIG / name).read_text(), name
