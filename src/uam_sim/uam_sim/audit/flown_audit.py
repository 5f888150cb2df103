"""Audit of what flew when plans change: plan versions chained into the
trajectories actually flown, and every flown trajectory checked against the airspace
constraints in force.

Plan versions (``FlightPlan.version``, ``effective_time``, ``state``, ``constraint_ids``,
``update_kind``; docs/replanning.md): version 1 is the approval (0 in recordings made before
versions); version n + 1 replaces version n from its ``effective_time`` on. The simulator flies
each version from the instant it takes effect, so what flew is, per request, version 1 up to the
effective instant of version 2, then version 2 up to that of version 3, and so on
(:func:`flown_trajectory`). A version without waypoints (a cancellation) ends the flight there.

**Chaining** (:func:`chain_problems`): the versions of a request must be 1, 2, ..., n with no gap
(a version n + 1 without n is a plan the recording lost, or one nobody issued), each effective
no earlier than its predecessor, each update (n >= 2) naming at least one constraint that the
planner announced on ``uam/constraints`` at or before it took effect (except an update of the
reaction to nonconformance, :func:`reaction_update`: the flight itself caused it, so it
names none; nor does a neighbour re-timed so that a nonconforming flight keeps separation,
``yielded``), and a version that takes over a flight in the air must start where the flight was
at that instant (to 1 mm; again except a reaction update, which starts where the aircraft was).
A recording that breaks any of these is NOT VERIFIED.

**Incursions** (:func:`incursions`): every flown trajectory, from the instant each version took
effect, against every constraint version while the planner had it in force (from the epoch it
took effect at, ``effective_s``, until it was replaced or withdrawn) and during its window
``[start_s, end_s)``. The test is written here again, independently of the planner's closed-form
prism test (``uam_planner.constraints``): each straight segment is clipped to the time interval
and to the altitude band (z is linear in t), and the clipped part is intersected with the
region by shapely (GEOS: exact segment-polygon intersection on the closed polygon; a circle by
the exact distance of the segment to its centre). The entry instant is the earliest point of
the intersection; it is an incursion when it lies before the end of the interval (the window is
half-open: entering exactly at ``end_s`` is allowed, as the planner allows it). A vertiport
closure is entered by a departure (the first flown waypoint) or an arrival (the last) at that
vertiport inside the interval.

rclpy-free and duck-typed: plans are anything with FlightPlan's fields.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Iterable, Sequence

import numpy as np

from uam_contract.stamps import stamp_s
from uam_planner.nonconformance import KIND, KIND_CONTINGENCY, KIND_YIELD, RATE_WORD
from uam_planner.replanning import KIND_MODIFIED

from .separation import trajectory_of

#: FlightPlan.STATE_CONTINGENT (uam_msgs)
STATE_CONTINGENT = 4

#: a version taking over a flight in the air must start within this of where the flight was [m]
CONTINUITY_M = 1e-3


def plan_version(p: Any) -> int:
    """A plan's version: 1 is the approval (``uam_planner.planning.Flight.version``); recordings
    made before versions carry 0, read as 1."""
    return max(1, int(getattr(p, "version", 0) or 0))


def effective_s(p: Any) -> float:
    """When a plan version takes effect [s]; the approval (version 1): -inf (it is flown whole
    until a later version takes over)."""
    if plan_version(p) == 1:
        return -math.inf
    given = getattr(p, "effective_s", None)  # a record's PlanVersion carries it in seconds
    return float(given) if given is not None else stamp_s(p.effective_time)


def version_trajectory(p: Any) -> tuple[np.ndarray, np.ndarray]:
    """(times_s, points_m) of a plan version: a FlightPlan's waypoints, or a record's
    ``PlanVersion`` arrays."""
    if hasattr(p, "times_s"):
        return np.asarray(p.times_s, dtype=np.float64), np.asarray(p.points_m, dtype=np.float64).reshape(-1, 3)
    return trajectory_of(p)


def _at(t: np.ndarray, x: np.ndarray, when: float) -> np.ndarray:
    return np.array([np.interp(when, t, x[:, k]) for k in range(3)])


def _clip(t: np.ndarray, x: np.ndarray, lo: float, hi: float) -> tuple[np.ndarray, np.ndarray]:
    """The part of a piecewise-linear trajectory in [lo, hi] (endpoints interpolated)."""
    if not len(t) or hi < t[0] or lo > t[-1] or hi < lo:
        return np.zeros(0), np.zeros((0, 3))
    a, b = max(lo, t[0]), min(hi, t[-1])
    inside = (t > a) & (t < b)
    times = np.concatenate([[a], t[inside], [b]]) if b > a else np.array([a])
    pts = np.vstack([_at(t, x, a), x[inside], _at(t, x, b)]) if b > a else _at(t, x, a)[None, :]
    return times, pts


@dataclass
class Flown:
    """What one request flew: its versions in order, each version's part while in force
    (``segments``: (times, points, plan version), one per version, its first point kept: a
    reaction update's is where the aircraft was; none given: the whole trajectory is the first
    version's) and the whole as one trajectory (``times_s``, ``points_m``: the segments joined, a
    segment's first point replacing its predecessor's last); ``pieces``: (version, start_s,
    end_s) of each part."""

    key: str
    versions: list
    times_s: np.ndarray
    points_m: np.ndarray
    pieces: list = field(default_factory=list)
    segments: list = field(default_factory=list)

    @property
    def latest(self) -> Any:
        return self.versions[-1]

    def trajectories(self) -> list[tuple[np.ndarray, np.ndarray]]:
        """The parts in force, each a piecewise-linear trajectory of two points or more."""
        return [(t, x) for t, x, _p in self.parts()]

    def parts(self) -> list[tuple[np.ndarray, np.ndarray, Any]]:
        """(times, points, plan version) of each part in force of two points or more."""
        found = self.segments or [(self.times_s, self.points_m, self.versions[0] if self.versions else None)]
        return [s for s in found if len(s[0]) >= 2]


def reaction_update(p: Any) -> bool:
    """Whether plan version ``p`` is an update of the reaction to nonconformance
    (``uam_planner.nonconformance``): kind ``nonconforming``, or a contingency re-timed from the
    flight's observed progress rate (its reason says so). It starts where the aircraft was, not
    where its plan had it, and no constraint caused it."""
    return str(getattr(p, "update_kind", "")) == KIND or RATE_WORD in str(getattr(p, "reason", ""))


def chain_problems(key: str, versions: Sequence[Any], announced: dict[str, float]) -> list[str]:
    """Why the versions of one request do not chain (empty when they do); see the module docstring.

    ``versions``: its distinct plan versions sorted by version; ``announced``: constraint id ->
    the first instant [s] the planner had it in force (from ``uam/constraints``)."""
    out = []
    numbers = [plan_version(p) for p in versions]
    if numbers and numbers[0] != 1:
        out.append(f"{key}: version {numbers[0]} without version 1 (the approval)")
    for a, b in zip(numbers, numbers[1:]):
        if b == a:
            out.append(f"{key}: version {b} twice, with different contents")
        elif b != a + 1:
            out.append(f"{key}: version {b} follows version {a} (version {a + 1} missing)")
    for prev, p in zip(versions, versions[1:]):
        e, e_prev = effective_s(p), effective_s(prev)
        if e < e_prev:
            out.append(f"{key}: version {plan_version(p)} takes effect at {e:g} s, before version "
                       f"{plan_version(prev)} (at {e_prev:g} s)")
    for p in versions[1:]:
        ids = [str(i) for i in getattr(p, "constraint_ids", [])]
        e = effective_s(p)
        # an operator's modification and a yield name no constraint
        if not ids and not (reaction_update(p) or str(getattr(p, "update_kind", "")) in (KIND_YIELD, KIND_MODIFIED)):
            out.append(f"{key}: version {plan_version(p)} ({getattr(p, 'update_kind', '') or 'update'}) names no "
                       "constraint")
        for cid in ids:
            first = announced.get(cid)
            if first is None:
                out.append(f"{key}: version {plan_version(p)} names constraint {cid!r}, never announced on the "
                           "constraint topic")
            elif first > e + 1e-9:
                out.append(f"{key}: version {plan_version(p)} takes effect at {e:g} s, before constraint {cid!r} "
                           f"was announced ({first:g} s)")
    return out


def flown_trajectory(key: str, versions: Sequence[Any]) -> tuple[Flown, list[str]]:
    """The trajectory one request flew (see the module docstring) and any continuity problem.

    Each version counts from the instant it takes effect until the next one does. A part of no
    duration (a version replaced, or cancelled, the instant it began: a cancellation effective
    at the departure) flew nothing. A version taking over in the air continues the segment it
    takes over when it starts where the flight was (to CONTINUITY_M); a reaction update, which
    starts where the aircraft was rather than where its plan had it, starts a segment of its
    own with its first waypoint kept."""
    problems = []
    segments: list[tuple] = []   # (times, points, plan version) per version in force
    pieces = []
    for n, p in enumerate(versions):
        start = effective_s(p)
        end = effective_s(versions[n + 1]) if n + 1 < len(versions) else math.inf
        if not p.waypoints:
            continue  # a cancellation: nothing flown from here on (the previous part ends at `start`)
        t, x = version_trajectory(p)
        ct, cx = _clip(t, x, start, end)
        if len(ct) < 2 or not ct[-1] > ct[0]:
            continue  # in force for no time: nothing flown
        piece = (plan_version(p), float(ct[0]), float(ct[-1]))
        last = segments[-1] if segments else None
        if last is not None and ct[0] <= last[0][-1] + 1e-9:
            # taking over a flight in the air: it must start where the flight was
            gap = float(np.linalg.norm(last[1][-1] - cx[0]))
            # a nonconforming flight's update (uam_planner.nonconformance) starts where the
            # aircraft was, not where its plan was: that gap is why it was updated
            if gap > CONTINUITY_M and not reaction_update(p):
                problems.append(f"{key}: version {plan_version(p)} starts {gap:.3f} m from where version "
                                f"{plan_version(versions[n - 1])} had the flight at {ct[0]:g} s")
        segments.append((ct, cx, p))
        pieces.append(piece)
    times, points = [], []
    for st, sx, _p in segments:
        if times and times[-1][-1] >= st[0] - 1e-9:
            times[-1], points[-1] = times[-1][:-1], points[-1][:-1]  # where the aircraft was wins
        times.append(st)
        points.append(sx)
    if times:
        t_all, x_all = np.concatenate(times), np.vstack(points)
    else:
        t_all, x_all = np.zeros(0), np.zeros((0, 3))
    return Flown(key, list(versions), t_all, x_all, pieces, segments), problems


def constraint_intervals(sets: Sequence[tuple[float, Sequence[tuple[Any, float]]]]) -> list[tuple[Any, float, float]]:
    """(constraint version, from_s, until_s) for each constraint version the planner had in force:
    from the effective instant recorded with it until the set that replaced or dropped it (inf)."""
    out: dict[tuple[str, int], list] = {}
    order = sorted(sets, key=lambda s: s[0])
    for i, (t_s, found) in enumerate(order):
        present = {(c.constraint_id, c.version) for c, _eff in found}
        for c, eff in found:
            out.setdefault((c.constraint_id, c.version), [c, float(eff), math.inf])
        for k, entry in out.items():
            if k not in present and entry[2] == math.inf and t_s >= entry[1]:
                entry[2] = float(t_s)
    return [tuple(v) for v in out.values()]


def _segment_entry(p0, p1, t0, t1, c) -> float | None:
    """The earliest instant in [t0, t1] at which the straight segment p0 -> p1 is in the closed
    prism of ``c`` (region x band), or None."""
    import shapely

    z0, z1 = float(p0[2]), float(p1[2])
    lo, hi = float(c.lower_m), float(c.upper_m)
    if t1 > t0 and z1 != z0:  # the band as an interval of t
        ta = t0 + (lo - z0) / (z1 - z0) * (t1 - t0) if math.isfinite(lo) else -math.inf
        tb = t0 + (hi - z0) / (z1 - z0) * (t1 - t0) if math.isfinite(hi) else math.inf
        ta, tb = min(ta, tb), max(ta, tb)
        a, b = max(t0, ta), min(t1, tb)
        if a > b:
            return None
    else:
        if not (lo <= z0 <= hi):
            return None
        a, b = t0, t1

    def at(t):
        s = 0.0 if t1 == t0 else (t - t0) / (t1 - t0)
        return (float(p0[0]) + s * (float(p1[0]) - float(p0[0])), float(p0[1]) + s * (float(p1[1]) - float(p0[1])))

    qa, qb = at(a), at(b)
    seg = shapely.LineString([qa, qb]) if qa != qb else shapely.Point(qa)
    if c.kind == "circle":
        center = shapely.Point(c.center_m)
        if seg.distance(center) > c.radius_m:
            return None
        if center.distance(shapely.Point(qa)) <= c.radius_m:
            return a
        # first root of |qa + s d - C| = r along the segment
        dx, dy = qb[0] - qa[0], qb[1] - qa[1]
        fx, fy = qa[0] - c.center_m[0], qa[1] - c.center_m[1]
        A, B, C = dx * dx + dy * dy, 2 * (fx * dx + fy * dy), fx * fx + fy * fy - c.radius_m ** 2
        s = (-B - math.sqrt(max(B * B - 4 * A * C, 0.0))) / (2 * A)
        return a + min(max(s, 0.0), 1.0) * (b - a)
    poly = shapely.Polygon(c.rings_m[0], list(c.rings_m[1:]))
    hit = seg.intersection(poly)
    if hit.is_empty:
        return None
    if seg.geom_type == "Point":
        return a
    length = seg.length
    coords = shapely.get_coordinates(hit)
    s = min(seg.project(shapely.Point(q)) for q in coords) / length
    return a + s * (b - a)


@dataclass
class Incursion:
    """A flown trajectory inside a constraint while it was in force."""

    key: str
    constraint_id: str
    constraint_version: int
    t_s: float
    what: str = "volume"   # "volume", "departure" or "arrival"
    #: already inside at the instant the version came into force (a zone that appears with no
    #: lead time over an airborne flight): no plan could have avoided it; reported all the same
    inside_at_start: bool = False

    def describe(self) -> str:
        return (f"{self.key} enters constraint {self.constraint_id!r} v{self.constraint_version} "
                f"({self.what}) at t = {self.t_s:g} s" +
                (" (already inside when it came into force: unavoidable)" if self.inside_at_start else ""))


def pad_of(network, vertiport_id: str, xy) -> int | None:
    """The index of the pad of ``vertiport_id`` nearest to ``xy`` (ENU m), as the planner tells
    it (``uam_planner.replanning.pad_of_point``); None without a network or for a vertiport it
    does not know."""
    from uam_planner.network import NetworkError
    from uam_planner.replanning import pad_of_point

    if network is None:
        return None
    try:
        return pad_of_point(network, network.node_index(vertiport_id), xy)
    except NetworkError:  # an unknown id: the pad cannot be told
        return None


def incursions(flown: Iterable[Flown], intervals: Sequence[tuple[Any, float, float]],
               network=None) -> list[Incursion]:
    """Every entry of a flown trajectory into a constraint version while it was in force and in
    its window (see the module docstring), earliest per (flight, constraint version). A closure
    of one pad (``pad_index``) is entered by a departure or arrival at that pad, told from the
    ``network``'s pad layout; without a network the pad cannot be told, and such an entry is
    reported with "(pad not known)"."""
    out = []
    for f in flown:
        if len(f.times_s) < 1:
            continue
        t = f.times_s
        for c, since, until in intervals:
            lo_t, hi_t = max(since, float(c.start_s)), min(until, float(c.end_s))
            if not hi_t > lo_t:
                continue
            if c.kind == "closure":
                latest = f.latest
                for what, when, node, xy in (
                        ("departure", float(t[0]), getattr(f.versions[0], "origin_id", ""), f.points_m[0]),
                        ("arrival", float(t[-1]), getattr(latest, "destination_id", ""), f.points_m[-1])):
                    if node != c.vertiport_id or not lo_t <= when < hi_t:
                        continue
                    pad = getattr(c, "pad_index", None)
                    if pad is not None:
                        found = pad_of(network, node, xy)
                        if found is not None and found != pad:
                            continue  # another pad of the vertiport: open
                        if found is None:
                            what += " (pad not known)"
                    out.append(Incursion(f.key, c.constraint_id, c.version, when, what))
                continue
            first = None
            for st, sx in f.trajectories():
                when = _first_entry(st, sx, lo_t, hi_t, c)
                if when is not None and (first is None or when < first):
                    first = when
            if first is not None:
                out.append(Incursion(f.key, c.constraint_id, c.version, float(first),
                                     inside_at_start=bool(first <= lo_t and t[0] < lo_t)))
    return sorted(out, key=lambda i: (i.t_s, i.key, i.constraint_id))


def _first_entry(t: np.ndarray, x: np.ndarray, lo_t: float, hi_t: float, c) -> float | None:
    """The earliest instant in [lo_t, hi_t) at which the trajectory (t, x) is inside ``c``."""
    for k in range(len(t) - 1):
        a, b = max(t[k], lo_t), min(t[k + 1], hi_t)
        if a > b or t[k + 1] < lo_t or t[k] >= hi_t:
            continue
        p0, p1 = _at(t[k:k + 2], x[k:k + 2], a), _at(t[k:k + 2], x[k:k + 2], b)
        when = _segment_entry(p0, p1, a, b, c)
        if when is not None and when < hi_t:
            return when
    return None


def announced_at(sets: Sequence[tuple[float, Sequence[tuple[Any, float]]]]) -> dict[str, float]:
    """constraint id -> the first instant [s] the planner had any version of it in force."""
    out: dict[str, float] = {}
    for _t, found in sets:
        for c, eff in found:
            out[c.constraint_id] = min(out.get(c.constraint_id, math.inf), float(eff))
    return out


def contingency(p: Any) -> bool:
    """Whether plan version ``p`` is a contingency (F3548 Contingent): the flight could not be
    saved by a deconflicted re-plan, so this version is not deconflicted by design."""
    return str(getattr(p, "update_kind", "")) == KIND_CONTINGENCY or \
        int(getattr(p, "state", 0) or 0) == STATE_CONTINGENT


__all__ = ["announced_at", "CONTINUITY_M", "Flown", "Incursion", "chain_problems", "constraint_intervals",
           "contingency", "effective_s", "flown_trajectory", "incursions", "pad_of", "plan_version",
           "version_trajectory"]
