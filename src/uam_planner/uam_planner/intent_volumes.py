"""Intents that never intersect: the planner's check of the 4D volumes a USS publishes.

A plan becomes one F3548 volume per piece of at most ``max_piece_s`` (``uam_planner.f3548``:
the rectangle around the piece widened by r_h, its band +-r_v, its time window). Separation
implies nothing about those volumes: two flights in trail 150 m apart keep a 100 m separation,
yet the trailing piece's rectangle reaches the leading one's while their windows share an
instant, and a peer that checks volumes at F3548's 1 cm sees two of our intents in conflict.
So in F3548 mode (``PlanningConfig.intent_volume_piece_s`` > 0) the planner checks the volumes
themselves, beside the separation: a candidate whose volumes meet a flight's in force is
discarded, and two candidates whose volumes meet conflict (:func:`restrict_graph`,
:func:`intent_pairs`).

The volumes are cut here for many trajectories at once (:func:`volume_table`), with the same
arithmetic as :func:`uam_planner.f3548.trajectory_volumes` (a test holds them equal), and
compared by :func:`intent_pairs`:

- broad phase: two flights' volumes can meet only where the flights come within the volumes'
  reach (``VolumeSpec.bounds_m``: D_h horizontally and D_v vertically at one instant), so the
  exact separation check with that cylinder (``separation.conflicting_pairs``) finds the pairs of
  flights to compare; of each pair, only volumes whose windows can overlap are compared;
- exact test: windows overlap (closed: touching counts), bands within the tolerance, and the two
  rectangles within the tolerance: 0 when no edge normal separates them (separating axes),
  else the least of the 32 corner-to-edge distances (exact for convex polygons).

The tolerance is F3548's 1 cm plus ``MARGIN_M`` (1 mm): a published vertex is a latitude and
longitude, and the round trip through WGS84 moves it by well under a millimetre; volumes that
this check keeps apart are apart for a peer too. Flights exactly at the separation publish
volumes 2 cm apart (r = half the separation less 1 cm), which the check keeps apart, so
adjacent flight levels stay usable.

Cost: one separation check, O(volumes) of the flights it pairs, O(overlapping windows) exact
tests. No ROS, no wall clock.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Sequence

import numpy as np

#: F3548's intersection precision [m] (IntersectionMinimumPrecisionCm, 1 cm)
PRECISION_M = 0.01
#: added to F3548's precision: the round trip of a vertex through WGS84 moves it by far less
MARGIN_M = 0.001


@dataclass(frozen=True)
class VolumeTable:
    """The volumes of several trajectories, flat.

    Attributes:
        owner: (m,) int64 index of the trajectory each volume belongs to.
        segment: (m,) int64 index of its segment among all the trajectories' segments (in order).
        corners: (m, 4, 2) rectangle corners [m], in the order of ``f3548._rectangle``.
        lower, upper: (m,) band [m]; t0, t1: (m,) window [s].
        n_owners: number of trajectories.
        box_lo, box_hi: (m, 2) the rectangles' bounding boxes [m] (the cheap first test).
    """

    owner: np.ndarray
    segment: np.ndarray
    corners: np.ndarray
    lower: np.ndarray
    upper: np.ndarray
    t0: np.ndarray
    t1: np.ndarray
    n_owners: int
    box_lo: np.ndarray = None
    box_hi: np.ndarray = None

    def __post_init__(self):
        if self.box_lo is None:
            object.__setattr__(self, "box_lo", self.corners.min(axis=1))
            object.__setattr__(self, "box_hi", self.corners.max(axis=1))

    def __len__(self) -> int:
        return int(self.owner.shape[0])


def _segments(trajectories) -> tuple:
    """(owner, t0, t1, p0, p1) of every segment of ``trajectories``."""
    owners, t0, t1, p0, p1 = [], [], [], [], []
    for i, tr in enumerate(trajectories):
        ts, ps = tr.times_s, tr.points_m
        k = ts.shape[0] - 1
        if k <= 0:
            continue
        owners.append(np.full(k, i, dtype=np.int64))
        t0.append(ts[:-1])
        t1.append(ts[1:])
        p0.append(ps[:-1])
        p1.append(ps[1:])
    if not owners:
        return (np.zeros(0, np.int64), np.zeros(0), np.zeros(0), np.zeros((0, 3)), np.zeros((0, 3)))
    return (np.concatenate(owners), np.concatenate(t0), np.concatenate(t1),
            np.concatenate(p0), np.concatenate(p1))


def _rectangles(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    """(m, 4, 2) rectangles around pieces a-b (m, 2) widened and lengthened by r: a square of
    side 2 r where a piece does not move horizontally (``f3548._rectangle``, vectorised)."""
    d = b - a
    length = np.hypot(d[:, 0], d[:, 1])
    still = length < 1e-9
    u = np.where(still[:, None], np.array([1.0, 0.0]), d / np.where(still, 1.0, length)[:, None])
    n = np.stack([-u[:, 1], u[:, 0]], axis=1)
    lo, hi = a - u * r, b + u * r
    return np.stack([lo - n * r, hi - n * r, hi + n * r, lo + n * r], axis=1)


def volume_table(trajectories: Sequence, spec, from_s: float = -math.inf) -> VolumeTable:
    """The volumes of ``trajectories`` under ``spec`` (a ``uam_planner.f3548.VolumeSpec``): each
    segment cut into ``ceil(duration / max_piece_s)`` equal pieces; with ``from_s`` only the
    pieces that end after it (as ``trajectory_volumes``). O(volumes)."""
    return _cut(_segments(trajectories), len(trajectories), spec, from_s)


def _cut(segs: tuple, n_owners: int, spec, from_s: float = -math.inf, only=None) -> VolumeTable:
    """The VolumeTable of the segments ``segs`` (``_segments``), of those where ``only`` (a mask
    over them) if given; each volume keeps its segment's index."""
    owner, t0, t1, p0, p1 = segs
    n = np.maximum(1, np.ceil((t1 - t0) / spec.max_piece_s - 1e-9)).astype(np.int64)
    if only is not None:
        n = np.where(only, n, 0)
    idx = np.repeat(np.arange(owner.shape[0]), n)
    start = np.cumsum(n) - n
    k = np.arange(idx.shape[0], dtype=np.int64) - start[idx]
    nn, kk = n[idx].astype(np.float64), k.astype(np.float64)
    last = k == n[idx] - 1
    s0, s1 = t0[idx], t1[idx]
    ta = s0 + (s1 - s0) * kk / nn
    tb = np.where(last, s1, s0 + (s1 - s0) * (kk + 1) / nn)
    q0, q1 = p0[idx], p1[idx]
    a = q0 + (q1 - q0) * (kk / nn)[:, None]
    b = np.where(last[:, None], q1, q0 + (q1 - q0) * ((kk + 1) / nn)[:, None])
    keep = tb > from_s
    a, b, ta, tb = a[keep], b[keep], ta[keep], tb[keep]
    r_v = spec.vertical_buffer_m
    return VolumeTable(owner[idx][keep], idx[keep].astype(np.int64),
                       _rectangles(a[:, :2], b[:, :2], spec.horizontal_buffer_m),
                       np.minimum(a[:, 2], b[:, 2]) - r_v, np.maximum(a[:, 2], b[:, 2]) + r_v,
                       ta, tb, n_owners)


def _point_segment(p: np.ndarray, e0: np.ndarray, e1: np.ndarray) -> np.ndarray:
    """Distances from points p to segments e0-e1 (..., 2)."""
    d = e1 - e0
    dd = np.einsum("...k,...k->...", d, d)
    t = np.clip(np.einsum("...k,...k->...", p - e0, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    q = e0 + t[..., None] * d
    return np.hypot(p[..., 0] - q[..., 0], p[..., 1] - q[..., 1])


def _separating_gap(ca: np.ndarray, cb: np.ndarray) -> np.ndarray:
    """The largest gap [m] between rectangles ``ca`` and ``cb`` (p, 4, 2) along their four edge
    normals: <= 0 when they overlap (separating axes), else a lower bound of their distance."""
    axes = np.concatenate([ca[:, 1:3] - ca[:, 0:2], cb[:, 1:3] - cb[:, 0:2]], axis=1)   # (p, 4, 2)
    norm = np.hypot(axes[..., 0], axes[..., 1])
    axes = axes / np.where(norm > 0, norm, 1.0)[..., None]
    pa = np.einsum("pck,pak->pac", ca, axes)     # (p, axes, corners)
    pb = np.einsum("pck,pak->pac", cb, axes)
    return np.maximum(pb.min(axis=2) - pa.max(axis=2), pa.min(axis=2) - pb.max(axis=2)).max(axis=1)


def rectangle_distance(ca: np.ndarray, cb: np.ndarray) -> np.ndarray:
    """Exact distances [m] between rectangles ``ca`` and ``cb`` (p, 4, 2), pair by pair: 0 when
    they overlap (no edge normal separates them), else the least corner-to-edge distance."""
    out = np.zeros(ca.shape[0])
    sep = _separating_gap(ca, cb) > 0
    if sep.any():
        a, b = ca[sep], cb[sep]
        d1 = _point_segment(a[:, :, None, :], b[:, None, :, :], np.roll(b, -1, axis=1)[:, None, :, :])
        d2 = _point_segment(b[:, :, None, :], a[:, None, :, :], np.roll(a, -1, axis=1)[:, None, :, :])
        out[sep] = np.minimum(d1.min(axis=(1, 2)), d2.min(axis=(1, 2)))
    return out


def _meet(ca: np.ndarray, cb: np.ndarray, tol: float) -> np.ndarray:
    """(p,) bool: rectangles within ``tol`` of each other (bounding boxes already within it):
    the separating axes, then the exact distance only where the gap is in (0, tol]."""
    gap = _separating_gap(ca, cb)
    out = gap <= 0
    near = np.flatnonzero((gap > 0) & (gap <= tol))
    if near.shape[0]:
        out[near] = rectangle_distance(ca[near], cb[near]) <= tol
    return out


def _velocity(segs: tuple, k=slice(None)) -> np.ndarray:
    """(m, 3) velocity [m/s] of the segments ``k`` of ``segs`` (``_segments``); 0 where a segment
    takes no time."""
    dur = segs[2][k] - segs[1][k]
    moving = dur > 0
    return np.where(moving[:, None], (segs[4][k] - segs[3][k]) / np.where(moving, dur, 1.0)[:, None], 0.0)


def _reach_model(segs: Sequence[tuple], spec, tol: float):
    """A cylinder that two flights come closer than whenever a volume of each meets (windows
    sharing t, rectangles and bands within ``tol``): at t each aircraft lies on its piece, and
    every point of a piece's rectangle is within sqrt((L + r_h)^2 + r_h^2) of every point of the
    piece (L <= v_h dt), every height of its band within r_v + v_z dt; so the aircraft are within
    D_h + tol horizontally and D_v + tol vertically at t (``VolumeSpec.bounds_m`` at the largest
    speeds of the segments ``segs``)."""
    from .separation import SeparationModel
    v = np.concatenate([_velocity(x) for x in segs])
    v_h = float(np.hypot(v[:, 0], v[:, 1]).max(initial=0.0))
    v_z = float(np.abs(v[:, 2]).max(initial=0.0))
    d_h, d_v = spec.bounds_m(v_h, v_z)
    return SeparationModel("cylinder", d_h + tol + 1e-3, d_v + tol + 1e-3)


def _expand(first: np.ndarray, count: np.ndarray) -> tuple:
    """(row, value) of the runs ``first[r] .. first[r] + count[r] - 1``, concatenated."""
    count = np.maximum(count, 0)
    row = np.repeat(np.arange(count.shape[0]), count)
    return row, np.repeat(first, count) + (np.arange(row.shape[0]) - np.repeat(np.cumsum(count) - count, count))


def _within_reach(sa: tuple, sb: tuple, si: np.ndarray, sj: np.ndarray, reach) -> tuple:
    """(lo, hi) [s] per segment pair (si of sa, sj of sb): the times both fly within which they
    are closer than ``reach`` (a cylinder: horizontally and vertically at once), from the roots
    of the relative motion (linear on both segments), widened by a millisecond; lo > hi where
    never. Two volumes of the pair can meet only at such a time (:func:`_reach_model`)."""
    def motion(segs, k):
        t0, t1, p0, v = segs[1][k], segs[2][k], segs[3][k], _velocity(segs, k)
        return t0, t1, p0 - v * t0[:, None], v        # position = c + v t
    a0, a1, ca, va = motion(sa, si)
    b0, b1, cb, vb = motion(sb, sj)
    c, w = ca - cb, va - vb
    lo, hi = np.maximum(a0, b0), np.minimum(a1, b1)
    big = np.inf
    # horizontally: |c + w t|^2 < R^2, a quadratic in t
    qa = w[:, 0] ** 2 + w[:, 1] ** 2
    qb = 2.0 * (c[:, 0] * w[:, 0] + c[:, 1] * w[:, 1])
    qc = c[:, 0] ** 2 + c[:, 1] ** 2 - float(reach.separation_m) ** 2
    moving = qa > 1e-12
    disc = qb * qb - 4.0 * qa * qc
    root = np.sqrt(np.maximum(disc, 0.0))
    h_lo = np.where(moving, (-qb - root) / np.where(moving, 2.0 * qa, 1.0), np.where(qc < 0, -big, big))
    h_hi = np.where(moving, (-qb + root) / np.where(moving, 2.0 * qa, 1.0), np.where(qc < 0, big, -big))
    never = moving & (disc < 0)
    h_lo, h_hi = np.where(never, big, h_lo), np.where(never, -big, h_hi)
    # vertically: |c_z + w_z t| < V
    vz, cz, r = w[:, 2], c[:, 2], float(reach.vertical_separation_m)
    climbing = np.abs(vz) > 1e-12
    safe = np.where(climbing, vz, 1.0)
    e1, e2 = (-r - cz) / safe, (r - cz) / safe
    v_lo = np.where(climbing, np.minimum(e1, e2), np.where(np.abs(cz) < r, -big, big))
    v_hi = np.where(climbing, np.maximum(e1, e2), np.where(np.abs(cz) < r, big, -big))
    eps = 1e-3
    return np.maximum(lo, np.maximum(h_lo, v_lo)) - eps, np.minimum(hi, np.minimum(h_hi, v_hi)) + eps


def _aligned_pairs(a: VolumeTable, b: VolumeTable, seg_pairs: np.ndarray, sa: tuple, sb: tuple,
                   piece_s: float, reach) -> np.ndarray:
    """(p, 2) (volume of a, volume of b) pairs of the segment pairs ``seg_pairs`` whose windows
    may overlap at a time the two segments are within ``reach`` (:func:`_within_reach`). A
    segment's volumes split its time span evenly (``_cut``), so the volumes of segment i
    meeting that time, and for each the volumes of segment j its window meets, are index ranges
    found by arithmetic, each widened by one on both sides against rounding (the window test
    decides)."""
    def layout(t: VolumeTable, segs: tuple):
        t0, t1 = segs[1], segs[2]
        n = np.maximum(1, np.ceil((t1 - t0) / piece_s - 1e-9)).astype(np.int64)
        first = np.searchsorted(t.segment, np.arange(t0.shape[0] + 1))
        kept = first[1:] - first[:-1]
        return t0, t1, n, first[:-1], n - kept      # the k of each segment's first kept volume

    def k_range(t0, t1, n, lo_s, hi_s):
        """Volume indices k of segments (t0, t1, n) whose windows may meet [lo_s, hi_s]."""
        dur = np.where(t1 > t0, t1 - t0, 1.0)
        return (np.floor((lo_s - t0) / dur * n).astype(np.int64) - 1,
                np.floor((hi_s - t0) / dur * n).astype(np.int64) + 1)

    ta0, ta1, na, fa, ka0 = layout(a, sa)
    tb0, tb1, nb, fb, kb0 = layout(b, sb)
    si, sj = seg_pairs[:, 0], seg_pairs[:, 1]
    near_lo, near_hi = _within_reach(sa, sb, si, sj, reach)
    lo, hi = k_range(ta0[si], ta1[si], na[si], near_lo, near_hi)
    lo, hi = np.maximum(lo, ka0[si]), np.minimum(hi, na[si] - 1)
    row, k = _expand(lo, hi - lo + 1)
    ia = fa[si[row]] + (k - ka0[si[row]])                    # the volumes of i, by table index
    j = sj[row]
    lo, hi = k_range(tb0[j], tb1[j], nb[j], a.t0[ia], a.t1[ia])
    lo, hi = np.maximum(lo, kb0[j]), np.minimum(hi, nb[j] - 1)
    row2, kj = _expand(lo, hi - lo + 1)
    return np.stack([ia[row2], fb[j[row2]] + (kj - kb0[j[row2]])], axis=1)


def _segment_set(segs: tuple, from_s: float = -math.inf):
    """The SegmentSet whose 'trajectories' are the segments ``segs`` (``_segments``) themselves,
    those ending after ``from_s`` (each keeps its index)."""
    from .separation import SegmentSet
    owner, t0, t1, p0, _p1 = segs
    keep = t1 > from_s
    v = _velocity(segs)
    return SegmentSet(np.flatnonzero(keep).astype(np.int64), t0[keep], t1[keep], p0[keep], v[keep],
                      int(owner.shape[0]))


def intent_pairs(trajs_a: Sequence, trajs_b: Sequence | None, spec, from_s_b: float = -math.inf,
                 groups=None, known=None, precision_m: float = PRECISION_M,
                 margin_m: float = MARGIN_M) -> np.ndarray:
    """(p, 2) pairs (i of ``trajs_a``, j of ``trajs_b``) whose published volumes meet (``b``'s from
    ``from_s_b`` on), or with ``trajs_b`` None pairs i < j within ``trajs_a`` of different
    ``groups``. Only segments that come within the volumes' reach (:func:`_reach_model`, found
    by the exact separation check on segments) are cut into volumes and compared; pairs in
    ``known`` ((k, 2), i < j; already in conflict for the caller) are not compared and not
    returned. Sorted."""
    from .separation import conflicting_pairs
    tol = float(precision_m) + float(margin_m)
    single = trajs_b is None
    if not len(trajs_a) or (not single and not len(trajs_b)):
        return np.zeros((0, 2), dtype=np.int64)
    sa = _segments(trajs_a)
    sb = sa if single else _segments(trajs_b)
    model = _reach_model([sa] if single else [sa, sb], spec, tol)
    if single:
        g = sa[0] if groups is None else np.asarray(groups)[sa[0]]
        near = conflicting_pairs(_segment_set(sa), None, model, groups_a=g)
    else:
        near = conflicting_pairs(_segment_set(sa), _segment_set(sb, from_s_b), model)
    near = np.asarray(near).reshape(-1, 2)[:, :2].astype(np.int64)
    nb = np.int64(max(len(trajs_a) if single else len(trajs_b), 1))
    if near.shape[0] and known is not None and len(known):
        oi, oj = sa[0][near[:, 0]], sb[0][near[:, 1]]
        if single:
            oi, oj = np.minimum(oi, oj), np.maximum(oi, oj)
        kc = np.sort(np.asarray(known, dtype=np.int64).reshape(-1, 2) @ np.array([nb, 1], dtype=np.int64))
        code = oi * nb + oj
        pos = np.clip(np.searchsorted(kc, code), 0, kc.shape[0] - 1)
        near = near[kc[pos] != code]
    if not near.shape[0]:
        return np.zeros((0, 2), dtype=np.int64)
    # volumes only of the segments that may meet
    used_a = np.zeros(sa[0].shape[0], dtype=bool)
    used_b = used_a if single else np.zeros(sb[0].shape[0], dtype=bool)
    used_a[near[:, 0]] = True
    used_b[near[:, 1]] = True
    a = _cut(sa, len(trajs_a), spec, only=used_a)
    b = a if single else _cut(sb, len(trajs_b), spec, from_s_b, only=used_b)
    p = _aligned_pairs(a, b, near, sa, sb, float(spec.max_piece_s), model)
    i, j = p[:, 0], p[:, 1]
    ok = (a.t0[i] <= b.t1[j]) & (b.t0[j] <= a.t1[i]) \
        & (a.lower[i] <= b.upper[j] + tol) & (b.lower[j] <= a.upper[i] + tol) \
        & (a.box_lo[i] <= b.box_hi[j] + tol).all(axis=1) & (b.box_lo[j] <= a.box_hi[i] + tol).all(axis=1)
    i, j = i[ok], j[ok]
    meet = _meet(a.corners[i], b.corners[j], tol)
    oi, oj = a.owner[i[meet]], b.owner[j[meet]]
    if single:
        oi, oj = np.minimum(oi, oj), np.maximum(oi, oj)
    code = np.sort(oi * nb + oj)
    code = code[np.concatenate(([True], code[1:] != code[:-1]))] if code.shape[0] else code
    return np.stack([code // nb, code % nb], axis=1)


def restrict_graph(graph, candidates, in_force: Sequence, spec, from_s: float):
    """``graph`` (a ``ConflictGraph``) with the published volumes checked too: its vertices whose
    candidate's volumes meet those of a flight in force (``in_force``: trajectories, their
    volumes from ``from_s`` on) are discarded, and vertices of different requests whose volumes
    meet get an edge. ``candidates``: the flat candidates ``graph.vertex_source`` indexes.
    The graph itself when nothing changes."""
    from .conflict_graph import ConflictGraph, _clique_edges, _unique_pairs

    src = graph.vertex_source
    if src.shape[0] == 0:
        return graph
    surv = [candidates[int(i)] for i in src.tolist()]
    blocked = np.zeros(src.shape[0], dtype=bool)
    if len(in_force):
        blocked[intent_pairs(surv, list(in_force), spec, from_s)[:, 0]] = True
    keep = ~blocked
    kept = np.flatnonzero(keep)
    # among the kept, pairs not already joined by the graph (edges are u < v, kept order kept)
    new_of = np.cumsum(keep) - 1
    e = graph.edges.astype(np.int64).reshape(-1, 2)
    e = new_of[e[keep[e[:, 0]] & keep[e[:, 1]]]] if e.shape[0] else e
    pairs = intent_pairs([surv[i] for i in kept.tolist()], None, spec,
                         groups=graph.vertex_request[kept], known=e)
    if not blocked.any() and not pairs.shape[0]:
        return graph
    edges = _unique_pairs(np.concatenate([e, pairs]).reshape(-1, 2), kept.shape[0]).astype(np.int32)
    vreq = graph.vertex_request[keep]
    order = np.argsort(vreq, kind="stable")
    bounds = np.searchsorted(vreq[order], np.arange(len(graph.groups) + 1))
    groups = [order[bounds[r]:bounds[r + 1]].astype(np.int64) for r in range(len(graph.groups))]
    n_clique = int(_clique_edges(groups).shape[0])
    discarded = graph.discarded.copy()
    discarded[src[blocked]] = True
    return ConflictGraph(weights=graph.weights[keep], edges=edges, vertex_request=vreq,
                         vertex_candidate=graph.vertex_candidate[keep], vertex_source=src[keep],
                         groups=groups, n_candidates=graph.n_candidates,
                         n_discarded=int(discarded.sum()), n_clique_edges=n_clique,
                         n_conflict_edges=int(edges.shape[0]) - n_clique, discarded=discarded)


def graph_for_config(graph, candidates, in_force: Sequence, config, from_s: float):
    """In F3548 mode (``config.intent_volumes`` set: ``PlanningConfig.intent_volume_piece_s`` >
    0), :func:`restrict_graph`; else ``graph`` itself. The one call every planning graph makes
    (epochs, re-plans, reactions)."""
    spec = config.intent_volumes
    if spec is None or graph.n_vertices == 0:
        return graph
    return restrict_graph(graph, candidates, list(in_force), spec, from_s)
