"""The conformance check of a flight to its plan and what the planner itself knows of where its
flights are, free of ROS.

A flight is *conforming* at time t, at position q, when q lies within bounds of its plan (the
intent's volumes of ASTM F3548-21, here a tube around the 4D trajectory): with p the point of the
planned path nearest to q (3D, exact per segment) and tau* its planned time, the **lateral**
error |q - p| horizontally <= ``lateral_m``, the **vertical** error |q_z - p_z| <= ``vertical_m``
and the **time** error |t - tau*| <= ``time_s`` (:func:`deviations`, :func:`conforming`). The same
test serves the conformance monitor (``uam_sim.world.conformance``, which imports it from here)
and the planner, which checks every report against its own plan (:func:`verify`) with its own
observations (:class:`PositionBook`). The reaction to a nonconforming flight is
:mod:`uam_planner.nonconformance`.
"""

from __future__ import annotations

import bisect
import math
from dataclasses import dataclass

import numpy as np
from uam_contract.params import CONFORMANCE_MONITOR

from .trajectory import Trajectory

_DEFAULTS = {prm.name: prm.default for prm in CONFORMANCE_MONITOR}  # one source: the node's table

#: the planner acts on its own observation only if it is at most this old at the epoch [s]
MAX_AGE_S = 10.0
#: the progress rate is estimated over the observations of the last SPEED_WINDOW_S seconds [s]
SPEED_WINDOW_S = 120.0
#: ... from at least this much time (else from the plan's departure) [s]
MIN_SPEED_SPAN_S = 10.0
#: a rate read from less than this time on the plan version (since its departure, within the
#: window) is drawn towards 1 (the aircraft flies the version it was given) in proportion:
#: ``1 + (rate - 1) x span / RATE_FULL_SPAN_S``. Measured over the 893 reaction
#: updates of ten Monte-Carlo runs (10 % speed error, the reaction every 5 s, probe 120 s):
#: rates read from under 60 s of a version had an SD of 0.12-0.14, from 60 s or more 0.047;
#: 31 updates timed from the short ones were reported nonconforming again within 90 s (9 of
#: them left as contingencies), none of the long ones; and in 5 of the 6 runs with a flown
#: loss with a contingency the contingency went back to a rate read from 25 s or less (one
#: of 1.33 read in a climb 10 s after departure) [s]
RATE_FULL_SPAN_S = 60.0
#: the estimated progress rate is clipped to this range (performance: an eVTOL does not fly
#: at half or twice its planned speed; a wild estimate would not be flown anyway)
RATE_RANGE = (0.5, 1.5)
_EPS_T = 1e-9


@dataclass(frozen=True)
class ConformanceBounds:
    """The tube around a plan: lateral [m], vertical [m] and time [s] bounds (inclusive);
    defaults: the conformance monitor node's (uam_contract.params.CONFORMANCE_MONITOR)."""

    lateral_m: float = _DEFAULTS["lateral_m"]
    vertical_m: float = _DEFAULTS["vertical_m"]
    time_s: float = _DEFAULTS["time_s"]

    def __post_init__(self):
        for name in ("lateral_m", "vertical_m", "time_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v <= 0:
                raise ValueError(f"ConformanceBounds.{name}: {v!r} must be a positive finite number")


#: the scales of a match between a sample and a pass of its plan (:func:`nearest`, with the
#: sample's time): the pass whose larger of distance / MATCH_M and |planned - sampled time| /
#: MATCH_S is least (the default lateral and time bounds of the conformance monitor: if a pass
#: has the sample inside both, the one chosen does). Where a plan comes back over itself (a
#: turn-back, a diversion along the way it came) the passes lie a few metres apart and the one
#: meant is the one at the right time. When the nearest pass won unless another was
#: within 1 m of it: in seed 12 of the Monte-Carlo (15 m buffer) a flight diverted
#: back along its way flew its return on time 1.7 m from the outbound pass, was read 14.9 s
#: late, declared nonconforming and sent back out as a contingency into a flown loss
MATCH_M = float(_DEFAULTS["lateral_m"])
MATCH_S = float(_DEFAULTS["time_s"])


def nearest(plan: Trajectory, points_m, times_s=None) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """For each point (n, 3): the plan's segment index j, the share along it, the nearest point
    of the planned path (3D, exact per segment) and its planned time tau*.

    With ``times_s`` (n,), the times of the points: the segment whose larger of distance /
    ``MATCH_M`` and |tau* - time| / ``MATCH_S`` is least (the first of equals). Without it, the
    nearest segment: a path that doubles back matches every point to its earlier pass (a flight
    flying its turn-back on time read as late by the whole out-and-back)."""
    q = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    a = plan.points_m[:-1]                     # (s, 3)
    d = plan.points_m[1:] - a
    dd = np.square(d).sum(axis=1)
    rel = q[:, None, :] - a[None, :, :]        # (n, s, 3)
    lam = np.where(dd > 0, (rel * d[None]).sum(axis=2) / np.where(dd > 0, dd, 1.0), 0.0)
    lam = np.clip(lam, 0.0, 1.0)
    near = a[None] + lam[..., None] * d[None]
    dist2 = np.square(q[:, None, :] - near).sum(axis=2)
    t0, t1 = plan.times_s[:-1], plan.times_s[1:]
    if times_s is None:
        j = np.argmin(dist2, axis=1)
    else:
        t = np.asarray(times_s, dtype=np.float64).reshape(-1)
        taus = t0[None] + lam * (t1 - t0)[None]
        j = np.argmin(np.maximum(np.sqrt(dist2) / MATCH_M, np.abs(taus - t[:, None]) / MATCH_S),
                      axis=1)
    rows = np.arange(q.shape[0])
    lj = lam[rows, j]
    tau = t0[j] + lj * (t1[j] - t0[j])
    return j, lj, near[rows, j], tau


def deviations(plan: Trajectory, times_s, points_m) -> tuple[np.ndarray, np.ndarray, np.ndarray]:
    """Lateral [m], vertical [m] (signed: above) and time [s] (positive = late) errors of
    samples against ``plan``, each against the path point nearest in space (nearest in planned
    time among passes as near: :func:`nearest`). Args: ``times_s`` (n,), ``points_m`` (n, 3).
    O(n p).

    Examples:
        A plan east at 10 m/s; the aircraft is 20 m north of it at 50 s, at the point planned
        for 48 s (2 s late), within the monitor's default bounds:

        >>> import numpy as np
        >>> from uam_planner.trajectory import Trajectory
        >>> plan = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0, 100], [1000.0, 0, 100]]))
        >>> lat, ver, late = deviations(plan, [50.0], [[480.0, 20.0, 100.0]])
        >>> lat.tolist(), ver.tolist(), late.tolist()
        ([20.0], [0.0], [2.0])
        >>> conforming(lat, ver, late, ConformanceBounds()).tolist()
        [True]
    """
    t = np.asarray(times_s, dtype=np.float64).reshape(-1)
    q = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    _j, _l, pt, tau = nearest(plan, q, t)
    off = q - pt
    return np.sqrt(np.square(off[:, :2]).sum(axis=1)), off[:, 2], t - tau


def conforming(lateral, vertical, time_err, bounds: ConformanceBounds) -> np.ndarray:
    """True where every error is within its bound (inclusive)."""
    return ((np.asarray(lateral) <= bounds.lateral_m) & (np.abs(vertical) <= bounds.vertical_m)
            & (np.abs(time_err) <= bounds.time_s))


# ---- what the planner itself knows ----------------------------------------------------------

@dataclass(frozen=True)
class Observation:
    t_s: float
    position_m: tuple


#: observations kept per vehicle at most (a flood of forged fleet states cannot grow the book
#: without bound; at the simulator's 1 s step the window holds about 120)
MAX_OBSERVATIONS = 1024


class PositionBook:
    """The planner's own observations of the airborne vehicles (from the fleet state), per
    request id, in time order. Observations are pruned to the last ``SPEED_WINDOW_S`` seconds
    before the planner's epoch time (:meth:`prune`), not before the newest observation, and
    every reader takes an ``until`` time: an observation stamped after the epoch (a forged or
    a clock-skewed one) is not used before its time and cannot push the real ones out."""

    def __init__(self):
        self._obs: dict[str, list] = {}

    def __len__(self) -> int:
        """The number of vehicles with observations."""
        return len(self._obs)

    def observe(self, request_id: str, t_s: float, position_m) -> str | None:
        """Record one observation; return None, or why it was refused (naming the field)."""
        if not isinstance(request_id, str) or not request_id:
            return f"request_id: {request_id!r} is not a non-empty string"
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
                or not math.isfinite(t_s):
            return f"t_s: {t_s!r} is not a finite time"
        p = np.asarray(position_m, dtype=np.float64).reshape(-1)
        if p.shape != (3,) or not np.isfinite(p).all():
            return f"position_m: {position_m!r} is not three finite numbers"
        q = self._obs.setdefault(request_id, [])
        t = float(t_s)
        if q and t <= q[-1].t_s:
            i = bisect.bisect_left(q, t, key=lambda o: o.t_s)
            if i < len(q) and q[i].t_s == t:
                return None  # a repeated sample: the first one is kept
            q.insert(i, Observation(t, tuple(float(x) for x in p)))
        else:
            q.append(Observation(t, tuple(float(x) for x in p)))
        if len(q) > MAX_OBSERVATIONS:
            del q[0]
        return None

    def observe_many(self, request_ids, t_s: float, positions_m) -> str | None:
        """Record one observation per vehicle of a fleet state at ``t_s`` [s]: ``positions_m``
        (n, 3), row i the position of ``request_ids[i]``; the same as :meth:`observe` of each
        row, checked per array instead of per row. Returns None, or why rows (or the state)
        were refused (naming the field); the other rows are recorded."""
        ids = list(request_ids)
        if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
                or not math.isfinite(t_s):
            return f"t_s: {t_s!r} is not a finite time"
        p = np.asarray(positions_m, dtype=np.float64)
        if p.shape != (len(ids), 3):
            return f"positions_m: shape {p.shape} for {len(ids)} vehicles"
        ok = np.isfinite(p).all(axis=1)
        refused = []
        t = float(t_s)
        for rid, row, good in zip(ids, p.tolist(), ok.tolist()):
            if not good or not isinstance(rid, str) or not rid:
                refused.append(self.observe(rid, t, row))
                continue
            q = self._obs.setdefault(rid, [])
            if q and t <= q[-1].t_s:
                self.observe(rid, t, row)   # not after the newest: the general path
                continue
            q.append(Observation(t, tuple(row)))
            if len(q) > MAX_OBSERVATIONS:
                del q[0]
        return f"{len(refused)} of {len(ids)} rows refused, the first: {refused[0]}" if refused else None

    def prune(self, t_s: float) -> None:
        """Drop the observations older than ``SPEED_WINDOW_S`` before the epoch at ``t_s``."""
        lo = float(t_s) - SPEED_WINDOW_S
        for q in self._obs.values():
            if q and q[0].t_s < lo:
                del q[:bisect.bisect_left(q, lo, key=lambda o: o.t_s)]

    def _upto(self, request_id: str, until: float | None) -> list:
        q = self._obs.get(request_id) or []
        if until is None or not q or q[-1].t_s <= until + _EPS_T:
            return q
        return q[:bisect.bisect_right(q, until + _EPS_T, key=lambda o: o.t_s)]

    def latest(self, request_id: str, until: float | None = None) -> Observation | None:
        """The newest observation of ``request_id`` (stamped at or before ``until``)."""
        q = self._upto(request_id, until)
        return q[-1] if q else None

    def observations(self, request_id: str, since: float, until: float) -> list:
        """The observations of ``request_id`` stamped in [since, until], in time order."""
        q = self._upto(request_id, until)
        return q[bisect.bisect_left(q, float(since), key=lambda o: o.t_s):]

    def forget(self, keep_ids) -> None:
        """Drop every vehicle not in ``keep_ids`` (landed flights)."""
        keep = set(keep_ids)
        for k in [k for k in self._obs if k not in keep]:
            del self._obs[k]

    def progress_rate(self, request_id: str, plan: Trajectory, until: float | None = None) -> float:
        """The observed progress rate along ``plan``: planned seconds covered per second, from
        the oldest observation of the window to the newest (the planned time of each one's
        nearest path point), or, with less than ``MIN_SPEED_SPAN_S`` of observations, from the
        plan's departure to the newest; 1 without observations; drawn towards 1 while the
        version has flown less than ``RATE_FULL_SPAN_S`` within the window (a rate read from a
        few seconds is mostly gusts and climbs); clipped to ``RATE_RANGE``.
        Only observations stamped in [the plan's departure, ``until``] count: one made before
        this version began was made against an older one (a nonconforming update starts where
        the aircraft was, so an older sighting projects onto its first point and would read as
        standing still; the rate, relative to this version, would collapse towards
        ``RATE_RANGE[0]`` and the next update be timed far too slow)."""
        q = self._upto(request_id, until)
        if q and q[0].t_s < plan.departure_s - _EPS_T:
            q = q[bisect.bisect_left(q, float(plan.departure_s) - _EPS_T, key=lambda o: o.t_s):]
        if not q:
            return 1.0
        last = q[-1]
        first = q[0]
        if last.t_s - first.t_s >= MIN_SPEED_SPAN_S:
            _j, _l, _p, tau = nearest(plan, np.array([first.position_m, last.position_m]),
                                      [first.t_s, last.t_s])
            rate = (tau[1] - tau[0]) / (last.t_s - first.t_s)
        elif last.t_s - plan.departure_s >= MIN_SPEED_SPAN_S:
            _j, _l, _p, tau = nearest(plan, np.array([last.position_m]), [last.t_s])
            rate = (tau[0] - plan.departure_s) / (last.t_s - plan.departure_s)
        else:
            return 1.0
        # the evidence: how long the aircraft has flown this version, within the window
        span = last.t_s - max(float(plan.departure_s), last.t_s - SPEED_WINDOW_S)
        if span < RATE_FULL_SPAN_S:
            rate = 1.0 + (rate - 1.0) * max(span, 0.0) / RATE_FULL_SPAN_S
        return float(np.clip(rate, *RATE_RANGE))


@dataclass(frozen=True)
class Claim:
    """A nonconformance report, as received: who says which flight is nonconforming when."""

    request_id: str
    t_s: float
    source: str = ""


def verify(flight, obs: Observation | None, bounds: ConformanceBounds, t_eff: float):
    """Check a claim about ``flight`` against the planner's own knowledge at the epoch ``t_eff``.

    Returns (errors (lateral, vertical, time), None) when the planner's own newest observation,
    at most ``MAX_AGE_S`` old, is outside ``bounds`` of the flight's current plan after its
    departure; else (None, the reason naming what did not hold).

    A sighting after the plan's arrival counts: the vehicle is still in the
    fleet state, so it is still in the air, late, and F3548 asks its intent to be updated like
    any other nonconforming one's. Before, such a flight flew the end of its plan with no
    update (held past it, ``overruns``): excursions of 11-15 s at the end of 3 of 174
    Monte-Carlo runs (F3548: at most 10 s)."""
    if obs is None:
        return None, f"request_id: {flight.request_id!r} has no fleet state the planner saw"
    if obs.t_s > t_eff + _EPS_T or obs.t_s < t_eff - MAX_AGE_S:
        return None, (f"fleet state of {flight.request_id!r} at t = {obs.t_s:g} s is not within "
                      f"{MAX_AGE_S:g} s before the epoch at {t_eff:g} s")
    tr = flight.trajectory
    if not tr.departure_s < obs.t_s:
        return None, (f"request_id: {flight.request_id!r} is not airborne on its plan at t = "
                      f"{obs.t_s:g} s (it departs at {tr.departure_s:g} s)")
    lat, ver, terr = (float(x[0]) for x in deviations(tr, [obs.t_s], [obs.position_m]))
    if bool(conforming(lat, ver, terr, bounds)):
        return None, (f"request_id: {flight.request_id!r} conforms in the planner's own view at "
                      f"t = {obs.t_s:g} s (lateral {lat:.1f} m, vertical {ver:.1f} m, time "
                      f"{terr:.1f} s within {bounds.lateral_m:g} m, {bounds.vertical_m:g} m, "
                      f"{bounds.time_s:g} s)")
    return (lat, ver, terr), None

