"""The independent brute-force audit catches losses and agrees with hand computations."""

import math

import numpy as np
import pytest

from uam_planner.audit import audit_flights, pair_min_distance
from uam_planner.trajectory import trajectory_from_points


def line(p, q, dep=0.0, speed=10.0):
    return trajectory_from_points(np.array([p, q], dtype=float), dep, speed)


def test_audit_reports_a_head_on_loss_and_the_minimum_pair():
    a = line((0, 0, 0), (1000, 0, 0))
    b = line((1000, 0, 0), (0, 0, 0))
    c = line((0, 500, 0), (1000, 500, 0))
    res = audit_flights([a, b, c], 100.0, labels=["a", "b", "c"])
    assert not res.ok
    assert [(x[0], x[1]) for x in res.losses] == [("a", "b")]
    assert res.losses[0][2] == pytest.approx(0.0, abs=1e-9)
    assert res.losses[0][3] == pytest.approx(50.0)
    assert res.pair_of_min == ("a", "b") and res.pairs_checked == 3


def test_audit_crossing_with_offset_and_disjoint_times():
    a = trajectory_from_points(np.array([(-500, 0, 0), (0, 0, 0), (500, 0, 0)], float), 0.0)
    b = trajectory_from_points(np.array([(0, -500, 0), (0, 0, 0), (0, 500, 0)], float), 20.0)
    d, t = pair_min_distance(a, b)
    assert d == pytest.approx(100.0 * math.sqrt(2.0)) and t == pytest.approx(60.0)
    late = line((0, 0, 0), (10, 0, 0), dep=1000.0)
    assert pair_min_distance(a, late) == (math.inf, pytest.approx(math.nan, nan_ok=True))
    res = audit_flights([a, b, late], 100.0)
    assert res.ok and res.pairs_checked == 1
    assert res.min_separation_m == pytest.approx(100.0 * math.sqrt(2.0))
