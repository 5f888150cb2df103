"""The compiled pair list (``separation_kernel.lost_pairs``) against the numpy path it replaces.

``conflicting_pairs`` without shifts, ranks or distances (the conflict graph's call) walks its
cell-mate pairs in a numba kernel when ``separation._COMPILED_PAIRS`` is on, in numpy when it is
off. The two must return the same array: these tests hold them to it on seeded random cases in
both models, within one set (no groups; groups in request order, so a set's own runs are
skipped in the broad phase; groups whose labels decrease within a cell, so the box filter drops
one group's pairs) and across two sets (with and without groups), and on the ties where a pair
could flip on the last bit: flat segments exactly V apart, touching time intervals, zero
relative velocity at exactly the separation and one rounding step closer.
"""

import numpy as np
import pytest

from uam_planner import separation, separation_kernel
from uam_planner.separation import conflicting_pairs
from uam_planner.trajectory import Trajectory

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))  # the shared cases, beside this file
from separation_cases import CYL, SPHERE  # noqa: E402
from separation_cases import random_case as _case  # noqa: E402
from separation_cases import ties as _ties  # noqa: E402

def _pairs(monkeypatch, compiled: bool, a, b, model, **kw):
    """conflicting_pairs with the compiled path on or off, its stats, and whether the broad
    phase skipped the set's own runs (None across two sets)."""
    monkeypatch.setattr(separation, "_COMPILED_PAIRS", compiled)
    seen = []
    broad = separation._broad_phase

    def spy(*args, **kwargs):
        bp = broad(*args, **kwargs)
        seen.append(None if bp is None or not bp.single else bp.runs_skipped)
        return bp

    monkeypatch.setattr(separation, "_broad_phase", spy)
    st: dict = {}
    got = conflicting_pairs(a, b, model, stats=st, **kw)
    monkeypatch.setattr(separation, "_broad_phase", broad)
    return got, st, seen[0] if seen else None


def _both(monkeypatch, a, b, model, **kw):
    """The compiled pairs (array-equal to the numpy path's, or the test fails) and whether the
    set's own runs were skipped."""
    got, st_c, runs = _pairs(monkeypatch, True, a, b, model, **kw)
    want, st_n, _ = _pairs(monkeypatch, False, a, b, model, **kw)
    assert got.dtype == want.dtype == np.int64
    assert got.shape == want.shape and np.array_equal(got, want)
    # the same stats keys; the kernel does not measure a pair it has just recorded again
    assert set(st_c) == set(st_n)
    assert st_c.get("exact_checks", 0) <= st_n.get("exact_checks", 0)
    if len(got):
        code = got[:, 0] * (int(got.max()) + 1) + got[:, 1]
        assert np.all(np.diff(code) > 0)             # sorted, unique
        if b is None:
            assert np.all(got[:, 0] < got[:, 1])
    return got, runs


def _planner_groups(n, size):
    """Labels in request order (non-decreasing with the trajectory), ``size`` candidates each."""
    return np.arange(n) // size


def _shuffled_groups(n, seed):
    """Labels that decrease along the trajectories: the broad phase cannot skip runs."""
    return np.random.default_rng(seed).integers(0, max(n // 3, 2), n)


@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("seed", range(6))
def test_one_set_compiled_pairs_are_the_numpy_paths(model, seed, monkeypatch):
    a, b = _case(100 + seed, 40, 60)
    s = a + b
    got, runs = _both(monkeypatch, s, None, model)
    assert len(got) > 10 and runs is True
    got, runs = _both(monkeypatch, s, None, model, groups_a=_planner_groups(len(s), 3))
    assert len(got) > 10 and runs is True
    got, runs = _both(monkeypatch, s, None, model, groups_a=_shuffled_groups(len(s), seed))
    assert len(got) > 10 and runs is False
    for kw in (dict(cell_m=150.0, bucket_s=15.0), dict(z_cell_m=model.vertical_reach_m),
               dict(bucket_s=7.5)):
        _both(monkeypatch, s, None, model, groups_a=_planner_groups(len(s), 4), **kw)


@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("seed", range(3))
def test_one_set_without_skipped_runs_is_the_numpy_paths(model, seed, monkeypatch):
    """The broad phase's own-run shortcut off: every cell mate is made, the kernel drops one
    trajectory's (and one group's) pairs itself."""
    monkeypatch.setattr(separation, "_SKIP_OWN_RUNS", False)
    a, b = _case(200 + seed, 30, 40)
    s = a + b
    for groups in (None, _planner_groups(len(s), 2)):
        got, runs = _both(monkeypatch, s, None, model, groups_a=groups)
        assert len(got) > 5 and runs is False


@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("seed", range(6))
def test_two_sets_compiled_pairs_are_the_numpy_paths(model, seed, monkeypatch):
    a, b = _case(300 + seed, 40, 60)
    got, _ = _both(monkeypatch, a, b, model)
    assert len(got) > 10
    ga = np.random.default_rng(seed).integers(0, 10, len(a))
    gb = np.random.default_rng(seed + 1).integers(0, 10, len(b))
    grouped, _ = _both(monkeypatch, a, b, model, groups_a=ga, groups_b=gb)
    assert 0 < len(grouped) < len(got)
    for kw in (dict(cell_m=150.0, bucket_s=15.0), dict(z_cell_m=model.vertical_reach_m)):
        _both(monkeypatch, a, b, model, **kw)
        _both(monkeypatch, a, b, model, groups_a=ga, groups_b=gb, **kw)


def test_the_other_options_keep_the_numpy_path(monkeypatch):
    """Distances, ranks and shifts are not the kernel's: the same answer, its first columns."""
    a, b = _case(7, 20, 30)
    monkeypatch.setattr(separation, "_COMPILED_PAIRS", True)
    pairs = conflicting_pairs(a, b, SPHERE)
    with_d, dist = conflicting_pairs(a, b, SPHERE, return_distances=True)
    assert np.array_equal(pairs, with_d) and np.all(dist < 100.0)
    ranked = conflicting_pairs(a, b, SPHERE, rank_a=np.arange(len(a)),
                               rank_b=np.arange(len(b)) + len(a))
    assert np.array_equal(pairs, ranked)


@pytest.mark.parametrize("name, a, b, cylinder, sphere", _ties(), ids=[t[0] for t in _ties()])
def test_ties_give_the_same_pairs_in_both_paths(name, a, b, cylinder, sphere, monkeypatch):
    for model, want in ((CYL, cylinder), (SPHERE, sphere)):
        got, _ = _both(monkeypatch, [a], [b], model)
        assert got.tolist() == ([[0, 0]] if want else [])
        got, _ = _both(monkeypatch, [a, b], None, model)
        assert got.tolist() == ([[0, 1]] if want else [])
        # one group: never a pair
        got, _ = _both(monkeypatch, [a, b], None, model, groups_a=[5, 5])
        assert got.tolist() == []


def test_all_ties_together_give_the_same_pairs(monkeypatch):
    a = [t[1] for t in _ties()]
    b = [t[2] for t in _ties()]
    for model in (SPHERE, CYL):
        _both(monkeypatch, a, b, model)
        _both(monkeypatch, a + b, None, model)
        _both(monkeypatch, a + b, None, model, groups_a=np.arange(2 * len(a))[::-1] // 2)


def test_empty_and_single_inputs(monkeypatch):
    a, _ = _case(11, 3, 0)
    for model in (SPHERE, CYL):
        assert _both(monkeypatch, a[:1], None, model)[0].shape == (0, 2)
        assert _both(monkeypatch, [], None, model)[0].shape == (0, 2)


def test_many_pairs_grow_the_kernels_buffer(monkeypatch):
    """More lost pairs than the kernel's first buffer holds (1024): it doubles, losing none."""
    rng = np.random.default_rng(5)
    s = [Trajectory(np.array([0.0, 100.0]),
                    np.array([[*rng.uniform(-300, 300, 2), 90.0], [*rng.uniform(-300, 300, 2),
                                                                   90.0]]))
         for _ in range(120)]
    got, _ = _both(monkeypatch, s, None, SPHERE)
    assert len(got) > 2048


def test_one_compiled_version_serves_every_setting(monkeypatch):
    separation.warm_up()
    a, b = _case(9, 10, 10)
    monkeypatch.setattr(separation, "_COMPILED_PAIRS", True)
    for model in (SPHERE, CYL):
        for kw in ({}, dict(z_cell_m=30.0)):
            conflicting_pairs(a + b, None, model, **kw)
            conflicting_pairs(a + b, None, model, groups_a=np.arange(len(a + b)) // 2, **kw)
            conflicting_pairs(a, b, model, **kw)
            conflicting_pairs(a, b, model, groups_a=np.zeros(len(a)), groups_b=np.ones(len(b)),
                              **kw)
    assert len(separation_kernel.lost_pairs.signatures) == 1
