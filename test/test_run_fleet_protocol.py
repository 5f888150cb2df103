"""scripts/run_fleet.sh end to end with the epoch protocol across processes: the run's --seed
reaches the planner (and so the solver), and the separate processes give the in-process
runner's plans."""

from __future__ import annotations

import os
import pathlib
import subprocess

import pytest

pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

ROOT = pathlib.Path(__file__).resolve().parents[1]
pytestmark = [pytest.mark.ros, pytest.mark.slow]


def test_run_fleet_passes_the_seed_to_the_planner_and_matches_the_runner(tmp_path, ros_process_domain_id):
    """Finding: --seed seeded the demand but not the solver."""
    from graph_harness import in_process

    from uam_sim.audit.analysis import iter_decoded

    out = tmp_path / "run"
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))
    proc = subprocess.run(
        ["bash", str(ROOT / "scripts" / "run_fleet.sh"), "--network", "config/networks/tiny.yaml", "--rate", "3",
         "--duration", "150", "--seed", "5", "--backend", "sa", "--rerun", "off", "--out", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "seed 5" in (out / "planner.log").read_text()
    approved = {str(p.request_id): (int(p.epoch_index), int(p.candidate_index))
                for topic, _t, p in iter_decoded(out / "run.mcap") if topic == "/uam/flight_plans" and p.outcome == 0}
    assert approved == in_process(3.0, 5, 150.0, "sa").decisions()


def test_run_fleet_layered_with_slots_and_cylinder_matches_the_runner_and_audits_in_the_cylinder(
        tmp_path, ros_process_domain_id):
    """Issue 10: run_fleet.sh --network singapore-layered --slot-s 5 reaches the planner and the
    recorder; the analysis audits in the recorded cylinder. Issue 19: the cylinder is the layered
    network's own model, taken without --separation (with the sphere, its levels 30 m apart
    separated nothing)."""
    from graph_harness import in_process

    from uam_sim.audit.analysis import iter_decoded, summarize

    out = tmp_path / "run"
    env = dict(os.environ, ROS_DOMAIN_ID=str(ros_process_domain_id))
    proc = subprocess.run(
        ["bash", str(ROOT / "scripts" / "run_fleet.sh"), "--network", "config/networks/singapore-layered.yaml",
         "--slot-s", "5", "--vertical-separation-m", "30", "--rate", "3",
         "--duration", "120", "--seed", "2", "--backend", "greedy", "--rerun", "off", "--out", str(out)],
        cwd=ROOT, env=env, capture_output=True, text=True, timeout=400)
    assert proc.returncode == 0, proc.stdout + proc.stderr
    assert "run_fleet: airspace: separation cylinder H 100 m, V 30 m" in proc.stdout
    assert "WARNING" not in proc.stderr
    assert "separation cylinder, departure slot 5 s" in (out / "planner.log").read_text()
    assert "100 m horizontal within 30 m vertical (cylinder)" in proc.stdout
    summary = summarize(out / "run.mcap")
    assert summary.audit.separation_model == "cylinder" and summary.audit.ok and summary.verified
    approved = {str(p.request_id): (int(p.epoch_index), int(p.candidate_index))
                for topic, _t, p in iter_decoded(out / "run.mcap") if topic == "/uam/flight_plans" and p.outcome == 0}
    assert approved and approved == in_process(
        3.0, 2, 120.0, "greedy", network=str(ROOT / "config" / "networks" / "singapore-layered.yaml"),
        separation_model="cylinder", vertical_separation_m=30.0, departure_slot_s=5.0).decisions()
