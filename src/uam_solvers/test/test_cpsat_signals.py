"""A CP-SAT solve must leave the host process's Ctrl-C handling alone (nodes rely on it to close
recordings and shut down cleanly)."""

from __future__ import annotations

import pathlib
import subprocess
import sys

SRC = pathlib.Path(__file__).resolve().parents[1]
CONTRACT = SRC.parent / "uam_contract"  # the one package below the solvers (option rows)

SCRIPT = """
import os, signal, time
# Python's own Ctrl-C handling, as in a terminal: a test run started as a background job (or by a
# caller that ignores SIGINT) hands its children SIGINT ignored, and Python keeps it ignored
signal.signal(signal.SIGINT, signal.default_int_handler)
from uam_solvers import solve
# a limit the cold start (OR-Tools' import) fits in on a loaded machine too: at 1 s the answer
# could be the fallback, with the start-up still in CP-SAT on a daemon thread at the exit
r = solve([1.0, 2.0, 1.5], [[0, 1], [1, 2]], backend="exact", time_limit_s=30.0)
assert not r.fallback and r.backend == "exact", (r.backend, r.message)
try:
    os.kill(os.getpid(), signal.SIGINT)
    time.sleep(5)
    print("not interrupted")
except KeyboardInterrupt:
    print("handled by python")
"""


def test_sigint_after_an_exact_solve_reaches_python():
    out = subprocess.run([sys.executable, "-c", SCRIPT], capture_output=True, text=True, timeout=120,
                         env={"PYTHONPATH": f"{SRC}:{CONTRACT}", "PATH": "/usr/bin:/bin"})
    assert out.returncode == 0, (out.returncode, out.stderr[-2000:])
    assert "handled by python" in out.stdout
