"""Seeded MWIS instances with the paper's structure, and the corpus file format.

The conflict graph of one planning epoch (design notes, step 6) has a vertex per candidate route,
weight w = d*/d (d* the request's shortest route length, d the candidate's length), a clique over
each request's candidates (at most one route per request) and an edge per conflict between
candidates of *different* requests. The generators here reproduce that shape without running the
planner:

* every request has k candidates (default 5, the paper's value); the first has weight 1 and the
  others have weights in (0, 1), strictly decreasing (longer detours);
* some candidates may be missing (in the planner they are discarded for conflicting with active
  flights, step 4), which is how vertex counts that are not multiples of k arise; surviving
  candidates keep their weight d*/d, so a request whose shortest route was discarded has no
  weight-1 vertex;
* two requests either do not interact at all (routes far apart in space or time) or interact;
  when they interact their candidates conflict in *blocks* (a group of one request's routes and a
  group of the other's share a corridor segment at the same time, so every pair between the two
  groups conflicts) plus scattered single conflicts.

`paper_instance` and `generate_corpus` give the small instances of the paper's time-to-solution
study (5 to 50 vertices); `large_instance` gives up to 10,000+ vertices with local interactions
(requests placed in a unit square interact with their neighbours), for scale.

Corpus files are JSON Lines, one instance per line; see docs/mwis-corpus-format.md and
`save_corpus` / `load_corpus`. `read_instances` picks a reader by file suffix from
`CORPUS_READERS` maps a file suffix to a reader: ``.jsonl``/``.json`` corpora, and ``.mcap``
planner recordings (the MWIS instance of every PlanningReport, read through uam_sim.audit.analysis).
"""

from __future__ import annotations

import gzip
import io
import json
import math
from dataclasses import dataclass
from pathlib import Path
from typing import Callable, Iterable, Sequence

import numpy as np

from uam_solvers.base import MwisInputError, MwisProblem

CORPUS_FORMAT = "uam-mwis-corpus/1"

#: size buckets [lo, hi] (vertices) of the committed real corpus: how
#: scripts/make_mwis_corpus.py samples it and ``python -m uam_solvers.bench --real-corpus``
#: reports it
SIZE_BUCKETS = ((2, 14), (15, 64), (65, 250), (251, 500), (501, 1000), (1001, 2000),
                (2001, 10**9))

#: the committed corpus of real planner instances (layered mode), relative to the repository
REAL_CORPUS = "data/mwis/layered-mwis.jsonl.gz"


def size_bucket(n: int) -> int:
    """Index into SIZE_BUCKETS of a graph of ``n`` vertices (-1 below 2)."""
    for i, (lo, hi) in enumerate(SIZE_BUCKETS):
        if lo <= n <= hi:
            return i
    return -1


#: the committed corpus of the planner's rolling-horizon graphs (H = 5 and 10,
#: requests filed 120 s ahead), relative to the repository
HORIZON_CORPUS = "data/mwis/horizon-mwis.jsonl.gz"


def real_corpus_path(name: str = REAL_CORPUS) -> Path:
    """Where a committed real corpus (``REAL_CORPUS`` or ``HORIZON_CORPUS``) is: under the
    current directory or the repository that holds this source file (the bench runs from a
    checkout)."""
    here = Path(__file__).resolve()
    for base in (Path.cwd(), *here.parents):
        cand = base / name
        if cand.is_file():
            return cand
    raise MwisInputError(f"the real corpus {name} was not found under {Path.cwd()} or "
                         f"above {here.parent} (write it with scripts/make_mwis_corpus.py)")

__all__ = [
    "CORPUS_FORMAT",
    "CORPUS_READERS",
    "REAL_CORPUS",
    "HORIZON_CORPUS",
    "SIZE_BUCKETS",
    "real_corpus_path",
    "size_bucket",
    "CorpusEntry",
    "generate_corpus",
    "generate_corpus_entries",
    "large_instance",
    "load_corpus",
    "paper_instance",
    "grouped_random_instance",
    "planner_instance",
    "read_instances",
    "save_corpus",
]


# --------------------------------------------------------------------------------------------
# Generators
# --------------------------------------------------------------------------------------------

def _check_int(name: str, value, minimum: int) -> int:
    if isinstance(value, bool) or not isinstance(value, (int, np.integer)) or value < minimum:
        raise MwisInputError(f"{name} must be an integer >= {minimum}, got {value!r}")
    return int(value)


def _check_prob(name: str, value) -> float:
    value = float(value)
    if not (0.0 <= value <= 1.0):
        raise MwisInputError(f"{name} must be a probability in [0, 1], got {value!r}")
    return value


def _candidate_weights(rng: np.random.Generator, n_requests: int, k: int,
                       detour_max: float) -> np.ndarray:
    """(n_requests, k) weights d*/d: column 0 is 1, the rest strictly decreasing in (0, 1).

    Candidate j's length is d* (1 + sum of j detour increments), each increment uniform in
    [0.02, detour_max] (relative extra length of the next-best diverse route).
    """
    increments = rng.uniform(0.02, detour_max, size=(n_requests, k - 1))
    rel_length = np.concatenate([np.ones((n_requests, 1)),
                                 1.0 + np.cumsum(increments, axis=1)], axis=1)
    return 1.0 / rel_length


def _keep_mask(rng: np.random.Generator, n_requests: int, k: int, n_vertices: int) -> np.ndarray:
    """(n_requests, k) bool: which candidates survive so that exactly n_vertices remain.

    Every request keeps at least one candidate (a request with none is not in the graph).
    """
    total = n_requests * k
    excess = total - n_vertices
    keep = np.ones((n_requests, k), dtype=bool)
    if excess <= 0:
        return keep
    protected = rng.integers(0, k, size=n_requests)  # one candidate per request always survives
    droppable = np.ones((n_requests, k), dtype=bool)
    droppable[np.arange(n_requests), protected] = False
    flat = np.flatnonzero(droppable.ravel())
    drop = rng.choice(flat, size=excess, replace=False)
    keep.ravel()[drop] = False
    return keep


def _conflict_edges(rng: np.random.Generator, pairs: np.ndarray, keep: np.ndarray,
                    conflict_prob: float, block_prob: float, block_fill: float) -> np.ndarray:
    """Conflict edges (in padded candidate indices r*k + j) for interacting request pairs.

    pairs: (P, 2) request indices a < b. Per pair: every candidate pair conflicts independently
    with conflict_prob; with block_prob there is also a block, a random nonempty subset of a's
    candidates (each in with block_fill) times one of b's, all of whose pairs conflict.
    Vectorised over pairs: O(P k^2).
    """
    n_pairs = len(pairs)
    k = keep.shape[1]
    if n_pairs == 0:
        return np.empty((0, 2), dtype=np.int64)
    mask = rng.random((n_pairs, k, k)) < conflict_prob
    has_block = rng.random(n_pairs) < block_prob
    in_a = rng.random((n_pairs, k)) < block_fill
    in_b = rng.random((n_pairs, k)) < block_fill
    # a block touches at least one candidate on each side
    in_a[np.arange(n_pairs), rng.integers(0, k, n_pairs)] = True
    in_b[np.arange(n_pairs), rng.integers(0, k, n_pairs)] = True
    mask |= has_block[:, None, None] & in_a[:, :, None] & in_b[:, None, :]
    a, b = pairs[:, 0], pairs[:, 1]
    mask &= keep[a][:, :, None] & keep[b][:, None, :]
    p, ja, jb = np.nonzero(mask)
    return np.stack([a[p] * k + ja, b[p] * k + jb], axis=1)


def _assemble(weights_padded: np.ndarray, keep: np.ndarray, conflicts_padded: np.ndarray
              ) -> MwisProblem:
    """Drop missing candidates, renumber vertices request by request, build the problem."""
    n_requests, k = keep.shape
    flat_keep = keep.ravel()
    new_index = np.full(n_requests * k, -1, dtype=np.int64)
    new_index[flat_keep] = np.arange(int(flat_keep.sum()))
    weights = weights_padded.ravel()[flat_keep].astype(np.float64)
    edges = new_index[conflicts_padded].reshape(-1, 2)
    edges = np.sort(edges, axis=1)
    edges = np.unique(edges, axis=0) if len(edges) else edges
    counts = keep.sum(axis=1)
    bounds = np.concatenate([[0], np.cumsum(counts)])
    groups = [np.arange(bounds[r], bounds[r + 1], dtype=np.int32) for r in range(n_requests)]
    return MwisProblem.from_arrays(weights, edges.astype(np.int32), groups=groups)


def paper_instance(n_requests: int, seed: int, k: int = 5, conflict_prob: float = 0.25,
                   interaction_prob: float = 0.6, block_prob: float = 0.6,
                   block_fill: float = 0.5, detour_max: float = 0.4,
                   n_vertices: int | None = None) -> MwisProblem:
    """A conflict graph shaped like one planning epoch's (see the module docstring).

    Args:
        n_requests: requests in the epoch (>= 1); one clique group each.
        seed: seed of numpy.random.default_rng; same seed, same instance.
        k: candidate routes per request (paper: 5).
        conflict_prob: probability that two candidates of two *interacting* requests conflict
            on their own (scattered conflicts).
        interaction_prob: probability that two requests interact at all (routes cross in space
            and time); non-interacting requests have no conflict edges.
        block_prob: probability that an interacting pair also has a block of conflicts (a set of
            one request's candidates all conflicting with a set of the other's).
        block_fill: probability that a candidate belongs to a block's set on its side.
        detour_max: relative extra length per next candidate is uniform in [0.02, detour_max];
            weights are d*/d, so candidate j has weight 1 / (1 + sum of j increments).
        n_vertices: if given (n_requests <= n_vertices <= n_requests * k), random candidates
            (never a request's last one) are discarded so exactly this many remain.

    Returns:
        MwisProblem with n_vertices (default n_requests * k) vertices, groups = requests'
        candidate index ranges (in order), edges = conflicts between different requests (the
        group cliques are implied by the groups, see MwisProblem.all_edges).

    Complexity: O(n_requests^2 k^2) time and memory (all request pairs are drawn).
    """
    n_requests = _check_int("n_requests", n_requests, 1)
    k = _check_int("k", k, 1)
    conflict_prob = _check_prob("conflict_prob", conflict_prob)
    interaction_prob = _check_prob("interaction_prob", interaction_prob)
    block_prob = _check_prob("block_prob", block_prob)
    block_fill = _check_prob("block_fill", block_fill)
    if not (detour_max > 0.02 and math.isfinite(detour_max)):
        raise MwisInputError(f"detour_max must be a finite number > 0.02, got {detour_max!r}")
    if n_vertices is None:
        n_vertices = n_requests * k
    n_vertices = _check_int("n_vertices", n_vertices, 1)
    if not (n_requests <= n_vertices <= n_requests * k):
        raise MwisInputError(
            f"n_vertices must lie in [n_requests, n_requests * k] = [{n_requests}, "
            f"{n_requests * k}], got {n_vertices}")
    rng = np.random.default_rng(seed)
    weights = _candidate_weights(rng, n_requests, k, detour_max)
    keep = _keep_mask(rng, n_requests, k, n_vertices)
    a, b = np.triu_indices(n_requests, k=1)
    interacting = rng.random(len(a)) < interaction_prob
    pairs = np.stack([a[interacting], b[interacting]], axis=1)
    conflicts = _conflict_edges(rng, pairs, keep, conflict_prob, block_prob, block_fill)
    return _assemble(weights, keep, conflicts)


def large_instance(n_vertices: int, seed: int, k: int = 5, mean_interactions: float = 8.0,
                   conflict_prob: float = 0.25, block_prob: float = 0.6,
                   block_fill: float = 0.5, detour_max: float = 0.4) -> MwisProblem:
    """A large paper-shaped conflict graph (thousands of vertices) with local interactions.

    ceil(n_vertices / k) requests are placed uniformly in the unit square; two requests interact
    when they are closer than r, with r chosen so that a request interacts with
    `mean_interactions` others on average (pi r^2 n_requests = mean_interactions), which models
    a city-wide network where only nearby flights can conflict. Candidate weights, blocks and
    scattered conflicts are as in `paper_instance`; candidates are discarded at random to reach
    exactly n_vertices.

    Complexity: O(n_requests log n_requests + P k^2) with P ~ n_requests * mean_interactions / 2
    interacting pairs; a 10,000-vertex instance has about 10^5 edges and takes well under a
    second.
    """
    from scipy.spatial import cKDTree

    n_vertices = _check_int("n_vertices", n_vertices, 1)
    k = _check_int("k", k, 1)
    if not (mean_interactions >= 0 and math.isfinite(mean_interactions)):
        raise MwisInputError(
            f"mean_interactions must be a finite number >= 0, got {mean_interactions!r}")
    conflict_prob = _check_prob("conflict_prob", conflict_prob)
    block_prob = _check_prob("block_prob", block_prob)
    block_fill = _check_prob("block_fill", block_fill)
    if not (detour_max > 0.02 and math.isfinite(detour_max)):
        raise MwisInputError(f"detour_max must be a finite number > 0.02, got {detour_max!r}")
    n_requests = -(-n_vertices // k)
    rng = np.random.default_rng(seed)
    weights = _candidate_weights(rng, n_requests, k, detour_max)
    keep = _keep_mask(rng, n_requests, k, n_vertices)
    positions = rng.random((n_requests, 2))
    radius = math.sqrt(mean_interactions / (math.pi * n_requests))
    pairs = cKDTree(positions).query_pairs(radius, output_type="ndarray").astype(np.int64)
    pairs = np.sort(pairs, axis=1)
    # query_pairs returns pairs in an unspecified order; sort so the rng draws are reproducible
    pairs = pairs[np.lexsort((pairs[:, 1], pairs[:, 0]))] if len(pairs) else pairs.reshape(0, 2)
    conflicts = _conflict_edges(rng, pairs, keep, conflict_prob, block_prob, block_fill)
    return _assemble(weights, keep, conflicts)


def grouped_random_instance(n_vertices: int, seed: int, k: int = 5, cross_degree: float = 2.5,
                            detour_max: float = 0.4) -> MwisProblem:
    """A paper-shaped graph as the bounded-solve measurement builds it (BENCHMARKS.md): ceil(n_vertices / k)
    requests of ``k`` candidates (weights d*/d as the planner makes them, one clique group
    each, the clique pairs listed among the edges as the planner lists them) plus random
    conflicts between candidates of different requests, ``cross_degree`` per vertex on average
    (uniform pairs, no locality). With k = 5 and cross degree 2.5 a request interacts with
    ~11 others when the groups are given and a vertex has mean degree ~6.5.
    O(n + m log m).
    """
    n_vertices = _check_int("n_vertices", n_vertices, 1)
    k = _check_int("k", k, 1)
    if not (cross_degree >= 0 and math.isfinite(cross_degree)):
        raise MwisInputError(f"cross_degree must be a finite number >= 0, got {cross_degree!r}")
    n_requests = -(-n_vertices // k)
    rng = np.random.default_rng(seed)
    weights = _candidate_weights(rng, n_requests, k, detour_max)
    keep = _keep_mask(rng, n_requests, k, n_vertices)
    base = _assemble(weights, keep, np.empty((0, 2), dtype=np.int64))
    n = base.n
    m = int(round(cross_degree * n / 2))
    u = rng.integers(0, n, size=m)
    v = rng.integers(0, n, size=m)
    req = np.zeros(n, dtype=np.int64)
    for r, g in enumerate(base.groups):
        req[g] = r
    if len(base.groups) < n:  # requests of one candidate have no group
        ungrouped = np.ones(n, dtype=bool)
        for g in base.groups:
            ungrouped[g] = False
        req[ungrouped] = len(base.groups) + np.arange(int(ungrouped.sum()))
    cross = np.stack([u, v], axis=1)[req[u] != req[v]]
    return MwisProblem.from_arrays(base.weights, np.concatenate([base.all_edges(), cross]),
                                   groups=list(base.groups))


def planner_instance(n_vertices: int, seed: int, k: int = 5, mean_interactions: float = 2.0,
                     **options) -> MwisProblem:
    """A paper-shaped conflict graph with the sparse interactions the planner produces.

    `large_instance` with ``mean_interactions`` = 2 (a request conflicts with two others on
    average) instead of 8: measured on the planner's own instances (scripts/
    measure_system_airspace.py, BENCHMARKS.md), a request interacts with 1.5 others
    (median; max 6.7) in Singapore layered at 20 requests per 30 s and with 1.6 (max 3.6) in a
    2,000-node city at 3,000 requests/h. Requests are cliques of ``k`` candidates; other
    arguments go to `large_instance`.
    """
    return large_instance(n_vertices, seed, k=k, mean_interactions=mean_interactions, **options)


# --------------------------------------------------------------------------------------------
# Corpus
# --------------------------------------------------------------------------------------------

@dataclass(frozen=True)
class CorpusEntry:
    """One instance of a corpus: a name, the problem, where it came from, its optimum if known.

    optimum is the proven maximum total weight (float), or None when unknown.
    """

    name: str
    problem: MwisProblem
    source: str = ""
    optimum: float | None = None


def generate_corpus_entries(n_instances: int, min_vertices: int = 5, max_vertices: int = 50,
                            seed: int = 0, k: int = 5, **instance_options) -> list[CorpusEntry]:
    """Seeded paper-shaped instances with sizes spread evenly over [min_vertices, max_vertices].

    Instance sizes are min + floor(i * span / N) for i < N (span = max - min + 1), shuffled: 600
    instances of 5..50 vertices hold each size 13 or 14 times, and 12 instances still span the
    range (5, 8, 12, ..., 47). Instance i has n_vertices v_i and ceil(v_i / k) requests
    (1 to 10 for 5..50 vertices with k = 5) and its own seed spawned from `seed`.
    instance_options go to `paper_instance`. Names are "paper-<seed>-<i>-v<v_i>".

    Complexity: O(n_instances * max_vertices^2).
    """
    n_instances = _check_int("n_instances", n_instances, 0)
    min_vertices = _check_int("min_vertices", min_vertices, 1)
    max_vertices = _check_int("max_vertices", max_vertices, min_vertices)
    rng = np.random.default_rng(seed)
    span = max_vertices - min_vertices + 1
    # evenly spread: instance i gets size min + floor(i * span / N), then shuffled
    sizes = rng.permutation(min_vertices + (np.arange(n_instances) * span) // max(n_instances, 1))
    child_seeds = np.random.SeedSequence(seed).generate_state(max(n_instances, 1), dtype=np.uint32)
    entries = []
    for i, (size, child) in enumerate(zip(sizes.tolist(), child_seeds.tolist())):
        n_requests = -(-size // k)
        problem = paper_instance(n_requests, int(child), k=k, n_vertices=size,
                                 **instance_options)
        opts = "".join(f", {key}={value!r}" for key, value in sorted(instance_options.items()))
        source = (f"uam_solvers.instances.paper_instance(n_requests={n_requests}, "
                  f"seed={child}, k={k}, n_vertices={size}{opts})")
        entries.append(CorpusEntry(name=f"paper-{seed}-{i:04d}-v{size}", problem=problem,
                                   source=source))
    return entries


def generate_corpus(n_instances: int, min_vertices: int = 5, max_vertices: int = 50,
                    seed: int = 0, **instance_options) -> list[MwisProblem]:
    """The problems of `generate_corpus_entries` (same arguments, same instances)."""
    return [entry.problem for entry in generate_corpus_entries(
        n_instances, min_vertices, max_vertices, seed, **instance_options)]


def _entry_to_json(entry: CorpusEntry) -> str:
    problem = entry.problem
    record = {
        "format": CORPUS_FORMAT,
        "name": entry.name,
        "weights": [float(w) for w in problem.weights],
        "edges": np.asarray(problem.edges, dtype=np.int64).reshape(-1, 2).tolist(),
        "groups": [np.asarray(g, dtype=np.int64).tolist() for g in problem.groups],
        "source": entry.source,
    }
    if entry.optimum is not None:
        record["optimum"] = float(entry.optimum)
    # json writes floats with repr, so weights round-trip exactly
    return json.dumps(record, separators=(",", ":"), allow_nan=False)


def save_corpus(path: str | Path, problems: Sequence[MwisProblem | CorpusEntry],
                names: Sequence[str] | None = None, sources: Sequence[str] | None = None,
                optima: Sequence[float | None] | None = None) -> Path:
    """Write instances as JSON Lines (one instance per line, format in docs/mwis-corpus-format.md);
    a path ending in ``.gz`` is written gzip-compressed (reproducible bytes).

    problems: MwisProblem or CorpusEntry items; names/sources/optima (same length) override the
    entries' fields; default names are "instance-<i>". Returns the path written. Names must be
    unique. Complexity: O(total size).
    """
    path = Path(path)
    entries = []
    for i, item in enumerate(problems):
        entry = item if isinstance(item, CorpusEntry) else CorpusEntry(f"instance-{i:04d}", item)
        entries.append(entry)
    for field, values in (("names", names), ("sources", sources), ("optima", optima)):
        if values is not None and len(values) != len(entries):
            raise MwisInputError(
                f"{field} has {len(values)} items but there are {len(entries)} problems")
    entries = [CorpusEntry(name=names[i] if names is not None else e.name,
                           problem=e.problem,
                           source=sources[i] if sources is not None else e.source,
                           optimum=optima[i] if optima is not None else e.optimum)
               for i, e in enumerate(entries)]
    seen = set()
    for entry in entries:
        if entry.name in seen:
            raise MwisInputError(f"names must be unique, {entry.name!r} appears twice")
        seen.add(entry.name)
    path.parent.mkdir(parents=True, exist_ok=True)
    with _open_text(path, "w") as handle:
        for entry in entries:
            handle.write(_entry_to_json(entry))
            handle.write("\n")
    return path


def _open_text(path: Path, mode: str):
    """A text handle on ``path``; a name ending in ``.gz`` is gzip-compressed (written with no
    time stamp or file name in the header, so the same corpus gives the same bytes)."""
    if path.suffix.lower() != ".gz":
        return path.open(mode, encoding="utf-8")
    if mode == "w":
        raw = path.open("wb")
        gz = gzip.GzipFile(filename="", mode="wb", fileobj=raw, mtime=0, compresslevel=9)

        class _Closing(io.TextIOWrapper):
            def close(self) -> None:  # closes the gzip stream, then the file under it
                super().close()
                raw.close()

        return _Closing(gz, encoding="utf-8")
    return io.TextIOWrapper(gzip.open(path, "rb"), encoding="utf-8")


def _entry_from_json(line: str, where: str) -> CorpusEntry:
    try:
        record = json.loads(line)
    except json.JSONDecodeError as exc:
        raise MwisInputError(f"{where}: not valid JSON ({exc})") from None
    if not isinstance(record, dict):
        raise MwisInputError(f"{where}: expected a JSON object, got {type(record).__name__}")
    fmt = record.get("format", CORPUS_FORMAT)
    if fmt != CORPUS_FORMAT:
        raise MwisInputError(f"{where}: field 'format' is {fmt!r}, expected {CORPUS_FORMAT!r}")
    for field in ("name", "weights", "edges"):
        if field not in record:
            raise MwisInputError(f"{where}: missing field {field!r}")
    name = record["name"]
    if not isinstance(name, str) or not name:
        raise MwisInputError(f"{where}: field 'name' must be a nonempty string, got {name!r}")
    try:
        weights = np.asarray(record["weights"], dtype=np.float64).reshape(-1)
        edges = np.asarray(record["edges"], dtype=np.int64).reshape(-1, 2)
    except (TypeError, ValueError) as exc:
        raise MwisInputError(f"{where} ({name}): bad 'weights' or 'edges': {exc}") from None
    groups = record.get("groups") or None
    if groups is not None:
        if not isinstance(groups, list):
            raise MwisInputError(f"{where} ({name}): field 'groups' must be a list of lists")
        groups = [np.asarray(g, dtype=np.int64).reshape(-1) for g in groups]
    try:
        problem = MwisProblem.from_arrays(weights, edges, groups=groups)
    except MwisInputError as exc:
        raise MwisInputError(f"{where} ({name}): {exc}") from None
    optimum = record.get("optimum")
    if optimum is not None:
        if isinstance(optimum, bool) or not isinstance(optimum, (int, float)) \
                or not math.isfinite(optimum):
            raise MwisInputError(
                f"{where} ({name}): field 'optimum' must be a finite number, got {optimum!r}")
        optimum = float(optimum)
    source = record.get("source", "")
    if not isinstance(source, str):
        raise MwisInputError(f"{where} ({name}): field 'source' must be a string, got {source!r}")
    return CorpusEntry(name=name, problem=problem, source=source, optimum=optimum)


def load_corpus(path: str | Path) -> list[CorpusEntry]:
    """Read a JSON Lines corpus written by `save_corpus` (or by hand, same format); a path
    ending in ``.gz`` is read as gzip-compressed JSON Lines.

    Blank lines are skipped. Every instance is validated by MwisProblem.from_arrays; an error
    names the file, the line number, the instance and the field. Complexity: O(file size).
    """
    path = Path(path)
    entries = []
    seen = set()
    with _open_text(path, "r") as handle:
        for line_no, line in enumerate(handle, start=1):
            if not line.strip():
                continue
            entry = _entry_from_json(line, f"{path}:{line_no}")
            if entry.name in seen:
                raise MwisInputError(f"{path}:{line_no}: duplicate instance name {entry.name!r}")
            seen.add(entry.name)
            entries.append(entry)
    return entries


def _read_mcap(path: Path) -> list[CorpusEntry]:
    """MWIS instances of a planner recording (the PlanningReports' instances, one per epoch).

    The recording format belongs to uam_sim, which depends on this package: uam_sim provides the
    reader as the entry point ``mcap`` of group ``uam_solvers.corpus_readers`` (its setup.py), so
    this package finds it at run time without importing a package above it.
    """
    from importlib.metadata import entry_points

    found = list(entry_points(group="uam_solvers.corpus_readers", name="mcap"))
    if not found:
        raise MwisInputError(f"{path}: reading .mcap recordings needs the uam_sim package "
                             "(no 'mcap' entry point in group 'uam_solvers.corpus_readers')")
    return found[0].load()(path)


#: Readers by file suffix for `read_instances` (extension point: reader(path) -> list[CorpusEntry]).
CORPUS_READERS: dict[str, Callable[[Path], list[CorpusEntry]]] = {
    ".jsonl": load_corpus,
    ".json": load_corpus,
    ".gz": load_corpus,  # .jsonl.gz: gzip-compressed JSON Lines
    ".mcap": _read_mcap,
}


def read_instances(path: str | Path) -> list[CorpusEntry]:
    """Read instances from any file type registered in CORPUS_READERS (by suffix)."""
    path = Path(path)
    reader = CORPUS_READERS.get(path.suffix.lower())
    if reader is None:
        raise MwisInputError(
            f"no corpus reader for suffix {path.suffix!r} of {path}; known: "
            f"{sorted(CORPUS_READERS)}")
    return reader(path)


def corpus_summary(entries: Iterable[CorpusEntry]) -> dict:
    """Counts for printing: instances, vertex range, mean edges (all_edges incl. cliques)."""
    sizes = []
    edges = []
    for entry in entries:
        sizes.append(entry.problem.n)
        edges.append(len(entry.problem.all_edges()))
    if not sizes:
        return {"instances": 0}
    return {"instances": len(sizes), "min_vertices": int(min(sizes)),
            "max_vertices": int(max(sizes)), "mean_edges": float(np.mean(edges))}
