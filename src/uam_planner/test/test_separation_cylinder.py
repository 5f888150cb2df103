"""Separation as a cylinder (H = 100 m, V = 30 m) against hand-computed geometry, the paper's
sphere beside it, the broad phase's z filter, and the overflow guard of its cell codes."""

import math

import numpy as np
import pytest

from uam_planner.audit import audit_flights, pair_min_distance
from uam_planner.separation import (SeparationModel, conflicting_pairs, loss_intervals_s,
                                    min_separation_m)
from uam_planner.trajectory import Trajectory
from uam_planner import separation

CYL = SeparationModel("cylinder", 100.0, 30.0)
SPHERE = SeparationModel("sphere", 100.0)


def line(t0, t1, p0, p1):
    return Trajectory(np.array([t0, t1], float), np.array([p0, p1], float))


def east(z):   # (-1000, 0) -> (1000, 0) at 10 m/s, over the origin at t = 100 s
    return line(0.0, 200.0, (-1000, 0, z), (1000, 0, z))


def north(z):  # (0, -1000) -> (0, 1000) at 10 m/s, over the origin at t = 100 s
    return line(0.0, 200.0, (0, -1000, z), (0, 1000, z))


def test_crossing_at_one_level_conflicts_in_both_models():
    a, b = east(90.0), north(90.0)
    for model in (CYL, SPHERE):
        pairs, dist = conflicting_pairs([a, b], separation_m=model, return_distances=True)
        assert pairs.tolist() == [[0, 1]] and dist[0] == pytest.approx(0.0, abs=1e-9)
    # horizontal distance 10 sqrt(2) |t - 100| < 100  <=>  |t - 100| < 5 sqrt(2)
    (s, e), = loss_intervals_s(a, b, CYL)
    assert (s, e) == pytest.approx((100 - 5 * math.sqrt(2), 100 + 5 * math.sqrt(2)))


def test_crossing_one_level_apart_is_separated_by_the_cylinder_only():
    a, b = east(90.0), north(120.0)          # exactly V = 30 m apart: not a loss (strict)
    assert conflicting_pairs([a, b], separation_m=CYL).tolist() == []
    assert conflicting_pairs([a], [b], separation_m=CYL).tolist() == []
    assert loss_intervals_s(a, b, CYL) == []
    # the paper's sphere of 100 m sees 30 m < 100 m
    assert conflicting_pairs([a, b], separation_m=SPHERE).tolist() == [[0, 1]]
    assert min_separation_m(a, b) == pytest.approx(30.0)
    assert audit_flights([a, b], CYL).ok and not audit_flights([a, b], SPHERE).ok
    # 29 m apart is a loss again, at horizontal distance 0
    pairs, dist = conflicting_pairs([east(90.0), north(119.0)], separation_m=CYL,
                                    return_distances=True)
    assert pairs.tolist() == [[0, 1]] and dist[0] == pytest.approx(0.0, abs=1e-9)


def climber():
    """Climbs vertically at the origin from 5 m (t = 0) to 120 m (t = 23 s, 5 m/s), then flies
    east at 120 m."""
    return Trajectory(np.array([0.0, 23.0, 123.0]),
                      np.array([(0, 0, 5), (0, 0, 120), (1000, 0, 120)], float))


def cruiser():
    """Flies east at 90 m, 40 m north of the origin, passing it at t = 17 s (10 m/s)."""
    return line(0.0, 100.0, (-170, 40, 90), (830, 40, 90))


def test_climb_through_an_occupied_level_conflicts_during_the_climb_only():
    up, level = climber(), cruiser()
    # |dz| < 30 while 60 < 5 + 5t < 120: 11 < t < 23. Horizontal (10t - 170)^2 + 40^2 < 100^2:
    # 7.83 < t < 26.17. Both: (11, 23). After t = 23 the climber is 30 m above: no loss, although
    # it stays within 100 m horizontally until t = 26.17.
    (s, e), = loss_intervals_s(up, level, CYL)
    assert (s, e) == pytest.approx((11.0, 23.0))
    pairs, dist = conflicting_pairs([up, level], separation_m=CYL, return_distances=True)
    assert pairs.tolist() == [[0, 1]]
    assert dist[0] == pytest.approx(40.0)    # at t = 17, horizontally 40 m, 0 m vertically
    d, t = pair_min_distance(up, level, vertical_m=30.0)
    assert (d, t) == pytest.approx((40.0, 17.0))
    # a cruiser passing at t = 30 s is within 100 m for 20.83 < t < 39.17, overlapping the
    # vertical window (11, 23): loss from 20.83 s until the climber reaches 120 m
    (s, e), = loss_intervals_s(up, line(0.0, 100.0, (-300, 40, 90), (700, 40, 90)), CYL)
    assert (s, e) == pytest.approx((30 - math.sqrt(84), 23.0))
    # passing at t = 40 s (within 100 m for 30.83 < t < 49.17, after the climb): no loss at all
    late = line(0.0, 100.0, (-400, 40, 90), (600, 40, 90))
    assert loss_intervals_s(up, late, CYL) == []
    assert conflicting_pairs([up, late], separation_m=CYL).tolist() == []
    assert audit_flights([up, late], CYL).ok


def test_sphere_is_the_default_and_numbers_mean_the_sphere():
    a, b = east(90.0), north(120.0)
    assert conflicting_pairs([a, b]).tolist() == [[0, 1]]
    assert conflicting_pairs([a, b], separation_m=100.0).tolist() == [[0, 1]]
    assert SeparationModel().kind == "sphere"


@pytest.mark.parametrize("bad, field", [
    (dict(kind="box"), "kind"),
    (dict(kind="cylinder", vertical_separation_m=0.0), "vertical_separation_m"),
    (dict(separation_m=float("nan")), "separation_m"),
])
def test_bad_model_names_the_field(bad, field):
    with pytest.raises(ValueError, match=field):
        SeparationModel(**bad)


def random_flights(rng, n, levels):
    out = []
    for _ in range(n):
        p = rng.uniform(-1500, 1500, 2)
        q = rng.uniform(-1500, 1500, 2)
        z0 = rng.choice(levels)
        z1 = rng.choice(levels)
        t0 = rng.uniform(0, 100)
        dur = np.linalg.norm(q - p) / 10 + 5
        mid = (p + q) / 2
        out.append(Trajectory(np.array([t0, t0 + dur / 2, t0 + dur]),
                              np.array([(*p, z0), (*mid, z1), (*q, z1)], float)))
    return out


@pytest.mark.parametrize("model", [CYL, SPHERE])
def test_broad_phase_with_z_filter_matches_brute_force_audit(model):
    rng = np.random.default_rng(3)
    # altitudes drawn at random: no pair sits exactly V apart (see the next test for levels)
    flights = random_flights(rng, 60, rng.uniform(0.0, 160.0, 40))
    got = set(map(tuple, conflicting_pairs(flights, separation_m=model).tolist()))
    audit = audit_flights(flights, model, labels=list(range(len(flights))))
    want = {(min(i, j), max(i, j)) for i, j, _, _ in audit.losses}
    assert got == want and len(want) > 10
    a, b = flights[:30], flights[30:]
    got_ab = set(map(tuple, conflicting_pairs(a, b, separation_m=model).tolist()))
    assert got_ab == {(i, j - 30) for i, j in want if i < 30 <= j}


def far_conflict(extent_m, t_s):
    """A short flight at the origin at t = 0 and a head-on pair (0 m apart at t_s + 50 s) at
    (extent_m, extent_m): the cell grid spans extent_m / 1200 m cells in x and y and
    t_s / 120 s buckets in time."""
    near = line(0.0, 100.0, (0, 0, 120), (1000, 0, 120))
    a = line(t_s, t_s + 100.0, (extent_m - 500, extent_m, 120), (extent_m + 500, extent_m, 120))
    b = line(t_s, t_s + 100.0, (extent_m + 500, extent_m, 120), (extent_m - 500, extent_m, 120))
    return near, a, b


@pytest.mark.parametrize("extent_m, t_s", [(1e6, 3600.0), (1e9, 1e12), (1e10, 1e10)])
def test_cell_code_overflow_never_misses_a_conflict(extent_m, t_s):
    # (1e9 m, 1e12 s): 8.3e5 x 8.3e5 cells x 8.3e9 buckets x 2 sides > 2^63; before the guard the
    # int64 cell code wrapped and this 0 m head-on conflict was silently missed.
    near, a, b = far_conflict(extent_m, t_s)
    for model in (SPHERE, CYL):
        pairs, dist = conflicting_pairs([near, a, b], separation_m=model, return_distances=True)
        assert pairs.tolist() == [[1, 2]] and dist[0] == pytest.approx(0.0, abs=1e-6)
        assert conflicting_pairs([near, a], [near, b], separation_m=model).tolist() == \
            [[0, 0], [1, 1]]


def test_extent_beyond_int64_cells_is_refused_with_the_reason():
    near, a, b = far_conflict(1e23, 0.0)
    with pytest.raises(ValueError, match="extent along x"):
        conflicting_pairs([near, a, b])


def test_at_flight_levels_the_planner_kernel_errs_towards_conflict():
    # Levels exactly V apart: climbs that end one level below another flight touch |dz| = V at a
    # waypoint. The kernel may count such a touch (rounding), never misses what the audit finds.
    rng = np.random.default_rng(3)
    flights = random_flights(rng, 80, [60.0, 90.0, 120.0, 150.0, 5.0])
    got = set(map(tuple, conflicting_pairs(flights, separation_m=CYL).tolist()))
    audit = audit_flights(flights, CYL, labels=list(range(len(flights))))
    want = {(min(i, j), max(i, j)) for i, j, _, _ in audit.losses}
    assert want <= got and len(want) > 10
    for i, j in got - want:   # extras are touches: no loss interval of positive length
        assert all(e - s < 1e-6 for s, e in loss_intervals_s(flights[i], flights[j], CYL))


@pytest.mark.parametrize("model", [CYL, SPHERE])
def test_shifted_candidates_give_the_same_pairs_as_every_shifted_trajectory(model):
    rng = np.random.default_rng(5)
    base = random_flights(rng, 40, [60.0, 90.0, 120.0, 150.0, 5.0])
    active = random_flights(rng, 60, [60.0, 90.0, 120.0, 150.0, 5.0])
    counts = rng.integers(0, 8, len(base))               # 0..7 slots per template
    first = np.concatenate(([0], np.cumsum(counts)))
    shift = np.concatenate([5.0 * np.arange(c) for c in counts])
    explicit = [base[j].shifted(float(shift[c])) for j in range(len(base))
                for c in range(first[j], first[j + 1])]
    want = conflicting_pairs(explicit, active, separation_m=model)
    got = conflicting_pairs(base, active, separation_m=model, shifts_a=(first, shift))
    assert got.tolist() == want.tolist() and len(want) > 20
    # z cells in the keys (the horizon's deconfliction): the same pairs
    keyed = conflicting_pairs(base, active, separation_m=model, shifts_a=(first, shift),
                              z_cell_m=model.vertical_reach_m)
    assert keyed.tolist() == want.tolist()
    with pytest.raises(ValueError, match="shifts_a"):
        conflicting_pairs(base, active, shifts_a=(first[:-1], shift))


def _levels_with_touches(rng, n):
    """Flights on levels exactly V apart, some a rounding step off (a box overlapping the next
    level's by 1e-14 m, or short of touching it): the edges of the z cells."""
    flights = random_flights(rng, n, [60.0, 90.0, 120.0, 150.0, 5.0])
    out = []
    for k, f in enumerate(flights):
        p = f.points_m.copy()
        if k % 5 == 0:
            p[1:, 2] = np.nextafter(p[1:, 2], np.inf if k % 10 else -np.inf)
        out.append(Trajectory(f.times_s.copy(), p))
    return out


@pytest.mark.parametrize("model", [CYL, SPHERE])
def test_z_cells_in_the_keys_give_the_same_pairs_and_distances_to_the_last_bit(model, monkeypatch):
    """z_cell_m only narrows the broad phase: the same pairs and the same float distances (the
    exact kernel sees the same piece pairs), with fewer piece pairs sharing a cell at levels.
    (The cylinder keys z by default: the plain path here is the one without that default.)"""
    monkeypatch.setattr(separation, "_CYLINDER_Z_KEYS", False)
    rng = np.random.default_rng(11)
    flights = _levels_with_touches(rng, 120)
    groups = rng.integers(0, 40, len(flights))
    plain_st, keyed_st = {}, {}
    want = conflicting_pairs(flights, separation_m=model, groups_a=groups, bucket_s=120.0,
                             return_distances=True, stats=plain_st)
    got = conflicting_pairs(flights, separation_m=model, groups_a=groups, bucket_s=120.0,
                            return_distances=True, stats=keyed_st,
                            z_cell_m=model.vertical_reach_m)
    assert got[0].tolist() == want[0].tolist() and len(want[0]) > 20
    assert got[1].tobytes() == want[1].tobytes()
    assert keyed_st["exact_checks"] == plain_st["exact_checks"]  # each piece pair checked once
    a, b = flights[:50], flights[50:]
    for z in (None, model.vertical_reach_m):
        ab = conflicting_pairs(a, b, separation_m=model, bucket_s=120.0, z_cell_m=z)
        assert ab.tolist() == conflicting_pairs(a, b, separation_m=model, bucket_s=120.0).tolist()
    if model.kind == "cylinder":  # 16,620 against 23,184 here (half the flights climb between levels)
        assert keyed_st["pairs_sharing_cell"] < plain_st["pairs_sharing_cell"]
    with pytest.raises(ValueError, match="z_cell_m"):
        conflicting_pairs(flights, separation_m=model, z_cell_m=0.0)


@pytest.mark.parametrize("model", [CYL, SPHERE])
def test_one_call_across_two_sets_with_ranks_and_groups_equals_the_call_within_their_union(model):
    """The rolling horizon's new x old call: with rank_a/rank_b (the candidates' places in the
    union) and groups_a/groups_b (their requests), one call across two interleaved sets gives the
    union's cross pairs of different groups, with the union's distances to the last bit (the
    kernel takes the lower-ranked trajectory first, as the call within the union does)."""
    rng = np.random.default_rng(12)
    flights = _levels_with_touches(rng, 120)
    groups = rng.integers(0, 40, len(flights))
    pairs, dist = conflicting_pairs(flights, separation_m=model, groups_a=groups, bucket_s=120.0,
                                    return_distances=True)
    old = np.flatnonzero(rng.random(len(flights)) < 0.6)
    new = np.setdiff1d(np.arange(len(flights)), old)
    is_new = np.isin(np.arange(len(flights)), new)
    cross = is_new[pairs[:, 0]] != is_new[pairs[:, 1]]
    want = {tuple(p): d for p, d in zip(pairs[cross].tolist(), dist[cross].tolist())}
    for z in (None, model.vertical_reach_m):
        ab, d = conflicting_pairs([flights[i] for i in old], [flights[i] for i in new],
                                  separation_m=model, bucket_s=120.0, groups_a=groups[old],
                                  groups_b=groups[new], rank_a=old, rank_b=new,
                                  return_distances=True, z_cell_m=z)
        u, v = old[ab[:, 0]], new[ab[:, 1]]
        got = {(min(x, y), max(x, y)): dd for x, y, dd in zip(u.tolist(), v.tolist(), d.tolist())}
        assert got.keys() == want.keys() and len(want) > 10
        assert all(np.float64(got[k]).tobytes() == np.float64(want[k]).tobytes() for k in want)
    with pytest.raises(ValueError, match="rank_a and rank_b"):
        conflicting_pairs(flights[:2], flights[2:4], rank_a=[0, 1])
    with pytest.raises(ValueError, match="groups_a and groups_b"):
        conflicting_pairs(flights[:2], flights[2:4], groups_b=[0, 1])


def _both_paths(monkeypatch, *args, **kw):
    """conflicting_pairs(*args, **kw) with its broad-phase shortcuts (the default) and without
    (separation._CYLINDER_Z_KEYS and _SKIP_OWN_RUNS off): (pairs, distances, stats) of each."""
    out = []
    for on in (True, False):
        monkeypatch.setattr(separation, "_CYLINDER_Z_KEYS", on)
        monkeypatch.setattr(separation, "_SKIP_OWN_RUNS", on)
        st = {}
        pairs, dist = conflicting_pairs(*args, return_distances=True, stats=st, **kw)
        out.append((pairs, dist, st))
    return out


@pytest.mark.parametrize("model", [CYL, SPHERE])
def test_broad_phase_shortcuts_give_the_same_pairs_and_distances_to_the_last_bit(model,
                                                                                 monkeypatch):
    """Issue 24's speed-up of conflicting_pairs (z cells for the cylinder by default; within one
    set, no pairs made inside a trajectory's or a request's run of a cell) against the plain
    path it replaced, which stays in the code: the same pairs, the same distances bit for bit,
    the same exact checks, and fewer pairs made where the shortcut applies (so it ran). Random
    flights on levels V apart (touching boxes, a rounding step off) and at random altitudes."""
    rng = np.random.default_rng(24)
    flights = _levels_with_touches(rng, 150) + random_flights(rng, 60, rng.uniform(0, 160, 30))
    n = len(flights)
    req_sorted = np.sort(rng.integers(0, 60, n))        # the planner's order: by request
    req_mixed = rng.permutation(req_sorted)              # labels that decrease: the plain path
    first = np.concatenate(([0], np.cumsum(rng.integers(1, 4, 80))))
    shift = rng.uniform(0.0, 30.0, first[-1])
    cases = [
        ("one set", (flights,), {}),
        ("one set, sorted groups", (flights,), {"groups_a": req_sorted, "bucket_s": 120.0}),
        ("one set, unsorted groups", (flights,), {"groups_a": req_mixed}),
        ("two sets", (flights[:90], flights[90:]), {}),
        ("two sets, shifts", (flights[:80], flights[80:]), {"shifts_a": (first, shift)}),
    ]
    for name, args, kw in cases:
        (p1, d1, s1), (p0, d0, s0) = _both_paths(monkeypatch, *args, separation_m=model, **kw)
        assert len(p0) > 20, name
        assert p1.tolist() == p0.tolist(), name
        assert d1.dtype == d0.dtype and d1.tobytes() == d0.tobytes(), name
        assert s1["exact_checks"] == s0["exact_checks"], name
        shortcut = (model.kind == "cylinder") or (len(args) == 1 and name != "one set, unsorted groups")
        if shortcut:
            assert s1["pairs_sharing_cell"] < s0["pairs_sharing_cell"], name
        else:
            assert s1["pairs_sharing_cell"] == s0["pairs_sharing_cell"], name
