"""Constant-speed piecewise-linear trajectories."""

import math

import numpy as np
import pytest

from uam_planner.trajectory import Trajectory, trajectory_from_points


def test_constant_speed_times_and_positions():
    pts = np.array([(0, 0, 0), (300, 0, 0), (300, 400, 0)], float)
    tr = trajectory_from_points(pts, departure_s=100.0, speed_mps=10.0)
    assert tr.times_s.tolist() == [100.0, 130.0, 170.0]
    assert tr.departure_s == 100.0 and tr.arrival_s == 170.0
    assert tr.position_at(115.0) == pytest.approx([150.0, 0.0, 0.0])
    assert tr.position_at(150.0) == pytest.approx([300.0, 200.0, 0.0])
    got = tr.position_at(np.array([100.0, 130.0, 170.0]))
    assert got == pytest.approx(pts)
    assert np.isnan(tr.position_at(99.0)).all()
    assert tr.position_at(200.0, clamp=True) == pytest.approx(pts[-1])
    assert tr.is_airborne(np.array([99.0, 100.0, 170.0, 170.5])).tolist() == [False, True, True, False]
    t0, t1, p0, v = tr.segments()
    assert np.linalg.norm(v, axis=1) == pytest.approx([10.0, 10.0])
    assert tr.shifted(5.0).times_s.tolist() == [105.0, 135.0, 175.0]


def test_bad_trajectories_are_rejected_with_the_field():
    with pytest.raises(ValueError, match="times_s"):
        Trajectory(np.array([0.0, 0.0]), np.zeros((2, 3)))
    with pytest.raises(ValueError, match="points_m"):
        Trajectory(np.array([0.0, 1.0]), np.zeros((3, 3)))
    with pytest.raises(ValueError, match="speed_mps"):
        trajectory_from_points(np.array([(0, 0, 0), (1, 0, 0)], float), 0.0, speed_mps=0.0)
    with pytest.raises(ValueError, match="coincide"):
        trajectory_from_points(np.array([(0, 0, 0), (0, 0, 0)], float), 0.0)
    with pytest.raises(ValueError, match="departure_s"):
        trajectory_from_points(np.array([(0, 0, 0), (1, 0, 0)], float), math.nan)
