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

    from uam_sim.conformance import ConformanceBounds
    from uam_sim.flown import recording_flown
    from uam_sim.mcap_writer import McapRecorder

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
