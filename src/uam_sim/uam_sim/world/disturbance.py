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

The effects: each of these is a :class:`DisturbanceEffect` in one registry (:func:`register_effect`;
``wind``, ``speed_error``, ``departure_delay``, ``vertical_gust``, ``altitude_error``, then
``time_control``, the along-track guidance below, which has no level), and the flight model sums
what they add: departure delays, commanded speed, airspeed error, horizontal air (along the track,
crabbed against, drifting across) and vertical forcing. "Are any disturbances on"
(``DisturbanceConfig.enabled``) is "is any registered effect's level not 0". docs/extending.md
adds one.

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
import re
import zlib
from dataclasses import dataclass, field, fields
from typing import Mapping, NamedTuple, Sequence

import numpy as np

from uam_contract.defaults import SPEED_ERROR_MAX

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
        extra: the fields of registered effects beyond these (``DisturbanceEffect.params``), by
            name; a name no registered effect declares raises ValueError. Read with :meth:`value`.
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
    extra: Mapping[str, float] = field(default_factory=dict, hash=False)

    def __post_init__(self):
        for f in fields(self):
            if f.name != "extra":
                _check_field(f.name, getattr(self, f.name))
        if self.speed_error > SPEED_ERROR_MAX:  # the node's bound, in its words (uam_contract.defaults)
            raise ValueError(f"DisturbanceConfig.speed_error: {self.speed_error!r} is above the maximum "
                             f"{SPEED_ERROR_MAX}")
        declared = _effect_params()
        for name, v in dict(self.extra).items():
            if name not in declared:
                raise ValueError(f"DisturbanceConfig.extra: {name!r} is no registered effect's field "
                                 f"(known: {sorted(declared)})")
            _check_field(name, v)
        object.__setattr__(self, "extra", dict(self.extra))

    def value(self, name: str):
        """The field ``name``: one of the attributes above, or a registered effect's own
        (its value in ``extra``, else the effect's default); KeyError for any other name."""
        if name in _CONFIG_FIELDS:
            return getattr(self, name)
        if name in self.extra:
            return self.extra[name]
        return _effect_params()[name]

    @property
    def enabled(self) -> bool:
        """True when any disturbance is on (else the plan is flown exactly): any registered
        effect is on (:meth:`DisturbanceEffect.on`: a level of it is not 0)."""
        return any(effect.on(self) for effect in _EFFECTS.values())

    @property
    def vertical(self) -> bool:
        """True when an effect that moves the height (one with a ``vertical`` hook: the vertical
        gusts, the altitude-hold error) is on."""
        return any(effect.on(self) for effect in _EFFECTS.values() if _has_hook(effect, "vertical"))

    @classmethod
    def from_mapping(cls, data) -> "DisturbanceConfig":
        """From a mapping of field names (YAML, flags), the registered effects' own fields among
        them; unknown names raise ValueError naming them."""
        data = dict(data or {})
        own = set(_CONFIG_FIELDS)
        known = own | set(_effect_params())
        unknown = sorted(set(data) - known)
        if unknown:
            raise ValueError(f"disturbance: unknown field {unknown[0]!r} (known: {sorted(known)})")
        return cls(**{k: v for k, v in data.items() if k in own},
                   extra={k: v for k, v in data.items() if k not in own})


#: fields whose 0 is no value: gains, bounds, the gust scales and the step
_POSITIVE = ("gust_length_m", "gust_period_s", "track_gain_per_s", "step_s", "max_lateral_m",
             "altitude_gain_per_s", "max_vertical_m")


def _check_field(name: str, v) -> None:
    """ValueError naming the field when ``v`` is not a valid value of the field ``name``: true or
    false for ``compensate_steady_wind``, an integer >= 0 for ``seed``, else a finite number >= 0
    (> 0 for those of _POSITIVE; below 1 for ``max_speed_adjust``)."""
    if name == "compensate_steady_wind":
        if not isinstance(v, bool):
            raise ValueError(f"DisturbanceConfig.compensate_steady_wind: {v!r} is not true or false")
        return
    if name == "seed":
        if isinstance(v, bool) or not isinstance(v, (int, np.integer)) or v < 0:
            raise ValueError(f"DisturbanceConfig.seed: {v!r} must be an integer >= 0")
        return
    if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
            or not math.isfinite(v):
        raise ValueError(f"DisturbanceConfig.{name}: {v!r} is not a finite number")
    positive = name in _POSITIVE
    if name == "max_speed_adjust" and v >= 1.0:
        raise ValueError(f"DisturbanceConfig.max_speed_adjust: {v!r} must be below 1")
    if v < 0 or (positive and v == 0):
        raise ValueError(f"DisturbanceConfig.{name}: {v!r} must be "
                         f"{'> 0' if positive else '>= 0'}")


#: the DisturbanceConfig fields of its own (the registered effects' fields live in ``extra``)
_CONFIG_FIELDS = tuple(f.name for f in fields(DisturbanceConfig) if f.name != "extra")


@dataclass(frozen=True)
class FlightDraws:
    """One flight's draws: airspeed factor error e, departure delay [s] and altitude-hold
    error [m]; ``extra``: the draws of registered effects beyond these, by name."""

    speed_error: float = 0.0
    delay_s: float = 0.0
    altitude_offset_m: float = 0.0
    extra: Mapping[str, float] = field(default_factory=dict, hash=False)

    def value(self, name: str) -> float:
        """The draw ``name``: an attribute above, or an effect's own in ``extra`` (0 when absent)."""
        if name in _DRAW_FIELDS:
            return getattr(self, name)
        return self.extra.get(name, 0.0)


_DRAW_FIELDS = ("speed_error", "delay_s", "altitude_offset_m")


def flight_draws(config: DisturbanceConfig, flight_id: str) -> FlightDraws:
    """The draws of ``flight_id``: a pure function of the seed and the id (not of the order
    flights are flown in). Every effect draws from one generator in the order the effects are
    registered, whatever their levels (the speed error's uniform u, the delay's exponential x, the
    altitude error's uniform z, then a registered effect's own), so one level does not shift
    another and an effect registered later does not shift the draws before it."""
    rng = np.random.default_rng([int(config.seed), zlib.crc32(flight_id.encode("utf-8"))])
    drawn: dict = {}
    for effect in _EFFECTS.values():
        drawn.update(effect.draw(rng, config))
    return FlightDraws(**{k: v for k, v in drawn.items() if k in _DRAW_FIELDS},
                       extra={k: v for k, v in drawn.items() if k not in _DRAW_FIELDS})


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


# ---- the effects: one class each, one registry, summed by the flight model ------------------


class FlightBatch:
    """The plans of one :func:`fly_batch` call as padded arrays (n flights, p waypoints at most),
    what an effect's hooks read besides the step (:class:`FlightStep`).

    Attributes:
        config, wind, draws: the call's; ``n`` flights.
        points (n, p, 3): the waypoints (the last repeated past a plan's end).
        cum_length (n, p): the path length at each waypoint (inf past the end).
        unit (n, p - 1, 3), unit_h (n, p - 1, 2): each segment's direction and its horizontal
            direction (0 for vertical and zero-length segments).
        speed (n, p - 1): each segment's planned speed (1 for zero-length ones).
        times (n, p): the planned waypoint times (inf past the end).
        nseg (n,), length (n,): each plan's segment count and path length.
        departure_s (n,): the planned departures.
    """

    def __init__(self, plans: Sequence[Trajectory], draws: Sequence[FlightDraws], config: DisturbanceConfig,
                 wind: WindField):
        self.config, self.wind, self.draws = config, wind, draws
        n = self.n = len(plans)
        p = max(pl.times_s.shape[0] for pl in plans)
        self.points = np.empty((n, p, 3))
        self.cum_length = np.full((n, p), np.inf)
        self.unit = np.zeros((n, p - 1, 3))
        self.unit_h = np.zeros((n, p - 1, 2))
        self.speed = np.ones((n, p - 1))
        self.times = np.full((n, p), np.inf)
        self.nseg = np.empty(n, dtype=np.int64)
        for i, pl in enumerate(plans):
            self._add_plan(i, pl)
        self.length = self.cum_length[np.arange(n), self.nseg]
        self.departure_s = np.array([pl.departure_s for pl in plans])
        self._drawn: dict = {}

    def _add_plan(self, i: int, pl: Trajectory) -> None:
        """Row ``i`` of the arrays: the plan's waypoints, lengths, directions, speeds and times."""
        pts, ts = pl.points_m, pl.times_s
        k = pts.shape[0]
        d = np.diff(pts, axis=0)
        ln = np.sqrt(np.square(d).sum(axis=1))
        self.cum_length[i, 0] = 0.0
        self.cum_length[i, 1:k] = np.cumsum(ln)
        self.points[i, :k] = pts
        self.points[i, k:] = pts[-1]
        nz = ln > 0
        self.unit[i, :k - 1][nz] = d[nz] / ln[nz, None]
        hl = np.sqrt(np.square(d[:, :2]).sum(axis=1))
        hz = hl > 1e-9 * np.maximum(ln, 1.0)
        self.unit_h[i, :k - 1][hz] = d[hz, :2] / hl[hz, None]
        self.speed[i, :k - 1] = np.where(nz, ln / np.diff(ts), 1.0)
        self.times[i, :k] = ts
        self.nseg[i] = k - 1

    def drawn(self, name: str) -> np.ndarray:
        """The draw ``name`` of every flight (:meth:`FlightDraws.value`), an (n,) array."""
        if name not in self._drawn:
            self._drawn[name] = np.array([d.value(name) for d in self.draws])
        return self._drawn[name]


class FlightStep:
    """The flights still in the air at one integration step, what an effect's per-step hooks read.

    Attributes:
        batch: the :class:`FlightBatch`; ``config`` and ``wind`` are its.
        rows (m,): the flights (rows of the batch).
        seg (m,): the segment each flies along.
        pos (m, 3): where each is (the path point plus the offsets).
        t_s (m,), s_m (m,): the time and the along-track distance flown.
        uh (m, 2): the segment's horizontal direction (0 on vertical segments).
        horizontal (m,): the segment is horizontal (level or slanted), not a climb or descent.
        plan_speed (m,): the segment's planned speed.
    """

    __slots__ = ("batch", "config", "wind", "rows", "seg", "pos", "t_s", "s_m", "uh", "horizontal", "plan_speed")

    def __init__(self, batch: FlightBatch, rows, seg, pos, t_s, s_m):
        self.batch, self.config, self.wind = batch, batch.config, batch.wind
        self.rows, self.seg, self.pos, self.t_s, self.s_m = rows, seg, pos, t_s, s_m
        self.uh = batch.unit_h[rows, seg]
        self.horizontal = np.square(self.uh).sum(axis=1) > 0.5
        self.plan_speed = batch.speed[rows, seg]


class Air(NamedTuple):
    """An effect's horizontal air at one step (:meth:`DisturbanceEffect.air`); None = nothing.

    along: [m/s] added to the ground speed along a horizontal segment.
    crab_sq: [m^2/s^2] the square of the cross-track air speed the aircraft crabs against (known,
        so compensated): it takes that share of the airspeed (ground speed sqrt(va^2 - crab_sq)).
    drift: (m, 2) [m/s] the horizontal air across the track the guidance corrects (uncompensated).
    """

    along: np.ndarray | None = None
    crab_sq: np.ndarray | None = None
    drift: np.ndarray | None = None


class DisturbanceEffect:
    """One effect of the disturbance model: a subclass sets the class attributes and overrides
    the hooks it needs (the others add nothing), and an instance is registered with
    :func:`register_effect`. Once any effect is on, the flight model (:func:`fly_batch`) calls
    every registered effect's hooks, in the order they were registered, and sums what they return
    (None = nothing). A level of 0 makes an effect add nothing (its draws are 0, a hook returns
    None), unless a caller gives the flight's draws itself (``fly_from`` flies on with a speed
    error of its own).

    Class attributes:
        name: its registry key (1 to 32 lower-case letters, digits or '_').
        description: one line for the docs and listings.
        levels: the config fields whose non-zero value turns it on: "are any disturbances on"
            (``DisturbanceConfig.enabled``) is "is any level of any registered effect not 0".
        params: its own config fields, beyond the DisturbanceConfig attributes (name -> default, a
            number >= 0); their values are in ``DisturbanceConfig.extra``, read with
            ``config.value(name)``, and ``DisturbanceConfig.from_mapping`` takes them by name.
    """

    name: str = ""
    description: str = ""
    levels: tuple = ()
    params: Mapping[str, float] = {}

    def on(self, config: DisturbanceConfig) -> bool:
        """True when a level of it is not 0."""
        return any(config.value(level) != 0 for level in self.levels)

    def draw(self, rng: np.random.Generator, config: DisturbanceConfig) -> dict:
        """The flight's draws from its generator (``flight_draws``), FlightDraws names (or the
        effect's own, kept in ``FlightDraws.extra``) -> values. Draw the same numbers whatever the
        level, so that a level does not shift the draws of the effects after it."""
        return {}

    def departure_delay(self, batch: FlightBatch):
        """[s] per flight, added to the planned departure."""
        return None

    def speed_command(self, step: FlightStep):
        """[m/s] per flight, added to the planned speed the aircraft commands."""
        return None

    def airspeed_error(self, step: FlightStep):
        """A share per flight: the airspeed is (1 + the effects' sum) x the commanded speed."""
        return None

    def air(self, step: FlightStep) -> Air | None:
        """The horizontal air it adds (:class:`Air`)."""
        return None

    def vertical(self, step: FlightStep):
        """[m/s] per flight forcing the height offset on horizontal segments (climbs and descents
        follow the path's height). An effect with this hook that is on turns the height model on
        (``DisturbanceConfig.vertical``)."""
        return None


class Wind(DisturbanceEffect):
    name = "wind"
    description = ("steady wind (wind_speed_mps from wind_from_deg) and horizontal gusts (gust_std_mps, "
                   "gust_length_m, gust_period_s); the aircraft crabs against the steady wind "
                   "(compensate_steady_wind)")
    levels = ("wind_speed_mps", "gust_std_mps")

    def air(self, step):
        uh, horizontal = step.uh, step.horizontal
        w = step.wind.at(step.pos[:, :2], step.t_s)
        w_along = np.where(horizontal, (w * uh).sum(axis=1), 0.0)
        cross = w - w_along[:, None] * uh                       # horizontal wind across the track
        if not step.config.compensate_steady_wind:
            return Air(w_along, None, cross)
        steady = step.wind.steady
        st_along = np.where(horizontal, uh @ steady, 0.0)
        st_cross = steady[None, :] - st_along[:, None] * uh
        # the aircraft crabs against the steady cross wind: the gusts' cross component drifts it
        return Air(w_along, np.where(horizontal, np.square(st_cross).sum(axis=1), 0.0), cross - st_cross)


class SpeedError(DisturbanceEffect):
    name = "speed_error"
    description = "per-flight airspeed error: (1 + e) x the commanded speed, e uniform in +-speed_error"
    levels = ("speed_error",)

    def draw(self, rng, config):
        return {"speed_error": float(rng.uniform(-1.0, 1.0) * config.speed_error)}

    def airspeed_error(self, step):
        # the flight's draw, whatever the level: a nonconforming update sets it (fly_on)
        return step.batch.drawn("speed_error")[step.rows]


class DepartureDelay(DisturbanceEffect):
    name = "departure_delay"
    description = "departure delay: exponential of mean delay_mean_s, truncated at delay_max_s"
    levels = ("delay_mean_s",)

    def draw(self, rng, config):
        x = rng.exponential(1.0)
        return {"delay_s": float(min(x * config.delay_mean_s, config.delay_max_s))
                if config.delay_mean_s > 0 else 0.0}

    def departure_delay(self, batch):
        return batch.drawn("delay_s")


class VerticalGust(DisturbanceEffect):
    name = "vertical_gust"
    description = "vertical gusts (vertical_gust_std_mps), a seeded field like the horizontal one"
    levels = ("vertical_gust_std_mps",)

    def vertical(self, step):
        return step.wind.vertical(step.pos[:, :2], step.t_s)


class AltitudeError(DisturbanceEffect):
    name = "altitude_error"
    description = ("per-flight altitude-hold error: the height held above the plan, uniform in "
                   "+-altitude_error_m")
    levels = ("altitude_error_m",)

    def draw(self, rng, config):
        return {"altitude_offset_m": float(rng.uniform(-1.0, 1.0) * config.altitude_error_m)}

    def vertical(self, step):
        # h' = w_z - k_z (h - b): the hold's pull towards the offset b is k_z b
        return float(step.config.altitude_gain_per_s) * step.batch.drawn("altitude_offset_m")[step.rows]


class TimeControl(DisturbanceEffect):
    """Not a disturbance (no level: it never turns the model on) but the aircraft's along-track
    (4D) guidance: with ``time_gain_per_s`` > 0 it commands the plan's speed plus
    k_t (s_plan(t) - s), within +-max_speed_adjust of the plan's."""

    name = "time_control"
    description = ("along-track (4D) guidance: the plan's speed plus time_gain_per_s x the distance behind "
                   "the plan, within +-max_speed_adjust of it (no level: it turns nothing on)")

    def speed_command(self, step):
        cfg = step.config
        if not cfg.time_gain_per_s > 0:
            return None
        b, r, vp = step.batch, step.rows, step.plan_speed
        tt = np.clip(step.t_s, b.times[r, 0], b.times[r, b.nseg[r]])
        ts_ = np.minimum((b.times[r] <= tt[:, None]).sum(axis=1) - 1, b.nseg[r] - 1)
        t0, t1 = b.times[r, ts_], b.times[r, ts_ + 1]
        s_plan = b.cum_length[r, ts_] + (tt - t0) / (t1 - t0) * (b.cum_length[r, ts_ + 1] - b.cum_length[r, ts_])
        return np.clip(cfg.time_gain_per_s * (s_plan - step.s_m), -cfg.max_speed_adjust * vp,
                       cfg.max_speed_adjust * vp)


#: the registered effects, name -> instance, in registration order (the order of the draws and
#: of the sums)
_EFFECTS: dict = {}
_NAME = re.compile(r"^[a-z][a-z0-9_]{0,31}$")
#: the effects of this module, which cannot be unregistered (the others' draws depend on them)
BUILTIN_EFFECTS = ("wind", "speed_error", "departure_delay", "vertical_gust", "altitude_error", "time_control")


def register_effect(effect, replace: bool = False) -> DisturbanceEffect:
    """Add an effect (a :class:`DisturbanceEffect` instance, or a subclass made with no
    arguments) after those registered: ValueError naming the field for a bad or taken name, a
    level that is no field, or a field of its own that another has."""
    if isinstance(effect, type) and issubclass(effect, DisturbanceEffect):
        effect = effect()
    if not isinstance(effect, DisturbanceEffect):
        raise ValueError(f"effect: {effect!r} is not a DisturbanceEffect")
    name = effect.name
    if not isinstance(name, str) or not _NAME.match(name):
        raise ValueError(f"effect name: {name!r} is not 1 to 32 lower-case letters, digits or '_'")
    if name in _EFFECTS and not (replace and name not in BUILTIN_EFFECTS):
        raise ValueError(f"effect name: {name!r} is already registered")
    taken = set(_CONFIG_FIELDS) | {p for n, e in _EFFECTS.items() if n != name for p in e.params}
    for p, default in dict(effect.params).items():
        if p in taken:
            raise ValueError(f"effect {name!r}: field {p!r} is already a DisturbanceConfig or effect field")
        _check_field(p, default)
    for level in effect.levels:
        if level not in _CONFIG_FIELDS and level not in effect.params:
            raise ValueError(f"effect {name!r}: level {level!r} is neither a DisturbanceConfig field nor its own")
    _EFFECTS[name] = effect
    return effect


def unregister_effect(name: str) -> None:
    """Remove a registered effect (a plugin's or a test's own; the built-in ones stay)."""
    if name in BUILTIN_EFFECTS:
        raise ValueError(f"effect name: {name!r} is a built-in effect")
    _EFFECTS.pop(name, None)


def effects() -> tuple:
    """The registered effects, in registration order (the built-in ones first)."""
    return tuple(_EFFECTS.values())


def _effect_params() -> dict:
    """The registered effects' own fields, name -> default."""
    return {p: v for effect in _EFFECTS.values() for p, v in dict(effect.params).items()}


def _has_hook(effect: DisturbanceEffect, hook: str) -> bool:
    """Whether ``effect`` overrides the hook ``hook`` of DisturbanceEffect."""
    return getattr(type(effect), hook) is not getattr(DisturbanceEffect, hook)


for _effect in (Wind, SpeedError, DepartureDelay, VerticalGust, AltitudeError, TimeControl):
    register_effect(_effect)


# ---- the flight model ------------------------------------------------------------------------


def fly(plan: Trajectory, draws: FlightDraws, config: DisturbanceConfig,
        wind: WindField | None = None) -> Trajectory:
    """The flown trajectory of one plan (see the module's model)."""
    return fly_batch([plan], [draws], config, wind)[0]


def fly_batch(plans: Sequence[Trajectory], draws: Sequence[FlightDraws], config: DisturbanceConfig,
              wind: WindField | None = None) -> list[Trajectory]:
    """The flown trajectories of several plans, integrated together (vectorised over them): the
    registered effects' sum (see the module's model).

    With ``config.enabled`` false, the plans themselves. Raises ValueError when the lengths of
    ``plans`` and ``draws`` differ.
    """
    if len(plans) != len(draws):
        raise ValueError(f"draws: {len(draws)} given for {len(plans)} plans")
    if not config.enabled or not plans:
        return list(plans)
    batch = FlightBatch(plans, draws, config, wind if wind is not None else WindField(config))
    return _tracks(_integrate(batch), batch.n)


def _sum(values: list):
    """The sum of the values that are not None, left to right (None when all are)."""
    total = None
    for v in values:
        if v is not None:
            total = v if total is None else total + v
    return total


def _air(step: FlightStep, hooks: list) -> Air:
    """The effects' air at one step, summed field by field."""
    parts = [a for a in [h(step) for h in hooks] if a is not None]
    if len(parts) == 1:
        return parts[0]
    return Air(*[_sum(list(x)) for x in zip(*parts)]) if parts else Air()


class _Hooks:
    """The registered effects' hooks of one batch, each hook's list in registration order (only
    the effects that override it)."""

    def __init__(self):
        found = effects()
        for hook in ("departure_delay", "speed_command", "airspeed_error", "air", "vertical"):
            setattr(self, hook, [getattr(e, hook) for e in found if _has_hook(e, hook)])


class _Guidance:
    """The path following's constants of one batch: the step, the exact one-step decay and gain
    of the cross-track offset (gain k) and of the height offset (gain k_z), and their bounds."""

    def __init__(self, config: DisturbanceConfig):
        self.dt = float(config.step_s)
        k = float(config.track_gain_per_s)
        self.decay = math.exp(-k * self.dt)
        self.gain = (1.0 - self.decay) / k
        kz = float(config.altitude_gain_per_s)
        self.decay_z = math.exp(-kz * config.step_s)
        self.gain_z = (1.0 - self.decay_z) / kz
        self.max_lateral_m, self.max_vertical_m = config.max_lateral_m, config.max_vertical_m


def _integrate(batch: FlightBatch) -> tuple:
    """Fly the batch a step at a time until every flight has landed: the samples as (rows, times,
    positions) arrays, one of each per step.

    Samples are recorded a step at a time as arrays and split per flight at the end: a per-row
    Python append was most of the flight model's time (profiled on a 900 s Monte-Carlo run)."""
    hooks, guidance, n, length = _Hooks(), _Guidance(batch.config), batch.n, batch.length
    delay = _sum([h(batch) for h in hooks.departure_delay])
    t = batch.departure_s + delay if delay is not None else batch.departure_s.copy()
    s = np.zeros(n)
    off = np.zeros((n, 2))      # the cross-track offset
    hoff = np.zeros(n)          # the height offset
    vertical = batch.config.vertical
    rows = np.arange(n)
    active = np.ones(n, dtype=bool)
    rec_r: list[np.ndarray] = []
    rec_t: list[np.ndarray] = []
    rec_p: list[np.ndarray] = []
    while active.any():
        r = rows[active]
        seg, pos = _where(batch, r, s, off, hoff if vertical else None)
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
        step = FlightStep(batch, r, seg, pos, t[r], s[r])
        air = _air(step, hooks.air)
        gs = _ground_speed(step, hooks, air)
        off[r] = _cross_track(off[r], air.drift, guidance)
        if vertical:
            hoff[r] = _height(hoff[r], step, hooks, guidance)
        _advance(s, t, r, gs, length, guidance.dt)
    return rec_r, rec_t, rec_p


def _where(batch: FlightBatch, r, s, off, hoff):
    """The segment each flight ``r`` flies along and its position: the path point at its
    along-track distance plus the cross-track offset (and the height offset when given)."""
    seg = np.minimum((batch.cum_length[r] <= s[r][:, None]).sum(axis=1) - 1, batch.nseg[r] - 1)
    base = batch.points[r, seg] + (s[r] - batch.cum_length[r, seg])[:, None] * batch.unit[r, seg]
    pos = base.copy()
    pos[:, :2] += off[r]
    if hoff is not None:
        pos[:, 2] += hoff[r]
    return seg, pos


def _ground_speed(step: FlightStep, hooks: _Hooks, air: Air):
    """The ground speed along the path: the commanded speed (the plan's plus the effects'
    commands) times (1 + the airspeed errors) is the airspeed va; on horizontal segments
    sqrt(va^2 - crab_sq) + the air along, at least MIN_GROUND_SPEED_SHARE of va; va on vertical
    ones."""
    vp = step.plan_speed
    for command in hooks.speed_command:
        adj = command(step)
        if adj is not None:
            vp = vp + adj
    e = _sum([h(step) for h in hooks.airspeed_error])
    va = (1.0 + e) * vp if e is not None else vp
    crab_sq = air.crab_sq if air.crab_sq is not None else 0.0
    along = air.along if air.along is not None else 0.0
    gs = np.where(step.horizontal, np.sqrt(np.maximum(va * va - crab_sq, 0.0)) + along, va)
    return np.maximum(gs, MIN_GROUND_SPEED_SHARE * va)


def _cross_track(off, drift, guidance: _Guidance):
    """The cross-track offsets after one step: d' = g - k d integrated exactly for the drift g
    held over the step, the norm clipped at max_lateral_m."""
    o = off * guidance.decay
    if drift is not None:
        o = o + drift * guidance.gain
    norm = np.sqrt(np.square(o).sum(axis=1))
    over = norm > guidance.max_lateral_m
    o[over] *= (guidance.max_lateral_m / norm[over])[:, None]
    return o


def _height(hoff, step: FlightStep, hooks: _Hooks, guidance: _Guidance):
    """The height offsets after one step: on horizontal segments h' = the effects' vertical sum
    - k_z h, integrated exactly for it held over the step; climbs and descents follow the path's
    height (h' = -k_z h); clipped at +-max_vertical_m."""
    forcing = _sum([h(step) for h in hooks.vertical])
    wz = np.where(step.horizontal, forcing if forcing is not None else 0.0, 0.0)
    return np.clip(hoff * guidance.decay_z + wz * guidance.gain_z, -guidance.max_vertical_m,
                   guidance.max_vertical_m)


def _advance(s, t, r, gs, length, dt: float) -> None:
    """Move flights ``r`` on by a step at ground speed ``gs``; the last step of a flight ends where
    its path does, at the time found by linear interpolation inside the step."""
    s_new = s[r] + gs * dt
    last = s_new >= length[r]
    step = np.where(last, (length[r] - s[r]) / gs, dt)
    step = np.maximum(step, 1e-6)  # strictly increasing sample times
    s[r] = np.where(last, length[r], s_new)
    t[r] = t[r] + step


def _tracks(samples: tuple, n: int) -> list[Trajectory]:
    """The samples of :func:`_integrate` split per flight, in time order."""
    rec_r, rec_t, rec_p = samples
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
    """The DisturbanceConfig of the simulator node's parameters (SIMULATOR_PARAMS, and a registered
    effect's own fields, each from the parameter of its name when there is one); the flown tracks
    are sampled at the simulator's step."""
    own = {name: params[name] for name in _effect_params() if name in params}
    return DisturbanceConfig.from_mapping({"step_s": float(step_s), **own,
                                           **{field_: params[name] for name, field_ in SIMULATOR_PARAMS.items()}})
