"""What flew, judged exactly: a pass inside the minimum at a sample instant is a loss whatever the
sampling bound (the error is 0 at a sample); a piece the simulator flew straight (its reported
velocity is the chord's) takes no bound; a pair the samples can neither prove nor clear is
unresolved, never OK; and the analysis exits 2 for what flew, not only for the plans."""

from __future__ import annotations

import numpy as np
import pytest

from uam_planner.separation import SeparationModel
from uam_planner.trajectory import Trajectory
from uam_sim.audit.flown import flown_audit, straight_pieces, tracks_and_velocities

CYLINDER = SeparationModel("cylinder", 100.0, 30.0)


def _crossing(step_s=2.0, gap_m=80.0, t_cross=10.0):
    """A east at 20 m/s on y = 0, B west at 20 m/s on y = gap_m, abreast at t_cross (a sample)."""
    t = np.arange(0.0, 20.0 + step_s / 2, step_s)
    a = np.c_[20.0 * (t - t_cross), np.zeros_like(t), np.full_like(t, 100.0)]
    b = np.c_[-20.0 * (t - t_cross), np.full_like(t, gap_m), np.full_like(t, 100.0)]
    return t, a, b


def test_a_pass_inside_the_minimum_at_a_sample_instant_is_a_loss_whatever_the_bound():
    t, a, b = _crossing()
    tracks = {"A": Trajectory(t, a), "B": Trajectory(t, b)}
    # no plan for either: every piece takes the global bound (20 m/s x 2 s / 2 = 20 m each, 40 m
    # the pair); shrinking the minimum by it everywhere left 60 m, and 80 m was called OK
    for model in (100.0, CYLINDER):
        got = flown_audit(tracks, model, sample_step_s=2.0, plans={})
        assert got["sampling_bound_m"] == pytest.approx(40.0)
        assert got["losses"] == 1, got
        a_, b_, d, when = got["loss_pairs"][0]
        assert (a_, b_) == ("A", "B") and d == pytest.approx(80.0) and when == pytest.approx(10.0)
        assert got["unresolved"] == 0


def test_a_piece_flown_straight_takes_no_bound_and_its_chord_loss_is_proven():
    # abreast at 11 s, between the samples 10 and 12 s (103 m apart at both): the chords come to
    # 95 m there, where the global bound (40 m the pair at mid-piece) cannot prove it
    t, a, b = _crossing(gap_m=95.0, t_cross=11.0)
    tracks = {"A": Trajectory(t, a), "B": Trajectory(t, b)}
    bare = flown_audit(tracks, 100.0, sample_step_s=2.0, plans={})
    assert bare["losses"] == 0 and bare["unresolved"] == 1  # possible, not proven: never OK
    assert bare["unresolved_pairs"][0][:2] == ["A", "B"]
    vel = {"A": np.tile([20.0, 0.0, 0.0], (t.size, 1)), "B": np.tile([-20.0, 0.0, 0.0], (t.size, 1))}
    got = flown_audit(tracks, 100.0, sample_step_s=2.0, plans={}, velocities=vel)
    assert got["losses"] == 1 and got["unresolved"] == 0
    assert got["loss_pairs"][0][2] == pytest.approx(95.0) and got["loss_pairs"][0][3] == pytest.approx(11.0)
    assert got["pieces_straight"] == 2 * (t.size - 1)


def test_a_velocity_that_is_not_the_chord_keeps_the_bound():
    t = np.array([0.0, 1.0, 2.0])
    tr = Trajectory(t, np.array([[0.0, 0, 0], [10.0, 0, 0], [20.0, 5.0, 0]]))
    # the second piece turned inside (the velocity reported at 1 s is not its chord)
    v = np.array([[10.0, 0, 0], [10.0, 0, 0], [10.0, 5.0, 0]])
    assert straight_pieces(tr, v).tolist() == [True, False]
    assert straight_pieces(tr, None).tolist() == [False, False]


def test_velocities_follow_their_samples_and_skip_repeats():
    ids = ["A", "B"]
    samples = [(0.0, ids, np.zeros((2, 3)), np.ones((2, 3))),
               (0.0, ids, np.zeros((2, 3)), np.full((2, 3), 9.0)),  # a repeated message
               (1.0, ids, np.ones((2, 3)), np.full((2, 3), 2.0))]
    tracks, vel = tracks_and_velocities(samples)
    assert sorted(tracks) == ["A", "B"] and vel["A"].tolist() == [[1.0] * 3, [2.0] * 3]
    assert tracks_and_velocities([s[:3] for s in samples])[1] == {}


def test_the_analysis_exits_2_for_a_flown_loss_between_deconflicted_plans(tmp_path, capsys):
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point, Vector3
    from run_frame import complete_run
    from uam_msgs.msg import FleetState, FlightPlan, FlightRequest, PlanningReport, VehicleState, Waypoint

    from uam_sim.audit.analysis import main
    from uam_sim.recording.mcap_writer import McapRecorder

    def plan(rid, y):
        return FlightPlan(request_id=rid, outcome=FlightPlan.OUTCOME_APPROVED, epoch_index=0, waypoints=[
            Waypoint(position=Point(x=0.0, y=y, z=100.0), time=Time(sec=0)),
            Waypoint(position=Point(x=1000.0, y=y, z=100.0), time=Time(sec=100))])

    path = tmp_path / "drift.mcap"
    rec = McapRecorder(path)
    for topic, cls in (("/uam/requests", FlightRequest), ("/uam/flight_plans", FlightPlan),
                       ("/uam/planning_reports", PlanningReport), ("/uam/fleet_state", FleetState)):
        rec.add_topic(topic, cls)
    with rec:
        for rid, y in (("r1", 0.0), ("r2", 300.0)):  # plans 300 m apart: deconflicted
            rec.write("/uam/requests", FlightRequest(request_id=rid), 0)
            rec.write("/uam/flight_plans", plan(rid, y), 0)
        rec.write("/uam/planning_reports", PlanningReport(epoch_index=0, approved=2), 0)
        for k in range(101):  # r2 drifts south to 60 m from r1 at 50 s, then back
            y2 = 300.0 - 240.0 * max(0.0, 1.0 - abs(k - 50) / 40.0)
            fs = FleetState(step_index=k, vehicles=[
                VehicleState(vehicle_id="r1", position=Point(x=10.0 * k, y=0.0, z=100.0), velocity=Vector3(x=10.0)),
                VehicleState(vehicle_id="r2", position=Point(x=10.0 * k, y=y2, z=100.0), velocity=Vector3(x=10.0))])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * 1_000_000_000)
        complete_run(rec, epochs=1)
    assert main([str(path), "--no-epochs"]) == 2
    out = capsys.readouterr().out
    assert "Safety audit     OK" in out  # the plans kept separation
    assert "Flown audit      LOSS OF SEPARATION in 1 pair(s)" in out and "loss r1 / r2: 60.0 m at t = 50.0 s" in out


def test_one_turn_inside_a_step_is_rebuilt_from_the_reported_velocities():
    from uam_sim.audit.flown import simulator_motion

    # east at 10 m/s to (5, 0) at 0.5 s, then north at 10 m/s: samples at 0, 1, 2 s
    t = np.array([0.0, 1.0, 2.0])
    p = np.array([[0.0, 0.0, 50.0], [5.0, 5.0, 50.0], [5.0, 15.0, 50.0]])
    v = np.array([[10.0, 0.0, 0.0], [0.0, 10.0, 0.0], [0.0, 10.0, 0.0]])
    tr, exact = simulator_motion(Trajectory(t, p), v)
    assert tr.times_s.tolist() == [0.0, 0.5, 1.0, 2.0] and exact.tolist() == [True, True, True]
    np.testing.assert_allclose(tr.points_m[1], [5.0, 0.0, 50.0])
    # velocities that no single turn explains: the piece is kept, not exact
    bad = v.copy()
    bad[0] = [10.0, 3.0, 0.0]
    tr, exact = simulator_motion(Trajectory(t, p), bad)
    assert tr.times_s.tolist() == [0.0, 1.0, 2.0] and exact.tolist() == [False, True]
