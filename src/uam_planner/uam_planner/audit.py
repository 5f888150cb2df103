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


#: the largest n*n (flights squared) whose pair count :func:`sweep_audit` keeps in a bitmap
PAIR_BITMAP_MAX = 64_000_000


def sweep_audit(flights: Sequence[Any], separation_m=DEFAULT_SEPARATION_M,
                labels: Sequence[Any] | None = None, chunk_pairs: int = 4_000_000) -> AuditResult:
    """The same audit as :func:`audit_flights` for thousands of flights, in numpy.

    Every pair of straight segments of different flights whose time intervals overlap is
    checked (a time sweep over the segments sorted by start time, no spatial pruning, so
    nothing depends on the planner's broad phase), with the parametrisation of
    :func:`pair_min_distance` (relative position interpolated between the ends of the overlap,
    s in [0, 1]; for the cylinder the window of s where |dz| < V first) and the same tie rule.
    ``min_separation_m`` and ``losses`` (one entry per losing flight pair, at its closest
    approach) as in :func:`audit_flights`; ``pairs_checked`` counts flight pairs that share
    time. O(S log S + P) for S segments and P time-overlapping segment pairs, chunked.
    """
    import numpy as np

    model = as_separation_model(separation_m)
    H = model.separation_m
    V = model.vertical_separation_m if model.kind == "cylinder" else None
    items = list(flights)
    if labels is None:
        labels = [getattr(f, "request_id", i) for i, f in enumerate(items)]
    t0s, t1s, p0s, p1s, fl = [], [], [], [], []
    for k, f in enumerate(items):
        tr = getattr(f, "trajectory", f)
        t = np.asarray(tr.times_s, dtype=np.float64)
        p = np.asarray(tr.points_m, dtype=np.float64).reshape(-1, 3)
        t0s.append(t[:-1]); t1s.append(t[1:]); p0s.append(p[:-1]); p1s.append(p[1:])
        fl.append(np.full(t.size - 1, k, dtype=np.int64))
    if len(items) < 2:
        return AuditResult(math.inf, None, [], 0)
    t0 = np.concatenate(t0s); t1 = np.concatenate(t1s)
    p0 = np.concatenate(p0s); p1 = np.concatenate(p1s); f = np.concatenate(fl)
    order = np.argsort(t0, kind="stable")
    t0, t1, p0, p1, f = t0[order], t1[order], p0[order], p1[order], f[order]
    end = np.searchsorted(t0, t1, side="right")
    counts = np.maximum(end - np.arange(t0.size) - 1, 0)
    cum = np.cumsum(counts)
    best, best_pair, best_t = math.inf, None, math.nan
    loss: dict = {}
    pair_codes = []
    n = len(items)
    # pairs_checked counts distinct flight pairs: a bitmap of the n*n pair codes where it fits
    # (up to 64 MB), else np.unique of each chunk's codes. Measured (issue 24, a 7,200 s decision-
    # study cell, 3,023 flights): np.unique's hash of the 4M-pair chunks took 42 of the audit's
    # 92 s, the bitmap a fraction of a second; the count is the same.
    seen = np.zeros(n * n, dtype=bool) if n * n <= PAIR_BITMAP_MAX else None
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
        fa, fb = np.minimum(f[i], f[j]), np.maximum(f[i], f[j])
        if seen is not None:
            seen[fa * n + fb] = True
        else:
            pair_codes.append(np.unique(fa * n + fb))
        k = int(np.argmin(d))
        if d[k] < best:
            best, best_pair = float(d[k]), (labels[fa[k]], labels[fb[k]])
            best_t = float(lo[k] + s[k] * (hi[k] - lo[k]))
        for x in np.flatnonzero(d < H * (1.0 - _TIE_RELATIVE)).tolist():
            key = (int(fa[x]), int(fb[x]))
            tt = float(lo[x] + s[x] * (hi[x] - lo[x]))
            if key not in loss or d[x] < loss[key][0]:
                loss[key] = (float(d[x]), tt)
    if seen is not None:
        checked = int(np.count_nonzero(seen))
    else:
        checked = int(np.unique(np.concatenate(pair_codes)).size) if pair_codes else 0
    losses = [(labels[a], labels[b], dist, tt) for (a, b), (dist, tt) in sorted(loss.items())]
    return AuditResult(best, best_pair, losses, checked, best_t)
