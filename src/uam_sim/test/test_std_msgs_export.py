"""Standard-message views of a run: exact CDR, readable by rosbags, drawn by Rerun's MCAP import."""

from __future__ import annotations

import shutil
import subprocess
import sys
from pathlib import Path
from types import SimpleNamespace as NS

import numpy as np
import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from uam_sim.views.std_msgs_export import (DEFAULT_SCENARIO_START_UTC, MARKER_LINE_LIST,  # noqa: E402
                                     MARKER_LINE_STRIP, MARKER_TEXT_VIEW_FACING, TOPIC_FLEET_CLOUD,
                                     TOPIC_NETWORK, TOPIC_ROUTES, Marker, ViewExporter,
                                     encode_marker_array, encode_nav_sat_fix, encode_point_cloud,
                                     scenario_start_ns, vehicle_topic)
from view_runs import TINY, record_run  # noqa: E402

SEC = 1_000_000_000
START_NS = 1736121600 * SEC  # 2025-01-06T00:00:00Z


def _cli() -> str | None:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


def same_as_rclpy(ours: bytes, msg) -> None:
    """Our bytes decode (with rclpy) to ``msg``, and equal rclpy's bytes except in alignment padding
    (which rclpy's serializer leaves uninitialised)."""
    from rclpy.serialization import deserialize_message

    from uam_sim.recording import serialize_exact
    theirs = serialize_exact(msg)
    assert len(ours) == len(theirs)
    assert deserialize_message(ours, type(msg)) == msg


def test_point_cloud_bytes_equal_rclpy():
    from sensor_msgs.msg import PointCloud2, PointField

    pts = np.array([[1.5, -2.0, 120.0], [1000.25, 30.0, 5.0]])
    msg = PointCloud2(height=1, width=2, is_bigendian=False, point_step=12, row_step=24, is_dense=True,
                      fields=[PointField(name=n, offset=o, datatype=PointField.FLOAT32, count=1)
                              for n, o in (("x", 0), ("y", 4), ("z", 8))],
                      data=pts.astype("<f4").tobytes())
    msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 1736121601, 500, "enu"
    same_as_rclpy(encode_point_cloud(1736121601 * SEC + 500, "enu", pts), msg)


def test_nav_sat_fix_and_marker_array_bytes_equal_rclpy():
    from builtin_interfaces.msg import Duration
    from geometry_msgs.msg import Point
    from sensor_msgs.msg import NavSatFix, NavSatStatus
    from std_msgs.msg import ColorRGBA
    from visualization_msgs.msg import Marker as RosMarker
    from visualization_msgs.msg import MarkerArray

    fix = NavSatFix(latitude=1.29, longitude=103.85, altitude=120.0,
                    status=NavSatStatus(status=NavSatStatus.STATUS_FIX, service=NavSatStatus.SERVICE_GPS))
    fix.header.stamp.sec, fix.header.frame_id = 1736121700, "r00001_002"
    same_as_rclpy(encode_nav_sat_fix(1736121700 * SEC, "r00001_002", 1.29, 103.85, 120.0), fix)

    strip = RosMarker(ns="routes", id=3, type=RosMarker.LINE_STRIP, action=RosMarker.ADD,
                      color=ColorRGBA(r=0.25, g=0.5, b=0.75, a=1.0), lifetime=Duration(sec=90, nanosec=500_000_000),
                      points=[Point(x=0.0, y=1.0, z=2.0), Point(x=3.0, y=4.0, z=5.0)], text="r1")
    strip.scale.x = 6.0
    strip.pose.orientation.w = 1.0
    strip.header.stamp.sec, strip.header.frame_id = 1736121630, "enu"
    text = RosMarker(ns="names", id=0, type=RosMarker.TEXT_VIEW_FACING, text="Aerodrome A",
                     color=ColorRGBA(r=1.0, g=1.0, b=1.0, a=1.0))
    text.pose.position.x, text.pose.position.z, text.pose.orientation.w = 10.0, 150.0, 1.0
    text.scale.z = 150.0
    text.header.frame_id = "enu"
    ours = encode_marker_array([
        Marker("routes", 3, MARKER_LINE_STRIP, 1736121630 * SEC, scale=(6.0, 0.0, 0.0),
               color=(0.25, 0.5, 0.75, 1.0), lifetime_s=90.5, points=[(0, 1, 2), (3, 4, 5)], text="r1"),
        Marker("names", 0, MARKER_TEXT_VIEW_FACING, 0, position=(10.0, 0.0, 150.0), scale=(0.0, 0.0, 150.0),
               text="Aerodrome A")])
    same_as_rclpy(ours, MarkerArray(markers=[strip, text]))


def test_scenario_start_parses_iso_times_and_names_bad_values():
    assert scenario_start_ns(DEFAULT_SCENARIO_START_UTC) == START_NS
    assert scenario_start_ns("sim") == 0  # stamps in simulation time, the other topics' clock
    assert scenario_start_ns("2025-01-06T08:00:00+08:00") == START_NS
    assert scenario_start_ns("2025-01-06T00:00:00.25Z") == START_NS + SEC // 4
    for bad, why in (("yesterday", "ISO 8601"), ("2025-01-06T00:00:00", "no time zone"),
                     ("1970-01-01T00:00:00Z", "1990")):
        with pytest.raises(ValueError, match=f"scenario_start_utc: '{bad}'.*{why}"):
            scenario_start_ns(bad)


def test_fix_period_thins_the_fixes_and_is_checked():
    from uam_planner.network import load_network

    net = load_network(TINY)
    pos = [[0.0, 0.0, 120.0], [10.0, 0.0, 120.0]]
    every = ViewExporter(net, fix_period_s=0)
    fives = ViewExporter(net)
    for k, expected in ((0, 2), (1, 0), (5, 2)):
        assert len(every.fleet_messages(k * SEC, ["a", "b"], pos)) == 1 + 2
        assert len(fives.fleet_messages(k * SEC, ["a", "b"], pos)) == 1 + expected
    with pytest.raises(ValueError, match="fix_period_s: -1"):
        ViewExporter(net, fix_period_s=-1)


def test_vehicle_topics_are_valid_ros_names():
    assert vehicle_topic("r00001_002") == "/uam/view/fix/r00001_002"
    assert vehicle_topic("7-a.b") == "/uam/view/fix/v7_a_b"


def test_corridors_get_one_line_list_per_level():
    from uam_planner.network import load_network

    net = load_network(TINY)
    levels = [0 if k % 2 else 300 for k in range(net.n_edges)]   # two levels, any labels
    leveled = NS(**{k: getattr(net, k) for k in ("enu_m", "edges", "is_aerodrome", "names", "node_ids",
                                                 "origin_lat_lon_alt")}, edge_levels=levels)
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    for network, n_lists in ((net, 1), (leveled, 2)):
        markers, points = ViewExporter(network).network_messages()
        assert (markers.topic, points.topic) == (TOPIC_NETWORK, "/uam/view/network_points")
        arr = ts.deserialize_cdr(markers.data, "visualization_msgs/msg/MarkerArray")
        lists = [m for m in arr.markers if m.type == MARKER_LINE_LIST and m.action == 0]
        assert len(lists) == n_lists
        assert sum(len(m.points) for m in lists) == 2 * net.n_edges
        assert len({(m.color.r, m.color.g, m.color.b) for m in lists}) == n_lists
    with pytest.raises(ValueError, match="edge_levels: 2 levels for 13 corridors"):
        ViewExporter(NS(**{**leveled.__dict__, "edge_levels": [0, 1]})).network_messages()


@pytest.fixture(scope="module")
def run_mcap(tmp_path_factory):
    path = tmp_path_factory.mktemp("views") / "run.mcap"
    result, net = record_run(path, "greedy", duration_s=150.0, stop_s=160)
    return path, result, net


def test_rosbags_reads_every_view_message_with_utc_stamps(run_mcap):
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore
    from uam_planner.geo import enu_to_geodetic

    path, result, net = run_mcap
    lat_lon = net.lat_lon_alt[:, :2]
    lo, hi = lat_lon.min(axis=0) - 1e-3, lat_lon.max(axis=0) + 1e-3
    counts: dict[str, int] = {}
    fleet_sizes = {}
    clouds = {}
    fixes = {}
    with AnyReader([path], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
        for conn, t_ns, raw in r.messages():
            msg = r.deserialize(raw, conn.msgtype)
            counts[conn.msgtype] = counts.get(conn.msgtype, 0) + 1
            if conn.topic == "/uam/fleet_state":
                fleet_sizes[t_ns] = [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]
                fleet_sizes.setdefault(("ids", t_ns), [v.vehicle_id for v in msg.vehicles])
                continue
            if not conn.topic.startswith("/uam/view/"):
                continue
            stamp = msg.markers[0].header.stamp if conn.msgtype.endswith("MarkerArray") else msg.header.stamp
            assert stamp.sec * SEC + stamp.nanosec == START_NS + t_ns, conn.topic   # real UTC
            if conn.topic == TOPIC_FLEET_CLOUD:
                clouds[t_ns] = np.frombuffer(bytes(msg.data), dtype="<f4").reshape(-1, 3)
                assert msg.header.frame_id == "enu" and msg.width == len(clouds[t_ns])
            elif conn.msgtype == "sensor_msgs/msg/NavSatFix":
                assert lo[0] <= msg.latitude <= hi[0] and lo[1] <= msg.longitude <= hi[1], conn.topic
                assert msg.header.frame_id == ""
                fixes[(t_ns, conn.topic)] = (msg.latitude, msg.longitude, msg.altitude)
            elif conn.topic == TOPIC_ROUTES:
                (m,) = msg.markers
                assert m.type == MARKER_LINE_STRIP and len(m.points) >= 2 and m.lifetime.sec > 0
    ids = {t: v for t, v in fleet_sizes.items() if isinstance(t, tuple)}
    fleet = {t: v for t, v in fleet_sizes.items() if not isinstance(t, tuple)}
    # a cloud per fleet state, and the network's points (for Rerun's MCAP import) once
    assert counts["sensor_msgs/msg/PointCloud2"] - 1 == len(fleet) == 161
    assert counts["visualization_msgs/msg/MarkerArray"] == 1 + result.summary["approved"]
    # fixes every 5 s of simulation time (the default fix period), one per airborne vehicle
    due = {t for t in fleet if t % (5 * SEC) == 0}
    assert sum(len(fleet[t]) for t in due) == counts["sensor_msgs/msg/NavSatFix"] > 0
    assert {t for t, _ in fixes} <= due
    for t_ns, pos in fleet.items():   # the cloud is the fleet (float32 precision)
        np.testing.assert_allclose(clouds[t_ns], np.array(pos).reshape(-1, 3), atol=1e-3)
        if pos and t_ns in due:   # each fix is its vehicle's ENU position on the Earth
            lla = enu_to_geodetic(np.array(pos), net.origin_lat_lon_alt)
            got = np.array([fixes[(t_ns, vehicle_topic(vid))] for vid in ids[("ids", t_ns)]])
            np.testing.assert_allclose(got, lla, atol=1e-9)


@pytest.mark.skipif(_cli() is None, reason="rerun CLI (rerun-sdk) not installed")
def test_rerun_mcap_convert_yields_points_and_geo_points(run_mcap, tmp_path):
    path, _, _ = run_mcap
    rrd = tmp_path / "conv.rrd"
    conv = subprocess.run([_cli(), "mcap", "convert", str(path), "-o", str(rrd)], capture_output=True,
                          text=True, timeout=120)
    assert conv.returncode == 0, conv.stdout + conv.stderr
    printed = subprocess.run([_cli(), "rrd", "print", "-vv", str(rrd)], capture_output=True, text=True,
                             timeout=120)
    assert printed.returncode == 0, printed.stderr
    chunks = printed.stdout.split("entity_path: ")[1:]
    by_entity: dict[str, str] = {}
    for c in chunks:
        name = c.split()[0]
        by_entity[name] = by_entity.get(name, "") + c
    assert "Points3D:positions" in by_entity[TOPIC_FLEET_CLOUD]
    fixes = [e for e in by_entity if e.startswith("/uam/view/fix/")]
    assert fixes and all("GeoPoints:positions" in by_entity[e] for e in fixes)
    assert "ros2_timestamp" in by_entity[TOPIC_FLEET_CLOUD]   # the UTC header stamps, as a timeline
    assert TOPIC_NETWORK in by_entity
    # Rerun 0.41 imports no MarkerArray as geometry: the network is drawn from its point cloud
    assert "Points3D:positions" not in by_entity[TOPIC_NETWORK]
    assert "Points3D:positions" in by_entity["/uam/view/network_points"]


def test_views_are_added_to_an_older_recording(tmp_path):
    """``python -m uam_sim.std_msgs_export`` copies a recording made without view topics and adds
    them; ``--log-time utc`` shifts every message by the scenario start."""
    from uam_sim.recording import read_messages
    from uam_sim.views.std_msgs_export import main

    src = tmp_path / "old.mcap"
    result, _ = record_run(src, "greedy", duration_s=60.0, views=False)
    before = [(m.topic, m.log_time_ns, m.data) for m in read_messages(src)]
    assert not any(t.startswith("/uam/view/") for t, _, _ in before)
    for mode, shift in (("sim", 0), ("utc", START_NS)):
        dst = tmp_path / f"views_{mode}.mcap"
        assert main([str(src), str(dst), "--network", str(TINY), "--log-time", mode]) == 0
        after = list(read_messages(dst))
        kept = [(m.topic, m.log_time_ns - shift, m.data) for m in after if not m.topic.startswith("/uam/view/")]
        assert sorted(kept) == sorted(before)           # the project's messages, unchanged
        views = [m for m in after if m.topic.startswith("/uam/view/")]
        assert {m.topic for m in views} >= {TOPIC_NETWORK, TOPIC_FLEET_CLOUD, TOPIC_ROUTES}
        assert sum(m.topic == TOPIC_ROUTES for m in views) == result.summary["approved"]
        assert min(m.log_time_ns for m in after) == shift   # t = 0 is the scenario start in utc mode
    with pytest.raises(SystemExit):   # dst missing: argparse names it
        main([str(src)])


def test_bulk_fleet_encoding_decodes_to_the_same_messages_as_the_per_vehicle_path():
    """The recorder's bulk encoding (one numpy array for all fixes, a cached cloud template) gives
    the messages the per-vehicle encoders give: same topics, same bytes, and rclpy decodes them to
    equal messages; vehicles with no geographic position are left out on both paths."""
    from rclpy.serialization import deserialize_message
    from sensor_msgs.msg import NavSatFix, PointCloud2

    from uam_planner.network import load_network
    from uam_sim.views.std_msgs_export import (TYPE_NAV_SAT_FIX, encode_nav_sat_fixes,
                                         encode_point_cloud_fast)

    net = load_network(TINY)
    exporter = ViewExporter(net, fix_period_s=5.0)
    rng = np.random.default_rng(7)
    for n in (0, 1, 2, 9, 131):
        ids = [f"generator/r{j:05d}_{j % 4:03d}" for j in range(n)] + (["x-y.z", "9lives"] if n > 5 else [])
        pos = rng.uniform(-8000.0, 8000.0, size=(len(ids), 3))
        if n > 5:
            pos[3] = np.nan  # no fix for this one on either path
        for t_ns in (0, 5 * SEC, 7 * SEC + 250_000_000, 3500 * SEC):
            bulk = exporter.fleet_messages(t_ns, ids, pos)
            old = exporter.fleet_messages_per_vehicle(t_ns, ids, pos)
            assert [(m.topic, m.type_name, m.sim_time_ns) for m in bulk] == \
                   [(m.topic, m.type_name, m.sim_time_ns) for m in old]
            assert len(bulk) == (1 + len(ids) - (n > 5) if t_ns % (5 * SEC) == 0 and ids else 1)
            for b, o in zip(bulk, old):
                cls = NavSatFix if b.type_name == TYPE_NAV_SAT_FIX else PointCloud2
                assert deserialize_message(b.data, cls) == deserialize_message(o.data, cls)
                assert b.data == o.data
    # the encoders themselves, for frame ids of every alignment
    lla = np.array([[1.29, 103.85, 120.0], [1.3, 103.9, -5.0]])
    for frame in ("", "a", "ab", "abc", "enu", "world_frame"):
        assert encode_nav_sat_fixes(START_NS + 3, frame, lla) == \
            [encode_nav_sat_fix(START_NS + 3, frame, *row) for row in lla]
        for pts in (np.zeros((0, 3)), lla, rng.uniform(-1, 1, (50, 3))):
            assert encode_point_cloud_fast(START_NS + 3, frame, pts) == encode_point_cloud(START_NS + 3, frame, pts)


def test_lines_are_sampled_into_points_at_most_25_m_apart():
    from uam_sim.views.std_msgs_export import sample_lines

    # 100 m east: 0, 25, 50, 75, 100; 30 m north: two steps of 15 m; a point-long segment: twice
    got = sample_lines([[[0, 0, 0], [100, 0, 0]], [[0, 0, 10], [0, 30, 10]], [[5, 5, 5], [5, 5, 5]]])
    np.testing.assert_allclose(got, [[0, 0, 0], [25, 0, 0], [50, 0, 0], [75, 0, 0], [100, 0, 0],
                                     [0, 0, 10], [0, 15, 10], [0, 30, 10], [5, 5, 5], [5, 5, 5]])
    assert sample_lines(np.zeros((0, 2, 3))).shape == (0, 3)


def test_constraints_are_drawn_with_their_window_as_markers_and_points():
    """A 500 m square over the origin, 0-300 m, [0, 10000) s: its outline is 2 rings of 4 sides
    and 4 vertical edges (12 segments = 24 LINE_LIST points); as points every 25 m, 21 per side of a
    ring (8 sides) and 13 per vertical edge (4): 220. A vertiport closure is a 150 m ring at 0 m."""
    from rosbags.typesys import Stores, get_typestore
    from uam_planner.constraints import Constraint
    from uam_planner.network import load_network

    net = load_network(TINY)
    square = Constraint("hub", 1, "event", 0.0, 10000.0, rings_m=(np.array([[-250, -250], [250, -250], [250, 250],
                                                                          [-250, 250]], dtype=float),),
                        lower_m=0.0, upper_m=300.0)
    closed = Constraint("C-closed", 2, "", 0.0, 150.0, vertiport_id="C")
    markers, cloud = ViewExporter(net).constraint_messages(30 * SEC, [square, closed])
    assert (markers.topic, cloud.topic) == ("/uam/view/constraints", "/uam/view/constraint_points")
    assert markers.sim_time_ns == cloud.sim_time_ns == 30 * SEC
    ts = get_typestore(Stores.ROS2_JAZZY)
    arr = ts.deserialize_cdr(markers.data, "visualization_msgs/msg/MarkerArray")
    assert arr.markers[0].action == 3   # DELETEALL: the set replaces the one before
    lines = [m for m in arr.markers if m.type == MARKER_LINE_LIST and m.action == 0]
    texts = sorted(m.text for m in arr.markers if m.type == 9)
    assert texts == ["C-closed v2 [0, 150) s", "hub v1 0..300 m [0, 10000) s"]
    by_len = sorted(len(m.points) for m in lines)
    assert by_len == [24, 2 * 48]   # the closure's ring: 48 segments
    pc = ts.deserialize_cdr(cloud.data, "sensor_msgs/msg/PointCloud2")
    # the closure's ring: 48 segments of 2 pi 150 / 48 = 19.6 m < 25 m, each drawn by its 2 ends
    assert pc.width == 220 + 48 * 2
    empty_markers, empty_cloud = ViewExporter(net).constraint_messages(60 * SEC, [])
    assert len(ts.deserialize_cdr(empty_markers.data, "visualization_msgs/msg/MarkerArray").markers) == 1
    assert ts.deserialize_cdr(empty_cloud.data, "sensor_msgs/msg/PointCloud2").width == 0
