"""Airspace constraints: prisms and vertiport / pad closures, and the exact test of a flight
against them ("Decisions over a horizon, and an airspace that changes"; format and
semantics: docs/constraints.md).

A **volume constraint** is a prism: a horizontal region (a polygon, holes allowed, or a circle) in
the network's local ENU metres, times an altitude band ``[lower_m, upper_m]`` (ENU up, metres),
times a time window ``[start_s, end_s)`` (simulation seconds). A **closure** closes a vertiport
(or one of its pads) to departures and arrivals during ``[start_s, end_s)``. Every constraint has
an id, a version and a reason.

**Never into a constraint.** A trajectory is piecewise linear in time (``uam_planner.trajectory``),
so each straight segment is tested in closed form, vectorised over all segments:

1. clip the segment's time interval ``[t0, t1]`` by the window and by the altitude band (z is
   linear in t, so the band is one time interval, or all / nothing for a level segment);
2. the clipped part is a straight segment in the plane; find the earliest parameter at which it
   is in the closed region: 0 if its start is inside (crossing number over every ring), else the
   least parameter at which it meets an edge (segment-segment intersection, collinear overlap
   included); for a circle the least root of ``|A + s d - C|^2 = r^2`` in [0, 1];
3. the segment enters the prism at that time; the flight is refused if that time is before
   ``end_s``.

**Ties** (chosen to be safe and tested in ``test/test_constraints.py``): the region and the
altitude band are closed sets, so touching the boundary counts as entering: a segment through a
polygon's corner, tangent to a circle or levelled exactly at ``upper_m`` is refused. The time
window is half-open: a flight in the volume at exactly ``end_s`` (and only from then on) is
allowed, one there at exactly ``start_s`` is refused. The tests are decided in float64
arithmetic (no tolerance added); F3548 asks an intersection to be precise to 1 cm
(IntersectionMinimumPrecisionCm), far coarser than the rounding here. A closure refuses a flight
whose departure (from its origin) or arrival (at its destination) instant lies in the window at
that vertiport and, if the closure names a pad, at that pad; passing near a closed vertiport is
not refused (a volume constraint does that).

The files (GeoJSON, ED-269) are read by :func:`load_constraints`; see ``docs/constraints.md``.
No rclpy here; no wall clock: "now" is always an argument.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Iterable, Mapping, Sequence

import numpy as np
# shapely (GEOS) at import, i.e. at the planner's start-up: imported lazily it was loaded inside
# the first re-planning decision after a restriction appeared, whose wall time it inflated
# (0.47 s of wall against 0.04 s of CPU, measured at load 8; the files read cold from disk on a
# fresh machine); about 30 ms when cached
import shapely  # noqa: F401

from .geo import geodetic_to_enu

try:  # ASTM F3548-21 constants (uas_standards is in requirements.txt)
    from uas_standards.astm.f3548.v21 import constants as _f3548
    #: most vertices of one constraint's outline (ASTM F3548-21 CstrMaxVertices)
    MAX_VERTICES = int(_f3548.CstrMaxVertices)
except ImportError:  # pragma: no cover - the pinned environment has it
    MAX_VERTICES = 1000

KINDS = ("polygon", "circle", "closure")
#: segments x edges per block of the all-pairs polygon test (about 25 float64 temporaries of
#: this many elements: ~50 MB at most)
_BLOCK = 1 << 18
#: outlines of at least this many vertices are tested through an STR-tree of their edges
INDEXED_MIN_VERTICES = 32


class ConstraintError(ValueError):
    """A constraint (or a file of them) that cannot be accepted; the message names field and value."""


def _finite(owner: str, name: str, v, allow_inf: bool = False, sign: int = 0) -> float:
    """A float, finite or (``allow_inf``) infinite of sign ``sign`` (0: either)."""
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)):
        raise ConstraintError(f"{owner}{name}: {v!r} is not a number")
    x = float(v)
    if math.isnan(x) or (math.isinf(x) and not (allow_inf and (sign == 0 or x * sign > 0))):
        raise ConstraintError(f"{owner}{name}: {v!r} is not a finite number")
    return x


@dataclass(frozen=True, eq=False)
class Constraint:
    """One constraint: a prism (``polygon`` or ``circle``) or a ``closure``.

    Attributes:
        constraint_id: non-empty id, unique in a ConstraintSet.
        version: integer >= 0 (a change of the same id has a higher version).
        reason: why it exists (free text, may be empty).
        start_s, end_s: time window [start_s, end_s) in simulation seconds; start_s may be
            -inf and end_s inf (a permanent zone).
        rings_m: polygon only: tuple of (n, 2) float arrays, exterior ring first then holes, in
            ENU metres (east, north) from the network's origin, without the closing vertex.
        center_m, radius_m: circle only: centre (east, north) [m] and radius [m] > 0.
        lower_m, upper_m: prisms only: altitude band [m, ENU up], lower_m < upper_m (either may
            be infinite: -inf = from the ground, inf = unlimited).
        vertiport_id, pad_index: closure only: the vertiport (an aerodrome id of the network) and
            optionally one pad index (None = the whole vertiport).
        announce_s: when the authority announces it [s] (-inf, the default: known from the
            start). A ``Planner`` holds a constraint back until its first epoch at a time >=
            announce_s, and then re-plans the flights it affects (docs/replanning.md).
        author: the airspace authority that added or last changed it (``uam_planner.authority``;
            "" for the constraints the run started with).
    """

    constraint_id: str
    version: int
    reason: str
    start_s: float
    end_s: float
    rings_m: tuple | None = None
    center_m: tuple | None = None
    radius_m: float = float("nan")
    lower_m: float = -math.inf
    upper_m: float = math.inf
    vertiport_id: str | None = None
    pad_index: int | None = None
    announce_s: float = -math.inf
    author: str = ""
    _index: dict = field(default_factory=dict, init=False, repr=False)  # GEOS tree, built once

    def __post_init__(self):
        cid = self.constraint_id
        if not isinstance(cid, str) or not cid.strip():
            raise ConstraintError(f"id: {cid!r} is not a non-empty string")
        own = f"constraint {cid!r}: "
        v = self.version
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ConstraintError(f"{own}version: {v!r} is not an integer >= 0")
        if not isinstance(self.reason, str):
            raise ConstraintError(f"{own}reason: {self.reason!r} is not a string")
        start = _finite(own, "start_s", self.start_s, allow_inf=True, sign=-1)
        end = _finite(own, "end_s", self.end_s, allow_inf=True, sign=1)
        if not end > start:
            raise ConstraintError(f"{own}end_s: {self.end_s!r} is not after start_s {self.start_s!r}")
        announce = _finite(own, "announce_s", self.announce_s, allow_inf=True, sign=-1)
        if not announce < end:
            raise ConstraintError(f"{own}announce_s: {self.announce_s!r} is not before end_s "
                                  f"{self.end_s!r} (announced after it ended)")
        object.__setattr__(self, "version", int(v))
        object.__setattr__(self, "announce_s", announce)
        object.__setattr__(self, "start_s", start)
        object.__setattr__(self, "end_s", end)
        given = [n for n, x in (("polygon", self.rings_m), ("circle", self.center_m),
                                ("closure", self.vertiport_id)) if x is not None]
        if len(given) != 1:
            raise ConstraintError(f"{own}geometry: exactly one of a polygon, a circle or a "
                                  f"vertiport closure is needed, got {given or 'none'}")
        if self.vertiport_id is not None:
            if not isinstance(self.vertiport_id, str) or not self.vertiport_id:
                raise ConstraintError(f"{own}vertiport_id: {self.vertiport_id!r} is not a non-empty string")
            p = self.pad_index
            if p is not None and (isinstance(p, bool) or not isinstance(p, (int, np.integer)) or p < 0):
                raise ConstraintError(f"{own}pad: {p!r} is not an integer >= 0")
            return
        lo = _finite(own, "lower_m", self.lower_m, allow_inf=True)
        hi = _finite(own, "upper_m", self.upper_m, allow_inf=True)
        if not hi > lo:
            raise ConstraintError(f"{own}upper_m: {self.upper_m!r} is not above lower_m {self.lower_m!r} "
                                  f"(inverted or empty altitude band)")
        object.__setattr__(self, "lower_m", lo)
        object.__setattr__(self, "upper_m", hi)
        if self.center_m is not None:
            c = np.asarray(self.center_m, dtype=np.float64)
            if c.shape != (2,) or not np.all(np.isfinite(c)):
                raise ConstraintError(f"{own}center: {self.center_m!r} is not 2 finite numbers")
            r = _finite(own, "radius_m", self.radius_m)
            if r <= 0.0:
                raise ConstraintError(f"{own}radius_m: {self.radius_m!r} is not positive")
            object.__setattr__(self, "center_m", (float(c[0]), float(c[1])))
            object.__setattr__(self, "radius_m", r)
            return
        object.__setattr__(self, "rings_m", _checked_rings(own, self.rings_m))

    @property
    def n_vertices(self) -> int:
        """Vertices of the outline (every ring), 0 for a circle or a closure."""
        return sum(r.shape[0] for r in self.rings_m) if self.rings_m is not None else 0

    @property
    def kind(self) -> str:
        """'polygon', 'circle' or 'closure'."""
        return "closure" if self.vertiport_id is not None else \
            "circle" if self.center_m is not None else "polygon"

    def label(self) -> str:
        """``id v<version> (reason)`` for messages to operators."""
        return f"{self.constraint_id!r} v{self.version}" + (f" ({self.reason})" if self.reason else "")


def _checked_rings(own: str, rings) -> tuple:
    """Rings as read-only (n, 2) arrays without a repeated closing vertex, checked: finite, at
    least 3 distinct vertices each, at most MAX_VERTICES in all, a valid polygon (shapely:
    no self-intersection, holes inside the shell) of positive area."""
    from shapely.validation import explain_validity

    if not isinstance(rings, (list, tuple)) or not rings:
        raise ConstraintError(f"{own}coordinates: {rings!r} is not a list of rings")
    out = []
    for k, ring in enumerate(rings):
        try:
            a = np.array(ring, dtype=np.float64)
        except (TypeError, ValueError) as exc:
            raise ConstraintError(f"{own}coordinates[{k}]: not a list of [x, y] pairs ({exc})") from None
        if a.ndim != 2 or a.shape[1] < 2:
            raise ConstraintError(f"{own}coordinates[{k}]: shape {a.shape} is not a list of [x, y] pairs")
        a = a[:, :2]
        if not np.all(np.isfinite(a)):
            raise ConstraintError(f"{own}coordinates[{k}]: not all finite")
        if a.shape[0] > 1 and np.array_equal(a[0], a[-1]):
            a = a[:-1]
        if a.shape[0] < 3:
            raise ConstraintError(f"{own}coordinates[{k}]: {a.shape[0]} vertices, a ring needs at least 3")
        a.setflags(write=False)
        out.append(a)
    n = sum(a.shape[0] for a in out)
    if n > MAX_VERTICES:
        raise ConstraintError(f"{own}coordinates: {n} vertices, more than the {MAX_VERTICES} of "
                              f"ASTM F3548-21 (CstrMaxVertices)")
    poly = shapely.Polygon(out[0], out[1:])
    if not poly.is_valid:
        raise ConstraintError(f"{own}coordinates: invalid polygon: {explain_validity(poly)} "
                              f"(self-intersecting outline, or a hole outside the shell)")
    if not poly.area > 0.0:
        raise ConstraintError(f"{own}coordinates: polygon of zero area")
    return tuple(out)


# ---- the exact segment-prism test --------------------------------------------------------------

def _cross(ax, ay, bx, by):
    return ax * by - ay * bx


def _edges(rings):
    """(px, py, ex, ey) of every ring's edges: start point and edge vector, (e,) each."""
    px = np.concatenate([r[:, 0] for r in rings])
    py = np.concatenate([r[:, 1] for r in rings])
    ex = np.concatenate([np.roll(r[:, 0], -1) for r in rings]) - px
    ey = np.concatenate([np.roll(r[:, 1], -1) for r in rings]) - py
    return px, py, ex, ey


def _pair_entry(Ax, Ay, Dx, Dy, px, py, ex, ey):
    """Least s in [0, 1] at which segment A + s D meets edge P + u E, u in [0, 1] (inf if
    never); arrays broadcast. Crossing, touching at an end, collinear overlap (its first
    point) and a point segment lying on the edge all count."""
    wx, wy = px - Ax, py - Ay                    # edge start relative to segment start
    denom = _cross(Dx, Dy, ex, ey)
    ns = _cross(wx, wy, ex, ey)
    nu = _cross(wx, wy, Dx, Dy)
    with np.errstate(divide="ignore", invalid="ignore"):
        s = ns / denom
        u = nu / denom
    hit = (denom != 0.0) & (s >= 0.0) & (s <= 1.0) & (u >= 0.0) & (u <= 1.0)
    cand = np.where(hit, s, np.inf)
    # parallel and collinear: the overlap's first point
    dd = Dx * Dx + Dy * Dy
    coll = (denom == 0.0) & (nu == 0.0) & (dd > 0.0)
    with np.errstate(divide="ignore", invalid="ignore"):
        s_p = (wx * Dx + wy * Dy) / dd
        s_q = ((wx + ex) * Dx + (wy + ey) * Dy) / dd
    s_lo, s_hi = np.minimum(s_p, s_q), np.maximum(s_p, s_q)
    cand = np.where(coll & (s_hi >= 0.0) & (s_lo <= 1.0), np.maximum(s_lo, 0.0), cand)
    # a point segment (no horizontal motion) on the edge
    t_on = -(wx * ex + wy * ey)
    on = (dd == 0.0) & (ns == 0.0) & (t_on >= 0.0) & (t_on <= ex * ex + ey * ey)
    return np.where(on, 0.0, cand)


def _polygon_entry(ax, ay, dx, dy, rings) -> np.ndarray:
    """Least s in [0, 1] with (ax + s dx, ay + s dy) in the closed polygon (inf if none), (m,).

    Every segment against every edge, in blocks; the start point's crossing number (even-odd
    over every ring: holes count) says whether it starts inside."""
    px, py, ex, ey = _edges(rings)
    m, e = ax.shape[0], px.shape[0]
    out = np.full(m, np.inf)
    step = max(1, _BLOCK // e)
    for lo in range(0, m, step):
        sl = slice(lo, min(m, lo + step))
        Ax, Ay, Dx, Dy = (a[sl, None] for a in (ax, ay, dx, dy))
        straddle = (py > Ay) != (py + ey > Ay)
        with np.errstate(divide="ignore", invalid="ignore"):
            xcross = px + (Ay - py) * ex / ey
        inside = (np.count_nonzero(straddle & (Ax < xcross), axis=1) % 2) == 1
        first = _pair_entry(Ax, Ay, Dx, Dy, px, py, ex, ey).min(axis=1)
        out[sl] = np.where(inside, 0.0, first)
    return out


def _polygon_entry_indexed(ax, ay, dx, dy, c: "Constraint") -> np.ndarray:
    """As :func:`_polygon_entry` for outlines of many vertices: a GEOS STR-tree (shapely) of
    the edges gives the segment-edge pairs whose bounding boxes meet (a necessary condition
    for meeting, so nothing is lost), on which the same closed-form test runs; whether a
    segment starts inside is GEOS's ``intersects_xy`` on the (prepared) polygon, boundary
    included. Same answers, O((m + pairs) log e) instead of O(m e)."""
    cache = c._index
    if "tree" not in cache:
        px, py, ex, ey = _edges(c.rings_m)
        lines = shapely.linestrings(np.stack([np.column_stack([px, py]),
                                              np.column_stack([px + ex, py + ey])], axis=1))
        poly = shapely.Polygon(c.rings_m[0], c.rings_m[1:])
        shapely.prepare(poly)
        cache.update(tree=shapely.STRtree(lines), edges=(px, py, ex, ey), poly=poly)
    px, py, ex, ey = cache["edges"]
    segs = shapely.linestrings(np.stack([np.column_stack([ax, ay]),
                                         np.column_stack([ax + dx, ay + dy])], axis=1))
    si, ei = cache["tree"].query(segs)
    s = _pair_entry(ax[si], ay[si], dx[si], dy[si], px[ei], py[ei], ex[ei], ey[ei])
    out = np.full(ax.shape[0], np.inf)
    np.minimum.at(out, si, s)
    inside = shapely.intersects_xy(cache["poly"], ax, ay)
    return np.where(inside, 0.0, out)


def _circle_entry(ax, ay, dx, dy, cx, cy, r) -> np.ndarray:
    """Least s in [0, 1] with |(a + s d) - c| <= r (inf if none), (m,). Tangent counts."""
    wx, wy = ax - cx, ay - cy
    ww = wx * wx + wy * wy
    wd = wx * dx + wy * dy
    dd = dx * dx + dy * dy
    disc = wd * wd - dd * (ww - r * r)
    with np.errstate(divide="ignore", invalid="ignore"):
        s1 = (-wd - np.sqrt(np.maximum(disc, 0.0))) / dd
    hit = (dd > 0.0) & (disc >= 0.0) & (s1 >= 0.0) & (s1 <= 1.0)
    out = np.where(hit, s1, np.inf)
    return np.where(ww <= r * r, 0.0, out)


def prism_entry_times(t0_s, t1_s, p0_m, v_mps, c: Constraint) -> np.ndarray:
    """When each straight segment first is inside the prism of ``c`` during its window.

    Args:
        t0_s, t1_s: (m,) segment start and end times [s] (t0 <= t1).
        p0_m: (m, 3) ENU position [m] at t0; v_mps: (m, 3) constant velocity [m/s].
        c: a polygon or circle Constraint.
    Returns: (m,) float64: the first time [s] in [t0, t1] at which the segment is in the
        region x band x [start_s, end_s] (closed; see the module's ties), inf where never; the
        segment violates ``c`` where that time is < ``c.end_s``. O(m x vertices) at most
        (outlines of many vertices: O((m + pairs) log vertices)), vectorised.
    """
    t0 = np.asarray(t0_s, dtype=np.float64)
    t1 = np.asarray(t1_s, dtype=np.float64)
    p0 = np.asarray(p0_m, dtype=np.float64).reshape(-1, 3)
    v = np.asarray(v_mps, dtype=np.float64).reshape(-1, 3)
    lo = np.maximum(t0, c.start_s)
    hi = np.minimum(t1, c.end_s)
    z0, vz = p0[:, 2], v[:, 2]
    with np.errstate(divide="ignore", invalid="ignore"):
        ta = t0 + (c.lower_m - z0) / vz
        tb = t0 + (c.upper_m - z0) / vz
    level = vz == 0.0
    in_band = (z0 >= c.lower_m) & (z0 <= c.upper_m)
    za = np.where(level, np.where(in_band, -np.inf, np.inf), np.minimum(ta, tb))
    zb = np.where(level, np.where(in_band, np.inf, -np.inf), np.maximum(ta, tb))
    lo = np.maximum(lo, za)
    hi = np.minimum(hi, zb)
    out = np.full(t0.shape[0], np.inf)
    live = np.flatnonzero(lo <= hi)
    if live.size == 0:
        return out
    lo, hi = lo[live], hi[live]
    ax = p0[live, 0] + v[live, 0] * (lo - t0[live])
    ay = p0[live, 1] + v[live, 1] * (lo - t0[live])
    bx = p0[live, 0] + v[live, 0] * (hi - t0[live])
    by = p0[live, 1] + v[live, 1] * (hi - t0[live])
    dx, dy = bx - ax, by - ay
    if c.center_m is not None:
        s = _circle_entry(ax, ay, dx, dy, c.center_m[0], c.center_m[1], c.radius_m)
    else:
        # bounding-box cull before the segments x edges test
        allp = np.concatenate(c.rings_m)
        xmin, ymin = allp.min(axis=0)
        xmax, ymax = allp.max(axis=0)
        near = ~((np.maximum(ax, bx) < xmin) | (np.minimum(ax, bx) > xmax) |
                 (np.maximum(ay, by) < ymin) | (np.minimum(ay, by) > ymax))
        s = np.full(live.size, np.inf)
        k = np.flatnonzero(near)
        if k.size:
            if c.n_vertices >= INDEXED_MIN_VERTICES:
                s[k] = _polygon_entry_indexed(ax[k], ay[k], dx[k], dy[k], c)
            else:
                s[k] = _polygon_entry(ax[k], ay[k], dx[k], dy[k], c.rings_m)
    with np.errstate(invalid="ignore"):  # s = inf where never: inf x 0 is masked out
        out[live] = np.where(np.isfinite(s), lo + s * (hi - lo), np.inf)
    return out


# ---- a set of constraints against a network ----------------------------------------------------

class ConstraintSet:
    """Constraints checked against one network, ready to test candidates.

    Args:
        constraints: iterable of Constraint (ids unique).
        network: the Network (closures must name one of its aerodromes, and a pad it has).
        now_s: optional current time [s]: a constraint whose window has ended by then
            (end_s <= now_s) is refused as "in the past".
    Raises ConstraintError naming the constraint, field and value.
    """

    def __init__(self, constraints: Iterable[Constraint], network, now_s: float | None = None):
        cs = tuple(constraints)
        seen = set()
        for c in cs:
            if not isinstance(c, Constraint):
                raise ConstraintError(f"constraints: {c!r} is not a Constraint")
            if c.constraint_id in seen:
                raise ConstraintError(f"id: {c.constraint_id!r} appears twice")
            seen.add(c.constraint_id)
            check_against(c, network, now_s)
        self.constraints = cs
        self.network = network
        self._closure_nodes = np.array([network.node_index(c.vertiport_id) if c.kind == "closure"
                                        else -1 for c in cs], dtype=np.int64)

    def __len__(self) -> int:
        return len(self.constraints)

    def __iter__(self):
        return iter(self.constraints)

    def by_id(self, constraint_id: str) -> Constraint:
        for c in self.constraints:
            if c.constraint_id == constraint_id:
                return c
        raise KeyError(constraint_id)

    def violations(self, trajectories: Sequence, origin_index=None, destination_index=None,
                   origin_pad=None, destination_pad=None) -> tuple[np.ndarray, np.ndarray]:
        """The first constraint each trajectory violates, and when.

        Args:
            trajectories: n Trajectory.
            origin_index, destination_index: (n,) network node indices of each flight's ends
                (needed only for closures).
            origin_pad, destination_pad: (n,) pad index used at each end (default 0).
        Returns: (which (n,) int64: index into ``constraints`` of the violated constraint
            entered first, -1 where none; when_s (n,) float64: the time it is entered, or the
            departure / arrival at a closed vertiport; inf where none). O(segments x vertices).
        """
        n = len(trajectories)
        which = np.full(n, -1, dtype=np.int64)
        when = np.full(n, np.inf)
        if n == 0 or not self.constraints:
            return which, when
        segs = [tr.segments() for tr in trajectories]
        counts = np.array([s[0].shape[0] for s in segs], dtype=np.int64)
        owner = np.repeat(np.arange(n), counts)
        t0 = np.concatenate([s[0] for s in segs])
        t1 = np.concatenate([s[1] for s in segs])
        p0 = np.concatenate([s[2] for s in segs])
        v = np.concatenate([s[3] for s in segs])
        dep = np.array([tr.departure_s for tr in trajectories])
        arr = np.array([tr.arrival_s for tr in trajectories])
        for k, c in enumerate(self.constraints):
            if c.kind == "closure":
                t = np.full(n, np.inf)
                node = self._closure_nodes[k]
                for ends, times, pads in ((origin_index, dep, origin_pad),
                                          (destination_index, arr, destination_pad)):
                    if ends is None:
                        raise ValueError("violations: closures need origin_index and destination_index")
                    at = np.asarray(ends) == node
                    if c.pad_index is not None:
                        at &= (np.zeros(n, np.int64) if pads is None else np.asarray(pads)) == c.pad_index
                    hit = at & (times >= c.start_s) & (times < c.end_s)
                    t = np.where(hit, np.minimum(t, times), t)
            else:
                seg_t = prism_entry_times(t0, t1, p0, v, c)
                seg_t = np.where(seg_t < c.end_s, seg_t, np.inf)
                t = np.full(n, np.inf)
                np.minimum.at(t, owner, seg_t)
            better = t < when
            which[better] = k
            when[better] = t[better]
        return which, when


def check_against(c: Constraint, network, now_s: float | None = None) -> None:
    """Raise ConstraintError if ``c`` cannot apply to ``network`` at ``now_s``: a closure of a
    node that is not an aerodrome or of a pad it does not have; a window already over."""
    own = f"constraint {c.constraint_id!r}: "
    if now_s is not None and c.end_s <= float(now_s):
        raise ConstraintError(f"{own}end_s: {c.end_s!r} is in the past (now is {float(now_s)!r} s)")
    if c.kind != "closure":
        return
    i = network.index.get(c.vertiport_id)
    if i is None or not network.is_aerodrome[i]:
        raise ConstraintError(f"{own}vertiport_id: {c.vertiport_id!r} is not a vertiport of network "
                              f"{network.name!r}")
    if c.pad_index is not None:
        n_pads = len(network.pads_of(i))
        if c.pad_index >= n_pads:
            raise ConstraintError(f"{own}pad: {c.pad_index!r} is not a pad of {c.vertiport_id!r} "
                                  f"(it has {n_pads}: 0..{n_pads - 1})")


def refuse_candidates(cset: ConstraintSet, network, trajectories: Sequence,
                      origin_ids: Sequence[str], destination_ids: Sequence[str],
                      level_indices: Sequence[int], candidate_request: Sequence[int],
                      request_ids: Sequence[str]) -> tuple[np.ndarray, dict]:
    """The planner's hook: which candidates enter a constraint, and which requests lost all.

    Args:
        cset: the ConstraintSet.
        network: the Network (pads: a candidate at level index i uses pad i mod n_pads at each
            end, as ``uam_planner.candidates`` builds it; index 0 without levels).
        trajectories: n candidate trajectories.
        origin_ids, destination_ids: (n,) node ids of each candidate's ends.
        level_indices: (n,) level index of each candidate (-1 without levels).
        candidate_request: (n,) index of each candidate's request in ``request_ids``.
        request_ids: the eligible requests' ids.
    Returns: (refused (n,) bool; {request_id: reason} for every request all of whose
        candidates were refused, the reason naming the constraint(s)).
    """
    n = len(trajectories)
    o = np.array([network.node_index(x) for x in origin_ids], dtype=np.int64)
    d = np.array([network.node_index(x) for x in destination_ids], dtype=np.int64)
    lvl = np.maximum(np.asarray(level_indices, dtype=np.int64).reshape(n), 0)
    n_o = np.array([len(network.pads_of(i)) for i in o.tolist()], dtype=np.int64)
    n_d = np.array([len(network.pads_of(i)) for i in d.tolist()], dtype=np.int64)
    which, when = cset.violations(trajectories, o, d, lvl % np.maximum(n_o, 1), lvl % np.maximum(n_d, 1))
    refused = which >= 0
    req = np.asarray(candidate_request, dtype=np.int64).reshape(n)
    reasons = {}
    for r in np.unique(req[refused]).tolist():
        mine = req == r
        if refused[mine].all():
            ks = sorted(set(which[mine].tolist()))
            names = ", ".join(cset.constraints[k].label() for k in ks)
            first = float(when[mine].min())
            reasons[request_ids[r]] = (f"every candidate enters constraint {names} "
                                       f"(earliest at t = {first:g} s)")
    return refused, reasons


# ---- files ---------------------------------------------------------------------------------------

def _prop(props: Mapping, key: str, where: str, required: bool = True, default=None):
    if key not in props:
        if required:
            raise ConstraintError(f"{where}.properties.{key}: missing")
        return default
    return props[key]


def _to_enu(coords, frame: str, network, where: str) -> np.ndarray:
    a = np.asarray(coords, dtype=np.float64)
    if a.ndim != 2 or a.shape[1] < 2:
        raise ConstraintError(f"{where}: {coords!r} is not a list of positions")
    if frame == "enu":
        return a[:, :2]
    if network is None:
        raise ConstraintError(f"{where}: lon/lat coordinates need the network (its ENU origin)")
    if np.any(np.abs(a[:, 1]) > 90.0) or np.any(np.abs(a[:, 0]) > 180.0):
        raise ConstraintError(f"{where}: {a[:, :2].tolist()[:3]}... are not [lon, lat] degrees")
    lla = np.column_stack([a[:, 1], a[:, 0], np.zeros(a.shape[0])])
    return geodetic_to_enu(lla, network.origin_lat_lon_alt)[:, :2]


def constraints_from_geojson(doc: Mapping, network=None) -> list[Constraint]:
    """Constraints from a GeoJSON FeatureCollection (format: docs/constraints.md).

    Each feature has properties ``id``, ``version``, ``reason``, ``start_s``, ``end_s`` and:
    a Polygon geometry (rings of [lon, lat], or of [east_m, north_m] when the collection says
    ``"frame": "enu"``) with ``lower_m``, ``upper_m``; or a Point with ``radius_m``, ``lower_m``,
    ``upper_m`` (a circle); or no geometry (null) with ``vertiport_id`` and optionally ``pad``
    (a closure). Raises ConstraintError naming ``features[i]`` and the field.
    """
    if not isinstance(doc, Mapping) or doc.get("type") != "FeatureCollection":
        raise ConstraintError(f"type: {doc.get('type') if isinstance(doc, Mapping) else doc!r} "
                              f"is not 'FeatureCollection'")
    frame = doc.get("frame", "wgs84")
    if frame not in ("wgs84", "enu"):
        raise ConstraintError(f"frame: {frame!r} is not 'wgs84' (lon/lat, RFC 7946) or 'enu' "
                              f"(metres from the network's origin)")
    feats = doc.get("features")
    if not isinstance(feats, list):
        raise ConstraintError(f"features: {feats!r} is not a list")
    out = []
    for i, f in enumerate(feats):
        where = f"features[{i}]"
        if not isinstance(f, Mapping) or f.get("type") != "Feature":
            raise ConstraintError(f"{where}.type: is not 'Feature'")
        props = f.get("properties")
        if not isinstance(props, Mapping):
            raise ConstraintError(f"{where}.properties: {props!r} is not an object")
        cid = _prop(props, "id", where)
        where = f"features[{i}] (id {cid!r})"
        common = dict(constraint_id=cid, version=_prop(props, "version", where),
                      reason=_prop(props, "reason", where, False, ""),
                      start_s=_prop(props, "start_s", where), end_s=_prop(props, "end_s", where),
                      announce_s=_prop(props, "announce_s", where, False, -math.inf),
                      author=str(_prop(props, "author", where, False, "") or ""))
        geom = f.get("geometry")
        try:
            if geom is None:
                out.append(Constraint(**common, vertiport_id=_prop(props, "vertiport_id", where),
                                      pad_index=_prop(props, "pad", where, False)))
                continue
            gtype = geom.get("type") if isinstance(geom, Mapping) else None
            band = dict(lower_m=_prop(props, "lower_m", where), upper_m=_prop(props, "upper_m", where))
            if gtype == "Polygon":
                rings = geom.get("coordinates")
                if not isinstance(rings, list) or not rings:
                    raise ConstraintError(f"{where}.geometry.coordinates: {rings!r} is not a list of rings")
                n = sum(len(r) if isinstance(r, list) else 0 for r in rings)
                if n > MAX_VERTICES + len(rings):  # refuse before converting a huge outline
                    raise ConstraintError(f"{where}.geometry.coordinates: {n} positions, more than "
                                          f"the {MAX_VERTICES} vertices of ASTM F3548-21 (CstrMaxVertices)")
                enu = [_to_enu(r, frame, network, f"{where}.geometry.coordinates[{k}]")
                       for k, r in enumerate(rings)]
                out.append(Constraint(**common, **band, rings_m=tuple(enu)))
            elif gtype == "Point":
                c = _to_enu([geom.get("coordinates")], frame, network, f"{where}.geometry.coordinates")[0]
                out.append(Constraint(**common, **band, center_m=(c[0], c[1]),
                                      radius_m=_prop(props, "radius_m", where)))
            else:
                raise ConstraintError(f"{where}.geometry.type: {gtype!r} is not 'Polygon' or 'Point' "
                                      f"(or null for a closure)")
        except ConstraintError as exc:
            msg = str(exc)
            raise ConstraintError(msg if msg.startswith("features[") else f"{where}: {msg}") from None
    return out


_FT_M = 0.3048


def _utc_s(text, start_ns: int, where: str) -> float:
    from datetime import datetime, timezone
    try:
        when = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        raise ConstraintError(f"{where}: {text!r} is not an ISO 8601 time") from None
    if when.tzinfo is None:
        raise ConstraintError(f"{where}: {text!r} has no time zone")
    epoch = datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (when.astimezone(timezone.utc) - epoch).total_seconds() - start_ns * 1e-9


#: how far ahead an ED-269 daily schedule is expanded into windows when its period has no end
#: [days]: ASTM F3548-21's planning horizon (constraints are planned up to 56 days ahead)
SCHEDULE_HORIZON_DAYS = 56


def _schedule_windows(schedule, lo_s: float, hi_s: float, start_ns: int, where: str) -> list:
    """The (start_s, end_s) windows of ED-269 daily periods (``DailyPeriod``: ``day`` a list of
    MON..SUN or ANY, ``startTime`` / ``endTime`` times of day with their time zone, through
    ``uas_standards``' ``ED269TimeType``) inside the applicability period [lo_s, hi_s) in
    simulation seconds. The weekday is that of the date in the times' own zone; an end at or
    before the start crosses midnight (ends the next day). Days from the period's start, or the
    scenario's start when it has none, to its end, or ``SCHEDULE_HORIZON_DAYS`` after the
    scenario's start when it has none. Windows over before the scenario starts (t <= 0) are left
    out (past occurrences of a recurring schedule, not a window in the past); each is cut to
    the period. Raises ConstraintError naming the field."""
    from datetime import datetime, timedelta, timezone
    epoch = datetime(1970, 1, 1, tzinfo=timezone.utc)
    t_start = epoch + timedelta(microseconds=start_ns // 1000)
    first = t_start + timedelta(seconds=lo_s) if math.isfinite(lo_s) else t_start
    last = t_start + timedelta(seconds=hi_s) if math.isfinite(hi_s) else \
        t_start + timedelta(days=SCHEDULE_HORIZON_DAYS)
    out = []
    for j, dp in enumerate(schedule):
        w = f"{where}[{j}]"
        days = {str(getattr(d, "value", d)) for d in dp.day}
        if not days:
            raise ConstraintError(f"{w}.day: empty; give MON..SUN or ANY")
        t_a, t_b = dp.startTime.time, dp.endTime.time
        if t_a.tzinfo is None or t_b.tzinfo is None:
            raise ConstraintError(f"{w}: startTime {str(dp.startTime)!r} / endTime {str(dp.endTime)!r} "
                                  f"need a time zone")
        d = (first.astimezone(t_a.tzinfo) - timedelta(days=1)).date()
        while True:
            a = datetime.combine(d, t_a.replace(tzinfo=None), tzinfo=t_a.tzinfo)
            b = datetime.combine(d, t_b.replace(tzinfo=None), tzinfo=t_b.tzinfo)
            if a > last:
                break
            if b <= a:
                b += timedelta(days=1)
            if "ANY" in days or a.strftime("%a").upper() in days:
                s0 = max((a - t_start).total_seconds(), lo_s)
                s1 = min((b - t_start).total_seconds(), hi_s)
                if s1 > s0 and s1 > 0.0:
                    out.append((s0, s1))
            d += timedelta(days=1)
    return sorted(out)


def _ed269_periods(z, where: str, start_ns: int) -> list[tuple[float, float]]:
    """A zone's applicability as (start, end) windows [s of simulation]: unbounded when
    permanent or open-ended, one window per day for a daily schedule."""
    periods = []
    for k, a in enumerate(z.applicability):
        w = f"{where}.applicability[{k}]"
        permanent = str(getattr(a.permanent, "value", a.permanent)) == "YES"
        t0 = _utc_s(a.startDateTime, start_ns, f"{w}.startDateTime") \
            if a.get("startDateTime") and not permanent else -math.inf
        t1 = _utc_s(a.endDateTime, start_ns, f"{w}.endDateTime") \
            if a.get("endDateTime") and not permanent else math.inf
        if a.get("schedule"):
            periods.extend(_schedule_windows(a.schedule, t0, t1, start_ns, f"{w}.schedule"))
            continue
        periods.append((t0, t1))
    return periods


def _ed269_band(vol, origin_alt: float) -> list[float]:
    """A geometry volume's [lower, upper] limits as ENU up [m] (feet converted, AMSL less the
    origin's altitude ``origin_alt`` [m]); a missing limit is unbounded."""
    unit = _FT_M if str(getattr(vol.uomDimensions, "value", vol.uomDimensions)) == "FT" else 1.0
    band = []
    for name, ref, default in (("lowerLimit", "lowerVerticalReference", -math.inf),
                               ("upperLimit", "upperVerticalReference", math.inf)):
        v = vol.get(name)
        if v is None:
            band.append(default)
            continue
        z_m = float(v) * unit
        if str(getattr(vol.get(ref), "value", vol.get(ref))) == "AMSL":
            z_m -= origin_alt
        band.append(z_m)
    return band


def _ed269_geometry(hp, network, w: str) -> dict:
    """A horizontal projection as Constraint's keywords: a circle's ENU centre and radius [m], or
    the polygon's rings in ENU [m] (at most MAX_VERTICES vertices)."""
    kind = str(getattr(hp.type, "value", hp.type))
    if kind == "Circle":
        c = _to_enu([hp.center], "wgs84", network, f"{w}.horizontalProjection.center")[0]
        return dict(center_m=(c[0], c[1]), radius_m=hp.radius)
    rings = hp.coordinates or []
    if sum(len(r) for r in rings) > MAX_VERTICES + len(rings):
        raise ConstraintError(f"{w}.horizontalProjection.coordinates: more than the "
                              f"{MAX_VERTICES} vertices of ASTM F3548-21 (CstrMaxVertices)")
    return dict(rings_m=tuple(_to_enu(r, "wgs84", network,
                                      f"{w}.horizontalProjection.coordinates[{j}]")
                              for j, r in enumerate(rings)))


def constraints_from_ed269(doc: Mapping, network, scenario_start_utc: str | None = None) -> list[Constraint]:
    """Constraints from an EUROCAE ED-269 UAS zone file, parsed with ``uas_standards``' types
    (``uas_standards.eurocae_ed269.ED269Schema``), where it fits this planner:

    - one Constraint per (geometry volume, applicability period) of a zone; its id is the zone's
      ``identifier`` (``identifier.g.a`` when a zone has several), version 0 (ED-269 has no
      version), reason ``restriction: reasons / message``;
    - ``NO_RESTRICTION`` zones constrain nothing and are skipped; ``PROHIBITED``,
      ``REQ_AUTHORISATION`` and ``CONDITIONAL`` are all no-fly here (the fleet holds no
      authorisations);
    - positions [lon, lat] (as GeoJSON and as published zone files have them); a ``Circle`` has
      ``center`` [lon, lat] and ``radius`` in metres;
    - limits in M or FT; ``AMSL`` becomes ENU up by subtracting the network origin's altitude,
      ``AGL`` is taken over flat ground at the origin (no terrain model); a missing limit is
      unbounded;
    - ``permanent: YES`` is always active; otherwise ``startDateTime`` / ``endDateTime`` become
      simulation seconds after ``scenario_start_utc`` (default
      ``uam_contract.stamps.DEFAULT_SCENARIO_START_UTC``); a daily ``schedule`` becomes one
      window per day it applies (:func:`_schedule_windows`), each a constraint.
    Raises ConstraintError naming ``features[i]`` and the field.
    """
    from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC, scenario_start_ns
    from uas_standards.eurocae_ed269 import ED269Schema

    start_ns = scenario_start_ns(scenario_start_utc or DEFAULT_SCENARIO_START_UTC)
    try:
        schema = ED269Schema.from_dict(dict(doc))
    except (ValueError, TypeError, KeyError) as exc:
        raise ConstraintError(f"ED-269: {exc}") from None
    origin_alt = float(network.origin_lat_lon_alt[2])
    out = []
    for i, z in enumerate(schema.features):
        where = f"features[{i}] (identifier {z.identifier!r})"
        restriction = str(getattr(z.restriction, "value", z.restriction))
        if restriction == "NO_RESTRICTION":
            continue
        reasons = ",".join(str(getattr(r, "value", r)) for r in (z.get("reason") or []))
        text = restriction + (f": {reasons}" if reasons else "") + \
            (f" / {z.message}" if z.get("message") else "")
        periods = _ed269_periods(z, where, start_ns)
        n = len(z.geometry) * len(periods)
        for g, vol in enumerate(z.geometry):
            w = f"{where}.geometry[{g}]"
            band = _ed269_band(vol, origin_alt)
            try:
                geom = _ed269_geometry(vol.horizontalProjection, network, w)
                for k, (t0, t1) in enumerate(periods):
                    cid = z.identifier if n == 1 else f"{z.identifier}.{g}.{k}"
                    out.append(Constraint(cid, 0, text, t0, t1, lower_m=band[0], upper_m=band[1], **geom))
            except ConstraintError as exc:
                msg = str(exc)
                raise ConstraintError(msg if msg.startswith("features[") else f"{w}: {msg}") from None
    return out


def load_constraints(path, network, now_s: float | None = None,
                     scenario_start_utc: str | None = None) -> ConstraintSet:
    """Read a constraints file and check it against ``network`` (and ``now_s``, if given): a
    GeoJSON FeatureCollection (``"type": "FeatureCollection"``), or else an ED-269 UAS zone
    file (``{"features": [UASZoneVersion, ...]}``, see :func:`constraints_from_ed269`); F3548
    documents too through :func:`uam_planner.airspace_files.load_airspace`, which the runner and
    the planner node use. Raises ConstraintError (a ValueError) naming the file, the feature and
    the field."""
    p = Path(path)
    try:
        doc = json.loads(p.read_text())
    except (OSError, json.JSONDecodeError) as exc:
        raise ConstraintError(f"constraints file {str(p)!r}: {exc}") from None
    return constraint_set_from_document(doc, network, now_s, scenario_start_utc, str(p))


def constraint_set_from_document(doc, network, now_s: float | None = None,
                                 scenario_start_utc: str | None = None, name: str = "") -> ConstraintSet:
    """:func:`load_constraints` of a parsed GeoJSON or ED-269 document (``name``: the file, for
    the errors). F3548 documents are read one layer up, by :func:`uam_planner.airspace_files.load_airspace`."""
    p = name or "<document>"
    try:
        if isinstance(doc, Mapping) and doc.get("type") != "FeatureCollection" and "features" in doc:
            found = constraints_from_ed269(doc, network, scenario_start_utc)
        else:
            found = constraints_from_geojson(doc, network)
        return ConstraintSet(found, network, now_s)
    except ConstraintError as exc:
        raise ConstraintError(f"constraints file {p!r}: {exc}") from None
