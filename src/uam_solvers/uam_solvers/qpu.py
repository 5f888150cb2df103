"""Quantum annealing backends: a D-Wave Advantage QPU ("qpu") and its offline emulator.

Pipeline (both backends, `embedded_solve`):

1. the MWIS QUBO of `uam_solvers.qubo` (lambda = 2) as a dimod BQM over variables 0..n-1;
2. minor embedding onto the sampler's graph with minorminer, inside dwave-system's
   EmbeddingComposite. minorminer is seeded (option embedding_seed, default 0, independent of
   the solve seed so one graph always gets the same embedding) and its embeddings are cached per
   (graph structure, target graph, embedding parameters) for the life of the process, because
   finding one takes seconds for a 50-vertex conflict graph on Pegasus P16;
3. chain strength: dwave-system's `uniform_torque_compensation` (prefactor 1.414, the Ocean
   default): sqrt(mean squared coupling x mean degree) x prefactor, strong enough to keep chains
   intact without flattening the problem's energy scale under the QPU's auto-scaling. A number
   in option chain_strength overrides it;
4. sampling: annealing_time 1 us, 100 reads (paper), parameters passed only when the sampler
   declares them in its `parameters`;
5. unembedding with majority-vote chain-break resolution; then every read is refined by one-flip
   steepest descent and repaired into an independent set, and the best read is returned.

Statistics: those of `refine_and_repair` (reads, feasible and optimal fractions, ...), chain
lengths (max, mean), qubits used, chain strength, chain-break fraction (mean fraction of broken
chains per read) and the fraction of reads with any broken chain, plus timing:

* `qpu`: the sampler's own timing from sampleset.info["timing"] in microseconds (QPU access,
  programming, anneal time per sample, sampling, readout per sample, ...) as stats
  "qpu_<key>_us"; when the sampler reports none, stats["qpu_timing"] says so;
* `qpu-emulator`: never reports QPU times: stats["qpu_timing"] = "none (emulator)".

Availability of `qpu`: a D-Wave token in DWAVE_API_TOKEN or a dwave-cloud-client configuration
file (`dwave config create`); otherwise `available()` is (False, NO_TOKEN_MESSAGE) and `solve`
raises BackendUnavailable with that text before any network call. The sampler is injectable
(constructor argument or option sampler_factory, a callable returning a structured dimod
sampler), so tests run the whole pipeline with `AdvantageStandInSampler`, a clearly named
stand-in on the real Advantage topology.

Topology note: an Advantage system is a Pegasus P16 graph (5,640 qubits, 40,484 couplers in the
ideal graph), but every real chip has a few inactive qubits and couplers; the stand-in and the
emulator use the ideal graph unless given `missing_qubits`, so an embedding found here may use
qubits that a given QPU lacks (the `qpu` backend embeds on the live chip's own graph).
"""

from __future__ import annotations

import functools
import hashlib
import os
import threading
import time
from typing import Any, Callable, Iterable, Mapping

import dimod
import numpy as np

from uam_solvers.annealing import (COMMON_OPTIONS_SPEC, _float_option, _int_option, _positive,
                                   common_options, given, sampleset_to_array)
from uam_solvers.options import Option
from uam_solvers.base import (
    Backend,
    BackendUnavailable,
    MwisInputError,
    MwisProblem,
    MwisResult,
    make_result,
)
from uam_solvers.qubo import mwis_qubo, refine_and_repair

__all__ = [
    "ADVANTAGE_PEGASUS_SIZE",
    "AdvantageStandInSampler",
    "NO_TOKEN_MESSAGE",
    "QpuBackend",
    "QpuEmulatorBackend",
    "advantage_graph",
    "cached_find_embedding",
    "dwave_token_configured",
    "embedded_solve",
]

ADVANTAGE_PEGASUS_SIZE = 16
DEFAULT_ANNEALING_TIME_US = 1.0
DEFAULT_CHAIN_STRENGTH_PREFACTOR = 1.414
NO_TOKEN_MESSAGE = "no D-Wave token: set DWAVE_API_TOKEN or run `dwave config create`"

_QPU_OPTIONS = {"annealing_time_us", "chain_strength", "chain_strength_prefactor",
                "embedding_seed", "embedding_timeout_s", "embedding_tries", "sampler_factory",
                "solver", "num_sweeps"}


def _chain_strength(value):
    if value in ("uniform_torque_compensation", "utc"):
        return value
    if isinstance(value, bool) or not isinstance(value, (int, float)) or not (
            np.isfinite(value) and value > 0):
        raise ValueError("must be 'uniform_torque_compensation' or a finite number > 0")
    return float(value)


def _callable(value):
    if not callable(value):
        raise ValueError("must be callable (returning a structured dimod sampler)")
    return value


#: Options of the embedding pipeline shared by qpu and qpu-emulator.
EMBEDDED_OPTIONS_SPEC = {
    **COMMON_OPTIONS_SPEC,
    "chain_strength": Option("chain_strength", "any", "uniform_torque_compensation",
                             "chain coupling: a number or 'uniform_torque_compensation'",
                             validator=_chain_strength),
    "chain_strength_prefactor": Option("chain_strength_prefactor", "float",
                                       1.414, "prefactor of uniform torque compensation",
                                       validator=_positive),
    "embedding_seed": Option("embedding_seed", "int", 0, "minorminer random seed", lo=0,
                             hi=2**31 - 1),
    "embedding_timeout_s": Option("embedding_timeout_s", "float", None, "minorminer timeout "
                                  "(None: max(1, time limit))", nullable=True, lo=0.001,
                                  hi=86_400.0),
    "embedding_tries": Option("embedding_tries", "int", 10, "minorminer tries", lo=1, hi=1000),
    "max_direct_vertices": Option("max_direct_vertices", "int", 100, "larger graphs are "
                                  "decomposed into subproblems instead of embedded whole",
                                  lo=1, hi=100_000),
}

# --------------------------------------------------------------------------------------------
# Topology and the stand-in sampler
# --------------------------------------------------------------------------------------------

@functools.lru_cache(maxsize=4)
def _pegasus_structure(size: int, missing: tuple[int, ...]) -> tuple[tuple, tuple]:
    try:
        from dwave.graphs import pegasus_graph  # Ocean >= 9.x; dwave_networkx is deprecated
    except ImportError:  # pragma: no cover - older Ocean
        from dwave_networkx import pegasus_graph
    graph = pegasus_graph(size)
    if missing:
        graph.remove_nodes_from(missing)
    nodes = tuple(sorted(graph.nodes))
    edges = tuple(sorted((min(u, v), max(u, v)) for u, v in graph.edges))
    return nodes, edges


def advantage_graph(missing_qubits: Iterable[int] = ()) -> tuple[list[int], list[tuple[int, int]]]:
    """(nodes, edges) of the ideal Advantage topology, Pegasus P16 (5,640 qubits, 40,484
    couplers), minus `missing_qubits` (real chips lack a few). Cached per process."""
    nodes, edges = _pegasus_structure(ADVANTAGE_PEGASUS_SIZE, tuple(sorted(set(missing_qubits))))
    return list(nodes), list(edges)


class AdvantageStandInSampler(dimod.Sampler, dimod.Structured):
    """STAND-IN for dwave.system.DWaveSampler: simulated annealing on the Advantage graph.

    NOT a quantum annealer. It exists so the `qpu` pipeline (embedding, chain strength,
    parameters, unembedding, chain-break statistics, descent, repair) runs in tests and CI
    without hardware. Its surface mirrors DWaveSampler: `properties` (topology, qubits, couplers,
    annealing_time_range, num_reads_range, h_range, j_range, chip_id), `parameters`,
    `nodelist`, `edgelist`, `adjacency`, and `sample(bqm, num_reads=..., annealing_time=...)`,
    which checks the BQM fits the graph and the parameters are in range, then runs simulated
    annealing (annealing_time is only checked and recorded, it has no physical meaning here).

    Every call's parameters are appended to `calls` so tests can assert what the pipeline passed.
    It returns no timing information unless `timing` is given (a dict, for a test that checks the
    pipeline copies a sampler's timing into its statistics); then it is returned as
    info["timing"] verbatim, and info["stand_in"] is always True. Beyond DWaveSampler's
    parameters it accepts `seed` (so runs are reproducible) and `num_sweeps`.

    missing_qubits: qubits to remove, to mimic a real chip's inactive qubits.
    """

    def __init__(self, missing_qubits: Iterable[int] = (), num_sweeps: int = 1000,
                 timing: Mapping[str, float] | None = None):
        self._nodelist, self._edgelist = advantage_graph(missing_qubits)
        self.num_sweeps = int(num_sweeps)
        self.timing = dict(timing) if timing is not None else None
        self.calls: list[dict] = []
        self._nodes = set(self._nodelist)
        self._edges = set(self._edgelist)
        self._properties = {
            "chip_id": "AdvantageStandInSampler (simulated annealing, not a QPU)",
            "stand_in": True,
            "topology": {"type": "pegasus", "shape": [ADVANTAGE_PEGASUS_SIZE]},
            "qubits": self._nodelist,
            "couplers": [list(e) for e in self._edgelist],
            "num_qubits": ADVANTAGE_PEGASUS_SIZE * (ADVANTAGE_PEGASUS_SIZE - 1) * 24,
            "annealing_time_range": [0.5, 2000.0],
            "default_annealing_time": 20.0,
            "num_reads_range": [1, 10000],
            "h_range": [-4.0, 4.0],
            "j_range": [-1.0, 1.0],
            "extended_j_range": [-2.0, 1.0],
        }
        self._parameters = {
            "num_reads": ["num_reads_range"],
            "annealing_time": ["annealing_time_range"],
            "answer_mode": [],
            "auto_scale": [],
            "seed": [],
            "num_sweeps": [],
        }

    @property
    def nodelist(self) -> list:
        return self._nodelist

    @property
    def edgelist(self) -> list:
        return self._edgelist

    @property
    def properties(self) -> dict:
        return self._properties

    @property
    def parameters(self) -> dict:
        return self._parameters

    def sample(self, bqm, num_reads: int = 1, annealing_time: float | None = None,
               seed: int | None = None, num_sweeps: int | None = None, **parameters):
        from dwave.samplers import SimulatedAnnealingSampler

        unknown = set(parameters) - set(self.parameters)
        if unknown:
            raise ValueError(f"AdvantageStandInSampler: unknown parameters {sorted(unknown)}")
        low, high = self.properties["num_reads_range"]
        if not (low <= num_reads <= high):
            raise ValueError(f"num_reads={num_reads} is outside num_reads_range {[low, high]}")
        if annealing_time is not None:
            low, high = self.properties["annealing_time_range"]
            if not (low <= annealing_time <= high):
                raise ValueError(
                    f"annealing_time={annealing_time} us is outside {[low, high]}")
        for v in bqm.variables:
            if v not in self._nodes:
                raise dimod.exceptions.BinaryQuadraticModelStructureError(
                    f"variable {v!r} is not a qubit of the Advantage graph")
        for u, v in bqm.quadratic:
            if (min(u, v), max(u, v)) not in self._edges:
                raise dimod.exceptions.BinaryQuadraticModelStructureError(
                    f"interaction ({u!r}, {v!r}) is not a coupler of the Advantage graph")
        self.calls.append(dict(num_reads=num_reads, annealing_time=annealing_time, seed=seed,
                               num_qubits=bqm.num_variables, **parameters))
        sampleset = SimulatedAnnealingSampler().sample(
            bqm, num_reads=num_reads, seed=seed,
            num_sweeps=self.num_sweeps if num_sweeps is None else num_sweeps)
        info = {"stand_in": True}
        if self.timing is not None:
            info["timing"] = dict(self.timing)
        return dimod.SampleSet(sampleset.record, sampleset.variables, info, sampleset.vartype)


def _emulator_sampler(missing_qubits: Iterable[int] = ()):
    """dimod.StructureComposite(SimulatedAnnealingSampler) on the Advantage graph."""
    from dwave.samplers import SimulatedAnnealingSampler

    nodes, edges = advantage_graph(missing_qubits)
    sampler = dimod.StructureComposite(SimulatedAnnealingSampler(), nodes, edges)
    sampler.pegasus_shape = ADVANTAGE_PEGASUS_SIZE  # its properties carry no topology
    return sampler


# --------------------------------------------------------------------------------------------
# Embedding cache
# --------------------------------------------------------------------------------------------

_EMBEDDING_CACHE: dict[tuple, dict] = {}
_TARGET_KEYS: dict[int, tuple[Any, str]] = {}
_CACHE_LOCK = threading.Lock()
_EMBEDDING_CACHE_MAX = 256


def _target_key(target_edgelist) -> str:
    """Digest of a target graph, memoised by object (the object is kept so its id stays unique)."""
    entry = _TARGET_KEYS.get(id(target_edgelist))
    if entry is not None and entry[0] is target_edgelist:
        return entry[1]
    edges = np.sort(np.asarray(list(target_edgelist), dtype=np.int64).reshape(-1, 2), axis=1)
    edges = edges[np.lexsort((edges[:, 1], edges[:, 0]))]
    digest = hashlib.sha1(edges.tobytes()).hexdigest()
    _TARGET_KEYS[id(target_edgelist)] = (target_edgelist, digest)
    return digest


def cached_find_embedding(source_edgelist, target_edgelist, **parameters) -> dict:
    """minorminer.find_embedding, memoised per (source graph, target graph, parameters).

    Same signature as minorminer.find_embedding, so it plugs into EmbeddingComposite. Results
    depend only on the graphs and parameters (random_seed included) unless minorminer's timeout
    binds. An empty embedding (failure) is not cached.
    """
    import minorminer

    source = sorted({(min(u, v), max(u, v)) for u, v in source_edgelist})
    key = (tuple(source), _target_key(target_edgelist), tuple(sorted(parameters.items())))
    with _CACHE_LOCK:
        if key in _EMBEDDING_CACHE:
            return {v: list(chain) for v, chain in _EMBEDDING_CACHE[key].items()}
    embedding = minorminer.find_embedding(source_edgelist, target_edgelist, **parameters)
    embedding = {v: list(chain) for v, chain in embedding.items()}
    if embedding:
        with _CACHE_LOCK:
            if len(_EMBEDDING_CACHE) >= _EMBEDDING_CACHE_MAX:
                _EMBEDDING_CACHE.pop(next(iter(_EMBEDDING_CACHE)))
            _EMBEDDING_CACHE[key] = embedding
    return {v: list(chain) for v, chain in embedding.items()}


# --------------------------------------------------------------------------------------------
# The shared pipeline
# --------------------------------------------------------------------------------------------

_TIMING_KEYS = ("qpu_access_time", "qpu_programming_time", "qpu_anneal_time_per_sample",
                "qpu_sampling_time", "qpu_readout_time_per_sample",
                "qpu_delay_time_per_sample", "qpu_access_overhead_time",
                "total_post_processing_time", "post_processing_overhead_time")


#: graphs above this many vertices are decomposed rather than embedded whole: minorminer held
#: the GIL for 26 s on a 10,000-vertex graph, and conflict graphs much above ~100 vertices
#: (cliques of 5 plus conflicts) rarely embed on P16 within seconds
QPU_DIRECT_MAX_VERTICES = 100
#: vertices per subproblem when decomposing for the QPU (embeds within ~1 s)
QPU_SUBPROBLEM_SIZE = 30


def fits_target(problem: MwisProblem, child) -> tuple[bool, str]:
    """Necessary conditions for an embedding on the child's graph: at most as many vertices as
    qubits and edges as couplers (a minor has no more of either). (True, "") or (False, why)."""
    qubits = len(getattr(child, "nodelist", ()) or ())
    couplers = len(getattr(child, "edgelist", ()) or ())
    m = int(problem.all_edges().shape[0])
    if qubits and problem.n > qubits:
        return False, f"{problem.n} vertices > {qubits} qubits of the target graph: cannot embed"
    if couplers and m > couplers:
        return False, f"{m} edges > {couplers} couplers of the target graph: cannot embed"
    return True, ""


_REGIONS: dict[int, tuple[Any, list]] = {}


def embedding_region(child, rows: int = 4) -> list:
    """Couplers of a corner of the child's Pegasus graph (``rows`` x ``rows`` unit cells: about
    370 qubits of P16), the target of subproblem embeddings: minorminer embeds a 30-vertex
    conflict subgraph there in ~0.5 s under load, where the whole 5,640-qubit graph made every
    embedding of the decomposition time out. Other topologies: the whole edge list. Cached
    per child object."""
    entry = _REGIONS.get(id(child))
    if entry is not None and entry[0] is child:
        return entry[1]
    edges = list(child.edgelist)
    topology = (getattr(child, "properties", {}) or {}).get("topology", {})
    if not topology and hasattr(child, "pegasus_shape"):
        topology = {"type": "pegasus", "shape": [child.pegasus_shape]}
    if topology.get("type") == "pegasus":
        try:
            from dwave.graphs import pegasus_coordinates
        except ImportError:  # pragma: no cover - older Ocean
            from dwave_networkx import pegasus_coordinates
        coords = pegasus_coordinates(int(topology["shape"][0]))
        keep = set()
        for v in child.nodelist:
            u, w, k, z = coords.linear_to_pegasus(v)
            if w < rows and z < rows:
                keep.add(v)
        edges = [(a, b) for a, b in edges if a in keep and b in keep]
    _REGIONS[id(child)] = (child, edges)
    return edges


_CLIQUES: dict[tuple[int, int], tuple[Any, dict | None]] = {}


def clique_embedding(child, size: int) -> dict | None:
    """A minorminer ``busclique`` embedding of the complete graph K_size into the child's
    Pegasus graph (variable i -> chain of qubits), or None (other topologies, no embedding).

    Every subproblem of at most ``size`` vertices is a subgraph of K_size, so this one embedding
    serves them all: measured here 0.2 s once (graph + busclique, chains of at most 4 qubits for
    K_30 on P16) where minorminer took ~0.4-1 s per subproblem under load, so that only 2-7
    subproblems fitted in 1-5 s and none improved the greedy start (BENCHMARKS.md).
    Cached per child object and size."""
    key = (id(child), int(size))
    entry = _CLIQUES.get(key)
    if entry is not None and entry[0] is child:
        return entry[1]
    emb = None
    topology = (getattr(child, "properties", {}) or {}).get("topology", {})
    if not topology and hasattr(child, "pegasus_shape"):  # the emulator's StructureComposite
        topology = {"type": "pegasus", "shape": [child.pegasus_shape]}
    if topology.get("type") == "pegasus":
        try:
            from minorminer import busclique
            try:
                from dwave.graphs import pegasus_graph
            except ImportError:  # pragma: no cover - older Ocean
                from dwave_networkx import pegasus_graph
            g = pegasus_graph(int(topology["shape"][0]), node_list=list(child.nodelist),
                              edge_list=[tuple(e) for e in child.edgelist],
                              check_node_list=False, check_edge_list=False)
            found = busclique.find_clique_embedding(int(size), g, use_cache=False)
            if found and len(found) == int(size):
                emb = {int(v): [int(q) for q in chain] for v, chain in found.items()}
        except Exception:  # noqa: BLE001 - no clique embedding: per-subproblem minorminer
            emb = None
    _CLIQUES[key] = (child, emb)
    return emb


def _decomposed_embedded(problem, child, *, backend, seed, time_limit_s, started, parsed,
                         options, passed, chain_strength, embedding_parameters, reason):
    """Energy-impact decomposition (uam_solvers.decompose) with every subproblem embedded and
    sampled on ``child``; each embedding gets at most the time left."""
    from dwave.embedding.chain_breaks import majority_vote
    from dwave.system import FixedEmbeddingComposite

    from uam_solvers.decompose import decomposed_solve

    deadline = started + time_limit_s
    sub_params = dict(passed)
    sub_params["num_reads"] = min(int(parsed["num_reads"]), 20)  # per subproblem
    stats_box = {"embedding_failures": 0}

    region = embedding_region(child)
    region_qubits = sorted({q for e in region for q in e})
    size = options.get("subproblem_size", QPU_SUBPROBLEM_SIZE)
    clique = clique_embedding(child, size)
    stats_box["clique_embedding"] = clique is not None

    def sample_embedded(sub_bqm, sub_seed, embedding):
        """Sample a subproblem on a fixed embedding (None when the embedding does not fit it)."""
        params = dict(sub_params)
        if "seed" in params:
            params["seed"] = sub_seed
        try:
            return FixedEmbeddingComposite(child, embedding=embedding).sample(
                sub_bqm, chain_strength=chain_strength, chain_break_method=majority_vote,
                **params)
        except ValueError:
            stats_box["embedding_failures"] += 1
            return None

    def sample_sub(sub_bqm, sub_seed, remaining_s):
        if clique is not None:
            # the subproblem's variables are 0..k-1 with k <= size: K_size's chains cover it
            return sample_embedded(sub_bqm, sub_seed, {v: clique[int(v)] for v in sub_bqm.variables})
        emb = dict(embedding_parameters)
        # minorminer holds the GIL and uses its whole timeout; sampling needs the rest
        emb["timeout"] = max(min(float(emb["timeout"]), 0.3 * remaining_s, 1.0), 0.01)
        emb["tries"] = 1
        source = [(u, v) for u, v in sub_bqm.quadratic]
        embedding = cached_find_embedding(source, region, **emb) if source else {}
        if source and not embedding:  # no embedding within the time left: skip it
            stats_box["embedding_failures"] += 1
            return None
        used = {q for chain in embedding.values() for q in chain}
        free = iter(q for q in region_qubits if q not in used)
        for v in sub_bqm.variables:  # isolated variables are not in minorminer's answer
            if v not in embedding:
                q = next(free, None)
                if q is None:
                    stats_box["embedding_failures"] += 1
                    return None
                embedding[v] = [q]
        return sample_embedded(sub_bqm, sub_seed, embedding)

    budget = max(deadline - time.perf_counter() - 0.05 - 1e-5 * problem.n, 1e-3)
    selected, stats = decomposed_solve(problem, sample_sub, size=size, time_limit_s=budget,
                                       seed=int(seed) % 2**32, lam=parsed["lambda"],
                                       # an embedding + anneal takes ~0.5-1 s under load
                                       # (an anneal alone, with the clique embedding, ~0.1 s):
                                       # none is started that could not finish
                                       min_iteration_s=min(0.15 if clique else 0.6,
                                                           0.3 * budget))
    stats.update({
        "lambda": parsed["lambda"], "decomposition_reason": reason,
        "embedding_failures": stats_box["embedding_failures"],
        "clique_embedding": int(stats_box["clique_embedding"]),
        "sampler": type(child).__name__,
        "sampler_is_stand_in": bool(getattr(child, "properties", {}).get("stand_in", False)),
        "qpu_timing": "none (decomposed; per-subproblem timing not aggregated)",
    })
    return make_result(problem, selected, proven_optimal=False,
                       solve_time_s=time.perf_counter() - started, backend=backend, stats=stats)


def _chain_strength_choice(options: Mapping[str, Any]) -> tuple[Any, str]:
    """The chain strength to pass dwave-system and its rule's name for the statistics: the
    uniform torque compensation (with the option's prefactor) unless a number is given."""
    from dwave.embedding.chain_strength import uniform_torque_compensation

    prefactor = _float_option(options, "chain_strength_prefactor",
                              DEFAULT_CHAIN_STRENGTH_PREFACTOR)
    chain_strength_option = options.get("chain_strength", "uniform_torque_compensation")
    if chain_strength_option in ("uniform_torque_compensation", "utc", None):
        chain_strength = functools.partial(uniform_torque_compensation, prefactor=prefactor)
        return chain_strength, f"uniform_torque_compensation(prefactor={prefactor})"
    return _float_option(options, "chain_strength", None), "fixed"


def _embedding_parameters(options: Mapping[str, Any], time_limit_s: float) -> dict:
    """minorminer's parameters from the options: seed, timeout (half the limit by default) and
    tries."""
    return {
        "random_seed": _int_option(options, "embedding_seed", 0, 0),
        # half the limit by default (it was max(1, limit): minorminer uses its whole timeout,
        # so a 1 s limit ran to 1.4 s and was killed; the backend contract test)
        "timeout": _float_option(options, "embedding_timeout_s", max(0.5 * float(time_limit_s), 0.05)),
        "tries": _int_option(options, "embedding_tries", 10, 1),
    }


def _declared_parameters(child, parsed: Mapping[str, Any], sampler_parameters: Mapping[str, Any],
                         seed: int) -> tuple[dict, list[str]]:
    """The wanted sampler parameters split into those ``child`` declares (passed) and the names
    of those it does not (reported, never passed: a sampler refuses unknown parameters)."""
    params = {"num_reads": parsed["num_reads"], **sampler_parameters}
    declared = getattr(child, "parameters", {}) or {}
    if "seed" in declared:
        params["seed"] = int(seed) % 2**32
    passed = {k: v for k, v in params.items() if k in declared}
    not_passed = sorted(k for k in params if k not in declared)
    return passed, not_passed


def _sample_direct(problem: MwisProblem, child, bqm, *, backend: str, chain_strength,
                   embedding_parameters: Mapping[str, Any], passed: Mapping[str, Any]):
    """Embed ``bqm`` with minorminer (cached) and sample it on ``child``; when minorminer finds
    no embedding in its time, the topology's clique embedding of K_n serves instead. Returns
    (sample set, seconds from the first sample call to the resolved sample set)."""
    from dwave.embedding.chain_breaks import majority_vote
    from dwave.system import EmbeddingComposite

    composite = EmbeddingComposite(child, find_embedding=cached_find_embedding,
                                   embedding_parameters=embedding_parameters)
    sample_start = time.perf_counter()
    try:
        sampleset = composite.sample(bqm, chain_strength=chain_strength,
                                     chain_break_method=majority_vote,
                                     chain_break_fraction=True, return_embedding=True, **passed)
        sampleset.resolve()
    except ValueError as exc:
        if "no embedding found" not in str(exc):
            raise
        # minorminer is a randomised heuristic on a time budget (half the limit), which a loaded
        # machine can exhaust even for small graphs: the graph is a subgraph of K_n, so the
        # busclique embedding of K_n (deterministic, cached per child) serves it instead
        clique = clique_embedding(child, problem.n)
        if clique is None:
            raise RuntimeError(
                f"{backend}: minorminer found no embedding of the {problem.n}-vertex conflict "
                f"graph ({len(problem.all_edges())} edges) within "
                f"{embedding_parameters['timeout']} s and the topology has no clique embedding of "
                f"that size; raise options['embedding_timeout_s'] or use a classical backend") from None
        from dwave.system import FixedEmbeddingComposite

        sampleset = FixedEmbeddingComposite(child, embedding={v: clique[int(v)] for v in bqm.variables}).sample(
            bqm, chain_strength=chain_strength, chain_break_method=majority_vote,
            chain_break_fraction=True, return_embedding=True, **passed)
        sampleset.resolve()
    return sampleset, time.perf_counter() - sample_start


def _embedding_stats(sampleset, chain_strength_rule: str) -> dict:
    """Chain lengths, qubits, the chain strength dwave-system used (0 when every chain is one
    qubit) and the chain-break fractions weighted by occurrences, from the sample set."""
    context = sampleset.info.get("embedding_context", {})
    chains = context.get("embedding", {})
    lengths = np.array([len(chain) for chain in chains.values()], dtype=np.int64)
    counts = np.asarray(sampleset.record.num_occurrences, dtype=np.float64)
    breaks = np.asarray(sampleset.record.chain_break_fraction, dtype=np.float64)
    used_strength = context.get("chain_strength")
    if isinstance(used_strength, Mapping):
        used_strength = max(used_strength.values()) if used_strength else None
    if used_strength is None and (not lengths.size or lengths.max() <= 1):
        # every chain is one qubit: dwave-system skips chain couplings altogether
        used_strength = 0.0
        chain_strength_rule = "none needed (every chain is a single qubit)"
    return {
        "chain_length_max": int(lengths.max()) if lengths.size else 0,
        "chain_length_mean": float(lengths.mean()) if lengths.size else 0.0,
        "qubits_used": int(lengths.sum()),
        "chain_strength": float(used_strength) if used_strength is not None else float("nan"),
        "chain_strength_rule": chain_strength_rule,
        "chain_break_method": "majority_vote",
        "chain_break_fraction": float(np.average(breaks, weights=counts)),
        "reads_with_broken_chains": float(np.average(breaks > 0, weights=counts)),
    }


def _add_qpu_timing(stats: dict, sampleset, report_qpu_timing: bool) -> None:
    """Copy the sampler's own timing (microseconds) into ``stats``, or say why there is none."""
    timing = sampleset.info.get("timing") if report_qpu_timing else None
    if not report_qpu_timing:
        stats["qpu_timing"] = "none (emulator)"
    elif not timing:
        stats["qpu_timing"] = "none reported by the sampler"
    else:
        stats["qpu_timing"] = "sampler info['timing'], microseconds"
        for key in _TIMING_KEYS:
            if key in timing:
                stats[f"{key}_us"] = float(timing[key])


def embedded_solve(problem: MwisProblem, child, *, backend: str, seed: int, time_limit_s: float,
                   options: Mapping[str, Any], report_qpu_timing: bool,
                   sampler_parameters: Mapping[str, Any]) -> MwisResult:
    """Embed the MWIS QUBO on `child` (a structured dimod sampler), sample, unembed, refine.

    Args:
        problem: the MWIS problem.
        child: structured sampler (DWaveSampler, AdvantageStandInSampler, StructureComposite).
        backend: name for the result.
        seed: solve seed, passed to the child only if it declares a "seed" parameter.
        time_limit_s: also the default minorminer timeout (at least 1 s).
        options: common options (num_reads, lambda, optimum) and chain_strength,
            chain_strength_prefactor, embedding_seed, embedding_timeout_s, embedding_tries.
        report_qpu_timing: copy sampleset.info["timing"] into the statistics (qpu only).
        sampler_parameters: wanted sampler parameters (annealing_time, num_sweeps, ...); each is
            passed only if the child declares it.

    Returns:
        MwisResult (proven_optimal False) with the statistics listed in the module docstring.
    """
    started = time.perf_counter()
    options = given(options)
    parsed = common_options(options, _QPU_OPTIONS)
    if problem.n == 0:
        return make_result(problem, np.zeros(0, dtype=np.int32), proven_optimal=True,
                           solve_time_s=time.perf_counter() - started, backend=backend,
                           stats={"reads": 0})
    chain_strength, chain_strength_rule = _chain_strength_choice(options)
    embedding_parameters = _embedding_parameters(options, time_limit_s)
    passed, not_passed = _declared_parameters(child, parsed, sampler_parameters, seed)

    fits, why = fits_target(problem, child)
    direct_max = options.get("max_direct_vertices", QPU_DIRECT_MAX_VERTICES)
    if not fits or problem.n > direct_max:
        # refused at once (no minorminer call that can never succeed): decompose instead
        return _decomposed_embedded(problem, child, backend=backend, seed=seed,
                                    time_limit_s=time_limit_s, started=started, parsed=parsed,
                                    options=options, passed=passed, chain_strength=chain_strength,
                                    embedding_parameters=embedding_parameters,
                                    reason=why or f"{problem.n} vertices > max_direct_vertices "
                                    f"= {direct_max}")

    qubo = mwis_qubo(problem, parsed["lambda"])
    bqm = qubo.to_bqm()
    sampleset, sample_time = _sample_direct(problem, child, bqm, backend=backend,
                                            chain_strength=chain_strength,
                                            embedding_parameters=embedding_parameters, passed=passed)

    raw = sampleset_to_array(sampleset, problem.n)
    post_start = time.perf_counter()
    selected, stats = refine_and_repair(problem, qubo, raw, optimum=parsed["optimum"])
    stats.update({
        "lambda": parsed["lambda"],
        "num_reads": parsed["num_reads"],
        **_embedding_stats(sampleset, chain_strength_rule),
        "embedding_seed": embedding_parameters["random_seed"],
        "sampler": type(child).__name__,
        "sampler_is_stand_in": bool(getattr(child, "properties", {}).get("stand_in", False)),
        "sampler_parameters": ",".join(f"{k}={v}" for k, v in sorted(passed.items())),
        "sample_time_s": sample_time,
    })
    if not_passed:
        stats["sampler_parameters_not_supported"] = ",".join(not_passed)
    _add_qpu_timing(stats, sampleset, report_qpu_timing)
    stats["postprocess_time_s"] = time.perf_counter() - post_start
    return make_result(problem, selected, proven_optimal=False,
                       solve_time_s=time.perf_counter() - started, backend=backend, stats=stats)


# --------------------------------------------------------------------------------------------
# Backends
# --------------------------------------------------------------------------------------------

def dwave_token_configured() -> tuple[bool, str]:
    """Whether a D-Wave token is configured, without any network call.

    Looks at DWAVE_API_TOKEN, then at the dwave-cloud-client configuration (files found by
    dwave.cloud.config.load_config, the same ones `dwave config create` writes).
    Returns (True, where) or (False, NO_TOKEN_MESSAGE or the configuration error).
    """
    if os.environ.get("DWAVE_API_TOKEN"):
        return True, "DWAVE_API_TOKEN"
    try:
        from dwave.cloud.config import load_config
    except ImportError as exc:
        return False, f"dwave-cloud-client is not installed ({exc})"
    try:
        config = load_config()
    except Exception as exc:  # noqa: BLE001 - a broken config file is a reason to report
        return False, f"{NO_TOKEN_MESSAGE} (reading the dwave configuration failed: {exc})"
    if config.get("token"):
        return True, "dwave configuration file"
    return False, NO_TOKEN_MESSAGE


class QpuBackend(Backend):
    """D-Wave Advantage QPU through dwave-system (DWaveSampler in an EmbeddingComposite).

    sampler_factory: callable returning the structured child sampler to use instead of
    DWaveSampler (tests pass AdvantageStandInSampler); the option of the same name overrides it
    per call. Options: num_reads (100), annealing_time_us (1.0), chain_strength (a number, or the
    default "uniform_torque_compensation"), chain_strength_prefactor (1.414), lambda (2.0),
    optimum, embedding_seed (0), embedding_timeout_s (max(0.5 time_limit_s, 0.05)), embedding_tries
    (10), solver (DWaveSampler solver selection, e.g. a name).
    """

    samples = True
    name = "qpu"
    description = ("D-Wave Advantage QPU (DWaveSampler + minorminer embedding), 1 us anneals, "
                   "100 reads, majority-vote chains, descent + repair; needs a D-Wave token")
    options_spec = {
        **EMBEDDED_OPTIONS_SPEC,
        "annealing_time_us": Option("annealing_time_us", "float", DEFAULT_ANNEALING_TIME_US,
                                    "anneal time per read, microseconds", lo=0.5, hi=2000.0),
        "sampler_factory": Option("sampler_factory", "any", None, "callable returning the "
                                  "structured child sampler instead of DWaveSampler (tests: "
                                  "AdvantageStandInSampler)", nullable=True, validator=_callable),
        "solver": Option("solver", "str", None, "DWaveSampler solver selection (e.g. a name)",
                         nullable=True),
        "num_sweeps": Option("num_sweeps", "int", None, "sweeps per read, only for a stand-in "
                             "sampler that declares it", lo=1, hi=10**7, nullable=True),
    }

    def __init__(self, sampler_factory: Callable[[], Any] | None = None):
        self.sampler_factory = sampler_factory
        self._child = None

    def available(self) -> tuple[bool, str]:
        if self.sampler_factory is not None:
            return True, ""
        ok, where = dwave_token_configured()
        return (True, "") if ok else (False, where)

    def _child_sampler(self, options: Mapping[str, Any]):
        factory = options.get("sampler_factory") or self.sampler_factory
        if factory is not None:
            if not callable(factory):
                raise MwisInputError(
                    f"options['sampler_factory'] must be callable, got {factory!r}")
            return factory()
        ok, reason = dwave_token_configured()
        if not ok:
            raise BackendUnavailable(reason)
        if self._child is None:
            from dwave.system import DWaveSampler

            solver = options.get("solver")
            self._child = DWaveSampler(solver=solver) if solver else DWaveSampler()
        return self._child

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        options = given(self.validate_options(options))
        child = self._child_sampler(options)  # raises BackendUnavailable at once without token
        annealing_time = _float_option(options, "annealing_time_us", DEFAULT_ANNEALING_TIME_US)
        return embedded_solve(problem, child, backend=self.name, seed=seed,
                              time_limit_s=time_limit_s, options=options,
                              report_qpu_timing=True,
                              sampler_parameters={"annealing_time": annealing_time,
                                                  **({"num_sweeps": options["num_sweeps"]}
                                                     if "num_sweeps" in options else {})})


class QpuEmulatorBackend(Backend):
    """The `qpu` pipeline offline: simulated annealing on a simulated Advantage (Pegasus P16).

    The child is dimod.StructureComposite(SimulatedAnnealingSampler) on the ideal P16 graph
    (minus `missing_qubits`), so embeddings, chain lengths and chain breaks can be studied
    without hardware. It never reports QPU times (stats["qpu_timing"] = "none (emulator)").
    Options as for `qpu`, plus num_sweeps (simulated annealing sweeps per read, default 1000);
    annealing_time_us is not used.
    """

    samples = True
    name = "qpu-emulator"
    # (minorminer holds the GIL while it embeds, so it is not bounded_in_process)
    warm_up_by_solving = True
    description = ("the qpu embedding pipeline on a simulated Advantage graph (Pegasus P16, "
                   "simulated annealing); chain statistics, no QPU times")
    options_spec = {
        **EMBEDDED_OPTIONS_SPEC,
        "num_sweeps": Option("num_sweeps", "int", 1000, "simulated annealing sweeps per read",
                             lo=1, hi=10**7),
    }

    def __init__(self, missing_qubits: Iterable[int] = ()):
        self.missing_qubits = tuple(missing_qubits)
        self._child = None

    def available(self) -> tuple[bool, str]:
        try:
            import dwave.samplers  # noqa: F401
            import dwave.system  # noqa: F401
            import minorminer  # noqa: F401
        except ImportError as exc:
            return False, f"missing Ocean package ({exc})"
        return True, ""

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        options = given(self.validate_options(options))
        if self._child is None:
            self._child = _emulator_sampler(self.missing_qubits)
        num_sweeps = _int_option(options, "num_sweeps", 1000, 1)
        return embedded_solve(problem, self._child, backend=self.name, seed=seed,
                              time_limit_s=time_limit_s, options=options,
                              report_qpu_timing=False,
                              sampler_parameters={"num_sweeps": num_sweeps})
