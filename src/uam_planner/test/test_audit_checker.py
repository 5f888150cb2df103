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


@pytest.mark.parametrize("kind", ["sphere", "cylinder"])
def test_sweep_audit_matches_the_pair_walk(kind):
    from uam_planner.audit import audit_flights, sweep_audit
    from uam_planner.separation import SeparationModel
    from uam_planner.trajectory import Trajectory
    rng = np.random.default_rng(11)
    flights = []
    for _ in range(50):
        p, q = rng.uniform(-1500, 1500, (2, 2))
        z = rng.uniform(0.0, 160.0, 3)
        t0 = rng.uniform(0, 100)
        dur = np.linalg.norm(q - p) / 10 + 5
        flights.append(Trajectory(np.array([t0, t0 + dur / 2, t0 + dur]),
                                  np.array([(*p, z[0]), (*((p + q) / 2), z[1]), (*q, z[2])])))
    model = SeparationModel(kind, 100.0, 30.0)
    a = audit_flights(flights, model, labels=list(range(50)))
    b = sweep_audit(flights, model, labels=list(range(50)), chunk_pairs=100)
    assert {(i, j) for i, j, _, _ in a.losses} == {(i, j) for i, j, _, _ in b.losses}
    assert len(a.losses) > 10 and b.pairs_checked == a.pairs_checked
    assert b.min_separation_m == pytest.approx(a.min_separation_m)


def test_the_sweep_counts_a_loss_per_flight_pair_and_never_pairs_two_parts_of_one_flight():
    # flight A in two parts (its version 1 until 50 s, version 2 from there, from the same point):
    # B flies beside both parts 50 m away, so there is one losing flight pair, not two; and the
    # parts, which touch at 50 s, are never a pair
    from uam_planner.audit import sweep_audit
    from uam_planner.trajectory import Trajectory

    a1 = Trajectory(np.array([0.0, 50.0]), np.array([[0.0, 0.0, 100.0], [500.0, 0.0, 100.0]]))
    a2 = Trajectory(np.array([50.0, 100.0]), np.array([[500.0, 0.0, 100.0], [1000.0, 0.0, 100.0]]))
    b = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 50.0, 100.0], [1000.0, 50.0, 100.0]]))
    by_part = sweep_audit([a1, a2, b], 100.0, labels=["A", "A", "B"])
    # by part: the two parts of A a "loss" at 0 m, and A-B counted once per part
    assert [(x, y) for x, y, *_ in by_part.losses] == [("A", "A"), ("A", "B"), ("A", "B")]
    got = sweep_audit([a1, a2, b], 100.0, groups=["A", "A", "B"])
    assert [(x, y) for x, y, *_ in got.losses] == [("A", "B")]
    assert got.min_separation_m == pytest.approx(50.0) and got.pairs_checked == 1
