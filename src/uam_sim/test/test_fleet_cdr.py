"""Fleet kinematics and the simulator's direct CDR encoding of FleetState and PoseArray."""
# (rclpy is imported inside the CDR test only: the kinematics tests need no ROS.)

from __future__ import annotations

import numpy as np
import pytest

from uam_planner.trajectory import Trajectory
from uam_sim.recording.cdr import encode_clock, encode_fleet_state, encode_pose_array, yaw_quaternions
from uam_sim.world.fleet import PHASE_CRUISE, PHASE_LANDING, PHASE_TAKEOFF, Fleet


def _fleet():
    fleet = Fleet()
    # b: 3 segments, 10 m/s east then north then down; a: one straight 100 m segment north, later
    fleet.add("b", Trajectory([0.0, 10.0, 20.0, 30.0], [[0, 0, 0], [100, 0, 0], [100, 100, 0], [100, 100, -100]]))
    fleet.add("a", Trajectory([5.0, 15.0], [[0, 0, 50], [0, 100, 50]]))
    return fleet


def test_positions_velocities_phases_and_distances_by_hand():
    fleet = _fleet()
    s = fleet.sample(12.5)
    assert s.vehicle_ids == ["a", "b"]  # sorted by id
    np.testing.assert_allclose(s.positions_m, [[0, 75, 50], [100, 25, 0]])
    np.testing.assert_allclose(s.velocities_mps, [[0, 10, 0], [0, 10, 0]])
    assert list(s.phases) == [PHASE_TAKEOFF, PHASE_CRUISE] and list(s.segment_indices) == [0, 1]
    np.testing.assert_allclose(s.flown_m, [75, 125])
    np.testing.assert_allclose(s.remaining_m, [25, 175])
    s = fleet.sample(25.0)
    assert s.vehicle_ids == ["b"] and list(s.phases) == [PHASE_LANDING]  # a landed at 15 s
    assert len(fleet) == 1
    assert len(fleet.sample(0.0)) == 1 and len(fleet.sample(30.0)) == 1 and len(fleet.sample(30.5)) == 0
    assert len(fleet) == 0


def test_a_flight_cannot_be_added_twice():
    fleet = _fleet()
    with pytest.raises(ValueError, match="vehicle_id: 'a'"):
        fleet.add("a", Trajectory([0.0, 1.0], [[0, 0, 0], [1, 0, 0]]))


def test_a_fleet_of_flights_added_over_time_samples_each_flight_where_it_is():
    """Flights added epoch by epoch, landing in between (the padded arrays are rebuilt only on
    adds, landed rows masked): every sample holds exactly the flights airborne then, each at
    its own trajectory's position."""
    rng = np.random.default_rng(3)
    fleet, flights = Fleet(), {}
    for t in range(0, 400):
        if t % 30 == 0:
            for j in range(int(rng.integers(0, 6))):
                k = int(rng.integers(2, 7))
                times = t + 0.5 + np.cumsum(rng.uniform(1.0, 40.0, k)) - 1.0
                tr = Trajectory(times, rng.normal(scale=500.0, size=(k, 3)))
                vid = f"v{t:03d}_{j}"
                fleet.add(vid, tr)
                flights[vid] = tr
        s = fleet.sample(float(t))
        expected = sorted(v for v, tr in flights.items() if tr.is_airborne(float(t)))
        assert s.vehicle_ids == expected, t
        for i, vid in enumerate(s.vehicle_ids):
            np.testing.assert_allclose(s.positions_m[i], flights[vid].position_at(float(t)), atol=1e-9)
        assert len(fleet) == sum(1 for tr in flights.values() if tr.arrival_s >= t)


def test_direct_cdr_equals_rclpy_serialization():
    pytest.importorskip("rclpy", reason="needs the built workspace")
    from geometry_msgs.msg import Point, Pose, PoseArray, Quaternion, Vector3
    from rclpy.serialization import deserialize_message, serialize_message
    from uam_msgs.msg import FleetState, VehicleState
    from uam_planner.fleet_state_cdr import observed_fleet

    for t, session in ((0.0, "3f2a9c01d4e5b6a7"), (12.5, "a"), (29.0, "abcd"), (40.0, "s" * 5)):  # 2, 2, 1, 0 vehicles
        s = _fleet().sample(t)
        msg = FleetState(step_index=int(t * 2), session=session)
        msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = int(t), 500_000_000, "enu"
        poses = PoseArray()
        poses.header = msg.header
        quats = yaw_quaternions(s.velocities_mps)
        for i, vid in enumerate(s.vehicle_ids):
            p, v = s.positions_m[i], s.velocities_mps[i]
            msg.vehicles.append(VehicleState(
                vehicle_id=vid, position=Point(x=p[0], y=p[1], z=p[2]), velocity=Vector3(x=v[0], y=v[1], z=v[2]),
                phase=int(s.phases[i]), segment_index=int(s.segment_indices[i]),
                distance_flown_m=float(s.flown_m[i]), distance_remaining_m=float(s.remaining_m[i])))
            q = quats[i]
            poses.poses.append(Pose(position=Point(x=p[0], y=p[1], z=p[2]),
                                    orientation=Quaternion(x=q[0], y=q[1], z=q[2], w=q[3])))
        ours = encode_fleet_state(int(t), 500_000_000, "enu", int(t * 2), s.vehicle_ids, s.positions_m,
                                  s.velocities_mps, s.phases, s.segment_indices, s.flown_m, s.remaining_m, session)
        # Same layout and content (rmw leaves alignment padding uninitialised, so compare decoded
        # messages and lengths rather than raw bytes).
        assert len(ours) == len(serialize_message(msg))
        assert deserialize_message(ours, FleetState) == msg
        # what the planner node reads from rclpy's own bytes
        theirs = observed_fleet(serialize_message(msg))
        assert theirs.session == session and theirs.vehicle_ids == list(s.vehicle_ids)
        np.testing.assert_array_equal(theirs.positions_m, np.asarray(s.positions_m).reshape(-1, 3))
        pose_bytes = encode_pose_array(int(t), 500_000_000, "enu", s.positions_m, quats)
        assert len(pose_bytes) == len(serialize_message(poses))
        assert deserialize_message(pose_bytes, PoseArray) == poses


def test_stamps_ids_and_positions_are_read_from_the_cdr_without_deserializing():
    """What the recorder and the analysis read from raw bytes equals the deserialized message."""
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import PoseArray
    from rosgraph_msgs.msg import Clock
    from uam_msgs.msg import FlightPlan, PlanningReport
    from uam_planner.fleet_state_cdr import observed_fleet
    from uam_sim.recording.cdr import fleet_state_digest, fleet_state_step_index, leading_stamp_ns, serialize_exact

    cases = (("", []), ("enu", ["a"]), ("e", ["r00001_000", "x" * 13, "é", "b7"]),
             ("enu", [f"r{i:05d}_000" for i in range(40)]),          # one length: strided path
             ("en", ["x"] + [f"r{i:05d}_000" for i in range(5)]),    # general, then strided
             ("enu", ["é1", "é2", "é3"]))                            # one length, not ASCII
    for frame, ids in cases:
        pos = np.arange(3.0 * len(ids)).reshape(-1, 3) * 1.5 - 7.0
        vel = np.arange(3.0 * len(ids)).reshape(-1, 3) * -0.25 + 2.0
        session = "s" * (len(ids) % 7) + "-run"
        data = encode_fleet_state(77, 123, frame, 5, ids, pos, vel, np.zeros(len(ids), np.uint8),
                                  np.arange(len(ids), dtype=np.uint32), np.ones(len(ids)), np.ones(len(ids)),
                                  session)
        d = fleet_state_digest(data, positions=True)
        assert d.vehicle_ids == ids and d.step_index == 5 == fleet_state_step_index(data)
        # the planner's reading: the same, and the session after the vehicles
        o = observed_fleet(data)
        assert o.session == session and o.vehicle_ids == ids
        np.testing.assert_array_equal(o.positions_m, pos)
        with pytest.raises(ValueError, match="session"):
            observed_fleet(data[:-(len(session) + 2)])
        np.testing.assert_array_equal(d.positions_m, pos)
        np.testing.assert_array_equal(d.velocities_mps, vel)
        assert leading_stamp_ns(data) == 77 * 10**9 + 123
    for msg in (Clock(clock=Time(sec=9, nanosec=8)), PoseArray(), FlightPlan(request_id="x"),
                PlanningReport(epoch_index=3)):
        stamp = msg.clock if isinstance(msg, Clock) else msg.header.stamp
        stamp.sec, stamp.nanosec = 9, 8
        assert leading_stamp_ns(serialize_exact(msg)) == 9_000_000_008
    assert leading_stamp_ns(b"\x00\x00\x00\x00" + bytes(8)) is None  # big-endian: not read


@pytest.mark.parametrize("frame_id", ["enu", "a-frame-id-of-odd-length"])
def test_direct_cdr_with_ids_of_every_length_mod_8(frame_id):
    """The vectorised encoder pads after each id by its length; ids of lengths 1..17 (and the
    scoped ids the simulator flies) decode exactly as rclpy serializes them."""
    pytest.importorskip("rclpy", reason="needs the built workspace")
    from geometry_msgs.msg import Point, Vector3
    from rclpy.serialization import deserialize_message, serialize_message
    from uam_msgs.msg import FleetState, VehicleState
    from uam_planner.fleet_state_cdr import observed_fleet

    ids = ["x" * k for k in range(1, 18)] + ["generator/r00012_003", "médecin/é"]
    n = len(ids)
    rng = np.random.default_rng(1)
    pos, vel = rng.normal(size=(n, 3)), rng.normal(size=(n, 3))
    phases, segs = rng.integers(0, 3, n), rng.integers(0, 9, n)
    flown, rem = rng.uniform(0, 1e4, n), rng.uniform(0, 1e4, n)
    for _ in range(2):  # the second time the ids come from the cache
        ours = encode_fleet_state(7, 123, frame_id, 42, ids, pos, vel, phases, segs, flown, rem, frame_id[:3])
        msg = FleetState(step_index=42, session=frame_id[:3], vehicles=[VehicleState(
            vehicle_id=ids[i], position=Point(x=pos[i, 0], y=pos[i, 1], z=pos[i, 2]),
            velocity=Vector3(x=vel[i, 0], y=vel[i, 1], z=vel[i, 2]), phase=int(phases[i]),
            segment_index=int(segs[i]), distance_flown_m=float(flown[i]), distance_remaining_m=float(rem[i]))
            for i in range(n)])
        msg.header.stamp.sec, msg.header.stamp.nanosec, msg.header.frame_id = 7, 123, frame_id
        assert len(ours) == len(serialize_message(msg))
        assert deserialize_message(ours, FleetState) == msg
        theirs = observed_fleet(serialize_message(msg))   # ids of every length, then the session
        assert theirs.session == frame_id[:3] and theirs.vehicle_ids == ids
        np.testing.assert_array_equal(theirs.positions_m, pos)
        # what the planner node reads from rclpy's own bytes
        theirs = observed_fleet(serialize_message(msg))
        assert theirs.session == msg.session and theirs.vehicle_ids == ids and theirs.step_index == 42
        np.testing.assert_array_equal(theirs.positions_m, pos)


def test_clock_cdr_equals_rclpy_serialization():
    pytest.importorskip("rosgraph_msgs.msg", reason="needs the built workspace")
    from builtin_interfaces.msg import Time
    from rclpy.serialization import deserialize_message, serialize_message
    from rosgraph_msgs.msg import Clock

    for sec, nanosec in ((0, 0), (3500, 0), (17, 999_999_999), (-1, 5)):
        msg = Clock(clock=Time(sec=sec, nanosec=nanosec))
        assert encode_clock(sec, nanosec) == serialize_message(msg)
        assert deserialize_message(encode_clock(sec, nanosec), Clock) == msg


def test_a_new_version_flies_from_its_effective_instant_and_must_chain():
    fleet = _fleet()
    # b re-planned at t = 15 (half-way along its second segment, at (100, 50, 0)): from the
    # waypoint (100, 100, 0) at t = 20 it turns west instead of descending, 100 m in 10 s
    new = Trajectory([0.0, 10.0, 20.0, 30.0], [[0, 0, 0], [100, 0, 0], [100, 100, 0], [0, 100, 0]])
    fleet.update("b", new, 15.0)
    s = fleet.sample(25.0)
    np.testing.assert_allclose(s.positions_m[s.vehicle_ids.index("b")], [50, 100, 0])
    s = fleet.sample(12.5)   # before the switch the old and new versions are the same path
    np.testing.assert_allclose(s.positions_m[s.vehicle_ids.index("b")], [100, 25, 0])
    # a version that is not where b is at the switch is refused, and b keeps flying its plan
    jump = Trajectory([15.0, 25.0], [[0, 0, 0], [0, 100, 0]])
    with pytest.raises(ValueError, match="versions do not chain"):
        fleet.update("b", jump, 15.0)
    np.testing.assert_allclose(fleet.sample(25.0).positions_m[fleet.sample(25.0).vehicle_ids.index("b")],
                               [50, 100, 0])
    assert fleet.total_added == 2       # a new version is not a new flight
    assert fleet.remove("b") and fleet.sample(25.0).vehicle_ids == []   # cancelled; a landed at 15
    assert not fleet.remove("b")
