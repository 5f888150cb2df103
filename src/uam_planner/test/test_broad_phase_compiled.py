"""The broad phase's compiled steps (``broad_phase_kernel``) against the numpy steps they replace.

With ``separation._COMPILED_KEYS`` on, cutting the pieces, their cell ranges, the packed keys, a
stage's merge of ``any_conflict``, the cell coordinates, the cell mates and the piece table's
box gathers run in numba kernels; off, in numpy. Every intermediate array must be the same to
the last bit (byte equality for floats, not closeness): these tests compare the two paths'
pieces on random segments with extreme values, the unsorted packed codes, and every array of
the broad phase (within one set, with and without groups, and across two sets, with shifts)
and of each stage of ``any_conflict``, on the shared random cases in both models; and
``any_conflict`` and ``conflicting_pairs`` with the switch on and off.
"""

import dataclasses
import os
import sys

import numpy as np
import pytest

from uam_planner import separation
from uam_planner.separation import SegmentSet, any_conflict, conflicting_pairs

sys.path.insert(0, os.path.dirname(__file__))  # the shared cases, beside this file
from separation_cases import CYL, SPHERE, line  # noqa: E402
from separation_cases import random_case as _case  # noqa: E402
from separation_cases import ties as _ties  # noqa: E402


def _same(x, y, what="") -> None:
    """x and y hold the same values to the last bit: arrays of one dtype and shape with equal
    bytes, dataclasses field by field (but their clocks), floats by their bits."""
    if isinstance(x, np.ndarray) or isinstance(y, np.ndarray):
        assert isinstance(x, np.ndarray) and isinstance(y, np.ndarray), what
        assert x.dtype == y.dtype and x.shape == y.shape, (what, x.dtype, y.dtype, x.shape,
                                                           y.shape)
        assert np.ascontiguousarray(x).tobytes() == np.ascontiguousarray(y).tobytes(), what
    elif dataclasses.is_dataclass(x):
        assert type(x) is type(y), what
        for f in dataclasses.fields(x):
            if f.name != "clock" and f.compare:   # not a clock or a cache
                _same(getattr(x, f.name), getattr(y, f.name), f"{what}.{f.name}")
    elif isinstance(x, (tuple, list)):
        assert isinstance(y, (tuple, list)) and len(x) == len(y), what
        for k, (u, w) in enumerate(zip(x, y)):
            _same(u, w, f"{what}[{k}]")
    elif isinstance(x, float):
        assert isinstance(y, float) and np.float64(x).tobytes() == np.float64(y).tobytes(), what
    else:
        assert x == y, (what, x, y)


def _both(monkeypatch, fn, *args, **kwargs):
    """fn(*args, **kwargs) with the compiled steps on, then off."""
    out = []
    for compiled in (True, False):
        monkeypatch.setattr(separation, "_COMPILED_KEYS", compiled)
        out.append(fn(*args, **kwargs))
    return out


def _extreme_segments(seed: int, n: int, cell: float, bucket: float) -> SegmentSet:
    """Random segments whose speeds span 1e-300 .. 1e150 m/s (and exact zeros), durations
    1e-9 .. 1e3 s (and zeros), times near 1e9 s and positions up to 1e12 m, each at most a
    few hundred cells long and buckets in duration (so the pieces stay few)."""
    rng = np.random.default_rng(seed)
    direction = rng.standard_normal((n, 3))
    direction /= np.linalg.norm(direction, axis=1)[:, None]
    speed = 10.0 ** rng.uniform(-300, 150, n)
    speed[rng.random(n) < 0.1] = 0.0
    v = direction * speed[:, None]
    v[rng.random(n) < 0.1, 2] = 0.0                     # level flight
    dur = np.minimum(np.minimum(10.0 ** rng.uniform(-9, 3, n), 300.0 * bucket),
                     300.0 * cell / np.maximum(speed, 1e-300))
    dur[rng.random(n) < 0.05] = 0.0
    t0 = rng.choice([0.0, 1e3, 1e9], n) + rng.uniform(-100, 100, n)
    p0 = rng.uniform(-1, 1, (n, 3)) * rng.choice([1.0, 1e4, 1e12], (n, 1))
    return SegmentSet(rng.integers(0, 5, n).astype(np.int64), t0, t0 + dur, p0, v, 5)


@pytest.mark.parametrize("seed", range(6))
def test_pieces_are_the_numpy_pieces_to_the_last_bit(seed):
    """_cut_pieces_compiled against _cut_pieces_numpy on extreme segments, several grids."""
    for cell, bucket, half, half_z in ((1200.0, 100.0, 50.0, 15.0), (100.0, 1e-3, 50.0, 50.0),
                                       (7.3, 0.37, 3.1, 0.7)):
        s = _extreme_segments(seed, 3000, cell, bucket)
        got = separation._cut_pieces_compiled(s, cell, bucket, half, half_z)
        assert got is not None
        _same(got, separation._cut_pieces_numpy(s, cell, bucket, half, half_z), "pieces")


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # squares beyond 1e308: inf
def test_the_norm_is_numpys_norm():
    """The kernels sum the squared components as numpy's norm does, (x x + y y) + z z; the
    other association differs on some of these vectors (so this test can tell them apart)."""
    rng = np.random.default_rng(3)
    v = rng.standard_normal((100_000, 3)) * 10.0 ** rng.uniform(-150, 150, (100_000, 3))
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    assert np.sqrt((x * x + y * y) + z * z).tobytes() == np.linalg.norm(v, axis=1).tobytes()
    assert np.sqrt(x * x + (y * y + z * z)).tobytes() != np.linalg.norm(v, axis=1).tobytes()
    from uam_planner import broad_phase_kernel as kernel

    v[:3] = [[np.nan, 0.0, 1.0], [np.inf, 1.0, 0.0], [-np.inf, np.nan, 0.0]]
    v[3:6] = [[1e-320, 5e-324, 0.0], [1e200, 1e200, 1e200], [-0.0, -0.0, -0.0]]
    _same(kernel.speeds(v), np.linalg.norm(v, axis=1), "speeds")


def test_a_masked_take_is_boolean_indexing():
    """SegmentSet.take by a mask (np.compress) gives the arrays boolean indexing gives."""
    s = _extreme_segments(2, 500, 1200.0, 100.0)
    rng = np.random.default_rng(2)
    for keep in (rng.random(500) < 0.7, np.zeros(500, bool), np.ones(500, bool)):
        got = s.take(keep)
        _same(got, SegmentSet(s.traj[keep], s.t0_s[keep], s.t1_s[keep], s.p0_m[keep],
                              s.v_mps[keep], s.n_trajectories), "take")
        assert got.p0_m.flags.c_contiguous and got.v_mps.flags.c_contiguous
    with pytest.raises(IndexError):
        s.take(np.ones(499, bool))


def test_counts_at_an_exact_multiple_of_the_cell():
    """A segment exactly one cell long by numpy's norm is one piece, not two: on vectors whose
    norm the other association of the sum rounds up, the counts are numpy's."""
    rng = np.random.default_rng(4)
    v = rng.standard_normal((20_000, 3)) * 10.0 ** rng.uniform(-3, 3, (20_000, 3))
    x, y, z = v[:, 0], v[:, 1], v[:, 2]
    norm = np.linalg.norm(v, axis=1)
    v = v[np.sqrt(x * x + (y * y + z * z)) > norm][:20]
    assert len(v) == 20
    for k in range(len(v)):
        s = SegmentSet(np.zeros(1, np.int64), np.zeros(1), np.ones(1), np.zeros((1, 3)),
                       v[k:k + 1].copy(), 1)
        cell = float(np.linalg.norm(v[k:k + 1], axis=1)[0])
        want = separation._cut_pieces_numpy(s, cell, 10.0, 1.0, 1.0)
        assert want.t0.shape == (1,)
        _same(separation._cut_pieces_compiled(s, cell, 10.0, 1.0, 1.0), want, "one piece")


@pytest.mark.filterwarnings("ignore::RuntimeWarning")  # numpy's cast of a NaN count
@pytest.mark.parametrize("bad", [np.nan, np.inf])
def test_a_count_not_finite_is_left_to_numpy(bad, monkeypatch):
    """A segment whose count of pieces is not finite: the kernel declines, and _cut_pieces
    does what the numpy path does (here: refuses)."""
    s = _extreme_segments(1, 20, 1200.0, 100.0)
    s.v_mps[3, 0] = bad
    assert separation._cut_pieces_compiled(s, 1200.0, 100.0, 50.0, 15.0) is None
    errors = []
    for compiled in (True, False):
        monkeypatch.setattr(separation, "_COMPILED_KEYS", compiled)
        try:
            separation._cut_pieces(s, 1200.0, 100.0, 50.0, 15.0)
            errors.append(None)
        except ValueError as e:
            errors.append(str(e))
    assert errors[0] == errors[1]


def test_z_cells_are_searchsorted():
    """The z cell counts (a guess settled by comparisons) are np.searchsorted's, side 'right'
    and 'left', on boundaries as _make_grid makes them, at, a step off, and far from them."""
    from uam_planner import broad_phase_kernel as kernel

    rng = np.random.default_rng(5)
    for n, z0, dz in ((1, 0.0, 30.0), (2, -15.0, 30.0), (9, -15.0, 30.0), (40, 1e6, 0.1),
                      (7, -3.3, 7.7)):
        bounds = z0 + dz * np.arange(n, dtype=np.float64)
        x = np.concatenate((bounds, np.nextafter(bounds, np.inf), np.nextafter(bounds, -np.inf),
                            z0 + dz * rng.uniform(-3, n + 3, 300), [-1e300, 1e300]))
        inv = 1.0 / (bounds[1] - bounds[0]) if n > 1 else 0.0
        for side, strict in (("right", False), ("left", True)):
            got = [kernel._count_at_most(bounds, v, strict, inv) for v in x]
            assert got == np.searchsorted(bounds, x, side=side).tolist(), (n, side)


def _keyed(model, a, b, z_cell_m):
    """Pieces, grid and cell ranges as _broad_phase makes them (a, b trajectories)."""
    sa, sb = SegmentSet.from_trajectories(a), SegmentSet.from_trajectories(b)
    sa, sb = separation._common_window(sa, sb, None)
    cell, bucket = separation._grid_size(sa, model.separation_m, None, None)
    half, half_z = 0.5 * model.separation_m, 0.5 * model.vertical_reach_m
    pa = separation._cut_pieces(sa, cell, bucket, half, half_z)
    pb = separation._cut_pieces(sb, cell, bucket, half, half_z)
    return (pa, pb) + separation._keyed_grid(pa, pb, pa.t1, cell, bucket, z_cell_m, half_z,
                                             False)


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model,z_cell_m", [(SPHERE, None), (CYL, 30.0), (SPHERE, 25.0)])
def test_ranges_and_packed_codes_are_the_numpy_ones(seed, model, z_cell_m, monkeypatch):
    """The grid, the cell ranges and the unsorted packed codes (in _expand_keys' order; for a
    stage, with a's global ids packed in) of both paths."""
    a, b = _case(seed, 25, 40)
    got, want = _both(monkeypatch, _keyed, model, a, b, z_cell_m)
    _same(got, want, "keyed")
    pa, pb, grid, ra, rb = got
    na = pa.t0.shape[0]
    item_bits = max(int(na + pb.t0.shape[0]).bit_length(), 1)
    codes = separation._packed_codes(((ra, 0, 0), (rb, 1, na)), grid, item_bits)
    ka, _ = separation._expand_keys(ra, 0, 0, grid, False, True, item_bits)
    kb, _ = separation._expand_keys(rb, 1, na, grid, False, True, item_bits)
    _same(codes, np.concatenate((ka, kb)), "codes")
    idx = np.flatnonzero(np.random.default_rng(seed).random(na) < 0.4)
    staged = separation._packed_codes(((ra, 0, 0),), grid, item_bits, idx)
    k_idx, _ = separation._expand_keys(tuple(r[idx] for r in ra), 0, 0, grid, False, True,
                                       item_bits)
    mask = (1 << item_bits) - 1
    _same(staged, ((k_idx >> item_bits) << item_bits) | idx[k_idx & mask], "stage codes")


def _broad(model, a, b, **kw):
    """_broad_phase of the trajectories a (and b, or None) as conflicting_pairs calls it."""
    sa = SegmentSet.from_trajectories(a)
    sb = sa if b is None else SegmentSet.from_trajectories(b)
    return separation._broad_phase(model, sa, sb, b is None, kw.get("groups"),
                                   kw.get("groups_b"), kw.get("slack"), None, None,
                                   kw.get("z_cell_m"))


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
def test_every_broad_phase_array_is_the_numpy_one(seed, model, monkeypatch):
    """Pieces, sorted keys, cell coordinates, cell mates and the piece table of _broad_phase:
    across two sets, within one set (with its own runs skipped, with groups in request order
    and with labels that decrease within a cell) and with a's pieces swept by a slack."""
    a, b = _case(seed, 30, 45)
    rng = np.random.default_rng(seed)
    settings = [(a, b, {}), (a, b, dict(z_cell_m=25.0)), (a + b, None, {}),
                (a + b, None, dict(groups=np.arange(len(a) + len(b)) // 3)),
                (a + b, None, dict(groups=rng.integers(0, 6, len(a) + len(b)))),
                (a, b, dict(slack=rng.choice([0.0, 30.0], len(a)))),
                (a, b, dict(groups=rng.integers(0, 4, len(a)),
                            groups_b=rng.integers(0, 4, len(b))))]
    for u, w, kw in settings:
        got, want = _both(monkeypatch, _broad, model, u, w, **kw)
        assert got is not None
        _same(got, want, f"broad phase {sorted(kw)}")


@pytest.mark.parametrize("far,widened", [(3e10, False), (1e13, True)])
def test_keys_not_packed_or_widened_are_the_numpy_ones(far, widened, monkeypatch):
    """Extents too large for one packed code (keys and items apart), or for one int64 cell
    code (keys sorted by coordinates): the numpy keys, then the compiled cell mates and
    gathers, the same arrays either way."""
    a, b = _case(7, 15, 20)
    a.append(line(0, 200, (far - 1000, far, 90), (far + 1000, far, 90)))
    b.append(line(0, 200, (far, far - 1000, 90), (far, far + 1000, 90)))
    for model in (SPHERE, CYL):
        for u, w in ((a, b), (a + b, None)):
            got, want = _both(monkeypatch, _broad, model, u, w)
            grid = got.grid
            max_code = grid.nt * grid.ny * grid.nx * grid.nz * 2
            assert (max_code.bit_length() > 63) == widened
            assert max_code.bit_length() + int(got.n_items).bit_length() > 63
            _same(got, want, "broad phase")


def _stages(model, a, b, shifts=None):
    """Every stage's broad phase of any_conflict (all of a's segments in stages by their
    start, as any_conflict cuts them, and a random half)."""
    sa, sb = SegmentSet.from_trajectories(a), SegmentSet.from_trajectories(b)
    first, shift, slack = separation._check_shifts(shifts, False, sa.n_trajectories)
    sa, sb = separation._common_window(sa, sb, slack)
    cell, bucket = separation._grid_size(sa, model.separation_m, None, None)
    z_cell_m = model.vertical_reach_m if model.kind == "cylinder" else None
    keyed = separation._KeyedSets.make(model, sa, sb, slack, cell, bucket, z_cell_m)
    t = sa.t0_s - sa.t0_s.min()
    masks = [t < 30.0, (t >= 30.0) & (t < 120.0), t >= 120.0,
             np.random.default_rng(len(a)).random(len(sa)) < 0.5]
    return keyed, [keyed.stage(m) for m in masks if m.any()]


@pytest.mark.parametrize("seed", range(5))
@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
def test_every_stage_array_is_the_numpy_one(seed, model, monkeypatch):
    """b's sorted codes and each stage's merged keys, cell mates and piece table."""
    a, b = _case(seed, 30, 45)
    first = np.concatenate(([0], np.cumsum(np.random.default_rng(seed).integers(1, 4, len(a)))))
    shift = 5.0 * (np.arange(first[-1]) - np.repeat(first[:-1], np.diff(first)))
    for shifts in (None, (first, shift)):
        got, want = _both(monkeypatch, _stages, model, a, b, shifts)
        assert len(got[1]) >= 2
        _same(got, want, "stages")


def _decisions(model, a, b, **kw):
    st: dict = {}
    out = any_conflict(a, b, model, stats=st, **kw)
    st = {k: v for k, v in st.items() if not k.endswith("_s")}
    return out, st


@pytest.mark.parametrize("seed", range(4))
@pytest.mark.parametrize("model", [SPHERE, CYL], ids=["sphere", "cylinder"])
def test_decisions_and_pairs_do_not_depend_on_the_switch(seed, model, monkeypatch):
    """any_conflict (with and without shifts) and conflicting_pairs (compiled and numpy pair
    walks, with distances, ranks and shifts) give the same arrays and counts either way."""
    a, b = _case(seed, 30, 45)
    first = np.concatenate(([0], np.cumsum(np.random.default_rng(seed).integers(1, 4, len(a)))))
    shift = 5.0 * (np.arange(first[-1]) - np.repeat(first[:-1], np.diff(first)))
    for kw in ({}, dict(shifts_a=(first, shift)), dict(z_cell_m=30.0)):
        got, want = _both(monkeypatch, _decisions, model, a, b, **kw)
        _same(got, want, f"any_conflict {sorted(kw)}")
        assert got[0].any() and not got[0].all()
    ranks = dict(rank_a=np.arange(len(a)), rank_b=len(a) + np.arange(len(b))[::-1])
    for u, w, kw in ((a, b, {}), (a + b, None, {}), (a + b, None, dict(return_distances=True)),
                     (a, b, dict(return_distances=True, **ranks)),
                     (a, b, dict(shifts_a=(first, shift), return_distances=True)),
                     (a + b, None, dict(groups_a=np.arange(len(a) + len(b)) // 2))):
        got, want = _both(monkeypatch, conflicting_pairs, u, w, model, **kw)
        _same(got, want, f"conflicting_pairs {sorted(kw)}")


def test_the_ties_do_not_depend_on_the_switch(monkeypatch):
    """The shared ties (a step either side of V, of touching in time, of the separation)."""
    for name, a, b, _, _ in _ties():
        for model in (SPHERE, CYL):
            got, want = _both(monkeypatch, _decisions, model, [a], [b])
            _same(got, want, name)
            got, want = _both(monkeypatch, conflicting_pairs, [a, b], None, model,
                              return_distances=True)
            _same(got, want, name)


def test_one_compiled_version_of_each_kernel(monkeypatch):
    """Every setting gives each kernel the same argument types: one compile (or load) each."""
    from uam_planner import broad_phase_kernel as kernel

    monkeypatch.setattr(separation, "_COMPILED_KEYS", True)
    separation.warm_up()
    a, b = _case(2, 10, 10)
    for model in (SPHERE, CYL):
        any_conflict(a, b, model)
        any_conflict(a, b, model, z_cell_m=30.0)
        conflicting_pairs(a + b, None, model, groups_a=np.arange(len(a) + len(b)))
        conflicting_pairs(a, b, model, return_distances=True)
    for name in ("speeds", "piece_counts", "box_rows", "cut_pieces", "cell_ranges", "key_count", "pack_keys",
                 "merge_stage", "cell_coordinates", "cell_mates", "gather_boxes"):
        assert len(getattr(kernel, name).signatures) == 1, name
