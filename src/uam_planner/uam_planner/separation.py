"""Exact separation between piecewise-linear 4D trajectories, in continuous time (framework steps 4-5).

Narrow phase (exact): two segments move linearly; over the common time interval [lo, hi] their
relative position is r(t) = r_lo + dv (t - lo), so the squared distance is a quadratic in t whose
minimum is at tau* = -(r_lo . dv) / |dv|^2 clamped to [0, hi - lo] (closest point of approach,
CPA). The minimum distance between two trajectories is the minimum over their time-overlapping
segment pairs. Nothing is sampled, so a fast head-on pass between two sample times is never missed.
``segment_pair_min_distance`` evaluates this for many segment pairs at once with numpy.

Broad phase (``conflicting_pairs``): why space-time buckets of short pieces.
All flights of the planner move along corridors at similar speeds, most of them far apart in space
or in time, so all-pairs checking would waste nearly all its work. We

1. keep only segments inside the common time window of the two sets (an active flight's flown
   part cannot conflict with a candidate departing now);
2. cut every segment into pieces no longer than ``cell_m`` in space and ``bucket_s`` in time (a
   long diagonal segment otherwise has a huge bounding box that lands in many cells);
3. give each piece every (x cell, y cell, time bucket) key that its bounding box, inflated by
   separation/2 in x and y, touches (a handful per piece, since cell_m >= separation);
4. sort the keys; pieces sharing a key are the candidate pairs. Two pieces closer than the
   separation at a common time t share the key of their midpoint at t, so no conflict is lost
   (z is ignored in the keys by default, which is conservative: 3D distance >= horizontal
   distance; with ``z_cell_m`` the keys also hold z cells, compared with the boundaries rather
   than divided, so two z ranges that overlap strictly always share one);
5. drop pairs whose inflated boxes or time intervals do not overlap and report each surviving
   pair only in one canonical cell (the one holding the low corner of the boxes' intersection),
   so the exact kernel runs once per pair of pieces that can actually come near.

Sorting is O(N log N) in the number of piece keys N, and the exact kernel's cost follows the
number of pieces that share a cell at the same time, not the square of the number of flights.
Pairs are generated in bounded chunks so memory stays bounded even in a crowded cell.
Steps 2-4 run in compiled kernels (``broad_phase_kernel``; ``_COMPILED_KEYS`` off: numpy), which
make the same arrays to the last bit as the numpy steps kept beside them.
"""

from __future__ import annotations

import time
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from uam_contract import defaults

from .trajectory import Trajectory

DEFAULT_SEPARATION_M = defaults.SEPARATION_M   # the one source: uam_contract.defaults
# Pairs per chunk of the narrow phase: 2^17 (was 2^20) keeps each chunk's temporaries (~1 MB)
# in memory malloc reuses; at 2^20 they were mapped and unmapped per chunk: 2.9 s of system
# time against 0.8 s in bench_horizon --in-process --cpu (H = 10, 300 s), the same pairs.
_MAX_PAIRS_PER_CHUNK = 1 << 17
# Cell-mate pairs per chunk of the check that decides (any_conflict): smaller chunks let the
# trajectories found blocked in one chunk drop out of the next sooner
_DECIDE_PAIRS_PER_CHUNK = 1 << 15
# The stages of any_conflict [s after a's first segment start]: in the synthetic city at
# 30,000 requests/h, 60 % of the candidates are blocked by a segment starting in their first
# 30 s, 73 % within 120 s, 89 % within 480 s
_DECIDE_STAGES_S = (30.0, 120.0, 480.0)
# Broad-phase defaults, tuned on the paper- and city-scale instances of python -m uam_planner.bench
# (corridors of 0.7-1 km): cells of 12 separations and time buckets of one cell's flight time
# balance the cell keys per piece (sorting cost) against the pairs that share a cell without
# coming near (filtering cost). Any cell_m >= separation_m gives the same, exact answer.
DEFAULT_CELL_SEPARATIONS = 12.0
DEFAULT_BUCKET_CELLS = 1.0
# Two broad-phase shortcuts of conflicting_pairs (63 % of a study cell's CPU was in it).
# Neither changes a result to the last bit: both only leave out piece pairs the box filter drops
# (the exact kernel sees the same piece pairs, in the same orientation). Off only in the tests
# that compare the two paths (test_separation_exact.py, test_separation_cylinder.py).
# - the cylinder's vertical reach V as z cells of the keys when z_cell_m is not given;
# - within one set, the partners of an entry start after its run of one trajectory (or group)
#   in its cell, where the labels are checked not to decrease within every cell.
_CYLINDER_Z_KEYS = True
_SKIP_OWN_RUNS = True
# The check that decides (any_conflict) walks its cell-mate pairs in a compiled kernel
# (separation_kernel): the same decisions to the last bit as the numpy path kept beside it
# (off: numpy), without the numpy path's gathers and temporaries per pair and per candidate
_COMPILED_DECIDE = True
# conflicting_pairs without shifts, ranks or distances (the conflict graph's call) walks its
# cell-mate pairs in a compiled kernel too: the same pairs as the numpy path kept beside it (off)
_COMPILED_PAIRS = True
# The broad phase's own steps (cutting pieces, cell ranges, packed keys, a stage's merge, cell
# coordinates, cell mates, the piece table's gathers) in compiled kernels (broad_phase_kernel):
# the same arrays to the last bit as the numpy steps kept beside them (off: numpy), without a
# temporary per operation; keys too wide for one packed int64 code stay on numpy
_COMPILED_KEYS = True


_KERNEL_BLOCK = 8192


def _cpa_block(t0a, t1a, ax, ay, az, vax, vay, vaz, t0b, t1b, bx, by, bz, vbx, vby, vbz, out):
    """Closest point of approach for one block of pairs, component-wise, in place into ``out``.

    Relative position at the start of the common interval lo = max(t0a, t0b):
    r = (a + va (lo - t0a)) - (b + vb (lo - t0b)); relative velocity dv = va - vb; the squared
    distance |r + dv tau|^2 is smallest at tau = -(r . dv) / |dv|^2, clamped to [0, hi - lo].
    """
    lo = np.maximum(t0a, t0b)
    span = np.minimum(t1a, t1b)
    span -= lo
    da = lo - t0a
    db = lo
    db -= t0b
    tmp = np.empty_like(lo)
    rx = vax * da
    rx += ax
    rx -= bx
    np.multiply(vbx, db, out=tmp)
    rx -= tmp
    ry = vay * da
    ry += ay
    ry -= by
    np.multiply(vby, db, out=tmp)
    ry -= tmp
    rz = vaz * da
    rz += az
    rz -= bz
    np.multiply(vbz, db, out=tmp)
    rz -= tmp
    dvx = vax - vbx
    dvy = vay - vby
    dvz = vaz - vbz
    a = dvx * dvx
    np.multiply(dvy, dvy, out=tmp)
    a += tmp
    np.multiply(dvz, dvz, out=tmp)
    a += tmp
    b = rx * dvx
    np.multiply(ry, dvy, out=tmp)
    b += tmp
    np.multiply(rz, dvz, out=tmp)
    b += tmp
    np.negative(b, out=b)
    tau = np.divide(b, a, out=np.zeros_like(a), where=a > 0.0)
    np.maximum(span, 0.0, out=tmp)
    np.clip(tau, 0.0, tmp, out=tau)
    dvx *= tau
    rx += dvx
    dvy *= tau
    ry += dvy
    dvz *= tau
    rz += dvz
    rx *= rx
    ry *= ry
    rz *= rz
    rx += ry
    rx += rz
    np.sqrt(rx, out=out)
    out[span < 0.0] = np.inf


def segment_pair_min_distance(t0a, t1a, p0a, va, t0b, t1b, p0b, vb) -> np.ndarray:
    """Exact minimum distance [m] of many pairs of linearly moving points over their common time.

    Pair i: point A is at ``p0a[i] + va[i] (t - t0a[i])`` for t in [t0a[i], t1a[i]], point B the
    same with b. Inputs are (n,) times [s], (n, 3) positions [m] at t0 and (n, 3) velocities [m/s].
    Returns (n,) float64 distances; +inf where the two time intervals do not overlap (touching
    intervals count as overlapping). O(n) time; evaluated in blocks of a few thousand pairs so the
    temporaries stay in the CPU cache (about 1.5x faster than whole-array numpy here).
    """
    t0a = np.asarray(t0a, dtype=np.float64)
    t1a = np.asarray(t1a, dtype=np.float64)
    t0b = np.asarray(t0b, dtype=np.float64)
    t1b = np.asarray(t1b, dtype=np.float64)
    p0a = np.asarray(p0a, dtype=np.float64)
    p0b = np.asarray(p0b, dtype=np.float64)
    va = np.asarray(va, dtype=np.float64)
    vb = np.asarray(vb, dtype=np.float64)
    n = t0a.shape[0]
    for name, arr, shape in (("t1a", t1a, (n,)), ("t0b", t0b, (n,)), ("t1b", t1b, (n,)),
                             ("p0a", p0a, (n, 3)), ("va", va, (n, 3)), ("p0b", p0b, (n, 3)),
                             ("vb", vb, (n, 3))):
        if arr.shape != shape:
            raise ValueError(f"{name} must have shape {shape}, got {arr.shape}")
    out = np.empty(n, dtype=np.float64)
    for s in range(0, n, _KERNEL_BLOCK):
        e = min(n, s + _KERNEL_BLOCK)
        pa, wa, pb, wb = p0a[s:e], va[s:e], p0b[s:e], vb[s:e]
        _cpa_block(t0a[s:e], t1a[s:e], pa[:, 0], pa[:, 1], pa[:, 2], wa[:, 0], wa[:, 1], wa[:, 2],
                   t0b[s:e], t1b[s:e], pb[:, 0], pb[:, 1], pb[:, 2], wb[:, 0], wb[:, 1], wb[:, 2],
                   out[s:e])
    return out


SEPARATION_MODELS = ("sphere", "cylinder")
DEFAULT_VERTICAL_SEPARATION_M = defaults.VERTICAL_SEPARATION_M


@dataclass(frozen=True)
class SeparationModel:
    """What counts as a loss of separation between two aircraft at one instant.

    Attributes:
        kind: ``'sphere'`` (the paper's model, default): the 3D distance is below
            ``separation_m``; ``'cylinder'``: the horizontal distance is below ``separation_m``
            (H) and the vertical distance below ``vertical_separation_m`` (V), at the same time.
        separation_m: the sphere's radius, or the cylinder's horizontal minimum H [m].
        vertical_separation_m: the cylinder's vertical minimum V [m]; unused by the sphere.

    Both are strict: aircraft exactly H apart horizontally, or exactly V apart vertically (two
    flight levels 30 m apart with V = 30 m), keep separation.
    """

    kind: str = "sphere"
    separation_m: float = DEFAULT_SEPARATION_M
    vertical_separation_m: float = DEFAULT_VERTICAL_SEPARATION_M

    def __post_init__(self):
        if self.kind not in SEPARATION_MODELS:
            raise ValueError(f"separation model kind must be one of {SEPARATION_MODELS}, "
                             f"got {self.kind!r}")
        for name in ("separation_m", "vertical_separation_m"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.floating, np.integer)) \
                    or not np.isfinite(v) or v <= 0:
                raise ValueError(f"SeparationModel.{name} must be positive and finite, got {v!r}")

    @property
    def vertical_reach_m(self) -> float:
        """Vertical distance [m] below which a loss is possible (the broad phase's z margin)."""
        return float(self.separation_m if self.kind == "sphere" else self.vertical_separation_m)

    def segment_measure(self, t0a, t1a, p0a, va, t0b, t1b, p0b, vb) -> np.ndarray:
        """Per segment pair, a distance [m] that is below ``separation_m`` exactly when the pair
        loses separation: the exact minimum 3D distance (sphere) or the exact minimum horizontal
        distance over the times when the vertical distance is below V (cylinder; +inf if never).
        Same inputs as :func:`segment_pair_min_distance`."""
        if self.kind == "sphere":
            return segment_pair_min_distance(t0a, t1a, p0a, va, t0b, t1b, p0b, vb)
        return segment_pair_min_horizontal_m(t0a, t1a, p0a, va, t0b, t1b, p0b, vb,
                                             self.vertical_separation_m)


def as_separation_model(separation) -> SeparationModel:
    """A SeparationModel from a model or a number (the paper's sphere of that radius [m])."""
    if isinstance(separation, SeparationModel):
        return separation
    if isinstance(separation, bool) or not isinstance(separation, (int, float, np.floating,
                                                                   np.integer)) \
            or not np.isfinite(separation) or separation <= 0:
        raise ValueError(f"separation_m must be positive and finite, got {separation!r}")
    return SeparationModel("sphere", float(separation))


def _relative_motion(t0a, t1a, p0a, va, t0b, t1b, p0b, vb):
    """Common interval start lo, its length span (< 0: no overlap), relative position at lo and
    relative velocity, for arrays of segment pairs."""
    lo = np.maximum(t0a, t0b)
    span = np.minimum(t1a, t1b) - lo
    r = (p0a + va * (lo - t0a)[:, None]) - (p0b + vb * (lo - t0b)[:, None])
    return lo, span, r, va - vb


# Strict at the ends of the common interval: a window that only touches an end (|dz| reaches V
# exactly at a waypoint, as when one flight starts its descent right under another flight one
# level up) is no loss. Where rounding could put such a touch on either side, the audit ignores
# windows shorter than 1e-9 of the overlap, so the planner's kernel never misses what it finds.
_WINDOW_TOLERANCE_S = 0.0


def _vertical_window(rz, dvz, span, vertical_m):
    """The part [wl, wh] of [0, span] where |rz + dvz tau| < vertical_m, and whether it is
    non-empty (open in the strict inequality, closed where it meets the ends of [0, span]).
    Two flat segments exactly ``vertical_m`` apart (two flight levels) never have a window."""
    with np.errstate(divide="ignore", invalid="ignore"):
        moving = dvz != 0.0
        a = np.where(moving, (-vertical_m - rz) / np.where(moving, dvz, 1.0), -np.inf)
        b = np.where(moving, (vertical_m - rz) / np.where(moving, dvz, 1.0), np.inf)
    vl = np.minimum(a, b)
    vh = np.maximum(a, b)
    still_ok = np.abs(rz) < vertical_m
    ok = np.where(moving, (vl < span + _WINDOW_TOLERANCE_S) & (vh > -_WINDOW_TOLERANCE_S),
                  still_ok) & (span >= 0.0)
    return np.maximum(vl, 0.0), np.minimum(vh, span), ok


def segment_pair_min_horizontal_m(t0a, t1a, p0a, va, t0b, t1b, p0b, vb,
                                  vertical_m: float) -> np.ndarray:
    """Cylinder kernel: per pair, the exact minimum horizontal distance [m] over the common
    times at which the vertical distance is below ``vertical_m`` [m]; +inf if there is no such
    time (or no common time).

    Over the common interval the relative motion is linear, so |dz(tau)| < V holds on one open
    interval of tau (closed form, or all/none when dz is constant) and the squared horizontal
    distance is a quadratic whose minimum over that interval is at the clamped closest point of
    approach. The pair loses separation (horizontal < H while |dz| < V) exactly when this
    minimum is below H: the interval where the horizontal distance is below H then meets the
    vertical interval. Inputs as in :func:`segment_pair_min_distance`. O(n).
    """
    arrs = [np.asarray(x, dtype=np.float64) for x in (t0a, t1a, p0a, va, t0b, t1b, p0b, vb)]
    n = arrs[0].shape[0]
    out = np.full(n, np.inf)
    for s in range(0, n, _KERNEL_BLOCK):
        e = min(n, s + _KERNEL_BLOCK)
        lo, span, r, dv = _relative_motion(*(x[s:e] for x in arrs))
        wl, wh, ok = _vertical_window(r[:, 2], dv[:, 2], span, float(vertical_m))
        rx, ry, dx, dy = r[:, 0], r[:, 1], dv[:, 0], dv[:, 1]
        aa = dx * dx + dy * dy
        tau = np.divide(-(rx * dx + ry * dy), aa, out=np.zeros_like(aa), where=aa > 0.0)
        tau = np.minimum(np.maximum(tau, wl), np.maximum(wh, wl))
        d = np.hypot(rx + dx * tau, ry + dy * tau)
        out[s:e] = np.where(ok, d, np.inf)
    return out


def loss_intervals_s(a: Trajectory, b: Trajectory, separation=DEFAULT_SEPARATION_M) -> list:
    """The time intervals [s] during which trajectories ``a`` and ``b`` lose separation.

    Per time-overlapping segment pair, in closed form: the open interval where the horizontal
    distance (sphere: the 3D distance) is below ``separation_m`` is the root interval of a
    quadratic; for the cylinder it is intersected with the open interval where |dz| is below V.
    Returns a sorted list of merged (start_s, end_s) tuples (a touching-only contact at one
    instant gives start == end). O(s_a * s_b).
    """
    model = as_separation_model(separation)
    t0a, t1a, p0a, va = a.segments()
    t0b, t1b, p0b, vb = b.segments()
    ia, ib = np.meshgrid(np.arange(t0a.shape[0]), np.arange(t0b.shape[0]), indexing="ij")
    ia, ib = ia.ravel(), ib.ravel()
    lo, span, r, dv = _relative_motion(t0a[ia], t1a[ia], p0a[ia], va[ia],
                                       t0b[ib], t1b[ib], p0b[ib], vb[ib])
    dims = 3 if model.kind == "sphere" else 2
    H = model.separation_m
    qa = np.einsum("ij,ij->i", dv[:, :dims], dv[:, :dims])
    qb = np.einsum("ij,ij->i", r[:, :dims], dv[:, :dims])
    qc = np.einsum("ij,ij->i", r[:, :dims], r[:, :dims]) - H * H
    with np.errstate(divide="ignore", invalid="ignore"):
        disc = qb * qb - qa * qc
        root = np.sqrt(np.maximum(disc, 0.0))
        hl = np.where(qa > 0, (-qb - root) / qa, np.where(qc < 0, -np.inf, np.inf))
        hh = np.where(qa > 0, (-qb + root) / qa, np.where(qc < 0, np.inf, -np.inf))
    h_ok = np.where(qa > 0, disc > 0, qc < 0)
    if model.kind == "cylinder":
        wl, wh, v_ok = _vertical_window(r[:, 2], dv[:, 2], span, model.vertical_separation_m)
    else:
        wl, wh, v_ok = np.zeros_like(span), span, span >= 0.0
    start = np.maximum(hl, wl)
    end = np.minimum(hh, wh)
    ok = h_ok & v_ok & (start < end) | (h_ok & v_ok & (span == 0.0) & (hl < 0) & (hh > 0))
    iv = sorted(zip((lo + start)[ok].tolist(), (lo + np.maximum(end, start))[ok].tolist()))
    merged = []
    for s0, s1 in iv:
        if merged and s0 <= merged[-1][1]:
            merged[-1] = (merged[-1][0], max(merged[-1][1], s1))
        else:
            merged.append((s0, s1))
    return merged


@dataclass(frozen=True)
class SegmentSet:
    """The segments of a set of trajectories, flattened into arrays.

    Attributes:
        traj: (s,) int64 index of the trajectory each segment belongs to.
        t0_s, t1_s: (s,) segment start and end times [s].
        p0_m: (s, 3) position at t0 [m]; v_mps: (s, 3) velocity [m/s].
        n_trajectories: number of trajectories (some may have no segment left after windowing).
    """

    traj: np.ndarray
    t0_s: np.ndarray
    t1_s: np.ndarray
    p0_m: np.ndarray
    v_mps: np.ndarray
    n_trajectories: int

    @classmethod
    def from_trajectories(cls, trajectories: Sequence[Trajectory]) -> "SegmentSet":
        """Flatten ``trajectories``; O(total segments)."""
        n = len(trajectories)
        if n == 0:
            return cls(np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 3)),
                       np.zeros((0, 3)), 0)
        segs = [tr.segments() for tr in trajectories]
        counts = np.fromiter((s[0].shape[0] for s in segs), dtype=np.int64, count=n)
        return cls(np.repeat(np.arange(n, dtype=np.int64), counts),
                   np.concatenate([s[0] for s in segs]),
                   np.concatenate([s[1] for s in segs]),
                   np.concatenate([s[2] for s in segs]),
                   np.concatenate([s[3] for s in segs]), n)

    def __len__(self) -> int:
        return int(self.traj.shape[0])

    def take(self, mask_or_index) -> "SegmentSet":
        """The segments a boolean mask (one entry per segment) or an index array selects."""
        m = mask_or_index
        if isinstance(m, np.ndarray) and m.dtype == np.bool_ and m.shape == self.traj.shape:
            # np.compress: the rows x[m] selects, the same arrays, several times faster than
            # boolean indexing on the (s, 3) arrays
            return SegmentSet(*(np.compress(m, x, axis=0) for x in (
                self.traj, self.t0_s, self.t1_s, self.p0_m, self.v_mps)), self.n_trajectories)
        return SegmentSet(self.traj[m], self.t0_s[m], self.t1_s[m], self.p0_m[m],
                          self.v_mps[m], self.n_trajectories)

    def window(self, t_lo_s: float, t_hi_s: float) -> "SegmentSet":
        """Only the segments airborne at some time in [t_lo_s, t_hi_s]."""
        keep = (self.t1_s >= t_lo_s) & (self.t0_s <= t_hi_s)
        return self if bool(keep.all()) else self.take(keep)


def _as_segment_set(trajs) -> SegmentSet:
    if isinstance(trajs, SegmentSet):
        return trajs
    return SegmentSet.from_trajectories(list(trajs))


def min_separation_m(a: Trajectory, b: Trajectory) -> float:
    """Exact minimum distance [m] between two trajectories over their common airborne time.

    Returns +inf if they are never airborne at the same time. O(s_a * s_b), vectorised.
    """
    t0a, t1a, p0a, va = a.segments()
    t0b, t1b, p0b, vb = b.segments()
    ia, ib = np.meshgrid(np.arange(t0a.shape[0]), np.arange(t0b.shape[0]), indexing="ij")
    ia = ia.ravel()
    ib = ib.ravel()
    d = segment_pair_min_distance(t0a[ia], t1a[ia], p0a[ia], va[ia],
                                  t0b[ib], t1b[ib], p0b[ib], vb[ib])
    return float(d.min()) if d.size else float("inf")


@dataclass
class _Pieces:
    seg: np.ndarray      # (q,) index into the SegmentSet
    t0: np.ndarray
    t1: np.ndarray
    p0: np.ndarray       # (q, 3)
    xlo: np.ndarray      # inflated bounding box in x, y
    xhi: np.ndarray
    ylo: np.ndarray
    yhi: np.ndarray
    zlo: np.ndarray      # z range inflated by half the vertical reach
    zhi: np.ndarray


def _cut_pieces(s: SegmentSet, cell_m: float, bucket_s: float, half_m: float,
                half_z_m: float) -> _Pieces:
    """Cut each segment into pieces at most cell_m long and bucket_s in duration (compiled
    with ``_COMPILED_KEYS``, unless a count is not finite or huge: the same pieces)."""
    if _COMPILED_KEYS and len(s):
        pieces = _cut_pieces_compiled(s, cell_m, bucket_s, half_m, half_z_m)
        if pieces is not None:
            return pieces
    return _cut_pieces_numpy(s, cell_m, bucket_s, half_m, half_z_m)


def _cut_pieces_compiled(s: SegmentSet, cell_m: float, bucket_s: float, half_m: float,
                         half_z_m: float) -> "_Pieces | None":
    """:func:`_cut_pieces_numpy` by ``broad_phase_kernel``; None where a segment's count of
    pieces is not finite or beyond the kernel's bound (the numpy path decides those)."""
    from . import broad_phase_kernel as kernel

    f8 = np.float64
    t0, t1, v = _c(s.t0_s, f8), _c(s.t1_s, f8), _c(s.v_mps, f8)
    n, ok = kernel.piece_counts(t0, t1, v, float(cell_m), float(bucket_s))
    if not ok:
        return None
    seg, pt0, pt1, p0, box = kernel.cut_pieces(t0, t1, _c(s.p0_m, f8), v, n, float(half_m),
                                               float(half_z_m))
    return _Pieces(seg, pt0, pt1, p0, *box)


def _cut_pieces_numpy(s: SegmentSet, cell_m: float, bucket_s: float, half_m: float,
                      half_z_m: float) -> _Pieces:
    """:func:`_cut_pieces` in numpy."""
    dur = s.t1_s - s.t0_s
    length = np.linalg.norm(s.v_mps, axis=1) * dur
    n = np.maximum(np.maximum(np.ceil(length / cell_m), np.ceil(dur / bucket_s)), 1).astype(np.int64)
    seg = np.repeat(np.arange(len(s), dtype=np.int64), n)
    starts = np.cumsum(n) - n
    k = np.arange(seg.shape[0], dtype=np.int64) - starts[seg]
    nk = n[seg]
    base_t0 = s.t0_s[seg]
    step = dur[seg] / nk
    t0 = base_t0 + k * step
    t1 = np.where(k + 1 == nk, s.t1_s[seg], base_t0 + (k + 1) * step)
    v = s.v_mps[seg]
    p0 = s.p0_m[seg] + v * (t0 - base_t0)[:, None]
    x1 = p0[:, 0] + v[:, 0] * (t1 - t0)
    y1 = p0[:, 1] + v[:, 1] * (t1 - t0)
    z1 = p0[:, 2] + v[:, 2] * (t1 - t0)
    return _Pieces(seg, t0, t1, p0,
                   np.minimum(p0[:, 0], x1) - half_m, np.maximum(p0[:, 0], x1) + half_m,
                   np.minimum(p0[:, 1], y1) - half_m, np.maximum(p0[:, 1], y1) + half_m,
                   np.minimum(p0[:, 2], z1) - half_z_m, np.maximum(p0[:, 2], z1) + half_z_m)


def _labels(name: str, values, n: int):
    """``values`` as an (n,) int64 array (or None), refused unless it labels every trajectory."""
    if values is None:
        return None
    arr = np.asarray(values, dtype=np.int64)
    if arr.shape != (n,):
        raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    return arr


def _check_groups(groups_a, single: bool, n_a: int, groups_b=None, n_b: int = 0):
    """(groups_a, groups_b) as int64 arrays (or None). Within one set groups_a alone; across two
    sets both or neither (a pair is skipped when its two labels are equal)."""
    if single and groups_b is not None:
        raise ValueError("groups_b is only supported with trajs_b")
    if not single and (groups_a is None) != (groups_b is None):
        raise ValueError("with trajs_b, give both groups_a and groups_b or neither")
    return _labels("groups_a", groups_a, n_a), _labels("groups_b", groups_b, n_b)


def _check_ranks(rank_a, rank_b, single: bool, n_a: int, n_b: int, shifts: bool):
    """(rank_a, rank_b) as int64 arrays (or None): both or neither, only across two sets and
    not with shifts_a."""
    if rank_a is None and rank_b is None:
        return None, None
    if single or shifts or (rank_a is None) != (rank_b is None):
        raise ValueError("rank_a and rank_b go together, only with trajs_b and without shifts_a")
    return _labels("rank_a", rank_a, n_a), _labels("rank_b", rank_b, n_b)


def _check_shifts(shifts_a, single: bool, n_a: int):
    """(first, shift_s, slack per trajectory of a) from ``shifts_a``, or (None, None, None)."""
    if shifts_a is None:
        return None, None, None
    if single:
        raise ValueError("shifts_a is only supported with trajs_b")
    first = np.asarray(shifts_a[0], dtype=np.int64)
    shift = np.asarray(shifts_a[1], dtype=np.float64)
    if first.shape != (n_a + 1,) or first[0] != 0 or \
            np.any(np.diff(first) < 0) or first[-1] != shift.shape[0]:
        raise ValueError(f"shifts_a: first must be ({n_a + 1},) non-decreasing "
                         f"offsets from 0 to len(shift_s)={shift.shape[0]}")
    if shift.size and not (np.all(np.isfinite(shift)) and shift.min() >= 0.0):
        raise ValueError("shifts_a: shift_s must be finite and >= 0")
    slack_traj = np.zeros(n_a)
    nonempty = np.flatnonzero(np.diff(first) > 0)
    if nonempty.size:
        slack_traj[nonempty] = np.maximum.reduceat(shift, first[nonempty])
    return first, shift, slack_traj


def _common_window(sa: SegmentSet, sb: SegmentSet, slack_traj):
    """The segments of a and b inside their common time window (a's stretched by its slack)."""
    if slack_traj is None:
        sa = sa.window(sb.t0_s.min(), sb.t1_s.max())
    else:
        keep = (sa.t1_s + slack_traj[sa.traj] >= sb.t0_s.min()) & (sa.t0_s <= sb.t1_s.max())
        sa = sa if bool(keep.all()) else sa.take(keep)
    if len(sa) == 0:
        return sa, sb
    hi_a = sa.t1_s.max() if slack_traj is None else (sa.t1_s + slack_traj[sa.traj]).max()
    return sa, sb.window(sa.t0_s.min(), hi_a)


def _grid_size(sa: SegmentSet, separation_m: float, cell_m, bucket_s) -> tuple[float, float]:
    """The broad phase's cell size [m] and time bucket [s] (defaults in the module's header)."""
    cell = float(cell_m) if cell_m is not None else DEFAULT_CELL_SEPARATIONS * float(separation_m)
    if cell < separation_m:
        raise ValueError(f"cell_m must be >= separation_m={separation_m}, got {cell}")
    if bucket_s is None:
        if _COMPILED_KEYS:
            from . import broad_phase_kernel as kernel

            speeds = kernel.speeds(_c(sa.v_mps, np.float64))
        else:
            speeds = np.linalg.norm(sa.v_mps, axis=1)
        med = float(np.median(speeds))
        bucket = DEFAULT_BUCKET_CELLS * cell / med if med > 0.0 else 60.0
    else:
        bucket = float(bucket_s)
    if not (np.isfinite(bucket) and bucket > 0.0):
        raise ValueError(f"bucket_s must be positive and finite, got {bucket_s!r}")
    return cell, bucket


@dataclass
class _Grid:
    """The space-time grid both sets are keyed on: origin, cell and bucket, extent in cells."""
    x0: float
    y0: float
    tt0: float
    cell: float
    bucket: float
    nx: int = 0
    ny: int = 0
    nt: int = 0
    z_bounds: np.ndarray | None = None  # z cell boundaries [m] (z in the keys), or None
    nz: int = 1

    def ranges(self, p: _Pieces, t1):
        """Per piece, the first and last cell index along x, y and t its box touches (and,
        with ``z_bounds``, along z: see :func:`_z_ranges`); compiled with ``_COMPILED_KEYS``."""
        if _COMPILED_KEYS and p.t0.shape[0]:
            from . import broad_phase_kernel as kernel

            f8 = np.float64
            use_z = self.z_bounds is not None
            r = kernel.cell_ranges(
                tuple(_c(x, f8) for x in (p.xlo, p.xhi, p.ylo, p.yhi, p.zlo, p.zhi)),
                _c(p.t0, f8), _c(t1, f8),
                (float(self.x0), float(self.y0), float(self.tt0), float(self.cell),
                 float(self.bucket)),
                _c(self.z_bounds, f8) if use_z else np.zeros(1), use_z)
            return r if use_z else r[:6]
        r = (np.floor((p.xlo - self.x0) / self.cell).astype(np.int64),
             np.floor((p.xhi - self.x0) / self.cell).astype(np.int64),
             np.floor((p.ylo - self.y0) / self.cell).astype(np.int64),
             np.floor((p.yhi - self.y0) / self.cell).astype(np.int64),
             np.floor((p.t0 - self.tt0) / self.bucket).astype(np.int64),
             np.floor((t1 - self.tt0) / self.bucket).astype(np.int64))
        return r if self.z_bounds is None else r + _z_ranges(self.z_bounds, p)


def _z_ranges(bounds: np.ndarray, p: _Pieces):
    """The z cells of each piece's z box [zlo, zhi), by comparison with the boundaries (no
    division, so no rounding): first = #{b <= zlo} - 1, last = #{b < zhi} - 1. Two boxes that
    overlap strictly (zlo_j < zhi_i, the z filter's test) then share the cell max(first_i,
    first_j): {b <= zlo_j} is a subset of {b < zhi_i}. Boxes that only touch (two flight levels
    exactly V apart) share no cell when the touching point is a boundary."""
    return (np.searchsorted(bounds, p.zlo, side="right").astype(np.int64) - 1,
            np.searchsorted(bounds, p.zhi, side="left").astype(np.int64) - 1)


def _make_grid(pa: _Pieces, pb: _Pieces, pa_t1_sweep, cell: float, bucket: float,
               z_cell_m: float | None = None, z_offset_m: float = 0.0) -> _Grid:
    """A grid origin shared by both sets so their keys agree; refuses extents whose cell
    indices would not fit int64 (the float -> int conversion would wrap). ``z_cell_m``: z cells
    of that height with boundaries at z_offset_m + k z_cell_m (None: z is not in the keys)."""
    grid = _Grid(min(pa.xlo.min(), pb.xlo.min()), min(pa.ylo.min(), pb.ylo.min()),
                 min(pa.t0.min(), pb.t0.min()), cell, bucket)
    if z_cell_m is not None:
        zmin = float(min(pa.zlo.min(), pb.zlo.min()))
        z0 = z_offset_m + z_cell_m * np.floor((zmin - z_offset_m) / z_cell_m)
        if z0 > zmin:  # rounding: the first boundary must lie at or below every box
            z0 -= z_cell_m
        span = float(max(pa.zhi.max(), pb.zhi.max())) - z0
        n = int(np.ceil(span / z_cell_m)) + 2 if np.isfinite(span) else 0
        if 0 < n <= 1 << 16:  # else (an absurd extent) z stays out of the keys
            grid.z_bounds = z0 + float(z_cell_m) * np.arange(n, dtype=np.float64)
    # up to int64 indices, a too-large combined cell code is widened in _sorted_keys
    for axis, span_cells in (
            ("x", (max(pa.xhi.max(), pb.xhi.max()) - grid.x0) / cell),
            ("y", (max(pa.yhi.max(), pb.yhi.max()) - grid.y0) / cell),
            ("t", (max(pa_t1_sweep.max(), pb.t1.max()) - grid.tt0) / bucket)):
        if not span_cells < float(1 << 62):
            raise ValueError(f"conflicting_pairs: the extent along {axis} spans {span_cells:.3g} "
                             f"broad-phase cells (cell_m={cell} m, bucket_s={bucket} s), more than "
                             f"int64 cell indices hold; use a larger cell_m or bucket_s")
    return grid


def _keyed_grid(pa: _Pieces, pb: _Pieces, pa_t1_sweep, cell: float, bucket: float, z_cell_m,
                half_z: float, single: bool):
    """The grid both sets are keyed on and every piece's cell index ranges on it (a's pieces
    swept to ``pa_t1_sweep``): (grid with its extent in cells, ra, rb)."""
    # z boundaries at -V/2 + k z_cell_m: flight levels at multiples of V = z_cell_m touch (their
    # boxes, inflated by V/2) exactly on a boundary and share no cell
    grid = _make_grid(pa, pb, pa_t1_sweep, cell, bucket, z_cell_m, -half_z)
    ra = grid.ranges(pa, pa_t1_sweep)
    rb = ra if single else grid.ranges(pb, pb.t1)
    grid.nx = int(max(ra[1].max(), rb[1].max())) + 1
    grid.ny = int(max(ra[3].max(), rb[3].max())) + 1
    grid.nt = int(max(ra[5].max(), rb[5].max())) + 1
    if grid.z_bounds is not None:
        grid.nz = int(max(ra[7].max(), rb[7].max())) + 1
        if ((grid.nt * grid.ny * grid.nx * grid.nz) * 2).bit_length() > 63:
            # the widened (coordinate) sort has no z: leave z out of the keys
            grid.z_bounds, grid.nz = None, 1
            ra, rb = ra[:6], rb[:6]
    return grid, ra, rb


def _expand_keys(r, side: int, offset: int, grid: _Grid, widened: bool, packed: bool,
                 item_bits: int):
    """Every (cell, side, item) key of the pieces with index ranges ``r``: the (t, y, x)
    coordinates when widened, else one int64 code (with the item packed in when it fits)."""
    ix0, ix1, iy0, iy1, it0, it1 = r[:6]
    cx = ix1 - ix0 + 1
    cy = iy1 - iy0 + 1
    cnt = cx * cy * (it1 - it0 + 1)
    z = len(r) > 6
    if z:
        cz = r[7] - r[6] + 1
        cnt = cnt * cz
    item = np.repeat(np.arange(cnt.shape[0], dtype=np.int64), cnt)
    local = np.arange(item.shape[0], dtype=np.int64) - np.repeat(np.cumsum(cnt) - cnt, cnt)
    if z:
        local, iz = np.divmod(local, cz[item])
        iz += r[6][item]
    cxi = cx[item]
    rest, ix = np.divmod(local, cxi)
    ix += ix0[item]
    cyi = cy[item]
    it, iy = np.divmod(rest, cyi)
    iy += iy0[item]
    it += it0[item]
    item += offset
    if widened:
        return (it, iy, ix), item
    code = (it * grid.ny + iy) * grid.nx + ix
    if z:
        code *= grid.nz
        code += iz
    code = code * 2 + side
    if packed:
        # one int64 holds (cell, side, item): a plain sort beats an argsort several-fold
        code <<= item_bits
        code |= item
        return code, None
    return code, item


@dataclass
class _SortedKeys:
    """The broad phase's sorted keys: per entry its item (piece id, b's offset by len(a)), key
    (cell * 2 + side), dense cell key and cell coordinates (kt, ky, kx)."""
    items: np.ndarray
    keys: np.ndarray
    cell_key: np.ndarray
    kt: np.ndarray
    ky: np.ndarray
    kx: np.ndarray
    kz: np.ndarray | None = None  # with z in the keys


def _sorted_keys(ra, rb, single: bool, na: int, n_items: int, grid: _Grid,
                 clock: list) -> _SortedKeys:
    """Sort every piece's cell keys so that the pieces sharing a cell lie together (a's before
    b's within a cell). Appends the time when the keys are made to ``clock`` (for ``stats``)."""
    item_bits = max(int(n_items).bit_length(), 1)
    # Python ints: the code of the last cell must fit int64 before any int64 arithmetic.
    max_code = (grid.nt * grid.ny * grid.nx * grid.nz) * 2
    packed = max_code.bit_length() + item_bits <= 63
    # Beyond int64 (e.g. 1e9 m and 1e12 s of extent) the single cell code would wrap around and
    # pieces of different cells would share a key or pieces of one cell be split, silently
    # missing conflicts; then cells are sorted by their (t, y, x) coordinates instead.
    widened = max_code.bit_length() > 63
    if _COMPILED_KEYS and packed:
        codes = _packed_codes(((ra, 0, 0),) if single else ((ra, 0, 0), (rb, 1, na)), grid,
                              item_bits)
        clock.append(time.perf_counter())
        codes.sort()
        return _cell_coordinates_packed(codes, item_bits, grid)
    ka, ia = _expand_keys(ra, 0, 0, grid, widened, packed, item_bits)
    if single:
        codes, items = ka, ia
    else:
        kb, ib = _expand_keys(rb, 1, na, grid, widened, packed, item_bits)
        if widened:
            codes = tuple(np.concatenate((u, w)) for u, w in zip(ka, kb))
            items = np.concatenate((ia, ib))
        else:
            codes = np.concatenate((ka, kb))
            items = None if packed else np.concatenate((ia, ib))
    clock.append(time.perf_counter())
    if widened:
        it_, iy_, ix_ = codes
        side_ = (items >= na).astype(np.int64) if not single else np.zeros_like(items)
        order = np.lexsort((items, side_, ix_, iy_, it_))
        kt, ky, kx = it_[order], iy_[order], ix_[order]
        items = items[order]
        new_cell = np.ones(kt.shape[0], dtype=bool)
        new_cell[1:] = (kt[1:] != kt[:-1]) | (ky[1:] != ky[:-1]) | (kx[1:] != kx[:-1])
        cell_key = np.cumsum(new_cell) - 1          # dense cell ranks fit int64 always
        keys = cell_key * 2 + side_[order]
    else:
        if packed:
            codes.sort()
            items = codes & ((1 << item_bits) - 1)
            keys = codes >> item_bits
        else:
            order = np.argsort(codes)
            keys = codes[order]
            items = items[order]
        return _cell_coordinates(items, keys, grid)
    return _SortedKeys(items, keys, cell_key, kt, ky, kx)


_NO_I8 = np.zeros(0, dtype=np.int64)


def _kernel_ranges(r) -> tuple:
    """Cell index ranges as the kernels take them: eight int64 arrays (the z pair empty when z
    is not in the keys)."""
    r = tuple(_c(x, np.int64) for x in r)
    return r if len(r) == 8 else r + (_NO_I8, _NO_I8)


def _packed_codes(parts, grid: _Grid, item_bits: int, idx=None) -> np.ndarray:
    """The packed codes :func:`_expand_keys` makes (not widened, packed) for each (ranges,
    side, item offset) of ``parts``, concatenated in that order, by ``broad_phase_kernel``.
    ``idx``: only these pieces of the one part, each with item idx[e] (a stage's pieces)."""
    from . import broad_phase_kernel as kernel

    use_z = grid.z_bounds is not None
    use_idx = idx is not None
    ix = _c(idx, np.int64) if use_idx else _NO_I8
    parts = [(_kernel_ranges(r), int(side), int(off)) for r, side, off in parts]
    counts = [kernel.key_count(r, ix, use_idx, use_z) for r, _, _ in parts]
    out = np.empty(int(sum(counts)), dtype=np.int64)
    pos = 0
    shape = (int(grid.ny), int(grid.nx), int(grid.nz))
    for r, side, off in parts:
        pos = kernel.pack_keys(r, ix, use_idx, use_z, side, off, shape, int(item_bits), out,
                               pos)
    return out


def _cell_coordinates_packed(codes: np.ndarray, item_bits: int, grid: _Grid) -> _SortedKeys:
    """:func:`_cell_coordinates` of sorted packed codes (item in the low ``item_bits``),
    compiled with ``_COMPILED_KEYS``."""
    if not _COMPILED_KEYS:
        return _cell_coordinates(codes & ((1 << item_bits) - 1), codes >> item_bits, grid)
    from . import broad_phase_kernel as kernel

    use_z = grid.z_bounds is not None
    items, keys, cell_key, kt, ky, kx, kz = kernel.cell_coordinates(
        _c(codes, np.int64), int(item_bits), (int(grid.ny), int(grid.nx), int(grid.nz)), use_z)
    return _SortedKeys(items, keys, cell_key, kt, ky, kx, kz if use_z else None)


def _cell_coordinates(items: np.ndarray, keys: np.ndarray, grid: _Grid) -> _SortedKeys:
    """The sorted keys with each entry's cell coordinates (for the canonical-cell test), from
    int64 keys (cell * 2 + side) on ``grid``."""
    cell_key = keys >> 1
    kz = None
    if grid.z_bounds is not None:
        rest, kz = np.divmod(cell_key, grid.nz)
        rest, kx = np.divmod(rest, grid.nx)
    else:
        rest, kx = np.divmod(cell_key, grid.nx)
    kt, ky = np.divmod(rest, grid.ny)
    return _SortedKeys(items, keys, cell_key, kt, ky, kx, kz)


def _cell_mates(sk: _SortedKeys, single: bool, run_label=None):
    """Per sorted entry that has partners in its cell: (its position, the first partner's
    position, the number of partners): within one set the entries after it in its cell, across
    two sets (only for a's entries) the b entries of its cell.

    ``run_label`` (within one set): each sorted entry's label (its trajectory, or its group),
    non-decreasing within every cell; the partners then start after the entry's run of equal
    labels in its cell, so pairs of one trajectory (group), which the box filter would drop
    first, are never made (the pairs made are the ones the filter would keep, in its order).
    Compiled with ``_COMPILED_KEYS``: the same arrays."""
    if _COMPILED_KEYS:
        from . import broad_phase_kernel as kernel

        i8 = np.int64
        return kernel.cell_mates(_c(sk.keys, i8), _c(sk.cell_key, i8), bool(single),
                                 _NO_I8 if run_label is None else _c(run_label, i8),
                                 run_label is not None)
    m = sk.keys.shape[0]
    bounds = np.flatnonzero(np.diff(sk.cell_key)) + 1
    g_start = np.concatenate(([0], bounds))
    g_end = np.concatenate((bounds, [m]))
    g_of = np.repeat(np.arange(g_start.shape[0]), g_end - g_start)
    if single:
        # Item at sorted position p pairs with positions p+1 .. end of its cell (with
        # run_label: from the end of its run of equal labels in its cell).
        left_pos = np.arange(m, dtype=np.int64)
        if run_label is None:
            right_first = left_pos + 1
        else:
            brk = np.flatnonzero((sk.cell_key[1:] != sk.cell_key[:-1])
                                 | (run_label[1:] != run_label[:-1])) + 1
            r_end = np.concatenate((brk, [m]))
            right_first = np.repeat(r_end, np.diff(np.concatenate(([0], r_end))))
        n_right = g_end[g_of] - right_first
    else:
        # Within a cell the A items (side 0) sort before the B items (side 1).
        is_b = (sk.keys & 1).astype(bool)
        nb_in_g = np.add.reduceat(is_b.astype(np.int64), g_start)
        first_b = g_end - nb_in_g
        left_pos = np.flatnonzero(~is_b)
        right_first = first_b[g_of[left_pos]]
        n_right = nb_in_g[g_of[left_pos]]
    keep = n_right > 0
    return left_pos[keep], right_first[keep], n_right[keep]


@dataclass
class _PieceTable:
    """Per-piece arrays of both sets by global item id (P_*: b's offset by len(a)) and the
    box arrays in sorted-key order (S_*), which the narrow phase's filters gather from."""
    P_t0: np.ndarray
    P_t1: np.ndarray
    P_p0: np.ndarray
    P_v: np.ndarray
    P_traj: np.ndarray
    S_t0: np.ndarray
    S_t1: np.ndarray
    S_xlo: np.ndarray
    S_xhi: np.ndarray
    S_ylo: np.ndarray
    S_yhi: np.ndarray
    S_zlo: np.ndarray
    S_zhi: np.ndarray
    S_traj: np.ndarray | None
    S_group: np.ndarray | None = None  # two sets with groups: each sorted entry's group label
    S_iz0: np.ndarray | None = None    # z in the keys: each sorted entry's first z cell


@dataclass
class _PieceArrays:
    """Per-piece values of both sets by global item id (b's offset by len(a)): what the piece
    table gathers in sorted-key order. ``t1_sweep``: a's pieces held until their t1 plus their
    trajectory's largest shift; ``group``: two sets with groups, each piece's group label;
    ``iz0``: z in the keys, each piece's first z cell."""
    t0: np.ndarray
    t1: np.ndarray
    t1_sweep: np.ndarray
    p0: np.ndarray
    v: np.ndarray
    traj: np.ndarray
    xlo: np.ndarray
    xhi: np.ndarray
    ylo: np.ndarray
    yhi: np.ndarray
    zlo: np.ndarray
    zhi: np.ndarray
    group: np.ndarray | None = None
    iz0: np.ndarray | None = None
    # the box columns as (q, 8) rows for the compiled gather, made at its first use
    rows: np.ndarray | None = field(default=None, compare=False, repr=False)


def _piece_arrays(pa: _Pieces, pb: _Pieces, sa: SegmentSet, sb: SegmentSet, single: bool,
                  pa_t1_sweep, slack: bool, groups_ab=None, iz0=None) -> _PieceArrays:
    # np.take(v, seg, axis=0): the rows v[seg] gathers, a few times faster on (s, 3) arrays
    if single:
        return _PieceArrays(pa.t0, pa.t1, pa_t1_sweep if slack else pa.t1, pa.p0,
                            np.take(sa.v_mps, pa.seg, axis=0), sa.traj[pa.seg], pa.xlo,
                            pa.xhi, pa.ylo, pa.yhi, pa.zlo, pa.zhi, None, iz0)
    t1 = np.concatenate((pa.t1, pb.t1))
    group = None
    if groups_ab is not None:
        ga, gb = groups_ab
        group = np.concatenate((ga[sa.traj[pa.seg]], gb[sb.traj[pb.seg]]))
    return _PieceArrays(np.concatenate((pa.t0, pb.t0)), t1,
                        np.concatenate((pa_t1_sweep, pb.t1)) if slack else t1,
                        np.concatenate((pa.p0, pb.p0)),
                        np.concatenate((np.take(sa.v_mps, pa.seg, axis=0),
                                        np.take(sb.v_mps, pb.seg, axis=0))),
                        np.concatenate((sa.traj[pa.seg], sb.traj[pb.seg])),
                        np.concatenate((pa.xlo, pb.xlo)), np.concatenate((pa.xhi, pb.xhi)),
                        np.concatenate((pa.ylo, pb.ylo)), np.concatenate((pa.yhi, pb.yhi)),
                        np.concatenate((pa.zlo, pb.zlo)), np.concatenate((pa.zhi, pb.zhi)),
                        group, iz0)


def _gather_table(P: _PieceArrays, items: np.ndarray, single: bool) -> _PieceTable:
    """The piece table of the sorted entries ``items`` (the same per-piece values in
    sorted-key order); the box columns gathered in one compiled pass with ``_COMPILED_KEYS``."""
    if _COMPILED_KEYS:
        from . import broad_phase_kernel as kernel

        f8 = np.float64
        if P.rows is None:   # built once, gathered from by every stage of any_conflict
            P.rows = kernel.box_rows(tuple(_c(x, f8) for x in (
                P.t0, P.t1_sweep, P.xlo, P.xhi, P.ylo, P.yhi, P.zlo, P.zhi)))
        labels = (P.traj if single else None, P.group, P.iz0)
        box, lab = kernel.gather_boxes(
            _c(items, np.int64), P.rows,
            tuple(_NO_I8 if x is None else _c(x, np.int64) for x in labels),
            tuple(x is not None for x in labels))
        return _PieceTable(P.t0, P.t1, P.p0, P.v, P.traj, *box,
                           *(None if x is None else y for x, y in zip(labels, lab)))
    return _PieceTable(P.t0, P.t1, P.p0, P.v, P.traj,
                       P.t0[items], P.t1_sweep[items], P.xlo[items], P.xhi[items], P.ylo[items],
                       P.yhi[items], P.zlo[items], P.zhi[items], P.traj[items] if single else None,
                       None if P.group is None else P.group[items],
                       None if P.iz0 is None else P.iz0[items])


def _piece_table(pa: _Pieces, pb: _Pieces, sa: SegmentSet, sb: SegmentSet, single: bool,
                 pa_t1_sweep, slack: bool, items: np.ndarray, groups_ab=None,
                 iz0=None) -> _PieceTable:
    return _gather_table(_piece_arrays(pa, pb, sa, sb, single, pa_t1_sweep, slack, groups_ab,
                                       iz0), items, single)


def _box_filter(l, r, pt: _PieceTable, sk: _SortedKeys, grid: _Grid, single: bool, groups,
                runs_skipped: bool = False):
    """The sorted-entry pairs (l, r) that may come near: different trajectories (and groups),
    overlapping inflated boxes in z, t, x and y, kept only in their canonical cell (the one
    holding the low corner of the boxes' intersection), so a pair sharing several cells is
    checked once. Returns the pairs' item ids (i, j). ``runs_skipped``: within one set, the
    pairs already are of different trajectories and groups (:func:`_cell_mates`' run_label)."""
    if single and not runs_skipped:
        ti = pt.S_traj[l]
        tj = pt.S_traj[r]
        ok = ti != tj
        if groups is not None:
            ok &= groups[ti] != groups[tj]
        l, r = l[ok], r[ok]
    elif pt.S_group is not None:
        ok = pt.S_group[l] != pt.S_group[r]
        l, r = l[ok], r[ok]
    # Filters in order of selectivity, compressing after each so later gathers are cheap
    # (on arrays in sorted-key order, so the gathers walk memory nearly sequentially).
    # z is not in the keys: first drop pieces whose z ranges, inflated by half the vertical
    # reach, do not overlap with positive length (a loss needs |dz| strictly below the
    # reach); at flight levels this removes most pairs sharing a cell
    ok = np.maximum(pt.S_zlo[l], pt.S_zlo[r]) < np.minimum(pt.S_zhi[l], pt.S_zhi[r])
    if sk.kz is not None:  # z in the keys: the canonical z cell is the pair's first common one
        ok &= np.maximum(pt.S_iz0[l], pt.S_iz0[r]) == sk.kz[l]
    l, r = l[ok], r[ok]
    lo = np.maximum(pt.S_t0[l], pt.S_t0[r])
    ok = lo <= np.minimum(pt.S_t1[l], pt.S_t1[r])
    ok &= np.floor((lo - grid.tt0) / grid.bucket).astype(np.int64) == sk.kt[l]
    l, r = l[ok], r[ok]
    lo = np.maximum(pt.S_xlo[l], pt.S_xlo[r])
    ok = lo <= np.minimum(pt.S_xhi[l], pt.S_xhi[r])
    ok &= np.floor((lo - grid.x0) / grid.cell).astype(np.int64) == sk.kx[l]
    l, r = l[ok], r[ok]
    lo = np.maximum(pt.S_ylo[l], pt.S_ylo[r])
    ok = lo <= np.minimum(pt.S_yhi[l], pt.S_yhi[r])
    ok &= np.floor((lo - grid.y0) / grid.cell).astype(np.int64) == sk.ky[l]
    return sk.items[l[ok]], sk.items[r[ok]]


@dataclass
class _BroadPhase:
    """What the broad phase leaves for the narrow phase: the windowed sets, the piece table,
    the sorted keys and grid, and per sorted entry with partners its cell mates (see
    :func:`_cell_mates`); ``clock``: wall times at its steps, for ``stats``."""
    sa: SegmentSet
    sb: SegmentSet
    single: bool
    groups: np.ndarray | None
    pt: _PieceTable
    sk: _SortedKeys
    grid: _Grid
    left_pos: np.ndarray
    right_first: np.ndarray
    n_right: np.ndarray
    runs_skipped: bool
    n_items: int
    clock: list
    segments_a: int = -1   # a's segments taking part, when not all of ``sa`` (a stage)

    def fill_stats(self, stats: dict, n_exact: int) -> None:
        c = self.clock
        stats.update(segments_a=len(self.sa) if self.segments_a < 0 else self.segments_a,
                     segments_b=len(self.sb), pieces=int(self.n_items),
                     keys=int(self.sk.keys.shape[0]), pairs_sharing_cell=int(self.n_right.sum()),
                     exact_checks=n_exact, pieces_s=c[1] - c[0], keys_s=c[2] - c[1],
                     sort_s=c[3] - c[2], pairs_and_exact_s=c[4] - c[3])


def _broad_phase(model: SeparationModel, sa: SegmentSet, sb: SegmentSet, single: bool, groups,
                 groups_b, slack_traj, cell_m, bucket_s, z_cell_m) -> _BroadPhase | None:
    """Pieces, their cell keys, sorted, and the cell mates of every entry (steps 1-4 of the
    module's header); None when the two sets have no common time."""
    separation_m = model.separation_m
    if z_cell_m is None and model.kind == "cylinder" and _CYLINDER_Z_KEYS:
        # The cylinder's vertical reach V as z cells: pieces cruising on levels V apart share no
        # cell, so their pairs are never made (the z filter would drop them all); the same piece
        # pairs reach the exact kernel, so the same pairs and distances to the last bit
        # (see z_cell_m below), for about half the cell-mate pairs at flight levels.
        z_cell_m = model.vertical_reach_m
    if len(sa) == 0 or len(sb) == 0:
        return None
    if not single:
        # Only the common time window can hold a conflict.
        sa, sb = _common_window(sa, sb, slack_traj)
        if len(sa) == 0 or len(sb) == 0:
            return None

    clock = [time.perf_counter()]
    cell, bucket = _grid_size(sa, separation_m, cell_m, bucket_s)
    half = 0.5 * float(separation_m)
    half_z = 0.5 * model.vertical_reach_m
    pa = _cut_pieces(sa, cell, bucket, half, half_z)
    pb = pa if single else _cut_pieces(sb, cell, bucket, half, half_z)
    na = pa.t0.shape[0]
    # a's pieces occupy their boxes until t1 plus their trajectory's largest shift
    pa_t1_sweep = pa.t1 if slack_traj is None else pa.t1 + slack_traj[sa.traj[pa.seg]]
    clock.append(time.perf_counter())
    if z_cell_m is not None and not (np.isfinite(z_cell_m) and z_cell_m > 0.0):
        raise ValueError(f"z_cell_m must be positive and finite, got {z_cell_m!r}")
    grid, ra, rb = _keyed_grid(pa, pb, pa_t1_sweep, cell, bucket, z_cell_m, half_z, single)
    n_items = na + (0 if single else pb.t0.shape[0])
    sk = _sorted_keys(ra, rb, single, na, n_items, grid, clock)
    run_label = None
    if single and _SKIP_OWN_RUNS:
        # Within a cell the entries sort by piece (packed codes, or the widened lexsort), so by
        # trajectory: a trajectory's entries are one run, and so are a group's when the labels
        # do not decrease with the trajectory (the planner's request order). Checked, not
        # assumed: if the labels decrease anywhere within a cell, this call makes every pair
        # and filters it as before.
        s_traj = sa.traj[pa.seg][sk.items]
        lab = s_traj if groups is None else groups[s_traj]
        if bool(np.all((lab[1:] >= lab[:-1]) | (sk.cell_key[1:] != sk.cell_key[:-1]))):
            run_label = lab
    left_pos, right_first, n_right = _cell_mates(sk, single, run_label)
    iz0 = None
    if grid.z_bounds is not None:
        iz0 = ra[6] if single else np.concatenate((ra[6], rb[6]))
    pt = _piece_table(pa, pb, sa, sb, single, pa_t1_sweep, slack_traj is not None, sk.items,
                      None if single or groups is None else (groups, groups_b), iz0)
    clock.append(time.perf_counter())
    return _BroadPhase(sa, sb, single, groups, pt, sk, grid, left_pos, right_first, n_right,
                       run_label is not None, n_items, clock)


def _near_piece_pairs(bp: _BroadPhase, max_pairs: int, open_left=None):
    """The piece pairs (i, j) that may come near (after :func:`_box_filter`), in chunks of
    about ``max_pairs`` cell-mate pairs, in the sorted keys' order (earliest time bucket
    first). ``open_left``: optional callable(start, stop) -> bool mask over the entries
    ``left_pos[start:stop]``, called just before their chunk: the entries left out make no
    pairs (a caller that has already decided them)."""
    csum = np.cumsum(bp.n_right)
    start = 0
    while start < bp.left_pos.shape[0]:
        done = int(csum[start - 1]) if start > 0 else 0
        stop = int(np.searchsorted(csum, done + max_pairs, side="right"))
        stop = max(stop, start + 1)
        lp = bp.left_pos[start:stop]
        nr = bp.n_right[start:stop]
        rf = bp.right_first[start:stop]
        if open_left is not None:
            m = open_left(start, stop)
            lp, nr, rf = lp[m], nr[m], rf[m]
        start = stop
        cnt = int(nr.sum())
        if cnt == 0:
            continue
        lrep = np.repeat(lp, nr)
        rpos = np.repeat(rf, nr) + (np.arange(cnt, dtype=np.int64) - np.repeat(np.cumsum(nr) - nr, nr))
        i, j = _box_filter(lrep, rpos, bp.pt, bp.sk, bp.grid, bp.single, bp.groups,
                           bp.runs_skipped)
        if i.size:
            yield i, j


def _narrow_phase(i, j, pt: _PieceTable, model: SeparationModel, first, shift, ranks=None,
                  skip=None):
    """The exact check of the piece pairs (i, j): (a index, b index, distance) of the pairs
    that lose separation (a index a candidate when shifted), or None; and the exact checks done.
    ``ranks`` (rank_a, rank_b): the kernel takes the piece of the lower-ranked trajectory first
    (its rounding is not symmetric to the last bit), as one call over the union would.
    ``skip``: optional (n_candidates,) bool, with shifts: candidates not to check (already
    decided); the others get the same values, so the same distances to the last bit."""
    separation_m = model.separation_m
    if shift is None:
        u, w = i, j
        if ranks is not None:
            # P_traj holds each set's own trajectory index (i of a, j of b)
            swap = ranks[1][pt.P_traj[j]] < ranks[0][pt.P_traj[i]]
            if swap.any():
                u, w = np.where(swap, j, i), np.where(swap, i, j)
        d = model.segment_measure(pt.P_t0[u], pt.P_t1[u], pt.P_p0[u], pt.P_v[u],
                                  pt.P_t0[w], pt.P_t1[w], pt.P_p0[w], pt.P_v[w])
        lose = d < separation_m
        if not lose.any():
            return None, 0
        return (pt.P_traj[i[lose]], pt.P_traj[j[lose]], d[lose]), 0
    # one exact check per candidate (shift) of a's trajectory
    ta = pt.P_traj[i]
    cnt = first[ta + 1] - first[ta]
    cand = np.repeat(first[ta], cnt) + (np.arange(int(cnt.sum()), dtype=np.int64)
                                        - np.repeat(np.cumsum(cnt) - cnt, cnt))
    if skip is not None:
        # only the candidates still open: the piece pairs repeated per open candidate
        go = ~skip[cand]
        rows = np.repeat(np.arange(i.shape[0], dtype=np.int64), cnt)[go]
        cand = cand[go]
        j_rep = j[rows]
        dt = shift[cand]
        extra = int(j_rep.size) - int(cnt.size)
        t0i = pt.P_t0[i[rows]]
        t0i += dt
        t1i = pt.P_t1[i[rows]]
        t1i += dt
        ir = i[rows]
        d = model.segment_measure(t0i, t1i, pt.P_p0[ir], pt.P_v[ir], pt.P_t0[j_rep],
                                  pt.P_t1[j_rep], pt.P_p0[j_rep], pt.P_v[j_rep])
        lose = d < separation_m
        if not lose.any():
            return None, extra
        return (cand[lose], pt.P_traj[j_rep[lose]], d[lose]), extra
    # gather each piece pair's values once, then repeat them per candidate (the same values as
    # gathering at the repeated indices, for a fraction of the gathers)
    j_rep = np.repeat(j, cnt)
    dt = shift[cand]
    extra = int(j_rep.size) - int(cnt.size)
    t0i = np.repeat(pt.P_t0[i], cnt)
    t0i += dt
    t1i = np.repeat(pt.P_t1[i], cnt)
    t1i += dt
    d = model.segment_measure(t0i, t1i, np.repeat(pt.P_p0[i], cnt, axis=0),
                              np.repeat(pt.P_v[i], cnt, axis=0),
                              np.repeat(pt.P_t0[j], cnt), np.repeat(pt.P_t1[j], cnt),
                              np.repeat(pt.P_p0[j], cnt, axis=0), np.repeat(pt.P_v[j], cnt, axis=0))
    j = j_rep
    lose = d < separation_m
    if not lose.any():
        return None, extra
    return (cand[lose], pt.P_traj[j[lose]], d[lose]), extra


def _unique_min_pairs(out_pairs, out_dist, nbt: int):
    """Unique pairs, sorted lexicographically, each with its minimum distance."""
    pairs = np.concatenate(out_pairs)
    dist = np.concatenate(out_dist)
    code = pairs[:, 0] * nbt + pairs[:, 1]
    order = np.lexsort((dist, code))
    code = code[order]
    first = np.concatenate(([True], code[1:] != code[:-1]))
    return pairs[order][first], dist[order][first]


def _lost_piece_pairs(bp: _BroadPhase, model: SeparationModel, first, shift, ranks, single: bool):
    """Exact check of ``bp``'s piece pairs in chunks (bounded memory): lost pairs, distances per chunk, checks done."""
    out_pairs = []
    out_dist = []
    n_exact = 0
    for i, j in _near_piece_pairs(bp, _MAX_PAIRS_PER_CHUNK):
        n_exact += int(i.size)
        lost, extra = _narrow_phase(i, j, bp.pt, model, first, shift, ranks)
        n_exact += extra
        if lost is None:
            continue
        a_idx, b_idx, d = lost
        if single:
            a_idx, b_idx = np.minimum(a_idx, b_idx), np.maximum(a_idx, b_idx)
        out_pairs.append(np.stack((a_idx, b_idx), axis=1))
        out_dist.append(d)
    return out_pairs, out_dist, n_exact


def conflicting_pairs(trajs_a, trajs_b=None, separation_m: float = DEFAULT_SEPARATION_M,
                      groups_a=None, cell_m: float | None = None, bucket_s: float | None = None,
                      return_distances: bool = False, stats: dict | None = None,
                      shifts_a=None, groups_b=None, rank_a=None, rank_b=None,
                      z_cell_m: float | None = None):
    """Pairs of trajectories that lose separation at some time (exact, continuous time).

    Args:
        trajs_a: sequence of Trajectory (or a SegmentSet).
        trajs_b: a second set, or None to find pairs within ``trajs_a``.
        separation_m: separation minimum [m] (the paper's sphere: a pair conflicts when its exact
            minimum 3D distance is strictly below it), or a :class:`SeparationModel` (sphere or
            cylinder).
        groups_a: optional (n_a,) labels: pairs within one group are skipped (the candidates
            of one request exclude each other anyway). With ``trajs_b``, together with
            ``groups_b`` (n_b,): a pair (i, j) is skipped when groups_a[i] == groups_b[j], before
            any box test (the planner's rolling horizon: a request's old and new candidates).
        cell_m, bucket_s: broad-phase cell size [m] (>= separation) and
            time bucket [s] (defaults: 12 x separation, and the time to fly one cell at the
            median segment speed).
        return_distances: also return each pair's exact minimum distance [m] (for the
            cylinder: the minimum horizontal distance while vertically closer than V).
        stats: optional dict that receives broad-phase counts (segments, pieces, keys, pairs
            sharing a cell that were made, i.e. without a set's own runs, exact checks: fewer
            on the compiled path, see :func:`_pairs_compiled`) and wall times, for benchmarks.
        shifts_a: optional ``(first, shift_s)``, only with ``trajs_b``: trajectory j of a stands
            for the candidates ``first[j] .. first[j+1]-1``, candidate c being trajectory j
            flown ``shift_s[c] >= 0`` seconds later (departure slots). The broad phase then runs
            once per trajectory of a, its pieces' time ranges stretched by the largest shift,
            and the exact check once per candidate of each surviving pair; the pairs returned
            are (candidate, j into b). The same answer as listing every shifted trajectory,
            for a fraction of the broad-phase work.
        rank_a, rank_b: optional (n_a,) and (n_b,) ranks, only with ``trajs_b`` and without
            ``shifts_a``: the exact kernel takes each pair's trajectory of the lower rank as its
            first argument, so a pair's distance is the one, to the last bit, that a call within
            one set ordered by rank computes (the kernel's rounding is not symmetric); one call
            then stands for the two orientations.
        z_cell_m: optional height [m] of z cells in the broad phase's keys (None: the
            cylinder's V, the sphere's z only filtered, not keyed). The same pairs and distances
            either way (the exact kernel sees the same piece pairs); with flight levels V apart
            and ``z_cell_m`` = V, pieces
            cruising on different levels no longer share a cell (the rolling horizon's dense
            graphs: see ``uam_planner.conflict_graph.CandidatePairCache``).
    Returns:
        (k, 2) int64 array of trajectory index pairs (i into a, j into b; i < j within one set),
        sorted lexicographically; with ``return_distances`` also (k,) float64 distances.
    Complexity: O(N log N) in the number of piece keys plus the exact kernel over the pairs that
    share a space-time cell (see the module docstring).
    """
    model = as_separation_model(separation_m)
    single = trajs_b is None
    sa = _as_segment_set(trajs_a)
    sb = sa if single else _as_segment_set(trajs_b)
    groups, groups_b = _check_groups(groups_a, single, sa.n_trajectories, groups_b,
                                     sb.n_trajectories)
    first, shift, slack_traj = _check_shifts(shifts_a, single, sa.n_trajectories)
    ranks = _check_ranks(rank_a, rank_b, single, sa.n_trajectories, sb.n_trajectories,
                         shifts_a is not None)
    ranks = None if ranks[0] is None else ranks
    empty = np.zeros((0, 2), dtype=np.int64)
    nothing = (empty, np.zeros(0)) if return_distances else empty
    bp = _broad_phase(model, sa, sb, single, groups, groups_b, slack_traj, cell_m, bucket_s,
                      z_cell_m)
    if bp is None:
        return nothing
    if _COMPILED_PAIRS and not return_distances and shift is None and ranks is None:
        return _pairs_compiled(bp, model, stats)
    out_pairs, out_dist, n_exact = _lost_piece_pairs(bp, model, first, shift, ranks, single)
    bp.clock.append(time.perf_counter())
    if stats is not None:
        bp.fill_stats(stats, n_exact)
    if not out_pairs:
        return nothing
    nbt = int(max(bp.sa.n_trajectories, bp.sb.n_trajectories,
                  0 if shift is None else shift.shape[0])) + 1
    pairs, dist = _unique_min_pairs(out_pairs, out_dist, nbt)
    return (pairs, dist) if return_distances else pairs


def any_conflict(trajs_a, trajs_b, separation_m: float = DEFAULT_SEPARATION_M,
                 cell_m: float | None = None, bucket_s: float | None = None,
                 shifts_a=None, z_cell_m: float | None = None,
                 stats: dict | None = None) -> np.ndarray:
    """Per trajectory of ``trajs_a`` (or per candidate, with ``shifts_a``): does it lose
    separation with at least one trajectory of ``trajs_b``? The check that decides.

    The same answer, to the last bit, as marking the first column of
    ``conflicting_pairs(trajs_a, trajs_b, ...)`` with the same arguments, for less work: no
    distances and no pair list are kept, and a trajectory (candidate) stops being checked at its
    first loss. Two things make that pay where most of a is blocked (a busy epoch discards
    98 % of its candidates, most of them near their departure):

    - stages in time: a's segments in windows of their start time (``_DECIDE_STAGES_S``),
      each only for the trajectories with an open candidate (the later segments of the
      blocked ones are never cut into pieces or keyed);
    - within a stage, a compiled kernel (``separation_kernel``; :func:`warm_up` at start-up)
      walks the cell mates in the sorted keys' order, a candidate until its first loss, a
      trajectory until its last candidate is blocked (``_COMPILED_DECIDE`` off: in numpy,
      the entries of trajectories decided in one chunk make no pairs in the next).

    b's pieces are cut, keyed and sorted once per call; a stage keys only a's open pieces and
    takes from b the entries of the cells those touch (work per stage follows a's open pieces,
    not the size of b). The piece pairs that pass the box filter do not depend on the grid's
    origin (each pair of overlapping boxes once, in its canonical cell), so the exact kernel
    sees the pair list's piece pairs in the same orientation (``test_any_conflict.py``).

    Args: as :func:`conflicting_pairs` (two sets only; no groups or ranks: a decision does not
        depend on which pair is found first); ``stats`` gets the counts summed over the stages
        (``exact_checks``: the exact measures taken, one per piece pair and open candidate).
    Returns: (n_a,) bool, or (n_candidates,) bool with ``shifts_a``.
    Complexity: the broad phase over b and a's undecided segments; the box filter and the
    exact kernel only over their piece pairs.
    """
    model = as_separation_model(separation_m)
    sa = _as_segment_set(trajs_a)
    sb = _as_segment_set(trajs_b)
    first, shift, slack_traj = _check_shifts(shifts_a, False, sa.n_trajectories)
    n_out = sa.n_trajectories if shift is None else int(shift.shape[0])
    blocked = np.zeros(n_out, dtype=bool)
    if len(sa) == 0 or len(sb) == 0:
        return blocked
    sa, sb = _common_window(sa, sb, slack_traj)
    if len(sa) == 0 or len(sb) == 0:
        return blocked
    if z_cell_m is None and model.kind == "cylinder" and _CYLINDER_Z_KEYS:
        z_cell_m = model.vertical_reach_m   # as _broad_phase: the same pieces and pairs
    if z_cell_m is not None and not (np.isfinite(z_cell_m) and z_cell_m > 0.0):
        raise ValueError(f"z_cell_m must be positive and finite, got {z_cell_m!r}")
    # the grid a single call over the windowed sets chooses, for every stage
    cell, bucket = _grid_size(sa, model.separation_m, cell_m, bucket_s)
    keyed = _KeyedSets.make(model, sa, sb, slack_traj, cell, bucket, z_cell_m)
    # per trajectory of a: how many of its candidates are still open (1 each without shifts)
    template_of = None if shift is None else \
        np.repeat(np.arange(sa.n_trajectories, dtype=np.int64), np.diff(first))
    open_count = np.ones(sa.n_trajectories, dtype=np.int64) if shift is None \
        else np.diff(first)
    total: dict = {}
    t_first = float(sa.t0_s.min())
    lo = -np.inf
    for hi in _DECIDE_STAGES_S + (np.inf,):
        hi = t_first + hi
        in_stage = (sa.t0_s >= lo) & (sa.t0_s < hi) & (open_count[sa.traj] > 0)
        lo = hi
        if not in_stage.any():
            continue
        st = {} if stats is not None else None
        if keyed is None:   # extents beyond one int64 code: the general broad phase per stage
            bp = _broad_phase(model, sa.take(in_stage), sb, False, None, None, slack_traj,
                              cell, bucket, z_cell_m)
        else:
            bp = keyed.stage(in_stage)
        if bp is not None:
            open_count = _decide_stage(bp, model, first, shift, template_of, blocked,
                                       open_count, st)
        for k, v in (st or {}).items():
            total[k] = total.get(k, 0) + v
    if stats is not None:
        stats.update(total)
    return blocked


@dataclass
class _KeyedSets:
    """Both sets of :func:`any_conflict` cut into pieces and keyed on one grid once, b's keys
    sorted once; :meth:`stage` builds one stage's broad phase from a's pieces of the chosen
    segments and the b entries of the cells they touch."""
    sa: SegmentSet
    sb: SegmentSet
    pa: _Pieces
    grid: _Grid
    ra: tuple
    item_bits: int
    b_codes: np.ndarray      # b's packed (cell, side, item) codes, sorted
    b_cell: np.ndarray       # their cells
    arrays: _PieceArrays
    n_items: int

    @classmethod
    def make(cls, model, sa, sb, slack_traj, cell, bucket, z_cell_m) -> "_KeyedSets | None":
        """None when one packed int64 code cannot hold a cell and an item (huge extents)."""
        half = 0.5 * float(model.separation_m)
        half_z = 0.5 * model.vertical_reach_m
        pa = _cut_pieces(sa, cell, bucket, half, half_z)
        pb = _cut_pieces(sb, cell, bucket, half, half_z)
        pa_t1_sweep = pa.t1 if slack_traj is None else pa.t1 + slack_traj[sa.traj[pa.seg]]
        grid, ra, rb = _keyed_grid(pa, pb, pa_t1_sweep, cell, bucket, z_cell_m, half_z, False)
        na = pa.t0.shape[0]
        n_items = na + pb.t0.shape[0]
        item_bits = max(int(n_items).bit_length(), 1)
        if ((grid.nt * grid.ny * grid.nx * grid.nz) * 2).bit_length() + item_bits > 63:
            return None
        if _COMPILED_KEYS:
            b_codes = _packed_codes(((rb, 1, na),), grid, item_bits)
        else:
            b_codes, _ = _expand_keys(rb, 1, na, grid, False, True, item_bits)
        b_codes.sort()
        iz0 = None if grid.z_bounds is None else np.concatenate((ra[6], rb[6]))
        arrays = _piece_arrays(pa, pb, sa, sb, False, pa_t1_sweep, slack_traj is not None,
                               None, iz0)
        return cls(sa, sb, pa, grid, ra, item_bits, b_codes, b_codes >> (item_bits + 1),
                   arrays, n_items)

    def stage(self, seg_mask: np.ndarray) -> "_BroadPhase | None":
        """The broad phase of a's pieces of the segments ``seg_mask`` against b."""
        clock = [time.perf_counter()]
        idx = np.flatnonzero(seg_mask[self.pa.seg])
        clock.append(time.perf_counter())
        if _COMPILED_KEYS:
            sk = self._merged_compiled(idx, clock)
        else:
            sk = self._merged_numpy(idx, clock)
        left_pos, right_first, n_right = _cell_mates(sk, False)
        pt = _gather_table(self.arrays, sk.items, False)
        clock.append(time.perf_counter())
        return _BroadPhase(self.sa, self.sb, False, None, pt, sk, self.grid, left_pos,
                           right_first, n_right, False, self.n_items, clock,
                           int(np.count_nonzero(seg_mask)))

    def _merged_compiled(self, idx: np.ndarray, clock: list) -> _SortedKeys:
        """:meth:`_merged_numpy` by ``broad_phase_kernel``: a's codes packed with their global
        ids (idx ascends, so the sorted order is the same), sorted, then merged with b's codes
        of the cells they touch in one pass."""
        from . import broad_phase_kernel as kernel

        ra = tuple(self.ra)
        codes = _packed_codes(((ra, 0, 0),), self.grid, self.item_bits, idx)
        codes.sort()
        clock.append(time.perf_counter())
        merged = kernel.merge_stage(codes, self.b_codes, self.b_cell, int(self.item_bits) + 1)
        return _cell_coordinates_packed(merged, self.item_bits, self.grid)

    def _merged_numpy(self, idx: np.ndarray, clock: list) -> _SortedKeys:
        """The sorted keys of a's pieces ``idx`` and b's entries of the cells they touch."""
        # a's keys with their position in idx packed in, sorted; then their global ids
        codes, _ = _expand_keys(tuple(r[idx] for r in self.ra), 0, 0, self.grid, False, True,
                                self.item_bits)
        codes.sort()
        mask = (1 << self.item_bits) - 1
        a_keys = codes >> self.item_bits
        a_codes = (a_keys << self.item_bits) | idx[codes & mask]
        cells = a_keys >> 1
        cells = cells[np.concatenate(([True], cells[1:] != cells[:-1]))]
        lo = np.searchsorted(self.b_cell, cells, side="left")
        n = np.searchsorted(self.b_cell, cells, side="right") - lo
        pos = np.repeat(lo, n) + (np.arange(int(n.sum()), dtype=np.int64)
                                  - np.repeat(np.cumsum(n) - n, n))
        clock.append(time.perf_counter())
        # a's entries sort before b's within a cell (side 0 < 1); two sorted runs: a merge
        merged = np.concatenate((a_codes, self.b_codes[pos]))
        merged.sort(kind="stable")
        return _cell_coordinates(merged & mask, merged >> self.item_bits, self.grid)


def _decide_stage(bp: _BroadPhase, model, first, shift, template_of, blocked, open_count,
                  stats):
    """One stage of :func:`any_conflict`: mark in ``blocked`` the candidates that lose
    separation among the piece pairs of ``bp`` (a's segments of this stage against b);
    returns the updated open count per trajectory of a. Compiled (:func:`_decide_compiled`)
    or, with ``_COMPILED_DECIDE`` off, in numpy: the same decisions to the last bit.
    ``stats["exact_checks"]``: the exact measures taken (one per piece pair and open
    candidate); the compiled path stops at a candidate's first loss, so it counts fewer."""
    if _COMPILED_DECIDE:
        return _decide_compiled(bp, model, first, shift, blocked, open_count, stats)
    left_traj = bp.pt.P_traj[bp.sk.items[bp.left_pos]]
    n_exact = 0
    for i, j in _near_piece_pairs(bp, _DECIDE_PAIRS_PER_CHUNK,
                                  lambda s, e: open_count[left_traj[s:e]] > 0):
        keep = open_count[bp.pt.P_traj[i]] > 0
        i, j = i[keep], j[keep]
        n_exact += int(i.size)
        if i.size == 0:
            continue
        lost, extra = _narrow_phase(i, j, bp.pt, model, first, shift, None, blocked)
        n_exact += extra
        if lost is None:
            continue
        blocked[lost[0]] = True
        open_count = (~blocked).astype(np.int64) if template_of is None else \
            np.bincount(template_of, weights=~blocked, minlength=open_count.shape[0])
    bp.clock.append(time.perf_counter())
    if stats is not None:
        bp.fill_stats(stats, n_exact)
    return open_count



def _c(a, dtype):
    """``a`` as a C-contiguous writable array of ``dtype``: one array type per kernel argument,
    so one compiled version of each kernel. The array itself when it already is one (what
    np.require returns then, without its few microseconds per call)."""
    if isinstance(a, np.ndarray) and a.dtype == dtype and a.flags.c_contiguous \
            and a.flags.writeable:
        return a
    return np.require(a, dtype, ("C", "W"))


def _kernel_tables(bp: _BroadPhase):
    """The broad phase's arrays as the kernels take them: (box, cells, grid, pieces, use_z) (see
    ``separation_kernel.decide_pairs``); kz and iz0 a dummy unless z is in the keys."""
    f8, i8 = np.float64, np.int64
    pt, sk, grid = bp.pt, bp.sk, bp.grid
    use_z = sk.kz is not None
    none_i8 = np.zeros(1, dtype=i8)
    box = tuple(_c(x, f8) for x in (pt.S_t0, pt.S_t1, pt.S_xlo, pt.S_xhi, pt.S_ylo, pt.S_yhi,
                                     pt.S_zlo, pt.S_zhi))
    cells = tuple(_c(x, i8) for x in (sk.kt, sk.kx, sk.ky, sk.kz if use_z else none_i8,
                                       pt.S_iz0 if use_z else none_i8))
    return (box, cells,
            (float(grid.tt0), float(grid.bucket), float(grid.x0), float(grid.y0),
             float(grid.cell)),
            (_c(pt.P_t0, f8), _c(pt.P_t1, f8), _c(pt.P_p0, f8), _c(pt.P_v, f8)), use_z)


def _decide_compiled(bp: _BroadPhase, model, first, shift, blocked, open_count, stats):
    """:func:`_decide_stage` by the compiled kernel (``separation_kernel.decide_pairs``): the
    box filter and the exact measure per cell-mate pair and open candidate, nothing
    materialised; ``blocked`` and the returned int64 open counts updated in place."""
    from . import separation_kernel

    if bp.single:
        raise ValueError("the compiled decide path compares two sets, not one")
    f8, i8 = np.float64, np.int64
    pt = bp.pt
    open_count = _c(open_count, i8)
    box, cells, grid, pieces, use_z = _kernel_tables(bp)
    none_i8 = np.zeros(1, dtype=i8)
    n_exact = separation_kernel.decide_pairs(
        _c(bp.left_pos, i8), _c(bp.right_first, i8), _c(bp.n_right, i8), _c(bp.sk.items, i8),
        _c(pt.P_traj, i8), box, cells, use_z,
        none_i8 if pt.S_group is None else _c(pt.S_group, i8), pt.S_group is not None,
        grid, pieces, none_i8 if shift is None else _c(first, i8),
        np.zeros(1, dtype=f8) if shift is None else _c(shift, f8), shift is not None,
        model.kind == "cylinder", float(model.separation_m), float(model.vertical_separation_m),
        float(_WINDOW_TOLERANCE_S), blocked, open_count)
    bp.clock.append(time.perf_counter())
    if stats is not None:
        bp.fill_stats(stats, int(n_exact))
    return open_count


def _pair_drop(bp: _BroadPhase):
    """(drop, group) for ``separation_kernel.lost_pairs``: the pairs :func:`_box_filter` drops
    before its box tests (within one set unless ``runs_skipped``: one trajectory's, and one
    group's by trajectory; across two sets: one group's by sorted entry)."""
    if bp.single and not bp.runs_skipped:
        return (1, None) if bp.groups is None else (2, bp.groups)
    if not bp.single and bp.pt.S_group is not None:
        return 3, bp.pt.S_group
    return 0, None


def _pairs_compiled(bp: _BroadPhase, model, stats) -> np.ndarray:
    """:func:`conflicting_pairs` without shifts, ranks or distances, by the compiled kernel
    (``separation_kernel.lost_pairs``): the same (k, 2) pairs, sorted and unique, as
    :func:`_lost_piece_pairs` then :func:`_unique_min_pairs`, nothing materialised per pair.
    ``stats["exact_checks"]``: the measures taken; a piece pair whose trajectory pair the
    kernel has just recorded is not measured again, so it counts fewer than the numpy path
    (which counts every piece pair past the box filter)."""
    from . import separation_kernel

    i8 = np.int64
    box, cells, grid, pieces, use_z = _kernel_tables(bp)
    drop, group = _pair_drop(bp)
    nbt = int(max(bp.sa.n_trajectories, bp.sb.n_trajectories)) + 1
    codes, n_exact = separation_kernel.lost_pairs(
        _c(bp.left_pos, i8), _c(bp.right_first, i8), _c(bp.n_right, i8), _c(bp.sk.items, i8),
        _c(bp.pt.P_traj, i8), box, cells, use_z,
        np.zeros(1, dtype=i8) if group is None else _c(group, i8), drop, grid, pieces,
        bp.single, model.kind == "cylinder", float(model.separation_m),
        float(model.vertical_separation_m), float(_WINDOW_TOLERANCE_S), nbt)
    bp.clock.append(time.perf_counter())
    if stats is not None:
        bp.fill_stats(stats, int(n_exact))
    codes = np.unique(codes)
    return np.stack((codes // nbt, codes % nbt), axis=1)


_WARM = False


#: glibc's mallopt parameters (malloc.h): M_TRIM_THRESHOLD, M_MMAP_THRESHOLD
_M_TRIM_THRESHOLD, _M_MMAP_THRESHOLD = -1, -3


def keep_freed_memory() -> bool:
    """Tell glibc's allocator to keep freed memory for reuse (trim threshold 1 GiB, mmap
    threshold 32 MiB, its maximum) instead of returning it to the system after each large free.

    Why: an epoch makes and frees numpy temporaries of 0.1-30 MB many times; returned to the
    system, each is faulted in again (zeroed pages) at its next allocation. glibc adapts its
    thresholds to a process's large frees, but loading numba's LLVM left them where the
    temporaries went back every time: on the layered city at 3,000 requests/h, 290,000-650,000
    page faults a run instead of 140,000, and CPU per epoch p99 104 ms instead of 83-90 ms
    (BENCHMARKS.md). The cost is memory a process has used staying with it (its peak).
    False where the C library is not glibc (nothing changed)."""
    import ctypes
    import ctypes.util

    try:
        libc = ctypes.CDLL(ctypes.util.find_library("c") or "libc.so.6")
        mallopt = libc.mallopt
    except (OSError, AttributeError):
        return False
    return bool(mallopt(_M_TRIM_THRESHOLD, 1 << 30)) and bool(mallopt(_M_MMAP_THRESHOLD, 32 << 20))


def warm_up() -> None:
    """Ready this process for planning epochs, at start-up, so that no epoch pays for it:
    compile the kernels of the check that decides (:func:`any_conflict` on two crossing flights
    in both models, with and without departure shifts) and of :func:`conflicting_pairs` (the
    two flights as one set), which run the broad phase's kernels (``broad_phase_kernel``) on
    the way (a cold compile takes seconds, numba keeps the result in
    ``__pycache__`` and later processes only load it), and :func:`keep_freed_memory`. Once per
    process; nothing to do with the numpy paths."""
    global _WARM
    if _WARM or not (_COMPILED_DECIDE or _COMPILED_PAIRS or _COMPILED_KEYS):
        return
    keep_freed_memory()
    a = [Trajectory(np.array([0.0, 100.0]), np.array([[-500.0, 0.0, 60.0], [500.0, 0.0, 60.0]]))]
    b = [Trajectory(np.array([0.0, 100.0]), np.array([[0.0, -500.0, 60.0], [0.0, 500.0, 60.0]]))]
    for model in (SeparationModel("sphere"), SeparationModel("cylinder")):
        any_conflict(a, b, model)
        any_conflict(a, b, model, shifts_a=(np.array([0, 2]), np.array([0.0, 5.0])))
        conflicting_pairs(a + b, None, model, groups_a=[0, 1])
    _WARM = True
