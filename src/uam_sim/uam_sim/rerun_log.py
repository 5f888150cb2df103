"""Rerun logging of a run: the network, the fleet on a ``sim_time`` timeline, routes and metrics.

Entity layout (ENU metres, z up):

- ``world/network/corridors`` (static): one 2-point LineStrips3D per corridor; on a layered
  network (flight levels) one per corridor and level, at the level's height and in the level's
  colour (:data:`LEVEL_COLORS`);
- ``world/network/aerodromes`` (static): Points3D labelled with the aerodrome names;
- ``world/network/waypoints`` (static): the other network nodes, small grey points;
- ``world/vehicles``: Points3D of the airborne vehicles at each simulation step, labelled with
  their vehicle ids (the request ids);
- ``world/routes/<request_id>``: the approved 4D route of a flight as a LineStrips3D, logged at
  the decision time and cleared when the vehicle has landed (it left the fleet state); on a
  layered network in the colour of its cruise level (:func:`flight_level_index`);
- ``metrics/approved_cumulative``, ``metrics/active_aircraft``, ``metrics/mwis_vertices``,
  ``metrics/mwis_selected``, ``metrics/solve_time_s``, ``metrics/pending_requests``: Scalars
  once per planning epoch.

Every time-varying entity is logged on the ``sim_time`` timeline (a duration, seconds of
simulation time). Modes: ``"off"`` (nothing, rerun is not even imported), ``"save"`` (an .rrd
file), ``"spawn"`` (start a local viewer and stream to it), ``"connect"`` (stream to a running
viewer at ``connect_url``, default ``rerun+http://127.0.0.1:9876/proxy``).

The ``log_*_msg`` methods take ROS messages (duck-typed, so this module never imports rclpy).
"""

from __future__ import annotations

import os
from pathlib import Path
from typing import Any, Sequence

import numpy as np

MODES = ("off", "save", "spawn", "connect")
TIMELINE = "sim_time"

_AERODROME_COLOR = (255, 170, 0)
_CORRIDOR_COLOR = (90, 140, 200)
_WAYPOINT_COLOR = (150, 150, 150)
_VEHICLE_COLOR = (230, 40, 60)
_ROUTE_COLOR = (60, 200, 90)
#: Colours of flight levels 0, 1, ... (lowest first), cycled when there are more levels.
LEVEL_COLORS = ((90, 140, 200), (0, 200, 200), (160, 110, 230), (230, 200, 60), (120, 200, 90))


def flight_level_index(points_m: Any, levels_m: Sequence[float]) -> int:
    """Index of the cruise level of a flight on a layered network (the level nearest its highest
    waypoint: flights climb to one level and keep it to the descent); -1 without levels."""
    pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    if not len(levels_m) or not len(pts):
        return -1
    return int(np.argmin(np.abs(np.asarray(levels_m, dtype=np.float64) - pts[:, 2].max())))


def _stamp_s(stamp: Any) -> float:
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


class RerunLogger:
    """Log a fleet run to Rerun.

    Args:
        mode: "off" | "save" | "spawn" | "connect".
        rrd_path: the .rrd file for mode "save" (parent directories are created).
        network: a ``uam_planner.network.Network`` to log once as static data, or None.
        app_id: Rerun application id.
        connect_url: the viewer's gRPC url for mode "connect" (None: Rerun's default).
        recording_id: optional Rerun recording id (to merge several streams into one recording).
    Raises ValueError naming the bad argument.
    """

    def __init__(self, mode: str, rrd_path: str | os.PathLike | None = None, network: Any = None,
                 app_id: str = "uam_fleet", connect_url: str | None = None,
                 recording_id: str | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f"mode: {mode!r} is not one of {MODES}")
        if mode == "save" and not rrd_path:
            raise ValueError("rrd_path: required when mode is 'save'")
        self.mode = mode
        self.rrd_path = Path(rrd_path) if rrd_path else None
        self._rec = None
        self._rr = None
        self._airborne: set[str] = set()
        self._routes: set[str] = set()
        self._levels_m: tuple = ()
        self._approved_total = 0
        if mode == "off":
            return
        import rerun as rr

        self._rr = rr
        self._rec = rr.RecordingStream(app_id, recording_id=recording_id)
        if mode == "save":
            self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
            self._rec.save(str(self.rrd_path))
        elif mode == "spawn":
            self._rec.spawn()
        else:
            self._rec.connect_grpc(connect_url)
        self._rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        if network is not None:
            self.log_network(network)

    @property
    def enabled(self) -> bool:
        return self._rec is not None

    @property
    def approved_total(self) -> int:
        """Approvals counted so far from the logged flight plans."""
        return self._approved_total

    def _at(self, t_s: float) -> None:
        self._rec.set_time(TIMELINE, duration=float(t_s))

    # -- static data ----------------------------------------------------------------------

    def log_network(self, network: Any) -> None:
        """Corridors, aerodromes and waypoints of a Network (ENU metres), as static data."""
        if not self.enabled:
            return
        rr = self._rr
        enu = np.asarray(network.enu_m, dtype=np.float64)
        edges = np.asarray(network.edges, dtype=np.int64).reshape(-1, 2)
        strips = enu[edges] if len(edges) else np.zeros((0, 2, 3))
        self._levels_m = tuple(float(z) for z in (getattr(network, "levels_m", None) or ()))
        if self._levels_m:  # layered: every corridor at every level, coloured by level
            per_level = []
            for z in self._levels_m:
                s_z = strips.copy()
                s_z[:, :, 2] = z
                per_level.append(s_z)
            colors = [LEVEL_COLORS[i % len(LEVEL_COLORS)] for i in range(len(self._levels_m))
                      for _ in range(len(strips))]
            self._rec.log("world/network/corridors",
                          rr.LineStrips3D(list(np.concatenate(per_level)), colors=colors, radii=4.0),
                          static=True)
        else:
            self._rec.log("world/network/corridors",
                          rr.LineStrips3D(list(strips), colors=_CORRIDOR_COLOR, radii=4.0), static=True)
        is_aero = np.asarray(network.is_aerodrome, dtype=bool)
        names = list(getattr(network, "names", None) or network.node_ids)
        labels = [names[i] for i in np.flatnonzero(is_aero)]
        self._rec.log("world/network/aerodromes",
                      rr.Points3D(enu[is_aero], labels=labels, colors=_AERODROME_COLOR, radii=40.0,
                                  show_labels=True), static=True)
        self._rec.log("world/network/waypoints",
                      rr.Points3D(enu[~is_aero], colors=_WAYPOINT_COLOR, radii=10.0), static=True)

    # -- time-varying data ------------------------------------------------------------------

    def log_fleet(self, t_s: float, vehicle_ids: Sequence[str], positions_m: Any) -> None:
        """The airborne vehicles at simulation time ``t_s`` [s]; clears routes of landed ones."""
        if not self.enabled:
            return
        rr = self._rr
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        ids = [str(v) for v in vehicle_ids]
        if len(ids) != len(pos):
            raise ValueError(f"vehicle_ids: {len(ids)} ids for {len(pos)} positions")
        self._at(t_s)
        self._rec.log("world/vehicles", rr.Points3D(pos, labels=ids, colors=_VEHICLE_COLOR,
                                                    radii=30.0))
        now = set(ids)
        for landed in sorted(self._airborne - now):
            if landed in self._routes:
                self._rec.log(f"world/routes/{landed}", rr.Clear(recursive=False))
                self._routes.discard(landed)
        self._airborne = now

    def log_route(self, t_s: float, request_id: str, points_m: Any) -> None:
        """An approved flight's route (waypoints, ENU metres) from decision time ``t_s`` [s]."""
        if not self.enabled:
            return
        pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
        self._at(t_s)
        level = flight_level_index(pts, self._levels_m)
        color = _ROUTE_COLOR if level < 0 else LEVEL_COLORS[level % len(LEVEL_COLORS)]
        self._rec.log(f"world/routes/{request_id}",
                      self._rr.LineStrips3D([pts], colors=color, radii=6.0,
                                            labels=[str(request_id)]))
        self._routes.add(str(request_id))

    def log_epoch(self, t_s: float, *, approved_cumulative: int, active_aircraft: int,
                  mwis_vertices: int, mwis_selected: int, solve_time_s: float,
                  pending_requests: int = 0) -> None:
        """Per-epoch metrics as Scalars at simulation time ``t_s`` [s]."""
        if not self.enabled:
            return
        rr = self._rr
        self._at(t_s)
        for name, value in (("approved_cumulative", approved_cumulative),
                            ("active_aircraft", active_aircraft),
                            ("mwis_vertices", mwis_vertices),
                            ("mwis_selected", mwis_selected),
                            ("solve_time_s", solve_time_s),
                            ("pending_requests", pending_requests)):
            self._rec.log(f"metrics/{name}", rr.Scalars(float(value)))

    # -- ROS messages (duck-typed) ----------------------------------------------------------

    def log_fleet_state_msg(self, msg: Any) -> None:
        """A uam_msgs/FleetState."""
        if not self.enabled:
            return
        ids = [v.vehicle_id for v in msg.vehicles]
        pos = [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]
        self.log_fleet(_stamp_s(msg.header.stamp), ids, pos)

    def log_flight_plan_msg(self, msg: Any) -> None:
        """A uam_msgs/FlightPlan: approved plans add a route and count towards the total."""
        if not self.enabled or int(msg.outcome) != 0:  # OUTCOME_APPROVED
            return
        self._approved_total += 1
        pts = [(w.position.x, w.position.y, w.position.z) for w in msg.waypoints]
        if pts:
            self.log_route(_stamp_s(msg.header.stamp), msg.request_id, pts)

    def log_planning_report_msg(self, msg: Any) -> None:
        """A uam_msgs/PlanningReport: the epoch's metrics (approvals counted from the reports)."""
        if not self.enabled:
            return
        self._report_approved = getattr(self, "_report_approved", 0) + int(msg.approved)
        self.log_epoch(_stamp_s(msg.header.stamp),
                       approved_cumulative=self._report_approved,
                       active_aircraft=int(msg.active_flights),
                       mwis_vertices=int(msg.vertices),
                       mwis_selected=len(msg.instance.selected),
                       solve_time_s=float(msg.solve_time_s),
                       pending_requests=int(msg.pending_requests))

    def close(self) -> None:
        """Flush everything and close the sink (the .rrd file is complete afterwards)."""
        if self._rec is None:
            return
        rec, self._rec = self._rec, None
        rec.flush()
        rec.disconnect()

    def __enter__(self) -> "RerunLogger":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()
