"""Conformance monitoring: each flight compared with its plan, free of ROS.

A flight is *conforming* at time t, at flown position q, when q lies within the documented bounds
of its plan (the intent's volumes of ASTM F3548-21, here a tube around the 4D trajectory):

- the reference point is the point of the planned path nearest to q in 3D (segment by segment,
  exact), and its planned time tau* (linear along that segment);
- **lateral error**: the horizontal distance from q to that point, at most ``lateral_m``;
- **vertical error**: the height of q above that point (signed), at most ``vertical_m`` in size;
- **time error**: ``t - tau*`` (positive = late), at most ``time_s`` in size.

Outside any bound the flight is *Nonconforming*; an *excursion* is a maximal run of
nonconforming samples, from its first nonconforming sample to the first conforming one after it
(or the flight's last sample): its duration is resolved to the sampling step. Its size is the
largest lateral, vertical and time error inside it.

Per run, the F3548 statistics (:func:`f3548_statistics`): share of flight time in conformance
(each sample counts for the interval to the next one), excursions per flight hour and the longest
excursion, against F3548's thresholds taken from ``uas_standards``: at least
``OiMinConformancePercent`` (95) % of time, at most ``OiMaxExcursionsPerFlightHour`` (18) per
flight hour, each at most ``OiMaxDurationPerExcursionSeconds`` (10) s.

Why the bounds relate to the planning buffers (docs/disturbances.md): two flights that both
conform are each within ``sqrt(lateral_m^2 + vertical_m^2)`` of a point of their plan whose
planned time is within ``time_s`` of now.
"""

from __future__ import annotations

from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np
from uas_standards.astm.f3548.v21 import constants as f3548

from uam_planner.trajectory import Trajectory

MIN_CONFORMANCE_PERCENT = float(f3548.OiMinConformancePercent)          # 95
MAX_EXCURSIONS_PER_FLIGHT_HOUR = float(f3548.OiMaxExcursionsPerFlightHour)  # 18
MAX_EXCURSION_S = float(f3548.OiMaxDurationPerExcursionSeconds)         # 10
#: a nonconforming intent must be updated within this long (F3548; the reaction, item 3)
MAX_UPDATE_NONCONFORMING_S = float(f3548.OiMaxUpdateTimeNonconfSeconds)  # 5


# the tube's bounds, the nearest-point errors and the inclusive test live below the simulator, in
# the planner, which checks every conformance report against its own plan with the same code
# (uam_planner.nonconformance)
from uam_planner.conformance import ConformanceBounds, conforming, deviations  # noqa: E402,F401


@dataclass(frozen=True)
class Excursion:
    """One excursion of one flight: start, end [s], and the largest errors inside it."""

    flight_id: str
    start_s: float
    end_s: float
    max_lateral_m: float
    max_vertical_m: float
    max_time_s: float

    @property
    def duration_s(self) -> float:
        return self.end_s - self.start_s


@dataclass
class TrackConformance:
    """One flight's conformance over its flown track."""

    flight_id: str
    times_s: np.ndarray
    conforming: np.ndarray
    lateral_m: np.ndarray
    vertical_m: np.ndarray
    time_err_s: np.ndarray
    excursions: list = field(default_factory=list)

    @property
    def flight_s(self) -> float:
        return float(self.times_s[-1] - self.times_s[0]) if self.times_s.size else 0.0

    @property
    def conforming_s(self) -> float:
        """Time in conformance: each sample counts for the interval to the next one."""
        if self.times_s.size < 2:
            return self.flight_s
        return float((np.diff(self.times_s) * self.conforming[:-1]).sum())

    @property
    def first_nonconforming_s(self) -> float | None:
        bad = np.flatnonzero(~self.conforming)
        return float(self.times_s[bad[0]]) if bad.size else None


def excursions_of(flight_id: str, times_s, ok, lateral, vertical, time_err) -> list[Excursion]:
    """The maximal runs of nonconforming samples (see the module)."""
    times_s = np.asarray(times_s, dtype=np.float64)
    ok = np.asarray(ok, dtype=bool)
    out = []
    n = ok.shape[0]
    i = 0
    while i < n:
        if ok[i]:
            i += 1
            continue
        j = i
        while j < n and not ok[j]:
            j += 1
        end = times_s[j] if j < n else times_s[n - 1]
        out.append(Excursion(flight_id, float(times_s[i]), float(end),
                             float(np.max(lateral[i:j])), float(np.max(np.abs(vertical[i:j]))),
                             float(np.max(np.abs(time_err[i:j])))))
        i = j
    return out


def track_conformance(flight_id: str, plan: Trajectory, flown: Trajectory,
                      bounds: ConformanceBounds, step_s: float | None = None) -> TrackConformance:
    """Conformance of a flown track with its plan, at the flown track's samples or every
    ``step_s`` from its departure (its arrival included)."""
    if step_s is None:
        times = flown.times_s
        pts = flown.points_m
    else:
        times = np.arange(flown.departure_s, flown.arrival_s, float(step_s))
        if times.size == 0 or times[-1] < flown.arrival_s:
            times = np.append(times, flown.arrival_s)
        pts = flown.position_at(times, clamp=True)
    lat, ver, terr = deviations(plan, times, pts)
    ok = conforming(lat, ver, terr, bounds)
    return TrackConformance(flight_id, np.asarray(times), ok, lat, ver, terr,
                            excursions_of(flight_id, times, ok, lat, ver, terr))


def versioned_conformance(flight_id: str, pieces, flown: Trajectory,
                          bounds: ConformanceBounds) -> TrackConformance:
    """Conformance of a flown track with the plan versions in force while it flew: ``pieces``
    [(from_s, plan)] in time order, each sample compared with the last version that took
    effect at or before it (a nonconforming update is a new intent from where the aircraft
    is: the flight is compared with it from then on)."""
    times, pts = flown.times_s, flown.points_m
    starts = np.array([p[0] for p in pieces], dtype=np.float64)
    which = np.clip(np.searchsorted(starts, times, side="right") - 1, 0, len(pieces) - 1)
    lat = np.empty(times.shape[0])
    ver = np.empty(times.shape[0])
    terr = np.empty(times.shape[0])
    for k, (_t0, plan) in enumerate(pieces):
        sel = which == k
        if sel.any():
            lat[sel], ver[sel], terr[sel] = deviations(plan, times[sel], pts[sel])
    ok = conforming(lat, ver, terr, bounds)
    return TrackConformance(flight_id, np.asarray(times), ok, lat, ver, terr,
                            excursions_of(flight_id, times, ok, lat, ver, terr))


@dataclass(frozen=True)
class F3548Statistics:
    """A run's conformance statistics and F3548's verdicts on them."""

    flights: int
    flight_hours: float
    conformance_percent: float
    excursions: int
    excursions_per_flight_hour: float
    longest_excursion_s: float
    nonconforming_flights: int

    @property
    def meets_time(self) -> bool:
        return self.conformance_percent >= MIN_CONFORMANCE_PERCENT

    @property
    def meets_rate(self) -> bool:
        return self.excursions_per_flight_hour <= MAX_EXCURSIONS_PER_FLIGHT_HOUR

    @property
    def meets_duration(self) -> bool:
        return self.longest_excursion_s <= MAX_EXCURSION_S

    def as_dict(self) -> dict:
        return {"flights": self.flights, "flight_hours": self.flight_hours,
                "conformance_percent": self.conformance_percent, "excursions": self.excursions,
                "excursions_per_flight_hour": self.excursions_per_flight_hour,
                "longest_excursion_s": self.longest_excursion_s,
                "nonconforming_flights": self.nonconforming_flights,
                "f3548_time_ok": self.meets_time, "f3548_rate_ok": self.meets_rate,
                "f3548_duration_ok": self.meets_duration}


def f3548_statistics(tracks: Iterable[TrackConformance]) -> F3548Statistics:
    """The F3548 statistics over every flight of a run (100 % and 0 excursions when none flew)."""
    tracks = list(tracks)
    total = sum(tr.flight_s for tr in tracks)
    ok = sum(tr.conforming_s for tr in tracks)
    exc = [e for tr in tracks for e in tr.excursions]
    hours = total / 3600.0
    return F3548Statistics(
        flights=len(tracks), flight_hours=hours,
        conformance_percent=100.0 * ok / total if total > 0 else 100.0,
        excursions=len(exc),
        excursions_per_flight_hour=len(exc) / hours if hours > 0 else 0.0,
        longest_excursion_s=max((e.duration_s for e in exc), default=0.0),
        nonconforming_flights=sum(1 for tr in tracks if tr.excursions))


@dataclass(frozen=True)
class ConformanceState:
    """One flight at one sample of the streaming monitor."""

    flight_id: str
    t_s: float
    conforming: bool
    lateral_m: float
    vertical_m: float
    time_err_s: float
    excursion_start_s: float | None   # while nonconforming: when the excursion began


class ConformanceMonitor:
    """Streaming form for a node: plans in (``set_plan``), fleet samples in (``update``), the
    state of each sampled flight out; every finished excursion kept (``excursions``), and the
    per-flight samples for :meth:`statistics`."""

    def __init__(self, bounds: ConformanceBounds | None = None):
        self.bounds = bounds or ConformanceBounds()
        self._plans: dict[str, Trajectory] = {}
        self._open: dict[str, list] = {}        # id -> [start, max lat, max vert, max time]
        self._samples: dict[str, list] = {}     # id -> [(t, ok, lat, vert, terr)]
        self.excursions: list[Excursion] = []

    def set_plan(self, flight_id: str, plan: Trajectory) -> None:
        """The plan (or a new version of it) the flight is compared with from now on."""
        self._plans[flight_id] = plan

    def has_plan(self, flight_id: str) -> bool:
        return flight_id in self._plans

    @property
    def open_excursions(self) -> int:
        """Flights nonconforming at their last sample (excursions begun, not yet over)."""
        return len(self._open)

    def update(self, t_s: float, flight_ids: Sequence[str], positions_m) -> list[ConformanceState]:
        """States of the sampled flights that have a plan (the others are skipped)."""
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        out = []
        for fid, q in zip(flight_ids, pos):
            plan = self._plans.get(fid)
            if plan is None:
                continue
            lat, ver, terr = (float(x[0]) for x in deviations(plan, [t_s], q[None]))
            ok = bool(conforming(lat, ver, terr, self.bounds))
            self._samples.setdefault(fid, []).append((float(t_s), ok, lat, ver, terr))
            ex = self._open.get(fid)
            if not ok:
                if ex is None:
                    ex = self._open[fid] = [float(t_s), 0.0, 0.0, 0.0]
                ex[1], ex[2], ex[3] = max(ex[1], lat), max(ex[2], abs(ver)), max(ex[3], abs(terr))
            elif ex is not None:
                self.excursions.append(Excursion(fid, ex[0], float(t_s), ex[1], ex[2], ex[3]))
                del self._open[fid]
                ex = None
            out.append(ConformanceState(fid, float(t_s), ok, lat, ver, terr, ex[0] if ex else None))
        return out

    def tracks(self) -> list[TrackConformance]:
        """Per flight, the samples seen so far as a TrackConformance (excursions included)."""
        out = []
        for fid, rows in sorted(self._samples.items()):
            a = np.array(rows, dtype=np.float64)
            t, ok = a[:, 0], a[:, 1].astype(bool)
            out.append(TrackConformance(fid, t, ok, a[:, 2], a[:, 3], a[:, 4],
                                        excursions_of(fid, t, ok, a[:, 2], a[:, 3], a[:, 4])))
        return out

    def statistics(self) -> F3548Statistics:
        return f3548_statistics(self.tracks())
