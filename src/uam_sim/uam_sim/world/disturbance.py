"""Disturbances: what an aircraft flies when the world is not the plan's, free of ROS.

A planned 4D trajectory and the flight's draws (speed error, departure delay) go in; the flown
trajectory comes out, sampled every ``step_s`` and linear between samples (the simulator flies it
as it flies a plan: ``Fleet.add``). Off by default: a :class:`DisturbanceConfig` with every level 0
returns the planned trajectory itself, so the paper's mode is unchanged bit for bit.

The world (seeded by ``DisturbanceConfig.seed``):

- **wind**: a steady wind (``wind_speed_mps`` from ``wind_from_deg``, meteorological: 270 = from
  the west) plus gusts, a field over horizontal position and time: the sum of ``GUST_MODES``
  random plane waves (wavelengths and periods drawn around ``gust_length_m`` and
  ``gust_period_s``) whose two horizontal components each have the standard deviation
  ``gust_std_mps``. The same field for every aircraft, a pure function of (x, y, t).
- **speed error**: each flight's airspeed is ``(1 + e)`` times the plan's on every segment, e
  uniform in ``[-speed_error, +speed_error]`` (0.1 = the +-10 % of NASA's study).
- **departure delay**: exponential with mean ``delay_mean_s``, truncated at ``delay_max_s``.
- **vertical** (off unless set): vertical gusts, a field like the horizontal one (its own seeded
  plane waves, standard deviation ``vertical_gust_std_mps``), and an altitude-hold error per
  flight, uniform in ``[-altitude_error_m, +altitude_error_m]`` (a barometric bias: the height
  the aircraft's altitude hold settles at above its plan).

The path-following model (one flight, every step ``dt``):

- along track, the aircraft holds its airspeed ``va = (1 + e) v_plan(segment)`` (not the plan's
  ground speed) or, with time control (``time_gain_per_s`` k_t > 0), ``va = (1 + e) (v_plan + c)``
  with ``c = k_t (s_plan(t) - s)`` clipped to ``+-max_speed_adjust v_plan`` (s the along-track
  distance flown, s_plan the plan's at t): its ground speed along the path is ``sqrt(va^2 - c^2) + w_along`` where
  ``w_along`` is the wind's component along the segment's horizontal direction and ``c`` the
  steady cross-track wind it crabs against (known, so compensated: with
  ``compensate_steady_wind`` false no crab, ``c = 0``, and the whole cross wind drifts it), at
  least ``MIN_GROUND_SPEED_SHARE`` of ``va``; vertical segments (climb, descent at pads) move at
  ``va``, wind does not change the vertical speed. So the aircraft is early or late along its
  path but follows its geometry.
- across track, the horizontal offset ``d`` (2D, from the commanded point on the path) obeys
  ``d' = g - k d`` with ``g`` the uncompensated horizontal wind across the track (the gusts'
  cross component; the whole cross wind without the crab) and ``k = track_gain_per_s`` the
  guidance gain, integrated exactly for ``g`` held over the step:
  ``d <- d exp(-k dt) + g (1 - exp(-k dt)) / k``; its norm is clipped at ``max_lateral_m``
  (the bound of the guidance). A steady uncompensated cross wind ``w`` settles at ``w / k``.
- the flown position is the path point at the along-track distance plus ``(d, 0)``; the flight
  ends (lands) when the along-track distance reaches the path's length, at the time found by
  linear interpolation inside that step.
- vertically, on level (horizontal) segments, the height offset ``h`` from the path obeys
  ``h' = w_z - k_z (h - b)`` with ``w_z`` the vertical gust, ``b`` the flight's altitude-hold error
  and ``k_z = altitude_gain_per_s`` (the altitude hold), integrated exactly for ``w_z`` held over the
  step and clipped at ``+-max_vertical_m``; on climbs and descents (vertical segments at pads)
  the aircraft follows the path's height: ``h' = -k_z h`` (it decays). With both vertical levels 0
  the height follows the path exactly (vertical error 0), bit for bit as before they existed.

Cost: O(n_steps x flights) numpy steps per batch, vectorised over the batch (``fly_batch``).
"""

from __future__ import annotations

import math
import zlib
from dataclasses import dataclass, fields
from typing import Sequence

import numpy as np

from uam_contract.defaults import SPEED_ERROR_MAX
from uam_contract.disturbances import disturbances_on

from uam_planner.trajectory import Trajectory

#: plane waves summed in the gust field
GUST_MODES = 8
#: the ground speed along track never falls below this share of the airspeed (a head wind
#: stronger than the aircraft is outside the model)
MIN_GROUND_SPEED_SHARE = 0.2


@dataclass(frozen=True)
class DisturbanceConfig:
    """The disturbance level and the path-following model (every level 0 = off, the default).

    Attributes:
        wind_speed_mps: steady wind speed [m/s].
        wind_from_deg: direction the steady wind blows from [deg clockwise from north].
        gust_std_mps: standard deviation of each horizontal gust component [m/s].
        gust_length_m, gust_period_s: typical gust wavelength [m] and period [s].
        speed_error: per-flight airspeed error bound: e ~ U[-speed_error, +speed_error] (0.1 = 10 %).
        delay_mean_s: mean departure delay [s] (exponential); 0 = on time.
        delay_max_s: the delay distribution is truncated here [s].
        track_gain_per_s: cross-track guidance gain k [1/s].
        max_lateral_m: bound on the cross-track offset [m].
        compensate_steady_wind: crab against the (forecast) steady wind; false = it drifts too.
        time_gain_per_s: along-track (4D) guidance gain k_t [1/s]: the commanded airspeed is the
            plan's plus k_t x (the plan's along-track distance now - the aircraft's), within
            +-max_speed_adjust of the plan's; 0 (default) = no time control, the airspeed is held
            (NASA's uncompensated speed error).
        max_speed_adjust: bound of that correction, as a share of the plan's speed.
        vertical_gust_std_mps: standard deviation of the vertical gust [m/s] (0 = none).
        altitude_error_m: per-flight altitude-hold error bound: b ~ U[-altitude_error_m,
            +altitude_error_m] [m] (0 = none).
        altitude_gain_per_s: the altitude hold's gain k_z [1/s].
        max_vertical_m: bound of the height offset [m].
        step_s: integration step; the flown track is sampled every step_s [s].
        seed: seed of the wind field and of every flight's draws.
    """

    wind_speed_mps: float = 0.0
    wind_from_deg: float = 270.0
    gust_std_mps: float = 0.0
    gust_length_m: float = 2000.0
    gust_period_s: float = 60.0
    speed_error: float = 0.0
    delay_mean_s: float = 0.0
    delay_max_s: float = 120.0
    track_gain_per_s: float = 0.1
    max_lateral_m: float = 50.0
    compensate_steady_wind: bool = True
    time_gain_per_s: float = 0.0
    max_speed_adjust: float = 0.1
    step_s: float = 1.0
    seed: int = 0
    vertical_gust_std_mps: float = 0.0
    altitude_error_m: float = 0.0
    altitude_gain_per_s: float = 0.1
    max_vertical_m: float = 30.0

    def __post_init__(self):
        for f in fields(self):
            v = getattr(self, f.name)
            if f.name == "compensate_steady_wind":
                if not isinstance(v, bool):
                    raise ValueError(f"DisturbanceConfig.compensate_steady_wind: {v!r} is not true or false")
                continue
            if f.name == "seed":
                if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
                    raise ValueError(f"DisturbanceConfig.seed: {v!r} must be an integer >= 0")
                continue
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v):
                raise ValueError(f"DisturbanceConfig.{f.name}: {v!r} is not a finite number")
            positive = f.name in ("gust_length_m", "gust_period_s", "track_gain_per_s", "step_s",
                                  "max_lateral_m", "altitude_gain_per_s", "max_vertical_m")
            if f.name == "max_speed_adjust" and v >= 1.0:
                raise ValueError(f"DisturbanceConfig.max_speed_adjust: {v!r} must be below 1")
            if v < 0 or (positive and v == 0):
                raise ValueError(f"DisturbanceConfig.{f.name}: {v!r} must be "
                                 f"{'> 0' if positive else '>= 0'}")
        if self.speed_error > SPEED_ERROR_MAX:  # the node's bound, in its words (uam_contract.defaults)
            raise ValueError(f"DisturbanceConfig.speed_error: {self.speed_error!r} is above the maximum "
                             f"{SPEED_ERROR_MAX}")

    @property
    def enabled(self) -> bool:
        """True when any disturbance is on (else the plan is flown exactly)."""
        return disturbances_on(self.wind_speed_mps, self.gust_std_mps, self.speed_error, self.delay_mean_s,
                               self.vertical_gust_std_mps, self.altitude_error_m)

    @property
    def vertical(self) -> bool:
        """True when a vertical disturbance is on (vertical gusts or an altitude-hold error)."""
        return bool(self.vertical_gust_std_mps or self.altitude_error_m)

    @classmethod
    def from_mapping(cls, data) -> "DisturbanceConfig":
        """From a mapping of field names (YAML, flags); unknown names raise ValueError naming them."""
        data = dict(data or {})
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"disturbance: unknown field {unknown[0]!r} (known: {sorted(known)})")
        return cls(**data)


@dataclass(frozen=True)
class FlightDraws:
    """One flight's draws: airspeed factor error e, departure delay [s] and altitude-hold
    error [m]."""

    speed_error: float = 0.0
    delay_s: float = 0.0
    altitude_offset_m: float = 0.0


def flight_draws(config: DisturbanceConfig, flight_id: str) -> FlightDraws:
    """The draws of ``flight_id``: a pure function of the seed and the id (not of the order
    flights are flown in). Every number is always drawn, in the same order (the altitude error
    last, so it did not shift the two drawn before it existed), so one level does not shift
    another."""
    rng = np.random.default_rng([int(config.seed), zlib.crc32(flight_id.encode("utf-8"))])
    u = rng.uniform(-1.0, 1.0)
    x = rng.exponential(1.0)
    z = rng.uniform(-1.0, 1.0)
    e = float(u * config.speed_error)
    delay = float(min(x * config.delay_mean_s, config.delay_max_s)) if config.delay_mean_s > 0 else 0.0
    return FlightDraws(e, delay, float(z * config.altitude_error_m))


def _plane_waves(rng, config, m: int):
    """m plane waves of random heading, wavelength (0.5-2 x gust_length_m), period (0.5-2 x
    gust_period_s) and phase, drawn from rng in that order: (wave vectors (m, 2), angular
    frequencies, phases)."""
    heading = rng.uniform(0.0, 2.0 * math.pi, m)
    wavelength = config.gust_length_m * rng.uniform(0.5, 2.0, m)
    period = config.gust_period_s * rng.uniform(0.5, 2.0, m)
    k = (2.0 * math.pi / wavelength)[:, None] * np.stack([np.cos(heading), np.sin(heading)], 1)
    return k, 2.0 * math.pi / period, rng.uniform(0.0, 2.0 * math.pi, m)


class WindField:
    """Steady wind plus a seeded gust field over (x, y, t): ``at(xy (n, 2), t) -> (n, 2)`` [m/s]."""

    def __init__(self, config: DisturbanceConfig):
        self.config = config
        frm = math.radians(config.wind_from_deg)
        # blowing *from* that bearing: the wind vector points the other way (ENU: x east, y north)
        self.steady = -config.wind_speed_mps * np.array([math.sin(frm), math.cos(frm)])
        rng = np.random.default_rng([int(config.seed), 0x57494E44])
        m = GUST_MODES
        self.k, self.omega, self.phase = _plane_waves(rng, config, m)
        # each component: sum of m cosines of amplitude a: variance m a^2 / 2 = std^2
        amp = config.gust_std_mps * math.sqrt(2.0 / m)
        self.amp = amp * rng.choice([-1.0, 1.0], size=(m, 2))
        # the vertical gusts: their own plane waves (their own stream: the horizontal field is
        # the same with or without them)
        vr = np.random.default_rng([int(config.seed), 0x56455254])
        self.kz, self.omega_z, self.phase_z = _plane_waves(vr, config, m)
        self.amp_z = config.vertical_gust_std_mps * math.sqrt(2.0 / m) * vr.choice([-1.0, 1.0], size=m)

    def gust(self, xy: np.ndarray, t_s) -> np.ndarray:
        """Gusts at positions ``xy`` (n, 2) and time(s) ``t_s`` (scalar or (n,))."""
        if self.config.gust_std_mps == 0.0:
            return np.zeros((xy.shape[0], 2))
        t = np.broadcast_to(np.asarray(t_s, dtype=np.float64), (xy.shape[0],))
        arg = xy @ self.k.T - t[:, None] * self.omega[None, :] + self.phase   # (n, m)
        return np.cos(arg) @ self.amp

    def at(self, xy: np.ndarray, t_s) -> np.ndarray:
        return self.steady + self.gust(np.asarray(xy, dtype=np.float64), t_s)

    def vertical(self, xy: np.ndarray, t_s) -> np.ndarray:
        """Vertical gusts [m/s] at positions ``xy`` (n, 2) and time(s) ``t_s``."""
        xy = np.asarray(xy, dtype=np.float64)
        if self.config.vertical_gust_std_mps == 0.0:
            return np.zeros(xy.shape[0])
        t = np.broadcast_to(np.asarray(t_s, dtype=np.float64), (xy.shape[0],))
        arg = xy @ self.kz.T - t[:, None] * self.omega_z[None, :] + self.phase_z
        return np.cos(arg) @ self.amp_z


def fly(plan: Trajectory, draws: FlightDraws, config: DisturbanceConfig,
        wind: WindField | None = None) -> Trajectory:
    """The flown trajectory of one plan (see the module's model)."""
    return fly_batch([plan], [draws], config, wind)[0]


def fly_batch(plans: Sequence[Trajectory], draws: Sequence[FlightDraws], config: DisturbanceConfig,
              wind: WindField | None = None) -> list[Trajectory]:
    """The flown trajectories of several plans, integrated together (vectorised over them).

    With ``config.enabled`` false, the plans themselves. Raises ValueError when the lengths of
    ``plans`` and ``draws`` differ.
    """
    if len(plans) != len(draws):
        raise ValueError(f"draws: {len(draws)} given for {len(plans)} plans")
    if not config.enabled or not plans:
        return list(plans)
    wind = wind if wind is not None else WindField(config)
    n = len(plans)
    p = max(pl.times_s.shape[0] for pl in plans)
    P = np.empty((n, p, 3))
    C = np.full((n, p), np.inf)          # cumulative path length at each waypoint
    U = np.zeros((n, p - 1, 3))          # unit direction per segment
    UH = np.zeros((n, p - 1, 2))         # unit horizontal direction (0 for vertical segments)
    V = np.ones((n, p - 1))              # planned speed per segment
    TT = np.full((n, p), np.inf)         # planned waypoint times
    nseg = np.empty(n, dtype=np.int64)
    for i, pl in enumerate(plans):
        pts, ts = pl.points_m, pl.times_s
        k = pts.shape[0]
        d = np.diff(pts, axis=0)
        ln = np.sqrt(np.square(d).sum(axis=1))
        C[i, 0] = 0.0
        C[i, 1:k] = np.cumsum(ln)
        P[i, :k] = pts
        P[i, k:] = pts[-1]
        nz = ln > 0
        U[i, :k - 1][nz] = d[nz] / ln[nz, None]
        hl = np.sqrt(np.square(d[:, :2]).sum(axis=1))
        hz = hl > 1e-9 * np.maximum(ln, 1.0)
        UH[i, :k - 1][hz] = d[hz, :2] / hl[hz, None]
        V[i, :k - 1] = np.where(nz, ln / np.diff(ts), 1.0)
        TT[i, :k] = ts
        nseg[i] = k - 1
    length = C[np.arange(n), nseg]
    e = np.array([d.speed_error for d in draws])
    t = np.array([pl.departure_s + d.delay_s for pl, d in zip(plans, draws)])
    s = np.zeros(n)
    off = np.zeros((n, 2))
    vertical = config.vertical
    hoff = np.zeros(n)
    bias = np.array([d.altitude_offset_m for d in draws])
    kz = float(config.altitude_gain_per_s)
    decay_z = math.exp(-kz * config.step_s)
    gain_z = (1.0 - decay_z) / kz
    dt = float(config.step_s)
    k = float(config.track_gain_per_s)
    decay = math.exp(-k * dt)
    gain = (1.0 - decay) / k
    rows = np.arange(n)
    # Samples are recorded a step at a time as (rows, times, positions) arrays and split per
    # flight at the end: a per-row Python append was most of this function's time (profiled on
    # a 900 s Monte-Carlo run, BENCHMARKS.md).
    rec_r: list[np.ndarray] = []
    rec_t: list[np.ndarray] = []
    rec_p: list[np.ndarray] = []
    active = np.ones(n, dtype=bool)
    steady = wind.steady
    min_share = MIN_GROUND_SPEED_SHARE
    while active.any():
        r = rows[active]
        seg = np.minimum((C[r] <= s[r][:, None]).sum(axis=1) - 1, nseg[r] - 1)
        base = P[r, seg] + (s[r] - C[r, seg])[:, None] * U[r, seg]
        pos = base.copy()
        pos[:, :2] += off[r]
        if vertical:
            pos[:, 2] += hoff[r]
        rec_r.append(r)
        rec_t.append(t[r])
        rec_p.append(pos)
        done = s[r] >= length[r]
        if done.any():
            active[r[done]] = False
            keep = ~done
            r, seg, pos = r[keep], seg[keep], pos[keep]
            if r.size == 0:
                break
        uh = UH[r, seg]
        horizontal = np.square(uh).sum(axis=1) > 0.5
        w = wind.at(pos[:, :2], t[r])
        w_along = np.where(horizontal, (w * uh).sum(axis=1), 0.0)
        cross = w - w_along[:, None] * uh                       # horizontal wind across the track
        if config.compensate_steady_wind:
            st_along = np.where(horizontal, uh @ steady, 0.0)
            st_cross = steady[None, :] - st_along[:, None] * uh
            drift = cross - st_cross                            # the gusts' cross component
            crab2 = np.where(horizontal, np.square(st_cross).sum(axis=1), 0.0)
        else:
            drift = cross
            crab2 = np.zeros(r.size)
        vp = V[r, seg]
        if config.time_gain_per_s > 0:
            tt = np.clip(t[r], TT[r, 0], TT[r, nseg[r]])
            ts_ = np.minimum((TT[r] <= tt[:, None]).sum(axis=1) - 1, nseg[r] - 1)
            t0, t1 = TT[r, ts_], TT[r, ts_ + 1]
            s_plan = C[r, ts_] + (tt - t0) / (t1 - t0) * (C[r, ts_ + 1] - C[r, ts_])
            adj = np.clip(config.time_gain_per_s * (s_plan - s[r]), -config.max_speed_adjust * vp,
                          config.max_speed_adjust * vp)
            vp = vp + adj
        va = (1.0 + e[r]) * vp
        gs = np.where(horizontal, np.sqrt(np.maximum(va * va - crab2, 0.0)) + w_along, va)
        gs = np.maximum(gs, min_share * va)
        o = off[r] * decay + drift * gain
        norm = np.sqrt(np.square(o).sum(axis=1))
        over = norm > config.max_lateral_m
        o[over] *= (config.max_lateral_m / norm[over])[:, None]
        off[r] = o
        if vertical:
            # level segments: h' = w_z - k_z (h - b); climbs and descents follow the path's height
            wz = np.where(horizontal, wind.vertical(pos[:, :2], t[r]) + kz * bias[r], 0.0)
            h = np.clip(hoff[r] * decay_z + wz * gain_z, -config.max_vertical_m, config.max_vertical_m)
            hoff[r] = h
        s_new = s[r] + gs * dt
        last = s_new >= length[r]
        step = np.where(last, (length[r] - s[r]) / gs, dt)
        step = np.maximum(step, 1e-6)  # strictly increasing sample times
        s[r] = np.where(last, length[r], s_new)
        t[r] = t[r] + step
    all_r = np.concatenate(rec_r)
    order = np.argsort(all_r, kind="stable")        # per flight, in time order
    all_t = np.concatenate(rec_t)[order]
    all_p = np.concatenate(rec_p)[order]
    cuts = np.cumsum(np.bincount(all_r, minlength=n))[:-1]
    return [Trajectory(ts, ps) for ts, ps in zip(np.split(all_t, cuts), np.split(all_p, cuts))]


def fly_plans(plans: Sequence[Trajectory], flight_ids: Sequence[str], config: DisturbanceConfig,
              wind: WindField | None = None) -> list[Trajectory]:
    """``fly_batch`` with each flight's draws from its id (:func:`flight_draws`)."""
    if not config.enabled:
        return list(plans)
    return fly_batch(plans, [flight_draws(config, fid) for fid in flight_ids], config, wind)


def fly_on(flown: Trajectory, new_plan: Trajectory, speed_error: float, rate: float,
           config: DisturbanceConfig, wind: WindField | None = None) -> tuple[Trajectory, float]:
    """What flies after a nonconforming update (``uam_planner.nonconformance``):
    ``flown`` up to the new plan's start, then the model flying ``new_plan`` from its first point
    (where the aircraft was), on time, with the aircraft's airspeed as it flew: the update timed
    the new plan at ``rate`` (the observed progress rate) times the old plan's speeds, so the
    aircraft's speed error against the new plan is (1 + e) / rate - 1. Returns (the flown
    track, that speed error, to be used for the next update of the same flight)."""
    e_new = (1.0 + float(speed_error)) / float(rate) - 1.0
    return fly_from(flown, new_plan, e_new, config, wind), e_new


def fly_from(flown: Trajectory, plan: Trajectory, speed_error: float, config: DisturbanceConfig,
             wind: WindField | None = None) -> Trajectory:
    """``flown`` up to ``plan``'s start, then the model flying ``plan`` from its first point with
    ``speed_error`` and no departure delay (:func:`fly_on`; a re-plan of a flight a
    nonconforming update moved before, flown on from that update by the runner and the node)."""
    t0 = float(plan.departure_s)
    cont = fly_batch([plan], [FlightDraws(speed_error, 0.0)], config, wind)[0]
    keep = flown.times_s < t0 - 1e-9
    return Trajectory(np.concatenate((flown.times_s[keep], cont.times_s)),
                      np.concatenate((flown.points_m[keep], cont.points_m)))


#: simulator parameter -> DisturbanceConfig field (uam_contract.params.SIMULATOR)
SIMULATOR_PARAMS = {"wind_speed_mps": "wind_speed_mps", "wind_from_deg": "wind_from_deg",
                    "gust_std_mps": "gust_std_mps", "gust_length_m": "gust_length_m",
                    "gust_period_s": "gust_period_s", "speed_error": "speed_error",
                    "delay_mean_s": "delay_mean_s", "delay_max_s": "delay_max_s",
                    "track_gain_per_s": "track_gain_per_s", "max_lateral_m": "max_lateral_m",
                    "compensate_steady_wind": "compensate_steady_wind", "disturbance_seed": "seed",
                    "vertical_gust_std_mps": "vertical_gust_std_mps",
                    "altitude_error_m": "altitude_error_m",
                    "altitude_gain_per_s": "altitude_gain_per_s", "max_vertical_m": "max_vertical_m"}


def from_simulator_params(params: dict, step_s: float) -> DisturbanceConfig:
    """The DisturbanceConfig of the simulator node's parameters; the flown tracks are sampled at
    the simulator's step."""
    return DisturbanceConfig(step_s=float(step_s),
                             **{field_: params[name] for name, field_ in SIMULATOR_PARAMS.items()})
