"""One bounded path for every caller (issue 20): ``uam_solvers.solve_bounded`` (the in-process
runner's and the planner library's solve) goes through the process's shared SolveService, so a
backend that holds the GIL and never returns is killed and answered by the fallback, as in the
solver node. The assertions are on what happened (fallback taken, the stand-in's process
gone), with no wall bound: the measured wall against the limit is in the benchmark
(``python -m uam_solvers.bench --issue20``, its deadline table), not here."""
import os
import sys
import time

import numpy as np
import psutil
import pytest

sys.path.insert(0, os.path.dirname(__file__))  # before any worker starts: workers import from it
import solver_test_backends as tb  # noqa: E402

import uam_solvers  # noqa: E402
import uam_solvers.registry as registry  # noqa: E402
from uam_solvers import executor  # noqa: E402
from uam_solvers.executor import close_shared_service, shared_service  # noqa: E402
from uam_solvers.instances import paper_instance  # noqa: E402

# not in `make test-fast`: the shared solve service's worker processes
pytestmark = pytest.mark.slow

# the stand-in alone would run for hours: an answer at all means its worker was killed


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def _describe(pid: int) -> str:
    """What the process with ``pid`` is now, for a failure message."""
    try:
        q = psutil.Process(pid)
        return (f"pid {pid} still there: status {q.status()}, name {q.name()}, parent "
                f"{q.ppid()}, started {time.time() - q.create_time():.1f} s ago, "
                f"cmdline {q.cmdline()[:3]}")
    except psutil.Error as exc:
        return f"pid {pid}: {exc!r}"


def test_solve_bounded_kills_a_gil_holding_backend_and_answers_with_the_fallback():
    p = paper_instance(8, seed=1)
    svc = shared_service()
    before = set(svc.worker_pids())
    r = uam_solvers.solve_bounded(p.weights, p.edges, list(p.groups),
                                  backend=tb.GilHoldingBackend(), time_limit_s=0.3)
    assert r.fallback and r.stats["executor"] == "killed"
    assert r.backend == "greedy" and "worker killed" in r.message
    assert p.is_independent(r.selected) and r.objective > 0
    # SIGKILL was sent before the answer; wait (a condition, not a sleep) until it is reaped
    deadline = time.monotonic() + 10.0
    while not (before - set(svc.worker_pids())) and time.monotonic() < deadline:
        time.sleep(0.01)
    killed = before - set(svc.worker_pids())  # not counted from the kill on, reaped or not
    deadline = time.monotonic() + 10.0  # the reaping is off the answer's path: wait for it
    while not all(_gone(pid) for pid in killed) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(killed) == 1
    pid = killed.pop()
    assert _gone(pid), _describe(pid)  # (a CI run at load once found it not gone after 10 s)


def test_planner_default_solve_is_bounded_and_warm_before_the_first_epoch(monkeypatch):
    from uam_planner.planning import PlanningConfig, default_solve_mwis

    monkeypatch.setattr(registry, "_entry_points",
                        lambda: {"test-gil-hog": "solver_test_backends:GilHoldingBackend"})
    close_shared_service()
    solve = default_solve_mwis(PlanningConfig(backend="test-gil-hog", time_limit_s=0.3))
    assert executor._SHARED is not None  # started and warmed when the solve function was made
    assert len(executor._SHARED.worker_pids()) == 2
    p = paper_instance(6, seed=2)
    r = solve(p.weights, p.edges, list(p.groups))
    assert r.fallback and r.stats["executor"] == "killed"
    assert p.is_independent(r.selected)


def test_solve_bounded_gives_the_answers_of_solve():
    # the same pipeline as solve(): inline on small graphs, a worker on others
    for n_req, backend in ((6, "exact"), (8, "auto"), (30, "auto"), (10, "sa")):
        p = paper_instance(n_req, seed=n_req)
        a = uam_solvers.solve_bounded(p.weights, p.edges, list(p.groups), backend=backend,
                                      time_limit_s=2.0, seed=3)
        b = uam_solvers.solve(p.weights, p.edges, list(p.groups), backend=backend,
                              time_limit_s=2.0, seed=3)
        assert not a.fallback
        if a.proven_optimal and b.proven_optimal or backend == "sa":
            assert a.objective == pytest.approx(b.objective, abs=1e-9)
        assert np.all(np.diff(a.selected) > 0)


def test_fallback_on_a_dense_graph_is_the_bounded_one():
    from uam_solvers.base import MwisProblem
    from uam_solvers.greedy import fallback_selection, needs_fast_fallback

    a, b = np.triu_indices(400, 1)
    p = MwisProblem.from_arrays(np.linspace(1.0, 2.0, 400), np.stack([a, b], 1))  # 79,800 pairs
    assert needs_fast_fallback(p)
    sel, rule = fallback_selection(p)
    assert rule.startswith("local-max") and sel.tolist() == [399]
