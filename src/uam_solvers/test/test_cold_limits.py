"""Every limit holds from a cold process: ``uam_solvers.solve`` counts a backend's start-up
(imports, first call) inside its limit and gives the backend the time left, kills a backend a
thread cannot stop, and ``solve_bounded`` does not wait for its service to start. The
stand-ins misbehave on purpose; the killing and fallback paths are the real code. The
assertions are on what happened (which path answered, what limit reached the backend), never
on how fast this machine is: the wall times are in ``python -m uam_solvers.bench_cold``."""
import os
import sys
import threading
import time

import numpy as np
import pytest

sys.path.insert(0, os.path.dirname(__file__))
import solver_test_backends as tb  # noqa: E402

import uam_solvers  # noqa: E402
from uam_solvers import executor, warmup  # noqa: E402
from uam_solvers.base import Backend, MwisInputError, make_result  # noqa: E402
from uam_solvers.instances import paper_instance, planner_instance  # noqa: E402

W = [1.0, 0.6, 0.9, 0.8]
EDGES = [[0, 2], [1, 3]]
GROUPS = [[0, 1], [2, 3]]


def _slow_start_backend(start_s: float, in_process: bool, release: threading.Event | None = None):
    """A fresh backend class (warm state is per class) whose warm-up takes ``start_s`` [s] (or
    waits for ``release``) and whose answer reports the limit it was given."""

    class SlowStart(Backend):
        name = "test-slow-start"
        description = "test: a slow first call, then reports the limit it got"
        bounded_in_process = in_process

        def warm_up(self):
            if release is not None:
                release.wait(60.0)
            else:
                time.sleep(start_s)

        def solve(self, problem, *, time_limit_s, seed, options):
            return make_result(problem, [0, 3], proven_optimal=False, solve_time_s=0.0,
                               backend=self.name, stats={"given_limit_s": float(time_limit_s),
                                                         "pid": os.getpid()})

    return SlowStart()


@pytest.mark.parametrize("in_process", [True, False])
def test_a_cold_backend_gets_the_time_left_after_its_start_up(in_process):
    backend = _slow_start_backend(0.3, in_process)
    cold = uam_solvers.solve(W, EDGES, GROUPS, backend=backend, time_limit_s=2.0, layers=False)
    assert not cold.fallback and cold.selected.tolist() == [0, 3]
    assert cold.stats["given_limit_s"] <= 2.0 - 0.3  # the start-up came out of the limit
    assert (cold.stats["pid"] == os.getpid()) == in_process
    # warm: the whole limit, exactly (the answers of a warm process are unchanged)
    warm = uam_solvers.solve(W, EDGES, GROUPS, backend=backend, time_limit_s=2.0, layers=False)
    assert warm.stats["given_limit_s"] == 2.0


def test_a_start_up_still_running_at_the_limit_answers_with_the_fallback():
    release = threading.Event()
    backend = _slow_start_backend(0.0, True, release)
    try:
        r = uam_solvers.solve(W, EDGES, GROUPS, backend=backend, time_limit_s=0.2)
        assert r.fallback and r.backend == "greedy" and r.stats["executor"] == "starting"
        assert "still starting" in r.message and "test-slow-start" in r.message
        assert r.selected.tolist() == [0, 3]
        assert not warmup.is_warm(backend)
    finally:
        release.set()
    # the start-up went on in the background: once it ends the backend answers itself
    deadline = time.monotonic() + 30.0
    while not warmup.is_warm(backend) and time.monotonic() < deadline:
        time.sleep(0.01)
    r = uam_solvers.solve(W, EDGES, GROUPS, backend=backend, time_limit_s=0.2, layers=False)
    assert not r.fallback and r.stats["given_limit_s"] == 0.2


def test_solve_kills_a_gil_holding_backend_and_answers_with_the_fallback():
    # (before, solve() waited for this stand-in for ever: a thread cannot stop it)
    p = paper_instance(6, seed=1)
    r = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend=tb.GilHoldingBackend(),
                          time_limit_s=0.3)
    assert r.fallback and r.stats["executor"] == "killed" and r.backend == "greedy"
    assert "child process killed" in r.message and "test-gil-hog" in r.message
    assert p.is_independent(r.selected) and r.objective > 0
    assert r.stats["requested_backend"] == "test-gil-hog"


def test_a_bounded_backend_s_large_graph_goes_to_a_child_with_the_fallback_made_meanwhile(
        monkeypatch):
    """Above PRECOMPUTE_FALLBACK_ABOVE vertices even a backend a guard thread could abandon
    runs in a child killed at the limit (in process, the layers before it are not bounded),
    and a dense graph's fallback is made on a thread while the child runs, not before the
    wait (which made the kill late)."""
    import uam_solvers.greedy as greedy

    class ClaimsBounded(tb.GilHoldingBackend):
        name = "test-claims-bounded"
        bounded_in_process = True   # wrongly: a guard thread cannot stop its C call

    p = paper_instance(6, seed=1)
    monkeypatch.setattr(executor, "PRECOMPUTE_FALLBACK_ABOVE", p.n - 1)
    monkeypatch.setattr(greedy, "needs_fast_fallback", lambda problem: True)
    made_on = []
    real = greedy.fallback_selection

    def counted(problem):
        made_on.append(threading.current_thread().name)
        return real(problem)
    monkeypatch.setattr(greedy, "fallback_selection", counted)
    r = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend=ClaimsBounded(),
                          time_limit_s=0.3)
    assert r.fallback and r.stats["executor"] == "killed" and "child process killed" in r.message
    assert made_on == ["uam-solvers-fallback"]   # once, on the thread, used at the kill
    assert p.is_independent(r.selected) and r.objective > 0


def test_solve_survives_a_crashing_backend_and_reports_a_backends_input_error():
    p = paper_instance(6, seed=2)
    r = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend=tb.CrashingBackend(),
                          time_limit_s=5.0)
    assert r.fallback and r.stats["executor"] == "child-crashed" and "exit code 3" in r.message
    assert p.is_independent(r.selected)

    class InputRefused(Backend):
        name = "test-input-refused"

        def solve(self, problem, *, time_limit_s, seed, options):
            raise MwisInputError("weights: 1e-300 cannot be scaled (test)")

    with pytest.raises(MwisInputError, match="cannot be scaled"):
        uam_solvers.solve(p.weights, p.edges, list(p.groups), backend=InputRefused(),
                          time_limit_s=5.0)


def test_a_backend_that_holds_the_gil_runs_in_a_child_and_answers_as_in_process():
    # kamis above its inline size: a child process; the answer is the one of the pipeline
    # solved here (a completed search does not depend on where it ran)
    p = planner_instance(200, seed=4)  # KaMIS proves it in milliseconds
    assert p.n > uam_solvers.get_backend("kamis").inline_max_vertices
    r = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend="kamis", time_limit_s=5.0)
    here = uam_solvers.build_pipeline("kamis").solve(p, time_limit_s=5.0, seed=0, options={})
    assert r.stats["executor"] == "child" and not r.fallback
    assert r.proven_optimal and here.proven_optimal
    assert r.selected.tolist() == here.selected.tolist()
    assert np.isclose(r.objective, p.objective(r.selected))


def test_warm_up_pays_once_and_refuses_unknown_names():
    spent = uam_solvers.warm_up(["greedy", "exact"])
    assert set(spent) == {"greedy", "exact"}
    assert warmup.is_warm("greedy") and warmup.is_warm("exact")
    with pytest.raises(uam_solvers.UnknownBackendError, match="no-such-backend"):
        uam_solvers.warm_up(["greedy", "no-such-backend"])
    with pytest.raises(TypeError, match="neither a backend name nor a Backend"):
        uam_solvers.warm_up([3])


def test_solve_bounded_does_not_wait_for_its_service_to_start(monkeypatch):
    # a service whose start never ends (as a loaded machine's 1-3 s start looks to a 0.3 s
    # limit): solve_bounded answers without it and leaves it starting in the background
    started, release = threading.Event(), threading.Event()

    def slow_start():
        started.set()
        release.wait(60.0)

    executor.close_shared_service()
    monkeypatch.setattr(executor, "shared_service", slow_start)
    p = paper_instance(20, seed=3)
    try:
        r = uam_solvers.solve_bounded(p.weights, p.edges, list(p.groups), backend="greedy",
                                      time_limit_s=0.3)
        assert not r.fallback and p.is_independent(r.selected)
        assert started.wait(30.0)  # the start was asked for, after the answer
        assert executor.ready_shared_service() is None
    finally:
        release.set()
        if executor._STARTER is not None:
            executor._STARTER.join(30.0)
