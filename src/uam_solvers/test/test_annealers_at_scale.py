"""sa, tabu and qpu-emulator on 10^4-vertex graphs (issue 11, "Annealers and QPU at scale"):
decomposition instead of refusal or blocking, answers never worse than the greedy start."""
import pytest

from uam_solvers.annealing import SimulatedAnnealingBackend, TabuBackend
from uam_solvers.decompose import decomposed_solve
from uam_solvers.instances import large_instance, paper_instance
from uam_solvers.qpu import QpuEmulatorBackend


@pytest.fixture(scope="module")
def big():
    return large_instance(10_000, seed=3)


@pytest.mark.parametrize("backend_cls", [SimulatedAnnealingBackend, TabuBackend])
def test_annealers_decompose_10000_vertices_within_the_limit(big, backend_cls):
    # no wall-clock bound here (it fails under load): the wall against the 1 s limit at 10^4
    # vertices is measured by `python -m uam_solvers.bench --skip-small --skip-targets
    # --large-sizes 10000 --large-limits 1 --large-backends sa,tabu`
    r = backend_cls().solve(big, time_limit_s=1.0, seed=0, options={})
    assert big.is_independent(r.selected)
    assert r.stats["decomposed"] is True and r.stats["subproblems"] >= 1
    assert r.objective >= r.stats["initial_objective"] - 1e-9  # never worse than greedy


def test_emulator_refuses_at_once_what_cannot_embed_and_decomposes():
    problem = large_instance(6000, seed=1)  # more vertices than the 5,640 qubits of P16
    r = QpuEmulatorBackend().solve(problem, time_limit_s=2.0, seed=0,
                                   options={"num_sweeps": 100})
    assert "cannot embed" in r.stats["decomposition_reason"]
    assert problem.is_independent(r.selected)
    assert r.objective >= r.stats["initial_objective"] - 1e-9


def test_decomposition_keeps_only_improvements():
    problem = paper_instance(12, seed=4)
    calls = []

    def worst_sampler(bqm, seed, remaining):  # proposes "select everything": never better
        import dimod
        calls.append(seed)
        return dimod.SampleSet.from_samples_bqm({v: 1 for v in bqm.variables}, bqm)

    sel, stats = decomposed_solve(problem, worst_sampler, size=8, time_limit_s=0.2, seed=5)
    assert stats["improvements"] == 0 and len(calls) == stats["subproblems"] >= 1
    assert calls[:2] == [5, 6][:len(calls[:2])]
    assert problem.is_independent(sel) and problem.objective(sel) >= stats["initial_objective"]
