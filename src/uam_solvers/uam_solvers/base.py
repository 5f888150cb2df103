"""The one interface every MWIS backend keeps.

A maximum weighted independent set (MWIS) problem is a conflict graph: a float64 weight per
vertex (a candidate route, w = d*/d in the paper), int32 edge pairs (conflicts between candidates
of different requests) and optional clique groups (the candidates of one request: at most one of
them may be selected). A backend takes a validated :class:`MwisProblem`, a time limit, a seed and
its own options and returns an :class:`MwisResult`.

Nothing here imports rclpy; the solver node converts messages to these types.
"""
from __future__ import annotations

import itertools
import math
from abc import ABC, abstractmethod
from dataclasses import dataclass, field
from functools import cached_property
from typing import Any, Iterable, Mapping, Sequence

import numpy as np
import scipy.sparse as sp

from .errors import BackendUnavailable, MwisInputError  # re-exported: the library's public errors

try:  # scipy's stable counting sort of COO entries by row (what coo_matrix.tocsr() runs)
    from scipy.sparse._sparsetools import coo_tocsr as _coo_tocsr
except ImportError:  # pragma: no cover - a scipy without it: the numpy argsort path
    _coo_tocsr = None

__all__ = [
    "MwisInputError",
    "MwisProblem",
    "MwisResult",
    "Backend",
    "BackendUnavailable",
    "check_selection",
    "integer_weights",
    "integer_proof_holds",
    "make_result",
    "brute_force_mwis",
    "induced_subproblem",
]


#: Largest total weight accepted: objectives are float64 sums (max ~1.8e308).
MAX_TOTAL_WEIGHT = 1e300



def _show(value: Any) -> str:
    """A caller's index value as they gave it (a Python int or float, never a wrapped int64)."""
    return repr(value.item() if isinstance(value, np.generic) else value)


def _asarray_exact(values: Any) -> np.ndarray:
    """``np.asarray(values)``, except that a list holding Python ints beyond int64 (which numpy
    turns into float64, losing digits) becomes an object array of the caller's exact values."""
    arr = np.asarray(values)
    if arr.dtype.kind == "f" and not isinstance(values, np.ndarray) and arr.size:
        with np.errstate(invalid="ignore"):
            big = np.abs(arr) >= 2.0**63
        if big.any():
            exact = np.asarray(values, dtype=object)
            if exact.shape == arr.shape:
                return exact
    return arr


def _index_values(arr: np.ndarray, field_name: str, n: int) -> tuple[np.ndarray, np.ndarray]:
    """``(idx, bad)`` for an array of vertex indices of any shape: ``idx`` the int64 values
    (0 where bad), ``bad`` True where a value is not an integer in [0, n). The range is checked
    in the array's own dtype (uint64 and floats beyond int64 never wrap, no numpy
    RuntimeWarning); Python ints of any size in an object array are checked exactly.
    Raises MwisInputError for a dtype that holds no integers."""
    kind = arr.dtype.kind
    if kind == "O":
        flat = arr.reshape(-1).tolist()
        ok = np.fromiter((isinstance(v, (int, np.integer)) and not isinstance(v, bool)
                          and 0 <= int(v) < n for v in flat), dtype=bool, count=len(flat))
        notint = [i for i, v in enumerate(flat)
                  if not isinstance(v, (int, np.integer, float, np.floating))]
        if notint:
            v = flat[notint[0]]
            raise MwisInputError(f"{field_name}: {v!r} is not a vertex index")
        fl = [float(v) for v in flat]  # floats among ints: integral ones in range are fine
        for i, v in enumerate(flat):
            if not ok[i] and isinstance(v, (float, np.floating)) and math.isfinite(v) \
                    and v == round(v) and 0 <= v < n:
                ok[i] = True
        idx = np.array([int(x) if ok[i] else 0 for i, x in enumerate(fl)], dtype=np.int64)
        return idx.reshape(arr.shape), ~ok.reshape(arr.shape)
    if kind == "f":
        with np.errstate(invalid="ignore"):
            bad = ~np.isfinite(arr) | (arr != np.round(arr)) | (arr < 0) | (arr >= n)
        idx = np.where(bad, 0, arr).astype(np.int64)
        return idx, bad
    if kind == "u":
        bad = arr >= n
        return np.where(bad, 0, arr).astype(np.int64), bad
    if kind in "ib":
        idx = arr.astype(np.int64)
        return idx, (idx < 0) | (idx >= n)
    raise MwisInputError(f"{field_name}: expected integer vertex indices, got dtype {arr.dtype}")


def _index_reason(value: Any, n: int) -> str:
    """Why one vertex index value is bad, in the caller's own terms."""
    if isinstance(value, (float, np.floating)) and (not math.isfinite(value)
                                                    or value != round(value)):
        return f"{value!r} is not an integer vertex index"
    return f"vertex {_show(value)} is out of range [0, {n})"


def _as_index_array(values: Any, field_name: str, n: int) -> np.ndarray:
    """Return ``values`` as a 1-D int64 array of vertex indices in [0, n), or raise MwisInputError
    naming the first bad element with the caller's value."""
    arr = np.asarray(values)
    if arr.size == 0:
        return np.zeros(0, dtype=np.int64)
    if arr.ndim != 1:
        raise MwisInputError(f"{field_name}: expected a 1-D index array, got shape {arr.shape}")
    idx, bad = _index_values(arr, field_name, n)
    if bad.any():
        i = int(np.flatnonzero(bad)[0])
        raise MwisInputError(f"{field_name}[{i}]: {_index_reason(arr[i], n)}")
    return idx


def _checked_weights(weights: Any, max_vertices: int | None) -> np.ndarray:
    """``weights`` as a 1-D float64 array; raises MwisInputError naming the first weight that is
    not finite or negative, a size over ``max_vertices``, or a total that could overflow."""
    try:
        w = np.asarray(weights, dtype=np.float64)
    except (TypeError, ValueError) as exc:
        raise MwisInputError(f"weights: not numeric ({exc})") from None
    if w.ndim != 1:
        raise MwisInputError(f"weights: expected a 1-D array, got shape {w.shape}")
    n = int(w.shape[0])
    if max_vertices is not None and n > max_vertices:
        raise MwisInputError(f"weights: {n} vertices exceed the limit max_vertices={max_vertices}")
    if n:
        i = int(np.argmax(w))  # (a NaN is its own maximum: it fails the test below)
        wmax = float(w[i])
    # all finite and >= 0 (a NaN fails both comparisons): one reduction and the maximum;
    # otherwise the passes below name the first bad weight (~3 us of a small solve)
    if n and not (float(w.min()) >= 0.0 and math.isfinite(wmax)):
        bad = ~np.isfinite(w)
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise MwisInputError(f"weights[{i}]: {float(w[i])!r} is not finite")
        bad = w < 0
        if bad.any():
            i = int(np.flatnonzero(bad)[0])
            raise MwisInputError(f"weights[{i}]: {float(w[i])!r} is negative")
    if n:
        # Objectives are float64 sums: refuse weights whose total could overflow (scaled
        # sum, so the check itself cannot overflow).
        if wmax > 0 and wmax * float(np.sum(w / wmax)) > MAX_TOTAL_WEIGHT:
            raise MwisInputError(
                f"weights[{i}]: {wmax!r} is too large: the total weight must stay below "
                f"{MAX_TOTAL_WEIGHT:g} (rescale the weights)")
    return w


def _normalised_keys(e: np.ndarray, n: int) -> np.ndarray | None:
    """The keys u * n + v [int64] of integer edges ``e`` that are already normalised (in range,
    u < v, strictly increasing keys), else None (the edges need the full checks)."""
    keys = None
    if e.dtype.kind in "iu" and e.shape[0] and n < 2**31:
        # already normalised (the planner's edges, every MwisProblem's own): in range, u < v
        # and strictly increasing keys u * n + v (sorted, unique; u[0] >= 0 then bounds
        # every u), checked in the caller's dtype; the keys are kept for the CSR, the
        # listed-groups check and the triangle gate (~4 passes over the pairs
        # instead of ~15)
        u, v = e[:, 0], e[:, 1]
        if int(u[0]) >= 0 and int(v.max()) < n and bool((u < v).all()):
            keys = u.astype(np.int64) * n + v.astype(np.int64)
            if keys.size > 1 and not bool((keys[1:] > keys[:-1]).all()):
                keys = None
    return keys


def _checked_edges(e: np.ndarray, n: int) -> np.ndarray:
    """Edges ``e`` (m, 2) as int64 vertex indices; raises MwisInputError naming the first pair
    that is not integer, has a vertex outside [0, n) or is a self-loop."""
    if e.dtype.kind == "i" and e.size and int(e.min()) >= 0 and int(e.max()) < n:
        # signed integers all in range (the planner's edges): nothing to report, so no
        # per-element mask (two reductions instead of four array passes)
        e64, bad = e.astype(np.int64, copy=False), None
    else:
        e64, bad2 = _index_values(e, "edges", n)
        bad = bad2.any(axis=1)
    if bad is not None and bad.any():
        i = int(np.flatnonzero(bad)[0])
        pair = repr(tuple(e[i].tolist()))
        if e.dtype.kind in "fO" and any(
                isinstance(v, (float, np.floating)) and (not math.isfinite(v) or v != round(v))
                for v in e[i].tolist()):
            raise MwisInputError(f"edges[{i}]: {pair} is not a pair of integer vertex indices")
        raise MwisInputError(f"edges[{i}]: {pair} has a vertex out of range [0, {n})")
    loops = e64[:, 0] == e64[:, 1]
    if loops.any():
        i = int(np.flatnonzero(loops)[0])
        raise MwisInputError(f"edges[{i}]: ({int(e64[i, 0])}, {int(e64[i, 1])}) is a self-loop")
    return e64


@dataclass(frozen=True, eq=False)
class MwisProblem:
    """A validated MWIS instance (a conflict graph).

    Attributes:
        weights: (n,) float64 vertex weights, finite and >= 0.
        edges: (m, 2) int32 conflict pairs with u < v, unique, sorted lexicographically.
        groups: clique groups (int32 vertex-index arrays, sorted, unique, size >= 2); every pair
            inside a group conflicts even when it is not listed in ``edges``.

    Build it with :meth:`from_arrays`, which validates and normalises; the constructor trusts its
    arguments.
    """

    weights: np.ndarray
    edges: np.ndarray
    groups: tuple[np.ndarray, ...] = ()

    @classmethod
    def from_arrays(
        cls,
        weights: Any,
        edges: Any,
        groups: Sequence[Any] | None = None,
        max_vertices: int | None = None,
    ) -> "MwisProblem":
        """Validate and normalise arrays into a problem.

        Inputs: ``weights`` (n,) numbers, finite and >= 0; ``edges`` (m, 2) vertex indices in
        [0, n) without self-loops (duplicates and order are normalised to unique u < v);
        ``groups`` an optional sequence of vertex-index sequences (clique groups; duplicates
        inside a group are dropped, groups of fewer than two vertices add nothing);
        ``max_vertices`` an optional size limit on n.
        Raises :class:`MwisInputError` naming the field and value. O(m log m + sum |group|).
        """
        w = _checked_weights(weights, max_vertices)
        n = int(w.shape[0])
        e = _edge_array(edges)
        if e.size == 0:
            e = np.zeros((0, 2), dtype=np.int64)
        if e.ndim != 2 or e.shape[1] != 2:
            raise MwisInputError(f"edges: expected shape (m, 2), got {e.shape}")
        keys = _normalised_keys(e, n)
        if keys is not None:
            gs = _normalise_groups(groups, n)
            problem = cls(weights=w, edges=e.astype(np.int32), groups=tuple(gs))
            keys.setflags(write=False)
            problem.__dict__["_listed_keys"] = keys  # (cached_property's slot)
            return problem
        norm = _normalise_edges(_checked_edges(e, n))

        gs = _normalise_groups(groups, n)
        return cls(weights=w, edges=norm.astype(np.int32), groups=tuple(gs))

    @property
    def n(self) -> int:
        """Number of vertices."""
        return int(self.weights.shape[0])

    @property
    def m(self) -> int:
        """Number of listed edges (group clique pairs not included; see :meth:`all_edges`)."""
        return int(self.edges.shape[0])

    @cached_property
    def _listed_keys(self) -> np.ndarray | None:
        """The listed edges' keys ``u * n + v``, strictly increasing (MwisProblem's edges are
        unique and sorted: checked here, None if not)."""
        keys = self.edges[:, 0].astype(np.int64) * max(self.n, 1) + self.edges[:, 1]
        if keys.size > 1 and not bool((keys[1:] > keys[:-1]).all()):
            return None
        keys.setflags(write=False)
        return keys

    @cached_property
    def _all_edges(self) -> np.ndarray:
        if not self.groups:
            out = self.edges
        elif _groups_listed(self.n, self.edges, self.groups, self._listed_keys):
            out = self.edges
        else:
            parts = [self.edges.astype(np.int64), _group_pairs(self.groups)]
            # The planner lists its group cliques among the edges already: when every group
            # pair is listed, the edges are the answer (a binary search per pair instead of
            # sorting edges and pairs together: 3.1 -> ~0.6 ms at 60,000 edges)
            base = max(self.n, 1)
            pairs = np.concatenate(parts[1:], axis=0)
            ekeys = self._listed_keys
            if ekeys is None:
                ekeys = self.edges[:, 0].astype(np.int64) * base + self.edges[:, 1]
            gkeys = pairs[:, 0] * base + pairs[:, 1]
            at = np.searchsorted(ekeys, gkeys)
            listed = at < ekeys.size
            listed[listed] = ekeys[at[listed]] == gkeys[listed]
            if listed.all():
                out = self.edges
            else:
                out = _normalise_edges(np.concatenate([parts[0], pairs[~listed]], axis=0)
                                       ).astype(np.int32)
        out = out.view()
        out.setflags(write=False)
        return out

    def all_edges(self) -> np.ndarray:
        """(m', 2) int32 unique u < v pairs: the listed edges plus every pair inside each group."""
        return self._all_edges

    @cached_property
    def _edge_keys(self) -> tuple[np.ndarray, bool]:
        e = self.all_edges()
        if e.shape[0] == self.edges.shape[0] and self._listed_keys is not None:
            return self._listed_keys, True  # every group pair listed: the same edges
        keys = e[:, 0].astype(np.int64) * max(self.n, 1) + e[:, 1]
        ordered = keys.size < 2 or bool((keys[1:] > keys[:-1]).all())
        keys.setflags(write=False)
        return keys, ordered

    def edge_keys(self) -> np.ndarray:
        """(m',) int64 keys ``u * n + v`` of the conflict pairs u < v of :meth:`all_edges`,
        strictly increasing: a pair conflicts exactly when its key is among them (a binary
        search). Cached, shared with :meth:`csr`."""
        keys, ordered = self._edge_keys
        return keys if ordered else sorted_unique(keys)

    @cached_property
    def _csr(self) -> tuple[np.ndarray, np.ndarray]:
        keys, ordered = self._edge_keys
        indptr, indices = csr_from_edges(self.n, self.all_edges(), keys if ordered else None)
        indptr.setflags(write=False)
        indices.setflags(write=False)
        return indptr, indices

    def csr(self) -> tuple[np.ndarray, np.ndarray]:
        """``(indptr, indices)`` of the symmetric adjacency of the full conflict graph (groups
        included), neighbours sorted; numpy only (cheaper than scipy on small graphs)."""
        return self._csr

    @cached_property
    def _adjacency(self) -> sp.csr_matrix:
        indptr, indices = self.csr()
        return sp.csr_matrix((np.ones(indices.size, dtype=np.int8), indices, indptr),
                             shape=(self.n, self.n))

    def adjacency(self) -> sp.csr_matrix:
        """Symmetric (n, n) scipy CSR adjacency of the full conflict graph (groups included)."""
        return self._adjacency

    def is_independent(self, selected: Any) -> bool:
        """True when ``selected`` is a set of distinct in-range vertices with no conflict between them."""
        return check_selection(self, selected)[0]

    def objective(self, selected: Any) -> float:
        """Sum of the weights of ``selected`` in float64 (no independence check)."""
        idx = np.asarray(selected, dtype=np.int64).reshape(-1)
        return float(math.fsum(self.weights[idx].tolist())) if idx.size else 0.0


def _edge_array(edges: Any) -> np.ndarray:
    """``edges`` as a numpy array; a ragged list names its first row that is not a pair."""
    if edges is None:
        return np.zeros((0, 2), dtype=np.int64)
    try:
        return _asarray_exact(edges)
    except (TypeError, ValueError):
        pass
    try:
        rows = list(edges)
    except TypeError:
        raise MwisInputError(f"edges: {edges!r} is not a sequence of vertex pairs") from None
    for i, row in enumerate(rows):
        try:
            a = np.asarray(row)
        except (TypeError, ValueError):
            a = None
        if a is None or a.shape != (2,):
            raise MwisInputError(f"edges[{i}]: {row!r} is not a pair of vertex indices")
    raise MwisInputError("edges: not an (m, 2) array of vertex indices")


def _group_list(groups: Any) -> list:
    """Clique groups as a list of per-group sequences: a list, tuple, (R, K) numpy array or 1-D
    object array of rows. Raises MwisInputError for anything else."""
    if groups is None:
        return []
    if isinstance(groups, np.ndarray):
        if groups.ndim == 2:
            return list(groups)
        if groups.ndim == 1 and (groups.dtype == object or groups.size == 0):
            return list(groups)
        raise MwisInputError(
            f"groups: expected a sequence of vertex-index sequences, got an array of shape "
            f"{groups.shape} and dtype {groups.dtype}")
    if isinstance(groups, (str, bytes)) or not isinstance(groups, (Sequence, Iterable)):
        raise MwisInputError(f"groups: {groups!r} is not a sequence of vertex-index sequences")
    return list(groups)


def _groups_listed(n: int, edges: np.ndarray, groups: Sequence[np.ndarray],
                   keys: np.ndarray | None = None) -> bool:
    """True when every pair inside each group is among ``edges`` (unique u < v pairs, sorted,
    as MwisProblem keeps them). With the edges' ``keys`` (``u * n + v``, strictly increasing)
    and groups of consecutive vertices (the planner's): two binary searches per group member,
    O(n log m). Otherwise, for disjoint groups, the listed edges inside a group of k vertices
    number exactly k (k - 1) / 2: O(n + m) without expanding the pairs (the
    expansion and its binary search cost ~25 us of a 400 us ``auto`` solve at 100 vertices;
    the planner always lists its group cliques). False also when it cannot tell cheaply
    (overlapping groups of other shapes): the caller then expands the pairs."""
    sizes = [g.size for g in groups]
    members = np.concatenate(groups)
    if keys is not None:
        # (keys strictly increasing) each member v's pairs (v, v + 1 .. last of its group):
        # their count sums to the groups' pair count exactly when every group is a range of
        # consecutive vertices (the planner's); then two binary searches per member tell
        # whether all are listed (~70 -> ~25 us at 8,700 edges, against gathering
        # each edge's group below). Overlaps need no care here: each pair is looked up.
        size = np.array(sizes, dtype=np.int64)
        v = members.astype(np.int64)
        last = np.repeat(v[np.cumsum(size) - 1], size)
        pairs = int((size * (size - 1)).sum()) // 2
        if int((last - v).sum()) == pairs:
            row = v * n
            found = np.searchsorted(keys, row + last, side="right") - \
                np.searchsorted(keys, row + v, side="right")
            return int(found.sum()) == pairs
    gid = np.full(n, -1, dtype=np.int64)
    gid[members] = np.repeat(np.arange(len(sizes), dtype=np.int64), sizes)
    if np.count_nonzero(gid >= 0) != members.size:  # overlapping groups
        return False
    a = gid[edges[:, 0]]
    # the edges are unique pairs, so no group holds more than k (k - 1) / 2 of them: the total
    # is reached only when every group's count is (no per-group count: ~8 us)
    inside = np.count_nonzero((a >= 0) & (a == gid[edges[:, 1]]))
    return inside == sum(k * (k - 1) // 2 for k in sizes)


def _group_pairs(groups: Sequence[np.ndarray]) -> np.ndarray:
    """(p, 2) int64 pairs u < v inside every group (each group sorted and duplicate-free, as
    MwisProblem keeps them), in one vectorised expansion: no Python loop over the groups
    (the per-size loop with np.stack cost ~0.4 ms of auto's 0.7 ms overhead at 150
    vertices)."""
    lengths = np.fromiter((g.size for g in groups), dtype=np.int64, count=len(groups))
    flat = np.concatenate(groups).astype(np.int64)
    starts = np.cumsum(lengths) - lengths
    pos = np.arange(flat.size, dtype=np.int64) - np.repeat(starts, lengths)
    later = np.repeat(lengths, lengths) - 1 - pos          # partners after each element
    total = int(later.sum())
    first = np.repeat(np.arange(flat.size, dtype=np.int64), later)
    step = np.arange(total, dtype=np.int64) - np.repeat(np.cumsum(later) - later, later)
    return np.stack([flat[first], flat[first + 1 + step]], axis=1)


def _normalise_groups(groups: Sequence[Any] | None, n: int) -> list[np.ndarray]:
    """Validate clique groups (indices in [0, n)), drop duplicates inside each, keep those of
    size >= 2 as sorted int32 arrays. Vectorised over all groups. Raises MwisInputError."""
    groups = _group_list(groups)
    if not groups:
        return []
    if all(type(g) is np.ndarray and g.ndim == 1 and g.dtype.kind in "iu" for g in groups):
        # fast path: 1-D integer arrays (MwisProblem's own groups, the planner's)
        # need none of the per-group conversion below; the range is checked on the whole
        arrays = groups
        clean = _clean_groups(arrays, n)
        if clean is not None:
            return clean
    else:
        arrays = _group_arrays(groups, n)
    lengths = np.fromiter((a.size for a in arrays), dtype=np.int64, count=len(arrays))
    return _normalise_groups_tail(arrays, lengths, n)


def _clean_groups(arrays: list[np.ndarray], n: int) -> list[np.ndarray] | None:
    """The groups as :func:`_normalise_groups_tail` returns them when they are already clean:
    1-D signed-integer arrays of at least two vertices each, in [0, n), each strictly
    increasing (so sorted and duplicate-free). None otherwise (the full path then checks, sorts
    and names a bad value). The same result in fewer numpy calls (~27 -> ~15 us of a
    0.35 ms ``auto`` solve at 100 vertices, 20 groups)."""
    lens = [a.size for a in arrays]
    if min(lens) < 2:
        return None
    flat = np.concatenate(arrays)
    if flat.dtype.kind != "i":
        return None
    rising = flat[1:] > flat[:-1]
    if rising.all():
        # the groups ascending one after the other (the planner's): the ends are the bounds
        # (two reductions fewer, and the slices below without a numpy cumsum)
        if int(flat[0]) < 0 or int(flat[-1]) >= n:
            return None
    else:
        if int(flat.min()) < 0 or int(flat.max()) >= n:
            return None
        ends = np.cumsum(lens)
        rising[ends[:-1] - 1] = True  # across a group boundary
        if not rising.all():
            return None
    flat = flat.astype(np.int32)
    out, start = [], 0
    for end in itertools.accumulate(lens):
        out.append(flat[start:end])
        start = end
    return out


def _group_arrays(groups: list, n: int) -> list[np.ndarray]:
    """Each group as a flat numpy array, or MwisInputError naming ``groups[i]``."""
    arrays = []
    for gi, g in enumerate(groups):
        try:
            a = _asarray_exact(g)
        except (TypeError, ValueError):
            raise MwisInputError(f"groups[{gi}]: {g!r} is not a flat sequence of vertex indices") from None
        if a.ndim == 0:
            raise MwisInputError(f"groups[{gi}]: {g!r} is not a sequence of vertex indices")
        if a.size and (a.ndim != 1 or a.dtype.kind not in "iuf"):
            _as_index_array(a, f"groups[{gi}]", n)  # raises with the group's name
        arrays.append(a.reshape(-1))
    return arrays


def _normalise_groups_tail(arrays: list[np.ndarray], lengths: np.ndarray,
                           n: int) -> list[np.ndarray]:
    """The groups' range check, their sort and duplicate removal (skipped when already sorted
    and duplicate-free), those of size >= 2 kept."""
    if lengths.sum() == 0:
        return []
    flat = np.concatenate(arrays)
    try:
        idx = _as_index_array(flat, "groups", n)
    except MwisInputError:
        # Re-check group by group so the message names groups[i][j].
        for gi, a in enumerate(arrays):
            _as_index_array(a, f"groups[{gi}]", n)
        raise
    # fast path: groups already sorted and duplicate-free (the planner's, and every
    # MwisProblem's own) need no sort; the check is one comparison per vertex
    if idx.size > 1:
        rising = idx[1:] > idx[:-1]
        starts = np.cumsum(lengths)[:-1]
        rising[starts[(lengths[1:] > 0) & (starts > 0)] - 1] = True  # across a group boundary
        if rising.all():
            return _pieces(idx.astype(np.int32), lengths)
    gid = np.repeat(np.arange(lengths.size, dtype=np.int64), lengths)
    key = sorted_unique(gid * max(n, 1) + idx)
    gid, v = key // max(n, 1), key % max(n, 1)
    counts = np.bincount(gid, minlength=lengths.size)
    return _pieces(v.astype(np.int32), counts)


def _pieces(flat: np.ndarray, counts: np.ndarray) -> list[np.ndarray]:
    """Consecutive slices of ``flat`` of the given lengths, those of length >= 2 only. Plain
    slicing: np.split costs ~1 ms per call on the 10-group graphs of one epoch."""
    ends = np.cumsum(counts).tolist()
    out, start = [], 0
    for end in ends:
        if end - start >= 2:
            out.append(flat[start:end])
        start = end
    return out


def sorted_unique(values: np.ndarray) -> np.ndarray:
    """Sorted unique values of a 1-D integer array by sort-and-compare: several times faster
    here than numpy 2's hash-based ``np.unique`` on 10^5 keys. O(m log m). numpy's default
    sort (vectorised introsort on x86) and not a stable one: equal integers cannot be told
    apart, so the result is the same, and on 5.5 M random int64 keys it takes 0.13 CPU-s
    against the stable sort's 0.62."""
    a = np.sort(np.asarray(values).reshape(-1))
    if a.size == 0:
        return a
    keep = np.empty(a.size, dtype=bool)
    keep[0] = True
    np.not_equal(a[1:], a[:-1], out=keep[1:])
    return a[keep]


def csr_from_edges(n: int, edges: np.ndarray, sorted_keys: np.ndarray | None = None
                   ) -> tuple[np.ndarray, np.ndarray]:
    """``(indptr int64, indices int32)`` of the symmetric adjacency of unique u < v ``edges``,
    each row's neighbours sorted. ``sorted_keys``: the edges' ``u * n + v`` when the caller has
    checked them strictly increasing. O(m) when the edges are sorted lexicographically (as
    MwisProblem keeps them), else O(m log m)."""
    e = np.asarray(edges).reshape(-1, 2)
    m = e.shape[0]
    if _coo_tocsr is not None and 0 < m and 2 * m < 2**31 and 0 < n < 2**31 \
            and e.dtype.kind in "iu":
        u, v = e[:, 0], e[:, 1]
        if sorted_keys is None:
            keys = u.astype(np.int64) * n + v.astype(np.int64)
            ordered = m == 1 or bool((keys[1:] > keys[:-1]).all())
        else:
            ordered = True
        # in range (u[0] is the least u when sorted) and u < v, checked in the caller's dtype:
        # coo_tocsr itself checks no index
        if ordered and int(u[0]) >= 0 and int(v.max()) < n and bool((u < v).all()):
            lo, hi = u.astype(np.int32), v.astype(np.int32)
            # sorted: each row's neighbours below it (the pairs (u, row), in u order) then
            # above it (the pairs (row, v), in v order) are already in order, so a stable
            # counting sort by row, scipy's coo_tocsr, gives sorted rows in O(m) (
            # 0.2 -> 0.05 ms at 8,700 edges, against the argsort below)
            indptr = np.empty(n + 1, dtype=np.int32)
            indices = np.empty(2 * m, dtype=np.int32)
            _coo_tocsr(n, n, 2 * m, np.concatenate([hi, lo]), np.concatenate([lo, hi]),
                       np.zeros(2 * m, dtype=np.int8), indptr, indices,
                       np.empty(2 * m, dtype=np.int8))
            return indptr.astype(np.int64), indices
    e = e.astype(np.int64, copy=False)
    rows = np.concatenate([e[:, 0], e[:, 1]])
    cols = np.concatenate([e[:, 1], e[:, 0]])
    order = np.argsort(rows * max(n, 1) + cols, kind="stable")
    indptr = np.zeros(n + 1, dtype=np.int64)
    np.cumsum(np.bincount(rows, minlength=n), out=indptr[1:])
    return indptr, cols[order].astype(np.int32)


def _normalise_edges(e: np.ndarray) -> np.ndarray:
    """Sort each pair to u < v and drop duplicates (lexicographic order). O(m log m)."""
    if e.shape[0] == 0:
        return np.zeros((0, 2), dtype=np.int64)
    lo = np.minimum(e[:, 0], e[:, 1]).astype(np.int64)
    hi = np.maximum(e[:, 0], e[:, 1]).astype(np.int64)
    base = int(hi.max()) + 1
    key = lo * base + hi
    if key.size > 1 and bool((key[1:] > key[:-1]).all()):
        # fast path: already sorted and unique (the planner's edges, and every
        # MwisProblem's own), no sort
        return np.stack([lo, hi], axis=1)
    key = sorted_unique(key)
    out = np.empty((key.shape[0], 2), dtype=np.int64)
    np.divmod(key, base, out=(out[:, 0], out[:, 1]))
    return out


def check_selection(problem: MwisProblem, selected: Any) -> tuple[bool, str]:
    """Check an answer against the input graph (groups included).

    Returns ``(True, "")`` when ``selected`` is a 1-D collection of distinct integer vertex indices
    in range with no conflicting pair, else ``(False, reason)`` naming the first problem found.
    O(n + m').
    """
    try:
        arr = np.asarray(selected)
    except Exception as exc:  # noqa: BLE001 - any garbage from a broken backend is a reason
        return False, f"selected: not an array ({exc})"
    if arr.size == 0:
        return True, ""
    if arr.ndim != 1:
        return False, f"selected: expected a 1-D array, got shape {arr.shape}"
    if arr.dtype.kind not in "iu":
        return False, f"selected: expected integer vertex indices, got dtype {arr.dtype}"
    idx = arr.astype(np.int64, copy=False)
    # the last selection found valid on this problem, by its int64 values in order (a backend's
    # check and the validation layer's see the same sorted set: checked once)
    key = idx.tobytes()
    if problem.__dict__.get("_valid_selection") == key:
        return True, ""
    if int(idx.min()) < 0 or int(idx.max()) >= problem.n:  # (two reductions)
        bad = (idx < 0) | (idx >= problem.n)
        i = int(np.flatnonzero(bad)[0])
        return False, f"selected[{i}]: vertex {int(idx[i])} is out of range [0, {problem.n})"
    mask = np.zeros(problem.n, dtype=bool)
    mask[idx] = True
    if np.count_nonzero(mask) != idx.size:
        return False, "selected: contains duplicate vertices"
    csr = problem.__dict__.get("_csr")
    if csr is not None:
        # the CSR is built (every backend that solved it needs it): the selected vertices'
        # neighbours, none selected, instead of every conflict pair (~50 -> ~10 us
        # at 8,700 pairs); a conflict is then named from the pairs below
        indptr, indices = csr
        start = indptr[idx]
        count = indptr[idx + 1] - start
        ends = np.cumsum(count)
        pos = np.arange(int(ends[-1]), dtype=np.int64) + np.repeat(start - ends + count, count)
        if not mask[indices[pos]].any():
            problem.__dict__["_valid_selection"] = key
            return True, ""
    e = problem.all_edges()
    both = mask[e[:, 0]] & mask[e[:, 1]]
    if both.any():
        i = int(np.flatnonzero(both)[0])
        return False, f"selected: vertices {int(e[i, 0])} and {int(e[i, 1])} conflict"
    problem.__dict__["_valid_selection"] = key
    return True, ""


def integer_weights(weights: np.ndarray, resolution: int = 10**6) -> tuple[np.ndarray, float]:
    """Scale float weights to non-negative int64 for integer solvers (CP-SAT, KaMIS, CHILS).

    ``w_int = round((w / max(w)) * resolution)``: the heaviest vertex becomes ``resolution`` and
    every weight is rounded to a multiple of ``max(w) / resolution`` (absolute error
    <= max(w) / (2 * resolution) per vertex). The ratio is taken first, so no finite input
    overflows (w / max(w) <= 1) and none turns into garbage. Positive weights that would round
    to 0 are kept at 1 so the solver still prefers taking them. Returns ``(w_int, scale)``,
    ``scale = resolution / max(w)`` (finite; 1.0 when all weights are 0). Exception: weights
    that are all whole numbers with ``max(w) <= resolution`` are multiplied by the whole factor
    ``resolution // max(w)`` instead (no rounding at all: an integer objective such as
    ``uam_planner.objectives``' lexicographic weights keeps its exact optimum). Callers recompute
    the objective from the float weights and check a claimed optimum with
    :func:`integer_proof_holds`.
    Raises MwisInputError naming the field and value when ``n * resolution`` would overflow
    int64 sums, or when the largest weight is so small that ``scale`` is not representable
    (below ``resolution / 1.8e308``, about 5.6e-303 at 10^6: rescale the weights).
    """
    w = np.asarray(weights, dtype=np.float64)
    if w.size and w.size * float(resolution) > 2.0**62:
        raise MwisInputError(f"weights: {w.size} vertices x resolution {resolution} overflows int64")
    if not w.size:
        return np.zeros(0, dtype=np.int64), 1.0
    i = int(np.argmax(w))
    wmax = float(w[i])
    if wmax <= 0.0:
        return np.zeros(w.shape, dtype=np.int64), 1.0
    if wmax <= resolution and wmax.is_integer() and np.all(w == np.floor(w)):
        # Integer weights (uam_planner.objectives: lexicographic and priority objectives) are
        # multiplied by a whole factor, so every sum keeps its exact order and a proof on the
        # integer weights is a proof on the input (all weights 1.0 still become ``resolution``).
        factor = int(resolution // wmax)
        return w.astype(np.int64) * factor, float(factor)
    with np.errstate(over="ignore"):
        scale = float(resolution) / wmax
    if not math.isfinite(scale):
        raise MwisInputError(
            f"weights[{i}]: {wmax!r} is the largest weight and too small for integer weights "
            f"(resolution {resolution} / {wmax!r} overflows float64; multiply the weights by "
            "a constant, which changes no optimum)")
    wi = np.rint((w / wmax) * float(resolution)).astype(np.int64)
    if not wi.all():  # (only then the mask: ~2 us of a small solve)
        wi[(wi == 0) & (w > 0)] = 1
    return wi, scale


def integer_proof_holds(problem: "MwisProblem", selected: Any, wi: np.ndarray, scale: float,
                        integer_bound: float) -> bool:
    """True when a proof found on the integer weights ``wi`` (``integer_weights``) holds for the
    returned set: its integer objective equals the solver's ``integer_bound`` (the optimum it
    proved) and its objective recomputed in the input's own weights equals that bound divided
    by ``scale`` up to the rounding of the selected weights (<= 1/2 step each; 1 step for a
    positive weight kept at 1). Anything else (a solver whose set is not the one it proved, a
    scale that turned the weights into garbage) is no proof. O(|selected|)."""
    sel = np.asarray(selected, dtype=np.int64).reshape(-1)
    if not math.isfinite(float(integer_bound)) or not math.isfinite(scale) or scale <= 0:
        return False
    int_obj = int(np.asarray(wi, dtype=np.int64)[sel].sum()) if sel.size else 0
    if int_obj != round(float(integer_bound)):
        return False
    obj = problem.objective(sel)
    tol = 0.5 * sel.size + float(np.sum(wi[sel] == 1)) * 0.5 + 1e-9 * max(int_obj, 1)
    return abs(obj * scale - int_obj) <= tol


@dataclass
class MwisResult:
    """A backend's answer.

    Attributes:
        selected: int32 sorted vertex indices, an independent set of the input graph.
        objective: sum of their weights, recomputed in float64 from ``problem.weights``.
        proven_optimal: True only when the backend proved optimality (for integer solvers:
            optimal for the integer-scaled weights, see :func:`integer_weights`).
        solve_time_s: wall time of the solve in seconds.
        backend: name of the backend that produced the answer (the fallback's name on fallback).
        stats: backend statistics, str -> int | float | str.
        fallback: True when validation rejected the requested backend's answer.
        message: why a fallback happened, or other notes for the caller.
    """

    selected: np.ndarray
    objective: float
    proven_optimal: bool
    solve_time_s: float
    backend: str
    stats: dict = field(default_factory=dict)
    fallback: bool = False
    message: str = ""


def make_result(
    problem: MwisProblem,
    selected: Any,
    *,
    proven_optimal: bool,
    solve_time_s: float,
    backend: str,
    stats: Mapping[str, Any] | None = None,
    message: str = "",
) -> MwisResult:
    """Build an MwisResult with sorted int32 ``selected`` and the objective recomputed in float64."""
    sel = np.unique(np.asarray(selected, dtype=np.int64).reshape(-1)).astype(np.int32)
    return MwisResult(
        selected=sel,
        objective=problem.objective(sel),
        proven_optimal=bool(proven_optimal),
        solve_time_s=float(solve_time_s),
        backend=backend,
        stats=dict(stats or {}),
        message=message,
    )


class Backend(ABC):
    """An MWIS solver with one small surface (like a dimod sampler).

    Subclasses set ``name`` (registry name) and ``description`` (one line) and implement
    :meth:`solve`. Layers in :mod:`uam_solvers.layers` wrap any backend and are backends too.
    """

    name: str = "backend"
    description: str = ""
    #: True for backends with a large fixed cost per call (ComponentSplit then hands them all
    #: non-trivial components in one call rather than one call per component).
    batch_components: bool = False
    #: True for backends that apply MWIS reductions of their own (KaMIS, CHILS); the Reduce
    #: layer then passes large graphs straight through instead of paying for a second pass.
    reduces_itself: bool = False
    #: Largest problem the solve service runs in-process for this backend: only where the
    #: backend is known to return well within any time limit at that size (default: never,
    #: every solve goes to a worker process that can be killed).
    inline_max_vertices: int = 0
    #: Largest problem :class:`uam_solvers.layers.ValidateFallback` solves on the caller's
    #: thread instead of its guard thread (None: ``inline_max_vertices``). Only for backends
    #: whose run up to that size holds the GIL (the guard could not abandon it anyway) or
    #: honours its limit, where the thread hand-off would be pure cost.
    thread_inline_max_vertices: int | None = None
    #: True for backends that a guard thread can abandon: pure Python or a library that
    #: releases the GIL, stopping near its time limit (CP-SAT, the dwave samplers, greedy).
    #: :func:`uam_solvers.solve` runs these in the caller's process; every other backend
    #: (KaMIS and CHILS hold the GIL, KaMIS can ignore its limit; a third-party backend is not
    #: known to do either) runs above ``inline_max_vertices`` in a child process that is
    #: killed at the deadline.
    bounded_in_process: bool = False
    #: True when :meth:`warm_up` may solve a four-vertex graph to pay the first call's costs
    #: (the backend is local and its tiny solve takes milliseconds once warm; not the QPU).
    warm_up_by_solving: bool = False
    #: Declared options, name -> :class:`uam_solvers.options.Option` (type, default, range).
    options_spec: Mapping[str, Any] = {}
    #: True for backends that draw samples (reads) of a QUBO and answer the best read: they
    #: never prove an answer optimal, and the TTS study counts their reads
    #: (``uam_solvers.registry.sampling_backends``; every list of samplers derives from it).
    samples: bool = False

    @property
    def parameters(self) -> dict[str, list]:
        """dimod-style ``parameters``: option name -> list of relevant properties (none here)."""
        return {name: [] for name in self.options_spec}

    def validate_options(self, options: Mapping[str, Any] | None) -> dict:
        """Every declared option, checked, defaults filled in; MwisInputError naming the option
        and value for an unknown name or a malformed value."""
        from .options import parse_options

        return parse_options(self.name, self.options_spec, options)

    def available(self) -> tuple[bool, str]:
        """``(True, "")`` when the backend can run here, else ``(False, reason)``."""
        return True, ""

    def warm_up(self) -> None:
        """Pay this backend's first-call costs in this process now (its library's import and
        set-up: OR-Tools ~0.3 s, dwave-system and minorminer ~0.6 s on a quiet machine), so
        that a later solve spends its time limit on solving. The availability check (which
        imports the library) and, when ``warm_up_by_solving``, one solve of a four-vertex path
        with a 0.05 s limit. An unavailable backend is left as it is (its solve says why)."""
        if not self.available()[0] or not self.warm_up_by_solving:
            return
        tiny = MwisProblem.from_arrays([1.0, 2.0, 1.5, 1.0], [[0, 1], [1, 2], [2, 3]])
        self.solve(tiny, time_limit_s=0.05, seed=0, options={})

    def require_available(self) -> None:
        """Raise :class:`BackendUnavailable` with the reason when :meth:`available` is False."""
        ok, reason = self.available()
        if not ok:
            raise BackendUnavailable(f"backend {self.name!r} is unavailable: {reason}")

    @abstractmethod
    def solve(
        self,
        problem: MwisProblem,
        *,
        time_limit_s: float,
        seed: int,
        options: Mapping[str, Any],
    ) -> MwisResult:
        """Solve ``problem`` within about ``time_limit_s`` seconds, deterministically for ``seed``."""

    def __repr__(self) -> str:
        return f"<{type(self).__name__} {self.name!r}>"


def induced_subproblem(problem: MwisProblem, vertices: np.ndarray) -> MwisProblem:
    """The subgraph induced by sorted ``vertices`` (original indices), re-indexed 0..k-1.

    Listed edges and clique groups are restricted (groups shrinking below 2 vertices vanish), so
    group structure survives for solvers that use it. O(n + m + sum |group|).
    """
    vertices = np.asarray(vertices, dtype=np.int64)
    new_index = np.full(problem.n, -1, dtype=np.int64)
    new_index[vertices] = np.arange(vertices.size)
    e = problem.edges
    keep = (new_index[e[:, 0]] >= 0) & (new_index[e[:, 1]] >= 0)
    # new_index is increasing on vertices, so u < v and lexicographic order are preserved.
    sub_edges = new_index[e[keep]].astype(np.int32).reshape(-1, 2)
    groups: list[np.ndarray] = []
    if problem.groups:
        lengths = np.fromiter((g.size for g in problem.groups), dtype=np.int64, count=len(problem.groups))
        mapped = new_index[np.concatenate(problem.groups)]
        gid = np.repeat(np.arange(lengths.size), lengths)
        keep_v = mapped >= 0
        counts = np.bincount(gid[keep_v], minlength=lengths.size)
        groups = _pieces(mapped[keep_v].astype(np.int32), counts)  # order kept: still sorted
    return MwisProblem(weights=problem.weights[vertices].copy(), edges=sub_edges, groups=tuple(groups))


def brute_force_mwis(problem: MwisProblem, max_vertices: int = 22) -> tuple[np.ndarray, float]:
    """Exact MWIS by enumerating all 2^n subsets (a reference for tests and tiny graphs).

    Returns ``(selected, objective)``; among equal-weight optima the smallest bitmask wins.
    O(2^n (n + m')) time, O(2^n) memory; raises MwisInputError above ``max_vertices``.
    """
    n = problem.n
    if n > max_vertices:
        raise MwisInputError(f"weights: brute force needs n <= {max_vertices}, got {n}")
    if n == 0:
        return np.zeros(0, dtype=np.int32), 0.0
    masks = np.arange(1 << n, dtype=np.int64)
    ok = np.ones(masks.size, dtype=bool)
    for u, v in problem.all_edges().tolist():
        ok &= ((masks >> u) & (masks >> v) & 1) == 0
    total = np.zeros(masks.size, dtype=np.float64)
    for i in range(n):
        total += ((masks >> i) & 1) * problem.weights[i]
    total[~ok] = -1.0
    best = int(np.argmax(total))
    sel = np.flatnonzero((best >> np.arange(n)) & 1).astype(np.int32)
    return sel, problem.objective(sel)
