"""Fleet kinematics: the vehicles of approved flights moving along their 4D plans, free of ROS.

Each vehicle flies its piecewise-linear trajectory exactly (constant speed per segment, as
planned); the simulator samples the fleet at fixed steps. A vehicle is airborne from its
departure to its arrival time inclusive and is dropped after it landed.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uam_planner.trajectory import Trajectory

PHASE_TAKEOFF = 0   # first segment (mirrors uam_msgs/VehicleState.PHASE_*)
PHASE_CRUISE = 1
PHASE_LANDING = 2


@dataclass(frozen=True)
class VehicleSample:
    """One airborne vehicle at one time. Positions [m] and velocities [m/s] in ENU."""

    vehicle_id: str
    position_m: np.ndarray
    velocity_mps: np.ndarray
    phase: int
    segment_index: int
    distance_flown_m: float
    distance_remaining_m: float


class Fleet:
    """The set of approved flights, sampled at any time.

    ``add(vehicle_id, trajectory)`` registers a flight; ``sample(t_s)`` returns the airborne
    vehicles at ``t_s`` sorted by id and forgets the ones that landed before ``t_s``.
    O(v log p) per sample for v vehicles of p waypoints.
    """

    def __init__(self):
        self._flights: dict[str, tuple[Trajectory, np.ndarray]] = {}
        self.total_added = 0

    def __len__(self) -> int:
        return len(self._flights)

    def add(self, vehicle_id: str, trajectory: Trajectory) -> None:
        if vehicle_id in self._flights:
            raise ValueError(f"vehicle_id: {vehicle_id!r} is already flying")
        seg_len = np.linalg.norm(np.diff(trajectory.points_m, axis=0), axis=1)
        self._flights[vehicle_id] = (trajectory, np.concatenate([[0.0], np.cumsum(seg_len)]))
        self.total_added += 1

    def sample(self, t_s: float) -> list[VehicleSample]:
        out: list[VehicleSample] = []
        landed = []
        for vid in sorted(self._flights):
            traj, cum = self._flights[vid]
            times, points = traj.times_s, traj.points_m
            if t_s > times[-1]:
                landed.append(vid)
                continue
            if t_s < times[0]:
                continue
            seg = int(min(np.searchsorted(times, t_s, side="right") - 1, len(times) - 2))
            frac = (t_s - times[seg]) / (times[seg + 1] - times[seg])
            pos = points[seg] + frac * (points[seg + 1] - points[seg])
            vel = (points[seg + 1] - points[seg]) / (times[seg + 1] - times[seg])
            n_seg = len(times) - 1
            phase = PHASE_TAKEOFF if seg == 0 else (PHASE_LANDING if seg == n_seg - 1 else PHASE_CRUISE)
            flown = float(cum[seg] + frac * (cum[seg + 1] - cum[seg]))
            out.append(VehicleSample(vid, pos, vel, phase, seg, flown, float(cum[-1] - flown)))
        for vid in landed:
            del self._flights[vid]
        return out
