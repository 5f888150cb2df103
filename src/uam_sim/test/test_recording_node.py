"""The recorder node in-process: it records what was published and closes on the run's end."""

from __future__ import annotations

import os
import signal
import subprocess
import sys
from pathlib import Path

import pytest
import yaml

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point, Pose, PoseArray  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.node import Node  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from rosgraph_msgs.msg import Clock  # noqa: E402
from uam_msgs.msg import (EpochSync, FleetState, FlightPlan, FlightRequest,  # noqa: E402
                          PlanningReport, VehicleState, Waypoint)

from uam_contract.names import resolved  # noqa: E402
from uam_sim.nodes.recorder_node import RECORDED_TOPICS, RecorderNode  # noqa: E402
from uam_sim.recording.mcap_reader import is_complete, read_messages  # noqa: E402

pytestmark = pytest.mark.ros
ROOT = Path(__file__).resolve().parents[3]
NS = 1_000_000_000


def t(sec: int) -> Time:
    return Time(sec=sec, nanosec=0)


def _recorder_and_talker(ros_context, spin_until, out, rerun: str, talker_name: str):
    """A recorder writing ``out`` and a node publishing on every recorded topic, matched."""
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(out)), Parameter("rerun", value=rerun),
        Parameter("network", value=str(ROOT / "config" / "networks" / "tiny.yaml"))])
    talker = Node(talker_name, context=ros_context)
    pubs = {resolved(topic): talker.create_publisher(cls, topic, qos) for topic, (cls, qos) in RECORDED_TOPICS.items()}
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(talker)
    assert spin_until(executor, lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()), 20)
    return recorder, talker, pubs, executor


def test_after_a_clean_end_the_recorder_waits_for_what_the_end_announces(ros_context, spin_until, tmp_path):
    """The simulator's end of run (t = 60 s, 30 s epochs) arrives before the recorder has the
    fleet state of 60 s and the report of epoch 1 (a recorder behind under load): it stays open
    past finish_quiet_s until both are in, then closes."""
    import time as _time
    out = tmp_path / "rec" / "run.mcap"
    recorder, talker, pubs, executor = _recorder_and_talker(ros_context, spin_until, out, "off", "talker_end")
    try:

        def state(k):
            fs = FleetState(step_index=k)
            fs.header.stamp = t(k)
            pubs["/uam/fleet_state"].publish(fs)
        for k in (0, 30, 59):
            state(k)
        report = PlanningReport(epoch_index=0)
        report.header.stamp = t(0)
        pubs["/uam/planning_reports"].publish(report)
        pubs["/uam/epoch_sync"].publish(EpochSync(sender="simulator", session="s", finished=True,
                                                  epoch_time=t(60), epoch_s=30.0))
        assert spin_until(executor, lambda: recorder.finish_requested, 10)
        end = _time.monotonic() + 2.0          # four times finish_quiet_s
        while _time.monotonic() < end:
            executor.spin_once(timeout_sec=0.05)
        assert not recorder.finished
        state(60)
        late = PlanningReport(epoch_index=1)
        late.header.stamp = t(30)
        pubs["/uam/planning_reports"].publish(late)
        assert spin_until(executor, lambda: recorder.finished, 5)   # well before finish_timeout_s
    finally:
        executor.shutdown()
        recorder.destroy_node()
        talker.destroy_node()


def test_records_every_topic_and_closes_on_the_simulators_finish(ros_context, spin_until, tmp_path):
    out = tmp_path / "rec" / "run.mcap"
    recorder, talker, pubs, executor = _recorder_and_talker(ros_context, spin_until, out, "save", "talker")
    try:
        for k in range(5):
            pubs["/clock"].publish(Clock(clock=t(k)))
            fs = FleetState(step_index=k, vehicles=[VehicleState(vehicle_id="r1", position=Point(x=10.0 * k))])
            fs.header.stamp = t(k)
            pubs["/uam/fleet_state"].publish(fs)
            pa = PoseArray(poses=[Pose()])
            pa.header.stamp = t(k)
            pubs["/uam/fleet_poses"].publish(pa)
        pubs["/uam/requests"].publish(FlightRequest(request_id="r1", request_time=t(0)))
        plan = FlightPlan(request_id="r1", outcome=FlightPlan.OUTCOME_APPROVED,
                          waypoints=[Waypoint(position=Point(), time=t(0)),
                                     Waypoint(position=Point(x=100.0), time=t(10))])
        plan.header.stamp = t(0)
        pubs["/uam/flight_plans"].publish(plan)
        report = PlanningReport(approved=1)
        report.header.stamp = t(0)
        pubs["/uam/planning_reports"].publish(report)
        assert spin_until(executor, lambda: recorder.messages_written == 18, 20)
        assert not recorder.finished
        # a planner's EpochSync does not end the run; the simulator's finished one does
        pubs["/uam/epoch_sync"].publish(EpochSync(sender="planner", finished=True, epoch_time=t(5)))
        pubs["/uam/epoch_sync"].publish(EpochSync(sender="simulator", finished=True, epoch_time=t(4)))
        assert spin_until(executor, lambda: recorder.finished, 20)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        talker.destroy_node()

    assert is_complete(out)
    msgs = list(read_messages(out))
    counts = {}
    for m in msgs:
        counts[m.topic] = counts.get(m.topic, 0) + 1
    views = {k: v for k, v in counts.items() if k.startswith("/uam/view/")}
    assert {k: v for k, v in counts.items() if k not in views} == {
        "/clock": 5, "/uam/fleet_state": 5, "/uam/fleet_poses": 5, "/uam/requests": 1,
        "/uam/flight_plans": 1, "/uam/planning_reports": 1, "/uam/epoch_sync": 2}
    # the run in standard types (views on by default): the network once, a cloud per fleet
    # state, the approved route, and vehicle r1's fix at t = 0 (one every 5 s)
    assert views == {"/uam/view/network": 1, "/uam/view/network_points": 1, "/uam/view/fleet": 5,
                     "/uam/view/routes": 1, "/uam/view/fix/r1": 1}
    from rosbags.typesys import Stores, get_typestore
    ts = get_typestore(Stores.ROS2_JAZZY)
    clouds = [m for m in msgs if m.topic == "/uam/view/fleet"]
    last = ts.deserialize_cdr(clouds[-1].data, "sensor_msgs/msg/PointCloud2")
    # one clock for every topic: the view stamps are simulation time, as the fleet state's (they
    # were UTC from 2025-01-06 while /uam/* carried simulation time)
    assert (last.header.stamp.sec, last.header.stamp.nanosec) == (4, 0) and last.width == 1
    # log time = the message's simulation stamp on the scenario's UTC clock (issue 22): by default
    # 2025-01-06T00:00:00Z = 1736121600 s after the Unix epoch, so viewers show that date
    zero = 1736121600 * NS
    assert [m.log_time_ns for m in clouds] == [zero + k * NS for k in range(5)]
    fleet_times = [m.log_time_ns for m in msgs if m.topic == "/uam/fleet_state"]
    assert fleet_times == [zero + k * NS for k in range(5)]
    from uam_sim.recording.mcap_reader import iter_decoded, read_metadata
    assert read_metadata(out, "uam_clock") == {"log_time_zero_ns": str(zero),
                                               "log_time_start_utc": "2025-01-06T00:00:00Z"}
    # the readers give simulation time back (the analysis works in seconds from the start)
    assert [t_ns for _topic, t_ns, _m in iter_decoded(out, topics=["/uam/fleet_state"])] == [k * NS for k in range(5)]
    assert [t_ns for _topic, t_ns, _m in iter_decoded(out, "rosbags", topics=["/uam/fleet_state"])] == \
        [k * NS for k in range(5)]
    # offered QoS as the publisher offered it (asked from the graph)
    plans_qos = yaml.safe_load(next(m.qos_yaml for m in msgs if m.topic == "/uam/flight_plans"))
    assert plans_qos[0]["durability"] == "transient_local" and plans_qos[0]["reliability"] == "reliable"
    rrd = out.with_suffix(".rrd")
    assert rrd.exists() and rrd.stat().st_size > 0


@pytest.mark.parametrize("sig", [signal.SIGTERM, signal.SIGINT], ids=["SIGTERM", "SIGINT"])
def test_sigterm_and_ctrl_c_close_the_file_properly(tmp_path, sig, ros_process_domain_id):
    """A recorder process stopped with SIGTERM or Ctrl-C leaves a complete file listing every topic."""
    out = tmp_path / "term.mcap"
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))  # not the in-process nodes' domain
    env["PYTHONPATH"] = str(ROOT / "src" / "uam_sim") + os.pathsep + str(ROOT / "src" / "uam_planner") \
        + os.pathsep + env.get("PYTHONPATH", "")
    proc = subprocess.Popen([sys.executable, "-m", "uam_sim.nodes.recorder_node", "--ros-args",
                             "-p", f"output:={out}"], env=env, stdout=subprocess.PIPE,
                            stderr=subprocess.STDOUT, text=True)
    try:
        # wait until the node is up (it logs once its subscriptions exist)
        lines = []
        for line in proc.stdout:
            lines.append(line)
            if f"recording {len(RECORDED_TOPICS)} topics" in line:  # 9: with uam/constraints (issue 22) and uam/conformance (issue 23)
                break
        assert out.exists(), "".join(lines)
        proc.send_signal(sig)
        rest, _ = proc.communicate(timeout=60)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 0, "".join(lines) + rest
    assert is_complete(out)
    from mcap.reader import make_reader
    with open(out, "rb") as f:
        summary = make_reader(f).get_summary()
    assert {c.topic for c in summary.channels.values()} == set(map(resolved, RECORDED_TOPICS))


def test_recorder_checks_announced_approvals_and_never_deserializes_fleet_states(
        ros_context, spin_until, tmp_path, monkeypatch):
    """Reports announce 2 approvals, 1 approved plan arrives, and a fleet state is missing: the
    recording says so (metadata),
    and the analysis will not call it OK. Stamps of /clock, fleet states and poses are read from
    the CDR bytes: those messages are never deserialized (they were most of the recorder's CPU)."""
    import uam_sim.nodes.recorder_node as recorder_module
    from uam_contract import names as c
    from uam_sim.audit.analysis import summarize
    from uam_sim.recording.mcap_reader import read_metadata

    decoded = []
    real = recorder_module.deserialize_message

    def counting(data, cls):
        decoded.append(cls.__name__)
        return real(data, cls)

    monkeypatch.setattr(recorder_module, "deserialize_message", counting)
    out = tmp_path / "run.mcap"
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(out)), Parameter("rerun", value="save")])
    talker = Node("talker", context=ros_context)
    pubs = {topic: talker.create_publisher(cls, topic, qos) for topic, (cls, qos) in RECORDED_TOPICS.items()}
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(talker)
    try:
        assert spin_until(executor, lambda: all(p.get_subscription_count() >= 1 for p in pubs.values()), 20)
        for k in range(3):
            pubs[c.TOPIC_CLOCK].publish(Clock(clock=t(k)))
            # step 2's fleet state never arrives (lost on the way): the check says so
            fs = FleetState(step_index=(0, 1, 3)[k], vehicles=[VehicleState(vehicle_id=v) for v in ("r1", "r2")])
            fs.header.stamp = t(k)
            pubs[c.TOPIC_FLEET].publish(fs)
            pa = PoseArray(poses=[Pose(), Pose()])
            pa.header.stamp = t(k)
            pubs[c.TOPIC_POSES].publish(pa)
        plan = FlightPlan(request_id="r1", outcome=FlightPlan.OUTCOME_APPROVED,
                          waypoints=[Waypoint(position=Point(), time=t(0)),
                                     Waypoint(position=Point(x=100.0), time=t(10))])
        plan.header.stamp = t(0)
        pubs[c.TOPIC_PLANS].publish(plan)
        report = PlanningReport(approved=2)
        report.header.stamp = t(0)
        pubs[c.TOPIC_REPORTS].publish(report)
        assert spin_until(executor, lambda: recorder.messages_written == 11, 20)
        pubs[c.TOPIC_SYNC].publish(EpochSync(sender="simulator", finished=True, epoch_time=t(2)))
        assert spin_until(executor, lambda: recorder.finished, 20)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        talker.destroy_node()

    assert not {"FleetState", "PoseArray", "Clock"} & set(decoded), decoded
    check = read_metadata(out, "uam_recorder_check")
    assert check["ok"] == "false" and check["announced_approvals"] == "2" and check["approved_plans"] == "1"
    assert "2 approvals" in check["verdict"] and "1 approved plan" in check["verdict"]
    assert check["fleet_states"] == "3" and check["fleet_states_missing"] == "1"
    assert "1 fleet state(s) missing" in check["verdict"] and "steps 2" in check["verdict"]
    s = summarize(out)
    assert not s.verified and any("the recorder found" in p for p in s.problems)


def test_recorder_subscribes_to_the_fleet_state_only_once_it_hears_the_planner(ros_context, spin_until, tmp_path):
    """Readiness race (issue 9): the simulator starts when the recorder subscribes to the fleet
    state, but the recorder could still be unmatched with the planner's and the generator's
    publishers; a run stopped early (SIGTERM in test_run_fleet.py, under load) then recorded fleet
    states and no plans or requests. With wait_for_publishers the fleet-state subscription (what
    the simulator waits for) appears only once those topics have matched publishers, and the
    latched plan published before it is in the file."""
    out = tmp_path / "run.mcap"
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(out)),
        Parameter("wait_for_publishers", value=["uam/flight_plans", "uam/requests"])])
    simulator = Node("simulator_probe", context=ros_context)
    fleet_pub = simulator.create_publisher(FleetState, "uam/fleet_state", RECORDED_TOPICS["uam/fleet_state"][1])
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(simulator)
    planner = None
    try:
        spin_until(executor, lambda: False, 1.5)
        assert fleet_pub.get_subscription_count() == 0 and not recorder.ready  # nobody to hear yet
        planner = Node("planner_probe", context=ros_context)
        plans = planner.create_publisher(FlightPlan, "uam/flight_plans", RECORDED_TOPICS["uam/flight_plans"][1])
        requests = planner.create_publisher(FlightRequest, "uam/requests", RECORDED_TOPICS["uam/requests"][1])
        plan = FlightPlan(request_id="r1", outcome=FlightPlan.OUTCOME_REJECTED)
        plans.publish(plan)
        requests.publish(FlightRequest(request_id="r1", request_time=t(0)))
        executor.add_node(planner)
        assert spin_until(executor, lambda: fleet_pub.get_subscription_count() == 1, 20)
        assert recorder.ready
        fs = FleetState(step_index=0)
        fs.header.stamp = t(0)
        fleet_pub.publish(fs)
        assert spin_until(executor, lambda: recorder.messages_written >= 3, 20)
    finally:
        recorder.close()
        executor.shutdown()
        for n in (recorder, simulator, planner):
            if n is not None:
                n.destroy_node()
    counts = {}
    for r in read_messages(out):
        counts[r.topic] = counts.get(r.topic, 0) + 1
    assert counts.get("/uam/flight_plans") == 1 and counts.get("/uam/requests") == 1
    assert counts.get("/uam/fleet_state") == 1


def test_recorder_refuses_waiting_for_a_topic_it_does_not_record(ros_context, tmp_path):
    with pytest.raises(ValueError, match="wait_for_publishers.*'uam/nope'"):
        RecorderNode(context=ros_context, parameter_overrides=[
            Parameter("output", value=str(tmp_path / "r.mcap")),
            Parameter("wait_for_publishers", value=["uam/nope"])])


def test_each_channel_s_log_times_are_in_order_when_its_publishers_stamps_are_not(ros_context, spin_until, tmp_path):
    """`rerun mcap check` reported "PROBLEM /uam/epoch_sync 2 unordered chunks on
    message_log_time": the simulator announces epoch k+1 before the planner and the generator
    report epoch k, and the log time was each message's own stamp."""
    out = tmp_path / "sync.mcap"
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(out)), Parameter("views", value=False),
        Parameter("log_time_start_utc", value="sim")])  # log times in simulation time, as before issue 22
    talker = Node("talker", context=ros_context)
    topic, (cls, qos) = next((k, v) for k, v in RECORDED_TOPICS.items() if k.endswith("epoch_sync"))
    pub = talker.create_publisher(cls, topic, qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(talker)
    sent = [("simulator", 1, 30), ("planner", 0, 0), ("request_generator", 1, 30), ("simulator", 2, 60),
            ("planner", 1, 30)]
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() >= 1, 20)
        for sender, k, sec in sent:
            pub.publish(EpochSync(sender=sender, epoch_index=k, epoch_time=t(sec)))
        assert spin_until(executor, lambda: recorder.messages_written == len(sent), 20)
        pub.publish(EpochSync(sender="simulator", finished=True, epoch_time=t(60)))
        assert spin_until(executor, lambda: recorder.finished, 20)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        talker.destroy_node()
    from rclpy.serialization import deserialize_message
    msgs = [m for m in read_messages(out) if m.topic == "/uam/epoch_sync"]
    assert len(msgs) == len(sent) + 1
    times = [m.log_time_ns for m in msgs]
    assert times == sorted(times) == [30 * NS, 30 * NS, 30 * NS, 60 * NS, 60 * NS, 60 * NS]
    # each message keeps its own stamp in its bytes (the order they arrived in)
    stamps = [deserialize_message(m.data, EpochSync).epoch_time.sec for m in msgs]
    assert stamps == [30, 0, 30, 60, 30, 60]


def test_the_check_says_how_many_fleet_states_it_holds_and_which_steps_it_never_received():
    """A replayed and re-recorded file held 594 of 601 fleet states and its check said "none
    missing": the first seven were published before the recorder subscribed."""
    from rclpy.serialization import serialize_message
    from uam_sim.nodes.recorder_node import RecordingCheck

    check = RecordingCheck()
    for k in range(7, 601):
        check.on_fleet_state(serialize_message(FleetState(step_index=k)))
    r = check.result()
    assert r["fleet_states"] == "594" and r["fleet_states_before_first"] == "7"
    assert "594 fleet states (steps 7..600)" in r["verdict"]
    assert "7 before the first not received (steps 0..6)" in r["verdict"]
    assert "none missing;" not in r["verdict"] and not r["verdict"].endswith("none missing")
    whole = RecordingCheck()
    for k in range(0, 601):
        whole.on_fleet_state(serialize_message(FleetState(step_index=k)))
    assert whole.result()["verdict"].endswith("601 fleet states (steps 0..600), none missing between the first and the last")


def test_view_stamps_are_real_utc_when_a_scenario_start_is_given(ros_context, spin_until, tmp_path):
    out = tmp_path / "utc.mcap"
    recorder = RecorderNode(context=ros_context, parameter_overrides=[
        Parameter("output", value=str(out)), Parameter("scenario_start_utc", value="2025-01-06T00:00:00Z")])
    talker = Node("talker", context=ros_context)
    topic, (cls, qos) = next((k, v) for k, v in RECORDED_TOPICS.items() if k.endswith("fleet_state"))
    sync, (sync_cls, sync_qos) = next((k, v) for k, v in RECORDED_TOPICS.items() if k.endswith("epoch_sync"))
    pub, end = talker.create_publisher(cls, topic, qos), talker.create_publisher(sync_cls, sync, sync_qos)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(recorder)
    executor.add_node(talker)
    try:
        assert spin_until(executor, lambda: pub.get_subscription_count() >= 1 and end.get_subscription_count() >= 1, 20)
        fs = FleetState(step_index=3, vehicles=[VehicleState(vehicle_id="r1")])
        fs.header.stamp = t(3)
        pub.publish(fs)
        assert spin_until(executor, lambda: recorder.messages_written == 1, 20)
        end.publish(EpochSync(sender="simulator", finished=True, epoch_time=t(3)))
        assert spin_until(executor, lambda: recorder.finished, 20)
    finally:
        executor.shutdown()
        recorder.destroy_node()
        talker.destroy_node()
    from rosbags.typesys import Stores, get_typestore
    cloud = next(m for m in read_messages(out) if m.topic == "/uam/view/fleet")
    stamp = get_typestore(Stores.ROS2_JAZZY).deserialize_cdr(cloud.data, "sensor_msgs/msg/PointCloud2").header.stamp
    assert stamp.sec == 1736121600 + 3  # 2025-01-06T00:00:03Z
    assert cloud.log_time_ns == (1736121600 + 3) * NS  # log time on the scenario's clock too (issue 22)
