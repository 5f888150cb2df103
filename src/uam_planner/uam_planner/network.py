"""The corridor network that UAM flights follow: nodes (aerodromes and corridor way points) and
undirected corridors between them.

A :class:`Network` is immutable. Node coordinates are given in WGS84 (lat, lon in degrees, altitude
in metres above the reference surface) and converted once into a local east-north-up frame
(``enu_m``, metres) about ``origin_lat_lon_alt``; everything downstream (candidate routes,
trajectories, separation) works in that frame. Corridor lengths are Euclidean 3D distances between
ENU end points.

File formats (YAML, GeoJSON, GraphML) are described in ``docs/network-format.md``. Every
validation failure raises :class:`NetworkError` with a message that names the field and the bad
value, e.g. ``nodes[3] (id 'N17').lat: 95.2 is out of range [-90, 90]``.
"""

from __future__ import annotations

import json
import math
from dataclasses import dataclass, field
from functools import cached_property
from pathlib import Path
from typing import Annotated, Any, Iterable, Mapping, Sequence

import numpy as np
import pydantic
import scipy.sparse
import scipy.sparse.csgraph
import yaml
from pydantic import AfterValidator, PlainValidator

from uam_contract.validation import parse
from uam_planner.geo import enu_to_geodetic, geodetic_to_enu

__all__ = [
    "NetworkError",
    "NoFlyZone",
    "Network",
    "build_network",
    "network_from_enu",
    "load_network",
    "save_network_yaml",
    "save_network_graphml",
    "save_network_geojson",
    "network_to_dict",
    "network_from_dict",
    "ALT_RANGE_M",
    "MIN_CORRIDOR_LENGTH_M",
    "DIRECTION_RULES",
]

#: Rules that give flight levels to directions: ``semicircular`` (a flight whose track from
#: origin to destination lies in [0, 180) degrees, east of north, flies the levels of even index
#: in ``levels_m``, the others the levels of odd index) or ``none`` (every level in either
#: direction).
DIRECTION_RULES = ("semicircular", "none")

#: Accepted node altitude range, metres above the reference surface.
ALT_RANGE_M = (-500.0, 10000.0)
#: Corridors shorter than this (end points coincide) are rejected, metres.
MIN_CORRIDOR_LENGTH_M = 1e-3
#: Default origin for networks built from ENU coordinates (central Singapore).
DEFAULT_ENU_ORIGIN = (1.3521, 103.8198, 0.0)


class NetworkError(ValueError):
    """A network definition is invalid; the message names the field and the offending value."""


@dataclass(frozen=True)
class NoFlyZone:
    """A vertical cylinder of restricted airspace (e.g. an airport zone) that no node may lie in
    and no corridor may cross (checked in the horizontal ENU plane).

    Attributes: name; lat, lon (deg) of the centre; radius_m (horizontal radius, metres).
    """

    name: str
    lat: float
    lon: float
    radius_m: float


def _readonly(a: np.ndarray) -> np.ndarray:
    a.setflags(write=False)
    return a


@dataclass(frozen=True, eq=False)
class Network:
    """An immutable corridor network.

    Attributes:
        name: network name.
        node_ids: unique string id per node; a node's index is its position here.
        names: human-readable name per node ('' if none).
        is_aerodrome: (n,) bool, True where a node is an aerodrome (vertiport).
        lat_lon_alt: (n, 3) float64: latitude deg, longitude deg, altitude m above the reference
            surface (WGS84 ellipsoid).
        enu_m: (n, 3) float64: local east, north, up metres about ``origin_lat_lon_alt``.
        origin_lat_lon_alt: (lat deg, lon deg, alt m) of the ENU origin.
        edges: (m, 2) int32 node-index pairs, u < v, lexicographically sorted and unique.
        edge_length_m: (m,) float64 Euclidean 3D corridor length between ENU end points.
        no_fly_zones: restricted circles (default none); construction checks that no node lies
            inside one and no corridor crosses one.
        levels_m: cruise flight levels [m above the reference surface], strictly increasing, or
            () for the paper's model (one cruise altitude per corridor node, aerodromes usable
            as way points). A network with levels is *layered*: aerodromes are vertiports, the
            terminals of routes (no route passes through one it does not start or end at), and
            a flight climbs vertically from a pad to one level, cruises at it and descends
            vertically to a pad (see ``uam_planner.candidates``).
        direction_rule: one of ``DIRECTION_RULES`` (layered networks only; default
            ``semicircular``).
        pads_m: ``{aerodrome id: ((east_m, north_m), ...)}`` pad offsets [m] from the
            aerodrome's position; an aerodrome not listed has one pad at (0, 0).

    Derived (computed on construction): ``index`` (id -> index), ``aerodrome_ids``,
    ``aerodrome_indices``, ``graph`` (networkx.Graph over indices 0..n-1; node attrs ``id``,
    ``aerodrome``; edge attrs ``length_m`` and ``edge_index``; treat it as read-only, copy it
    before changing weights) and ``adjacency_m`` (symmetric scipy CSR matrix of corridor lengths,
    for vectorised shortest paths). All arrays are read-only.

    Construction validates the structure (shapes, finite values, unique ids, canonical edges,
    no zero-length corridor, >= 2 aerodromes, all aerodromes mutually reachable) and raises
    :class:`NetworkError` otherwise. Use :func:`build_network`, :func:`network_from_enu` or
    :func:`load_network` rather than calling the constructor directly.
    """

    name: str
    node_ids: tuple[str, ...]
    names: tuple[str, ...]
    is_aerodrome: np.ndarray
    lat_lon_alt: np.ndarray
    enu_m: np.ndarray
    origin_lat_lon_alt: tuple[float, float, float]
    edges: np.ndarray
    edge_length_m: np.ndarray
    no_fly_zones: tuple[NoFlyZone, ...] = ()
    levels_m: tuple[float, ...] = ()
    direction_rule: str = "semicircular"
    pads_m: Mapping[str, tuple] = field(default_factory=dict)
    index: dict[str, int] = field(init=False, repr=False)
    aerodrome_ids: tuple[str, ...] = field(init=False, repr=False)
    aerodrome_indices: np.ndarray = field(init=False, repr=False)
    adjacency_m: scipy.sparse.csr_array = field(init=False, repr=False)

    def __post_init__(self) -> None:
        set_ = object.__setattr__  # frozen dataclass: derived fields are set once, here
        node_ids = tuple(self.node_ids)
        n = len(node_ids)
        names = tuple("" if s is None else str(s) for s in self.names)
        if len(names) != n:
            raise NetworkError(f"names: {len(names)} entries for {n} nodes")
        index = _node_index(node_ids)
        is_aerodrome = np.array(self.is_aerodrome, dtype=bool).reshape(-1)
        if is_aerodrome.shape != (n,):
            raise NetworkError(f"is_aerodrome: shape {is_aerodrome.shape}, expected ({n},)")
        lla = np.array(self.lat_lon_alt, dtype=np.float64)
        enu = np.array(self.enu_m, dtype=np.float64)
        _check_coordinates(node_ids, lla, enu)
        origin = tuple(float(v) for v in self.origin_lat_lon_alt)
        if len(origin) != 3 or not all(math.isfinite(v) for v in origin):
            raise NetworkError(f"origin_lat_lon_alt: {self.origin_lat_lon_alt!r} is not 3 finite numbers")
        edges = np.array(self.edges, dtype=np.int64).reshape(-1, 2) if len(self.edges) else \
            np.zeros((0, 2), dtype=np.int64)
        _check_edges(edges, node_ids)
        edges = edges.astype(np.int32)
        length = np.array(self.edge_length_m, dtype=np.float64).reshape(-1)
        _check_lengths(length, edges, enu, node_ids)
        aerodrome_indices, adjacency = _connected_aerodromes(is_aerodrome, edges, length, node_ids)

        zones = tuple(self.no_fly_zones)
        _check_no_fly_zones(zones, node_ids, enu, edges, origin)
        levels, rule, pads = _check_airspace(self.levels_m, self.direction_rule, self.pads_m,
                                             index, is_aerodrome, lla)

        set_(self, "name", str(self.name))
        set_(self, "node_ids", node_ids)
        set_(self, "names", names)
        set_(self, "is_aerodrome", _readonly(is_aerodrome))
        set_(self, "lat_lon_alt", _readonly(lla))
        set_(self, "enu_m", _readonly(enu))
        set_(self, "origin_lat_lon_alt", origin)
        set_(self, "edges", _readonly(edges))
        set_(self, "edge_length_m", _readonly(length))
        set_(self, "no_fly_zones", zones)
        set_(self, "levels_m", levels)
        set_(self, "direction_rule", rule)
        set_(self, "pads_m", pads)
        set_(self, "index", index)
        set_(self, "aerodrome_ids", tuple(node_ids[i] for i in aerodrome_indices))
        set_(self, "aerodrome_indices", _readonly(aerodrome_indices))
        set_(self, "adjacency_m", adjacency)

    # -- queries -------------------------------------------------------------------------------
    @property
    def n_nodes(self) -> int:
        """Number of nodes."""
        return len(self.node_ids)

    @property
    def n_edges(self) -> int:
        """Number of corridors."""
        return len(self.edges)

    @property
    def layered(self) -> bool:
        """True if the network declares flight levels (vertiports, levels, pads)."""
        return bool(self.levels_m)

    @property
    def separation_model(self) -> str:
        """The separation model the network was built for: 'cylinder' for a layered network (its
        levels are tens of metres apart, so under the paper's 100 m sphere they would separate
        nothing), else the paper's 'sphere'. What '' means for the planner's separation_model."""
        return "cylinder" if self.layered else "sphere"

    def pads_of(self, node_index: int) -> np.ndarray:
        """(p, 2) pad offsets [m] (east, north) of an aerodrome; one pad at (0, 0) by default."""
        return np.asarray(self.pads_m.get(self.node_ids[int(node_index)], ((0.0, 0.0),)),
                          dtype=np.float64).reshape(-1, 2)

    def node_index(self, node_id: str) -> int:
        """Index of the node with id ``node_id``; NetworkError naming the id if unknown. O(1)."""
        try:
            return self.index[node_id]
        except (KeyError, TypeError):
            raise NetworkError(f"node id {node_id!r} is not in network {self.name!r}") from None

    def edge_index(self, u: int, v: int) -> int:
        """Index into ``edges`` of the corridor between node indices u and v (either order). O(1)."""
        return int(self.edge_indices([u], [v])[0])

    @cached_property
    def graph(self):
        """The network as a networkx Graph (node i with ``id`` and ``aerodrome``, each corridor
        with ``length_m`` and ``edge_index``), built on first use: importing networkx costs
        ~0.3 CPU-s, and only the studies' figures and GraphML files use it, not the nodes."""
        import networkx as nx

        graph = nx.Graph(name=str(self.name))
        graph.add_nodes_from((i, {"id": self.node_ids[i], "aerodrome": bool(self.is_aerodrome[i])})
                             for i in range(self.n_nodes))
        graph.add_edges_from(
            (int(u), int(v), {"length_m": float(d), "edge_index": k})
            for k, ((u, v), d) in enumerate(zip(self.edges.tolist(), self.edge_length_m.tolist())))
        return graph

    @cached_property
    def _edge_keys(self) -> tuple[np.ndarray, np.ndarray]:
        """(sorted keys lo * n + hi of the corridors, the corridor index of each key)."""
        e = np.asarray(self.edges, dtype=np.int64).reshape(-1, 2)
        keys = np.minimum(e[:, 0], e[:, 1]) * self.n_nodes + np.maximum(e[:, 0], e[:, 1])
        order = np.argsort(keys, kind="stable")
        return keys[order], order

    def edge_indices(self, u, v) -> np.ndarray:
        """:meth:`edge_index` of many node index pairs at once (arrays u, v, either order):
        int64 corridor indices; NetworkError naming the first pair without a corridor.
        O(k log E)."""
        u = np.asarray(u, dtype=np.int64).reshape(-1)
        v = np.asarray(v, dtype=np.int64).reshape(-1)
        if u.shape != v.shape:
            raise NetworkError(f"edge_indices: u has {u.size} entries, v {v.size}")
        keys, order = self._edge_keys
        n = self.n_nodes
        ok = (u >= 0) & (u < n) & (v >= 0) & (v < n)
        want = np.minimum(u, v) * n + np.maximum(u, v)
        pos = np.minimum(np.searchsorted(keys, want), max(keys.size - 1, 0))
        ok &= keys.size > 0
        if keys.size:
            ok &= keys[pos] == want
        if not ok.all():
            i = int(np.flatnonzero(~ok)[0])
            raise NetworkError(f"no corridor between node indices {int(u[i])} and {int(v[i])} "
                               f"in network {self.name!r}")
        return order[pos]

    def path_length_m(self, path: Sequence[int]) -> float:
        """Length in metres of a route given as a sequence of node indices along corridors.

        Raises NetworkError if two consecutive nodes are not joined by a corridor. O(len(path)).
        """
        p = np.asarray(path, dtype=np.int64).reshape(-1)
        if len(p) < 2:
            return 0.0
        if p.min() < 0 or p.max() >= self.n_nodes:
            raise NetworkError(f"path: node index out of range [0, {self.n_nodes - 1}] in {p.tolist()}")
        adj = self.graph.adj
        for k in range(len(p) - 1):
            if int(p[k + 1]) not in adj[int(p[k])]:
                raise NetworkError(
                    f"path[{k}]->path[{k + 1}]: no corridor between {self.node_ids[p[k]]!r} and "
                    f"{self.node_ids[p[k + 1]]!r}")
        return float(np.linalg.norm(np.diff(self.enu_m[p], axis=0), axis=1).sum())

    def __reduce__(self):
        # Rebuild through the constructor, so an unpickled copy (e.g. in a worker process) is
        # validated again and keeps read-only arrays and the derived fields.
        return (Network, (self.name, self.node_ids, self.names, self.is_aerodrome,
                          self.lat_lon_alt, self.enu_m, self.origin_lat_lon_alt, self.edges,
                          self.edge_length_m, self.no_fly_zones, self.levels_m,
                          self.direction_rule, dict(self.pads_m)))

    def __repr__(self) -> str:
        levels = f", levels_m={list(self.levels_m)}" if self.levels_m else ""
        return (f"Network(name={self.name!r}, nodes={self.n_nodes}, corridors={self.n_edges}, "
                f"aerodromes={len(self.aerodrome_ids)}{levels})")


def _check_airspace(levels_m, direction_rule, pads_m, index, is_aerodrome, lla):
    """Validate levels, direction rule and pads; return them normalised (tuple, str, dict)."""
    if levels_m is None:
        levels_m = ()
    if not isinstance(levels_m, (list, tuple, np.ndarray)):
        raise NetworkError(f"airspace.levels_m: {levels_m!r} is not a list of altitudes")
    levels = tuple(_number(v, f"airspace.levels_m[{k}]") for k, v in enumerate(levels_m))
    for k in range(1, len(levels)):
        if not levels[k] > levels[k - 1]:
            raise NetworkError(f"airspace.levels_m[{k}]: {levels[k]!r} is not above "
                               f"levels_m[{k - 1}] {levels[k - 1]!r} (strictly increasing)")
    if levels:
        top = float(lla[is_aerodrome, 2].max())
        if not levels[0] > top:
            raise NetworkError(f"airspace.levels_m[0]: {levels[0]!r} is not above the highest "
                               f"aerodrome altitude {top!r} m")
    if direction_rule not in DIRECTION_RULES:
        raise NetworkError(f"airspace.direction_rule: {direction_rule!r} is not one of "
                           f"{list(DIRECTION_RULES)}")
    if direction_rule == "semicircular" and len(levels) == 1:
        raise NetworkError("airspace.direction_rule: 'semicircular' needs at least 2 levels, "
                           "got 1 (use 'none')")
    pads = {}
    for node_id, offsets in dict(pads_m or {}).items():
        where = f"nodes (id {node_id!r}).pads_m"
        if node_id not in index:
            raise NetworkError(f"{where}: {node_id!r} is not a node id")
        if not is_aerodrome[index[node_id]]:
            raise NetworkError(f"{where}: node {node_id!r} is not an aerodrome")
        if not levels:
            raise NetworkError(f"{where}: pads need a layered network (airspace.levels_m)")
        if not isinstance(offsets, (list, tuple, np.ndarray)) or len(offsets) == 0:
            raise NetworkError(f"{where}: {offsets!r} is not a non-empty list of [east_m, north_m]")
        out = []
        for k, off in enumerate(offsets):
            if not isinstance(off, (list, tuple, np.ndarray)) or len(off) != 2:
                raise NetworkError(f"{where}[{k}]: {off!r} is not [east_m, north_m]")
            pt = (_number(off[0], f"{where}[{k}][0]"), _number(off[1], f"{where}[{k}][1]"))
            if pt in out:
                raise NetworkError(f"{where}[{k}]: {list(pt)} duplicates pad {out.index(pt)}")
            out.append(pt)
        pads[node_id] = tuple(out)
    return levels, str(direction_rule), pads


def _segment_point_distance_xy(a: np.ndarray, b: np.ndarray, p: np.ndarray) -> np.ndarray:
    """Horizontal distance from point p (2,) to each segment a[i]-b[i] ((m, 2) arrays). O(m)."""
    d = b - a
    dd = np.einsum("ij,ij->i", d, d)
    t = np.clip(np.einsum("ij,ij->i", p - a, d) / np.where(dd > 0, dd, 1.0), 0.0, 1.0)
    return np.linalg.norm(a + t[:, None] * d - p, axis=1)


def _node_index(node_ids: tuple) -> dict[str, int]:
    """Node id -> index; raises NetworkError on an id that is not a non-empty string or repeats."""
    index: dict[str, int] = {}
    for i, node_id in enumerate(node_ids):
        if not isinstance(node_id, str) or not node_id:
            raise NetworkError(f"node_ids[{i}]: {node_id!r} is not a non-empty string")
        if node_id in index:
            raise NetworkError(
                f"node_ids[{i}]: {node_id!r} duplicates node_ids[{index[node_id]}]")
        index[node_id] = i
    return index


def _check_coordinates(node_ids: tuple, lla: np.ndarray, enu: np.ndarray) -> None:
    """Raises NetworkError unless the geodetic (deg, deg, m) and ENU [m] coordinates are one
    finite row of 3 per node."""
    n = len(node_ids)
    for fname, arr in (("lat_lon_alt", lla), ("enu_m", enu)):
        if arr.shape != (n, 3):
            raise NetworkError(f"{fname}: shape {arr.shape}, expected ({n}, 3)")
        bad = np.argwhere(~np.isfinite(arr))
        if len(bad):
            i, j = bad[0]
            raise NetworkError(
                f"{fname}[{i}] (id {node_ids[i]!r}): {arr[i].tolist()} is not finite")


def _check_edges(edges: np.ndarray, node_ids: tuple) -> None:
    """Raises NetworkError unless every corridor (u, v) joins two nodes with u < v and the
    corridors are sorted by (u, v) without a duplicate."""
    n, m = len(node_ids), len(edges)
    if not m:
        return
    bad = np.flatnonzero((edges < 0).any(axis=1) | (edges >= n).any(axis=1))
    if len(bad):
        raise NetworkError(f"edges[{bad[0]}]: {edges[bad[0]].tolist()} has a node index "
                           f"outside [0, {n - 1}]")
    bad = np.flatnonzero(edges[:, 0] >= edges[:, 1])
    if len(bad):
        u, v = edges[bad[0]]
        what = "is a self loop" if u == v else "is not ordered u < v"
        raise NetworkError(f"edges[{bad[0]}] ({node_ids[u]!r}-{node_ids[v]!r}): "
                           f"{[int(u), int(v)]} {what}")
    order = np.lexsort((edges[:, 1], edges[:, 0]))
    if np.any(order != np.arange(m)):
        raise NetworkError("edges: not sorted lexicographically by (u, v)")
    dup = np.flatnonzero((np.diff(edges, axis=0) == 0).all(axis=1))
    if len(dup):
        u, v = edges[dup[0] + 1]
        raise NetworkError(f"edges[{dup[0] + 1}] ({node_ids[u]!r}-{node_ids[v]!r}): "
                           f"duplicate corridor")


def _check_lengths(length: np.ndarray, edges: np.ndarray, enu: np.ndarray, node_ids: tuple) -> None:
    """Raises NetworkError unless each corridor's length [m] is its end points' ENU distance and
    at least MIN_CORRIDOR_LENGTH_M."""
    m = len(edges)
    if length.shape != (m,):
        raise NetworkError(f"edge_length_m: shape {length.shape}, expected ({m},)")
    expected = np.linalg.norm(enu[edges[:, 1]] - enu[edges[:, 0]], axis=1) if m else length
    if m and not np.allclose(length, expected, rtol=1e-9, atol=1e-6):
        k = int(np.argmax(np.abs(length - expected)))
        raise NetworkError(f"edge_length_m[{k}]: {length[k]} differs from the ENU distance "
                           f"{expected[k]}")
    short = np.flatnonzero(length < MIN_CORRIDOR_LENGTH_M)
    if len(short):
        u, v = edges[short[0]]
        raise NetworkError(
            f"edges[{short[0]}] ({node_ids[u]!r}-{node_ids[v]!r}): zero-length corridor "
            f"({length[short[0]]:.3g} m; end points coincide)")


def _connected_aerodromes(is_aerodrome: np.ndarray, edges: np.ndarray, length: np.ndarray,
                          node_ids: tuple) -> tuple[np.ndarray, "scipy.sparse.csr_array"]:
    """The aerodromes' node indices and the symmetric adjacency of corridor lengths [m]; raises
    NetworkError with fewer than 2 aerodromes or one that cannot reach the first."""
    n = len(node_ids)
    aerodrome_indices = np.flatnonzero(is_aerodrome).astype(np.int64)
    if len(aerodrome_indices) < 2:
        raise NetworkError(
            f"is_aerodrome: {len(aerodrome_indices)} aerodrome(s); at least 2 are needed")
    adjacency = scipy.sparse.csr_array(
        (np.concatenate([length, length]),
         (np.concatenate([edges[:, 0], edges[:, 1]]), np.concatenate([edges[:, 1], edges[:, 0]]))),
        shape=(n, n))
    _, labels = scipy.sparse.csgraph.connected_components(adjacency, directed=False)
    a_labels = labels[aerodrome_indices]
    off = np.flatnonzero(a_labels != a_labels[0])
    if len(off):
        a, b = node_ids[aerodrome_indices[0]], node_ids[aerodrome_indices[off[0]]]
        raise NetworkError(f"corridors: aerodromes {a!r} and {b!r} cannot reach each other "
                           f"({len(off)} of {len(aerodrome_indices)} aerodromes are not "
                           f"connected to {a!r})")
    return aerodrome_indices, adjacency
def _check_no_fly_zones(zones: Sequence[NoFlyZone], node_ids: Sequence[str], enu: np.ndarray,
                        edges: np.ndarray, origin: tuple[float, float, float]) -> None:
    """Raise NetworkError if a node lies inside, or a corridor crosses, a no-fly zone. O(z (n+m))."""
    for z_i, zone in enumerate(zones):
        if not isinstance(zone, NoFlyZone):
            raise NetworkError(f"no_fly_zones[{z_i}]: {zone!r} is not a NoFlyZone")
        centre = geodetic_to_enu([zone.lat, zone.lon, 0.0], origin)[:2]
        dist = np.linalg.norm(enu[:, :2] - centre, axis=1)
        inside = np.flatnonzero(dist < zone.radius_m)
        if len(inside):
            i = inside[0]
            raise NetworkError(
                f"nodes[{i}] (id {node_ids[i]!r}): lies {dist[i]:.0f} m from the centre of no-fly "
                f"zone {zone.name!r}, inside its radius {zone.radius_m:g} m")
        if len(edges):
            seg = _segment_point_distance_xy(enu[edges[:, 0], :2], enu[edges[:, 1], :2], centre)
            crossing = np.flatnonzero(seg < zone.radius_m)
            if len(crossing):
                k = crossing[0]
                u, v = edges[k]
                raise NetworkError(
                    f"corridor ({node_ids[u]!r}-{node_ids[v]!r}): passes {seg[k]:.0f} m from the "
                    f"centre of no-fly zone {zone.name!r}, inside its radius {zone.radius_m:g} m")


def _parse_no_fly_zones(zones: Any, where: str = "no_fly_zones") -> tuple[NoFlyZone, ...]:
    """Validate the ``no_fly_zones`` list of the file formats: {name, lat, lon, radius_m}."""
    if zones is None:
        return ()
    if not isinstance(zones, (list, tuple)):
        raise NetworkError(f"{where}: expected a list, got {type(zones).__name__}")
    zones = [{"name": z.name, "lat": z.lat, "lon": z.lon, "radius_m": z.radius_m}
             if isinstance(z, NoFlyZone) else z for z in zones]
    return tuple(NoFlyZone(z.name, z.lat, z.lon, z.radius_m)
                 for z in parse(list[_ZoneFile], _dicts(zones), where=where, error=NetworkError))


# -- construction ------------------------------------------------------------------------------
def _canonical_edges(pairs: np.ndarray) -> np.ndarray:
    """Sort each pair (u < v) and the list lexicographically. Duplicates must already be gone."""
    pairs = np.sort(np.asarray(pairs, dtype=np.int64).reshape(-1, 2), axis=1)
    order = np.lexsort((pairs[:, 1], pairs[:, 0]))
    return pairs[order]


def _check_corridor_pairs(pairs: np.ndarray, node_ids: Sequence[str], enu: np.ndarray,
                          field_name: str) -> None:
    """Reject self loops, duplicate and zero-length corridors, naming the offending entry."""
    m = len(pairs)
    if m == 0:
        return
    loops = np.flatnonzero(pairs[:, 0] == pairs[:, 1])
    if len(loops):
        k = loops[0]
        raise NetworkError(f"{field_name}[{k}].to: {node_ids[pairs[k, 1]]!r} equals from "
                           f"(self loop)")
    key = np.sort(pairs, axis=1)
    _, first, inverse = np.unique(key, axis=0, return_index=True, return_inverse=True)
    inverse = inverse.reshape(-1)
    dup = np.flatnonzero(first[inverse] != np.arange(m))
    if len(dup):
        k = dup[0]
        raise NetworkError(
            f"{field_name}[{k}] ({node_ids[pairs[k, 0]]!r}-{node_ids[pairs[k, 1]]!r}): duplicate "
            f"of {field_name}[{first[inverse[k]]}]")
    length = np.linalg.norm(enu[pairs[:, 1]] - enu[pairs[:, 0]], axis=1)
    short = np.flatnonzero(length < MIN_CORRIDOR_LENGTH_M)
    if len(short):
        k = short[0]
        raise NetworkError(
            f"{field_name}[{k}] ({node_ids[pairs[k, 0]]!r}-{node_ids[pairs[k, 1]]!r}): zero-length "
            f"corridor ({length[k]:.3g} m; the end points coincide)")


def _parse_airspace(airspace) -> tuple[tuple, str]:
    """(levels_m, direction_rule) from the ``airspace`` mapping of the file formats."""
    if airspace is None:
        return (), "semicircular"
    if not isinstance(airspace, Mapping):
        raise NetworkError(f"airspace: {airspace!r} is not a mapping {{levels_m, direction_rule}}")
    a = parse(_AirspaceFile, dict(airspace), where="airspace", error=NetworkError)
    return a.levels_m, a.direction_rule


def _assemble(name: str, node_ids: Sequence[str], names: Sequence[str], is_aerodrome,
              lla: np.ndarray, enu: np.ndarray, origin, pairs: np.ndarray,
              field_name: str, no_fly_zones: tuple[NoFlyZone, ...] = (), levels_m=(),
              direction_rule: str = "semicircular", pads_m=None) -> Network:
    _check_corridor_pairs(pairs, node_ids, enu, field_name)
    edges = _canonical_edges(pairs) if len(pairs) else np.zeros((0, 2), dtype=np.int64)
    length = np.linalg.norm(enu[edges[:, 1]] - enu[edges[:, 0]], axis=1) if len(edges) else \
        np.zeros(0)
    return Network(name=name, node_ids=tuple(node_ids), names=tuple(names),
                   is_aerodrome=np.asarray(is_aerodrome, dtype=bool), lat_lon_alt=lla,
                   enu_m=enu, origin_lat_lon_alt=tuple(float(v) for v in origin),
                   edges=edges, edge_length_m=length, no_fly_zones=no_fly_zones,
                   levels_m=levels_m, direction_rule=direction_rule, pads_m=pads_m or {})


def _number(value: Any, where: str) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise NetworkError(f"{where}: {value!r} is not a number")
    x = float(value)
    if not math.isfinite(x):
        raise NetworkError(f"{where}: {value!r} is not finite")
    return x


def _in_range(value: Any, lo: float, hi: float, where: str) -> float:
    x = _number(value, where)
    if not lo <= x <= hi:
        raise NetworkError(f"{where}: {value!r} is out of range [{lo:g}, {hi:g}]")
    return x


# ---- the file schema (pydantic, docs/architecture.md) ------------------------------
# The structure, types and ranges of the YAML document, its nodes, corridors, no-fly zones and
# airspace are these models (uam_contract.validation.parse: a refusal names the path, e.g.
# ``nodes[3] (id 'W2').lat``, and the value). What needs the whole network (duplicate ids,
# corridor ends, lengths, connectivity, levels above the aerodromes, pads, zones against nodes and
# corridors) stays in the code below, after the models: geometry and graph checks, not a schema.
# Numbers are any real number (numpy scalars from GraphML too, which pydantic's strict float
# refuses), never a bool or a numeric string, as before.

def _real(value: Any) -> float:
    if isinstance(value, bool) or not isinstance(value, (int, float, np.integer, np.floating)):
        raise ValueError("is not a number")
    if not math.isfinite(float(value)):
        raise ValueError("is not finite")
    return float(value)


def _within(lo: float, hi: float):
    def check(x: float) -> float:
        if not lo <= x <= hi:
            raise ValueError(f"is out of range [{lo:g}, {hi:g}]")
        return x
    return AfterValidator(check)


def _positive_number(x: float) -> float:
    if x <= 0:
        raise ValueError("is not positive")
    return x


def _id_text(value: Any) -> str:
    if not isinstance(value, str) or not value.strip():
        raise ValueError("is not a non-empty string")
    return value


def _zone_name(value: Any) -> str:
    if not isinstance(value, str) or not value:
        raise ValueError("is not a non-empty string")
    return value


def _flag(value: Any) -> bool:
    if not isinstance(value, (bool, np.bool_)):
        raise ValueError("is not true/false")
    return bool(value)


def _label(value: Any) -> str:
    if value is None:
        return ""
    if not isinstance(value, str):
        raise ValueError("is not a string")
    return value


_Real = Annotated[Any, PlainValidator(_real)]
_Lat = Annotated[_Real, _within(-90.0, 90.0)]
_Lon = Annotated[_Real, _within(-180.0, 180.0)]
_Alt = Annotated[_Real, _within(*ALT_RANGE_M)]
_Schema = pydantic.ConfigDict(extra="forbid")


class _NodeFile(pydantic.BaseModel):
    model_config = _Schema
    id: Annotated[Any, PlainValidator(_id_text)]
    lat: _Lat
    lon: _Lon
    alt_m: _Alt
    aerodrome: Annotated[Any, PlainValidator(_flag)] = False
    name: Annotated[Any, PlainValidator(_label)] = ""
    pads_m: Any = None  # checked with the airspace (_check_airspace): needs the levels


class _CorridorFile(pydantic.BaseModel):
    model_config = _Schema
    from_: Any = pydantic.Field(alias="from")  # a node id of this network: checked after the nodes
    to: Any
    route: Any = None


class _ZoneFile(pydantic.BaseModel):
    model_config = _Schema
    name: Annotated[Any, PlainValidator(_zone_name)]
    lat: _Lat
    lon: _Lon
    radius_m: Annotated[_Real, AfterValidator(_positive_number)]


class _AirspaceFile(pydantic.BaseModel):
    model_config = _Schema
    levels_m: Any  # strictly increasing, above the aerodromes: _check_airspace
    direction_rule: Any = "semicircular"


class _NetworkFile(pydantic.BaseModel):
    """The top level of the YAML document (docs/network-format.md)."""

    model_config = _Schema
    name: Any = None
    description: Any = None
    cruise_alt_m: Any = None
    origin: Any = None  # {lat, lon, alt_m} or [lat, lon, alt_m]: _parse_origin
    no_fly_zones: Any = None
    nodes: Any
    corridors: Any
    airspace: Any = None


def _dicts(items) -> list:
    """Any mapping as a dict (pydantic reads dicts), anything else as it is (to be refused)."""
    return [dict(x) if isinstance(x, Mapping) else x for x in items]


def _node_tag(nodes):
    """The id of a node after its index in a refusal (``nodes[3] (id 'W2').lat``)."""
    def tag(loc: tuple) -> str:
        i = loc[-1]
        node = nodes[i] if isinstance(nodes, (list, tuple)) and i < len(nodes) else None
        node_id = node.get("id") if isinstance(node, Mapping) else None
        return f" (id {node_id!r})" if isinstance(node_id, str) and node_id.strip() else ""
    return tag


def _parse_origin(origin: Any, where: str = "origin") -> tuple[float, float, float]:
    if isinstance(origin, Mapping):
        unknown = set(origin) - {"lat", "lon", "alt_m"}
        if unknown:
            raise NetworkError(f"{where}: unknown field {sorted(unknown)[0]!r}")
        for key in ("lat", "lon"):
            if key not in origin:
                raise NetworkError(f"{where}.{key}: missing")
        vals = (origin["lat"], origin["lon"], origin.get("alt_m", 0.0))
    elif isinstance(origin, (list, tuple, np.ndarray)) and len(origin) in (2, 3):
        vals = (origin[0], origin[1], origin[2] if len(origin) == 3 else 0.0)
    else:
        raise NetworkError(f"{where}: {origin!r} is not {{lat, lon, alt_m}} or [lat, lon, alt_m]")
    return (_in_range(vals[0], -90.0, 90.0, f"{where}.lat"),
            _in_range(vals[1], -180.0, 180.0, f"{where}.lon"),
            _in_range(vals[2], *ALT_RANGE_M, f"{where}.alt_m"))


def build_network(name: str, nodes: list[dict], corridors: list[dict], origin=None,
                  no_fly_zones=None, airspace=None) -> Network:
    """Build and validate a network from plain dictionaries (the YAML schema).

    Args:
        name: network name.
        nodes: ``{id: str, lat: deg, lon: deg, alt_m: m, aerodrome: bool = False, name: str = ''}``
            per node, in index order.
        corridors: ``{from: id, to: id, route: str (optional, informational)}`` per undirected
            corridor.
        origin: ENU origin as ``{lat, lon, alt_m}`` or ``(lat, lon, alt_m)``; default: the mean
            latitude and longitude of the nodes at altitude 0 m.
        no_fly_zones: optional list of ``{name, lat, lon, radius_m}`` (or :class:`NoFlyZone`);
            no node may lie inside and no corridor may cross one.
        airspace: optional ``{levels_m: [m, ...], direction_rule: 'semicircular' | 'none'}``
            (a layered network); aerodrome nodes may then carry ``pads_m: [[east_m, north_m],
            ...]``.

    Returns the :class:`Network`; raises :class:`NetworkError` naming the field and the value.
    O(n + m log m).
    """
    if not isinstance(name, str) or not name:
        raise NetworkError(f"name: {name!r} is not a non-empty string")
    if not isinstance(nodes, (list, tuple)):
        raise NetworkError(f"nodes: expected a list, got {type(nodes).__name__}")
    if not isinstance(corridors, (list, tuple)):
        raise NetworkError(f"corridors: expected a list, got {type(corridors).__name__}")
    n = len(nodes)
    pads: dict = {}
    node_ids: list[str] = []
    names: list[str] = []
    aerodrome = np.zeros(n, dtype=bool)
    lla = np.zeros((n, 3))
    index: dict[str, int] = {}
    parsed = parse(list[_NodeFile], _dicts(nodes), where="nodes", error=NetworkError, tag=_node_tag(nodes))
    for i, node in enumerate(parsed):
        node_id = node.id
        if node_id in index:
            raise NetworkError(f"nodes[{i}] (id {node_id!r}).id: {node_id!r} duplicates nodes[{index[node_id]}]")
        lla[i] = (node.lat, node.lon, node.alt_m)
        aerodrome[i] = node.aerodrome
        index[node_id] = i
        node_ids.append(node_id)
        names.append(node.name)
        if "pads_m" in nodes[i]:
            pads[node_id] = nodes[i]["pads_m"]

    pairs = np.zeros((len(corridors), 2), dtype=np.int64)
    cors = parse(list[_CorridorFile], _dicts(corridors), where="corridors", error=NetworkError)
    for k, cor in enumerate(cors):
        for j, (key, ref) in enumerate((("from", cor.from_), ("to", cor.to))):
            if not isinstance(ref, str) or ref not in index:
                raise NetworkError(f"corridors[{k}].{key}: {ref!r} is not a node id")
            pairs[k, j] = index[ref]

    if n == 0:
        raise NetworkError("nodes: empty list; at least 2 aerodromes are needed")
    zones = _parse_no_fly_zones(no_fly_zones)
    if origin is None:
        origin_t = (float(lla[:, 0].mean()), float(lla[:, 1].mean()), 0.0)
    else:
        origin_t = _parse_origin(origin)
    enu = geodetic_to_enu(lla, origin_t)
    levels, rule = _parse_airspace(airspace)
    return _assemble(name, node_ids, names, aerodrome, lla, enu, origin_t, pairs, "corridors",
                     zones, levels, rule, pads)


def network_from_enu(name: str, node_ids: Sequence[str], enu_m, is_aerodrome,
                     edges_as_id_pairs: Iterable[tuple[str, str]], names: Sequence[str] | None = None,
                     origin_lat_lon_alt=DEFAULT_ENU_ORIGIN, no_fly_zones=None, airspace=None,
                     pads_m=None) -> Network:
    """Build a network straight from local ENU coordinates (synthetic networks, tests).

    Args:
        name: network name.
        node_ids: unique string ids, in index order.
        enu_m: (n, 3) east, north, up metres about ``origin_lat_lon_alt``.
        is_aerodrome: (n,) bool.
        edges_as_id_pairs: corridors as (id, id) pairs, any order.
        names: optional human names.
        origin_lat_lon_alt: geodetic origin of the ENU frame (default central Singapore).
        no_fly_zones: optional list of ``{name, lat, lon, radius_m}`` or :class:`NoFlyZone`.
        airspace, pads_m: optional levels and direction rule, and ``{aerodrome id: [[east_m,
            north_m], ...]}`` pads (a layered network, see :class:`Network`).

    The geodetic coordinates are derived from ENU (the exact inverse transform); ``enu_m`` is kept
    as given. Raises :class:`NetworkError`. O(n + m log m).
    """
    node_ids = [str(s) for s in node_ids]
    n = len(node_ids)
    enu = np.array(enu_m, dtype=np.float64)
    if enu.shape != (n, 3):
        raise NetworkError(f"enu_m: shape {enu.shape}, expected ({n}, 3)")
    bad = np.argwhere(~np.isfinite(enu))
    if len(bad):
        i = bad[0][0]
        raise NetworkError(f"enu_m[{i}] (id {node_ids[i]!r}): {enu[i].tolist()} is not finite")
    origin = _parse_origin(origin_lat_lon_alt, "origin_lat_lon_alt")
    index = {}
    for i, node_id in enumerate(node_ids):
        if not node_id:
            raise NetworkError(f"node_ids[{i}]: {node_id!r} is not a non-empty string")
        if node_id in index:
            raise NetworkError(f"node_ids[{i}]: {node_id!r} duplicates node_ids[{index[node_id]}]")
        index[node_id] = i
    pair_list = list(edges_as_id_pairs)
    pairs = np.zeros((len(pair_list), 2), dtype=np.int64)
    for k, pair in enumerate(pair_list):
        if len(pair) != 2:
            raise NetworkError(f"edges_as_id_pairs[{k}]: {pair!r} is not an (id, id) pair")
        for j in range(2):
            if pair[j] not in index:
                raise NetworkError(f"edges_as_id_pairs[{k}][{j}]: {pair[j]!r} is not a node id")
            pairs[k, j] = index[pair[j]]
    lla = enu_to_geodetic(enu, origin)
    names = [""] * n if names is None else list(names)
    levels, rule = _parse_airspace(airspace)
    return _assemble(name, node_ids, names, is_aerodrome, lla, enu, origin, pairs,
                     "edges_as_id_pairs", _parse_no_fly_zones(no_fly_zones), levels, rule, pads_m)


# -- dictionaries and files --------------------------------------------------------------------
def network_to_dict(net: Network) -> dict:
    """The YAML schema of a network as plain Python data (floats as full-precision floats)."""
    nodes = []
    for i, node_id in enumerate(net.node_ids):
        lat, lon, alt = (float(v) for v in net.lat_lon_alt[i])
        entry = {"id": node_id, "lat": lat, "lon": lon, "alt_m": alt,
                 "aerodrome": bool(net.is_aerodrome[i])}
        if net.names[i]:
            entry["name"] = net.names[i]
        nodes.append(entry)
    o = net.origin_lat_lon_alt
    d = {
        "name": net.name,
        "origin": {"lat": o[0], "lon": o[1], "alt_m": o[2]},
    }
    if net.no_fly_zones:
        d["no_fly_zones"] = _zones_to_list(net.no_fly_zones)
    if net.levels_m:
        d["airspace"] = {"levels_m": [float(v) for v in net.levels_m],
                         "direction_rule": net.direction_rule}
        for entry in nodes:
            if entry["id"] in net.pads_m:
                entry["pads_m"] = [[float(a), float(b)] for a, b in net.pads_m[entry["id"]]]
    d["nodes"] = nodes
    d["corridors"] = [{"from": net.node_ids[u], "to": net.node_ids[v]}
                      for u, v in net.edges.tolist()]
    return d


def _zones_to_list(zones: Sequence[NoFlyZone]) -> list[dict]:
    return [{"name": z.name, "lat": float(z.lat), "lon": float(z.lon),
             "radius_m": float(z.radius_m)} for z in zones]


def network_from_dict(data: Any, default_name: str = "network") -> Network:
    """Build a network from the YAML schema (see docs/network-format.md). Raises NetworkError."""
    if not isinstance(data, Mapping):
        raise NetworkError(f"document: expected a mapping with nodes and corridors, got "
                           f"{type(data).__name__}")
    parse(_NetworkFile, dict(data), error=NetworkError)  # the top-level keys
    return build_network(data.get("name", default_name), data["nodes"], data["corridors"],
                         origin=data.get("origin"), no_fly_zones=data.get("no_fly_zones"),
                         airspace=data.get("airspace"))


def _load_yaml(path: Path) -> Network:
    try:
        # the C loader (when PyYAML has it) parses a few-hundred-node file ~10x faster
        data = yaml.load(path.read_text(), Loader=getattr(yaml, "CSafeLoader", yaml.SafeLoader))
    except yaml.YAMLError as exc:
        raise NetworkError(f"{path}: not valid YAML ({exc})") from None
    return network_from_dict(data, default_name=path.stem)


def _load_geojson(path: Path) -> Network:
    try:
        doc = json.loads(path.read_text())
    except json.JSONDecodeError as exc:
        raise NetworkError(f"{path}: not valid JSON ({exc})") from None
    if not isinstance(doc, Mapping) or doc.get("type") != "FeatureCollection":
        raise NetworkError(f"type: {doc.get('type') if isinstance(doc, Mapping) else doc!r} "
                           f"is not 'FeatureCollection'")
    features = doc.get("features")
    if not isinstance(features, list):
        raise NetworkError(f"features: {features!r} is not a list")
    nodes, corridors = [], []
    for f_i, feat in enumerate(features):
        where = f"features[{f_i}]"
        if not isinstance(feat, Mapping):
            raise NetworkError(f"{where}: {feat!r} is not a feature object")
        geom = feat.get("geometry") or {}
        props = dict(feat.get("properties") or {})
        gtype = geom.get("type")
        coords = geom.get("coordinates")
        if gtype == "Point":
            if not isinstance(coords, list) or len(coords) not in (2, 3):
                raise NetworkError(f"{where}.geometry.coordinates: {coords!r} is not "
                                   f"[lon, lat] or [lon, lat, alt_m]")
            node = {"id": props.pop("id", feat.get("id")), "lon": coords[0], "lat": coords[1]}
            if "alt_m" in props:
                node["alt_m"] = props.pop("alt_m")
            elif len(coords) == 3:
                node["alt_m"] = coords[2]
            for key in ("aerodrome", "name"):
                if key in props:
                    node[key] = props.pop(key)
            if node["id"] is None:
                raise NetworkError(f"{where}.properties.id: missing")
            nodes.append(node)
        elif gtype == "LineString":
            cor = {key: props[key] for key in ("from", "to", "route") if key in props}
            for key in ("from", "to"):
                if key not in cor:
                    raise NetworkError(f"{where}.properties.{key}: missing")
            corridors.append(cor)
        else:
            raise NetworkError(f"{where}.geometry.type: {gtype!r} is not 'Point' or 'LineString'")
    return build_network(doc.get("name", path.stem), nodes, corridors, origin=doc.get("origin"),
                         no_fly_zones=doc.get("no_fly_zones"))


def _load_graphml(path: Path) -> Network:
    try:
        import networkx as nx

        g = nx.read_graphml(path)
    except Exception as exc:  # networkx raises assorted parser errors
        raise NetworkError(f"{path}: not readable as GraphML ({type(exc).__name__}: {exc})") from None
    nodes = []
    for node_id, attrs in g.nodes(data=True):
        node = {"id": str(node_id)}
        for key in ("lat", "lon", "alt_m"):
            if key in attrs:
                node[key] = attrs[key]
        if "aerodrome" in attrs:
            flag = attrs["aerodrome"]
            # GraphML booleans come back as bool; tolerate "true"/"false" strings from other tools
            if isinstance(flag, str) and flag.lower() in ("true", "false"):
                flag = flag.lower() == "true"
            node["aerodrome"] = flag
        if "name" in attrs:
            node["name"] = attrs["name"]
        nodes.append(node)
    corridors = [{"from": str(u), "to": str(v)} for u, v in g.edges()]
    origin = None
    if "origin_lat" in g.graph and "origin_lon" in g.graph:
        origin = {"lat": g.graph["origin_lat"], "lon": g.graph["origin_lon"],
                  "alt_m": g.graph.get("origin_alt_m", 0.0)}
    zones = None
    if "no_fly_zones" in g.graph:
        try:
            zones = json.loads(g.graph["no_fly_zones"])
        except (TypeError, json.JSONDecodeError):
            raise NetworkError(f"graph.no_fly_zones: {g.graph['no_fly_zones']!r} is not a JSON "
                               f"list") from None
    return build_network(str(g.graph.get("name", path.stem)), nodes, corridors, origin=origin,
                         no_fly_zones=zones)


def load_network(path) -> Network:
    """Load a network file, dispatching on the extension: .yaml/.yml, .geojson/.json, .graphml.

    Raises NetworkError (file missing, unknown extension, or invalid content naming the field).
    """
    path = Path(path)
    if not path.is_file():
        raise NetworkError(f"path: {str(path)!r} does not exist or is not a file")
    suffix = path.suffix.lower()
    if suffix in (".yaml", ".yml"):
        return _load_yaml(path)
    if suffix in (".geojson", ".json"):
        return _load_geojson(path)
    if suffix == ".graphml":
        return _load_graphml(path)
    raise NetworkError(f"path: extension {suffix!r} of {str(path)!r} is not one of "
                       f".yaml, .yml, .geojson, .json, .graphml")


def save_network_yaml(net: Network, path, header: str | None = None,
                      corridor_routes: Sequence[str] | None = None,
                      extra: Mapping[str, Any] | None = None) -> None:
    """Write the network in the YAML schema, one node or corridor per line.

    Args:
        net: the network.
        path: output file.
        header: optional text written as leading ``#`` comment lines (e.g. data sources).
        corridor_routes: optional informational route label per corridor (in ``net.edges``
            order), written as each corridor's ``route``.
        extra: optional informational top-level fields (``description``, ``cruise_alt_m``).

    Floats are written with full precision, so loading gives back the same coordinates.
    """
    d = network_to_dict(net)
    if corridor_routes is not None:
        if len(corridor_routes) != net.n_edges:
            raise NetworkError(f"corridor_routes: {len(corridor_routes)} labels for "
                               f"{net.n_edges} corridors")
        for cor, route in zip(d["corridors"], corridor_routes):
            if route:
                cor["route"] = str(route)
    lines = []
    if header:
        lines += [f"# {line}".rstrip() for line in header.splitlines()]
    dump = lambda obj: yaml.safe_dump(obj, default_flow_style=True, sort_keys=False,  # noqa: E731
                                      width=1_000_000).strip()
    lines.append(yaml.safe_dump({"name": d["name"]}, width=1_000_000).strip())
    for key, value in (extra or {}).items():
        if key not in ("description", "cruise_alt_m"):
            raise NetworkError(f"extra.{key}: not an informational top-level field")
        lines.append(yaml.safe_dump({key: value}, width=1_000_000).strip())
    lines.append(f"origin: {dump(d['origin'])}")
    if "no_fly_zones" in d:
        lines.append("no_fly_zones:")
        lines += [f"  - {dump(z)}" for z in d["no_fly_zones"]]
    if "airspace" in d:
        lines.append(f"airspace: {dump(d['airspace'])}")
    lines.append("nodes:")
    lines += [f"  - {dump(node)}" for node in d["nodes"]]
    lines.append("corridors:")
    lines += [f"  - {dump(c)}" for c in d["corridors"]]
    Path(path).write_text("\n".join(lines) + "\n")


def save_network_graphml(net: Network, path) -> None:
    """Write the network as GraphML (node key = id; attrs lat, lon, alt_m, aerodrome, name;
    edge attr length_m, informational; graph attrs name, origin_lat, origin_lon, origin_alt_m and,
    if any, no_fly_zones as a JSON string)."""
    if net.layered:
        raise NetworkError(f"save_network_graphml: network {net.name!r} is layered (levels, pads); only the "
                           f"YAML format holds those, use save_network_yaml")
    import networkx as nx

    o = net.origin_lat_lon_alt
    g = nx.Graph(name=net.name, origin_lat=o[0], origin_lon=o[1], origin_alt_m=o[2])
    if net.no_fly_zones:
        g.graph["no_fly_zones"] = json.dumps(_zones_to_list(net.no_fly_zones))
    for i, node_id in enumerate(net.node_ids):
        lat, lon, alt = (float(v) for v in net.lat_lon_alt[i])
        g.add_node(node_id, lat=lat, lon=lon, alt_m=alt, aerodrome=bool(net.is_aerodrome[i]),
                   name=net.names[i])
    for k, (u, v) in enumerate(net.edges.tolist()):
        g.add_edge(net.node_ids[u], net.node_ids[v], length_m=float(net.edge_length_m[k]))
    nx.write_graphml(g, path)


def save_network_geojson(net: Network, path) -> None:
    """Write the network as a GeoJSON FeatureCollection: a Point per node ([lon, lat, alt_m];
    properties id, name, aerodrome, alt_m) and a LineString per corridor (properties from, to,
    length_m); top-level members name, origin and (if any) no_fly_zones."""
    if net.layered:
        raise NetworkError(f"save_network_geojson: network {net.name!r} is layered (levels, pads); only the "
                           f"YAML format holds those, use save_network_yaml")
    o = net.origin_lat_lon_alt
    features = []
    for i, node_id in enumerate(net.node_ids):
        lat, lon, alt = (float(v) for v in net.lat_lon_alt[i])
        features.append({"type": "Feature", "geometry": {"type": "Point",
                                                         "coordinates": [lon, lat, alt]},
                         "properties": {"id": node_id, "name": net.names[i],
                                        "aerodrome": bool(net.is_aerodrome[i]), "alt_m": alt}})
    for k, (u, v) in enumerate(net.edges.tolist()):
        coords = [[float(net.lat_lon_alt[j, 1]), float(net.lat_lon_alt[j, 0]),
                   float(net.lat_lon_alt[j, 2])] for j in (u, v)]
        features.append({"type": "Feature", "geometry": {"type": "LineString",
                                                         "coordinates": coords},
                         "properties": {"from": net.node_ids[u], "to": net.node_ids[v],
                                        "length_m": float(net.edge_length_m[k])}})
    doc = {"type": "FeatureCollection", "name": net.name,
           "origin": {"lat": o[0], "lon": o[1], "alt_m": o[2]}}
    if net.no_fly_zones:
        doc["no_fly_zones"] = _zones_to_list(net.no_fly_zones)
    doc["features"] = features
    Path(path).write_text(json.dumps(doc, indent=1) + "\n")
