"""Test harness shared by every package's tests.

Node tests use the fixtures here: each test gets its own rclpy Context, initialised on this test
run's own ROS domain id, and waits on conditions with timeouts (`spin_until`), never on sleeps.

The domain id is chosen once per pytest process (each pytest-xdist worker of scripts/test.sh
claims its own) by taking an exclusive lock file per id
(/tmp/uam-ros-domain-<id>.lock), so two test runs on one machine never share a domain and never
hear each other; discovery is also limited to this machine.
"""

from __future__ import annotations

import fcntl
import os
import shutil
import subprocess
import sys
import time
from typing import Callable

import pytest

_DOMAIN_RANGE = range(20, 101)  # Fast DDS maps ids to UDP ports; ids up to 101 are safe on Linux.


def _claim_domain_id() -> tuple[int, object]:
    for domain_id in _DOMAIN_RANGE:
        fh = open(f"/tmp/uam-ros-domain-{domain_id}.lock", "w")
        try:
            fcntl.flock(fh, fcntl.LOCK_EX | fcntl.LOCK_NB)
        except OSError:
            fh.close()
            continue
        return domain_id, fh
    raise RuntimeError(f"no free ROS domain id in {_DOMAIN_RANGE}: too many concurrent test runs")


@pytest.fixture(scope="session")
def ros_process_domain_id():
    """The ROS domain id of the node *processes* this test process starts (run_fleet.sh, a
    node run with ``python -m``), held for the whole run; also this process's ROS_DOMAIN_ID, so
    a process started without one names it too. It is not the domain of the in-process nodes
    (:func:`ros_domain_id`): a node process ends at once after a stop signal (os._exit, without
    destroying its DDS participant) or is killed, and Fast DDS's shared-memory transport then
    can leave that domain's ports (files in /dev/shm, reused by the next participant of the
    domain) corrupted for the processes still in it (eProsima/Fast-DDS#1144); a CI run hung in
    an in-process graph test that came after such runs in its domain."""
    domain_id, lock = _claim_domain_id()
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
    yield domain_id
    lock.close()


@pytest.fixture(scope="session")
def ros_domain_id(ros_process_domain_id):
    """This test process's own ROS domain id for its in-process nodes (held for the whole run;
    node processes it starts use :func:`ros_process_domain_id`)."""
    domain_id, lock = _claim_domain_id()
    yield domain_id
    lock.close()


@pytest.fixture
def ros_context(ros_domain_id):
    """A fresh rclpy Context for one test, on the run's domain; shut down afterwards."""
    import rclpy
    from rclpy.context import Context

    context = Context()
    rclpy.init(context=context, domain_id=ros_domain_id)
    yield context
    rclpy.try_shutdown(context=context)


def spin_until(executor, condition: Callable[[], bool], timeout_s: float = 10.0, step_s: float = 0.05) -> bool:
    """Spin `executor` until `condition()` is true or `timeout_s` of wall time passed.

    Returns the final value of the condition, so tests write `assert spin_until(...)`.
    """
    deadline = time.monotonic() + timeout_s
    while True:
        if condition():
            return True
        remaining = deadline - time.monotonic()
        if remaining <= 0:
            return bool(condition())
        try:
            executor.spin_once(timeout_sec=min(step_s, remaining))
        except Exception as exc:  # noqa: BLE001 - only rclpy's race below is tolerated
            # rclpy's MultiThreadedExecutor can take a timer a node has just cancelled (a run
            # that ends on an error cancels its timers) and raise "timer is canceled" from the
            # spin (ros2/rclpy#1485, fixed upstream after the wheels used here): the node meant
            # it; anything else is raised
            if "timer is canceled" not in str(exc):
                raise


@pytest.fixture(name="spin_until")
def spin_until_fixture():
    return spin_until


# ---------------------------------------------------------------------------------------------
# Hang watchdog: a test stuck in native code is stopped, with its stacks, within a bound
# ---------------------------------------------------------------------------------------------
# pytest-timeout (pytest.ini) raises in the main thread from SIGALRM: that needs the main thread
# to come back to the interpreter. A thread spinning in native code with the GIL held (rclpy's
# destroy_node() did in a loaded run, BENCHMARKS.md ninth stop) never does, and neither does any
# other Python thread: a CI run once sat at 1068 of 1071 tests until its 90 min were up, with
# nothing printed. So each test process gets a watcher process (it needs no GIL of ours): told
# when each test starts and ends, it prints the native and Python stacks of a test process whose
# test ran UAM_TEST_HANG_S seconds (default 240, past pytest-timeout's 180; 0 = off) with
# py-spy, then sends SIGABRT (pytest's faulthandler prints every thread's Python stack, and the
# test is reported failed: under xdist "worker crashed", the other tests go on).

_WATCHER = r"""
import os, select, signal, subprocess, sys, time
pid, hang_s, pyspy = int(sys.argv[1]), float(sys.argv[2]), sys.argv[3]
current, since, buf = None, 0.0, b""
while True:
    wait = None if current is None else max(0.0, since + hang_s - time.monotonic())
    if select.select([0], [], [], wait)[0]:
        chunk = os.read(0, 65536)
        if not chunk:
            sys.exit(0)  # the test process closed the pipe (it ended)
        *lines, buf = (buf + chunk).split(b"\n")
        for line in lines:
            if line.startswith(b"start "):
                current, since = line[6:].decode(errors="replace"), time.monotonic()
            elif line == b"end":
                current = None
        continue
    err = sys.stderr
    print(f"\n[test watchdog] {current} still running after {hang_s:g} s in test process "
          f"{pid}: its stacks, then SIGABRT", file=err, flush=True)
    try:
        for tid in sorted(os.listdir(f"/proc/{pid}/task"), key=int):
            with open(f"/proc/{pid}/task/{tid}/stat") as f:
                stat = f.read().rsplit(")", 1)[1].split()
            with open(f"/proc/{pid}/task/{tid}/wchan") as f:
                wchan = f.read().strip()
            print(f"[test watchdog] thread {tid}: state {stat[0]}, kernel wait {wchan or '-'}",
                  file=err, flush=True)
    except OSError as exc:
        print(f"[test watchdog] /proc/{pid}: {exc}", file=err, flush=True)
    if pyspy:
        try:
            subprocess.run([pyspy, "dump", "--native", "--pid", str(pid)], stdout=err,
                           stderr=err, timeout=120)
        except (OSError, subprocess.SubprocessError) as exc:
            print(f"[test watchdog] py-spy: {exc}", file=err, flush=True)
    try:
        gone = os.pidfd_open(pid)  # readable once the process has ended
        os.kill(pid, signal.SIGABRT)
        if not select.select([gone], [], [], 20)[0]:
            os.kill(pid, signal.SIGKILL)  # SIGABRT handled and survived: end it
    except ProcessLookupError:
        pass
    sys.exit(0)
"""


def _hang_s() -> float:
    raw = os.environ.get("UAM_TEST_HANG_S", "240")
    try:
        value = float(raw)
    except ValueError:
        raise pytest.UsageError(f"UAM_TEST_HANG_S: {raw!r} is not a number of seconds") from None
    if not value >= 0:
        raise pytest.UsageError(f"UAM_TEST_HANG_S: {raw!r} is not a number >= 0")
    return value


def _watchdog(config):
    """This test process's watcher (started with its first test), or None when off."""
    w = getattr(config, "_uam_watchdog", False)
    if w is False:
        w = None
        hang_s = _hang_s()
        if hang_s > 0:
            pyspy = shutil.which("py-spy") or shutil.which("py-spy", path=os.path.dirname(sys.executable)) or ""
            # stdout not inherited: under xdist it is the worker's channel to the controller
            w = subprocess.Popen([sys.executable, "-c", _WATCHER, str(os.getpid()), repr(hang_s), pyspy],
                                 stdin=subprocess.PIPE, stdout=subprocess.DEVNULL)
        config._uam_watchdog = w
    return w


def _tell(config, line: str) -> None:
    w = _watchdog(config)
    if w is not None and w.poll() is None:
        try:
            w.stdin.write(line.encode() + b"\n")
            w.stdin.flush()
        except OSError:
            pass


@pytest.hookimpl(hookwrapper=True)
def pytest_runtest_protocol(item, nextitem):
    _tell(item.config, f"start {item.nodeid}")
    try:
        yield
    finally:
        _tell(item.config, "end")


def pytest_unconfigure(config):
    w = getattr(config, "_uam_watchdog", None)
    if w:
        try:
            w.stdin.close()
            w.wait(10)
        except (OSError, subprocess.TimeoutExpired):
            w.kill()
