"""The main command as a user runs it: scripts/run_fleet.sh starts the real executables (separate
processes talking over DDS), and on SIGTERM mid-run stops every node cleanly and leaves a
complete, readable recording."""

from __future__ import annotations

import os
import pathlib
import signal
import subprocess
import time

import pytest

pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

ROOT = pathlib.Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.ros, pytest.mark.slow]


def _wait_for(condition, timeout_s: float) -> bool:
    deadline = time.monotonic() + timeout_s
    while time.monotonic() < deadline:
        if condition():
            return True
        time.sleep(0.2)
    return condition()


def _node_processes(out_dir: pathlib.Path) -> list[str]:
    """Node processes of this run still alive (matched by the run's output folder in their args)."""
    ps = subprocess.run(["ps", "-eo", "pid,args"], capture_output=True, text=True, check=True).stdout
    return [line for line in ps.splitlines() if str(out_dir) in line and "/lib/uam_" in line]


def test_sigterm_mid_run_stops_every_node_and_keeps_the_recording(tmp_path, ros_domain_id):
    from mcap.reader import make_reader

    out = tmp_path / "run"
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_domain_id))
    proc = subprocess.Popen(
        ["bash", str(ROOT / "scripts" / "run_fleet.sh"), "--network", "config/networks/tiny.yaml",
         "--rate", "2", "--duration", "100000", "--mode", "realtime", "--rtf", "20", "--rerun", "off",
         "--out", str(out)],
        cwd=ROOT, env=env, stdout=subprocess.PIPE, stderr=subprocess.STDOUT, text=True)
    try:
        # running for real: plans are being published and recorded
        sim_log = out / "simulator.log"
        assert _wait_for(lambda: sim_log.exists() and "starting the run" in sim_log.read_text(), 90), \
            "the run did not start"
        mcap = out / "run.mcap"
        assert _wait_for(lambda: mcap.exists() and mcap.stat().st_size > 20_000, 60)
        proc.send_signal(signal.SIGTERM)
        output, _ = proc.communicate(timeout=90)
    finally:
        if proc.poll() is None:
            proc.kill()
    assert proc.returncode == 130, output
    assert "interrupted; stopping every node" in output
    assert "Safety audit" in output and "OK" in output
    assert _node_processes(out) == []
    assert "killing it" not in output, output  # every node stopped on SIGINT by itself
    assert "exited with code" not in output, output  # ... and cleanly
    # closed properly: summary and footer present, messages of every kind inside
    with open(out / "run.mcap", "rb") as f:
        reader = make_reader(f)
        summary = reader.get_summary()
        assert summary is not None and summary.statistics is not None
        counts = {summary.channels[cid].topic: n for cid, n in summary.statistics.channel_message_counts.items()}
    assert counts.get("/uam/fleet_state", 0) > 10
    assert counts.get("/uam/flight_plans", 0) > 0
    assert counts.get("/uam/requests", 0) > 0
