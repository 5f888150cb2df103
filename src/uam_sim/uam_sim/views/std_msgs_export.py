"""The run in standard ROS message types, so generic viewers draw it without our message package.

Rerun's MCAP import and Foxglove's 3D and Map panels know ``sensor_msgs`` and
``visualization_msgs`` but not ``uam_msgs``. :class:`ViewExporter` turns what the recorder sees
(fleet states, flight plans, the network) into these messages, written next to the project's
own topics in the same recording:

========================  ==================================  ===========================================
topic                     type                                content
========================  ==================================  ===========================================
``/uam/view/network``     visualization_msgs/msg/MarkerArray  corridors (one LINE_LIST per flight level,
                                                              coloured as in Rerun), vertiports
                                                              (SPHERE_LIST) and their names (TEXT); once,
                                                              at the start of the run
``/uam/view/routes``      visualization_msgs/msg/MarkerArray  each approved route (LINE_STRIP) from its
                                                              decision time, with a lifetime that ends at
                                                              the flight's arrival
``/uam/view/fleet``       sensor_msgs/msg/PointCloud2         the airborne aircraft (x, y, z float32, ENU
                                                              metres) every simulation step
``/uam/view/fix/<id>``    sensor_msgs/msg/NavSatFix           one topic per vehicle: its WGS84 position
                                                              every step while airborne
========================  ==================================  ===========================================

Frames: the cloud and the markers are in frame ``enu`` (the network's local east-north-up frame,
the frame of the project's own messages); it is the only frame, so no transform is needed (choose
``enu`` as the display frame in Foxglove's 3D panel). NavSatFix carries WGS84 latitude/longitude
[deg] and altitude [m] computed from the network's origin, with an empty frame_id (the topic names
the vehicle; a frame per vehicle that no transform reaches makes Rerun's MCAP import show an
error on its 3D view, tried).

Stamps: header stamps are ``scenario_start_utc`` + simulation time. The recorder's default,
``"sim"`` (:data:`SIM_CLOCK`), stamps them in simulation time, the clock of every other topic of
the recording; an ISO 8601 instant (e.g. :data:`DEFAULT_SCENARIO_START_UTC`, 08:00 on a Monday in
Singapore) stamps them in real UTC for tools that want dates. Rerun puts Unix-range header stamps
on its ``ros2_timestamp`` timeline.

The CDR bytes are written directly (as :mod:`uam_sim.recording.cdr` does for the simulator's messages);
a test holds them equal to rclpy's serialization of the same messages. No rclpy import here.
"""

from __future__ import annotations

import functools
import math
import re
import struct
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from uam_contract import names
from uam_contract.names import FRAME_ID, resolved
from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC, SIM_CLOCK, scenario_start_ns  # noqa: F401 (used by the views)

from ..recording.cdr import ENCAPSULATION, CdrWriter
from uam_contract.stamps import stamp_ns

#: The default scenario start: Monday 6 January 2025, 08:00 in Singapore (00:00 UTC).
TOPIC_NETWORK = resolved(names.TOPIC_VIEW_NETWORK)
TOPIC_ROUTES = resolved(names.TOPIC_VIEW_ROUTES)
TOPIC_FLEET_CLOUD = resolved(names.TOPIC_VIEW_FLEET)
TOPIC_FIX_PREFIX = resolved(names.TOPIC_VIEW_FIX_PREFIX)
TOPIC_NETWORK_POINTS = resolved(names.TOPIC_VIEW_NETWORK_POINTS)
TOPIC_CONSTRAINTS = resolved(names.TOPIC_VIEW_CONSTRAINTS)
TOPIC_CONSTRAINT_POINTS = resolved(names.TOPIC_VIEW_CONSTRAINT_POINTS)
#: spacing of the points that draw lines in a PointCloud2 (Rerun 0.41 imports no MarkerArray) [m]
LINE_POINT_SPACING_M = 25.0

TYPE_MARKER_ARRAY = "visualization_msgs/msg/MarkerArray"
TYPE_POINT_CLOUD2 = "sensor_msgs/msg/PointCloud2"
TYPE_NAV_SAT_FIX = "sensor_msgs/msg/NavSatFix"

# visualization_msgs/Marker constants
MARKER_LINE_STRIP = 4
MARKER_LINE_LIST = 5
MARKER_SPHERE_LIST = 7
MARKER_TEXT_VIEW_FACING = 9
MARKER_ADD = 0
MARKER_DELETEALL = 3
# sensor_msgs/PointField.FLOAT32, sensor_msgs/NavSatStatus
POINTFIELD_FLOAT32 = 7
NAVSAT_STATUS_FIX = 0
NAVSAT_SERVICE_GPS = 1

_NS = 1_000_000_000
_TOKEN_RE = re.compile(r"[^A-Za-z0-9_]")


def vehicle_topic(vehicle_id: str) -> str:
    """The NavSatFix topic of a vehicle: its id with characters ROS names refuse replaced by '_'."""
    token = _TOKEN_RE.sub("_", str(vehicle_id)) or "_"
    if token[0].isdigit():
        token = "v" + token
    return TOPIC_FIX_PREFIX + token


# --------------------------------------------------------------------------------------------
# CDR encoders
# --------------------------------------------------------------------------------------------

# (one writer for every CDR message of the package: uam_sim.recording.cdr.CdrWriter)


def _split_ns(t_ns: int) -> tuple[int, int]:
    return int(t_ns // _NS), int(t_ns % _NS)


def encode_point_cloud(stamp_ns: int, frame_id: str, positions_m: Any) -> bytes:
    """Serialized sensor_msgs/PointCloud2 of (n, 3) points: fields x, y, z float32, one row."""
    pts = np.ascontiguousarray(np.asarray(positions_m, dtype="<f4").reshape(-1, 3))
    n = pts.shape[0]
    w = CdrWriter()
    w.header(*_split_ns(stamp_ns), frame_id)
    w.u32(1)            # height
    w.u32(n)            # width
    w.u32(3)            # fields
    for offset, name in ((0, "x"), (4, "y"), (8, "z")):
        w.string(name)
        w.u32(offset)
        w.u8(POINTFIELD_FLOAT32)
        w.u32(1)
    w.u8(0)             # is_bigendian
    w.u32(12)           # point_step
    w.u32(12 * n)       # row_step
    w.octets(pts.tobytes())
    w.u8(1)             # is_dense
    return ENCAPSULATION + bytes(w.buf)


@functools.lru_cache(maxsize=16)
def _point_cloud_template(frame_id: str) -> tuple[bytes, int, int, int]:
    """The bytes of an empty cloud of ``frame_id`` up to its data, and the offsets (in them) of
    width, row_step and the data length: all that changes between steps besides the stamp."""
    w = CdrWriter()
    w.header(0, 0, frame_id)
    w.u32(1)
    w.align(4)
    width_at = len(w.buf)
    w.u32(0)
    w.u32(3)
    for offset, name in ((0, "x"), (4, "y"), (8, "z")):
        w.string(name)
        w.u32(offset)
        w.u8(POINTFIELD_FLOAT32)
        w.u32(1)
    w.u8(0)
    w.u32(12)
    w.align(4)
    row_step_at = len(w.buf)
    w.u32(0)
    w.align(4)
    length_at = len(w.buf)
    w.u32(0)
    return ENCAPSULATION + bytes(w.buf), 4 + width_at, 4 + row_step_at, 4 + length_at


def encode_point_cloud_fast(stamp_ns: int, frame_id: str, positions_m: Any) -> bytes:
    """:func:`encode_point_cloud` from a cached template (the same bytes; a test holds them equal)."""
    pts = np.ascontiguousarray(np.asarray(positions_m, dtype="<f4").reshape(-1, 3))
    n = pts.shape[0]
    template, width_at, row_step_at, length_at = _point_cloud_template(frame_id)
    buf = bytearray(template)
    struct.pack_into("<iI", buf, 4, *_split_ns(stamp_ns))
    struct.pack_into("<I", buf, width_at, n)
    struct.pack_into("<I", buf, row_step_at, 12 * n)
    struct.pack_into("<I", buf, length_at, 12 * n)
    buf += pts.tobytes()
    buf += b"\x01"      # is_dense
    return bytes(buf)


_FIX_BODY = struct.Struct("<12dB")   # latitude, longitude, altitude, covariance[9], covariance type


def encode_nav_sat_fix(stamp_ns: int, frame_id: str, lat_deg: float, lon_deg: float,
                       alt_m: float) -> bytes:
    """Serialized sensor_msgs/NavSatFix: a GPS fix (status FIX), covariance unknown.

    Written with one precompiled struct per part rather than field by field: the recorder
    writes one per airborne vehicle and step, and this is ~4x faster than the generic writer.
    """
    sec, nsec = _split_ns(stamp_ns)
    fid = frame_id.encode("utf-8") + b"\x00"
    head = struct.pack("<iII", sec, nsec, len(fid)) + fid
    p = len(head)                        # payload offset of NavSatStatus.status (int8)
    pad2 = (p + 1) % 2                   # service (uint16) aligned to 2
    p += 1 + pad2 + 2
    pad8 = (-p) % 8                      # latitude (float64) aligned to 8
    return b"".join((ENCAPSULATION, head, struct.pack("<b", NAVSAT_STATUS_FIX), b"\x00" * pad2,
                     struct.pack("<H", NAVSAT_SERVICE_GPS), b"\x00" * pad8,
                     _FIX_BODY.pack(float(lat_deg), float(lon_deg), float(alt_m), *([0.0] * 9), 0)))


_FIX_TAIL = np.dtype([("values", "<f8", (12,)), ("covariance_type", "u1")])   # 97 bytes, packed
assert _FIX_TAIL.itemsize == 97


def encode_nav_sat_fixes(stamp_ns: int, frame_id: str, lat_lon_alt: Any) -> list[bytes]:
    """Serialized sensor_msgs/NavSatFix of each row of an (n, 3) array [deg, deg, m], one stamp.

    The same bytes as :func:`encode_nav_sat_fix` per row (a test holds them equal), built in
    bulk: everything before the latitude is one shared prefix (stamp, frame, status), and the
    12 float64 and the covariance type of all rows are one numpy structured array cut into
    slices. The recorder writes ~130 fixes per fix period; one at a time they cost ~10 us each.
    """
    lla = np.asarray(lat_lon_alt, dtype=np.float64).reshape(-1, 3)
    prefix = encode_nav_sat_fix(stamp_ns, frame_id, 0.0, 0.0, 0.0)[:-_FIX_TAIL.itemsize]
    tail = np.zeros(len(lla), dtype=_FIX_TAIL)
    tail["values"][:, :3] = lla
    raw = tail.tobytes()
    size = _FIX_TAIL.itemsize
    return [prefix + raw[k:k + size] for k in range(0, len(raw), size)]


@dataclass
class Marker:
    """The fields of visualization_msgs/Marker this project uses (the rest are left empty).

    ``scale`` [m] (x = line width for lines, text height for text); ``color`` RGBA in 0..1;
    ``points`` (n, 3) [m]; ``lifetime_s`` 0 = forever.
    """

    ns: str
    id: int
    type: int
    stamp_ns: int
    frame_id: str = FRAME_ID
    action: int = MARKER_ADD
    position: tuple = (0.0, 0.0, 0.0)
    scale: tuple = (1.0, 1.0, 1.0)
    color: tuple = (1.0, 1.0, 1.0, 1.0)
    lifetime_s: float = 0.0
    points: Any = field(default_factory=lambda: np.zeros((0, 3)))
    text: str = ""


def encode_marker_array(markers: Sequence[Marker]) -> bytes:
    """Serialized visualization_msgs/MarkerArray."""
    w = CdrWriter()
    w.u32(len(markers))
    for m in markers:
        w.header(*_split_ns(m.stamp_ns), m.frame_id)
        w.string(m.ns)
        w.i32(int(m.id))
        w.i32(int(m.type))
        w.i32(int(m.action))
        w.f64s(m.position)
        w.f64s((0.0, 0.0, 0.0, 1.0))        # orientation
        w.f64s(m.scale)
        w.f32s(m.color)
        life_ns = max(0, int(round(float(m.lifetime_s) * _NS)))
        w.i32(life_ns // _NS)
        w.u32(life_ns % _NS)
        w.u8(0)                             # frame_locked
        pts = np.asarray(m.points, dtype="<f8").reshape(-1, 3)
        w.u32(pts.shape[0])
        if pts.shape[0]:
            w.align(8)
            w.buf += np.ascontiguousarray(pts).tobytes()
        w.u32(0)                            # colors
        w.string("")                        # texture_resource
        w.header(0, 0, "")                  # texture (sensor_msgs/CompressedImage)
        w.string("")                        # texture.format
        w.u32(0)                            # texture.data
        w.u32(0)                            # uv_coordinates
        w.string(m.text)
        w.string("")                        # mesh_resource
        w.string("")                        # mesh_file.filename
        w.u32(0)                            # mesh_file.data
        w.u8(0)                             # mesh_use_embedded_materials
    return ENCAPSULATION + bytes(w.buf)


def sample_lines(segments_m: Any, spacing_m: float = LINE_POINT_SPACING_M) -> np.ndarray:
    """Points along each segment of an (n, 2, 3) array, both ends included, at most ``spacing_m``
    apart: lines drawn as a point cloud."""
    seg = np.asarray(segments_m, dtype=np.float64).reshape(-1, 2, 3)
    if not len(seg):
        return np.zeros((0, 3))
    length = np.linalg.norm(seg[:, 1] - seg[:, 0], axis=1)
    counts = np.maximum(1, np.ceil(length / float(spacing_m)).astype(np.int64))
    owner = np.repeat(np.arange(len(seg)), counts + 1)
    start = np.concatenate([[0], np.cumsum(counts + 1)[:-1]])
    frac = (np.arange(len(owner)) - np.repeat(start, counts + 1)) / np.repeat(counts, counts + 1)
    return seg[owner, 0] + frac[:, None] * (seg[owner, 1] - seg[owner, 0])


# --------------------------------------------------------------------------------------------
# The exporter
# --------------------------------------------------------------------------------------------

def _rgba(rgb: Sequence[int], alpha: float = 1.0) -> tuple:
    return (rgb[0] / 255.0, rgb[1] / 255.0, rgb[2] / 255.0, float(alpha))


@dataclass(frozen=True)
class ViewMessage:
    """One message to write: topic, type name, CDR bytes, and the simulation time [ns] it belongs to."""

    topic: str
    type_name: str
    data: bytes
    sim_time_ns: int


class ViewExporter:
    """Standard-message views of a run (see the module docstring).

    Args:
        network: the run's ``uam_planner.network.Network`` or None (then no network markers and
            no geographic fixes: the ENU frame has no place on the Earth).
        scenario_start_utc: ISO 8601 instant of simulation time 0.
        geo_fixes: write the per-vehicle NavSatFix topics.
        fix_period_s: write the fixes at simulation times that are multiples of this [s] (the
            fleet cloud goes out every step); 0 = every fleet state. Fixes are one message per
            vehicle, the bulk of the view topics: every 5 s keeps the recorder's cost per step
            near that of the cloud (BENCHMARKS.md).
    Methods return :class:`ViewMessage` lists; the caller registers unknown topics (type in the
    message) and writes them.
    """

    def __init__(self, network: Any = None, scenario_start_utc: str = DEFAULT_SCENARIO_START_UTC,
                 geo_fixes: bool = True, fix_period_s: float = 5.0) -> None:
        if not (fix_period_s >= 0 and math.isfinite(fix_period_s)):
            raise ValueError(f"fix_period_s: {fix_period_s!r} must be a finite number >= 0")
        self.network = network
        self.fix_period_ns = int(round(fix_period_s * _NS))
        self.start_ns = scenario_start_ns(scenario_start_utc)
        self.geo_fixes = bool(geo_fixes) and network is not None
        self._route_ids: dict[str, int] = {}
        self._fix_topics: dict[str, str] = {}   # vehicle id -> its NavSatFix topic (ids repeat every step)

    def stamp_ns(self, sim_time_ns: int) -> int:
        """UTC stamp [ns since the Unix epoch] of a simulation time [ns]."""
        return self.start_ns + int(sim_time_ns)

    def network_messages(self, sim_time_ns: int = 0) -> list[ViewMessage]:
        """The network's MarkerArray (empty list without a network)."""
        if self.network is None:
            return []
        from .rerun_log import AERODROME_COLOR, LEVEL_COLORS, _node_labels, corridor_levels

        net = self.network
        stamp = self.stamp_ns(sim_time_ns)
        enu = np.asarray(net.enu_m, dtype=np.float64)
        edges = np.asarray(net.edges, dtype=np.int64).reshape(-1, 2)
        levels = corridor_levels(net)
        markers = [Marker("corridors", -1, MARKER_LINE_LIST, stamp, action=MARKER_DELETEALL)]
        for level in sorted(set(levels.tolist())):
            sel = edges[levels == level]
            markers.append(Marker("corridors", int(level), MARKER_LINE_LIST, stamp,
                                  scale=(15.0, 0.0, 0.0),
                                  color=_rgba(LEVEL_COLORS[level % len(LEVEL_COLORS)], 0.9),
                                  points=enu[sel].reshape(-1, 3)))
        aero = np.flatnonzero(np.asarray(net.is_aerodrome, dtype=bool))
        markers.append(Marker("vertiports", 0, MARKER_SPHERE_LIST, stamp, scale=(120.0, 120.0, 120.0),
                              color=_rgba(AERODROME_COLOR), points=enu[aero]))
        labels = _node_labels(net)
        for k, i in enumerate(aero):
            markers.append(Marker("vertiport_names", int(k), MARKER_TEXT_VIEW_FACING, stamp,
                                  position=tuple(enu[i] + (0.0, 0.0, 150.0)), scale=(0.0, 0.0, 150.0),
                                  color=_rgba((255, 255, 255)), text=labels[i]))
        # Rerun 0.41's MCAP import draws no MarkerArray but does draw PointCloud2 (as Points3D):
        # the corridors as points every LINE_POINT_SPACING_M, and the vertiports, in one cloud
        pts = np.vstack([sample_lines(enu[edges]), enu[aero]]) if len(edges) else enu[aero]
        return [ViewMessage(TOPIC_NETWORK, TYPE_MARKER_ARRAY, encode_marker_array(markers), sim_time_ns),
                ViewMessage(TOPIC_NETWORK_POINTS, TYPE_POINT_CLOUD2, encode_point_cloud(stamp, FRAME_ID, pts),
                            sim_time_ns)]

    def constraint_messages(self, sim_time_ns: int, constraints: Sequence[Any]) -> list[ViewMessage]:
        """The constraint set in force from ``sim_time_ns``: a MarkerArray (DELETEALL,
        then one LINE_LIST outline of each prism or closure and a text with its id, version, band
        and window) and the same outlines as a PointCloud2 (points every LINE_POINT_SPACING_M), for
        Rerun's MCAP import. An empty set clears both."""
        from .rerun_log import CONSTRAINT_COLOR, constraint_label, constraint_outline

        stamp = self.stamp_ns(sim_time_ns)
        markers = [Marker("constraints", -1, MARKER_LINE_LIST, stamp, action=MARKER_DELETEALL)]
        clouds = []
        for k, c in enumerate(sorted(constraints, key=lambda c: c.constraint_id)):
            strips = constraint_outline(c, self.network)
            if not strips:
                continue
            pairs = np.vstack([np.column_stack([s[:-1], s[1:]]).reshape(-1, 3) for s in strips])
            markers.append(Marker("constraints", 2 * k, MARKER_LINE_LIST, stamp, scale=(10.0, 0.0, 0.0),
                                  color=_rgba(CONSTRAINT_COLOR, 0.9), points=pairs))
            top = max(strips, key=lambda s: float(s[:, 2].max()))
            markers.append(Marker("constraint_labels", 2 * k + 1, MARKER_TEXT_VIEW_FACING, stamp,
                                  position=tuple(top[0] + (0.0, 0.0, 60.0)), scale=(0.0, 0.0, 120.0),
                                  color=_rgba(CONSTRAINT_COLOR), text=constraint_label(c)))
            clouds.append(np.vstack([sample_lines(np.stack([s[:-1], s[1:]], axis=1)) for s in strips]))
        pts = np.vstack(clouds) if clouds else np.zeros((0, 3))
        return [ViewMessage(TOPIC_CONSTRAINTS, TYPE_MARKER_ARRAY, encode_marker_array(markers), sim_time_ns),
                ViewMessage(TOPIC_CONSTRAINT_POINTS, TYPE_POINT_CLOUD2, encode_point_cloud(stamp, FRAME_ID, pts),
                            sim_time_ns)]

    def plan_messages(self, plan: Any) -> list[ViewMessage]:
        """The route marker of an approved uam_msgs/FlightPlan (duck-typed); [] for others."""
        if int(plan.outcome) != 0 or not plan.waypoints:
            return []
        t_ns = stamp_ns(plan.header.stamp)
        arrival_ns = stamp_ns(plan.arrival_time)
        rid = self._route_ids.setdefault(str(plan.request_id), len(self._route_ids))
        pts = [(w.position.x, w.position.y, w.position.z) for w in plan.waypoints]
        from .rerun_log import ROUTE_COLOR
        marker = Marker("routes", rid, MARKER_LINE_STRIP, self.stamp_ns(t_ns), scale=(6.0, 0.0, 0.0),
                        color=_rgba(ROUTE_COLOR[:3], 0.8),
                        lifetime_s=max(arrival_ns - t_ns, 1) / _NS, points=pts, text=str(plan.request_id))
        return [ViewMessage(TOPIC_ROUTES, TYPE_MARKER_ARRAY, encode_marker_array([marker]), t_ns)]

    def fleet_messages(self, sim_time_ns: int, vehicle_ids: Sequence[str], positions_m: Any) -> list[ViewMessage]:
        """The fleet's PointCloud2 and (with a network, when a fix is due) one NavSatFix per vehicle."""
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        if len(vehicle_ids) != len(pos):
            raise ValueError(f"vehicle_ids: {len(vehicle_ids)} ids for {len(pos)} positions")
        stamp = self.stamp_ns(sim_time_ns)
        out = [ViewMessage(TOPIC_FLEET_CLOUD, TYPE_POINT_CLOUD2, encode_point_cloud_fast(stamp, FRAME_ID, pos),
                           sim_time_ns)]
        due = self.fix_period_ns == 0 or int(sim_time_ns) % self.fix_period_ns == 0
        if self.geo_fixes and due and len(pos):
            from uam_planner.geo import enu_to_geodetic
            lla = enu_to_geodetic(pos, self.network.origin_lat_lon_alt)
            keep = np.isfinite(lla[:, 0]) & np.isfinite(lla[:, 1])
            # frame_id left empty: the vehicle is named by the topic, and a frame named after
            # it (a frame no transform reaches) makes Rerun's MCAP import flag the 3D view
            datas = encode_nav_sat_fixes(stamp, "", lla[keep])
            topics = self._fix_topics
            if len(topics) > 100_000:   # bounded: a long run flies many more vehicles than are airborne
                topics.clear()
            kept = (vid for vid, k in zip(vehicle_ids, keep.tolist()) if k)
            for vid, data in zip(kept, datas):
                topic = topics.get(vid)
                if topic is None:
                    topic = topics[vid] = vehicle_topic(vid)
                out.append(ViewMessage(topic, TYPE_NAV_SAT_FIX, data, sim_time_ns))
        return out

    def fleet_messages_per_vehicle(self, sim_time_ns: int, vehicle_ids: Sequence[str],
                                   positions_m: Any) -> list[ViewMessage]:
        """:meth:`fleet_messages` message by message, as before the bulk encoding (the reference
        the bulk path is tested against; ~2x slower)."""
        pos = np.asarray(positions_m, dtype=np.float64).reshape(-1, 3)
        if len(vehicle_ids) != len(pos):
            raise ValueError(f"vehicle_ids: {len(vehicle_ids)} ids for {len(pos)} positions")
        stamp = self.stamp_ns(sim_time_ns)
        out = [ViewMessage(TOPIC_FLEET_CLOUD, TYPE_POINT_CLOUD2, encode_point_cloud(stamp, FRAME_ID, pos),
                           sim_time_ns)]
        due = self.fix_period_ns == 0 or int(sim_time_ns) % self.fix_period_ns == 0
        if self.geo_fixes and due and len(pos):
            from uam_planner.geo import enu_to_geodetic
            lla = enu_to_geodetic(pos, self.network.origin_lat_lon_alt)
            for vid, (lat, lon, alt) in zip(vehicle_ids, lla.tolist()):
                if not (math.isfinite(lat) and math.isfinite(lon)):
                    continue
                out.append(ViewMessage(vehicle_topic(vid), TYPE_NAV_SAT_FIX,
                                       encode_nav_sat_fix(stamp, "", lat, lon, alt), sim_time_ns))
        return out

    def fleet_state_messages(self, msg: Any) -> list[ViewMessage]:
        """:meth:`fleet_messages` of a uam_msgs/FleetState (duck-typed)."""
        t_ns = stamp_ns(msg.header.stamp)
        ids = [v.vehicle_id for v in msg.vehicles]
        pos = [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]
        return self.fleet_messages(t_ns, ids, pos)


def _metadata_records(path: str) -> list[tuple[str, dict]]:
    """(name, data) of every MCAP metadata record of a complete recording."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        return [(m.name, dict(m.metadata)) for m in make_reader(f).iter_metadata()]


def write_views(src: str, dst: str, network: Any = None,
                scenario_start_utc: str = DEFAULT_SCENARIO_START_UTC, geo_fixes: bool = True,
                log_time: str = "sim") -> int:
    """Copy a recording and add the view topics; returns the view messages added.

    ``log_time``: "sim" writes every log time in simulation time (a source on the scenario's UTC
    clock, MCAP record ``uam_clock``, is taken back to it); "utc" puts every message's log and
    publish time on the scenario's clock (``scenario_start_utc`` + simulation time), so a player's
    timeline shows real dates. The source's other metadata records (the run's airspace, the
    recorder's check) are copied. Decodes with rclpy.
    """
    from ..recording import McapRecorder, deserialize, parse_offered_qos, read_messages

    if log_time not in ("sim", "utc"):
        raise ValueError(f"log_time: {log_time!r} is not 'sim' or 'utc'")
    if log_time == "utc" and scenario_start_utc == SIM_CLOCK:
        raise ValueError(f"log_time 'utc' needs scenario_start_utc as an instant, not {SIM_CLOCK!r}")
    from ..recording.mcap_reader import CLOCK_METADATA, log_time_zero_ns

    views = ViewExporter(network, scenario_start_utc, geo_fixes)
    # the source's log times may already be on the scenario's UTC clock (its uam_clock record):
    # taken back to simulation time, then put on the clock asked for
    zero_src = log_time_zero_ns(src)
    zero_dst = views.start_ns if log_time == "utc" else 0
    n = 0
    with McapRecorder(dst) as rec:
        rec.add_metadata(CLOCK_METADATA, {"log_time_zero_ns": zero_dst,
                                          "log_time_start_utc": scenario_start_utc if zero_dst else SIM_CLOCK})
        for name, data in _metadata_records(src):
            if name not in ("rosbag2", CLOCK_METADATA):
                rec.add_metadata(name, data)

        def put(vm: ViewMessage) -> None:
            if not rec.has_topic(vm.topic):
                rec.add_topic(vm.topic, vm.type_name)
            rec.write(vm.topic, vm.data, vm.sim_time_ns + zero_dst)

        for vm in views.network_messages(0):
            put(vm)
            n += 1
        for r in read_messages(src):
            if not rec.has_topic(r.topic):
                rec.add_topic(r.topic, r.type_name, offered_qos_profiles=parse_offered_qos(r.qos_yaml) or None)
            rec.write(r.topic, r.data, r.log_time_ns - zero_src + zero_dst, r.publish_time_ns - zero_src + zero_dst)
            if r.topic == resolved(names.TOPIC_FLEET):
                extra = views.fleet_state_messages(deserialize(r))
            elif r.topic == resolved(names.TOPIC_PLANS):
                extra = views.plan_messages(deserialize(r))
            elif r.topic == resolved(names.TOPIC_CONSTRAINTS):  # the set in force
                from uam_planner.live_constraints import constraints_from_text
                t_set, found = constraints_from_text(deserialize(r).data)
                extra = views.constraint_messages(max(r.log_time_ns - zero_src, int(round(t_set * 1e9))),
                                                  [k for k, _eff in found])
            else:
                continue
            for vm in extra:
                put(vm)
                n += 1
    return n


def benchmark(network: Any, steps: int = 500, vehicles: int = 70, seed: int = 0) -> list[dict]:
    """Cost per simulation step of the view topics and of Rerun's fleet logging (wall ms).

    ``steps`` fleet states of ``vehicles`` aircraft at random ENU positions; the view messages
    are encoded and written to a temporary MCAP, once with fixes every step and once every 5 s.
    """
    import tempfile
    import time

    from ..recording import McapRecorder
    from .rerun_log import RerunLogger

    rng = np.random.default_rng(seed)
    ids = [f"r{j:05d}_000" for j in range(vehicles)]
    pos = rng.uniform(-10000, 10000, size=(steps, vehicles, 3))
    rows = []
    with tempfile.TemporaryDirectory() as tmp:
        for period in (0.0, 5.0):
            ex = ViewExporter(network, fix_period_s=period)
            t0 = time.perf_counter()
            msgs = [ex.fleet_messages(k * _NS, ids, pos[k]) for k in range(steps)]
            encode_s = time.perf_counter() - t0
            with McapRecorder(f"{tmp}/views_{period}.mcap") as rec:
                t0 = time.perf_counter()
                for out in msgs:
                    for vm in out:
                        if not rec.has_topic(vm.topic):
                            rec.add_topic(vm.topic, vm.type_name)
                        rec.write(vm.topic, vm.data, vm.sim_time_ns)
                write_s = time.perf_counter() - t0
            rows.append({"what": f"view topics, fixes every {period:g} s", "msgs_per_step":
                         sum(len(m) for m in msgs) / steps, "ms_per_step": 1e3 * (encode_s + write_s) / steps})
        with RerunLogger("save", f"{tmp}/x.rrd", network=network) as logger:
            t0 = time.perf_counter()
            for k in range(steps):
                if k % 50 == 0:   # the airborne set changes: routes are re-logged
                    ids = ids[1:] + [f"z{k:05d}"]
                logger.log_fleet(float(k), ids, pos[k])
            rr_s = time.perf_counter() - t0
        rows.append({"what": "Rerun log_fleet (.rrd)", "msgs_per_step": float("nan"),
                     "ms_per_step": 1e3 * rr_s / steps})
    return rows


def main(argv: list[str] | None = None) -> int:
    """``python -m uam_sim.std_msgs_export RUN.mcap OUT.mcap [--network NET.yaml]`` | ``--bench``."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m uam_sim.std_msgs_export",
                                 description="copy a recording and add the standard-message view topics")
    ap.add_argument("src", nargs="?")
    ap.add_argument("dst", nargs="?")
    ap.add_argument("--bench", action="store_true", help="print the cost per step of the views "
                    "(with --network, default the Singapore network) and exit")
    ap.add_argument("--network", default="", help="the run's network file (needed for markers and fixes)")
    ap.add_argument("--scenario-start-utc", default=None,
                    help="'sim' (default: header stamps in simulation time, as every other topic's) "
                         f"or an ISO 8601 instant of simulation time 0 (default with --log-time utc: "
                         f"{DEFAULT_SCENARIO_START_UTC})")
    ap.add_argument("--no-fixes", action="store_true", help="leave out the per-vehicle NavSatFix topics")
    ap.add_argument("--log-time", choices=("sim", "utc"), default="sim")
    args = ap.parse_args(argv)
    if not args.bench and not (args.src and args.dst):
        ap.error("src and dst are required (or --bench)")
    try:
        network = None
        if args.network or args.bench:
            from pathlib import Path

            from uam_planner.network import load_network
            default = Path(__file__).resolve().parents[4] / "config" / "networks" / "singapore.yaml"
            network = load_network(args.network or default)
        if args.bench:
            for row in benchmark(network):
                print(f"{row['what']:34s} {row['msgs_per_step']:6.1f} msgs/step {row['ms_per_step']:7.2f} ms/step")
            return 0
        start = args.scenario_start_utc or (DEFAULT_SCENARIO_START_UTC if args.log_time == "utc" else SIM_CLOCK)
        n = write_views(args.src, args.dst, network, start, not args.no_fixes, args.log_time)
    except (OSError, ValueError) as exc:
        print(f"std_msgs_export: {exc}", file=sys.stderr)
        return 1
    print(f"wrote {args.dst} with {n} view messages")
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
