"""Candidate routes by penalised Dijkstra (framework step 2).

For a request from origin o to destination d: find the shortest path, then add
``penalty_factor`` x the ORIGINAL length to every corridor that path used and search again; k
searches in all, duplicate paths dropped. Each route keeps its true (unpenalised) length d, and
its MWIS weight is w = d* / d with d* the shortest length, so the shortest route has w = 1 and
every weight lies in (0, 1].

Routes depend only on (o, d), the network and (k, penalty_factor), never on time, so
``CandidateCache`` computes them once per pair and also keeps each route's waypoint positions and
relative waypoint times at the cruise speed, so a trajectory departing at t is one addition.

Layered networks (``Network.levels_m`` declared; the paper's model otherwise):

- vertiports are terminals: the route search blocks every corridor that touches an aerodrome
  other than the request's origin and destination, so no route passes through one;
- each route is flown at one cruise level (level changes happen only at vertiports, i.e. a
  flight keeps its level from the top of its climb to the start of its descent), taken from the
  levels that the network's direction rule allows for the flight's track (bearing from origin
  to destination): ``semicircular`` gives tracks in [0, 180) degrees the levels of even index,
  the others those of odd index; ``none`` allows every level;
- a flight climbs vertically from a pad of its origin to its level at ``climb_rate_mps``, cruises
  at ``speed_mps`` from the pad to the corridor nodes of its route and on to a pad of its
  destination, and descends vertically at ``descent_rate_mps``. The pad of a candidate at level
  index i is pad i mod (number of pads) at each end, so flights to different levels leave from
  different pads where a vertiport has several;
- z is the altitude above the reference surface (the level's value, the aerodrome's ``alt_m``),
  not ENU up, so two levels are exactly their difference apart everywhere (ENU up would add the
  Earth's curvature, up to 8 m at 10 km, and break exact vertical separation).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from uam_contract import defaults
import scipy.sparse
from scipy.sparse.csgraph import dijkstra

from .trajectory import DEFAULT_SPEED_MPS, Trajectory, relative_times_s


@dataclass(frozen=True, slots=True)
class CandidateRoute:
    """One candidate route of a request.

    Attributes:
        node_indices: route as network node indices, origin first.
        length_m: true (unpenalised) route length [m].
        weight: MWIS weight d*/d in (0, 1]; 1 for the shortest route.
        candidate_index: position among the request's candidates (0 = shortest).
    """

    node_indices: tuple[int, ...]
    length_m: float
    weight: float
    candidate_index: int


DEFAULT_CLIMB_RATE_MPS = defaults.CLIMB_RATE_MPS        # the one source: uam_contract.defaults
DEFAULT_DESCENT_RATE_MPS = defaults.DESCENT_RATE_MPS
AVOID_COST_M = 1e7  # extra cost of an avoided corridor in a re-planning search


class _PenalisedGraph:
    """A directed CSR copy of the network whose corridor costs can be raised per search."""

    def __init__(self, network):
        n = network.n_nodes
        edges = np.asarray(network.edges, dtype=np.int64)
        m = edges.shape[0]
        rows = np.concatenate((edges[:, 0], edges[:, 1]))
        cols = np.concatenate((edges[:, 1], edges[:, 0]))
        order = np.lexsort((cols, rows))
        self.length = np.asarray(network.edge_length_m, dtype=np.float64)
        self.indptr = np.concatenate(([0], np.cumsum(np.bincount(rows, minlength=n)))).astype(np.int32)
        self.indices = cols[order].astype(np.int32)
        self.entry_edge = np.concatenate((np.arange(m), np.arange(m)))[order]
        # position of every directed entry in CSR order; edge e sits at pos[e] and pos[m + e]
        pos = np.empty(2 * m, dtype=np.int64)
        pos[order] = np.arange(2 * m)
        self.pos_fwd = pos[:m]
        self.pos_bwd = pos[m:]
        self.n = n
        self._mat = None
        self._network = network

    def matrix(self, cost: np.ndarray) -> scipy.sparse.csr_matrix:
        """The CSR matrix with corridor costs ``cost`` (m,); reuses one matrix object."""
        if self._mat is None:
            self._mat = scipy.sparse.csr_matrix(
                (cost[self.entry_edge], self.indices, self.indptr), shape=(self.n, self.n))
        else:
            self._mat.data[:] = cost[self.entry_edge]
        return self._mat

    def path_edges(self, path: list[int]) -> np.ndarray:
        """The corridor indices along ``path`` (node indices), in order."""
        p = np.asarray(path, dtype=np.int64)
        return self._network.edge_indices(p[:-1], p[1:])


def _validate_k_penalty(k, penalty_factor):
    if isinstance(k, bool) or not isinstance(k, (int, np.integer)) or k < 1:
        raise ValueError(f"k must be an integer >= 1, got {k!r}")
    if not (np.isfinite(penalty_factor) and penalty_factor >= 0.0):
        raise ValueError(f"penalty_factor must be finite and >= 0, got {penalty_factor!r}")


def _routes(graph: _PenalisedGraph, network, o: int, d: int, k: int,
            penalty_factor: float, terminals: bool = False,
            blocked: np.ndarray | None = None) -> list[CandidateRoute]:
    """``blocked``: optional (m,) bool, corridors to avoid (re-planning around a constraint,
    ``uam_planner.replanning``): each costs ``AVOID_COST_M`` more, so a route takes one only
    where there is no other way (e.g. to leave a zone before it opens; the exact test decides)."""
    cost = graph.length.copy()
    if blocked is not None:
        cost[blocked] += AVOID_COST_M
    if terminals:
        # Vertiports are terminals: corridors touching any other aerodrome are closed.
        other = network.is_aerodrome.copy()
        other[[o, d]] = False
        cost[other[network.edges[:, 0]] | other[network.edges[:, 1]]] = np.inf
    seen: set[tuple[int, ...]] = set()
    paths: list[tuple[tuple[int, ...], float]] = []
    limit = np.inf
    found: list[np.ndarray] = []
    for _ in range(int(k)):
        # After the first search, the penalised cost of a route already found bounds the new
        # optimum, so the search may stop there (same result, fewer nodes settled).
        _, pred = dijkstra(graph.matrix(cost), directed=True, indices=o, return_predecessors=True,
                           limit=limit)
        if pred[d] < 0:
            via = " without passing through another vertiport" if terminals else ""
            raise ValueError(f"destination node {network.node_ids[d]!r} is unreachable from "
                             f"origin {network.node_ids[o]!r}{via}")
        path = [d]
        while path[-1] != o:
            path.append(int(pred[path[-1]]))
        path.reverse()
        used = graph.path_edges(path)
        key = tuple(path)
        if key not in seen:
            seen.add(key)
            paths.append((key, float(graph.length[used].sum())))
        cost[used] += penalty_factor * graph.length[used]
        found.append(used)
        limit = min(float(cost[u].sum()) for u in found) * (1.0 + 1e-9) + 1e-6
    d_star = paths[0][1]
    return [CandidateRoute(p, length, d_star / length, i) for i, (p, length) in enumerate(paths)]


def candidate_routes(network, origin_id: str, destination_id: str, k: int = 5,
                     penalty_factor: float = 5.0) -> list[CandidateRoute]:
    """Up to k distinct candidate routes from ``origin_id`` to ``destination_id``.

    Args:
        network: a ``uam_planner.network.Network``.
        origin_id, destination_id: node ids (distinct).
        k: number of penalised Dijkstra searches (routes after dropping duplicates: 1..k).
        penalty_factor: after each search, each used corridor's cost grows by this times its length.
    Returns: routes in search order; the first is a shortest route (weight 1).
    Complexity: k Dijkstra searches, O(k (m + n log n)). Ties are broken deterministically (same
    network, same routes), by scipy's Dijkstra on the fixed CSR order of the corridors.
    """
    _validate_k_penalty(k, penalty_factor)
    o = network.node_index(origin_id)
    d = network.node_index(destination_id)
    if o == d:
        raise ValueError(f"origin_id and destination_id are the same node {origin_id!r}")
    return _routes(_PenalisedGraph(network), network, o, d, k, penalty_factor,
                   terminals=network.layered)


@dataclass(frozen=True, slots=True)
class RouteTemplate:
    """A candidate route ready to fly: waypoints and times relative to departure.

    ``segments_rel`` holds (t0_s, t1_s, p0_m, v_mps) with times relative to departure.
    In a layered network ``level_index`` / ``level_m`` give the cruise level (index into
    ``Network.levels_m`` and its altitude [m]) and the waypoints include the vertical climb and
    descent at the pads; in the paper's model they are -1 and nan.
    """

    route: CandidateRoute
    node_ids: tuple[str, ...]
    points_m: np.ndarray
    rel_times_s: np.ndarray
    segments_rel: tuple
    level_index: int = -1
    level_m: float = float("nan")

    @property
    def duration_s(self) -> float:
        return float(self.rel_times_s[-1])

    def trajectory(self, departure_s: float) -> Trajectory:
        """The trajectory departing at ``departure_s`` [s]."""
        _, _, p0, v = self.segments_rel
        dep = float(departure_s)
        if not np.isfinite(dep):
            raise ValueError(f"departure_s must be finite, got {departure_s!r}")
        times = self.rel_times_s + dep
        times.setflags(write=False)
        # The template was validated when cached; only the time shift is new.
        return Trajectory._trusted(times, self.points_m, (times[:-1], times[1:], p0, v))


class CandidateCache:
    """Candidate routes per (origin, destination) pair, computed once.

    Args:
        network: the ``Network``.
        k, penalty_factor: as in :func:`candidate_routes`.
        speed_mps: cruise speed [m/s] used for the templates' relative times.

    ``templates(o_idx, d_idx)`` returns the tuple of RouteTemplate for node indices o, d; the
    first call for a pair costs k Dijkstra searches, later calls a dict lookup. ``hits`` and
    ``misses`` count lookups.
    """

    def __init__(self, network, k: int = 5, penalty_factor: float = 5.0,
                 speed_mps: float = DEFAULT_SPEED_MPS,
                 climb_rate_mps: float = DEFAULT_CLIMB_RATE_MPS,
                 descent_rate_mps: float = DEFAULT_DESCENT_RATE_MPS):
        _validate_k_penalty(k, penalty_factor)
        for name, v in (("speed_mps", speed_mps), ("climb_rate_mps", climb_rate_mps),
                        ("descent_rate_mps", descent_rate_mps)):
            if not (np.isfinite(v) and v > 0.0):
                raise ValueError(f"{name} must be positive and finite, got {v!r}")
        self.climb_rate_mps = float(climb_rate_mps)
        self.descent_rate_mps = float(descent_rate_mps)
        self.network = network
        self.k = int(k)
        self.penalty_factor = float(penalty_factor)
        self.speed_mps = float(speed_mps)
        self._graph = _PenalisedGraph(network)
        self._store: dict[tuple[int, int], tuple[RouteTemplate, ...]] = {}
        self.hits = 0
        self.misses = 0

    def __len__(self) -> int:
        return len(self._store)

    def precompute(self, pairs=None) -> int:
        """Fill the cache for ``pairs`` of (origin, destination) node indices (default: every
        ordered pair of distinct aerodromes, a(a-1) pairs of k searches each). Returns the number
        of pairs computed now. Use at start-up so that no epoch pays for a route search."""
        if pairs is None:
            ai = [int(i) for i in self.network.aerodrome_indices]
            pairs = [(o, d) for o in ai for d in ai if o != d]
        before = self.misses
        for o, d in pairs:
            self.templates(o, d)
        return self.misses - before

    def routes(self, origin_index: int, destination_index: int) -> list[CandidateRoute]:
        return [t.route for t in self.templates(origin_index, destination_index)]

    def templates(self, origin_index: int, destination_index: int) -> tuple[RouteTemplate, ...]:
        key = (int(origin_index), int(destination_index))
        got = self._store.get(key)
        if got is not None:
            self.hits += 1
            return got
        self.misses += 1
        if key[0] == key[1]:
            raise ValueError(f"origin and destination are the same node "
                             f"{self.network.node_ids[key[0]]!r}")
        routes = _routes(self._graph, self.network, key[0], key[1], self.k, self.penalty_factor,
                         terminals=self.network.layered)
        if self.network.layered:
            got = tuple(self._layered(key[0], key[1], routes))
            self._store[key] = got
            return got
        out = []
        for r in routes:
            pts = np.ascontiguousarray(self.network.enu_m[np.asarray(r.node_indices)], dtype=np.float64)
            rel = relative_times_s(pts, self.speed_mps)
            t0 = rel[:-1]
            t1 = rel[1:]
            v = (pts[1:] - pts[:-1]) / (t1 - t0)[:, None]
            for a in (pts, rel, v):
                a.setflags(write=False)
            out.append(RouteTemplate(r, tuple(self.network.node_ids[i] for i in r.node_indices),
                                     pts, rel, (t0, t1, pts[:-1], v)))
        got = tuple(out)
        self._store[key] = got
        return got

    def allowed_levels(self, origin_index: int, destination_index: int) -> list[int]:
        """Indices into ``levels_m`` that the direction rule gives the flight's track."""
        net = self.network
        n = len(net.levels_m)
        if net.direction_rule == "none":
            return list(range(n))
        d = net.enu_m[destination_index, :2] - net.enu_m[origin_index, :2]
        track_deg = float(np.degrees(np.arctan2(d[0], d[1]))) % 360.0
        first = 0 if track_deg < 180.0 else 1
        return list(range(first, n, 2))

    def _layered(self, o: int, d: int, routes) -> list[RouteTemplate]:
        """One template per (allowed level, route), level-major: pad climb, cruise, pad descent.

        Each route's templates for all its levels are built at once, as rows of (levels, points)
        arrays, and each template holds read-only views of its row: a pair of a large city has
        up to 12 levels x 5 routes, and one numpy call per template made this function three
        quarters of a route search's CPU. The arithmetic is the same per element as one template
        at a time (same differences, norms of two terms, sequential cumulative sums)."""
        net = self.network
        xy = net.enu_m[:, :2]
        alt = net.lat_lon_alt[:, 2]
        pads_o, pads_d = net.pads_of(o), net.pads_of(d)
        lis = np.asarray(self.allowed_levels(o, d), dtype=np.int64)
        levels = np.asarray(net.levels_m, dtype=np.float64)[lis]
        n_l = len(lis)
        po = xy[o] + pads_o[lis % len(pads_o)]
        pd = xy[d] + pads_d[lis % len(pads_d)]
        climb = (levels - alt[o]) / self.climb_rate_mps
        descent = (levels - alt[d]) / self.descent_rate_mps
        blocks = []
        for r in routes:
            mid = xy[np.asarray(r.node_indices[1:-1], dtype=np.int64)].reshape(-1, 2)
            n_h = mid.shape[0] + 2
            pts = np.empty((n_l, n_h + 2, 3), dtype=np.float64)
            pts[:, 0, :2] = po
            pts[:, 0, 2] = alt[o]
            pts[:, 1, :2] = po
            pts[:, 2:n_h, :2] = mid
            pts[:, n_h, :2] = pd
            pts[:, 1:n_h + 1, 2] = levels[:, None]
            pts[:, n_h + 1, :2] = pd
            pts[:, n_h + 1, 2] = alt[d]
            legs = np.linalg.norm(np.diff(pts[:, 1:n_h + 1, :2], axis=1), axis=2)
            if np.any(legs <= 0.0):
                raise ValueError(f"route {[net.node_ids[i] for i in r.node_indices]} has a pad "
                                 f"on a corridor node (zero-length leg)")
            dur = np.empty((n_l, n_h + 1), dtype=np.float64)
            dur[:, 0] = climb
            dur[:, 1:n_h] = legs / self.speed_mps
            dur[:, n_h] = descent
            rel = np.zeros((n_l, n_h + 2), dtype=np.float64)
            np.cumsum(dur, axis=1, out=rel[:, 1:])
            v = np.diff(pts, axis=1) / np.diff(rel, axis=1)[:, :, None]
            for a in (pts, rel, v):
                a.setflags(write=False)
            blocks.append((r, tuple(net.node_ids[i] for i in r.node_indices), pts, rel, v))
        return [RouteTemplate(r, ids, pts[j], rel[j], (rel[j, :-1], rel[j, 1:], pts[j, :-1], v[j]),
                              int(lis[j]), float(levels[j]))
                for j in range(n_l) for r, ids, pts, rel, v in blocks]
