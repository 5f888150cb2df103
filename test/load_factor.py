"""The one allowance the tests make for a loaded machine.

A correctness test never depends on how fast the machine is; where a test must bound a wall time
(a process that has to end, a hang that has to be cut), the bound is generous and multiplied by
``UAM_TEST_LOAD_FACTOR`` (default 1; e.g. 3 on a machine running other jobs), which
``scripts/test.sh`` also applies to pytest-timeout's per-test limit and the hang watchdog.
"""

from __future__ import annotations

import os


def load_factor() -> float:
    """``UAM_TEST_LOAD_FACTOR`` as a number >= 1 (ValueError naming it otherwise)."""
    raw = os.environ.get("UAM_TEST_LOAD_FACTOR", "1")
    try:
        value = float(raw)
    except ValueError:
        raise ValueError(f"UAM_TEST_LOAD_FACTOR: {raw!r} is not a number") from None
    if not value >= 1.0:
        raise ValueError(f"UAM_TEST_LOAD_FACTOR: {raw!r} must be a number >= 1")
    return value


def slack(seconds: float) -> float:
    """A wall-time allowance of ``seconds`` on a quiet machine, scaled by the load factor."""
    return seconds * load_factor()
