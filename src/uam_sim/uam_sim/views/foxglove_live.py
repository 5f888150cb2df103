"""Live view of a running fleet for Foxglove, served over the Foxglove WebSocket protocol.

Uses the ``foxglove-sdk`` package (pinned in requirements.txt). Channels, all in frame ``enu``
(the network's local east-north-up frame, metres) and stamped in real UTC (scenario start +
simulation time):

=======================  =============================  =======================================
topic                    schema                         content
=======================  =============================  =======================================
``/uam/live/network``    foxglove.SceneUpdate           corridors (one line list per flight level,
                                                        the Rerun colours), vertiports and names;
                                                        sent again to every new subscriber
``/uam/live/routes``     foxglove.SceneUpdate           each approved route from its decision,
                                                        removed by its lifetime at arrival
``/uam/live/fleet``      foxglove.PointCloud            the airborne aircraft, every step
``/uam/live/fleet_geo``  foxglove.LocationFixes         the same in WGS84, for the Map panel
``/uam/live/metrics``    JSON                           approved (cumulative), airborne, pending,
                                                        MWIS size and selected, solve time [s]
=======================  =============================  =======================================

Connect: Foxglove -> *Open connection* -> *Foxglove WebSocket* -> ``ws://HOST:PORT`` (default
port 8765); in the 3D panel choose display frame ``enu``. The recorder node serves it with
``-p foxglove_port:=8765`` (0 = off). The ``on_*`` methods take ROS messages duck-typed, so this
module never imports rclpy.
"""

from __future__ import annotations

import json
from typing import Any

import numpy as np

from uam_contract.stamps import stamp_ns
from uam_contract import names
from uam_contract.names import resolved
from .std_msgs_export import DEFAULT_SCENARIO_START_UTC, FRAME_ID, scenario_start_ns

TOPIC_NETWORK = resolved(names.TOPIC_LIVE_NETWORK)
TOPIC_ROUTES = resolved(names.TOPIC_LIVE_ROUTES)
TOPIC_FLEET = resolved(names.TOPIC_LIVE_FLEET)
TOPIC_FLEET_GEO = resolved(names.TOPIC_LIVE_FLEET_GEO)
TOPIC_METRICS = resolved(names.TOPIC_LIVE_METRICS)

_NS = 1_000_000_000



class FoxgloveLive:
    """A Foxglove WebSocket server showing the fleet (see the module docstring).

    Args:
        network: the run's Network, or None (no network scene, no geographic fixes).
        port: TCP port (0 = any free port; :attr:`port` tells which).
        host: interface to listen on ("127.0.0.1" = this machine only).
        scenario_start_utc: ISO 8601 instant of simulation time 0 (the stamps' epoch).
    Raises ValueError for a bad ``scenario_start_utc`` or port.
    """

    def __init__(self, network: Any = None, port: int = 8765, host: str = "127.0.0.1",
                 scenario_start_utc: str = DEFAULT_SCENARIO_START_UTC) -> None:
        if not 0 <= int(port) <= 65535:
            raise ValueError(f"port: {port!r} is not in 0..65535")
        import foxglove
        from foxglove import Channel, Context
        from foxglove.channels import LocationFixesChannel, PointCloudChannel, SceneUpdateChannel

        self._fg = foxglove
        self.network = network
        self.start_ns = scenario_start_ns(scenario_start_utc)
        self._ctx = Context()
        self._network_ch = SceneUpdateChannel(TOPIC_NETWORK, context=self._ctx)
        self._routes_ch = SceneUpdateChannel(TOPIC_ROUTES, context=self._ctx)
        self._fleet_ch = PointCloudChannel(TOPIC_FLEET, context=self._ctx)
        self._geo_ch = LocationFixesChannel(TOPIC_FLEET_GEO, context=self._ctx)
        self._metrics_ch = Channel(TOPIC_METRICS, message_encoding="json", context=self._ctx, schema={
            "type": "object", "properties": {k: {"type": "number"} for k in (
                "approved_cumulative", "active_aircraft", "pending_requests", "mwis_vertices",
                "mwis_selected", "solve_time_s")}})
        self._approved = 0
        self._last_sim_ns = 0
        live = self

        class _Listener(foxglove.ServerListener):
            def on_subscribe(self, client, channel) -> None:  # noqa: ANN001 - SDK callback
                if channel.topic == TOPIC_NETWORK:
                    live.send_network()

        self._server = foxglove.start_server(name="uam_fleet", host=host, port=int(port),
                                             context=self._ctx, server_listener=_Listener())
        self.port = self._server.port

    # -- helpers ----------------------------------------------------------------------------

    def _ts(self, sim_ns: int):
        t = self.start_ns + int(sim_ns)
        return self._fg.messages.Timestamp(sec=t // _NS, nsec=t % _NS)

    def _color(self, rgb, alpha: float = 1.0):
        return self._fg.messages.Color(r=rgb[0] / 255, g=rgb[1] / 255, b=rgb[2] / 255, a=alpha)

    def _pose(self, p):
        m = self._fg.messages
        return m.Pose(position=m.Vector3(x=float(p[0]), y=float(p[1]), z=float(p[2])),
                      orientation=m.Quaternion(x=0.0, y=0.0, z=0.0, w=1.0))

    def _points(self, pts):
        P = self._fg.messages.Point3
        return [P(x=float(p[0]), y=float(p[1]), z=float(p[2])) for p in pts]

    # -- what is shown ----------------------------------------------------------------------

    def send_network(self) -> None:
        """The network scene (also sent to every new subscriber of its channel)."""
        if self.network is None:
            return
        from .rerun_log import AERODROME_COLOR, LEVEL_COLORS, _node_labels, corridor_levels

        m = self._fg.messages
        net = self.network
        enu = np.asarray(net.enu_m, dtype=np.float64)
        edges = np.asarray(net.edges, dtype=np.int64).reshape(-1, 2)
        levels = corridor_levels(net)
        lines = [m.LinePrimitive(type=m.LinePrimitiveLineType.LineList, thickness=2.0, scale_invariant=True,
                                 points=self._points(enu[edges[levels == lv]].reshape(-1, 3)),
                                 color=self._color(LEVEL_COLORS[lv % len(LEVEL_COLORS)]))
                 for lv in sorted(set(levels.tolist()))]
        aero = np.flatnonzero(np.asarray(net.is_aerodrome, dtype=bool))
        labels = _node_labels(net)
        spheres = [m.SpherePrimitive(pose=self._pose(enu[i]),
                                     size=m.Vector3(x=150.0, y=150.0, z=150.0), color=self._color(AERODROME_COLOR))
                   for i in aero]
        texts = [m.TextPrimitive(pose=self._pose(enu[i] + (0, 0, 200.0)), billboard=True,
                                 font_size=14.0, scale_invariant=True, color=self._color((255, 255, 255)),
                                 text=labels[i]) for i in aero]
        entity = m.SceneEntity(timestamp=self._ts(self._last_sim_ns), frame_id=FRAME_ID, id="network",
                               lines=lines, spheres=spheres, texts=texts)
        self._network_ch.log(m.SceneUpdate(entities=[entity]), log_time=self.start_ns + self._last_sim_ns)

    def on_flight_plan(self, plan: Any) -> None:
        """An approved uam_msgs/FlightPlan becomes a route entity living until its arrival."""
        if int(plan.outcome) != 0 or not plan.waypoints:
            return
        from .rerun_log import ROUTE_COLOR

        m = self._fg.messages
        self._approved += 1
        t_ns = stamp_ns(plan.header.stamp)
        life_ns = max(stamp_ns(plan.arrival_time) - t_ns, 1)
        line = m.LinePrimitive(type=m.LinePrimitiveLineType.LineStrip, thickness=1.5, scale_invariant=True,
                               points=self._points([(w.position.x, w.position.y, w.position.z)
                                                    for w in plan.waypoints]),
                               color=self._color(ROUTE_COLOR[:3], 0.8))
        entity = m.SceneEntity(timestamp=self._ts(t_ns), frame_id=FRAME_ID, id=str(plan.request_id),
                               lifetime=m.Duration(sec=life_ns // _NS, nsec=life_ns % _NS), lines=[line])
        self._routes_ch.log(m.SceneUpdate(entities=[entity]), log_time=self.start_ns + t_ns)

    def on_fleet(self, sim_ns: int, vehicle_ids, positions_m) -> None:
        """The airborne aircraft at simulation time ``sim_ns`` [ns] (ENU metres)."""
        m = self._fg.messages
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        self._last_sim_ns = int(sim_ns)
        f32 = m.PackedElementFieldNumericType.Float32
        cloud = m.PointCloud(timestamp=self._ts(sim_ns), frame_id=FRAME_ID, point_stride=12,
                             fields=[m.PackedElementField(name=n, offset=o, type=f32)
                                     for n, o in (("x", 0), ("y", 4), ("z", 8))],
                             data=pos.astype("<f4").tobytes())
        self._fleet_ch.log(cloud, log_time=self.start_ns + int(sim_ns))
        if self.network is not None:
            from uam_planner.geo import enu_to_geodetic
            lla = enu_to_geodetic(pos, self.network.origin_lat_lon_alt) if len(pos) else np.zeros((0, 3))
            fixes = [m.LocationFix(timestamp=self._ts(sim_ns), frame_id=str(v), latitude=float(a),
                                   longitude=float(b), altitude=float(c))
                     for v, (a, b, c) in zip(vehicle_ids, lla.tolist())]
            self._geo_ch.log(m.LocationFixes(fixes=fixes), log_time=self.start_ns + int(sim_ns))

    def on_fleet_state(self, msg: Any) -> None:
        """A uam_msgs/FleetState (duck-typed)."""
        self.on_fleet(stamp_ns(msg.header.stamp), [v.vehicle_id for v in msg.vehicles],
                      [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles])

    def on_planning_report(self, msg: Any) -> None:
        """A uam_msgs/PlanningReport: the epoch's metrics as one JSON message."""
        t_ns = stamp_ns(msg.header.stamp)
        self._report_approved = getattr(self, "_report_approved", 0) + int(msg.approved)
        self._metrics_ch.log(json.dumps({
            "approved_cumulative": self._report_approved, "active_aircraft": int(msg.active_flights),
            "pending_requests": int(msg.pending_requests), "mwis_vertices": int(msg.vertices),
            "mwis_selected": len(msg.instance.selected), "solve_time_s": float(msg.solve_time_s)}).encode(),
            log_time=self.start_ns + t_ns)

    def close(self) -> None:
        """Stop the server. Idempotent."""
        if self._server is not None:
            server, self._server = self._server, None
            server.stop()

    def __enter__(self) -> "FoxgloveLive":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()

