"""The contract every registered backend keeps (built-in and entry points), through the solve
service: a valid independent set, the objective recomputed from the weights, the time limit
held, options validated; checked by ``uam_solvers.testing``, the kit plugin authors use."""

import numpy as np
import pytest

import uam_solvers.registry as registry
from uam_solvers.executor import SolveService
from uam_solvers.qpu import AdvantageStandInSampler, QpuBackend
from uam_solvers.testing import (CONTRACT_PROBLEMS, assert_answer_kept, assert_backend_contract,
                                 assert_options_validated)

# not in `make test-fast`: every backend through a SolveService's worker processes
pytestmark = pytest.mark.slow

LIMIT_S = 1.0


@pytest.fixture(scope="module")
def service():
    # a generous margin: this test is about answering at all (a backend that never answers is
    # killed at the limit + margin and fails on "killed"), not about timing precision, which the
    # deadline table of `python -m uam_solvers.bench --issue20` measures; 0.4 s failed under load
    # 5-7 and 1.5 s under load 8 (qpu and qpu-emulator on paper-8); a backend that answers does
    # not wait for the margin, so only a failing one pays it
    svc = SolveService(small_workers=1, large_workers=1, margin_s=10.0)
    yield svc
    svc.close()


@pytest.fixture(autouse=True)
def entry_point(monkeypatch):
    """One backend advertised as an entry point (as a third-party package would)."""
    monkeypatch.setattr(registry, "_entry_points",
                        lambda: {"contract-entry-point": "uam_solvers.greedy:GreedyBackend"})


def _names():
    real = registry._entry_points
    registry._entry_points = lambda: {"contract-entry-point": "uam_solvers.greedy:GreedyBackend"}
    try:
        return registry.backend_names()
    finally:
        registry._entry_points = real


def _backend(name):
    # qpu has no D-Wave token here: its real pipeline (embedding, chains, unembedding) runs on
    # the stand-in sampler with the Advantage topology, a simulated annealer, not a QPU
    return QpuBackend(sampler_factory=AdvantageStandInSampler) if name == "qpu" else name


def _runnable(name):
    backend = _backend(name)
    backend = registry.get_backend(backend) if isinstance(backend, str) else backend
    return backend.available()


_WARM: set = set()
PROBLEMS = {k: make() for k, make in CONTRACT_PROBLEMS.items()}


@pytest.mark.parametrize("name", _names())
@pytest.mark.parametrize("which", list(PROBLEMS))
def test_backend_contract(service, name, which):
    ok, why = _runnable(name)
    if not ok:
        pytest.skip(f"{name} unavailable here: {why}")
    if name not in _WARM:
        # a backend's first solve in the worker pays its imports and set-up (the QPU stand-in
        # builds the Advantage graph): paid here with a generous limit, not held to the contract's
        # limit, which is about solving (warm-up is paid at start by the nodes and the runner)
        # (3 s: enough for the imports; CHILS runs to its limit, so not more)
        service.solve(PROBLEMS["paper-8"], backend=_backend(name), time_limit_s=3.0, seed=0)
        _WARM.add(name)
    # the plugin authors' kit: the same checks (no wall-clock bound here: the wall against the
    # limit is measured by `python -m uam_solvers.bench --issue20`, its deadline table)
    assert_answer_kept(service, _backend(name), PROBLEMS[which], LIMIT_S)


@pytest.mark.parametrize("name", _names())
def test_backend_options_are_validated(service, name):
    ok, why = _runnable(name)
    if not ok:
        pytest.skip(f"{name} unavailable here: {why}")
    assert_options_validated(service, _backend(name), PROBLEMS["paper-8"],
                             registry.get_backend(name).options_spec, LIMIT_S)


def test_the_kit_runs_on_a_backend_class_and_sees_a_broken_one():
    """``assert_backend_contract`` as a plugin author calls it: on a Backend subclass (with its
    determinism), and a backend that returns a set that is not independent fails it."""
    from uam_solvers.base import make_result
    from uam_solvers.greedy import GreedyBackend

    assert_backend_contract(GreedyBackend, deterministic=True)

    class Broken(GreedyBackend):
        name = "broken-for-the-kit"

        def solve(self, problem, *, time_limit_s, seed=0, options=None):
            return make_result(problem, np.arange(problem.n), proven_optimal=False, solve_time_s=0.0,
                               backend=self.name)

    with pytest.raises(AssertionError):
        assert_backend_contract(Broken)
