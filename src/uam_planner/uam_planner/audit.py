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
    """

    min_separation_m: float
    pair_of_min: tuple | None
    losses: list = field(default_factory=list)
    pairs_checked: int = 0

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
    best, best_pair = math.inf, None
    losses = []
    checked = 0
    for i in range(len(items)):
        for j in range(i + 1, len(items)):
            if spans[i][1] < spans[j][0] or spans[j][1] < spans[i][0]:
                continue
            checked += 1
            d, t = pair_min_distance(items[i], items[j], vertical_m)
            if d < best:
                best, best_pair = d, (labels[i], labels[j])
            if d < separation_m * (1.0 - _TIE_RELATIVE):
                losses.append((labels[i], labels[j], d, t))
    return AuditResult(best, best_pair, losses, checked)
