"""qpu (with the Advantage stand-in) and qpu-emulator: the whole embedding pipeline offline."""

import dimod
import pytest

import uam_solvers.qpu as qpu_module
from uam_solvers.base import BackendUnavailable, MwisProblem
from uam_solvers.instances import paper_instance
from uam_solvers.qpu import (
    NO_TOKEN_MESSAGE,
    AdvantageStandInSampler,
    QpuBackend,
    QpuEmulatorBackend,
    advantage_graph,
)
from uam_solvers.registry import get_backend

# two requests of three candidates; conflicts 0-3 and 1-4: {0,4} = 1.9 is the optimum
TWO_REQUESTS = dict(weights=[1.0, 0.8, 0.6, 1.0, 0.9, 0.5], edges=[[0, 3], [1, 4]],
                    groups=[[0, 1, 2], [3, 4, 5]])
# path 0-1-2-3: {1,3} = 1.5
PATH = dict(weights=[0.6, 1.0, 0.7, 0.5], edges=[[0, 1], [1, 2], [2, 3]])

FAKE_TIMING = {"qpu_access_time": 15000.0, "qpu_programming_time": 14000.0,
               "qpu_anneal_time_per_sample": 1.0, "qpu_readout_time_per_sample": 50.0}


@pytest.fixture(scope="module")
def stand_in():
    return AdvantageStandInSampler(num_sweeps=200)


@pytest.fixture
def no_token(monkeypatch, tmp_path):
    """No DWAVE_API_TOKEN and no dwave config file anywhere the client looks."""
    for var in ("DWAVE_API_TOKEN", "DWAVE_CONFIG_FILE", "DWAVE_PROFILE"):
        monkeypatch.delenv(var, raising=False)
    monkeypatch.setenv("HOME", str(tmp_path))
    monkeypatch.setenv("XDG_CONFIG_HOME", str(tmp_path / "config"))
    monkeypatch.setenv("XDG_CONFIG_DIRS", str(tmp_path / "etc"))

    def no_network(*args, **kwargs):
        raise AssertionError("DWaveSampler must not be constructed without a token")

    import dwave.system
    monkeypatch.setattr(dwave.system, "DWaveSampler", no_network)


def test_advantage_graph_is_pegasus_16():
    nodes, edges = advantage_graph()
    assert len(nodes) == 5640 and len(edges) == 40484
    fewer, _ = advantage_graph(missing_qubits=[nodes[0], nodes[1]])
    assert len(fewer) == 5638


def test_qpu_without_token_fails_at_once_with_the_configuration_message(no_token):
    backend = QpuBackend()
    assert backend.available() == (False, NO_TOKEN_MESSAGE)
    problem = MwisProblem.from_arrays(**PATH)
    with pytest.raises(BackendUnavailable, match="DWAVE_API_TOKEN.*dwave config create"):
        backend.solve(problem, time_limit_s=1.0, seed=0, options={})
    with pytest.raises(BackendUnavailable, match="no D-Wave token"):
        get_backend("qpu").require_available()


def test_qpu_token_in_environment_counts_as_configured(no_token, monkeypatch):
    monkeypatch.setenv("DWAVE_API_TOKEN", "not-a-real-token")
    assert QpuBackend().available() == (True, "")


def test_stand_in_is_labelled_and_checks_structure(stand_in):
    assert stand_in.properties["topology"] == {"type": "pegasus", "shape": [16]}
    assert "not a QPU" in stand_in.properties["chip_id"]
    assert "annealing_time" in stand_in.parameters
    u, v = stand_in.nodelist[0], stand_in.nodelist[-1]
    assert (u, v) not in set(stand_in.edgelist)
    with pytest.raises(dimod.exceptions.BinaryQuadraticModelStructureError):
        stand_in.sample(dimod.BQM({u: 1.0, v: 1.0}, {(u, v): 1.0}, 0.0, "BINARY"))
    with pytest.raises(ValueError, match="annealing_time"):
        stand_in.sample(dimod.BQM({u: 1.0}, {}, 0.0, "BINARY"), annealing_time=0.1)


@pytest.mark.parametrize("case, expected", [(TWO_REQUESTS, [0, 4]), (PATH, [1, 3])])
def test_qpu_pipeline_with_stand_in_finds_hand_checked_optimum(stand_in, case, expected):
    problem = MwisProblem.from_arrays(**case)
    backend = QpuBackend(sampler_factory=lambda: stand_in)
    assert backend.available() == (True, "")
    before = len(stand_in.calls)
    result = backend.solve(problem, time_limit_s=10.0, seed=3, options={"num_reads": 20})
    assert result.selected.tolist() == expected
    assert result.proven_optimal is False and result.backend == "qpu"
    # parameters passed through to the sampler: 1 us anneals, the reads, the seed
    call = stand_in.calls[before]
    assert call["annealing_time"] == 1.0 and call["num_reads"] == 20 and call["seed"] == 3
    stats = result.stats
    assert stats["sampler"] == "AdvantageStandInSampler" and stats["sampler_is_stand_in"]
    assert stats["chain_length_max"] >= 1
    assert stats["chain_length_mean"] >= 1.0
    assert stats["qubits_used"] == call["num_qubits"]
    assert 0.0 <= stats["chain_break_fraction"] <= 1.0
    assert 0.0 <= stats["reads_with_broken_chains"] <= 1.0
    if stats["chain_length_max"] > 1:
        assert stats["chain_strength"] > 0
    else:
        assert stats["chain_strength_rule"].startswith("none needed")
    assert stats["chain_break_method"] == "majority_vote"
    # the stand-in reports no timing, and the pipeline does not invent any
    assert stats["qpu_timing"] == "none reported by the sampler"
    assert not any(key.endswith("_us") for key in stats)


def test_qpu_pipeline_reads_sampler_timing_when_present():
    sampler = AdvantageStandInSampler(num_sweeps=100, timing=FAKE_TIMING)
    problem = MwisProblem.from_arrays(**PATH)
    result = QpuBackend().solve(problem, time_limit_s=10.0, seed=0,
                                options={"num_reads": 5, "annealing_time_us": 2.0,
                                         "sampler_factory": lambda: sampler})
    assert sampler.calls[-1]["annealing_time"] == 2.0
    stats = result.stats
    assert stats["qpu_access_time_us"] == 15000.0
    assert stats["qpu_programming_time_us"] == 14000.0
    assert stats["qpu_anneal_time_per_sample_us"] == 1.0
    assert stats["qpu_readout_time_per_sample_us"] == 50.0


def test_qpu_pipeline_on_a_paper_instance_reports_chains(stand_in):
    problem = paper_instance(3, seed=4, n_vertices=12)
    result = QpuBackend(sampler_factory=lambda: stand_in).solve(
        problem, time_limit_s=20.0, seed=1, options={"num_reads": 10, "chain_strength": 0.3})
    assert problem.is_independent(result.selected)
    stats = result.stats
    assert stats["chain_strength"] == pytest.approx(0.3)
    assert stats["chain_strength_rule"] == "fixed"
    # cliques of up to 5 plus conflicts do not embed natively: some chains have 2+ qubits
    assert stats["chain_length_max"] >= 2
    assert stats["qubits_used"] > problem.n
    assert stats["reads"] == 10


def test_emulator_finds_optimum_and_never_reports_qpu_times():
    problem = MwisProblem.from_arrays(**TWO_REQUESTS)
    result = QpuEmulatorBackend().solve(problem, time_limit_s=10.0, seed=2,
                                        options={"num_reads": 10, "num_sweeps": 200,
                                                 "optimum": 1.9})
    assert result.selected.tolist() == [0, 4]
    assert result.backend == "qpu-emulator"
    assert result.stats["qpu_timing"] == "none (emulator)"
    assert not any(key.endswith("_us") for key in result.stats)
    assert "num_sweeps=200" in result.stats["sampler_parameters"]
    assert "annealing_time" not in result.stats["sampler_parameters"]
    assert result.stats["optimal_fraction"] > 0
    assert isinstance(get_backend("qpu-emulator"), QpuEmulatorBackend)


def test_embeddings_are_cached_and_seeded(monkeypatch, stand_in):
    import minorminer

    calls = []
    real = minorminer.find_embedding

    def counting(*args, **kwargs):
        calls.append(kwargs.get("random_seed"))
        return real(*args, **kwargs)

    monkeypatch.setattr(minorminer, "find_embedding", counting)
    problem = MwisProblem.from_arrays([0.5, 0.6, 0.7, 0.8, 0.9],
                                      [[0, 1], [1, 2], [2, 3], [3, 4], [0, 4], [0, 2]])
    backend = QpuBackend(sampler_factory=lambda: stand_in)
    first = backend.solve(problem, time_limit_s=10.0, seed=0,
                          options={"num_reads": 4, "embedding_seed": 7})
    second = backend.solve(problem, time_limit_s=10.0, seed=1,
                           options={"num_reads": 4, "embedding_seed": 7})
    assert calls == [7], "one minorminer call, seeded; the second solve reuses the embedding"
    assert first.stats["qubits_used"] == second.stats["qubits_used"]
    assert len(qpu_module._EMBEDDING_CACHE) >= 1
