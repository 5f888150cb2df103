"""scripts/setup.sh says what it is doing: each step with the time since the start, the tools' own
progress lines (pip's packages, colcon's packages started and finished) and, in a long quiet
stretch, the tool's last line; everything in log/setup.log. It printed one line for 8 min 20 s
(pip ~3 min, colcon ~5 min) when run_fleet.sh hid its output in a temporary file."""

from __future__ import annotations

import pathlib
import re
import subprocess

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]
PROGRESS = ROOT / "scripts" / "setup_progress.sh"


def _run_logged(tmp_path, brief: bool):
    log = tmp_path / "setup.log"
    tool = "echo Collecting numpy==2.1; echo Downloading numpy.whl; sleep 2.5; echo Collecting scipy; exit 3"
    script = (f"set -Eeuo pipefail; LOG={log}; T0=$SECONDS; HEARTBEAT_S=1; UAM_SETUP_BRIEF={int(brief)}; "
              f"source {PROGRESS}; step 'Python packages'; "
              f"run_logged '^Collecting ' bash -c '{tool}' || echo rc=$?; step 'colcon build'; up_to_date")
    res = subprocess.run(["bash", "-c", script], capture_output=True, text=True, timeout=60)
    return res.stdout, log.read_text()


@pytest.mark.parametrize("brief", [False, True])
def test_a_tools_progress_and_heartbeats_are_shown_and_all_of_its_output_logged(tmp_path, brief):
    shown, log = _run_logged(tmp_path, brief)
    lines = shown.splitlines()
    # the elapsed times are the machine's (a loaded one starts at 0:01): the text after them counts
    assert all(re.match(r"\[setup \d+:\d\d\] ", line) for line in lines[:2]), shown
    assert [line.split("] ", 1)[1] for line in lines[:2]] == ["Python packages", "  Collecting numpy==2.1"], shown
    assert any(re.fullmatch(r"\[setup \d+:\d\d\]   \.\.\. still in 'Python packages' \(its last output: "
                            r"Downloading numpy\.whl\)", line) for line in lines), shown
    assert any(re.fullmatch(r"\[setup \d+:\d\d\]   Collecting scipy", line) for line in lines), shown
    # a line that is not progress is in the log only, until the tool fails: then its output's end is shown
    failed = next(i for i, line in enumerate(lines) if "failed (exit code 3)" in line)
    assert "Downloading numpy.whl" not in [line.split("] ", 1)[-1].strip() for line in lines[:failed]]
    assert "    Downloading numpy.whl" in lines[failed:] and "rc=3" in shown  # ... and its exit code comes back
    # an up-to-date step says nothing in brief mode (run_fleet.sh's)
    assert ("colcon build" in shown) is (not brief), shown
    for text in ("Collecting numpy==2.1", "Downloading numpy.whl", "Collecting scipy", "colcon build"):
        assert text in log, log


def test_setup_feeds_pip_and_colcon_through_their_progress():
    text = (ROOT / "scripts" / "setup.sh").read_text()
    assert re.search(r"run_logged '\^\(Collecting\|[^']*' \\\n\s+\"\$VPY\" -m pip install", text)
    assert re.search(r"run_logged '\^\(Starting\|Finished\|Failed\|Aborted\) [^']*' \\\n\s+colcon build .*"
                     r"console_direct\+ console_start_end\+", text)


@pytest.mark.ros
def test_setup_as_the_readme_writes_it_shows_timed_steps_and_keeps_a_full_log():
    pytest.importorskip("rclpy", reason="needs the built workspace (a set-up from nothing takes minutes)")
    if not ((ROOT / ".venv" / "bin" / "python").exists() and (ROOT / "install" / "setup.bash").exists()):
        # rclpy came from another checkout's workspace (a worktree run with its PYTHONPATH): the
        # set-up here would build a second workspace from nothing
        pytest.skip(f"{ROOT} has no built workspace of its own (.venv, install): the set-up would build one")
    res = subprocess.run(["bash", "scripts/setup.sh"], cwd=ROOT, capture_output=True, text=True, timeout=300)
    assert res.returncode == 0, res.stdout + res.stderr
    lines = res.stdout.splitlines()
    assert lines and all(re.match(r"\[setup \d+:\d\d\] ", line) for line in lines), res.stdout
    assert "[setup 0:00] Python packages (pinned)" in lines or any("Python packages (pinned)" in x for x in lines)
    assert "full log: log/setup.log" in res.stdout
    log = (ROOT / "log" / "setup.log").read_text()
    assert "colcon build" in log and "up to date" in log
