"""The test harness's hang watchdog (conftest.py): a test stuck in native code with the GIL held,
which pytest-timeout's SIGALRM cannot stop, is stopped within UAM_TEST_HANG_S with the native and
Python stacks of its threads printed, and reported as a failure instead of holding the run until
CI's limit. (A CI run once sat at 1068 of 1071 tests for its whole 90 min, printing nothing.)"""
import os
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parents[1]

STUCK = '''
import ctypes

def test_stuck_in_native_code_with_the_gil():
    libc = ctypes.PyDLL(None)  # PyDLL: the GIL stays held during the call
    mutex = ctypes.create_string_buffer(64)  # zeroed: PTHREAD_MUTEX_INITIALIZER, normal kind
    libc.pthread_mutex_lock(mutex)
    libc.pthread_mutex_lock(mutex)  # waits for itself forever

def test_after_it():
    pass
'''


def _run(tmp_path, hang_s: str, timeout_s: float = 180) -> subprocess.CompletedProcess:
    (tmp_path / "test_stuck.py").write_text(STUCK)
    env = {**os.environ, "UAM_TEST_HANG_S": hang_s, "PYTHONPATH": str(ROOT)}
    # the repository's conftest.py as a plugin, on a test file of its own (no ini, no xdist)
    return subprocess.run([sys.executable, "-m", "pytest", "-p", "conftest", "-c", os.devnull,
                           "--rootdir", str(tmp_path), "-p", "no:cacheprovider", "-p", "no:xdist",
                           "-q", str(tmp_path / "test_stuck.py")],
                          cwd=tmp_path, env=env, capture_output=True, text=True, timeout=timeout_s)


def test_a_test_stuck_in_native_code_is_stopped_with_its_stacks(tmp_path):
    res = _run(tmp_path, "3")
    out = res.stdout + res.stderr
    assert res.returncode != 0, out
    assert "test_stuck.py::test_stuck_in_native_code_with_the_gil still running after 3 s" in out, out
    assert "state S, kernel wait futex" in out, out  # each thread's kernel state
    if "Python v3" in out:  # py-spy could read the process (it needs ptrace: root or a child)
        assert "pthread_mutex_lock" in out, out  # the native stack of the stuck thread
    assert "Fatal Python error: Aborted" in out and "test_stuck.py\", line 8" in out, out  # faulthandler


def test_bad_watchdog_setting_is_refused_naming_it(tmp_path):
    res = _run(tmp_path, "soon", timeout_s=60)
    assert res.returncode != 0
    assert "UAM_TEST_HANG_S: 'soon' is not a number of seconds" in res.stdout + res.stderr
