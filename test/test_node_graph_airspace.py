"""The expanded airspace through the whole node graph (issue 10, Deliver 7): the planner's slot and
separation parameters, the flight plans' levels and departures, the recorder's airspace record and
the analysis auditing in the run's model, and the same plans as the in-process runner."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import ROOT, build_graph, in_process, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402

from uam_planner.nodes.conversions import plan_level_m  # noqa: E402

pytestmark = pytest.mark.ros

LAYERED = str(ROOT / "config" / "networks" / "singapore-layered.yaml")
AIRSPACE = {"separation_model": "cylinder", "separation_m": 100.0, "vertical_separation_m": 30.0,
            "departure_slot_s": 5.0}


def test_layered_slots_cylinder_graph_equals_runner_and_is_audited_in_the_cylinder(
        ros_context, spin_until, tmp_path):
    rate, seed, duration = 4.0, 5, 240.0
    executor, nodes, obs = build_graph(
        ros_context, network=LAYERED, rate=rate, seed=seed, duration_s=duration, backend="greedy",
        planner_extra=dict(AIRSPACE, precompute_routes=False), recorder_extra=AIRSPACE,
        record_to=tmp_path / "run.mcap")
    try:
        run_to_end(executor, nodes, obs, spin_until, timeout_s=240.0)
    finally:
        shutdown(executor, nodes)
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    assert len(approved) >= 10
    # the plan says its departure (a slot, possibly after the epoch that decided it) and its level
    dep = {p.request_id: p.departure_time.sec + p.departure_time.nanosec * 1e-9 for p in approved}
    assert any(dep[p.request_id] > 30.0 * p.epoch_index + 1e-6 for p in approved)
    assert all(30.0 * p.epoch_index <= dep[p.request_id] <= 30.0 * (p.epoch_index + 1) for p in approved)
    levels = {plan_level_m(p) for p in approved}
    assert len(levels) >= 2 and levels <= {60.0, 90.0, 120.0, 150.0}
    # one library, two ways to run it: the runner with the same options makes the same plans
    lib = in_process(rate, seed, duration, "greedy", network=LAYERED, **{
        k: v for k, v in AIRSPACE.items() if k != "separation_m"})
    runner = {f["request_id"]: (f["departure_s"], tuple(f["route"].split()), f["level_m"]) for f in lib.flights}
    graph = {p.request_id: (dep[p.request_id], tuple(p.route_node_ids), plan_level_m(p)) for p in approved}
    assert graph.keys() == runner.keys()
    for rid, (d, route, level) in graph.items():
        assert route == runner[rid][1] and level == runner[rid][2]
        assert np.isclose(d, runner[rid][0])
    # the recording says the run's model; the analysis audits in it
    from uam_sim.audit.analysis import summarize
    summary = summarize(tmp_path / "run.mcap")
    assert summary.audit.separation_model == "cylinder"
    assert summary.audit.vertical_separation_m == 30.0
    assert summary.audit.ok and summary.verified and summary.audit.pairs_checked > 0
    assert summary.approved == len(approved)
