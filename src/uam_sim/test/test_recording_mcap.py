"""The MCAP recording is what rosbag2 writes, and three independent readers agree on it.

Needs the built workspace (uam_msgs, rclpy serialization): run with scripts/env.sh sourced.
"""

from __future__ import annotations

import os
import shutil
import signal
import subprocess
import sys
import textwrap
from pathlib import Path

import pytest
import yaml

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point, Pose, PoseArray, Vector3  # noqa: E402
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy  # noqa: E402
from rclpy.serialization import serialize_message  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from uam_msgs.msg import (EpochSync, FleetState, FlightPlan, FlightRequest,  # noqa: E402
                          MwisInstance, PlanningReport, VehicleState, Waypoint)

from uam_sim.recording.mcap_reader import (deserialize, is_complete, read_messages,  # noqa: E402
                                 read_messages_tolerant)
from uam_sim.recording.mcap_schema import DEFINITION_SEPARATOR, RecordingError, message_definition  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402
from uam_contract.qos_spec import offered_qos_yaml, parse_offered_qos  # noqa: E402
from uam_contract.stamps import sim_stamp_ns  # noqa: E402

RELIABLE = QoSProfile(depth=100, reliability=ReliabilityPolicy.RELIABLE)
LATCHED = QoSProfile(depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                     durability=DurabilityPolicy.TRANSIENT_LOCAL)


def t(sec: float) -> Time:
    return Time(sec=int(sec), nanosec=int(round((sec - int(sec)) * 1e9)))


def sample_messages() -> list[tuple[str, object, object]]:
    """(topic, qos, message) with one message of every recorded type, fields filled in."""
    req = FlightRequest(request_id="r000001", origin_id="A", destination_id="B", request_time=t(30),
                        earliest_departure=t(30), latest_departure=t(90))
    plan = FlightPlan(request_id="r000001", outcome=FlightPlan.OUTCOME_APPROVED, origin_id="A",
                      destination_id="B", epoch_index=1, departure_time=t(60), arrival_time=t(160),
                      route_node_ids=["A", "W1", "B"], length_m=2000.0, weight=1.0,
                      candidate_index=0, method="mwis", backend="exact",
                      waypoints=[Waypoint(position=Point(x=0.0, y=0.0, z=5.0), time=t(60)),
                                 Waypoint(position=Point(x=1000.0, y=0.0, z=120.0), time=t(110)),
                                 Waypoint(position=Point(x=2000.0, y=0.0, z=5.0), time=t(160))])
    plan.header.stamp = t(60)
    plan.header.frame_id = "enu"
    report = PlanningReport(epoch_index=1, policy="mwis", approved=1, vertices=3, edges=3,
                            solve_time_s=0.002, backend_requested="exact", backend_used="exact",
                            instance=MwisInstance(weights=[1.0, 0.8, 0.5], edges_u=[0, 0, 1],
                                                  edges_v=[1, 2, 2],
                                                  vertex_request_ids=["r000001"] * 3,
                                                  vertex_candidate_index=[0, 1, 2], selected=[0]))
    report.header.stamp = t(60)
    state = FleetState(step_index=61, vehicles=[VehicleState(
        vehicle_id="r000001", position=Point(x=20.0, y=0.0, z=6.0),
        velocity=Vector3(x=20.0, y=0.0, z=2.3), phase=VehicleState.PHASE_TAKEOFF)])
    state.header.stamp = t(61)
    state.header.frame_id = "enu"
    poses = PoseArray(poses=[Pose()])
    poses.header.stamp = t(61)
    poses.header.frame_id = "enu"
    sync = EpochSync(epoch_index=2, epoch_time=t(60), sender="simulator", finished=True)
    return [
        ("/clock", RELIABLE, Clock(clock=t(61))),
        ("/uam/requests", RELIABLE, req),
        ("/uam/flight_plans", LATCHED, plan),
        ("/uam/planning_reports", RELIABLE, report),
        ("/uam/fleet_state", RELIABLE, state),
        ("/uam/fleet_poses", RELIABLE, poses),
        ("/uam/epoch_sync", RELIABLE, sync),
    ]


@pytest.fixture(scope="module")
def recording(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("rec") / "run.mcap"
    with McapRecorder(path) as rec:
        for i, (topic, qos, msg) in enumerate(sample_messages()):
            rec.add_topic(topic, type(msg), qos)
            rec.write(topic, msg, log_time_ns=1_000_000_000 * (i + 1))
        # a second message on one topic, given as CDR bytes
        rec.write("/clock", serialize_message(Clock(clock=t(62))), log_time_ns=62_000_000_000)
    return path


def test_header_schemas_and_channels_are_as_rosbag2_writes_them(recording):
    from mcap.reader import make_reader

    with open(recording, "rb") as f:
        reader = make_reader(f)
        header = reader.get_header()
        summary = reader.get_summary()
    assert header.profile == "ros2"
    assert header.library.startswith("uam_sim/")
    schemas = {s.name: s for s in summary.schemas.values()}
    assert set(schemas) == {"rosgraph_msgs/msg/Clock", "uam_msgs/msg/FlightRequest",
                            "uam_msgs/msg/FlightPlan", "uam_msgs/msg/PlanningReport",
                            "uam_msgs/msg/FleetState", "geometry_msgs/msg/PoseArray",
                            "uam_msgs/msg/EpochSync"}
    assert all(s.encoding == "ros2msg" for s in schemas.values())
    fleet = schemas["uam_msgs/msg/FleetState"].data.decode()
    for dep in ("std_msgs/Header", "builtin_interfaces/Time", "uam_msgs/VehicleState",
                "geometry_msgs/Point", "geometry_msgs/Vector3"):
        assert f"\n{DEFINITION_SEPARATOR}\nMSG: {dep}\n" in fleet
        assert fleet.count(f"MSG: {dep}\n") == 1  # each dependency once
    assert len(DEFINITION_SEPARATOR) == 80 and set(DEFINITION_SEPARATOR) == {"="}
    channels = {c.topic: c for c in summary.channels.values()}
    assert len(channels) == 7
    for topic, channel in channels.items():
        assert channel.message_encoding == "cdr"
        qos = yaml.safe_load(channel.metadata["offered_qos_profiles"])
        assert qos[0]["reliability"] == "reliable"
        assert set(qos[0]) == {"history", "depth", "reliability", "durability", "deadline",
                               "lifespan", "liveliness", "liveliness_lease_duration",
                               "avoid_ros_namespace_conventions"}
        assert channel.metadata["topic_type_hash"].startswith("RIHS01_")
    plans_qos = yaml.safe_load(channels["/uam/flight_plans"].metadata["offered_qos_profiles"])
    assert plans_qos[0]["durability"] == "transient_local" and plans_qos[0]["depth"] == 1000
    stats = summary.statistics
    assert stats.message_count == 8
    by_topic = {summary.channels[cid].topic: n for cid, n in stats.channel_message_counts.items()}
    assert by_topic["/clock"] == 2 and by_topic["/uam/fleet_state"] == 1
    assert summary.chunk_indexes, "the file is chunked and indexed"
    assert "rosbag2" in {m.name for m in summary.metadata_indexes}


def test_rosbag2_metadata_record_describes_the_bag(recording):
    from mcap.reader import make_reader

    with open(recording, "rb") as f:
        records = list(make_reader(f).iter_metadata())
    assert [r.name for r in records] == ["rosbag2", "rosbag2"]  # an empty one first, the final last
    assert yaml.safe_load(records[0].metadata["serialized_metadata"])["version"] == 9
    meta = yaml.safe_load(records[-1].metadata["serialized_metadata"])
    assert meta["version"] == 9 and meta["storage_identifier"] == "mcap"
    assert meta["message_count"] == 8
    counts = {t["topic_metadata"]["name"]: t["message_count"] for t in meta["topics_with_message_count"]}
    assert counts["/clock"] == 2


def test_full_definition_parses_with_rosbags_and_every_message_decodes(recording):
    """rosbags registers our types from the embedded text alone: the definitions are complete."""
    from rosbags.highlevel import AnyReader
    from rosbags.typesys import Stores, get_typestore

    typestore = get_typestore(Stores.ROS2_JAZZY)  # knows std types only, not uam_msgs
    with AnyReader([recording], default_typestore=typestore) as reader:
        assert reader.message_count == 8
        decoded = {}
        for connection, _timestamp, raw in reader.messages():
            decoded.setdefault(connection.topic, []).append(reader.deserialize(raw, connection.msgtype))
    plan = decoded["/uam/flight_plans"][0]
    assert plan.request_id == "r000001" and list(plan.route_node_ids) == ["A", "W1", "B"]
    assert plan.waypoints[1].position.x == 1000.0 and plan.waypoints[2].time.sec == 160
    report = decoded["/uam/planning_reports"][0]
    assert list(report.instance.edges_v) == [1, 2, 2] and report.instance.weights[1] == 0.8
    assert decoded["/uam/fleet_state"][0].vehicles[0].velocity.z == 2.3
    assert decoded["/uam/epoch_sync"][0].finished is True
    assert [c.clock.sec for c in decoded["/clock"]] == [61, 62]


def test_mcap_reader_round_trips_through_rclpy(recording):
    msgs = list(read_messages(recording))
    assert [m.log_time_ns for m in msgs] == sorted(m.log_time_ns for m in msgs)
    originals = {topic: msg for topic, _q, msg in sample_messages()}
    for rec in msgs:
        if rec.topic != "/clock":
            assert deserialize(rec) == originals[rec.topic]


def test_definition_of_a_type_without_dependencies_is_its_file():
    text = message_definition("geometry_msgs/msg/Point")
    assert "float64 x" in text and "MSG:" not in text


def test_bad_input_is_refused_with_the_value(tmp_path):
    with McapRecorder(tmp_path / "x.mcap") as rec:
        with pytest.raises(RecordingError, match="not_a/type/at/all"):
            rec.add_topic("/a", "not_a/type/at/all")
        with pytest.raises(RecordingError, match="relative"):
            rec.add_topic("relative", Clock)
        rec.add_topic("/a", Clock)
        with pytest.raises(RecordingError, match="already recorded"):
            rec.add_topic("/a", FleetState)
        with pytest.raises(RecordingError, match="/b"):
            rec.write("/b", b"", 0)
        with pytest.raises(RecordingError, match="-5"):
            rec.write("/a", Clock(), -5)
    with pytest.raises(RecordingError, match="closed"):
        rec.write("/a", Clock(), 0)


def test_qos_yaml_round_trips():
    qos = QoSProfile(history=HistoryPolicy.KEEP_ALL, depth=1, durability=DurabilityPolicy.TRANSIENT_LOCAL)
    spec = parse_offered_qos(offered_qos_yaml([qos]))[0]
    assert (spec.history, spec.durability, spec.reliability) == ("keep_all", "transient_local", "reliable")
    assert spec.deadline_ns is None


def test_sim_stamp_of_each_type():
    stamps = {topic: sim_stamp_ns(msg) for topic, _q, msg in sample_messages()}
    assert stamps["/clock"] == 61_000_000_000
    assert stamps["/uam/requests"] == 30_000_000_000
    assert stamps["/uam/epoch_sync"] == 60_000_000_000
    assert stamps["/uam/fleet_poses"] == 61_000_000_000
    assert sim_stamp_ns(FleetState()) == 0  # the first step of a run is at time 0
    assert sim_stamp_ns(Point()) is None  # a type without a stamp


def test_torn_recording_still_yields_the_chunks_written_before_the_cut(tmp_path):
    """A writer process killed with SIGKILL: no summary, no footer; flushed chunks survive."""
    path = tmp_path / "killed.mcap"
    script = textwrap.dedent(f"""
        import os, signal, sys
        from rosgraph_msgs.msg import Clock
        from builtin_interfaces.msg import Time
        from uam_sim.recording.mcap_writer import McapRecorder
        rec = McapRecorder({str(path)!r}, flush_period_s=None)
        rec.add_topic("/clock", Clock)
        for i in range(300):
            rec.write("/clock", Clock(clock=Time(sec=i)), i * 1_000_000_000)
            if i < 200 and i % 50 == 49:
                rec.flush()   # what the periodic flush does: four chunks of 50
        os.kill(os.getpid(), signal.SIGKILL)
    """)
    env = dict(os.environ)
    env["PYTHONPATH"] = str(Path(__file__).resolve().parents[1]) + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.run([sys.executable, "-c", script], env=env, capture_output=True, timeout=60)
    assert proc.returncode == -signal.SIGKILL, proc.stderr.decode()
    assert not is_complete(path)
    got = [deserialize(m).clock.sec for m in read_messages_tolerant(path)]
    assert got == list(range(200))  # the unflushed last 100 are lost, nothing else
    # a cut in the middle of the file (inside the third chunk): the two chunks before it read
    data = path.read_bytes()
    cut = tmp_path / "cut.mcap"
    cut.write_bytes(data[: len(data) // 2 + 20])
    got_cut = [deserialize(m).clock.sec for m in read_messages_tolerant(cut)]
    assert got_cut in (list(range(50)), list(range(100)), list(range(150)))
    # rosbags needs the footer and summary: it refuses the torn file ...
    from rosbags.highlevel import AnyReader, AnyReaderError
    with pytest.raises(AnyReaderError, match="magic"):
        with AnyReader([path]):
            pass
    # ... and recover rewrites it into a complete file that every reader opens

    from uam_sim.recording.mcap_recover import recover
    fixed = tmp_path / "fixed.mcap"
    assert recover(path, fixed) == 200
    assert is_complete(fixed)
    with AnyReader([fixed]) as reader:
        assert reader.message_count == 200
        assert reader.topics["/clock"].msgtype == "rosgraph_msgs/msg/Clock"


def _rerun_cli() -> str | None:
    exe = Path(sys.executable).with_name("rerun")
    return str(exe) if exe.exists() else shutil.which("rerun")


@pytest.mark.skipif(_rerun_cli() is None, reason="rerun CLI (rerun-sdk) not installed")
@pytest.mark.slow  # not in `make test-fast`: a subprocess of the rerun CLI
def test_rerun_cli_reads_the_recording(recording, tmp_path):
    cli = _rerun_cli()
    info = subprocess.run([cli, "mcap", "info", str(recording)], capture_output=True, text=True, timeout=120)
    assert info.returncode == 0, info.stderr
    assert "/uam/fleet_state" in info.stdout + info.stderr
    check = subprocess.run([cli, "mcap", "check", str(recording)], capture_output=True, text=True, timeout=120)
    assert check.returncode == 0, check.stdout + check.stderr
    assert "PROBLEM" not in check.stdout + check.stderr, check.stdout
    rrd = tmp_path / "run.rrd"
    conv = subprocess.run([cli, "mcap", "convert", str(recording), "-o", str(rrd)],
                          capture_output=True, text=True, timeout=120)
    assert conv.returncode == 0, conv.stdout + conv.stderr
    assert rrd.stat().st_size > 0
    printed = subprocess.run([cli, "rrd", "print", str(rrd)], capture_output=True, text=True, timeout=120)
    # decoded by reflection from the embedded definitions, not just kept as raw bytes
    assert "uam_msgs.msg.FleetState:message" in printed.stdout + printed.stderr


def test_exact_cdr_size_matches_what_dds_delivers():
    """rmw_serialize pads some messages with junk; the recorder writes the exact CDR.

    The expected lengths were measured from raw DDS subscriptions (Fast DDS, Jazzy): an empty
    MwisInstance is 28 bytes (header + six counts), serialize_message returns 32.
    """
    from rosbags.typesys import Stores, get_typestore, get_types_from_msg

    from uam_sim.recording.cdr import cdr_size, serialize_exact

    assert cdr_size(MwisInstance()) == 28
    assert cdr_size(MwisInstance(edges_u=[7])) == 32
    assert cdr_size(MwisInstance(weights=[1.0])) == 40  # float64 data aligned to 8 after the count
    assert cdr_size(PlanningReport()) == 157  # constraint_set_sha256: 4-aligned, length, NUL
    typestore = get_typestore(Stores.ROS2_JAZZY)
    for _topic, _qos, msg in sample_messages() + [("", None, m) for m in (
            PlanningReport(), MwisInstance(), FlightPlan(), FleetState(), EpochSync(), PoseArray())]:
        name = type(msg).__module__.split(".")[0] + "/msg/" + type(msg).__name__
        typestore.register(get_types_from_msg(message_definition(name), name))
        data = serialize_exact(msg)
        assert len(data) == cdr_size(msg)
        typestore.deserialize_cdr(data, name)  # rosbags checks the length strictly


def test_a_flight_plan_recorded_before_observed_progress_rate_still_reads(tmp_path):
    """Issue 23 item 2 added ``FlightPlan.observed_progress_rate`` (the last field). A recording
    made before it holds the old definition in its schema and messages without the field:
    read with the file's own schema, into today's class, the field at its default 0."""
    from mcap_ros2.writer import Writer
    from uam_sim.recording.mcap_schema import DEFINITION_SEPARATOR, message_definition

    new = message_definition("uam_msgs/msg/FlightPlan")
    head, sep, deps = new.partition("\n" + DEFINITION_SEPARATOR)
    old = head[:head.index("float64 observed_progress_rate")].rstrip("\n") + "\n" + sep + deps
    assert "observed_progress_rate" not in old
    fields = {"header": {"stamp": {"sec": 30, "nanosec": 0}, "frame_id": "enu"}, "operator_id": "op",
              "request_id": "r1", "outcome": 0, "version": 2, "update_kind": "nonconforming",
              "waypoints": [{"position": {"x": 1.0, "y": 2.0, "z": 3.0}, "time": {"sec": 31, "nanosec": 5}}],
              "route_node_ids": ["A", "B"], "length_m": 42.0}

    def one(path, definition, message):
        with open(path, "wb") as f:
            w = Writer(f)
            schema = w.register_msgdef("uam_msgs/msg/FlightPlan", definition)
            w.write_message("/uam/flight_plans", schema, message, log_time=30_000_000_000,
                            publish_time=30_000_000_000)
            w.finish()
        (rec,) = list(read_messages(path))
        return deserialize(rec)

    msg = one(tmp_path / "old.mcap", old, fields)
    assert isinstance(msg, FlightPlan) and msg.observed_progress_rate == 0.0
    assert (msg.operator_id, msg.request_id, msg.version, msg.update_kind, msg.length_m) == \
        ("op", "r1", 2, "nonconforming", 42.0)
    assert list(msg.route_node_ids) == ["A", "B"] and msg.header.stamp.sec == 30
    (wp,) = msg.waypoints
    assert (wp.position.x, wp.position.z, wp.time.sec, wp.time.nanosec) == (1.0, 3.0, 31, 5)
    # a plan of today's definition reads as before (rclpy), the field kept
    msg = one(tmp_path / "new.mcap", new, dict(fields, observed_progress_rate=0.9))
    assert isinstance(msg, FlightPlan) and msg.observed_progress_rate == 0.9 and msg.version == 2
