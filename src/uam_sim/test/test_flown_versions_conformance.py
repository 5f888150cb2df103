"""The recording's conformance of what flew compares each sample with the plan version in force
at that instant (issue 22 item 5), not with the first version: hand-computed tracks."""

from __future__ import annotations

import pytest

from uam_planner.separation import SeparationModel

CYLINDER = SeparationModel("cylinder", 100.0, 30.0)


def _plan(rid, version, effective_s, points):
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FlightPlan, Waypoint

    return FlightPlan(operator_id="op", request_id=rid, outcome=FlightPlan.OUTCOME_APPROVED, version=version,
                      effective_time=Time(sec=int(effective_s)),
                      waypoints=[Waypoint(position=Point(x=float(x), y=float(y), z=float(z)), time=Time(sec=int(t)))
                                 for t, x, y, z in points])


def test_conformance_follows_each_version_from_the_instant_it_takes_effect(tmp_path):
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FleetState, VehicleState

    from uam_sim.world.conformance import ConformanceBounds
    from uam_sim.audit.flown import recording_flown
    from uam_sim.recording.mcap_writer import McapRecorder

    # version 1: east at 10 m/s, (0, 0) at 0 s to (1000, 0) at 100 s; version 2, in force from
    # 50 s: from (500, 0) north to (500, 500) at 100 s. r1 flies version 1 then version 2 (what
    # the simulator does); r2 has the same plans 2 km south and stops at (500, 0) at 50 s (hovers).
    v1 = [(0, 0, 0, 90), (100, 1000, 0, 90)]
    v2 = [(0, 0, 0, 90), (50, 500, 0, 90), (100, 500, 500, 90)]
    south = {"r1": 0.0, "r2": -2000.0}

    def moved(points, dy):
        return [(t, x, y + dy, z) for t, x, y, z in points]
    plans = [_plan(r, 1, 0, moved(v1, south[r])) for r in south] + \
        [_plan(r, 2, 50, moved(v2, south[r])) for r in south]

    def at(rid, k):
        if k <= 50:
            return 10.0 * k, south[rid]
        return 500.0, (10.0 * (k - 50) if rid == "r1" else south[rid])

    path = tmp_path / "versions.mcap"
    rec = McapRecorder(path)
    rec.add_topic("/uam/fleet_state", FleetState)
    with rec:
        for k in range(101):
            fs = FleetState(step_index=k, vehicles=[
                VehicleState(vehicle_id=f"op/{rid}", position=Point(x=x, y=y, z=90.0))
                for rid in south for x, y in [at(rid, k)]])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * 1_000_000_000)
    bounds = ConformanceBounds(lateral_m=25.0, vertical_m=10.0, time_s=30.0)
    got = recording_flown(path, CYLINDER, bounds=bounds, plans=plans)
    c = got["conformance"]
    assert c["flights"] == 2
    # r1 conforms throughout (every error 0; compared with version 1 only, it would be 30 m off
    # laterally at 53 s); r2, hovering at (500, 0) whose planned time is 50 s: late by k - 50 s,
    # over 30 s first at 81 s, nonconforming to its last sample (100 s)
    assert c["nonconforming_flights"] == 1 and c["excursions"] == 1
    assert c["longest_excursion_s"] == pytest.approx(100.0 - 81.0)
    # time in conformance: r1 100 s, r2 81 s of 100
    assert c["conformance_percent"] == pytest.approx(100.0 * 181.0 / 200.0)
    assert got["versioned_flights"] == 2


def _record(path, tracks, steps):
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FleetState, VehicleState

    from uam_sim.recording.mcap_writer import McapRecorder

    rec = McapRecorder(path)
    rec.add_topic("/uam/fleet_state", FleetState)
    with rec:
        for k in steps:
            fs = FleetState(step_index=k, vehicles=[
                VehicleState(vehicle_id=f"op/{rid}", position=Point(x=float(x), y=float(y), z=float(z)))
                for rid, tr in sorted(tracks.items()) for x, y, z in [tr.position_at(float(k))]])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * 1_000_000_000)


def test_the_chord_across_the_top_of_a_climb_is_not_a_loss(tmp_path):
    """The city run's 6 "flown losses" (third stop), by hand. A cruises at 90 m east along y = 0,
    x = 10 t - 208; B climbs at 5 m/s on its pad at (0, 0) and levels off at 120 m at t = 10.5 s,
    then hovers there. Planned: while B climbs A is more than 103 m away; from 10.5 s they are
    exactly V = 30 m apart (a tie: separated), so no loss, although A passes under B. Sampled
    every second, B's chord on [10, 11] s rises from 117.5 m to 120 m while A comes within 100 m
    (from 10.8 s): the chords lose separation (98 m at 11 s), the aircraft do not."""
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    import numpy as np

    from uam_planner.audit import audit_flights
    from uam_planner.trajectory import Trajectory
    from uam_sim.audit.flown import recording_flown

    a = Trajectory(np.array([0.0, 40.0]), np.array([(-208.0, 0, 90), (192.0, 0, 90)]))
    b = Trajectory(np.array([0.0, 10.5, 40.0]), np.array([(0, 0, 67.5), (0, 0, 120), (0, 0, 120.0)]))
    assert audit_flights([a, b], CYLINDER).losses == []          # the plans keep separation
    plans = [_plan("a", 1, 0, [(0, -208, 0, 90), (40, 192, 0, 90)]),
             _plan("b", 1, 0, [(0, 0, 0, 67.5), (10.5, 0, 0, 120), (40, 0, 0, 120)])]
    # Time(sec=int(10.5)) would truncate: the waypoint at 10.5 s, exactly
    plans[1].waypoints[1].time.sec, plans[1].waypoints[1].time.nanosec = 10, 500_000_000
    path = tmp_path / "climb.mcap"
    _record(path, {"a": a, "b": b}, range(0, 41))
    got = recording_flown(path, CYLINDER, plans=plans)
    assert got["losses"] == 0          # (before this stop: 1, the chord's)
    assert got["interpolated_losses"] == 1
    assert got["interpolated_loss_pairs"][0][2] == pytest.approx(98.0) and got["interpolated_loss_pairs"][0][3] == pytest.approx(11.0)
    # B's piece [10, 11] s: vertical speed 5 then 0 m/s, bound 5 x 1 / 4 = 1.25 m; every other
    # piece is on a single plan segment (bound 0): the chord needs dz < 28.75 m to prove a loss
    # (it is >= 29.5 m where A is within 100 m), and comes within 31.25 m: a possible loss
    assert got["losses"] == 0
    # (the reported bound is the largest pair bound: twice the largest piece bound)
    assert got["sampling_bound_v_m"] == pytest.approx(2.5) and got["sampling_bound_m"] == 0.0
    assert got["possible_losses"] == 1 and got["possible_loss_pairs"][0][2] == pytest.approx(98.0)
    assert got["pieces"] == 80 and got["pieces_exact"] == 79
    assert got["samples_off_plan"] == 0 and got["tracks_without_plan"] == 0
    # the same tracks 2 m lower for A (dz 32 m): cleared, not even possible
    a2 = Trajectory(a.times_s, a.points_m - [0, 0, 2])
    plans[0] = _plan("a", 1, 0, [(0, -208, 0, 88), (40, 192, 0, 88)])
    path2 = tmp_path / "climb2.mcap"
    _record(path2, {"a": a2, "b": b}, range(0, 41))
    got = recording_flown(path2, CYLINDER, plans=plans)
    assert got["interpolated_losses"] == 0 and got["losses"] == 0 and got["possible_losses"] == 0
    # a sample off its plan (A 5 m north at 20 s) is counted, and its two pieces take the
    # global bound (the ball of the largest chord speed, sqrt(10^2 + 5^2) m/s, x 1 s / 2 each)
    off = Trajectory(np.arange(0.0, 41.0), a2.position_at(np.arange(0.0, 41.0)) + np.where(
        np.arange(41)[:, None] == 20, [0, 5.0, 0], [0, 0, 0]))
    path3 = tmp_path / "off.mcap"
    _record(path3, {"a": off, "b": b}, range(0, 41))
    got = recording_flown(path3, CYLINDER, plans=plans)
    assert got["samples_off_plan"] == 1 and got["pieces_exact"] == 77
