"""The audit of what flew, pruned by its own grid hash (issue 22, third stop: the city recording's
analysis took more than 23 CPU-min), gives the same answers as the full sweep of every
time-overlapping pair of pieces: on a small recording, on random tracks in both separation
models, and on hand-computed cases (a pair that shares a single instant, a minimum far beyond
the first reach)."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uam_planner.audit import audit_flights, sweep_audits
from uam_planner.separation import SeparationModel
from uam_planner.trajectory import Trajectory

SPHERE = SeparationModel("sphere", 100.0, 30.0)
CYLINDER = SeparationModel("cylinder", 100.0, 30.0)
WIDE = SeparationModel("cylinder", 130.0, 60.0)


def _fields(r):
    return (r.min_separation_m, r.pair_of_min, r.min_time_s, r.losses, r.pairs_checked)


def _same(a, b):
    fa, fb = _fields(a), _fields(b)
    for x, y in zip(fa, fb):
        if isinstance(x, float) and math.isnan(x):
            assert isinstance(y, float) and math.isnan(y)
        else:
            assert x == y   # exactly: the same pairs through the same arithmetic


def _tracks(rng, n, box_m, aligned):
    """Random-walk tracks sampled every second (aligned: on whole seconds, as fleet states are;
    else at jittered instants), at one of four levels with climbs."""
    out = []
    for _ in range(n):
        m = int(rng.integers(2, 120))
        t0 = float(rng.integers(0, 150)) if aligned else float(rng.uniform(0, 150))
        t = t0 + np.arange(m, dtype=float) if aligned else t0 + np.cumsum(rng.uniform(0.2, 1.5, m))
        xy = rng.uniform(-box_m, box_m, 2) + np.cumsum(rng.normal(0, 12, (m, 2)), axis=0)
        z = rng.choice([60.0, 90.0, 120.0, 150.0]) + np.cumsum(rng.normal(0, 2, m))
        out.append(Trajectory(t, np.column_stack([xy, z])))
    return out


@pytest.mark.parametrize("aligned", [True, False])
@pytest.mark.parametrize("box_m", [300.0, 3000.0])
def test_the_pruned_sweep_equals_the_full_sweep(aligned, box_m):
    rng = np.random.default_rng(int(box_m) + aligned)
    tracks = _tracks(rng, 80, box_m, aligned)
    full = sweep_audits(tracks, [SPHERE, CYLINDER, WIDE], prune=False, chunk_pairs=997)
    fast = sweep_audits(tracks, [SPHERE, CYLINDER, WIDE])
    for a, b in zip(full, fast):
        _same(a, b)
    # not a vacuous comparison: these tracks lose separation, in both models
    assert full[0].losses and full[1].losses and len(full[2].losses) >= len(full[1].losses)
    # several models at once are each the model alone
    for model, b in zip([SPHERE, CYLINDER, WIDE], fast):
        _same(sweep_audits(tracks, [model])[0], b)


def test_a_microsecond_jump_in_one_track_changes_nothing_and_costs_little():
    """Seventh stop: a flown track with a segment of a microsecond that moves 5 m (a switch
    between versions) set the grid's time bucket for every segment from its ~5e6 m/s; one such
    Monte-Carlo run allocated past 11 GiB. The bucket now follows the fast segments, not the
    fastest; the pairs found are those of the full sweep, with the jump's own pair among them."""
    rng = np.random.default_rng(7)
    tracks = _tracks(rng, 60, 300.0, True)
    t = tracks[0].times_s
    i = len(t) // 2
    times = np.concatenate([t[:i + 1], [t[i] + 1e-6], t[i + 1:] + 1e-6])
    pts = tracks[0].points_m
    jumped = np.concatenate([pts[:i + 1], pts[i:i + 1] + [5.0, 0.0, 0.0], pts[i + 1:] + [5.0, 0.0, 0.0]])
    tracks[0] = Trajectory(times, jumped)
    full = sweep_audits(tracks, [SPHERE, CYLINDER], prune=False, chunk_pairs=997)
    fast = sweep_audits(tracks, [SPHERE, CYLINDER], chunk_pairs=997)
    for a, b in zip(full, fast):
        _same(a, b)
    assert full[0].losses


def test_a_pair_sharing_one_instant_is_found_and_computed_by_hand():
    # a flies (0, 0) -> (-200, 0) in t = [0, 10] and ends there; b starts at t = 10 at
    # (-150, 0) and flies east: they share the instant t = 10 only, 50 m apart: a loss seen at
    # that single instant (a sampled track ending on a bucket edge; nowhere else)
    a = Trajectory(np.array([0.0, 10.0]), np.array([[0, 0, 60], [-200, 0, 60.0]]))
    b = Trajectory(np.array([10.0, 20.0]), np.array([[-150, 0, 60], [500, 0, 60.0]]))
    far = Trajectory(np.array([0.0, 20.0]), np.array([[0, 9000, 60], [0, 9000, 60.0]]))
    for model in (SPHERE, CYLINDER):
        res = sweep_audits([a, b, far], [model], labels=["a", "b", "far"])[0]
        _same(res, sweep_audits([a, b, far], [model], labels=["a", "b", "far"], prune=False)[0])
        assert res.losses == [("a", "b", pytest.approx(50.0), pytest.approx(10.0))]
        assert res.pairs_checked == 3


def test_a_minimum_far_beyond_the_first_reach_is_still_exact():
    # two parallel tracks 5 km apart (the first reach is 200 m): the minimum is 5,000 m, found
    # by widening the reach; a third track 4 km above one of them is never within V (cylinder)
    a = Trajectory(np.array([0.0, 100.0]), np.array([[0, 0, 60], [1000, 0, 60.0]]))
    b = Trajectory(np.array([0.0, 100.0]), np.array([[0, 5000, 60], [1000, 5000, 60.0]]))
    c = Trajectory(np.array([0.0, 100.0]), np.array([[0, 0, 4060], [1000, 0, 4060.0]]))
    sph, cyl = sweep_audits([a, b], [SPHERE, CYLINDER], labels=["a", "b"])
    assert sph.min_separation_m == pytest.approx(5000.0) and cyl.min_separation_m == pytest.approx(5000.0)
    assert sph.ok and sph.pair_of_min == ("a", "b")
    lone = sweep_audits([a, c], [CYLINDER], labels=["a", "c"])[0]
    assert lone.min_separation_m == math.inf and lone.pairs_checked == 1 and lone.ok
    assert audit_flights([a, b], SPHERE).min_separation_m == pytest.approx(5000.0)


def test_the_recordings_flown_audit_is_the_full_sweeps(tmp_path):
    """A small recording (40 vehicles, fleet states every second): recording_flown pruned equals
    the full sweep, field for field, with losses and possible losses in it."""
    pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FleetState, VehicleState

    from uam_sim.audit.flown import recording_flown
    from uam_sim.recording.mcap_writer import McapRecorder

    rng = np.random.default_rng(7)
    n, steps = 40, 120
    start = rng.integers(0, 60, n)
    stop = start + rng.integers(20, 60, n)
    pos = rng.uniform(-600, 600, (n, 3)) * [1, 1, 0] + [0, 0, 90]
    vel = rng.normal(0, 8, (n, 3)) * [1, 1, 0.05]
    path = tmp_path / "small.mcap"
    rec = McapRecorder(path)
    rec.add_topic("/uam/fleet_state", FleetState)
    with rec:
        for k in range(steps):
            live = [v for v in range(n) if start[v] <= k <= stop[v]]
            fs = FleetState(step_index=k, vehicles=[
                VehicleState(vehicle_id=f"op/r{v}", position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])))
                for v in live for p in [pos[v] + vel[v] * (k - start[v])]])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * 1_000_000_000)
    fast = recording_flown(path, CYLINDER)
    full = recording_flown(path, CYLINDER, prune=False)
    assert fast == full
    assert fast["losses"] > 0 and fast["possible_losses"] > fast["losses"] and fast["sample_step_s"] == 1.0
