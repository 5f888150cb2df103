"""4D trajectories: constant-speed, piecewise-linear motion through 3D waypoints (framework step 3).

A trajectory is the list of waypoint times ``times_s`` (p,) and ENU positions ``points_m`` (p, 3).
Between two waypoints the vehicle moves in a straight line at constant velocity; it is airborne
from ``departure_s = times_s[0]`` to ``arrival_s = times_s[-1]`` and absent outside that interval.

Segments are the primitive of the exact separation check (see ``separation.py``): segment j runs
from ``t0[j] = times_s[j]`` to ``t1[j] = times_s[j+1]`` starting at ``p0[j] = points_m[j]`` with
velocity ``v[j]`` in m/s.
"""

from __future__ import annotations

from dataclasses import dataclass, field

import numpy as np

DEFAULT_SPEED_MPS = 10.0


@dataclass(frozen=True, eq=False)
class Trajectory:
    """A piecewise-linear 4D trajectory.

    Attributes:
        times_s: (p,) float64 waypoint times [s], strictly increasing, p >= 2.
        points_m: (p, 3) float64 waypoint positions in ENU metres.
    """

    times_s: np.ndarray
    points_m: np.ndarray
    _segments: tuple | None = field(default=None, repr=False, compare=False)

    def __post_init__(self):
        times = np.ascontiguousarray(self.times_s, dtype=np.float64)
        points = np.ascontiguousarray(self.points_m, dtype=np.float64)
        if times.ndim != 1 or times.shape[0] < 2:
            raise ValueError(f"times_s must be a 1-D array of at least 2 times, got shape {times.shape}")
        if points.shape != (times.shape[0], 3):
            raise ValueError(f"points_m must have shape ({times.shape[0]}, 3), got {points.shape}")
        if not (np.all(np.isfinite(times)) and np.all(np.isfinite(points))):
            raise ValueError("times_s and points_m must be finite")
        if np.any(np.diff(times) <= 0.0):
            bad = int(np.argmax(np.diff(times) <= 0.0))
            raise ValueError(f"times_s must be strictly increasing; times_s[{bad}]={times[bad]} "
                             f">= times_s[{bad + 1}]={times[bad + 1]}")
        times.setflags(write=False)
        points.setflags(write=False)
        object.__setattr__(self, "times_s", times)
        object.__setattr__(self, "points_m", points)

    @property
    def departure_s(self) -> float:
        """Departure time [s] (first waypoint)."""
        return float(self.times_s[0])

    @property
    def arrival_s(self) -> float:
        """Arrival time [s] (last waypoint)."""
        return float(self.times_s[-1])

    @property
    def n_segments(self) -> int:
        return int(self.times_s.shape[0] - 1)

    def is_airborne(self, t_s) -> np.ndarray | bool:
        """True where departure_s <= t_s <= arrival_s (vectorised over t_s)."""
        t = np.asarray(t_s, dtype=np.float64)
        out = (t >= self.times_s[0]) & (t <= self.times_s[-1])
        return bool(out) if out.ndim == 0 else out

    def position_at(self, t_s, clamp: bool = False) -> np.ndarray:
        """ENU position [m] at time(s) ``t_s``.

        Args:
            t_s: scalar or array of times [s].
            clamp: if True, times before departure (after arrival) give the first (last) waypoint;
                if False they give NaN (the vehicle is not airborne).
        Returns: (3,) for a scalar time, else (..., 3). O(len(t) log p).
        """
        t = np.asarray(t_s, dtype=np.float64)
        flat = np.atleast_1d(t).ravel()
        out = np.empty((flat.shape[0], 3), dtype=np.float64)
        for d in range(3):
            out[:, d] = np.interp(flat, self.times_s, self.points_m[:, d])
        if not clamp:
            out[(flat < self.times_s[0]) | (flat > self.times_s[-1])] = np.nan
        return out[0] if t.ndim == 0 else out.reshape(t.shape + (3,))

    def segments(self) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
        """Segment arrays ``(t0_s, t1_s, p0_m, v_mps)`` with shapes (s,), (s,), (s,3), (s,3)."""
        if self._segments is None:
            t0 = self.times_s[:-1]
            t1 = self.times_s[1:]
            p0 = self.points_m[:-1]
            v = (self.points_m[1:] - p0) / (t1 - t0)[:, None]
            object.__setattr__(self, "_segments", (t0, t1, p0, v))
        return self._segments

    @classmethod
    def _trusted(cls, times_s: np.ndarray, points_m: np.ndarray, segments: tuple) -> "Trajectory":
        """Build without validation from arrays already checked (cached route templates)."""
        obj = object.__new__(cls)
        object.__setattr__(obj, "times_s", times_s)
        object.__setattr__(obj, "points_m", points_m)
        object.__setattr__(obj, "_segments", segments)
        return obj

    def shifted(self, dt_s: float) -> "Trajectory":
        """The same path flown ``dt_s`` seconds later."""
        return Trajectory(self.times_s + float(dt_s), self.points_m)


def relative_times_s(points_m: np.ndarray, speed_mps: float = DEFAULT_SPEED_MPS) -> np.ndarray:
    """Cumulative flight time [s] from the first waypoint at constant ``speed_mps`` (p,).

    Raises ValueError if the speed is not positive and finite or two consecutive waypoints coincide.
    """
    if not (np.isfinite(speed_mps) and speed_mps > 0.0):
        raise ValueError(f"speed_mps must be positive and finite, got {speed_mps!r}")
    pts = np.asarray(points_m, dtype=np.float64)
    if pts.ndim != 2 or pts.shape[1] != 3 or pts.shape[0] < 2:
        raise ValueError(f"points_m must have shape (p>=2, 3), got {pts.shape}")
    seg_len = np.linalg.norm(np.diff(pts, axis=0), axis=1)
    if np.any(seg_len <= 0.0):
        bad = int(np.argmax(seg_len <= 0.0))
        raise ValueError(f"points_m[{bad}] and points_m[{bad + 1}] coincide (zero-length segment)")
    return np.concatenate(([0.0], np.cumsum(seg_len))) / float(speed_mps)


def trajectory_from_points(points_m, departure_s: float,
                           speed_mps: float = DEFAULT_SPEED_MPS) -> Trajectory:
    """Constant-speed trajectory through ``points_m`` (p, 3) departing at ``departure_s`` [s]."""
    if not np.isfinite(departure_s):
        raise ValueError(f"departure_s must be finite, got {departure_s!r}")
    rel = relative_times_s(points_m, speed_mps)
    return Trajectory(rel + float(departure_s), np.asarray(points_m, dtype=np.float64))


def trajectory_from_route(network, node_indices, departure_s: float,
                          speed_mps: float = DEFAULT_SPEED_MPS) -> Trajectory:
    """Constant-speed trajectory along a route of network node indices.

    Args:
        network: a ``uam_planner.network.Network`` (uses ``enu_m``).
        node_indices: route as node indices, origin first (at least 2).
        departure_s: departure time [s].
        speed_mps: cruise speed [m/s].
    """
    idx = np.asarray(node_indices, dtype=np.int64)
    if idx.ndim != 1 or idx.shape[0] < 2:
        raise ValueError(f"node_indices must list at least 2 nodes, got {list(idx)}")
    return trajectory_from_points(network.enu_m[idx], departure_s, speed_mps)
