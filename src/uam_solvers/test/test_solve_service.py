"""The solve service keeps deadlines for backends that cannot be stopped by a thread (issue 11,
"Deadlines"): a GIL-holding solve is killed at limit + margin, the caller gets the flagged
greedy answer at once, and no process or CPU is left behind."""
import os
import sys
import threading
import time

import numpy as np
import psutil
import pytest

sys.path.insert(0, os.path.dirname(__file__))  # before any worker starts: workers import from it
import solver_test_backends as tb  # noqa: E402

from uam_solvers import MwisInputError, MwisProblem  # noqa: E402
from uam_solvers.executor import SolveService  # noqa: E402
from uam_solvers.instances import large_instance, paper_instance  # noqa: E402

# not in `make test-fast`: worker processes
pytestmark = pytest.mark.slow


@pytest.fixture(scope="module")
def service():
    svc = SolveService(small_workers=1, large_workers=1, small_lane_max_vertices=100,
                       margin_s=0.3, max_time_limit_s=30.0, max_vertices=50_000)
    yield svc
    svc.close()


def _gone(pid: int) -> bool:
    try:
        return psutil.Process(pid).status() == psutil.STATUS_ZOMBIE
    except psutil.NoSuchProcess:
        return True


def _wait_for_workers(service, count, timeout_s=10.0):
    assert service.wait_until_ready(120.0)  # a replacement after a kill or crash is started
    end = time.monotonic() + timeout_s
    while len(service.worker_pids()) != count and time.monotonic() < end:
        time.sleep(0.02)
    assert len(service.worker_pids()) == count


def _wait_busy(service, timeout_s=10.0):
    end = time.monotonic() + timeout_s
    while not service._busy and time.monotonic() < end:
        time.sleep(0.01)
    assert service._busy


def test_gil_holding_backend_is_killed_at_the_deadline(service):
    problem = paper_instance(6, seed=1)
    _wait_for_workers(service, 2)
    before = set(service.worker_pids())
    # the stand-in would hold the GIL for hours: an answer at all means the worker was killed
    # (the wall against the limit is measured by `python -m uam_solvers.bench --issue20`, its deadline table)
    r = service.solve(problem, backend=tb.GilHoldingBackend(), time_limit_s=0.5)
    assert r.fallback and r.backend == "greedy" and r.stats["executor"] == "killed"
    assert "exceeded its time limit" in r.message and problem.is_independent(r.selected)
    # SIGKILL is sent before the answer, the reaping is off the answer's path (issue 20):
    # wait (a condition) until the killed worker is gone
    deadline = time.monotonic() + 10.0
    killed = before - set(service.worker_pids())  # not counted from the kill on, reaped or not
    while not all(_gone(pid) for pid in killed) and time.monotonic() < deadline:
        time.sleep(0.01)
    assert len(killed) == 1 and all(_gone(pid) for pid in killed)  # nothing left running
    _wait_for_workers(service, 2)  # replaced by a fresh worker (started in the background)
    again = service.solve(problem, backend=tb.WorkerPidBackend(), time_limit_s=1.0)
    assert again.stats["executor"] == "worker" and not again.fallback


def test_the_limit_counts_from_the_caller_s_start_when_given(service):
    """``started_at``: the caller's own work before the call (solve_bounded's validation of
    the arrays) is inside its limit; the worker gets the time left, not the whole limit."""
    problem = large_instance(300, seed=4)
    _wait_for_workers(service, 2)
    full = service.solve(problem, backend=tb.LimitReportingBackend(), time_limit_s=5.0)
    began = time.perf_counter() - 3.0
    cut = service.solve(problem, backend=tb.LimitReportingBackend(), time_limit_s=5.0,
                        started_at=began)
    assert full.stats["executor"] == cut.stats["executor"] == "worker"
    assert 4.0 < full.stats["limit_s"] <= 5.0
    assert 0.0 < cut.stats["limit_s"] <= 2.0


def test_small_request_does_not_wait_behind_a_large_one(service):
    large = large_instance(2000, seed=0)
    small = paper_instance(4, seed=2)
    box = {}
    t = threading.Thread(target=lambda: box.setdefault(
        "large", service.solve(large, backend=tb.GilHoldingBackend(), time_limit_s=3.0)))
    _wait_for_workers(service, 2)  # a worker killed by an earlier test is replaced
    t.start()
    _wait_busy(service)  # the large solve occupies its worker
    r = service.solve(small, backend=tb.WorkerPidBackend(), time_limit_s=2.0)
    # answered by its own worker while the large solve still runs (an order, not a wall bound)
    assert t.is_alive() and r.stats["executor"] == "worker" and not r.fallback
    t.join()
    assert box["large"].fallback and box["large"].stats["executor"] == "killed"


def test_no_free_worker_means_fallback_within_the_limit(service):
    large = large_instance(2000, seed=1)
    box = {}
    t = threading.Thread(target=lambda: box.setdefault(
        "first", service.solve(large, backend=tb.GilHoldingBackend(), time_limit_s=2.0)))
    _wait_for_workers(service, 2)
    t.start()
    _wait_busy(service)
    r = service.solve(large, backend=tb.WorkerPidBackend(), time_limit_s=0.5)
    # refused at once rather than queued: answered while the first solve still holds its worker
    assert t.is_alive()
    assert r.fallback and r.stats["executor"] == "no-free-worker" and "all busy" in r.message
    t.join()


def test_crashed_worker_is_replaced_and_answered_by_greedy(service):
    problem = paper_instance(5, seed=3)
    r = service.solve(problem, backend=tb.CrashingBackend(), time_limit_s=2.0)
    assert r.fallback and r.stats["executor"] == "worker-crashed" and "exit code 3" in r.message
    assert problem.is_independent(r.selected)
    _wait_for_workers(service, 2)


def test_small_problems_of_fast_backends_run_in_process(service):
    problem = paper_instance(8, seed=4)
    r = service.solve(problem, backend="exact", time_limit_s=1.0)
    assert r.stats["executor"] == "inline" and r.proven_optimal
    w = service.solve(problem, backend=tb.WorkerPidBackend(), time_limit_s=1.0)
    assert w.stats["executor"] == "worker" and w.stats["pid"] != os.getpid()


def test_registered_backend_runs_in_a_worker_and_matches_in_process(service):
    problem = large_instance(3000, seed=5)  # above greedy's in-process size (2,000)
    r = service.solve(problem, backend="greedy", time_limit_s=20.0)
    assert r.stats["executor"] == "worker" and not r.fallback
    import uam_solvers
    direct = uam_solvers.solve_problem(problem, "greedy", time_limit_s=20.0)
    assert np.array_equal(r.selected, direct.selected)


def test_bounds_and_options_are_checked_before_any_solve(service):
    problem = paper_instance(5, seed=6)
    with pytest.raises(MwisInputError, match=r"^time_limit_s: 100"):
        service.solve(problem, backend="greedy", time_limit_s=100.0)
    with pytest.raises(MwisInputError, match=r"max_vertices=50000"):
        service.solve(MwisProblem.from_arrays(np.ones(50_001), []), backend="greedy")
    with pytest.raises(MwisInputError, match=r"options\['rulez'\]"):
        service.solve(problem, backend="greedy", options={"rulez": "gwmin"})
    with pytest.raises(MwisInputError, match=r"options\['num_sweeps'\]: 0"):
        service.solve(problem, backend="sa", options={"num_sweeps": 0})


def test_close_stops_every_worker():
    svc = SolveService(small_workers=1, large_workers=2)
    pids = svc.worker_pids()
    assert len(pids) == 3
    svc.close()
    assert all(_gone(pid) for pid in pids)
    with pytest.raises(RuntimeError, match="closed"):
        svc.solve(paper_instance(3, seed=0), backend=tb.WorkerPidBackend())


def test_after_a_kill_the_next_solve_is_served_by_the_replacement(service):
    # issue 20 (noticed by issue 24): after a kill the replacement starts in the background;
    # on a loaded machine the next solve fell back "no free small-lane worker (all busy)", and
    # worker_pids() still counted the killed worker until it was reaped
    problem = paper_instance(6, seed=2)
    assert service.wait_until_ready(120.0)
    before = set(service.worker_pids())
    r = service.solve(problem, backend=tb.GilHoldingBackend(), time_limit_s=0.3)
    assert r.fallback and r.stats["executor"] == "killed"
    after = set(service.worker_pids())
    assert len(before - after) == 1, "the killed worker is not counted, reaped or not"
    assert service.wait_until_ready(120.0)  # a condition: the replacement is warm and idle
    assert len(service.worker_pids()) == len(before)
    again = service.solve(problem, backend=tb.WorkerPidBackend(), time_limit_s=1.0)
    assert again.stats["executor"] == "worker" and not again.fallback
    assert again.stats["pid"] not in before


def test_wait_until_ready_checks_its_timeout_and_is_false_once_closed():
    svc = SolveService(small_workers=1, large_workers=1, margin_s=0.3)
    try:
        assert svc.wait_until_ready(60.0)
        with pytest.raises(MwisInputError, match="timeout_s"):
            svc.wait_until_ready(-1.0)
    finally:
        svc.close()
    assert not svc.wait_until_ready(1.0)


def test_a_large_problem_s_fallback_is_made_while_the_worker_solves(service, monkeypatch):
    """Above PRECOMPUTE_FALLBACK_ABOVE vertices the fallback is computed on a thread of the
    caller's process while the worker solves, so a kill finds it ready (on the large city's
    graphs it took a second after the kill); computed once, not again after the kill."""
    import uam_solvers.executor as executor
    import uam_solvers.greedy as greedy

    problem = paper_instance(6, seed=1)
    _wait_for_workers(service, 2)
    # this process's threshold (the worker, its own process, computes no fallback at all)
    monkeypatch.setattr(executor, "PRECOMPUTE_FALLBACK_ABOVE", problem.n - 1)
    real, calls = greedy.fallback_selection, []

    def counted(p):
        calls.append(threading.current_thread().name)
        return real(p)
    monkeypatch.setattr(greedy, "fallback_selection", counted)
    r = service.solve(problem, backend=tb.GilHoldingBackend(), time_limit_s=0.5)
    assert r.fallback and r.stats["executor"] == "killed" and problem.is_independent(r.selected)
    assert calls == ["uam-solvers-fallback"]
    _wait_for_workers(service, 2)
