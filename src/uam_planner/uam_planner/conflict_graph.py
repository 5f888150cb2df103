"""Deconfliction against active flights and the conflict graph (framework steps 4-6).

Vertices are the candidates that keep separation with every active flight. Each request's
surviving candidates form a clique (a request flies at most one route); an edge joins two
candidates of different requests that lose separation with each other. The MWIS of this graph is
a largest-weight set of mutually conflict-free routes, at most one per request.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass, field

import numpy as np

from .separation import (
    DEFAULT_SEPARATION_M,
    SegmentSet,
    any_conflict,
    as_separation_model,
    conflicting_pairs,
)
from .trajectory import Trajectory


@dataclass
class ConflictGraph:
    """The MWIS instance of one epoch.

    Attributes:
        weights: (v,) float64 vertex weights d*/d.
        edges: (e, 2) int32 vertex pairs, u < v, sorted lexicographically, unique.
        vertex_request: (v,) int64 index of each vertex's request in the eligible request list.
        vertex_candidate: (v,) int64 candidate index of each vertex within its request.
        vertex_source: (v,) int64 index of each vertex in the flat candidate list given.
        groups: one int64 array of vertex indices per eligible request (possibly empty).
        n_candidates: candidates given; n_discarded: lost separation with an active flight.
        n_clique_edges, n_conflict_edges: edges inside requests / between requests.
        discarded: (n_candidates,) bool, True for candidates discarded against active flights.
    """

    weights: np.ndarray
    edges: np.ndarray
    vertex_request: np.ndarray
    vertex_candidate: np.ndarray
    vertex_source: np.ndarray
    groups: list
    n_candidates: int
    n_discarded: int
    n_clique_edges: int
    n_conflict_edges: int
    discarded: np.ndarray = field(repr=False, default=None)

    @property
    def n_vertices(self) -> int:
        return int(self.weights.shape[0])

    @property
    def n_edges(self) -> int:
        return int(self.edges.shape[0])


def discard_against_active(candidates, active, separation_m: float = DEFAULT_SEPARATION_M,
                           ) -> np.ndarray:
    """(n,) bool mask of candidates that lose separation with at least one active flight.

    ``candidates`` and ``active`` are sequences of Trajectory or SegmentSets. A decision per
    candidate (``separation.any_conflict``: the first loss found settles it), no pair list.
    """
    cand = candidates if isinstance(candidates, SegmentSet) else SegmentSet.from_trajectories(list(candidates))
    act = active if isinstance(active, SegmentSet) else SegmentSet.from_trajectories(list(active))
    if cand.n_trajectories == 0 or len(act) == 0:
        return np.zeros(cand.n_trajectories, dtype=bool)
    return any_conflict(cand, act, separation_m)


#: groups up to this size keep their upper-triangle indices (at most ~5.6 MB for all of them)
_KEPT_GROUP_SIZE = 128


@functools.lru_cache(maxsize=_KEPT_GROUP_SIZE)
def _kept_upper_pairs(c: int) -> tuple[np.ndarray, np.ndarray]:
    iu, ju = np.triu_indices(c, k=1)
    iu.setflags(write=False)
    ju.setflags(write=False)
    return iu, ju


def _upper_pairs(c: int) -> tuple[np.ndarray, np.ndarray]:
    """``np.triu_indices(c, k=1)``, read-only, kept for small groups: a request's group has one
    of a few sizes, and building the indices was most of the clique edges' time; a large city's
    groups (hundreds of candidates) would make the kept ones hundreds of MB, so those are built."""
    return _kept_upper_pairs(c) if c <= _KEPT_GROUP_SIZE else np.triu_indices(c, k=1)


def _clique_edges(groups: list) -> np.ndarray:
    parts = []
    for g in groups:
        c = g.shape[0]
        if c > 1:
            iu, ju = _upper_pairs(int(c))
            parts.append(np.stack((g[iu], g[ju]), axis=1))
    return np.concatenate(parts) if parts else np.zeros((0, 2), dtype=np.int64)


class ShiftedCandidates:
    """Candidates given as base trajectories and departure shifts (departure slots).

    Args:
        base: one Trajectory per (route, level) template, flown at its earliest slot.
        first: (len(base) + 1,) offsets: candidates first[j] .. first[j+1]-1 are base[j]
            shifted by ``shift_s`` of each.
        shift_s: (c,) shifts [s] >= 0.

    A sequence of the c candidate trajectories, built on access only (most candidates of a busy
    epoch are discarded against the active flights and never need one).
    """

    def __init__(self, base, first, shift_s, exact=None):
        # a sequence; one with a ``segment_set()`` method (the planner's templates) gives the
        # base segments without building each base trajectory
        self.base = base if hasattr(base, "segment_set") else list(base)
        self.first = np.asarray(first, dtype=np.int64)
        self.shift_s = np.asarray(shift_s, dtype=np.float64)
        self.template_of = np.repeat(np.arange(len(self.base)), np.diff(self.first))
        # optional callable(c) -> the candidate's trajectory built from its template and
        # departure (not shifted from the base: the same floats whatever the base)
        self.exact = exact

    def __len__(self) -> int:
        return int(self.shift_s.shape[0])

    def base_segments(self) -> SegmentSet:
        """The SegmentSet of the base trajectories."""
        fast = getattr(self.base, "segment_set", None)
        return fast() if fast is not None else SegmentSet.from_trajectories(list(self.base))

    def segments_of(self, candidates, base: SegmentSet | None = None) -> SegmentSet:
        """The SegmentSet of the candidates ``candidates`` (indices, in that order): the same
        floats as ``SegmentSet.from_trajectories([self[c] for c in candidates])``, without
        building a trajectory per candidate (each time is the base's plus the shift, one
        addition as in ``__getitem__``). ``base``: ``base_segments()``, if already made."""
        idx = np.asarray(candidates, dtype=np.int64)
        if self.exact is not None:
            return SegmentSet.from_trajectories([self[c] for c in idx.tolist()])
        bs = self.base_segments() if base is None else base
        # the base's segments are grouped by template, in order
        seg_first = np.searchsorted(bs.traj, np.arange(len(self.base) + 1))
        tpl = self.template_of[idx]
        count = seg_first[tpl + 1] - seg_first[tpl]
        rows = np.repeat(seg_first[tpl], count) + (np.arange(int(count.sum()), dtype=np.int64)
                                                   - np.repeat(np.cumsum(count) - count, count))
        dt = np.repeat(self.shift_s[idx], count)
        t0 = bs.t0_s[rows]
        t1 = bs.t1_s[rows]
        moved = dt != 0.0   # a candidate at the base's own slot is the base, not base + 0.0
        t0[moved] += dt[moved]
        t1[moved] += dt[moved]
        return SegmentSet(np.repeat(np.arange(idx.shape[0], dtype=np.int64), count), t0, t1,
                          bs.p0_m[rows], bs.v_mps[rows], int(idx.shape[0]))

    def __getitem__(self, c):
        c = int(c)
        if self.exact is not None:
            return self.exact(c)
        tr = self.base[int(self.template_of[c])]
        dt = float(self.shift_s[c])
        if dt == 0.0:
            return tr
        t0, t1, p0, v = tr.segments()
        times = tr.times_s + dt
        times.setflags(write=False)
        return Trajectory._trusted(times, tr.points_m, (times[:-1], times[1:], p0, v))


def _unique_pairs(pairs: np.ndarray, n: int) -> np.ndarray:
    """Rows (min, max) of ``pairs`` over 0..n-1, unique and sorted lexicographically (as
    ``np.unique(np.sort(pairs, axis=1), axis=0)``, on one int64 code per row)."""
    if pairs.shape[0] == 0:
        return np.zeros((0, 2), dtype=np.int64)
    a = np.minimum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    b = np.maximum(pairs[:, 0], pairs[:, 1]).astype(np.int64)
    code = a * max(int(n), 1) + b
    code.sort()  # a sort and a mask: np.unique's hash path is several times slower here
    code = code[np.concatenate(([True], code[1:] != code[:-1]))]
    return np.stack(np.divmod(code, max(int(n), 1)), axis=1)


class CandidatePairCache:
    """The conflicts among one epoch's surviving candidates, reused at the next (rolling horizon).

    Whether two candidates lose separation is a function of their two trajectories alone, and a
    candidate is its request, template and departure time: ``keys`` name them (``(request_id,
    id(template), departure_s)`` in the planner, whose CandidateCache keeps the templates alive;
    keys must be unique within a call, and two candidates of both calls must keep their relative
    order, as the planner's arrival-ordered vertices do). With a
    horizon of H epochs most candidates of an epoch were candidates of the previous one (the
    later epochs' departures stay on the same slot grid), so only the pairs with a new candidate
    are checked: new x new and new x old (``conflicting_pairs`` calls with a fixed time bucket);
    the old x old pairs come from the previous epoch's answer. The result is the same set of
    pairs, to the last bit, as one call over all candidates with that bucket
    (``test_planner_horizon_builds_the_same_graphs_with_and_without_the_pair_cache``).

    Holds one epoch: ``conflicts`` replaces what it holds by the pairs it returns.
    """

    def __init__(self):
        self._index: dict = {}
        self._pairs = np.zeros((0, 2), dtype=np.int64)
        self.reused_pairs = 0  # old x old pairs taken from the cache, over the run
        self.checked_new = 0   # candidates that were new, over the run

    def conflicts(self, keys, candidates, request, separation_m, bucket_s: float) -> np.ndarray:
        """Conflicting pairs (i < j, sorted) among ``candidates`` (sequence of Trajectory) of
        different ``request`` labels; ``keys[i]`` identifies candidate i's trajectory (the same
        key must mean the same floats). ``bucket_s``: the broad phase's time bucket, fixed so
        that every call cuts a segment into the same pieces: the verdict on a pair is then a
        function of its two trajectories alone, to the last bit, whatever else is in the call."""
        n = len(candidates)
        request = np.asarray(request, dtype=np.int64)
        if len(keys) != n:
            raise ValueError(f"keys: {len(keys)} keys for {n} candidates")
        old_pos = np.fromiter((self._index.get(k, -1) for k in keys), dtype=np.int64, count=n)
        old = np.flatnonzero(old_pos >= 0)
        new = np.flatnonzero(old_pos < 0)
        parts = []
        # z cells of the vertical reach in the broad phase's keys: the horizon's candidates
        # cruise on levels V apart, and pieces on different levels then share no cell (the same
        # pairs, to the last bit: conflicting_pairs(z_cell_m=))
        z_cell = as_separation_model(separation_m).vertical_reach_m
        if old.size and self._pairs.shape[0]:
            renumber = np.full(len(self._index), -1, dtype=np.int64)
            renumber[old_pos[old]] = old
            p = renumber[self._pairs]
            p = p[(p >= 0).all(axis=1)]
            self.reused_pairs += int(p.shape[0])
            parts.append(p)
        if new.size > 1:
            nn = conflicting_pairs([candidates[i] for i in new], None, separation_m,
                                   groups_a=request[new], bucket_s=bucket_s, z_cell_m=z_cell)
            parts.append(new[nn])
        if new.size and old.size:
            # new x old in one call: the exact kernel takes the lower-index candidate first, as
            # one call over all candidates does (its rounding is not symmetric to the last bit:
            # rank_a, rank_b), and pairs of one request are skipped before any box test (a
            # request's old and new candidates share their pad and routes: groups). Was three
            # calls, (old, late new), (early new, old) and (old, early new), each filtering
            # afterwards: 92.1 M piece pairs sharing a cell against 71.9 M in one call, before
            # the z cells (bench_horizon --in-process, H = 10, 120/120, 300 s).
            ab = conflicting_pairs([candidates[i] for i in old], [candidates[i] for i in new],
                                   separation_m, bucket_s=bucket_s, groups_a=request[old],
                                   groups_b=request[new], rank_a=old, rank_b=new,
                                   z_cell_m=z_cell)
            parts.append(np.stack((old[ab[:, 0]], new[ab[:, 1]]), axis=1))
        self.checked_new += int(new.size)
        pairs = _unique_pairs(np.concatenate(parts) if parts else np.zeros((0, 2), np.int64), n)
        index = {k: i for i, k in enumerate(keys)}
        if len(index) != n:
            raise ValueError(f"keys: {n - len(index)} of {n} keys repeat an earlier one")
        self._index = index
        self._pairs = pairs
        return pairs


def _candidate_arrays(candidate_request, candidate_index, candidate_weight, n: int, n_requests: int):
    """The per-candidate arrays as int64, int64, float64, checked: a wrong shape or request is refused by name."""
    cand_req = np.asarray(candidate_request, dtype=np.int64)
    cand_idx = np.asarray(candidate_index, dtype=np.int64)
    cand_w = np.asarray(candidate_weight, dtype=np.float64)
    for name, arr in (("candidate_request", cand_req), ("candidate_index", cand_idx),
                      ("candidate_weight", cand_w)):
        if arr.shape != (n,):
            raise ValueError(f"{name} must have shape ({n},), got {arr.shape}")
    if n and (cand_req.min() < 0 or cand_req.max() >= n_requests):
        raise ValueError(f"candidate_request values must lie in [0, {n_requests - 1}]")
    return cand_req, cand_idx, cand_w


def _discarded_by_active(candidates, n: int, active, separation_m, pair_cache):
    """(n,) bool: the candidates that lose separation with an active flight; base segments of shifted ones (reused)."""
    base = None
    if isinstance(candidates, ShiftedCandidates):
        discarded = np.zeros(n, dtype=bool)
        act = active if isinstance(active, SegmentSet) else \
            SegmentSet.from_trajectories(list(active))
        if n and len(act):
            # with the horizon's pair cache, z cells in the keys as in its calls (the same pairs)
            z_cell = as_separation_model(separation_m).vertical_reach_m \
                if pair_cache is not None else None
            base = candidates.base_segments()
            discarded = any_conflict(base, act,
                                     separation_m,
                                     shifts_a=(candidates.first, candidates.shift_s),
                                     z_cell_m=z_cell)
    else:
        cand_set = SegmentSet.from_trajectories(list(candidates))
        discarded = discard_against_active(cand_set, active, separation_m)
    return discarded, base


def _survivor_conflicts(candidates, keep, vreq, base, separation_m, keys, pair_cache, bucket_s):
    """The conflict edges among the survivors ``keep`` of different requests (pair cache when given: fewer checks)."""
    if pair_cache is not None:
        if keys is None or bucket_s is None:
            raise ValueError("build_conflict_graph: pair_cache needs keys and bucket_s")
        surv = [candidates[i] for i in keep]
        return pair_cache.conflicts([keys[i] for i in keep.tolist()], surv, vreq, separation_m,
                                    bucket_s)
    surv = candidates.segments_of(keep, base) if isinstance(candidates, ShiftedCandidates) \
        else [candidates[i] for i in keep]
    return conflicting_pairs(surv, None, separation_m, groups_a=vreq,
                             bucket_s=bucket_s) if keep.shape[0] > 1 \
        else np.zeros((0, 2), dtype=np.int64)


def build_conflict_graph(candidates, candidate_request, candidate_index, candidate_weight,
                         n_requests: int, active=(), separation_m: float = DEFAULT_SEPARATION_M,
                         timings: dict | None = None, keys=None,
                         pair_cache: CandidatePairCache | None = None,
                         bucket_s: float | None = None) -> ConflictGraph:
    """Deconflict candidates against active flights and build the conflict graph.

    Args:
        candidates: sequence of n candidate Trajectory (all requests' candidates, flat), or a
            ShiftedCandidates (deconflicted per template, see ``conflicting_pairs(shifts_a=)``).
        candidate_request: (n,) index of each candidate's request in 0..n_requests-1.
        candidate_index: (n,) candidate index within its request.
        candidate_weight: (n,) weights d*/d.
        n_requests: number of eligible requests.
        active: sequence of Trajectory (or a SegmentSet) of active flights.
        separation_m: separation minimum [m] (the paper's sphere) or a SeparationModel.
        timings: optional dict; gets 'deconfliction_s', 'conflicts_s', 'graph_s' (wall time,
            for reports and benchmarks only).
        keys, pair_cache: optional (n,) hashable names of the candidates' trajectories and a
            CandidatePairCache: the conflicts among survivors then reuse the previous call's
            (same graph, fewer checks; the planner's rolling horizon).
        bucket_s: the time bucket of the conflicts among survivors (default: the separation
            module's, from the median speed; required with ``pair_cache``).
    Returns: a ConflictGraph. Complexity: that of two ``conflicting_pairs`` calls plus
    O(v + e log e).
    """
    import time

    n = len(candidates)
    cand_req, cand_idx, cand_w = _candidate_arrays(candidate_request, candidate_index,
                                                   candidate_weight, n, n_requests)
    t = time.perf_counter()
    discarded, base = _discarded_by_active(candidates, n, active, separation_m, pair_cache)
    t1 = time.perf_counter()

    keep = np.flatnonzero(~discarded)
    vreq = cand_req[keep]
    conflict = _survivor_conflicts(candidates, keep, vreq, base, separation_m, keys, pair_cache,
                                   bucket_s)
    t2 = time.perf_counter()

    order = np.argsort(vreq, kind="stable")
    bounds = np.searchsorted(vreq[order], np.arange(n_requests + 1))
    groups = [order[bounds[r]:bounds[r + 1]].astype(np.int64) for r in range(n_requests)]
    clique = _clique_edges(groups)
    edges = _unique_pairs(np.concatenate((clique, conflict)), keep.shape[0])
    edges = edges.astype(np.int32).reshape(-1, 2)
    t3 = time.perf_counter()
    if timings is not None:
        timings["deconfliction_s"] = t1 - t
        timings["conflicts_s"] = t2 - t1
        timings["graph_s"] = t3 - t2
    return ConflictGraph(weights=cand_w[keep].astype(np.float64), edges=edges,
                         vertex_request=vreq, vertex_candidate=cand_idx[keep],
                         vertex_source=keep.astype(np.int64), groups=groups,
                         n_candidates=n, n_discarded=int(discarded.sum()),
                         n_clique_edges=int(clique.shape[0]),
                         n_conflict_edges=int(conflict.shape[0]), discarded=discarded)


class ActiveFlightIndex:
    """The segments of the active flights, kept from one epoch to the next.

    Rebuilding the flat segment arrays of every active flight each epoch costs O(active
    segments) of Python-level concatenation (about 2,000 flights x 10 segments at city scale);
    the index instead drops the flights that are gone and the segments already flown (time only
    moves forward, so a segment that ended before the epoch can never conflict again), and
    appends only the new approvals. ``segments(flights, t_s)`` returns the SegmentSet of
    ``flights`` (anything with ``.trajectory``) restricted to segments ending at or after
    ``t_s`` [s], with trajectory indices into ``flights``; if ``flights`` is not the previous
    list minus some flights plus new ones at the end (in that order), it is rebuilt.
    """

    def __init__(self):
        self._flights: list = []
        self._set = SegmentSet.from_trajectories([])
        self.rebuilds = 0

    def __len__(self) -> int:
        return len(self._flights)

    def segments(self, flights, t_s: float | None = None) -> SegmentSet:
        flights = list(flights)
        pos = {id(f): i for i, f in enumerate(self._flights)}
        old_idx = np.fromiter((pos.get(id(f), -1) for f in flights), dtype=np.int64,
                              count=len(flights))
        n_kept = int(np.argmax(old_idx < 0)) if (old_idx < 0).any() else len(flights)
        kept = old_idx[:n_kept]
        incremental = bool((old_idx[n_kept:] < 0).all() and np.all(np.diff(kept) > 0))
        if incremental:
            keep_traj = np.zeros(max(len(self._flights), 1), dtype=bool)
            keep_traj[kept] = True
            renumber = np.cumsum(keep_traj) - 1
            s = self._set
            m = keep_traj[s.traj] if len(s) else np.zeros(0, bool)
            if t_s is not None and len(s):
                m &= s.t1_s >= t_s
            old = SegmentSet(renumber[s.traj[m]], s.t0_s[m], s.t1_s[m], s.p0_m[m], s.v_mps[m],
                             n_kept)
            new = SegmentSet.from_trajectories([f.trajectory for f in flights[n_kept:]])
            merged = SegmentSet(np.concatenate((old.traj, new.traj + n_kept)),
                                np.concatenate((old.t0_s, new.t0_s)),
                                np.concatenate((old.t1_s, new.t1_s)),
                                np.concatenate((old.p0_m, new.p0_m)),
                                np.concatenate((old.v_mps, new.v_mps)), len(flights))
        else:
            self.rebuilds += 1
            merged = SegmentSet.from_trajectories([f.trajectory for f in flights])
            if t_s is not None:
                merged = merged.take(merged.t1_s >= t_s)
        self._flights = flights
        self._set = merged
        return merged
