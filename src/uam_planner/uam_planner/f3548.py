"""Plans as ASTM F3548-21 operational intents, constraints as F3548 constraints (
docs/f3548.md). Built with ``uas_standards.astm.f3548.v21.api`` types; no ROS, no wall clock.

**Volumes.** A trajectory (piecewise linear in time, ``uam_planner.trajectory``) becomes one
Volume4D per *piece*: every segment is cut in time into ``ceil(duration / max_piece_s)`` equal
pieces. A piece flown from A (time ta) to B (time tb) gives

- horizontally the rectangle around the segment A-B widened by ``r_h`` on both sides and
  lengthened by ``r_h`` beyond both ends (a square of side 2 r_h for a vertical climb); it
  contains every disc of radius r_h centred on the piece;
- vertically [min(zA, zB) - r_v, max(zA, zB) + r_v];
- in time [ta, tb] (start rounded down, end up, to the microsecond).

``VolumeSpec.for_separation`` takes r_h = H / 2 and r_v = V / 2 of the run's separation model
(the sphere: V = H = the radius), each less F3548's 1 cm precision: two flights exactly at the
separation (two adjacent flight levels) get volumes 2 cm apart, which F3548 counts as disjoint
(it counts volumes within 1 cm of each other as intersecting). So at every instant t the
aircraft's box (disc r_h x band r_v) lies inside the volume of the piece flying at t, and:

- **a loss of separation by more than 1 cm always shows as intersecting volumes** at F3548's
  precision (two aircraft within H - 1 cm horizontally and V - 1 cm vertically at t: their
  boxes, and so their volumes at t, are within 1 cm of each other);
- **the converse does not hold**: a volume holds its whole piece for its whole time window, so
  two flights that keep separation can have intersecting volume sets. :meth:`VolumeSpec.bounds_m`
  gives the exact sufficient condition used in the tests: the volume sets of two flights are
  disjoint (by more than F3548's 1 cm) if at every instant both are airborne their horizontal
  distance exceeds ``D_h = 2 sqrt((v_h dt + r_h)^2 + r_h^2)`` or their vertical distance
  exceeds ``D_v = 2 (r_v + v_z dt)`` (dt = max_piece_s, v_h, v_z the largest speeds), plus 1 cm.
  A planner run with a separation >= sqrt(D_h^2 + D_v^2) + 1 cm (sphere) therefore publishes
  volume sets that never intersect; with the paper's 100 m and 5 s pieces at 10 m/s,
  D_h = 223.6 m.

**Frames.** What a trajectory's z means depends on the network (``IntentContext.for_network``):

- a layered network (``Network.layered``): z is the height above the WGS84 ellipsoid (the
  flight level), so the band is exactly [min z - r_v, max z + r_v]: two levels V apart give
  bands V - 2 r_v apart everywhere. (x, y) is published at the latitude and longitude of the
  ENU point (x, y, ``horizontal_up_m``), one map for every height, so volumes disjoint in the
  network's frame stay disjoint when published;
- the paper's networks: z is ENU up. Corners are converted to WGS84 exactly
  (``uam_planner.geo.enu_to_geodetic``, at the piece's lower and upper altitude); the band is the
  least and greatest ellipsoidal height over the corners, so it holds the ENU slab (ENU up
  tilts from the local vertical: a 30 m slab spans 30.27 m of heights at 10 km).

Polygon edges are geodesics in F3548 and straight lines in ENU; for pieces of ~50 m the two
differ by far less than 1 cm.

**References.** ``id``: a UUID in F3548's UUIDv4 format derived from (operator, request id) by
SHA-1 (``uuid5`` with its version bits set to 4, as F3548's EntityID pattern demands), so the
same flight has the same id in every run and every version. ``version``: a new one for every
plan version and every state change (:func:`intent_version`), so an intent's details never
change while its version stands; the details hold every volume of the plan version.
``ovn``: without a DSS no one issues OVNs, so it is the SHA-256 of (id, version), 32 hex digits
(F3548: 16-128 characters). ``state``: :func:`uam_planner.replanning.flight_state`;
a Contingent intent has no ``volumes`` and its plan in ``off_nominal_volumes`` (F3548);
Ended is no F3548 state (the intent is deleted): :func:`operational_intent` returns None.
"""

from __future__ import annotations

import hashlib
import math
import re
import uuid
from dataclasses import dataclass
from datetime import datetime, timedelta, timezone
from typing import Sequence

import numpy as np
from shapely import STRtree
from shapely.geometry import Polygon as ShapelyPolygon
from uas_standards.astm.f3548.v21 import api
from uas_standards.astm.f3548.v21.constants import IntersectionMinimumPrecisionCm, OiMaxVertices

from uam_contract.stamps import DEFAULT_SCENARIO_START_UTC, scenario_start_ns

from .geo import enu_to_geodetic
from .separation import SeparationModel, as_separation_model

#: F3548's intersection precision [m] (1 cm)
PRECISION_M = IntersectionMinimumPrecisionCm / 100.0
#: default duration of one volume [s]: 50 m of flight at the paper's 10 m/s
DEFAULT_PIECE_S = 5.0
#: UUID namespace of this project's intent and constraint ids (fixed: ids are stable across runs)
ID_NAMESPACE = uuid.UUID("8f0c5b7e-3a61-4c39-9d0e-25f3548a0000")
DEFAULT_MANAGER = "uam-fleet"
DEFAULT_USS_BASE_URL = "http://localhost:8090"


class F3548Error(ValueError):
    """Bad input for a conversion, naming the field and the value."""


@dataclass(frozen=True)
class VolumeSpec:
    """How a trajectory becomes volumes.

    Attributes:
        horizontal_buffer_m: r_h, the rectangle's half-width and end extension [m] > 0.
        vertical_buffer_m: r_v, added below and above the piece's altitudes [m] > 0.
        max_piece_s: the longest time window of one volume [s] > 0.
    """

    horizontal_buffer_m: float
    vertical_buffer_m: float
    max_piece_s: float = DEFAULT_PIECE_S

    def __post_init__(self):
        for name in ("horizontal_buffer_m", "vertical_buffer_m", "max_piece_s"):
            v = getattr(self, name)
            if isinstance(v, bool) or not isinstance(v, (int, float, np.integer, np.floating)) \
                    or not math.isfinite(v) or v <= 0:
                raise F3548Error(f"VolumeSpec.{name}: {v!r} is not a positive finite number")

    @classmethod
    def for_separation(cls, separation, max_piece_s: float = DEFAULT_PIECE_S) -> "VolumeSpec":
        """r_h = H / 2 - 1 cm, r_v = V / 2 - 1 cm (the sphere: both the radius / 2 - 1 cm) of a
        SeparationModel or a number (the paper's sphere of that radius): flights exactly at the
        separation get volumes 2 cm apart, disjoint at F3548's 1 cm precision."""
        model: SeparationModel = as_separation_model(separation)
        vertical = model.separation_m if model.kind == "sphere" else model.vertical_separation_m
        return cls(model.separation_m / 2.0 - PRECISION_M, vertical / 2.0 - PRECISION_M,
                   float(max_piece_s))

    def bounds_m(self, horizontal_speed_mps: float, vertical_speed_mps: float = 0.0) -> tuple:
        """(D_h, D_v): two flights whose pieces' windows overlap at t and whose volumes meet are
        within D_h horizontally AND D_v vertically at t (module docstring)."""
        r, dt = self.horizontal_buffer_m, self.max_piece_s
        d_h = 2.0 * math.hypot(abs(horizontal_speed_mps) * dt + r, r)
        d_v = 2.0 * (self.vertical_buffer_m + abs(vertical_speed_mps) * dt)
        return d_h, d_v


@dataclass(frozen=True)
class EnuVolume:
    """One volume in the network's frame: a convex polygon (corners (k, 2), ENU metres) times the
    band [lower_m, upper_m] (ENU up) times the window [t0_s, t1_s]."""

    corners_m: np.ndarray
    lower_m: float
    upper_m: float
    t0_s: float
    t1_s: float

    def polygon(self) -> ShapelyPolygon:
        return ShapelyPolygon(self.corners_m)


def _rectangle(a: np.ndarray, b: np.ndarray, r: float) -> np.ndarray:
    d = b - a
    length = float(math.hypot(d[0], d[1]))
    if length < 1e-9:  # vertical (or no) motion: a square centred on the point
        u, n = np.array([1.0, 0.0]), np.array([0.0, 1.0])
    else:
        u = d / length
        n = np.array([-u[1], u[0]])
    lo, hi = a - u * r, b + u * r
    return np.array([lo - n * r, hi - n * r, hi + n * r, lo + n * r])


def trajectory_volumes(trajectory, spec: VolumeSpec, from_s: float = -math.inf) -> list:
    """The EnuVolumes of ``trajectory`` (module docstring), in time order; with ``from_s`` only the
    pieces that end after it (the piece flying at ``from_s`` is kept whole). O(pieces)."""
    times, points = trajectory.times_s, trajectory.points_m
    out = []
    r_h, r_v = spec.horizontal_buffer_m, spec.vertical_buffer_m
    for j in range(times.shape[0] - 1):
        t0, t1 = float(times[j]), float(times[j + 1])
        if t1 <= from_s:
            continue
        n = max(1, math.ceil((t1 - t0) / spec.max_piece_s - 1e-9))
        p0, p1 = points[j], points[j + 1]
        for k in range(n):
            ta = t0 + (t1 - t0) * k / n
            tb = t1 if k == n - 1 else t0 + (t1 - t0) * (k + 1) / n
            if tb <= from_s:
                continue
            a = p0 + (p1 - p0) * (k / n)
            b = p1 if k == n - 1 else p0 + (p1 - p0) * ((k + 1) / n)
            out.append(EnuVolume(_rectangle(a[:2], b[:2], r_h), float(min(a[2], b[2]) - r_v),
                                 float(max(a[2], b[2]) + r_v), ta, tb))
    return out


def volumes_for_limit(trajectory, spec: VolumeSpec, from_s: float = -math.inf,
                      max_vertices: int = OiMaxVertices) -> tuple:
    """(volumes, spec used): the spec's pieces, or, where they would exceed F3548's
    ``OiMaxVertices`` (10,000; 4 per volume), pieces just long enough to fit (the bound of
    :meth:`VolumeSpec.bounds_m` then holds with the longer ``max_piece_s`` returned)."""
    vols = trajectory_volumes(trajectory, spec, from_s)
    while 4 * len(vols) > max_vertices:
        spec = VolumeSpec(spec.horizontal_buffer_m, spec.vertical_buffer_m,
                          spec.max_piece_s * 4 * len(vols) / max_vertices * 1.05)
        vols = trajectory_volumes(trajectory, spec, from_s)
    return vols, spec


def first_intersection(a: Sequence[EnuVolume], b: Sequence[EnuVolume],
                       precision_m: float = PRECISION_M):
    """The first pair (i, j) of volumes of ``a`` and ``b`` that intersect at F3548's precision
    (windows overlap, bands overlap or lie closer than ``precision_m``, polygons closer than
    ``precision_m``; closed sets, so touching counts), or None. GEOS STR-tree over ``b``."""
    if not a or not b:
        return None
    polys_b = [v.polygon() for v in b]
    tree = STRtree(polys_b)
    for i, va in enumerate(a):
        pa = va.polygon()
        for j in sorted(int(k) for k in tree.query(pa, predicate="dwithin", distance=precision_m)):
            vb = b[j]
            if va.t0_s <= vb.t1_s and vb.t0_s <= va.t1_s \
                    and va.lower_m <= vb.upper_m + precision_m and vb.lower_m <= va.upper_m + precision_m:
                return i, j
    return None


#: the form :func:`rfc3339` writes (UTC, six fractional digits, 'Z')
_OWN_RFC3339 = re.compile(r"\d{4}-\d\d-\d\dT\d\d:\d\d:\d\d\.\d{6}Z")


def _timestamp(value: str) -> float:
    """Seconds since 1970 of an RFC 3339 instant: the form :func:`rfc3339` writes by the
    standard library's parser (the same datetime as implicitdict's arrow parser, at a tenth of
    its cost: it dominated the check of a run's published intents), any other form by
    implicitdict's, as every peer's document is read."""
    if _OWN_RFC3339.fullmatch(value):
        return datetime.fromisoformat(value).timestamp()
    from implicitdict import StringBasedDateTime

    return StringBasedDateTime(value).datetime.timestamp()


def published_prisms(volumes, origin_lat_lon_alt) -> list:
    """(polygon in the origin's tangent plane [m], lower, upper [m], t0, t1 [s since 1970]) of
    Volume4D JSON documents with polygon outlines (what :func:`first_published_intersection`
    compares; make them once when a set is compared many times)."""
    from .geo import geodetic_to_enu
    origin = origin_lat_lon_alt
    out = []
    for v in volumes:
        if isinstance(v, tuple):  # already made
            out.append(v)
            continue
        vol = v["volume"]
        ll = np.array([[p["lat"], p["lng"], float(origin[2])]
                       for p in vol["outline_polygon"]["vertices"]], dtype=float)
        xy = geodetic_to_enu(ll, origin)[:, :2]
        times = [_timestamp(v[k]["value"]) for k in ("time_start", "time_end")]
        out.append((ShapelyPolygon(xy), float(vol["altitude_lower"]["value"]),
                    float(vol["altitude_upper"]["value"]), *times))
    return out


def first_published_intersection(a: Sequence[dict], b: Sequence[dict], origin_lat_lon_alt,
                                 precision_m: float = PRECISION_M):
    """As :func:`first_intersection`, on published Volume4Ds (JSON, polygon outlines, W84
    heights, RFC 3339 windows; or :func:`published_prisms` of them), as a peer sees them:
    vertices placed in the tangent plane of ``origin_lat_lon_alt`` at its height (over a city,
    within millimetres of the geodesic distances), bands compared as heights. The first
    intersecting pair (i, j) or None."""
    pa, pb = published_prisms(a, origin_lat_lon_alt), published_prisms(b, origin_lat_lon_alt)
    if not pa or not pb:
        return None
    tree = STRtree([p[0] for p in pb])
    for i, (poly, lo, hi, t0, t1) in enumerate(pa):
        for j in sorted(int(k) for k in tree.query(poly, predicate="dwithin", distance=precision_m)):
            _, lo2, hi2, s0, s1 = pb[j]
            if t0 <= s1 and s0 <= t1 and lo <= hi2 + precision_m and lo2 <= hi + precision_m:
                return i, j
    return None

def published_intersections(decided, ctx: IntentContext, origin_lat_lon_alt) -> tuple:
    """Our own intents as a peer checks them: (pairs of intents of different flights that stand
    at the same time and fly at overlapping times, the intersecting ones as (flight a, flight b,
    vertical overlap [m])), on the published documents (``volume4d`` JSON, compared with
    :func:`first_published_intersection` at F3548's 1 cm). ``decided``: every (flight, decision
    time [s]) of a run, a version standing from its decision until the flight's next version.
    O(pairs x volumes); for tests and benchmarks."""
    versions = {}
    for f, t in decided:
        versions.setdefault(f.request_id, []).append((t, f))
    items = []
    for rid, vs in versions.items():
        vs.sort(key=lambda x: (x[0], x[1].version))
        for n, (t, f) in enumerate(vs):
            until = vs[n + 1][0] if n + 1 < len(vs) else f.arrival_s
            vols, _ = volumes_for_limit(f.trajectory, ctx.spec)
            prisms = published_prisms([as_json(volume4d(v, ctx)) for v in vols], origin_lat_lon_alt)
            # (..., the prisms, each prism's t0, t1 [s since 1970], lower, upper [m])
            items.append((rid, t, until, f, prisms,
                          np.array([(q[3], q[4], q[1], q[2]) for q in prisms], dtype=float).reshape(-1, 4)))
    pairs, hits = 0, []
    for i, a in enumerate(items):
        for b in items[i + 1:]:
            if a[0] == b[0] or a[2] < b[1] or b[2] < a[1] \
                    or a[3].arrival_s < b[3].departure_s or b[3].arrival_s < a[3].departure_s:
                continue
            pairs += 1
            # only a prism that overlaps one of the other set in time and band can be in the pair
            # first_published_intersection returns; compared without the others, in the same
            # order, the first intersecting pair is the same, at a fraction of the tree queries
            ta, tb = a[5], b[5]
            ok = ((ta[:, 0, None] <= tb[None, :, 1]) & (tb[None, :, 0] <= ta[:, 1, None])
                  & (ta[:, 2, None] <= tb[None, :, 3] + PRECISION_M)
                  & (tb[None, :, 2] <= ta[:, 3, None] + PRECISION_M))
            ia, ib = np.flatnonzero(ok.any(axis=1)), np.flatnonzero(ok.any(axis=0))
            hit = first_published_intersection([a[4][i] for i in ia], [b[4][j] for j in ib],
                                               origin_lat_lon_alt)
            if hit is not None:
                pa, pb = a[4][ia[hit[0]]], b[4][ib[hit[1]]]
                hits.append((a[3], b[3], min(pa[2], pb[2]) - max(pa[1], pb[1])))
    return pairs, hits


# ---- identities and times ---------------------------------------------------------------------

def entity_id(kind: str, *parts: str) -> str:
    """A stable id in F3548's UUIDv4 format (version 4, RFC 4122 variant) from ``kind`` and
    ``parts`` (SHA-1 name-based, uuid5, with the version bits set to 4)."""
    name = "/".join([kind, *(str(p) for p in parts)])
    return str(uuid.UUID(bytes=uuid.uuid5(ID_NAMESPACE, name).bytes, version=4))


def intent_id(operator_id: str, request_id: str) -> str:
    """The operational intent id of a request (every version shares it)."""
    return entity_id("operational_intent", operator_id or "", request_id)


def constraint_entity_id(constraint_id: str) -> str:
    return entity_id("constraint", constraint_id)


#: each state's step within one plan version, in the order they can follow each other
_STATE_STEP = {"Accepted": 0, "Activated": 1, "Nonconforming": 2, "Contingent": 2}


def intent_version(plan_version: int, state: str) -> int:
    """The F3548 version of an operational intent in ``state`` at plan version ``plan_version``:
    a new one for every plan version and for every state change within one (F3548: an intent's
    details never change while its version and OVN stand), ``3 (v - 1) + 1`` Accepted, ``+ 2``
    Activated, ``+ 3`` Nonconforming or Contingent; it only grows as a flight goes on."""
    if state not in _STATE_STEP:
        raise F3548Error(f"state: {state!r} is not an F3548 operational intent state")
    return 3 * (max(1, int(plan_version)) - 1) + _STATE_STEP[state] + 1


def ovn(entity: str, version: int) -> str:
    """A local OVN (no DSS issues one here): 32 hex digits of SHA-256(id, version)."""
    return hashlib.sha256(f"{entity}:{int(version)}".encode()).hexdigest()[:32]


def rfc3339(t_s: float, start_ns: int, up: bool = False) -> str:
    """Simulation time ``t_s`` as an RFC 3339 UTC instant ('Z') after the scenario start
    ``start_ns`` [ns since 1970], to the microsecond, rounded down (or ``up``)."""
    if not math.isfinite(t_s):
        raise F3548Error(f"time: {t_s!r} is not finite")
    us = (math.ceil if up else math.floor)(float(t_s) * 1e6)
    base = datetime(1970, 1, 1, tzinfo=timezone.utc) + timedelta(microseconds=start_ns // 1000)
    when = base + timedelta(microseconds=us)
    return when.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


@dataclass(frozen=True)
class IntentContext:
    """What a conversion needs beyond the plan.

    Attributes:
        origin_lat_lon_alt: the network's ENU origin (lat deg, lon deg, ellipsoidal height m).
        spec: the VolumeSpec (from the run's separation model).
        scenario_start_utc: the UTC instant of simulation time 0 (ISO 8601 with a zone; 'sim' is
            refused: F3548 needs absolute times).
        manager, uss_base_url: the USS the intents say they come from (no trailing '/').
        altitude_is_height: True when z is the height above the WGS84 ellipsoid (a layered
            network), False when it is ENU up (module docstring, "Frames").
        horizontal_up_m: with ``altitude_is_height``, the ENU up [m] at which (x, y) is placed.
    """

    origin_lat_lon_alt: tuple
    spec: VolumeSpec
    scenario_start_utc: str = DEFAULT_SCENARIO_START_UTC
    manager: str = DEFAULT_MANAGER
    uss_base_url: str = DEFAULT_USS_BASE_URL
    altitude_is_height: bool = False
    horizontal_up_m: float = 0.0

    @classmethod
    def for_network(cls, network, spec: VolumeSpec, **kw) -> "IntentContext":
        """The context of ``network``: its origin, and for a layered network z read as the
        height above the ellipsoid, (x, y) placed at the mean flight level."""
        if getattr(network, "layered", False):
            kw.setdefault("altitude_is_height", True)
            kw.setdefault("horizontal_up_m", float(np.mean(network.levels_m))
                          - float(network.origin_lat_lon_alt[2]))
        return cls(tuple(float(v) for v in network.origin_lat_lon_alt), spec, **kw)

    def __post_init__(self):
        start = scenario_start_ns(self.scenario_start_utc)
        if start == 0:
            raise F3548Error(f"scenario_start_utc: {self.scenario_start_utc!r}: F3548 times are "
                             f"absolute UTC; give an instant such as {DEFAULT_SCENARIO_START_UTC!r}")
        if not isinstance(self.uss_base_url, str) or not self.uss_base_url \
                or self.uss_base_url.endswith("/"):
            raise F3548Error(f"uss_base_url: {self.uss_base_url!r} must be a URL without a "
                             f"trailing '/'")
        object.__setattr__(self, "_start_ns", start)

    @property
    def start_ns(self) -> int:
        return self._start_ns

    @property
    def subscription_id(self) -> str:
        """The subscription an intent names (F3548 requires one; without a DSS it is this
        USS's single, fixed id)."""
        return entity_id("subscription", self.manager)

    def time(self, t_s: float, up: bool = False) -> api.Time:
        return api.Time(value=rfc3339(t_s, self.start_ns, up), format="RFC3339")

    def altitude(self, h_m: float) -> api.Altitude:
        return api.Altitude(value=float(h_m), reference="W84", units="M")

    def outline_and_band(self, corners_m, lower_m: float, upper_m: float) -> tuple:
        """(lat lng (k, 2) [deg], lowest, highest height [m]) of the prism ``corners_m`` (k, 2)
        x [lower_m, upper_m] in the network's frame (module docstring, "Frames")."""
        xy = np.asarray(corners_m, dtype=float).reshape(-1, 2)
        k = xy.shape[0]
        if self.altitude_is_height:
            enu = np.column_stack([xy, np.full(k, self.horizontal_up_m)])
            return enu_to_geodetic(enu, self.origin_lat_lon_alt)[:, :2], float(lower_m), float(upper_m)
        enu = np.zeros((2 * k, 3))
        enu[:k, :2] = xy
        enu[k:, :2] = xy
        enu[:k, 2] = lower_m
        enu[k:, 2] = upper_m
        lla = enu_to_geodetic(enu, self.origin_lat_lon_alt)
        return ((lla[:k, :2] + lla[k:, :2]) / 2.0, float(lla[:k, 2].min()),
                float(lla[k:, 2].max()))


def volume4d(v: EnuVolume, ctx: IntentContext) -> api.Volume4D:
    """One EnuVolume as an F3548 Volume4D (WGS84 corners, W84 altitudes, UTC window)."""
    latlng, lower, upper = ctx.outline_and_band(v.corners_m, v.lower_m, v.upper_m)
    vertices = [api.LatLngPoint(lat=float(lat), lng=float(lng)) for lat, lng in latlng]
    return api.Volume4D(
        volume=api.Volume3D(outline_polygon=api.Polygon(vertices=vertices),
                            altitude_lower=ctx.altitude(lower), altitude_upper=ctx.altitude(upper)),
        time_start=ctx.time(v.t0_s), time_end=ctx.time(v.t1_s, up=True))


def operational_intent(flight, t_s: float, ctx: IntentContext, state: str | None = None):
    """The F3548 OperationalIntent of ``flight`` (a ``planning.Flight``, its version) as known
    at simulation time ``t_s``: state at ``t_s`` (or ``state``), every volume of the plan
    version (its details are the same whenever asked: F3548 changes them only with a new
    version), the version :func:`intent_version`; None when Ended. Raises F3548Error naming
    the field for a bad state."""
    from .replanning import flight_state
    st = state if state is not None else flight_state(flight, t_s)
    if st == "Ended":
        return None
    version = intent_version(flight.version, st)
    vols, _ = volumes_for_limit(flight.trajectory, ctx.spec)
    if not vols:
        return None
    v4 = [volume4d(v, ctx) for v in vols]
    oid = intent_id(flight.operator_id, flight.request_id)
    reference = api.OperationalIntentReference(
        id=oid, manager=ctx.manager, uss_availability="Unknown", version=version, state=st,
        ovn=ovn(oid, version), time_start=v4[0].time_start, time_end=v4[-1].time_end,
        uss_base_url=ctx.uss_base_url, subscription_id=ctx.subscription_id)
    off_nominal = st in ("Nonconforming", "Contingent")
    details = api.OperationalIntentDetails(
        volumes=[] if st == "Contingent" else v4, off_nominal_volumes=v4 if off_nominal else [],
        priority=int(flight.priority))
    return api.OperationalIntent(reference=reference, details=details)


def constraint_volumes(c, ctx: IntentContext) -> list:
    """The Volume4Ds of a prism Constraint (``uam_planner.constraints``): the polygon's exterior
    ring (holes are not expressible in F3548 and are filled: the F3548 volume is larger) or the
    circle, its band (an infinite limit is left out), its window (an infinite end is left out).
    Raises F3548Error for a closure (F3548 constraints are volumes)."""
    if c.vertiport_id is not None:
        raise F3548Error(f"constraint {c.constraint_id!r}: a vertiport closure has no F3548 volume")
    finite = [z for z in (c.lower_m, c.upper_m) if math.isfinite(z)]
    z_ref = finite[0] if finite else 0.0
    kw = {}
    xy = np.asarray(c.rings_m[0], dtype=float) if c.rings_m is not None \
        else np.asarray(c.center_m, dtype=float).reshape(1, 2)
    latlng, _, _ = ctx.outline_and_band(xy, z_ref, z_ref)
    if c.rings_m is not None:
        kw["outline_polygon"] = api.Polygon(vertices=[api.LatLngPoint(lat=float(a), lng=float(b))
                                                      for a, b in latlng])
    else:
        kw["outline_circle"] = api.Circle(center=api.LatLngPoint(lat=float(latlng[0, 0]),
                                                                 lng=float(latlng[0, 1])),
                                          radius=api.Radius(value=float(c.radius_m), units="M"))
    centre = xy.mean(axis=0)
    for name, z in (("altitude_lower", c.lower_m), ("altitude_upper", c.upper_m)):
        if math.isfinite(z):
            h = z if ctx.altitude_is_height else \
                enu_to_geodetic([centre[0], centre[1], z], ctx.origin_lat_lon_alt)[2]
            kw[name] = ctx.altitude(float(h))
    v4 = {"volume": api.Volume3D(**kw)}
    if math.isfinite(c.start_s):
        v4["time_start"] = ctx.time(c.start_s)
    if math.isfinite(c.end_s):
        v4["time_end"] = ctx.time(c.end_s, up=True)
    return [api.Volume4D(**v4)]


#: the reference's end of a constraint without an end: F3548 requires one; a fixed instant (this
#: long after the scenario's start) keeps a version's reference the same whenever it is served [s]
OPEN_END_S = 10_000_000.0


def f3548_constraint(c, ctx: IntentContext):
    """An F3548 Constraint (reference and details) of a prism Constraint; its id is derived from
    the constraint's id, its version is the constraint's. None for a closure. The same document
    whenever it is asked for (F3548: a version's details never change): an open start is the
    scenario's start, an open end :data:`OPEN_END_S` after it."""
    if c.vertiport_id is not None:
        return None
    vols = constraint_volumes(c, ctx)
    cid = constraint_entity_id(c.constraint_id)
    start = vols[0].time_start if "time_start" in vols[0] else ctx.time(0.0)
    end = vols[0].time_end if "time_end" in vols[0] else ctx.time(OPEN_END_S, up=True)
    reference = api.ConstraintReference(
        id=cid, manager=ctx.manager, uss_availability="Unknown", version=int(c.version),
        ovn=ovn(cid, c.version), time_start=start, time_end=end, uss_base_url=ctx.uss_base_url)
    details = api.ConstraintDetails(volumes=vols, type="uam_fleet.restriction")
    return api.Constraint(reference=reference, details=details)


def as_json(obj) -> dict:
    """An ImplicitDict (or a list of them) as plain JSON data (enums as strings)."""
    import json
    return json.loads(json.dumps(obj, default=lambda o: o.value if hasattr(o, "value") else str(o)))


# ---- in: another USS's operational intents and F3548 constraints ------------------------------

F3548_KEYS = ("operational_intent", "operational_intents", "constraint", "constraints",
              "reference")


def is_f3548_document(doc) -> bool:
    """True for what :func:`constraints_from_f3548` reads: a GetOperationalIntentDetailsResponse
    or GetConstraintDetailsResponse, a bare OperationalIntent or Constraint, a list of those, or
    ``{"operational_intents": [...], "constraints": [...]}``."""
    if isinstance(doc, list):
        return bool(doc) and all(is_f3548_document(d) for d in doc)
    return isinstance(doc, dict) and doc.get("type") != "FeatureCollection" \
        and any(k in doc for k in F3548_KEYS)


def _sim_s(time_doc, start_ns: int, where: str) -> float:
    from implicitdict import StringBasedDateTime
    try:
        when = StringBasedDateTime(time_doc["value"]).datetime
    except (KeyError, TypeError, ValueError):
        raise F3548Error(f"{where}: {time_doc!r} is not an F3548 Time") from None
    delta = when.astimezone(timezone.utc) - datetime(1970, 1, 1, tzinfo=timezone.utc)
    ns = (delta.days * 86400 + delta.seconds) * 1_000_000_000 + delta.microseconds * 1000
    return (ns - start_ns) / 1e9


def _volume_constraint(v4: dict, cid: str, version: int, reason: str, origin, start_ns: int,
                       buffer_h: float, buffer_v: float, where: str, heights: bool = False):
    """One F3548 Volume4D (JSON) as a prism Constraint in the network's frame, widened by
    ``buffer_h`` horizontally (mitre joins: the polygon stays a polygon) and ``buffer_v``
    below and above. ``heights``: the frame's z is the height above the ellipsoid (a layered
    network), so a W84 altitude is taken as it is."""
    from shapely.geometry import Polygon as P

    from .constraints import Constraint
    from .geo import geodetic_to_enu

    vol = v4.get("volume") or {}
    lower = vol.get("altitude_lower")
    upper = vol.get("altitude_upper")
    for name, alt in (("altitude_lower", lower), ("altitude_upper", upper)):
        if alt is not None and (alt.get("reference") != "W84" or alt.get("units") != "M"):
            raise F3548Error(f"{where}.volume.{name}: {alt!r} is not W84 metres")
    if vol.get("outline_polygon"):
        pts = vol["outline_polygon"].get("vertices") or []
        if len(pts) < 3:
            raise F3548Error(f"{where}.volume.outline_polygon: {len(pts)} vertices, fewer than 3")
        lla = np.array([[p["lat"], p["lng"], 0.0] for p in pts], dtype=float)
        h_ref = float(lower["value"]) if lower else 0.0
        lla[:, 2] = h_ref
        enu = geodetic_to_enu(lla, origin)
        ring = P(enu[:, :2])
        if buffer_h > 0:
            ring = ring.buffer(buffer_h, join_style="mitre", mitre_limit=10.0)
        xy = np.asarray(ring.exterior.coords)[:-1]
        centre = enu[:, :2].mean(axis=0)
        shape = {"rings_m": (xy,)}
    elif vol.get("outline_circle"):
        circ = vol["outline_circle"]
        if circ.get("radius", {}).get("units") != "M":
            raise F3548Error(f"{where}.volume.outline_circle.radius: {circ.get('radius')!r} is not metres")
        h_ref = float(lower["value"]) if lower else 0.0
        c = geodetic_to_enu([circ["center"]["lat"], circ["center"]["lng"], h_ref], origin)
        centre = c[:2]
        shape = {"center_m": (float(c[0]), float(c[1])),
                 "radius_m": float(circ["radius"]["value"]) + buffer_h}
    else:
        raise F3548Error(f"{where}.volume: neither outline_polygon nor outline_circle")

    def up(alt, sign):
        if alt is None:
            return -math.inf if sign < 0 else math.inf
        h = float(alt["value"])
        z = h if heights else geodetic_to_enu([*_centre_lla(centre, origin), h], origin)[2]
        return float(z + sign * buffer_v)

    start = _sim_s(v4["time_start"], start_ns, f"{where}.time_start") if v4.get("time_start") else -math.inf
    end = _sim_s(v4["time_end"], start_ns, f"{where}.time_end") if v4.get("time_end") else math.inf
    return Constraint(cid, int(version), reason, start, end, lower_m=up(lower, -1),
                      upper_m=up(upper, +1), **shape)


def volume_prism(v4: dict, network, scenario_start_utc: str, constraint_id: str, where: str,
                 buffer_h_m: float = 0.0, buffer_v_m: float = 0.0):
    """One Volume4D (JSON, F3548's or InterUSS flight_planning's: the same fields) as a prism
    Constraint in ``network``'s frame, widened by ``buffer_h_m`` / ``buffer_v_m``; times on the
    scenario's clock. Raises F3548Error naming ``where`` and the field (a reference other than
    W84, a polygon of fewer than 3 vertices, no outline, a time that is not RFC 3339)."""
    if not isinstance(v4, dict):
        raise F3548Error(f"{where}: {type(v4).__name__} is not a Volume4D")
    try:
        return _volume_constraint(v4, constraint_id, 1, where, network.origin_lat_lon_alt,
                                  scenario_start_ns(scenario_start_utc), float(buffer_h_m), float(buffer_v_m),
                                  where, bool(getattr(network, "layered", False)))
    except (KeyError, TypeError, ValueError) as exc:
        if isinstance(exc, F3548Error):
            raise
        raise F3548Error(f"{where}: {exc}") from None


def _centre_lla(centre_enu, origin):
    lla = enu_to_geodetic([float(centre_enu[0]), float(centre_enu[1]), 0.0], origin)
    return float(lla[0]), float(lla[1])


def constraints_from_f3548(doc, network, scenario_start_utc: str = DEFAULT_SCENARIO_START_UTC,
                           spec: VolumeSpec | None = None) -> list:
    """Another USS's operational intents and F3548 constraints as this planner's prism
    Constraints (``uam_planner.constraints``; docs/f3548.md, "In").

    - every volume of an intent (``volumes`` and ``off_nominal_volumes``) becomes one prism, widened
      by ``spec``'s r_h horizontally and r_v vertically (default: half the paper's 100 m), so our
      aircraft's half-separation box stays out of the other USS's volume; id
      ``oi:<intent id>:<k>``, version the intent's, reason naming the manager, state and priority.
      Every foreign intent is avoided whatever its priority (F3548 lets a higher-priority flight
      conflict with a lower one; this planner never plans into conflict);
    - every volume of an F3548 constraint becomes one prism, not widened (as our own constraints:
      the trajectory may not enter it); id ``cst:<constraint id>:<k>``.
    Times are read on the scenario's UTC clock (simulation time 0 = ``scenario_start_utc``).
    Raises F3548Error (a ValueError) naming the document, the volume and the field."""
    from implicitdict import ImplicitDict

    spec = spec or VolumeSpec.for_separation(100.0)
    start_ns = scenario_start_ns(scenario_start_utc)
    origin = network.origin_lat_lon_alt
    heights = bool(getattr(network, "layered", False))
    items = doc if isinstance(doc, list) else [doc]
    out = []
    for n, item in enumerate(items):
        where = f"document {n}"
        if not isinstance(item, dict):
            raise F3548Error(f"{where}: {type(item).__name__} is not an F3548 document")
        if "operational_intents" in item or "constraints" in item:
            out += constraints_from_f3548(
                [{"operational_intent": d} for d in item.get("operational_intents", [])]
                + [{"constraint": d} for d in item.get("constraints", [])],
                network, scenario_start_utc, spec)
            continue
        kind = "constraint" if "constraint" in item else "operational_intent"
        body = item.get(kind, item)
        try:
            ImplicitDict.parse(body, api.Constraint if kind == "constraint" else api.OperationalIntent)
        except (ValueError, KeyError, TypeError) as exc:
            raise F3548Error(f"{where}: not an F3548 {'Constraint' if kind == 'constraint' else 'OperationalIntent'}: "
                             f"{exc}") from None
        ref, det = body["reference"], body["details"]
        where = f"{where} ({kind} {ref['id']})"
        if kind == "constraint":
            vols = det.get("volumes") or []
            reason = f"F3548 constraint {ref['id']} of {ref.get('manager', '?')}"
            if det.get("type"):
                reason += f" ({det['type']})"
            for k, v4 in enumerate(vols):
                out.append(_volume_constraint(v4, f"cst:{ref['id']}:{k}", ref["version"], reason,
                                              origin, start_ns, 0.0, 0.0, f"{where}.volumes[{k}]",
                                              heights))
            continue
        vols = list(det.get("volumes") or []) + list(det.get("off_nominal_volumes") or [])
        reason = (f"operational intent {ref['id']} of {ref.get('manager', '?')} "
                  f"({ref.get('state', '?')}, priority {det.get('priority', 0)})")
        for k, v4 in enumerate(vols):
            out.append(_volume_constraint(v4, f"oi:{ref['id']}:{k}", ref["version"], reason, origin,
                                          start_ns, spec.horizontal_buffer_m, spec.vertical_buffer_m,
                                          f"{where}.volumes[{k}]", heights))
    return out
