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
def ros_domain_id():
    """This test run's own ROS domain id (held for the whole run)."""
    domain_id, lock = _claim_domain_id()
    os.environ["ROS_DOMAIN_ID"] = str(domain_id)
    os.environ.setdefault("ROS_AUTOMATIC_DISCOVERY_RANGE", "LOCALHOST")
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
        executor.spin_once(timeout_sec=min(step_s, remaining))


@pytest.fixture(name="spin_until")
def spin_until_fixture():
    return spin_until
