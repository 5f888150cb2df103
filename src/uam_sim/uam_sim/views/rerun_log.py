"""Rerun logging of a run: the network, the fleet on a ``sim_time`` timeline, routes, metrics, and
the blueprint (the layout of the viewer) that goes with every recording, live or ``.rrd``.

The blueprint (:func:`make_blueprint`) shows, side by side:

- **Network (top-down)**: a 3D view whose camera looks straight down on the network (north up),
  corridors coloured by flight level (one colour when the network has no levels), vertiports
  labelled where their labels do not overlap (:func:`declutter_labels`), aircraft as points whose size is in UI points (visible at any zoom), and the routes of
  the airborne flights as thin lines. Clicking an aircraft selects it *and* its route (they are
  instance ``k`` of the same entity, see ``world/fleet`` below), which Rerun highlights;
- **Side (from the south)**, for a layered network: its corridors and constraints again
  (``side/``), heights exaggerated (:func:`height_exaggeration`) so that the flight levels lie
  apart, each in its colour and labelled with its height; top-down the highest level covers the
  others;
- **Geographic**: the same network and fleet as GeoPoints / GeoLineStrings on a map
  (OpenStreetMap tiles when the viewer is online; the points are drawn without tiles too);
- **Metrics** on the ``sim_time`` timeline, two panels abreast with the map: approved (cumulative), airborne and pending flights;
  MWIS size (conflict-graph vertices) and selected vertices in panels of their own (at city scale
  ~20 selected beside ~1,300 vertices sat flat at 0 on one axis); MWIS solve time [s].

Entity layout (ENU metres, z up; geographic entities in WGS84 degrees):

- ``world/network/corridors`` (static): one 2-point LineStrips3D per corridor, coloured by level;
- ``world/network/aerodromes/labelled`` (static): Points3D of the vertiports whose labels (their
  names without a parenthesised part) fit without overlapping; ``.../unlabelled``: the others,
  their names shown on hover;
- ``world/network/waypoints`` (static): the other network nodes, small grey points;
- ``world/fleet``: Points3D of the airborne aircraft at each simulation step (labels = vehicle
  ids, shown on hover) and, on the same entity, LineStrips3D of their approved routes in the same
  instance order (re-logged only when the set of airborne flights changes);
- ``geo/network/corridors``, ``geo/network/aerodromes`` (static), ``geo/fleet``: the same in
  latitude/longitude (only with a network, whose origin places ENU on the Earth);
- ``metrics/approved_cumulative``, ``metrics/active_aircraft``, ``metrics/pending_requests``,
  ``metrics/mwis_vertices``, ``metrics/mwis_selected``, ``metrics/solve_time_s``: Scalars once
  per planning epoch;
- the decisions operators value, once per planning epoch from the plans and requests
  logged so far: ``metrics/decisions/approved`` and ``metrics/decisions/expired`` (cumulative),
  ``metrics/delay/p95_s`` and ``metrics/delay/mean_s`` (the approved flights' departure - their
  request's earliest departure, over the run so far; numpy's linear percentile, as
  ``uam_sim.world.flights``), ``metrics/share/<operator>`` (approved / decided so far, per named
  operator): the panels "Approvals and expiries", "Departure delay [s]" and
  "Operator approval share";
- ``side/network/corridors``, ``side/network/levels`` (static), ``side/constraints/<id>``: the
  side view's corridors, level labels and constraints, heights exaggerated (layered networks).

Every time-varying entity is logged on the ``sim_time`` timeline (a duration, seconds of
simulation time) and, given the scenario's UTC start (``utc_zero_ns``, as the recorder and
:func:`log_recording` pass it), on the ``utc`` timeline too (a timestamp: real dates).
Modes: ``"off"`` (nothing, rerun is not even imported), ``"save"`` (an .rrd
file), ``"spawn"`` (start a local viewer and stream to it), ``"connect"`` (stream to a running
viewer at ``connect_url``, default ``rerun+http://127.0.0.1:9876/proxy``).

The ``log_*_msg`` methods take ROS messages (duck-typed, so this module never imports rclpy).
``python -m uam_sim.rerun_log RUN.mcap --network NET.yaml --out RUN.rrd`` turns a recording into
an .rrd with the same content and blueprint (for runs recorded without Rerun).
"""

from __future__ import annotations

import os
import time
from pathlib import Path
from typing import Any, Sequence

from uam_contract import names
from uam_contract.names import RERUN_MODES, resolved
import numpy as np

from uam_contract.stamps import stamp_s

MODES = RERUN_MODES
TIMELINE = "sim_time"
#: the second timeline: the same instants on the scenario's UTC clock (a timestamp),
#: when the logger is given the scenario's start (``utc_zero_ns``), as the MCAP's log times are
UTC_TIMELINE = "utc"

#: Colours (RGB) of the view; tests look for these colours in screenshots.
AERODROME_COLOR = (255, 170, 0)
CORRIDOR_COLOR = (90, 140, 200)
WAYPOINT_COLOR = (150, 150, 150)
VEHICLE_COLOR = (255, 40, 200)
#: Routes of the airborne flights: opaque and wider than the corridors, so they show on top of them.
ROUTE_COLOR = (60, 220, 90, 255)
#: Corridor colours by flight level (level 0, 1, ...), cycled when there are more levels.
LEVEL_COLORS = ((90, 140, 200), (0, 200, 200), (160, 110, 230), (230, 200, 60), (120, 200, 90))

#: Sizes in UI points (constant on screen at any zoom); Rerun takes negative radii as UI points.
VEHICLE_RADIUS_UI = 5.0
AERODROME_RADIUS_UI = 5.0
WAYPOINT_RADIUS_UI = 1.5
CORRIDOR_RADIUS_UI = 1.5
ROUTE_RADIUS_UI = 2.5
#: Share of the network's horizontal extent that its height range spans in the views (heights
#: are exaggerated: 30 m between flight levels is invisible beside 40 km of city).
HEIGHT_SHARE = 0.25

#: Where the side view names the flight levels: left of the network by this share of its width.
LEVEL_LABEL_OFFSET = 0.15

#: Attribute names under which a network may carry one flight level per corridor.
LEVEL_ATTRIBUTES = ("edge_levels", "corridor_levels", "edge_level")


def _ui(points: float) -> float:
    return -abs(float(points))


def _strips_arrow(strips: Sequence[np.ndarray]) -> Any:
    """Line strips as one Arrow list array of Rerun's LineStrip3D type, built from one flat
    array (Rerun converts a Python list of strips one strip at a time: ~9 ms per re-log of the
    ~130 routes of the paper scenario, measured)."""
    import pyarrow as pa
    from rerun.components import LineStrip3DBatch
    from rerun.encodings import Vec3DBatch

    offsets = np.zeros(len(strips) + 1, dtype=np.int32)
    np.cumsum([len(s) for s in strips], out=offsets[1:])
    flat = np.concatenate(strips).astype(np.float32) if len(strips) else np.zeros((0, 3), np.float32)
    return pa.ListArray.from_arrays(pa.array(offsets), Vec3DBatch(flat).as_arrow_array(),
                                    type=LineStrip3DBatch._ARROW_DATATYPE)


def corridor_levels(network: Any) -> np.ndarray:
    """Flight level index (0, 1, ...) of each corridor of a network; all 0 when it has no levels.

    Reads the first of :data:`LEVEL_ATTRIBUTES` the network has (one value per edge; any
    hashable level labels, numbered in sorted order). Raises ValueError if its length differs
    from the number of corridors.
    """
    n_edges = int(np.asarray(network.edges).reshape(-1, 2).shape[0])
    for name in LEVEL_ATTRIBUTES:
        values = getattr(network, name, None)
        if values is None:
            continue
        values = list(values)
        if len(values) != n_edges:
            raise ValueError(f"network.{name}: {len(values)} levels for {n_edges} corridors")
        order = {v: i for i, v in enumerate(sorted(set(values)))}
        return np.array([order[v] for v in values], dtype=np.int64)
    return np.zeros(n_edges, dtype=np.int64)


def level_colors(levels: np.ndarray) -> np.ndarray:
    """(m, 3) uint8 colours of corridors with the given level indices (:data:`LEVEL_COLORS`)."""
    palette = np.asarray(LEVEL_COLORS, dtype=np.uint8)
    return palette[np.asarray(levels, dtype=np.int64) % len(palette)]


def flight_level_index(points_m: Any, levels_m: Sequence[float]) -> int:
    """Index of the cruise level of a flight on a layered network (the level nearest its highest
    waypoint: flights climb to one level and keep it to the descent); -1 without levels."""
    pts = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)
    if not len(levels_m) or not len(pts):
        return -1
    return int(np.argmin(np.abs(np.asarray(levels_m, dtype=np.float64) - pts[:, 2].max())))


def _node_labels(network: Any) -> list[str]:
    ids = list(network.node_ids)
    names = list(getattr(network, "names", None) or ids)
    return [str(n) if n else str(i) for n, i in zip(names, ids)]


#: Vertiport labels in the top-down view: their estimated size on screen at 1400x800, where the
#: network spans about LABEL_VIEW_PX pixels, LABEL_CHAR_PX per character and LABEL_LINE_PX high.
LABEL_VIEW_PX = 600.0
LABEL_CHAR_PX = 7.5
LABEL_LINE_PX = 18.0


def short_label(name: str) -> str:
    """A vertiport's name without its parenthesised part: ``"Tampines (Tampines West)"`` -> ``"Tampines"``."""
    return name.split(" (")[0].strip() or name


def declutter_labels(xy_m: Any, texts: Sequence[str], priority: Sequence[float] | None = None,
                     view_px: float = LABEL_VIEW_PX) -> np.ndarray:
    """Which labels to show so that no two overlap on screen: a boolean mask over ``texts``.

    Each label is a box centred on its anchor ``xy_m`` (ENU metres), ``len(text)`` x
    :data:`LABEL_CHAR_PX` wide and :data:`LABEL_LINE_PX` high, at the scale where the anchors'
    extent spans ``view_px`` pixels. Labels are taken greedily in order of ``priority``
    (highest first, ties in input order) and one is kept when its box meets no kept box.
    Deterministic; O(n^2) for n labels (a network has tens of vertiports).
    """
    xy = np.asarray(xy_m, dtype=np.float64).reshape(-1, 2)
    if len(xy) != len(texts):
        raise ValueError(f"texts: {len(texts)} labels for {len(xy)} anchors")
    if not len(xy):
        return np.zeros(0, dtype=bool)
    m_per_px = max(float(np.ptp(xy[:, 0])), float(np.ptp(xy[:, 1])), 100.0) / view_px
    half_w = np.array([len(t) for t in texts], dtype=np.float64) * LABEL_CHAR_PX * m_per_px / 2
    height = LABEL_LINE_PX * m_per_px
    order = np.argsort(-np.asarray(priority if priority is not None else np.zeros(len(xy)), dtype=np.float64),
                       kind="stable")
    keep = np.zeros(len(xy), dtype=bool)
    for i in order:
        kept = np.flatnonzero(keep)
        clear_x = np.abs(xy[kept, 0] - xy[i, 0]) >= half_w[kept] + half_w[i]
        clear_y = np.abs(xy[kept, 1] - xy[i, 1]) >= height
        keep[i] = bool(np.all(clear_x | clear_y))
    return keep


def height_exaggeration(network: Any) -> float:
    """Factor on heights (z) in the 3D views: the network's height range (its flight levels, else
    its nodes' heights, at least 100 m) spans :data:`HEIGHT_SHARE` of its horizontal extent."""
    enu = np.asarray(network.enu_m, dtype=np.float64).reshape(-1, 3)
    extent = float(max(np.ptp(enu[:, 0]), np.ptp(enu[:, 1]), 100.0)) if len(enu) else 1000.0
    heights = list(getattr(network, "levels_m", None) or ()) + list(enu[:, 2]) + [0.0]
    top = max(float(max(heights)), 100.0)
    return max(1.0, HEIGHT_SHARE * extent / top)


def side_eye(network: Any) -> tuple[tuple, tuple]:
    """Camera position and look target (ENU m, heights exaggerated) of the side view: from the
    south, level with the middle of the flight levels, far enough to see the whole width."""
    enu = np.asarray(network.enu_m, dtype=np.float64).reshape(-1, 3)
    lo, hi = enu[:, :2].min(axis=0), enu[:, :2].max(axis=0)
    centre = (lo + hi) / 2
    extent = float(max(hi - lo)) if len(enu) > 1 else 1000.0
    levels = list(getattr(network, "levels_m", None) or ()) or [float(enu[:, 2].max()) if len(enu) else 100.0]
    z = 0.5 * (min(levels) + max(levels)) * height_exaggeration(network)
    target = (float(centre[0]), float(centre[1]), z)
    return (target[0], float(lo[1]) - 0.2 * extent, z), target


def top_down_eye(network: Any, fov_y_deg: float = 55.0) -> tuple[tuple, tuple]:
    """Camera position and look target (ENU m) that frame the whole network from straight above."""
    enu = np.asarray(network.enu_m, dtype=np.float64).reshape(-1, 3)
    lo, hi = enu[:, :2].min(axis=0), enu[:, :2].max(axis=0)
    centre = (lo + hi) / 2
    extent = float(max(hi - lo)) if len(enu) > 1 else 1000.0
    height = 0.5 * max(extent, 100.0) / np.tan(np.radians(fov_y_deg) / 2)
    target = (float(centre[0]), float(centre[1]), 0.0)
    return (target[0], target[1], float(height)), target


def map_zoom(network: Any, pane_px: float = 200.0) -> float:
    """Web-map zoom level at which the network's extent fits a map pane of ``pane_px`` pixels."""
    enu = np.asarray(network.enu_m, dtype=np.float64).reshape(-1, 3)
    extent = float(max(np.ptp(enu[:, 0]), np.ptp(enu[:, 1]), 200.0))
    lat = float(network.origin_lat_lon_alt[0])
    # 156543 m/px at zoom 0 on the equator (256 px tiles), halving per zoom level.
    return float(np.clip(np.log2(156543.03 * np.cos(np.radians(lat)) * pane_px / extent), 1.0, 18.0))


#: colour of the route of a flight re-planned around a constraint (a plan version > 1)
REPLANNED_ROUTE_COLOR = (255, 150, 40)
#: colour of airspace constraints in Rerun and the standard-message views
CONSTRAINT_COLOR = (235, 60, 60)
CONSTRAINT_RADIUS_UI = 1.5
#: drawn height of a band open upwards [m], and of a vertiport closure's ring [m]
CONSTRAINT_OPEN_TOP_M = 600.0
CLOSURE_RADIUS_M = 150.0


def constraint_outline(c: Any, network: Any = None, segments: int = 48) -> list[np.ndarray]:
    """Line strips (each (n, 3), ENU metres) that outline a constraint's prism: the outline at the
    bottom and at the top of its band (an unbounded band drawn from 0 m or to
    :data:`CONSTRAINT_OPEN_TOP_M`) and a vertical edge at each vertex (a circle: at 8 of its
    ``segments``); a vertiport closure is a ring of :data:`CLOSURE_RADIUS_M` around it at 0 m."""
    if c.kind == "closure":
        ids = list(getattr(network, "node_ids", ()) if network is not None else ())
        if c.vertiport_id not in ids:
            return []
        x, y, z = (float(v) for v in np.asarray(network.enu_m)[ids.index(c.vertiport_id)])
        a = np.linspace(0.0, 2 * np.pi, segments + 1)
        return [np.column_stack([x + CLOSURE_RADIUS_M * np.cos(a), y + CLOSURE_RADIUS_M * np.sin(a),
                                 np.full(a.shape, z)])]
    lo = 0.0 if not np.isfinite(c.lower_m) else float(c.lower_m)
    hi = CONSTRAINT_OPEN_TOP_M if not np.isfinite(c.upper_m) else float(c.upper_m)
    if c.kind == "circle":
        a = np.linspace(0.0, 2 * np.pi, segments + 1)
        rings = [np.column_stack([c.center_m[0] + c.radius_m * np.cos(a), c.center_m[1] + c.radius_m * np.sin(a)])]
        verticals = rings[0][:-1:max(1, segments // 8)]
    else:
        rings = [np.vstack([r, r[:1]]) for r in c.rings_m]
        verticals = np.vstack([r for r in c.rings_m])
    out = []
    for r in rings:
        for z in (lo, hi):
            out.append(np.column_stack([r, np.full(len(r), z)]))
    for x, y in np.asarray(verticals, dtype=np.float64).reshape(-1, 2):
        out.append(np.array([[x, y, lo], [x, y, hi]]))
    return out


def constraint_label(c: Any) -> str:
    """``id vN band [start, end) s``: what a view writes beside a constraint. Not its reason:
    drawn on the map, the reasons' sentences covered one another and the vertiports' names in
    the city centre (the summary and the planner's messages give it, ``Constraint.label``)."""
    def t(x: float) -> str:
        return "-inf" if x == -np.inf else "inf" if x == np.inf else f"{x:g}"
    band = "" if c.kind == "closure" else f" {t(c.lower_m)}..{t(c.upper_m)} m"
    return f"{c.constraint_id} v{c.version}{band} [{t(c.start_s)}, {t(c.end_s)}) s"


#: the fixed y range of the operator approval shares (approved / decided, 0..1)
SHARE_RANGE = (0.0, 1.05)
#: the map and the metric panels, this many side by side
METRIC_COLUMNS = 2
#: panel titles short enough for a panel's width at 1400x800 (~280 px; longer ones were cut)
MWIS_SIZE_TITLE = "MWIS size [vertices]"
DELAY_TITLE = "Departure delay [s]"


def make_blueprint(network: Any = None) -> Any:
    """The viewer layout sent with every recording (see the module docstring)."""
    import rerun.blueprint as rrb

    eye = side = None
    side_name = "Side (from the south)"
    if network is not None:
        position, target = top_down_eye(network)
        eye = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=position, look_target=target,
                                eye_up=(0.0, 1.0, 0.0))
        s_pos, s_target = side_eye(network)
        side = rrb.EyeControls3D(kind=rrb.Eye3DKind.Orbital, position=s_pos, look_target=s_target,
                                 eye_up=(0.0, 0.0, 1.0))
        side_name = f"Side (from the south, heights x{height_exaggeration(network):.0f})"
    top_down = rrb.Spatial3DView(name="Network (top-down)", origin="world", contents="$origin/**",
                                 eye_controls=eye, line_grid=rrb.LineGrid3D(visible=False),
                                 background=(18, 18, 24))
    # the flight levels apart (top-down, the highest level covers the others): the corridors
    # logged again under side/ with their heights exaggerated, seen from the south
    layered = network is not None and bool(getattr(network, "levels_m", None))
    side_view = rrb.Spatial3DView(name=side_name, origin="side", contents="$origin/**",
                                  eye_controls=side, line_grid=rrb.LineGrid3D(visible=False),
                                  background=(18, 18, 24))
    geo = rrb.MapView(name="Geographic", origin="geo", contents="$origin/**",
                      zoom=map_zoom(network) if network is not None else None,
                      background=rrb.MapProvider.OpenStreetMap)
    # The plots show the run from its start up to the time cursor (not a window around it).
    axis = rrb.TimeAxis(view_range=rrb.TimeRange(start=rrb.TimeRangeBoundary.infinite(),
                                                 end=rrb.TimeRangeBoundary.cursor_relative(seconds=0.0)))
    # Legends: a multi-series panel puts its legend where its curves are not. Counts that
    # start at 0 and grow (approvals, airborne, delays) leave the top left empty; the shares
    # start at 0 or 1 on the left, so their legend goes to the bottom right on a fixed 0..1 axis.
    top_left = rrb.PlotLegend(rrb.Corner2D.LeftTop)
    flights = rrb.TimeSeriesView(name="Flights", origin="metrics", axis_x=axis, contents=[
        "$origin/approved_cumulative", "$origin/active_aircraft", "$origin/pending_requests"],
        plot_legend=top_left)
    # one panel each: at city scale the selection (~20) sat flat at 0 beside ~1,300 vertices;
    # a single series needs no legend (the title names it), so none covers the curve's start
    no_legend = rrb.PlotLegend(visible=False)
    mwis = rrb.TimeSeriesView(name=MWIS_SIZE_TITLE, origin="metrics",
                              axis_x=axis, contents=["$origin/mwis_vertices"], plot_legend=no_legend)
    selected = rrb.TimeSeriesView(name="MWIS selected vertices", origin="metrics", axis_x=axis,
                                  contents=["$origin/mwis_selected"], plot_legend=no_legend)
    solve = rrb.TimeSeriesView(name="Solve time [s]", origin="metrics", axis_x=axis,
                               contents=["$origin/solve_time_s"], plot_legend=no_legend)
    decisions = rrb.TimeSeriesView(name="Approvals and expiries", origin="metrics/decisions",
                                   axis_x=axis, contents="$origin/**", plot_legend=top_left)
    delay = rrb.TimeSeriesView(name=DELAY_TITLE, origin="metrics/delay",
                               axis_x=axis, contents="$origin/**", plot_legend=top_left)
    shares = rrb.TimeSeriesView(name="Operator approval share", origin="metrics/share",
                                axis_x=axis, contents="$origin/**", axis_y=rrb.ScalarAxis(range=SHARE_RANGE),
                                plot_legend=rrb.PlotLegend(rrb.Corner2D.RightBottom))
    # The map and the metric panels two abreast: stacked in one column, eight panels had ~90 px
    # each at 1400x800, too little for the y axis's values beside a legend.
    plots = rrb.Grid(geo, flights, mwis, selected, solve, decisions, delay, shares,
                     grid_columns=METRIC_COLUMNS)
    return rrb.Blueprint(
        rrb.Horizontal(rrb.Vertical(top_down, side_view, row_shares=[3, 1]) if layered else top_down,
                       plots,
                       column_shares=[3, 2]),
        rrb.BlueprintPanel(state="collapsed"),
        rrb.SelectionPanel(state="collapsed"),
        # "following": the time cursor goes to the newest data, live and in a file (the end of
        # the run, whose metrics then show the whole run; press play from the start to replay).
        rrb.TimePanel(state="collapsed", timeline=TIMELINE, play_state="following"),
        auto_views=False,
    )


class RerunLogger:
    """Log a fleet run to Rerun, with the blueprint of :func:`make_blueprint`.

    Args:
        mode: "off" | "save" | "spawn" | "connect".
        rrd_path: the .rrd file for mode "save" (parent directories are created).
        network: a ``uam_planner.network.Network`` to log once as static data, or None.
        app_id: Rerun application id.
        connect_url: the viewer's gRPC url for mode "connect" (None: Rerun's default).
        recording_id: optional Rerun recording id (to merge several streams into one recording).
        batch_steps: fleet steps whose positions are sent together (:meth:`log_fleet`); 1 = each
            step at once.
        batch_wall_s: the longest a logged step waits to be sent [s wall].
    Raises ValueError naming the bad argument.
    """

    def __init__(self, mode: str, rrd_path: str | os.PathLike | None = None, network: Any = None,
                 app_id: str = "uam_fleet", connect_url: str | None = None,
                 recording_id: str | None = None, batch_steps: int = 50,
                 batch_wall_s: float = 0.25, utc_zero_ns: int | None = None) -> None:
        if mode not in MODES:
            raise ValueError(f"mode: {mode!r} is not one of {MODES}")
        if mode == "save" and not rrd_path:
            raise ValueError("rrd_path: required when mode is 'save'")
        self.mode = mode
        self.rrd_path = Path(rrd_path) if rrd_path else None
        self._rec = None
        self._rr = None
        self._network = network
        self._origin = None if network is None else tuple(network.origin_lat_lon_alt)
        if utc_zero_ns is not None and int(utc_zero_ns) < 0:
            raise ValueError(f"utc_zero_ns: {utc_zero_ns!r} must be >= 0 (ns since the Unix epoch)")
        self._utc_zero_s = None if not utc_zero_ns else int(utc_zero_ns) * 1e-9
        self._routes: dict[str, np.ndarray] = {}
        self._fleet_ids: tuple[str, ...] | None = None
        self._fleet_styled = False
        self.batch_steps = int(batch_steps)
        self.batch_wall_s = float(batch_wall_s)
        if self.batch_steps < 1:
            raise ValueError(f"batch_steps: {batch_steps!r} must be >= 1")
        if not self.batch_wall_s >= 0:
            raise ValueError(f"batch_wall_s: {batch_wall_s!r} must be >= 0")
        self._pending_t: list[float] = []
        self._pending_pos: list[np.ndarray] = []
        self._pending_since = 0.0
        self._approved_total = 0
        self._report_approved = 0
        # the decisions operators value, from the requests and plans logged so far
        self._earliest: dict[str, float] = {}
        self._delays: list[float] = []
        self._expired_total = 0
        self._decided: dict[str, int] = {}
        self._approved_by: dict[str, int] = {}
        self._styled_ops: set[str] = set()
        # the side view's height factor, once a layered network is logged (None: no side view)
        self._side_k: float | None = None
        if mode == "off":
            return
        import rerun as rr

        self._rr = rr
        self._rec = rr.RecordingStream(app_id, recording_id=recording_id)
        blueprint = make_blueprint(network)
        if mode == "save":
            self.rrd_path.parent.mkdir(parents=True, exist_ok=True)
            self._rec.save(str(self.rrd_path), default_blueprint=blueprint)
        elif mode == "spawn":
            self._rec.spawn(default_blueprint=blueprint)
        else:
            self._rec.connect_grpc(connect_url, default_blueprint=blueprint)
        self._rec.log("world", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)
        self._rec.log("side", rr.ViewCoordinates.RIGHT_HAND_Z_UP, static=True)

        self._log_series_styles()
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
        if self._utc_zero_s is not None:
            self._rec.set_time(UTC_TIMELINE, timestamp=self._utc_zero_s + float(t_s))

    def _lat_lon(self, enu_m: np.ndarray) -> np.ndarray:
        from uam_planner.geo import enu_to_geodetic
        return enu_to_geodetic(np.asarray(enu_m, dtype=np.float64).reshape(-1, 3), self._origin)[:, :2]

    # -- static data ----------------------------------------------------------------------

    def _log_series_styles(self) -> None:
        rr = self._rr
        for name, label, color in (("approved_cumulative", "approved (cumulative)", (60, 200, 90)),
                                   ("active_aircraft", "airborne or scheduled", VEHICLE_COLOR),
                                   ("pending_requests", "pending requests", (230, 200, 60)),
                                   ("mwis_vertices", "MWIS size (vertices)", (90, 140, 200)),
                                   ("mwis_selected", "selected vertices", (60, 200, 90)),
                                   ("solve_time_s", "solve time [s]", (230, 120, 60)),
                                   ("decisions/approved", "approved (cumulative)", (60, 200, 90)),
                                   ("decisions/expired", "expired (cumulative)", (230, 80, 60)),
                                   ("delay/p95_s", "p95", (230, 120, 60)),
                                   ("delay/mean_s", "mean", (90, 140, 200))):
            self._rec.log(f"metrics/{name}", rr.SeriesLines(names=label, colors=color, widths=2.0),
                          static=True)

    def log_network(self, network: Any) -> None:
        """Corridors (coloured by level), vertiports and waypoints of a Network, as static data."""
        if not self.enabled:
            return
        rr = self._rr
        enu = np.asarray(network.enu_m, dtype=np.float64)
        edges = np.asarray(network.edges, dtype=np.int64).reshape(-1, 2)
        strips = enu[edges] if len(edges) else np.zeros((0, 2, 3))
        colors = level_colors(corridor_levels(network))
        levels_m = tuple(float(z) for z in (getattr(network, "levels_m", None) or ()))
        if levels_m and len(strips):  # layered network: every corridor at every flight level
            world_strips = np.concatenate([np.concatenate([s[..., :2], np.full(s.shape[:-1] + (1,), z)], axis=-1)
                                           for s, z in ((strips, z) for z in levels_m)])
            world_colors = np.repeat(level_colors(np.arange(len(levels_m))), len(strips), axis=0)
        else:
            world_strips, world_colors = strips, colors
        self._rec.log("world/network/corridors",
                      rr.LineStrips3D(list(world_strips), colors=world_colors, radii=_ui(CORRIDOR_RADIUS_UI)),
                      static=True)
        if levels_m and len(strips):  # the side view's copy, heights exaggerated
            k = self._side_k = height_exaggeration(network)
            self._rec.log("side/network/corridors",
                          rr.LineStrips3D(list(world_strips * np.array([1.0, 1.0, k])), colors=world_colors,
                                          radii=_ui(CORRIDOR_RADIUS_UI)), static=True)
            # each level named by its height, left of the network's west end, in its colour
            west = float(enu[:, 0].min()) - LEVEL_LABEL_OFFSET * float(max(np.ptp(enu[:, 0]), 100.0))
            self._rec.log("side/network/levels", rr.Points3D(
                [(west, float(enu[:, 1].mean()), z * k) for z in levels_m],
                labels=[f"{z:g} m" for z in levels_m], colors=level_colors(np.arange(len(levels_m))),
                radii=_ui(WAYPOINT_RADIUS_UI), show_labels=True), static=True)
        is_aero = np.asarray(network.is_aerodrome, dtype=bool)
        aero = np.flatnonzero(is_aero)
        names = [_node_labels(network)[i] for i in aero]
        # hubs (most corridors) keep their label first; the others show theirs on hover
        degree = np.bincount(edges.ravel(), minlength=len(enu))[aero] if len(edges) else np.zeros(len(aero))
        shown = declutter_labels(enu[aero, :2], [short_label(n) for n in names], priority=degree)
        for path, mask, visible in (("world/network/aerodromes/labelled", shown, True),
                                    ("world/network/aerodromes/unlabelled", ~shown, False)):
            self._rec.log(path, rr.Points3D(
                enu[aero[mask]], labels=[short_label(n) if visible else n for n, m in zip(names, mask) if m],
                colors=AERODROME_COLOR, radii=_ui(AERODROME_RADIUS_UI), show_labels=visible,
                point_shading="flat"), static=True)
        self._rec.log("world/network/waypoints",
                      rr.Points3D(enu[~is_aero], colors=WAYPOINT_COLOR, radii=_ui(WAYPOINT_RADIUS_UI)),
                      static=True)
        if getattr(network, "origin_lat_lon_alt", None) is None:
            return
        self._origin = tuple(network.origin_lat_lon_alt)
        lat_lon = self._lat_lon(enu)
        self._rec.log("geo/network/corridors",
                      rr.GeoLineStrings(lat_lon=list(lat_lon[edges]) if len(edges) else [],
                                        colors=colors, radii=_ui(CORRIDOR_RADIUS_UI)), static=True)
        self._rec.log("geo/network/aerodromes",
                      rr.GeoPoints(lat_lon=lat_lon[is_aero], colors=AERODROME_COLOR,
                                   radii=_ui(AERODROME_RADIUS_UI)), static=True)

    # -- time-varying data ------------------------------------------------------------------

    def log_fleet(self, t_s: float, vehicle_ids: Sequence[str], positions_m: Any) -> None:
        """The airborne aircraft at simulation time ``t_s`` [s] (ENU metres, one row per id).

        Their routes are re-logged on the same entity, in the same order, whenever the set of
        airborne flights changes (so instance k is aircraft k and its route).

        What the viewer shows at each step is the same as one ``log`` of a full Points3D per step,
        but it is sent more cheaply (measured: the per-step ``log`` calls were ~7 CPU s of a
        3500-step paper run in the recorder, BENCHMARKS.md): the styling (colour, size, shading)
        is logged once as static data, the labels only when the set of aircraft changes (Rerun
        joins them to the positions by latest-at), and the positions of up to
        :attr:`batch_steps` steps go out as one :meth:`send_columns` call, sent at the latest
        :attr:`batch_wall_s` of wall time after the oldest step (so a live viewer lags by at
        most about that) and on :meth:`close`.
        """
        if not self.enabled:
            return
        self._release_constraints(t_s)
        rr = self._rr
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        ids = vehicle_ids if isinstance(vehicle_ids, tuple) else tuple(str(v) for v in vehicle_ids)
        if len(ids) != len(pos):
            raise ValueError(f"vehicle_ids: {len(ids)} ids for {len(pos)} positions")
        if not self._fleet_styled:
            self._rec.log("world/fleet", rr.Points3D.from_fields(
                colors=VEHICLE_COLOR, radii=_ui(VEHICLE_RADIUS_UI), show_labels=False,
                point_shading="flat"), static=True)
            if self._origin is not None:
                self._rec.log("geo/fleet", rr.GeoPoints.from_fields(
                    colors=VEHICLE_COLOR, radii=_ui(VEHICLE_RADIUS_UI)), static=True)
            self._fleet_styled = True
        if ids != self._fleet_ids or getattr(self, "_routes_changed", False):
            self._routes_changed = False
            self._at(t_s)
            self._rec.log("world/fleet", rr.Points3D.from_fields(labels=list(ids)))
            strips = []
            for vid, p in zip(ids, pos):
                route = self._routes.get(vid)
                strips.append(route if route is not None and len(route) >= 2 else np.stack([p, p]))
            replanned = getattr(self, "_replanned", set())
            colors = ROUTE_COLOR if not replanned & set(ids) else \
                [REPLANNED_ROUTE_COLOR if vid in replanned else ROUTE_COLOR for vid in ids]
            self._rec.log("world/fleet", rr.LineStrips3D(_strips_arrow(strips), colors=colors,
                                                         radii=_ui(ROUTE_RADIUS_UI)))
            for landed in set(self._fleet_ids or ()) - set(ids):
                self._routes.pop(landed, None)
            self._fleet_ids = ids
        if not self._pending_t:
            self._pending_since = time.monotonic()
        self._pending_t.append(float(t_s))
        self._pending_pos.append(pos)
        if len(self._pending_t) >= self.batch_steps or time.monotonic() - self._pending_since >= self.batch_wall_s:
            self.flush_fleet()

    def flush_fleet(self) -> None:
        """Send the fleet positions of the steps logged since the last send (one call per entity)."""
        if not self._pending_t or not self.enabled:
            return
        rr = self._rr
        times, parts = self._pending_t, self._pending_pos
        self._pending_t, self._pending_pos = [], []
        lengths = [len(p) for p in parts]
        flat = np.concatenate(parts) if parts else np.zeros((0, 3))
        index = [rr.TimeColumn(TIMELINE, duration=times)]
        if self._utc_zero_s is not None:
            index.append(rr.TimeColumn(UTC_TIMELINE, timestamp=[self._utc_zero_s + t for t in times]))
        self._rec.send_columns("world/fleet", indexes=index,
                               columns=rr.Points3D.columns(positions=flat).partition(lengths))
        if self._origin is not None:
            self._rec.send_columns("geo/fleet", indexes=index,
                                   columns=rr.GeoPoints.columns(positions=self._lat_lon(flat)).partition(lengths))

    def log_route(self, t_s: float, request_id: str, points_m: Any) -> None:
        """An approved flight's route (waypoints, ENU metres), drawn while the flight is airborne."""
        if not self.enabled:
            return
        self._routes[str(request_id)] = np.asarray(points_m, dtype=np.float64).reshape(-1, 3)

    def log_epoch(self, t_s: float, *, approved_cumulative: int, active_aircraft: int,
                  mwis_vertices: int, mwis_selected: int, solve_time_s: float,
                  pending_requests: int = 0) -> None:
        """Per-epoch metrics as Scalars at simulation time ``t_s`` [s]."""
        if not self.enabled:
            return
        self._release_constraints(t_s)
        rr = self._rr
        self._at(t_s)
        for name, value in (("approved_cumulative", approved_cumulative),
                            ("active_aircraft", active_aircraft),
                            ("mwis_vertices", mwis_vertices),
                            ("mwis_selected", mwis_selected),
                            ("solve_time_s", solve_time_s),
                            ("pending_requests", pending_requests)):
            self._rec.log(f"metrics/{name}", rr.Scalars(float(value)))

    def log_constraints(self, t_s: float, constraints: Sequence[Any]) -> None:
        """The constraint set the planner plans with from ``t_s`` on: each constraint an
        entity ``world/constraints/<id>`` (its prism's outline, :func:`constraint_outline`, labelled
        with id, version, band and window) and ``geo/constraints/<id>`` on the map, shown from
        ``max(t_s, start_s)`` and cleared at ``end_s``; those no longer in the set are cleared at
        ``t_s``. A start or an end later than ``t_s`` is logged once the run reaches it (the
        fleet or an epoch logged at that time or later), never beyond the run: logged at a
        window's end (+3,600 s), it made the viewer open there, after the run and with every
        constraint cleared."""
        if not self.enabled:
            return
        self._release_constraints(t_s)
        shown = getattr(self, "_constraints_shown", set())
        now = {str(c.constraint_id): c for c in constraints}
        # a new set replaces what the last one scheduled
        self._constraint_events = [e for e in getattr(self, "_constraint_events", []) if e[1] not in shown | set(now)]
        self._at(t_s)
        for cid in shown - set(now):
            self._log_constraint(cid, None)
        for cid, c in now.items():
            strips = constraint_outline(c, self._network)
            if not strips:
                continue
            self._constraint_events.append((max(float(t_s), float(c.start_s)), cid, (strips, constraint_label(c))))
            if np.isfinite(c.end_s):
                self._constraint_events.append((float(c.end_s), cid, None))
        self._constraints_shown = set(now)
        self._release_constraints(t_s)
        self._at(t_s)

    def _release_constraints(self, t_s: float) -> None:
        """Log the scheduled constraint starts and ends at or before ``t_s``, each at its time."""
        events = getattr(self, "_constraint_events", [])
        due = sorted((e for e in events if e[0] <= t_s), key=lambda e: e[0])
        if not due:
            return
        self._constraint_events = [e for e in events if e[0] > t_s]
        for when, cid, shape in due:
            self._at(when)
            self._log_constraint(cid, shape)

    def _log_constraint(self, cid: str, shape) -> None:
        """Draw constraint ``cid`` (``shape`` = (strips, label)) or clear it (None), at the current time."""
        rr = self._rr
        k = self._side_k   # a side view (a layered network) shows them too
        if shape is None:
            self._rec.log(f"world/constraints/{cid}", rr.Clear(recursive=True))
            if k is not None:
                self._rec.log(f"side/constraints/{cid}", rr.Clear(recursive=True))
            if self._origin is not None:
                self._rec.log(f"geo/constraints/{cid}", rr.Clear(recursive=True))
            return
        strips, label = shape
        self._rec.log(f"world/constraints/{cid}", rr.LineStrips3D(
            strips, colors=CONSTRAINT_COLOR, radii=_ui(CONSTRAINT_RADIUS_UI), labels=[label] + [""] * (len(strips) - 1)))
        if k is not None:
            self._rec.log(f"side/constraints/{cid}", rr.LineStrips3D(
                [s * np.array([1.0, 1.0, k]) for s in strips], colors=CONSTRAINT_COLOR,
                radii=_ui(CONSTRAINT_RADIUS_UI)))
        if self._origin is not None:
            outlines = [s for s in strips if len(s) > 2][::2]   # each ring once (its bottom)
            self._rec.log(f"geo/constraints/{cid}", rr.GeoLineStrings(
                lat_lon=[self._lat_lon(s) for s in outlines], colors=CONSTRAINT_COLOR,
                radii=_ui(CONSTRAINT_RADIUS_UI)))

    def log_constraints_msg(self, msg: Any) -> None:
        """A std_msgs/String of ``uam/constraints`` (uam_planner.live_constraints.set_geojson)."""
        if not self.enabled:
            return
        from uam_planner.live_constraints import constraints_from_text
        t_s, found = constraints_from_text(msg.data, self._network)
        self.log_constraints(t_s, [c for c, _eff in found])

    # -- ROS messages (duck-typed) ----------------------------------------------------------

    def log_fleet_state_msg(self, msg: Any) -> None:
        """A uam_msgs/FleetState."""
        if not self.enabled:
            return
        ids = [v.vehicle_id for v in msg.vehicles]
        pos = [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]
        self.log_fleet(stamp_s(msg.header.stamp), ids, pos)

    def log_request_msg(self, msg: Any) -> None:
        """A uam_msgs/FlightRequest: its earliest departure, for the delay of its approval."""
        if not self.enabled:
            return
        self._earliest.setdefault(_request_key(msg), stamp_s(msg.earliest_departure))

    def log_flight_plan_msg(self, msg: Any) -> None:
        """A uam_msgs/FlightPlan: approved plans add a route and count towards the total;
        approvals and expiries count towards the decision panels (delay, operator shares); a
        re-planned version redraws the route and counts as no new decision."""
        if not self.enabled:
            return
        # the simulator names each vehicle operator/request (uam_contract.wire.scoped_id): the
        # route must carry the same key to be drawn with its aircraft (plans without an operator,
        # as from the in-process runner, keep the bare id the fleet uses there)
        op = str(getattr(msg, "operator_id", "") or "")
        key = f"{op}/{msg.request_id}" if op else str(msg.request_id)
        pts = [(w.position.x, w.position.y, w.position.z) for w in msg.waypoints]
        if int(getattr(msg, "version", 0) or 0) > 1:  # a re-planned version: not an approval
            if not hasattr(self, "_replanned"):
                self._replanned = set()
            self._replanned.add(key)
            if int(msg.outcome) == 0 and pts:
                self.log_route(stamp_s(msg.header.stamp), key, pts)
            self._routes_changed = True   # re-log the routes at the next step, in their new colour
            return
        outcome = int(msg.outcome)
        if outcome == 2:  # OUTCOME_EXPIRED
            self._expired_total += 1
            if op:
                self._decided[op] = self._decided.get(op, 0) + 1
        if outcome != 0:  # not OUTCOME_APPROVED
            return
        self._approved_total += 1
        if op:
            self._decided[op] = self._decided.get(op, 0) + 1
            self._approved_by[op] = self._approved_by.get(op, 0) + 1
        earliest = self._earliest.get(_request_key(msg))
        if earliest is not None:
            self._delays.append(stamp_s(msg.departure_time) - earliest)
        if pts:
            self.log_route(stamp_s(msg.header.stamp), key, pts)

    def decision_values(self) -> dict:
        """What the decision panels show now: entity path under ``metrics/`` -> value."""
        out = {"decisions/approved": float(self._approved_total),
               "decisions/expired": float(self._expired_total)}
        if self._delays:
            d = np.asarray(self._delays, dtype=np.float64)
            out["delay/p95_s"] = float(np.percentile(d, 95))
            out["delay/mean_s"] = float(d.mean())
        for op in sorted(self._decided):
            out[f"share/{op}"] = self._approved_by.get(op, 0) / self._decided[op]
        return out

    def log_decisions(self, t_s: float) -> None:
        """The decision panels at simulation time ``t_s`` [s] (called once per epoch)."""
        if not self.enabled:
            return
        rr = self._rr
        self._at(t_s)
        for name, value in self.decision_values().items():
            op = name[len("share/"):] if name.startswith("share/") else None
            if op is not None and op not in self._styled_ops:
                self._styled_ops.add(op)
                self._rec.log(f"metrics/{name}", rr.SeriesLines(names=op, widths=2.0), static=True)
            self._rec.log(f"metrics/{name}", rr.Scalars(value))

    def log_planning_report_msg(self, msg: Any) -> None:
        """A uam_msgs/PlanningReport: the epoch's metrics (approvals counted from the reports)."""
        if not self.enabled:
            return
        self._report_approved += int(msg.approved)
        self.log_epoch(stamp_s(msg.header.stamp),
                       approved_cumulative=self._report_approved,
                       active_aircraft=int(msg.active_flights),
                       mwis_vertices=int(msg.vertices),
                       mwis_selected=len(msg.instance.selected),
                       solve_time_s=float(msg.solve_time_s),
                       pending_requests=int(msg.pending_requests))
        self.log_decisions(stamp_s(msg.header.stamp))

    def close(self) -> None:
        """Flush everything and close the sink (the .rrd file is complete afterwards)."""
        if self._rec is None:
            return
        self.flush_fleet()
        rec, self._rec = self._rec, None
        rec.flush()
        rec.disconnect()

    def __enter__(self) -> "RerunLogger":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


TOPIC_FLEET = resolved(names.TOPIC_FLEET)
TOPIC_PLANS = resolved(names.TOPIC_PLANS)
TOPIC_REPORTS = resolved(names.TOPIC_REPORTS)
TOPIC_REQUESTS = resolved(names.TOPIC_REQUESTS)


def _request_key(msg: Any) -> str:
    """``operator_id/request_id`` (bare request_id without an operator), as the analysis keys
    requests and plans (``uam_sim.audit.analysis.request_key``)."""
    operator = str(getattr(msg, "operator_id", "") or "")
    return f"{operator}/{msg.request_id}" if operator else str(msg.request_id)
TOPIC_CONSTRAINTS = resolved(names.TOPIC_CONSTRAINTS)


def log_recording(mcap_path: str | os.PathLike, rrd_path: str | os.PathLike, network: Any = None) -> int:
    """Replay a recording's fleet states, flight plans and reports into an .rrd; returns messages.

    Messages go to the logger in log-time order, as the recorder node would have sent them live.
    What was in force is the run's record (``uam_sim.audit.record``, as the analysis builds it):
    a plan or plan version of no flight in it (forged) and a constraint set no planning report
    names are not drawn. Decodes with rclpy (the workspace must be sourced).
    """
    import hashlib

    from ..audit.analysis import iter_decoded, request_key, summarize
    from ..audit.flown_audit import plan_version
    from ..recording.mcap_reader import log_time_zero_ns

    summary = summarize(mcap_path, network=network, flown=False)   # the record is enough
    versions = {(f.request, plan_version(v)) for f in summary.record.flights for v in f.versions}
    sets = summary.constraint_sets_taken
    n = 0
    with RerunLogger("save", rrd_path, network=network, utc_zero_ns=log_time_zero_ns(mcap_path) or None) as logger:
        for topic, _t_ns, msg in iter_decoded(mcap_path, topics=(TOPIC_FLEET, TOPIC_PLANS, TOPIC_REPORTS,
                                                                 TOPIC_REQUESTS, TOPIC_CONSTRAINTS)):
            if topic == TOPIC_FLEET:
                logger.log_fleet_state_msg(msg)
            elif topic == TOPIC_REQUESTS:
                logger.log_request_msg(msg)
            elif topic == TOPIC_PLANS:
                in_force = (request_key(msg), plan_version(msg)) in versions
                if (int(msg.outcome) == 0 or plan_version(msg) > 1) and not in_force:
                    continue   # not in the record: a forged plan
                logger.log_flight_plan_msg(msg)
            elif topic == TOPIC_CONSTRAINTS:
                if hashlib.sha256(msg.data.encode("utf-8")).hexdigest() not in sets:
                    continue   # not the planner's
                logger.log_constraints_msg(msg)
            else:
                logger.log_planning_report_msg(msg)
            n += 1
    return n


def main(argv: list[str] | None = None) -> int:
    """``python -m uam_sim.rerun_log RUN.mcap [--network NET.yaml] [--out RUN.rrd]``."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m uam_sim.rerun_log",
                                 description="turn a run's MCAP recording into a Rerun .rrd with the view")
    ap.add_argument("mcap")
    ap.add_argument("--network", default="", help="network file the run used (draws the network and "
                    "places the fleet on the map); empty = fleet and metrics only")
    ap.add_argument("--out", default="", help="the .rrd to write (default: the MCAP path with .rrd)")
    args = ap.parse_args(argv)
    out = args.out or str(Path(args.mcap).with_suffix(".rrd"))
    try:
        network = None
        if args.network:
            from uam_planner.network import load_network
            network = load_network(args.network)
        n = log_recording(args.mcap, out, network)
    except (OSError, ValueError) as exc:
        print(f"rerun_log: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {out} from {n} messages of {args.mcap}")
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
