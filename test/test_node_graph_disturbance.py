"""Disturbances through the node graph (issue 23): the simulator flies the disturbance model,
so uam/fleet_state carries what flew (the library's flown tracks, not the plans), and the
analysis of the recording audits what flew beside what was planned."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import build_graph, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402

from uam_planner.nodes import conversions as m  # noqa: E402
from uam_sim.disturbance import DisturbanceConfig, fly_plans  # noqa: E402

pytestmark = pytest.mark.ros


def test_fleet_state_is_what_flew_and_the_analysis_audits_it(ros_context, spin_until, tmp_path):
    sim = {"speed_error": 0.1, "gust_std_mps": 1.0, "disturbance_seed": 5}
    executor, nodes, obs = build_graph(ros_context, rate=3.0, seed=5, duration_s=180.0, backend="greedy",
                                       simulator_extra=sim, record_to=tmp_path / "run.mcap")
    try:
        run_to_end(executor, nodes, obs, spin_until, timeout_s=240.0)
    finally:
        shutdown(executor, nodes)
    approved = {f"{p.operator_id}/{p.request_id}": m.trajectory_from_plan(p) for p in obs.plans
                if p.outcome == FlightPlan.OUTCOME_APPROVED}
    assert len(approved) >= 5
    cfg = DisturbanceConfig(speed_error=0.1, gust_std_mps=1.0, seed=5, step_s=1.0)
    flown = dict(zip(approved, fly_plans(list(approved.values()), list(approved), cfg)))
    off_plan, compared = 0.0, 0
    for fs in obs.fleet:
        t = fs.header.stamp.sec + fs.header.stamp.nanosec * 1e-9
        for v in fs.vehicles:
            p = np.array([v.position.x, v.position.y, v.position.z])
            assert p == pytest.approx(flown[v.vehicle_id].position_at(t, clamp=True), abs=1e-6)
            planned = approved[v.vehicle_id].position_at(t, clamp=True)
            off_plan = max(off_plan, float(np.linalg.norm(p - planned)))
            compared += 1
    assert compared > 100 and off_plan > 10.0   # what flew is not the plan
    from uam_sim.analysis import format_summary, summarize
    summary = summarize(tmp_path / "run.mcap")
    assert summary.audit.ok and summary.flown["what"] == "flown"
    assert summary.flown["sample_step_s"] == 1.0 and summary.flown["pairs_checked"] > 0
    assert 0.0 < summary.flown["conformance"]["conformance_percent"] <= 100.0
    text = format_summary(summary)
    assert "Flown audit" in text and "the audit above is of the plans" in text and "Conformance" in text
