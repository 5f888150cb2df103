"""Fleet kinematics: the vehicles of approved flights moving along their 4D plans, free of ROS.

Each vehicle flies its piecewise-linear trajectory exactly (constant speed per segment, as
planned); the simulator samples the fleet at fixed steps. A vehicle is airborne from its
departure to its arrival time inclusive and is dropped after it landed.

Sampling is vectorised over the fleet: the flights' waypoints are kept in padded arrays
(rebuilt only when flights were added), so one sample costs a few numpy operations whatever the
fleet size.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uam_planner.trajectory import Trajectory

PHASE_TAKEOFF = 0   # first segment (mirrors uam_msgs/VehicleState.PHASE_*)
PHASE_CRUISE = 1
PHASE_LANDING = 2


@dataclass(frozen=True)
class FleetSample:
    """The airborne vehicles at one time, one row each, sorted by id. ENU metres and m/s."""

    t_s: float
    vehicle_ids: list
    positions_m: np.ndarray       # (v, 3)
    velocities_mps: np.ndarray    # (v, 3)
    phases: np.ndarray            # (v,) PHASE_*
    segment_indices: np.ndarray   # (v,)
    flown_m: np.ndarray           # (v,) distance flown since departure
    remaining_m: np.ndarray       # (v,) distance left to the destination

    def __len__(self) -> int:
        return len(self.vehicle_ids)


class Fleet:
    """The set of approved flights, sampled at any time.

    ``add(vehicle_id, trajectory)`` registers a flight; ``sample(t_s)`` returns the airborne
    vehicles at ``t_s`` sorted by id and forgets the ones that landed before ``t_s``.
    O(v p) per sample for v flights of at most p waypoints, vectorised.

    Each flight's arrays (times, points, cumulative distance) are computed once, when it is
    added; the padded fleet arrays are rebuilt from them only when flights were added (once per
    epoch in the simulator). A landed flight stays in them, masked out, until that rebuild:
    rebuilding at every landing cost the simulator 1.5 s of a 3,500 s paper run (BENCHMARKS.md).
    """

    def __init__(self):
        self._flights: dict[str, tuple] = {}   # id -> (times (k,), points (k, 3), cumulative m (k,))
        self._arrays = None
        self.total_added = 0

    def __len__(self) -> int:
        return len(self._flights)

    def add(self, vehicle_id: str, trajectory: Trajectory) -> None:
        if vehicle_id in self._flights:
            raise ValueError(f"vehicle_id: {vehicle_id!r} is already flying")
        times = np.asarray(trajectory.times_s, dtype=np.float64)
        points = np.asarray(trajectory.points_m, dtype=np.float64)
        cum = np.zeros(times.shape[0])
        cum[1:] = np.cumsum(np.sqrt(np.square(np.diff(points, axis=0)).sum(axis=1)))
        self._flights[vehicle_id] = (times, points, cum)
        self._arrays = None
        self.total_added += 1

    def update(self, vehicle_id: str, trajectory: Trajectory, effective_s: float) -> None:
        """Fly a new plan version of ``vehicle_id`` from ``effective_s`` on: the old trajectory
        before, the new one after (``uam_planner.replanning.spliced``: ValueError if the two do
        not chain, i.e. the new one is not where the old one is at ``effective_s``). A flight
        not (or no longer) in the fleet is added with the new trajectory."""
        from uam_planner.replanning import spliced
        got = self._flights.pop(vehicle_id, None)
        if got is not None:
            old = Trajectory(got[0], got[1])
            try:
                trajectory = spliced(old, trajectory, effective_s)
            except ValueError:
                self._flights[vehicle_id] = got
                raise
            self.total_added -= 1  # a new version, not a new flight
        self.add(vehicle_id, trajectory)

    def flown(self, vehicle_id: str) -> Trajectory | None:
        """The trajectory ``vehicle_id`` flies (None if it is not in the fleet)."""
        got = self._flights.get(vehicle_id)
        return None if got is None else Trajectory(got[0], got[1])

    def replace(self, vehicle_id: str, trajectory: Trajectory) -> None:
        """Fly ``trajectory`` for ``vehicle_id`` in place of what it flew (not a new flight): with
        disturbances, a new plan version is flown by the path-following model over the spliced
        plan, whose track equals the old one up to the switch (uam_sim.world.disturbance is causal)."""
        if self._flights.pop(vehicle_id, None) is not None:
            self.total_added -= 1
        self.add(vehicle_id, trajectory)

    def remove(self, vehicle_id: str) -> bool:
        """Drop ``vehicle_id`` (a cancelled plan); True if it was in the fleet."""
        found = self._flights.pop(vehicle_id, None) is not None
        if found:
            self._arrays = None
        return found

    def _build(self):
        ids = sorted(self._flights)
        v = len(ids)
        p = max((self._flights[i][0].shape[0] for i in ids), default=2)
        T = np.full((v, p), np.inf)
        P = np.empty((v, p, 3))
        C = np.empty((v, p))
        nseg = np.empty(v, dtype=np.int64)
        for row, vid in enumerate(ids):
            times, points, cum = self._flights[vid]
            k = times.shape[0]
            T[row, :k] = times
            P[row, :k] = points
            P[row, k:] = points[-1]
            C[row, :k] = cum
            C[row, k:] = cum[-1]
            nseg[row] = k - 1
        arrival = T[np.arange(v), nseg] if v else np.zeros(0)
        # rows still in the fleet (a landed row is masked out until the next rebuild)
        self._arrays = (ids, T, P, C, nseg, arrival, np.ones(v, dtype=bool))

    def sample(self, t_s: float) -> FleetSample:
        if self._arrays is None:
            self._build()
        ids, T, P, C, nseg, arrival, alive = self._arrays
        landed = alive & (arrival < t_s)
        if landed.any():
            for row in np.flatnonzero(landed):
                del self._flights[ids[row]]
            alive &= ~landed
        rows = np.flatnonzero(alive & (T[:, 0] <= t_s))
        seg = np.minimum((T[rows] <= t_s).sum(axis=1) - 1, nseg[rows] - 1)
        t0, t1 = T[rows, seg], T[rows, seg + 1]
        frac = (t_s - t0) / (t1 - t0)
        p0, p1 = P[rows, seg], P[rows, seg + 1]
        pos = p0 + frac[:, None] * (p1 - p0)
        vel = (p1 - p0) / (t1 - t0)[:, None]
        c0, c1 = C[rows, seg], C[rows, seg + 1]
        flown = c0 + frac * (c1 - c0)
        total = C[rows, nseg[rows]]
        phase = np.where(seg == 0, PHASE_TAKEOFF, np.where(seg == nseg[rows] - 1, PHASE_LANDING, PHASE_CRUISE))
        return FleetSample(float(t_s), [ids[r] for r in rows.tolist()], pos, vel, phase.astype(np.uint8),
                           seg.astype(np.int64), flown, total - flown)
