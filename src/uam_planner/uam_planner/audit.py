"""An independent brute-force safety audit of approved flights.

Deliberately simple and separate from ``separation.py`` (no numpy kernel, no broad phase, a
different parametrisation of the closest point of approach) so that it can check it: for every
pair of flights and every pair of their segments that overlap in time, the relative position is
interpolated between the two ends of the overlap, r(s) = r_lo + s (r_hi - r_lo) for s in [0, 1],
and its minimum norm is found with plain Python floats. The time-overlapping segment pairs of two
flights are walked with two pointers, so a pair of flights costs O(s_a + s_b).

Both separation models are audited: the paper's sphere (3D distance below the minimum) and the
cylinder (horizontal distance below H while the vertical distance is below V): for the cylinder
the window of s where |dz(s)| < V is found first and the horizontal distance minimised over it.
Pass the run's model (``separation_m`` may be a number, the sphere, or a SeparationModel).

Use it in tests, analysis and reports; it is not meant for the planning hot path.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

from .separation import DEFAULT_SEPARATION_M, as_separation_model


# Flights exactly the minimum apart keep separation (the inequality is strict), and such exact
# ties are common by construction: two departures one slot apart on one route at the same speed
# trail each other by slot x speed (5 s x 10 m/s x 2 = 100 m). Rounding puts a tie a few 1e-14
# of H on either side, differently in the planner's kernel and here, so distances within this
# relative margin below the minimum count as ties, not losses.
_TIE_RELATIVE = 1e-9


@dataclass
class AuditResult:
    """Outcome of an audit.

    Attributes:
        min_separation_m: smallest distance [m] between any two flights at a common time
            (inf if no two flights are ever airborne together).
        pair_of_min: the labels (request ids, or indices) of the pair at that distance, or None.
        losses: (label_i, label_j, distance_m, time_s) for every pair closer than the separation.
        pairs_checked: flight pairs with a common airborne time.
        min_time_s: time [s] of the closest approach (nan when unknown or never together).
    """

    min_separation_m: float
    pair_of_min: tuple | None
    losses: list = field(default_factory=list)
    pairs_checked: int = 0
    min_time_s: float = math.nan

    @property
    def ok(self) -> bool:
        return not self.losses


def _waypoints(item: Any) -> tuple[list[float], list[tuple[float, float, float]]]:
    traj = getattr(item, "trajectory", item)
    if hasattr(traj, "times_s") and hasattr(traj, "points_m"):
        times, points = traj.times_s, traj.points_m
    else:
        times, points = item
    return ([float(t) for t in times],
            [(float(p[0]), float(p[1]), float(p[2])) for p in points])


def _at(times, points, k: int, t: float) -> tuple[float, float, float]:
    """Position on segment k at time t, interpolated between its two waypoints."""
    t0, t1 = times[k], times[k + 1]
    f = (t - t0) / (t1 - t0)
    a, b = points[k], points[k + 1]
    return (a[0] + f * (b[0] - a[0]), a[1] + f * (b[1] - a[1]), a[2] + f * (b[2] - a[2]))


def _min_in_window(r_lo, dr, dims: int, vertical_m: float | None) -> tuple[float, float]:
    """Minimum over s in [0, 1] of |(r_lo + s dr)[:dims]| (and the s of it), restricted, when
    ``vertical_m`` is given, to the s where |r_lo[2] + s dr[2]| < vertical_m; (inf, nan) if that
    set is empty."""
    s_lo, s_hi = 0.0, 1.0
    if vertical_m is not None:
        z0, dz = r_lo[2], dr[2]
        if dz == 0.0:
            if not abs(z0) < vertical_m:
                return math.inf, math.nan
        else:
            a, b = (-vertical_m - z0) / dz, (vertical_m - z0) / dz
            a, b = min(a, b), max(a, b)
            # A window shorter than 1e-9 of the overlap is a touch at |dz| = V that rounding may
            # put on either side of V (a climb ending one level below another flight): no loss.
            if not (a < 1.0 - 1e-9 and b > 1e-9):
                return math.inf, math.nan
            s_lo, s_hi = max(a, 0.0), min(b, 1.0)
    dd = sum(dr[c] * dr[c] for c in range(dims))
    s = s_lo
    if dd > 0.0:
        s = -sum(r_lo[c] * dr[c] for c in range(dims)) / dd
        s = min(s_hi, max(s_lo, s))
    return math.sqrt(sum((r_lo[c] + s * dr[c]) ** 2 for c in range(dims))), s


def pair_min_distance(a, b, vertical_m: float | None = None) -> tuple[float, float]:
    """(minimum distance [m], time [s] of it) of two trajectories over their common time.

    ``a`` and ``b``: Trajectory, Flight or (times_s, points_m). (inf, nan) if never together.
    With ``vertical_m`` (the cylinder's V [m]) the distance is horizontal and only the times at
    which the vertical distance is below ``vertical_m`` count.

    Examples:
        Two flights east at 10 m/s, 50 m apart, and one crossing them from the south:

        >>> east = ([0.0, 100.0], [(0, 0, 100), (1000, 0, 100)])
        >>> pair_min_distance(east, ([0.0, 100.0], [(0, 50, 100), (1000, 50, 100)]))
        (50.0, 0.0)
        >>> pair_min_distance(east, ([0.0, 100.0], [(500, -500, 100), (500, 500, 100)]))
        (0.0, 50.0)
    """
    ta, pa = _waypoints(a)
    tb, pb = _waypoints(b)
    best, best_t = math.inf, math.nan
    i = j = 0
    while i < len(ta) - 1 and j < len(tb) - 1:
        lo = max(ta[i], tb[j])
        hi = min(ta[i + 1], tb[j + 1])
        if lo <= hi:
            a_lo, b_lo = _at(ta, pa, i, lo), _at(tb, pb, j, lo)
            a_hi, b_hi = _at(ta, pa, i, hi), _at(tb, pb, j, hi)
            r_lo = [a_lo[c] - b_lo[c] for c in range(3)]
            dr = [(a_hi[c] - b_hi[c]) - r_lo[c] for c in range(3)]
            dist, s = _min_in_window(r_lo, dr, 3 if vertical_m is None else 2, vertical_m)
            if dist < best:
                best, best_t = dist, lo + s * (hi - lo)
        # advance the segment that ends first (both if they end together)
        end_a, end_b = ta[i + 1], tb[j + 1]
        if end_a <= end_b:
            i += 1
        if end_b <= end_a:
            j += 1
    return best, best_t


def audit_flights(flights: Sequence[Any], separation_m=DEFAULT_SEPARATION_M,
                  labels: Sequence[Any] | None = None) -> AuditResult:
    """Check every pair of flights for loss of separation, by brute force.

    Args:
        flights: Flights (anything with ``.trajectory``), Trajectories or (times_s, points_m).
        separation_m: separation minimum [m] (the paper's sphere; a loss is a distance strictly
            below it, by more than 1e-9 of it: closer than that is an exact tie rounded) or a ``SeparationModel`` (for the cylinder, ``min_separation_m`` and the
            losses' distances are horizontal distances while vertically closer than V).
        labels: names for the report; default each flight's ``request_id`` or its index.
    Returns: AuditResult. Complexity O(F^2 + sum over overlapping pairs of (s_a + s_b)), pure Python.
    """
    model = as_separation_model(separation_m)
    separation_m = model.separation_m
    vertical_m = model.vertical_separation_m if model.kind == "cylinder" else None
    items = list(flights)
    if labels is None:
        labels = [getattr(f, "request_id", i) for i, f in enumerate(items)]
    spans = []
    for f in items:
        times, _ = _waypoints(f)
        spans.append((times[0], times[-1]))
    best, best_pair, best_t = math.inf, None, math.nan
    losses = []
    checked = 0
    for i in range(len(items)):
        for j in range(i + 1, len(items)):
            if spans[i][1] < spans[j][0] or spans[j][1] < spans[i][0]:
                continue
            checked += 1
            d, t = pair_min_distance(items[i], items[j], vertical_m)
            if d < best:
                best, best_pair, best_t = d, (labels[i], labels[j]), t
            if d < separation_m * (1.0 - _TIE_RELATIVE):
                losses.append((labels[i], labels[j], d, t))
    return AuditResult(best, best_pair, losses, checked, best_t)


def _segments(items):
    """The straight segments of every flight, sorted by start time (stable): t0, t1 (S,), p0, p1
    (S, 3) and the flight index of each (S,)."""
    import numpy as np

    t0s, t1s, p0s, p1s, fl = [], [], [], [], []
    for k, f in enumerate(items):
        tr = getattr(f, "trajectory", f)
        t = np.asarray(tr.times_s, dtype=np.float64)
        p = np.asarray(tr.points_m, dtype=np.float64).reshape(-1, 3)
        t0s.append(t[:-1]); t1s.append(t[1:]); p0s.append(p[:-1]); p1s.append(p[1:])
        fl.append(np.full(t.size - 1, k, dtype=np.int64))
    t0 = np.concatenate(t0s); t1 = np.concatenate(t1s)
    p0 = np.concatenate(p0s); p1 = np.concatenate(p1s); f = np.concatenate(fl)
    order = np.argsort(t0, kind="stable")
    return t0[order], t1[order], p0[order], p1[order], f[order]


def _closest(seg, i, j, V):
    """The closest approach of segment pairs (i, j) (index arrays into ``seg``, time intervals
    overlapping): the parametrisation of :func:`pair_min_distance` in numpy. Returns (d, t): the
    distance (horizontal for the cylinder, inf where never vertically closer than V) and its time.
    One function for the full sweep and the pruned one, so both compute the same floats."""
    import numpy as np

    t0, t1, p0, p1, _f = seg
    lo = np.maximum(t0[i], t0[j])
    hi = np.minimum(t1[i], t1[j])

    def at(k, t):
        w = ((t - t0[k]) / (t1[k] - t0[k]))[:, None]
        return p0[k] + w * (p1[k] - p0[k])
    r_lo = at(i, lo) - at(j, lo)
    dr = (at(i, hi) - at(j, hi)) - r_lo
    s_lo = np.zeros(i.size)
    s_hi = np.ones(i.size)
    ok = np.ones(i.size, dtype=bool)
    dims = 3
    if V is not None:
        dims = 2
        z0, dz = r_lo[:, 2], dr[:, 2]
        moving = dz != 0.0
        with np.errstate(divide="ignore", invalid="ignore"):
            a = np.where(moving, (-V - z0) / np.where(moving, dz, 1.0), -np.inf)
            b = np.where(moving, (V - z0) / np.where(moving, dz, 1.0), np.inf)
        a, b = np.minimum(a, b), np.maximum(a, b)
        ok = np.where(moving, (a < 1.0 - 1e-9) & (b > 1e-9), np.abs(z0) < V)
        s_lo = np.maximum(a, 0.0)
        s_hi = np.minimum(b, 1.0)
    rr, dd_ = r_lo[:, :dims], dr[:, :dims]
    dd = np.einsum("ij,ij->i", dd_, dd_)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = np.where(dd > 0.0, -np.einsum("ij,ij->i", rr, dd_) / np.where(dd > 0, dd, 1.0), s_lo)
    s = np.minimum(np.maximum(s, s_lo), np.maximum(s_hi, s_lo))
    d = np.linalg.norm(rr + s[:, None] * dd_, axis=1)
    d = np.where(ok, d, np.inf)
    return d, lo + s * (hi - lo)


class _Tally:
    """The minimum and the losses over segment pairs fed in the sweep's order (i, then j,
    ascending): the first pair at the minimum wins, and per flight pair its closest losing pair
    (the first at equal distance)."""

    def __init__(self, H):
        self.H = H
        self.best, self.best_pair, self.best_t = math.inf, None, math.nan
        self.loss: dict = {}

    def add(self, seg, i, j, d, t):
        import numpy as np

        f = seg[4]
        fa, fb = np.minimum(f[i], f[j]), np.maximum(f[i], f[j])
        k = int(np.argmin(d))
        if d[k] < self.best:
            self.best, self.best_pair, self.best_t = float(d[k]), (int(fa[k]), int(fb[k])), float(t[k])
        for x in np.flatnonzero(d < self.H * (1.0 - _TIE_RELATIVE)).tolist():
            key = (int(fa[x]), int(fb[x]))
            if key not in self.loss or d[x] < self.loss[key][0]:
                self.loss[key] = (float(d[x]), float(t[x]))

    def result(self, labels, checked) -> AuditResult:
        pair = (labels[self.best_pair[0]], labels[self.best_pair[1]]) if self.best_pair else None
        losses = [(labels[a], labels[b], dist, tt) for (a, b), (dist, tt) in sorted(self.loss.items())]
        return AuditResult(self.best, pair, losses, checked, self.best_t)


def _h_v(model):
    return model.separation_m, (model.vertical_separation_m if model.kind == "cylinder" else None)


def _full_sweep(seg, models, n, chunk_pairs):
    """Every time-overlapping segment pair of different flights (the sweep without pruning)."""
    import numpy as np

    t0, t1 = seg[0], seg[1]
    f = seg[4]
    end = np.searchsorted(t0, t1, side="right")
    counts = np.maximum(end - np.arange(t0.size) - 1, 0)
    cum = np.cumsum(counts)
    tallies = [_Tally(_h_v(m)[0]) for m in models]
    pair_codes = []
    start = 0
    while start < t0.size:
        base = cum[start - 1] if start else 0
        stop = max(int(np.searchsorted(cum, base + chunk_pairs, side="right")), start + 1)
        c = counts[start:stop]
        i = np.repeat(np.arange(start, stop), c)
        j = i + 1 + (np.arange(int(c.sum())) - np.repeat(np.cumsum(c) - c, c))
        start = stop
        keep = f[i] != f[j]
        i, j = i[keep], j[keep]
        if i.size == 0:
            continue
        pair_codes.append(np.unique(np.minimum(f[i], f[j]) * n + np.maximum(f[i], f[j])))
        for m, tally in zip(models, tallies):
            d, t = _closest(seg, i, j, _h_v(m)[1])
            tally.add(seg, i, j, d, t)
    checked = int(np.unique(np.concatenate(pair_codes)).size) if pair_codes else 0
    return tallies, checked


def _flights_sharing_time(seg, n) -> int:
    """Flight pairs whose flown spans overlap (closed intervals): the pairs the sweep checks."""
    import numpy as np

    t0, t1, _p0, _p1, f = seg
    first = np.full(n, np.inf)
    last = np.full(n, -np.inf)
    np.minimum.at(first, f, t0)
    np.maximum.at(last, f, t1)
    has = np.isfinite(first)
    a, b = first[has], last[has]
    order = np.argsort(a, kind="stable")
    a, b = a[order], b[order]
    return int((np.searchsorted(a, b, side="right") - np.arange(a.size) - 1).sum())


class _PieceGrid:
    """:func:`_near_pairs`'s pieces (cut at time-bucket edges) and their boxes' cells, plain and widened by reach."""

    def __init__(self, seg, reach: float):
        import numpy as np

        self.S = seg[0].size
        self.seg_of, self.bucket, lo, hi = _time_pieces(seg, reach)
        c = reach
        org = lo.min(axis=0) - 2 * reach
        self.plain_lo = np.floor((lo - org) / c).astype(np.int64)
        self.plain_hi = np.floor((hi - org) / c).astype(np.int64)
        self.wide_lo = np.floor((lo - reach - org) / c).astype(np.int64)
        self.wide_hi = np.floor((hi + reach - org) / c).astype(np.int64)
        self.ny = int(max(self.plain_hi[:, 1].max(), self.wide_hi[:, 1].max())) + 2
        self.nx = int(max(self.plain_hi[:, 0].max(), self.wide_hi[:, 0].max())) + 2

    def entries(self, lo_c, hi_c, rows):
        """(cell code, piece) of every cell of the pieces ``rows`` in [lo_c, hi_c]: the keys two pieces meet on."""
        import numpy as np

        n_x = hi_c[rows, 0] - lo_c[rows, 0] + 1
        n_y = hi_c[rows, 1] - lo_c[rows, 1] + 1
        cnt = n_x * n_y
        piece = np.repeat(rows, cnt)
        r = np.arange(piece.size) - np.repeat(np.cumsum(cnt) - cnt, cnt)
        nyr = np.repeat(n_y, cnt)
        cx = lo_c[piece, 0] + r // nyr
        cy = lo_c[piece, 1] + r % nyr
        return (self.bucket[piece] * self.nx + cx) * self.ny + cy, piece

    def batches(self, max_entries: int):
        """The pieces in bucket order, batches of about ``max_entries`` wide entries (bounded memory), whole buckets."""
        import numpy as np

        bucket, wide_lo, wide_hi = self.bucket, self.wide_lo, self.wide_hi
        order = np.argsort(bucket, kind="stable")
        wide_cnt = ((wide_hi[:, 0] - wide_lo[:, 0] + 1) * (wide_hi[:, 1] - wide_lo[:, 1] + 1))[order]
        cum = np.cumsum(wide_cnt)
        start = 0
        while start < order.size:
            base = cum[start - 1] if start else 0
            stop = max(int(np.searchsorted(cum, base + max_entries, side="right")), start + 1)
            # never split a bucket between batches
            last_b = bucket[order[stop - 1]]
            stop = int(np.searchsorted(bucket[order], last_b, side="right"))
            rows = order[start:stop]
            start = stop
            yield rows

    def near_codes(self, seg, rows):
        """Sorted unique codes i * S + j of the segment pairs of one batch's cell mates (None: no cell mates)."""
        import numpy as np

        t0, t1, _p0, _p1, f = seg
        S, seg_of = self.S, self.seg_of
        kp, pp = self.entries(self.plain_lo, self.plain_hi, rows)
        srt = np.argsort(kp, kind="stable")
        kp, pp = kp[srt], pp[srt]
        kw, pw = self.entries(self.wide_lo, self.wide_hi, rows)
        left = np.searchsorted(kp, kw, side="left")
        right = np.searchsorted(kp, kw, side="right")
        m = right - left
        if not m.sum():
            return None
        a = np.repeat(pw, m)
        b = pp[np.repeat(left, m) + (np.arange(int(m.sum())) - np.repeat(np.cumsum(m) - m, m))]
        sa, sb = seg_of[a], seg_of[b]
        keep = f[sa] != f[sb]
        sa, sb = sa[keep], sb[keep]
        i, j = np.minimum(sa, sb), np.maximum(sa, sb)
        keep = np.maximum(t0[i], t0[j]) <= np.minimum(t1[i], t1[j])
        return _sorted_unique(i[keep] * S + j[keep])


def _time_pieces(seg, reach: float):
    """Segments cut at time-bucket edges (T: about one cell of flight): (segment, bucket, box lo, box hi) per piece."""
    import numpy as np

    t0, t1, p0, p1, _f = seg
    S = t0.size
    c = reach
    speed = np.sqrt(np.square((p1 - p0)[:, :2]).sum(axis=1)) / (t1 - t0)
    # T from the speed of the fast segments, not of the fastest one: any T finds every pair (a
    # piece's box holds its part of the segment), T only sets the cost. A flown track can hold a
    # segment of a microsecond (a switch between versions) that moves metres: at ~10^6 m/s it
    # made T = 1 ms for all, ~10^8 entries and a Monte-Carlo worker past 11 GiB;
    # such a segment now spans a few cells in one piece instead
    vmax = min(float(speed.max()), 4.0 * float(np.quantile(speed, 0.99))) if S else 0.0
    T = min(max(c / vmax if vmax > 0 else 60.0, 1e-3), 60.0)
    k0 = np.floor(t0[0] / T) - 1 if S else 0.0
    edges = (k0 + np.arange(int(np.ceil((t1.max() - t0[0]) / T)) + 4)) * T
    b0 = np.searchsorted(edges, t0, side="right") - 1
    b1 = np.searchsorted(edges, t1, side="right") - 1
    npc = (b1 - b0 + 1).astype(np.int64)
    seg_of = np.repeat(np.arange(S), npc)
    bucket = b0[seg_of] + (np.arange(seg_of.size) - np.repeat(np.cumsum(npc) - npc, npc))
    ta = np.maximum(t0[seg_of], edges[bucket])
    tb = np.minimum(t1[seg_of], edges[bucket + 1])
    tb = np.maximum(ta, tb)
    w = ((t1 - t0)[seg_of])
    xa = p0[seg_of, :2] + ((ta - t0[seg_of]) / w)[:, None] * (p1 - p0)[seg_of, :2]
    xb = p0[seg_of, :2] + ((tb - t0[seg_of]) / w)[:, None] * (p1 - p0)[seg_of, :2]
    lo, hi = np.minimum(xa, xb), np.maximum(xa, xb)
    return seg_of, bucket, lo, hi


def _near_pairs(seg, reach_m: float, max_entries: int = 8_000_000):
    """Every pair (i < j, sweep order) of segments of different flights, closed-overlapping in
    time, that may come within ``reach_m`` per horizontal axis at a common instant: a grid hash
    on time buckets and horizontal cells. Sorted, unique.

    Each segment is cut into pieces at the edges of time buckets of length T (the instant a
    piece ends on an edge is a piece of its own); two segments that share an instant t* both
    have a piece in t*'s bucket whose time interval holds t*. A piece is entered (its bucket,
    the cells of side c >= reach its box covers) on the "plain" side and (its bucket, the cells
    its box widened by reach covers) on the "wide" side; the positions of two segments at t*
    lie in their pieces' boxes, so if they are within reach on each axis the cell of one lies
    in the other's wide cells: the pair is found. Cost: O(S log S) in the pieces and entries
    (T = c / the fastest segment speed, so a piece spans about one cell), plus the pairs found.
    """
    import numpy as np

    S = seg[0].size
    reach = float(reach_m) * (1.0 + 1e-9) + 1e-6   # the boxes' rounding, generously
    grid = _PieceGrid(seg, reach)
    codes = []
    for rows in grid.batches(max_entries):
        code = grid.near_codes(seg, rows)
        if code is not None:
            codes.append(code)
    if not codes:
        return np.zeros(0, np.int64), np.zeros(0, np.int64)
    u = _sorted_unique(np.concatenate(codes))
    return u // S, u % S


def _sorted_unique(x):
    """np.unique of an int64 array by sorting (numpy 2's hash-based unique took 14 s on 11 M
    pair codes where this takes about 1 s: measured)."""
    import numpy as np

    if x.size == 0:
        return x
    x = np.sort(x)
    return x[np.concatenate([[True], x[1:] != x[:-1]])]


def sweep_audits(flights: Sequence[Any], models: Sequence[Any], labels: Sequence[Any] | None = None,
                 chunk_pairs: int = 4_000_000, prune: bool = True,
                 groups: Sequence[Any] | None = None) -> list[AuditResult]:
    """:func:`sweep_audit` in several separation models at once (e.g. the true minimum and the
    minimum widened by a sampling bound): one candidate search, one result per model.

    ``groups`` (one name per trajectory): trajectories of one group are the parts of one flight
    (each plan version while in force): never a pair, and the results name the groups (losses
    and ``pairs_checked`` per pair of groups); ``labels`` is then ignored.

    ``prune=True`` (the default) checks only the segment pairs that a grid hash on time buckets
    and horizontal cells finds within reach of each other (:func:`_near_pairs`, reach = twice
    the largest horizontal minimum, widened until it holds the minimum of every model), in the
    same order and with the same arithmetic as the full sweep: every loss, the minimum, its
    pair and time, and ``pairs_checked`` (flight pairs sharing time) are those of
    ``prune=False``, which checks every time-overlapping segment pair (O(P)). Pruned:
    O(S log S) in the segments plus the pairs found near each other. Measured (BENCHMARKS.md):
    a city recording of 2,000 flights went from > 23 CPU-min to seconds.
    """
    import numpy as np

    models = [as_separation_model(m) for m in models]
    items = list(flights)
    if labels is None:
        labels = [getattr(f, "request_id", i) for i, f in enumerate(items)]
    if len(items) < 2:
        return [AuditResult(math.inf, None, [], 0) for _m in models]
    seg = _segments(items)
    n = len(items)
    if groups is not None:  # a segment belongs to its group: the sweep pairs groups
        labels = list(dict.fromkeys(groups))
        index = {g: k for k, g in enumerate(labels)}
        of = np.array([index[g] for g in groups], dtype=np.int64)
        seg = (*seg[:4], of[seg[4]])
        n = len(labels)
    if not prune:
        tallies, checked = _full_sweep(seg, models, n, chunk_pairs)
        return [t.result(labels, checked) for t in tallies]
    checked = _flights_sharing_time(seg, n)
    p = np.concatenate([seg[2], seg[3]])
    extent = float(np.sqrt(np.square(p.max(axis=0)[:2] - p.min(axis=0)[:2]).sum()))
    reach = 2.0 * max(m.separation_m for m in models)
    while True:
        i, j = _near_pairs(seg, reach)
        tallies = [_Tally(_h_v(m)[0]) for m in models]
        for a in range(0, i.size, chunk_pairs):
            ii, jj = i[a:a + chunk_pairs], j[a:a + chunk_pairs]
            for m, tally in zip(models, tallies):
                d, t = _closest(seg, ii, jj, _h_v(m)[1])
                tally.add(seg, ii, jj, d, t)
        # a pair closer than reach on each axis is among those checked: the minimum is proven
        # once it is below reach (or nothing shares time, or reach spans the whole extent, where
        # every time-overlapping pair is checked); else widen
        if all(t.best < reach for t in tallies) or checked == 0 or reach > extent:
            return [t.result(labels, checked) for t in tallies]
        reach *= 4.0


def sweep_audit(flights: Sequence[Any], separation_m=DEFAULT_SEPARATION_M,
                labels: Sequence[Any] | None = None, chunk_pairs: int = 4_000_000,
                prune: bool = True, groups: Sequence[Any] | None = None) -> AuditResult:
    """The same audit as :func:`audit_flights` for thousands of flights, in numpy.

    Every pair of straight segments of different flights whose time intervals overlap is
    checked (a time sweep over the segments sorted by start time; with ``prune`` (default) only
    the pairs a grid hash of its own finds near each other, which gives the same result:
    :func:`sweep_audits`; nothing depends on the planner's broad phase), with the
    parametrisation of :func:`pair_min_distance` (relative position interpolated between the
    ends of the overlap, s in [0, 1]; for the cylinder the window of s where |dz| < V first) and
    the same tie rule. ``min_separation_m`` and ``losses`` (one entry per losing flight pair, at
    its closest approach) as in :func:`audit_flights`; ``pairs_checked`` counts flight pairs
    that share time. Unpruned O(S log S + P) for S segments and P time-overlapping segment
    pairs, chunked.
    """
    return sweep_audits(flights, [separation_m], labels, chunk_pairs, prune, groups)[0]
