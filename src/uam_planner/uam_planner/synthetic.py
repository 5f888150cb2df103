"""Seeded synthetic corridor networks of any size, for tests, scaling studies and benchmarks.

The corridor layer is a jittered grid of way points at cruise altitude joined by the short edges of
their Delaunay triangulation (a planar, street-grid-like mesh) plus a minimum spanning tree, so it
is always connected. Aerodromes sit at ground level at random places inside the same square and
each is joined to its nearest corridor nodes, so every aerodrome reaches every other.
"""

from __future__ import annotations

import math

import numpy as np
import scipy.sparse
import scipy.sparse.csgraph
from scipy.spatial import Delaunay, QhullError, cKDTree

from uam_planner.network import DEFAULT_ENU_ORIGIN, Network, NetworkError, network_from_enu

__all__ = ["CITIES", "DEFAULT_CORRIDOR_SPACING_M", "generate_city", "generate_network"]

#: Default grid spacing of corridor way points when no extent is given, metres.
DEFAULT_CORRIDOR_SPACING_M = 750.0
#: Delaunay edges up to this multiple of the grid spacing are kept as corridors (grid edges and
#: a few diagonals); longer ones only if the spanning tree needs them.
_MAX_EDGE_FACTOR = 1.3
#: Each aerodrome gets corridors to this many nearest corridor nodes (redundant access).
_AERODROME_LINKS = 2


def _corridor_edges(xy: np.ndarray, spacing_m: float) -> np.ndarray:
    """Undirected edges (k, 2), u < v, over corridor points: short Delaunay edges + an MST."""
    n = len(xy)
    if n < 2:
        return np.zeros((0, 2), dtype=np.int64)
    try:
        if n < 3:
            raise QhullError("too few points")
        simplices = Delaunay(xy).simplices
        cand = np.concatenate([simplices[:, [0, 1]], simplices[:, [1, 2]], simplices[:, [0, 2]]])
    except QhullError:
        # Collinear or tiny inputs: a chain in x order is the planar answer.
        order = np.lexsort((xy[:, 1], xy[:, 0]))
        cand = np.stack([order[:-1], order[1:]], axis=1)
    cand = np.unique(np.sort(cand, axis=1), axis=0)
    length = np.linalg.norm(xy[cand[:, 0]] - xy[cand[:, 1]], axis=1)
    # The MST of the Delaunay graph is the Euclidean MST, so connectivity never needs a long jump
    # beyond what the triangulation offers.
    w = scipy.sparse.coo_array((length + 1e-9, (cand[:, 0], cand[:, 1])), shape=(n, n)).tocsr()
    mst = scipy.sparse.csgraph.minimum_spanning_tree(w).tocoo()
    mst_edges = np.sort(np.stack([mst.row, mst.col], axis=1), axis=1)
    keep = cand[length <= _MAX_EDGE_FACTOR * spacing_m]
    return np.unique(np.concatenate([keep, mst_edges]).astype(np.int64), axis=0)


def pad_offsets_m(n_pads: int, spacing_m: float = 150.0) -> list[list[float]]:
    """``n_pads`` pad offsets [m] (east, north) on a circle, neighbours ``spacing_m`` apart
    (one pad: [[0, 0]]; four: a square of side ``spacing_m``)."""
    if n_pads == 1:
        return [[0.0, 0.0]]
    radius = spacing_m / (2.0 * math.sin(math.pi / n_pads))
    ang = 2.0 * math.pi * np.arange(n_pads) / n_pads + math.pi / 4.0
    return [[float(radius * math.cos(a)), float(radius * math.sin(a))] for a in ang]


def _check_arguments(n_nodes, n_aerodromes, seed, pads_per_vertiport, levels_m, pad_spacing_m,
                     cruise_alt_m) -> None:
    """Raises NetworkError naming the first of :func:`generate_network`'s arguments that is
    not an integer or a positive finite number where one is needed, or out of range."""
    for label, value in (("n_nodes", n_nodes), ("n_aerodromes", n_aerodromes), ("seed", seed)):
        if isinstance(value, bool) or not isinstance(value, (int, np.integer)):
            raise NetworkError(f"{label}: {value!r} is not an integer")
    if n_aerodromes < 2:
        raise NetworkError(f"n_aerodromes: {n_aerodromes} is below the minimum 2")
    if n_nodes < n_aerodromes + 1:
        raise NetworkError(f"n_nodes: {n_nodes} must exceed n_aerodromes ({n_aerodromes}) by at "
                           f"least 1 corridor node")
    if isinstance(pads_per_vertiport, bool) or not isinstance(pads_per_vertiport, (int, np.integer)) \
            or pads_per_vertiport < 1:
        raise NetworkError(f"pads_per_vertiport: {pads_per_vertiport!r} is not an integer >= 1")
    if pads_per_vertiport > 1 and not levels_m:
        raise NetworkError(f"pads_per_vertiport: {pads_per_vertiport} pads need levels_m "
                           f"(a layered network)")
    if not (isinstance(pad_spacing_m, (int, float)) and math.isfinite(pad_spacing_m)
            and pad_spacing_m > 0):
        raise NetworkError(f"pad_spacing_m: {pad_spacing_m!r} is not a positive finite number")
    if not (isinstance(cruise_alt_m, (int, float)) and math.isfinite(cruise_alt_m)
            and cruise_alt_m > 0):
        raise NetworkError(f"cruise_alt_m: {cruise_alt_m!r} is not a positive finite number")


def _corridor_points(rng: np.random.Generator, n_corridor: int, k: int, spacing_m: float,
                     extent_m: float) -> np.ndarray:
    """The corridor way points' east/north [m]: one per cell, picked at random, of a k x k grid
    of ``spacing_m`` centred on the origin, jittered by up to 0.3 spacings."""
    cells = np.sort(rng.choice(k * k, size=n_corridor, replace=False))
    cx, cy = cells % k, cells // k
    jitter = rng.uniform(-0.3, 0.3, size=(n_corridor, 2))
    return (np.stack([cx, cy], axis=1) + 0.5 + jitter) * spacing_m - extent_m / 2.0


def _aerodrome_access(rng: np.random.Generator, xy: np.ndarray, n_aerodromes: int,
                      extent_m: float) -> tuple[np.ndarray, np.ndarray]:
    """The aerodromes' east/north [m], uniform over the square, and their access corridors
    (aerodrome index, node index) to the nearest corridor way points (numbered after them)."""
    a_xy = rng.uniform(-extent_m / 2.0, extent_m / 2.0, size=(n_aerodromes, 2))
    n_links = min(_AERODROME_LINKS, len(xy))
    _, nearest = cKDTree(xy).query(a_xy, k=n_links)
    nearest = np.asarray(nearest).reshape(n_aerodromes, n_links)
    access = np.stack([np.repeat(np.arange(n_aerodromes), n_links),
                       nearest.reshape(-1) + n_aerodromes], axis=1)
    return a_xy, access


def generate_network(n_nodes: int, n_aerodromes: int, seed: int, extent_m: float | None = None,
                     cruise_alt_m: float = 120.0, name: str | None = None,
                     origin_lat_lon_alt=DEFAULT_ENU_ORIGIN, levels_m=None,
                     direction_rule: str = "semicircular", pads_per_vertiport: int = 1,
                     pad_spacing_m: float = 150.0) -> Network:
    """Generate a random, connected, planar-ish corridor network.

    Args:
        n_nodes: total number of nodes, aerodromes included (>= n_aerodromes + 1).
        n_aerodromes: number of aerodromes (>= 2), at ground level (up = 0 m).
        seed: seed for ``numpy.random.default_rng``; the same arguments give the same network.
        extent_m: side of the square area, metres, centred on the ENU origin; default
            ``750 m * ceil(sqrt(n_nodes - n_aerodromes))``, which gives corridors of about
            0.75-0.9 km on average.
        cruise_alt_m: altitude of the corridor way points, metres.
        name: network name; default ``synthetic-n{n_nodes}-a{n_aerodromes}-s{seed}``.
        origin_lat_lon_alt: geodetic origin of the ENU frame (default central Singapore).
        levels_m: cruise levels [m] (e.g. [60, 90, 120, 150]) for a layered network (vertiports
            as terminals, see :class:`Network`); default None, the paper's single cruise
            altitude.
        direction_rule: the layered network's rule (``semicircular`` or ``none``).
        pads_per_vertiport: pads per aerodrome (layered only), on a circle with neighbours
            ``pad_spacing_m`` [m] apart (see :func:`pad_offsets_m`).

    Returns a :class:`Network` whose first ``n_aerodromes`` nodes are the aerodromes
    (ids ``A000``...) followed by the corridor way points (ids ``N0000``...). Corridor way points
    are placed one per cell of a jittered k x k grid (k = ceil(sqrt(corridor nodes)), cells picked
    at random when not all are needed) and joined by Delaunay edges up to 1.3 grid spacings plus a
    Euclidean minimum spanning tree; each aerodrome is joined to its 2 nearest corridor nodes.
    Raises NetworkError on bad arguments. O(n log n).
    """
    _check_arguments(n_nodes, n_aerodromes, seed, pads_per_vertiport, levels_m, pad_spacing_m,
                     cruise_alt_m)
    n_corridor = int(n_nodes - n_aerodromes)
    k = max(1, math.ceil(math.sqrt(n_corridor)))
    if extent_m is None:
        extent_m = DEFAULT_CORRIDOR_SPACING_M * k
    if not (isinstance(extent_m, (int, float)) and math.isfinite(extent_m) and extent_m > 0):
        raise NetworkError(f"extent_m: {extent_m!r} is not a positive finite number")
    spacing_m = float(extent_m) / k
    rng = np.random.default_rng(seed)
    xy = _corridor_points(rng, n_corridor, k, spacing_m, extent_m)
    corridor_edges = _corridor_edges(xy, spacing_m) + n_aerodromes
    a_xy, access = _aerodrome_access(rng, xy, n_aerodromes, extent_m)

    enu = np.zeros((n_nodes, 3))
    enu[:n_aerodromes, :2] = a_xy
    enu[n_aerodromes:, :2] = xy
    enu[n_aerodromes:, 2] = cruise_alt_m
    width_a = max(3, len(str(n_aerodromes - 1)))
    width_n = max(4, len(str(n_corridor - 1)))
    ids = [f"A{i:0{width_a}d}" for i in range(n_aerodromes)] + \
          [f"N{i:0{width_n}d}" for i in range(n_corridor)]
    is_aerodrome = np.zeros(n_nodes, dtype=bool)
    is_aerodrome[:n_aerodromes] = True
    edges = np.concatenate([access, corridor_edges])
    pairs = [(ids[u], ids[v]) for u, v in edges.tolist()]
    airspace = pads = None
    if levels_m:
        airspace = {"levels_m": list(levels_m), "direction_rule": direction_rule}
        offsets = pad_offsets_m(int(pads_per_vertiport), float(pad_spacing_m))
        pads = {ids[i]: offsets for i in range(n_aerodromes)} if pads_per_vertiport > 1 else None
    default = f"synthetic-n{n_nodes}-a{n_aerodromes}-s{seed}" + ("-layered" if levels_m else "")
    return network_from_enu(name or default, ids, enu, is_aerodrome, pairs,
                            origin_lat_lon_alt=origin_lat_lon_alt, airspace=airspace,
                            pads_m=pads)


#: Named synthetic cities: :func:`generate_network`'s arguments but the seed.
#: - ``layered-city``: the benchmarks' and studies' city (2,000 nodes, 100 vertiports, 4
#:   levels, 4 pads; 33 km across). Its en-route capacity, not its vertiports, binds: about
#:   3,000 requests/h at 95 % approvals, 28 % approved at 30,000/h (BENCHMARKS.md).
#: - ``city-30k``: an airspace sized for 30,000 requests/h (docs/airspace.md, "A city sized for
#:   the demand": how its size was found and the approvals it sustains).
CITIES: dict[str, dict] = {
    "layered-city": dict(n_nodes=2000, n_aerodromes=100, levels_m=[60.0, 90.0, 120.0, 150.0],
                         pads_per_vertiport=4),
    # 16.5 km across, 1,000 vertiports of 8 pads, 24 levels 30 m apart (60-750 m): 91 % of the
    # requests decided at steady state approved at 30,000/h, ~8,600 airborne
    "city-30k": dict(n_nodes=2000, n_aerodromes=1000, extent_m=16500.0,
                     levels_m=[60.0 + 30.0 * k for k in range(24)], pads_per_vertiport=8),
}


def generate_city(name: str, seed: int = 0) -> Network:
    """The named synthetic city of :data:`CITIES` with ``seed``; NetworkError for an unknown
    name (naming the known ones)."""
    if name not in CITIES:
        raise NetworkError(f"city: {name!r} is not one of {sorted(CITIES)}")
    spec = CITIES[name]
    return generate_network(seed=seed, name=f"{name}-s{seed}", **spec)


def _benchmark(argv=None) -> int:
    """Print a table of generation times: ``python -m uam_planner.synthetic [sizes...]``."""
    import argparse
    import time

    ap = argparse.ArgumentParser(description="Time generate_network for several sizes.")
    ap.add_argument("sizes", nargs="*", type=int, default=[100, 500, 2000, 5000, 10000])
    ap.add_argument("--repeat", type=int, default=3, help="runs per size; the median is shown")
    args = ap.parse_args(argv)
    print(f"{'nodes':>7} {'aerodromes':>10} {'corridors':>9} {'mean corridor m':>15} "
          f"{'build ms (median)':>17}")
    for n in args.sizes:
        n_a = max(2, n // 50)
        times = []
        for r in range(args.repeat):
            t0 = time.perf_counter()
            net = generate_network(n, n_a, seed=r)
            times.append(time.perf_counter() - t0)
        corridor = ~net.is_aerodrome[net.edges].any(axis=1)
        print(f"{n:>7} {n_a:>10} {net.n_edges:>9} {net.edge_length_m[corridor].mean():>15.0f} "
              f"{1000 * float(np.median(times)):>17.1f}")
    return 0


if __name__ == "__main__":
    raise SystemExit(_benchmark())
