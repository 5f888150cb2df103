"""Exact continuous-time separation: hand-computed cases, sampling reference, broad phase."""

import math

import numpy as np
import pytest

from uam_planner.audit import pair_min_distance
from uam_planner.separation import (SegmentSet, conflicting_pairs, min_separation_m,
                                    segment_pair_min_distance)
from uam_planner.trajectory import trajectory_from_points


def line(p, q, dep=0.0, speed=10.0):
    return trajectory_from_points(np.array([p, q], dtype=float), dep, speed)


def sampled_min(a, b, dt):
    lo, hi = max(a.departure_s, b.departure_s), min(a.arrival_s, b.arrival_s)
    if lo > hi:
        return math.inf
    t = np.arange(lo, hi + 1e-12, dt)
    return float(np.min(np.linalg.norm(a.position_at(t) - b.position_at(t), axis=1)))


def test_head_on_on_one_corridor_meets_at_the_middle():
    a = line((0, 0, 100), (1000, 0, 100))
    b = line((1000, 0, 100), (0, 0, 100))
    assert min_separation_m(a, b) == pytest.approx(0.0, abs=1e-9)
    # B departs 50 s later: A at 10 t, B at 1000 - 10 (t - 50): they meet at t = 75 s.
    b_late = line((1000, 0, 100), (0, 0, 100), dep=50.0)
    assert min_separation_m(a, b_late) == pytest.approx(0.0, abs=1e-9)
    # B departs after A has landed: never airborne together.
    assert min_separation_m(a, line((1000, 0, 100), (0, 0, 100), dep=200.0)) == math.inf


def test_crossing_at_a_node_same_time_and_with_time_offset():
    a = trajectory_from_points(np.array([(-500, 0, 0), (0, 0, 0), (500, 0, 0)], float), 0.0)
    b = trajectory_from_points(np.array([(0, -500, 0), (0, 0, 0), (0, 500, 0)], float), 0.0)
    assert min_separation_m(a, b) == pytest.approx(0.0, abs=1e-9)
    # B 20 s late: r(t) = (10t - 500, -(10t - 700)); min at 10t = 600 -> (100, 100).
    b20 = b.shifted(20.0)
    assert min_separation_m(a, b20) == pytest.approx(100.0 * math.sqrt(2.0), rel=1e-12)
    # B 5 s late: min at 10t = 525 -> (25, 25).
    b5 = b.shifted(5.0)
    assert min_separation_m(a, b5) == pytest.approx(25.0 * math.sqrt(2.0), rel=1e-12)
    pairs = conflicting_pairs([a], [b20, b5, b], separation_m=100.0)
    assert pairs.tolist() == [[0, 1], [0, 2]]


@pytest.mark.parametrize("gap_m, conflict", [(80.0, True), (120.0, False)])
def test_parallel_corridors(gap_m, conflict):
    a = line((0, 0, 0), (1000, 0, 0))
    same_dir = line((0, gap_m, 0), (1000, gap_m, 0))
    opposite = line((1000, gap_m, 0), (0, gap_m, 0), dep=30.0)
    for b in (same_dir, opposite):
        assert min_separation_m(a, b) == pytest.approx(gap_m, rel=1e-12)
        assert (conflicting_pairs([a], [b], 100.0).shape[0] == 1) is conflict
        assert (conflicting_pairs([a, b], None, 100.0).shape[0] == 1) is conflict


def test_fast_head_on_pass_missed_by_one_second_sampling_is_caught():
    # A at 100 m/s from x=0, B at 100 m/s from x=700 toward A, 10 m apart laterally:
    # they pass at t = 3.5 s; at t = 3 s and 4 s they are 100.5 m apart.
    a = line((0, 0, 0), (1000, 0, 0), speed=100.0)
    b = line((700, 10, 0), (-300, 10, 0), speed=100.0)
    assert sampled_min(a, b, 1.0) == pytest.approx(math.hypot(100.0, 10.0))
    assert sampled_min(a, b, 1.0) > 100.0
    assert min_separation_m(a, b) == pytest.approx(10.0, rel=1e-12)
    assert conflicting_pairs([a], [b], 100.0).tolist() == [[0, 0]]


def test_touching_time_intervals_count_and_disjoint_are_inf():
    d = segment_pair_min_distance(
        np.array([0.0, 0.0]), np.array([10.0, 10.0]), np.zeros((2, 3)), np.array([[1.0, 0, 0]] * 2),
        np.array([10.0, 10.5]), np.array([20.0, 20.0]), np.array([[10.0, 3, 0]] * 2),
        np.zeros((2, 3)))
    assert d[0] == pytest.approx(3.0)
    assert d[1] == math.inf


def random_trajectory(rng, n_max=7, spread=1500.0):
    n = int(rng.integers(2, n_max + 1))
    pts = np.cumsum(rng.normal(0.0, 300.0, (n, 3)) * [1.0, 1.0, 0.1], axis=0) \
        + rng.uniform(-spread, spread, 3)
    return trajectory_from_points(pts, float(rng.uniform(0.0, 200.0)), float(rng.uniform(5.0, 30.0)))


def test_exact_minimum_against_dense_sampling_reference():
    rng = np.random.default_rng(7)
    for _ in range(60):
        a, b = random_trajectory(rng, spread=300.0), random_trajectory(rng, spread=300.0)
        exact = min_separation_m(a, b)
        if exact == math.inf:
            assert sampled_min(a, b, 0.5) == math.inf
            continue
        dt = 0.01
        coarse = sampled_min(a, b, 1.0)
        fine = sampled_min(a, b, dt)
        assert exact <= coarse + 1e-9
        assert exact <= fine + 1e-9
        # Between samples the distance changes at most at the relative speed (<= 60 m/s here).
        assert fine - exact <= 60.0 * dt + 1e-9


def test_exact_minimum_agrees_with_independent_audit_kernel():
    rng = np.random.default_rng(11)
    for _ in range(100):
        a, b = random_trajectory(rng, spread=500.0), random_trajectory(rng, spread=500.0)
        d_audit, _ = pair_min_distance(a, b)
        d = min_separation_m(a, b)
        if d == math.inf:
            assert d_audit == math.inf
        else:
            assert d == pytest.approx(d_audit, rel=1e-9, abs=1e-6)


@pytest.mark.parametrize("seed", range(6))
def test_broad_phase_finds_exactly_the_all_pairs_conflicts(seed):
    rng = np.random.default_rng(seed)
    A = [random_trajectory(rng) for _ in range(40)]
    B = [random_trajectory(rng) for _ in range(30)]
    sep = float(rng.uniform(50.0, 400.0))
    pairs, dist = conflicting_pairs(A, B, sep, return_distances=True)
    brute = {(i, j): min_separation_m(A[i], B[j]) for i in range(len(A)) for j in range(len(B))}
    expect = sorted(k for k, d in brute.items() if d < sep)
    assert [tuple(p) for p in pairs.tolist()] == expect
    for (i, j), d in zip(pairs.tolist(), dist):
        assert d == pytest.approx(brute[(i, j)], abs=1e-9)
    groups = rng.integers(0, 8, len(A))
    within = conflicting_pairs(SegmentSet.from_trajectories(A), None, sep, groups_a=groups)
    expect = sorted((i, j) for i in range(len(A)) for j in range(i + 1, len(A))
                    if groups[i] != groups[j] and min_separation_m(A[i], A[j]) < sep)
    assert [tuple(p) for p in within.tolist()] == expect


def test_broad_phase_with_small_cells_and_buckets_is_still_exact():
    rng = np.random.default_rng(3)
    A = [random_trajectory(rng, spread=400.0) for _ in range(25)]
    expect = sorted((i, j) for i in range(25) for j in range(i + 1, 25)
                    if min_separation_m(A[i], A[j]) < 100.0)
    for cell, bucket in ((100.0, 1.0), (100.0, 1000.0), (5000.0, 3.0)):
        got = conflicting_pairs(A, None, 100.0, cell_m=cell, bucket_s=bucket)
        assert [tuple(p) for p in got.tolist()] == expect


def test_bad_inputs_name_the_field():
    a = line((0, 0, 0), (100, 0, 0))
    with pytest.raises(ValueError, match="separation_m"):
        conflicting_pairs([a], [a], separation_m=0.0)
    with pytest.raises(ValueError, match="cell_m"):
        conflicting_pairs([a], [a], separation_m=100.0, cell_m=50.0)
    with pytest.raises(ValueError, match="groups_a"):
        conflicting_pairs([a], [a], groups_a=[0])
    assert conflicting_pairs([], [a]).shape == (0, 2)
