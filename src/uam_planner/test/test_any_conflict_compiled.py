"""The compiled check that decides (``separation_kernel``) against the numpy path it replaces.

``any_conflict`` walks its cell-mate pairs in a numba kernel when ``separation._COMPILED_DECIDE``
is on, in numpy when it is off. The two must decide the same to the last bit: the kernel's
measures are the numpy kernels' floating-point operations in the same order, and these tests
hold them to it, per segment pair (the distances themselves, byte for byte) and per decision,
on seeded random cases in both models, with and without departure shifts, with trajectories
longer than the deciding stages, and on the ties where a decision could flip on the last bit:
flat segments exactly V apart, touching time intervals, zero relative velocity, a candidate
whose only loss is in the last stage. Both are also held to the first column of
``conflicting_pairs``, the pair list the planner used before the deciding check.
"""

import numpy as np
import pytest

from uam_planner import separation, separation_kernel
from uam_planner.separation import (any_conflict, conflicting_pairs,
                                    segment_pair_min_distance, segment_pair_min_horizontal_m)
from uam_planner.trajectory import Trajectory

import os
import sys

sys.path.insert(0, os.path.dirname(__file__))  # the shared cases, beside this file
from separation_cases import CYL, SPHERE  # noqa: E402
from separation_cases import line as _line  # noqa: E402
from separation_cases import random_case as _case  # noqa: E402
from separation_cases import ties as _ties  # noqa: E402

def _decide(monkeypatch, compiled: bool, a, b, model, **kw):
    """any_conflict with the compiled path on or off, and its stats."""
    monkeypatch.setattr(separation, "_COMPILED_DECIDE", compiled)
    st: dict = {}
    got = any_conflict(a, b, model, stats=st, **kw)
    return got, st


def _both(monkeypatch, a, b, model, **kw):
    """The compiled and the numpy decisions (equal, or the test fails), the pair list's mask
    beside them, and the two paths' stats."""
    got, st_c = _decide(monkeypatch, True, a, b, model, **kw)
    want, st_n = _decide(monkeypatch, False, a, b, model, **kw)
    assert got.dtype == want.dtype == bool
    assert got.tolist() == want.tolist()
    shifts = kw.get("shifts_a")
    n = len(a) if shifts is None else len(shifts[1])
    mask = np.zeros(n, dtype=bool)
    pairs = conflicting_pairs(a, b, model, **kw)
    mask[pairs[:, 0]] = True
    assert got.tolist() == mask.tolist()
    # the same stats keys (none when no stage had a piece pair to look at); the compiled path
    # stops at a candidate's first loss, within a chunk too, so it takes at most as many
    # exact measures
    assert set(st_c) == set(st_n)
    assert st_c.get("exact_checks", 0) <= st_n.get("exact_checks", 0)
    return got, st_c, st_n


def _shifts(seed, n):
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 8, n)
    first = np.concatenate(([0], np.cumsum(counts)))
    shift = np.concatenate([5.0 * np.arange(c) for c in counts])
    return first, shift


@pytest.mark.parametrize("stages", [separation._DECIDE_STAGES_S, (10.0, 40.0, 200.0, 700.0)])
@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("seed", range(5))
def test_compiled_decisions_are_the_numpy_paths(model, seed, stages, monkeypatch):
    monkeypatch.setattr(separation, "_DECIDE_STAGES_S", stages)
    a, b = _case(seed, 50, 70)
    got, st, _ = _both(monkeypatch, a, b, model)
    assert 5 < got.sum() < len(a)
    assert st["exact_checks"] > 0
    # the segments of a starting after the last stage boundary take part (a late stage)
    assert max(tr.times_s[-2] for tr in a) > stages[-1] + 60.0
    for kw in (dict(cell_m=150.0, bucket_s=15.0), dict(z_cell_m=model.vertical_reach_m)):
        _both(monkeypatch, a, b, model, **kw)


@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
@pytest.mark.parametrize("seed", range(4))
def test_compiled_decisions_with_shifts_are_the_numpy_paths(model, seed, monkeypatch):
    base, active = _case(50 + seed, 30, 60)
    first, shift = _shifts(seed, len(base))
    got, _, _ = _both(monkeypatch, base, active, model, shifts_a=(first, shift))
    assert 5 < got.sum() < shift.size
    _both(monkeypatch, base, active, model, shifts_a=(first, shift),
          z_cell_m=model.vertical_reach_m)


def _segments(rng, n):
    """Random segment pairs with the ties mixed in: equal velocities, flat segments exactly V
    (30 m) apart, touching or disjoint time intervals, a common instant only."""
    t0a = rng.uniform(0, 100, n)
    t1a = t0a + rng.uniform(0, 60, n)
    t0b = t0a + rng.uniform(-40, 40, n)
    t1b = t0b + rng.uniform(0, 60, n)
    p0a = rng.uniform(-300, 300, (n, 3))
    p0b = p0a + rng.uniform(-150, 150, (n, 3)) * [1.0, 1.0, 0.4]
    va = rng.uniform(-15, 15, (n, 3)) * [1.0, 1.0, 0.3]
    vb = rng.uniform(-15, 15, (n, 3)) * [1.0, 1.0, 0.3]
    k = np.arange(n)
    vb[k % 5 == 0] = va[k % 5 == 0]                     # zero relative velocity
    flat = k % 5 == 1                                   # two flat segments V apart
    va[flat, 2] = vb[flat, 2] = 0.0
    p0b[flat, 2] = p0a[flat, 2] + 30.0
    t0b[k % 7 == 2] = t1a[k % 7 == 2]                   # touching intervals
    t0b[k % 7 == 3] = np.nextafter(t1a[k % 7 == 3], np.inf)   # one rounding step apart
    t1a[k % 11 == 4] = t0a[k % 11 == 4]                 # an instant
    return t0a, t1a, p0a, va, t0b, t1b, p0b, vb


def test_kernel_measures_are_the_numpy_kernels_to_the_last_bit():
    rng = np.random.default_rng(0)
    args = _segments(rng, 3000)
    t0a, t1a, p0a, va, t0b, t1b, p0b, vb = args
    sphere = segment_pair_min_distance(*args)
    cylinder = segment_pair_min_horizontal_m(*args, 30.0)
    got_s = np.empty_like(sphere)
    got_c = np.empty_like(cylinder)
    for k in range(sphere.shape[0]):
        row = (t0a[k], t1a[k], *p0a[k], *va[k], t0b[k], t1b[k], *p0b[k], *vb[k])
        got_s[k] = separation_kernel.sphere_measure(*row)
        got_c[k] = separation_kernel.cylinder_measure(*row, 30.0, separation._WINDOW_TOLERANCE_S)
    assert got_s.tobytes() == sphere.tobytes()
    assert got_c.tobytes() == cylinder.tobytes()
    # the ties are there: finite and infinite measures, both models
    assert np.isfinite(cylinder).sum() > 300 and np.isinf(cylinder).sum() > 300
    assert np.isinf(sphere).sum() > 100 and (sphere < 100.0).sum() > 100


@pytest.mark.parametrize("name, a, b, cylinder, sphere", _ties(), ids=[t[0] for t in _ties()])
def test_ties_decide_the_same_in_both_paths(name, a, b, cylinder, sphere, monkeypatch):
    for model, want in ((CYL, cylinder), (SPHERE, sphere)):
        got, _, _ = _both(monkeypatch, [a], [b], model)
        assert got.tolist() == [want], model.kind
        # the same flight as one of several candidates, departing 0, 5 and 10 s late
        got, _, _ = _both(monkeypatch, [a], [b], model,
                          shifts_a=(np.array([0, 3]), np.array([0.0, 5.0, 10.0])))
        assert got[0] == want


def test_all_ties_together_decide_the_same(monkeypatch):
    a = [t[1] for t in _ties()]
    b = [t[2] for t in _ties()]
    for model in (SPHERE, CYL):
        _both(monkeypatch, a, b, model)


def test_a_loss_in_the_last_stage_only_decides_the_same(monkeypatch):
    """Candidates of a long flight whose only loss is 20 min after a's first departure (past
    every stage boundary): some shifts meet the crossing flight there, others pass."""
    # east, over the origin at t = 1000, in legs of 100 s: the legs near the origin start in
    # the last stage
    times = np.arange(0.0, 2001.0, 100.0)
    east = Trajectory(times, np.stack((-10000.0 + 10.0 * times, 0.0 * times, 90.0 + 0.0 * times),
                                      axis=1))
    assert times[9] > separation._DECIDE_STAGES_S[-1]
    other = _line(0, 10, (5000, 5000, 150), (5100, 5000, 150))  # a's stages start at t = 0
    a = [other, east]
    north = _line(1000, 1200, (0, -1000, 90), (0, 1000, 90))    # over the origin at t = 1100
    first = np.array([0, 1, 31])
    shift = np.concatenate(([0.0], 5.0 * np.arange(30)))
    for model in (SPHERE, CYL):
        got, st_c, st_n = _both(monkeypatch, a, [north], model, shifts_a=(first, shift))
        lost = np.flatnonzero(got) - 1
        # candidate k departs 5 k s late: over the origin at 1000 + 5 k, north at 1100
        assert lost.min() > 0 and 100 / 5 in lost and got[0] == False  # noqa: E712
        assert st_c["exact_checks"] > 0 and st_n["exact_checks"] >= st_c["exact_checks"]
        got, _, _ = _both(monkeypatch, a, [north], model)
        assert got.tolist() == [False, False]


def test_huge_extents_take_the_general_broad_phase_and_decide_the_same(monkeypatch):
    """Extents whose packed cell codes do not fit int64: the per-stage general broad phase
    (keys sorted by their coordinates) feeds the same kernel."""
    a, b = _case(3, 20, 30)
    far = 1e13
    a.append(_line(0, 200, (far - 1000, far, 90), (far + 1000, far, 90)))
    b.append(_line(0, 200, (far, far - 1000, 90), (far, far + 1000, 90)))
    for model in (SPHERE, CYL):
        got, _, _ = _both(monkeypatch, a, b, model)
        assert got[-1] and got[:-1].any()


def test_one_compiled_version_serves_every_setting(monkeypatch):
    """Both models, shifts or none, z in the keys or not: the kernel sees one set of argument
    types, so a process compiles (or loads) it once."""
    separation.warm_up()
    a, b = _case(9, 10, 10)
    first, shift = _shifts(9, len(a))
    monkeypatch.setattr(separation, "_COMPILED_DECIDE", True)
    for model in (SPHERE, CYL):
        for kw in ({}, dict(shifts_a=(first, shift)), dict(z_cell_m=30.0)):
            any_conflict(a, b, model, **kw)
    assert len(separation_kernel.decide_pairs.signatures) == 1


def test_keep_freed_memory_keeps_a_freed_temporary_for_the_next_one():
    """After separation.keep_freed_memory, a freed 20 MB temporary is kept and the next one
    reuses it; by default glibc gives it back and the next one faults its pages in again. In
    fresh processes: the setting changes the process's allocator."""
    import subprocess
    import sys

    code = (
        "import resource, sys, numpy as np\n"
        "from uam_planner import separation\n"
        "if sys.argv[1] == 'keep':\n"
        "    assert separation.keep_freed_memory()\n"
        "def faults():\n"
        "    f0 = resource.getrusage(resource.RUSAGE_SELF).ru_minflt\n"
        "    np.ones(20 << 17).sum()\n"
        "    return resource.getrusage(resource.RUSAGE_SELF).ru_minflt - f0\n"
        "faults()\n"
        "print(faults())\n")

    def second_faults(how):
        out = subprocess.run([sys.executable, "-c", code, how], capture_output=True, text=True,
                             timeout=120, check=True)
        return int(out.stdout.split()[-1])
    default, kept = second_faults("default"), second_faults("keep")
    assert default > 100, default   # the default gave the first one back
    assert kept < 50, (kept, default)
