"""The whole node graph in one process: generator -> planner -> solver service -> simulator."""

from __future__ import annotations

import collections
import math

import pytest

pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

import rclpy.parameter  # noqa: E402
from graph_harness import build_graph, in_process, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402

from uam_planner.audit import audit_flights  # noqa: E402
from uam_planner.nodes.conversions import trajectory_from_plan  # noqa: E402

pytestmark = pytest.mark.ros


def _run(ros_context, spin_until, timeout_s=120.0, **kw):
    executor, nodes, obs = build_graph(ros_context, **kw)
    try:
        run_to_end(executor, nodes, obs, spin_until, timeout_s=timeout_s)
        return obs, nodes
    finally:
        shutdown(executor, nodes)


def test_every_request_decided_once_safe_and_recorded(ros_context, spin_until, tmp_path):
    rate, seed, duration = 3.0, 11, 300.0
    obs, nodes = _run(ros_context, spin_until, rate=rate, seed=seed, duration_s=duration,
                      record_to=tmp_path / "run.mcap")
    request_ids = [r.request_id for r in obs.requests]
    assert len(request_ids) == len(set(request_ids)) > 0
    decided = collections.Counter(p.request_id for p in obs.plans)
    # Requests of the last epoch may still be waiting when the run ends; all others are decided once.
    last_epoch_t = (math.ceil(duration / 30) - 1) * 30
    undecided = [r for r in obs.requests if r.request_id not in decided]
    assert all(r.request_time.sec >= last_epoch_t - 60 for r in undecided)
    assert all(c == 1 for c in decided.values()), [k for k, c in decided.items() if c != 1]
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    assert approved, "a 300 s run at 3 requests per epoch approves something"
    # Independent safety audit over the flown plans.
    audit = audit_flights([trajectory_from_plan(p) for p in approved], separation_m=100.0)
    assert audit.ok and audit.pairs_checked > 0, audit.losses
    # Reports: one per epoch, counts add up, solver used without fallback.
    assert len(obs.reports) == math.ceil(duration / 30)  # epochs at t < duration, as the runner
    assert sum(r.approved for r in obs.reports) == len(approved)
    assert not any(r.fallback for r in obs.reports)
    assert {r.backend_used for r in obs.reports if r.vertices} <= {"exact"}
    # (that the graph equals the in-process runner is test_epoch_protocol's
    # test_the_graph_equals_the_in_process_runner, for every backend and policy)
    # The fleet flew them: fleet state every step, vehicles only when airborne.
    assert [f.step_index for f in obs.fleet] == sorted(f.step_index for f in obs.fleet)
    assert len(obs.fleet) == duration + 1  # t = 0, 1, ..., 300 s
    assert max(len(f.vehicles) for f in obs.fleet) >= 1
    # The recording, decoded by the independent rosbags reader, holds the same run.
    from uam_sim.audit.analysis import summarize
    summary = summarize(tmp_path / "run.mcap", reader="rosbags")
    assert summary.complete_file
    assert summary.requests == len(request_ids)
    assert summary.approved == len(approved)
    assert summary.expired == sum(p.outcome == FlightPlan.OUTCOME_EXPIRED for p in obs.plans)
    assert summary.rejected == 0 and summary.duplicate_decisions == 0
    assert summary.fleet_steps == len(obs.fleet)
    assert len(summary.epochs) == len(obs.reports)
    assert summary.audit.ok and summary.audit.pairs_checked > 0
    # The MWIS instances come back out of the recording for the TTS study, as solved.
    from uam_solvers.instances import read_instances
    entries = read_instances(tmp_path / "run.mcap")
    solved = [r for r in obs.reports if r.vertices > 0]
    assert len(entries) == len(solved)
    for entry, report in zip(entries, solved):
        assert entry.problem.n == report.vertices
        assert entry.problem.objective(list(report.instance.selected)) == pytest.approx(report.objective)
    assert summary.audit.min_separation_m == pytest.approx(audit.min_separation_m, abs=1e-6)
    # Delay and detour of the recording are the in-process runner's (the experiment report's code).
    from uam_sim.world.flights import run_metrics
    # (both leave out the requests still within their window at the end, as the runner does)
    lib_stats = run_metrics(in_process(rate, seed, duration, "exact").flights, end_s=duration)
    for name in ("flights", "delay_mean_s", "delayed_share", "detour_mean_pct", "shortest_share",
                 "route_length_mean_m"):
        assert summary.flight_stats[name] == pytest.approx(lib_stats[name]), name
    # The simulator counts approvals apart from all decisions (it said "N plans received",
    # expired ones included).
    sim = nodes["simulator"]
    assert sim.approvals_received == len(approved)
    assert sim.plans_received == len(obs.plans) > len(approved)


def test_planner_falls_back_to_greedy_when_solver_absent(ros_context, spin_until):
    obs, _ = _run(ros_context, spin_until, rate=3.0, seed=5, duration_s=120.0, with_solver=False,
                  planner_extra={"solver_timeout_margin_s": 0.5, "solver_startup_timeout_s": 0.5})
    with_graph = [r for r in obs.reports if r.vertices > 0]
    assert with_graph, "some epoch had candidates"
    assert all(r.fallback and r.backend_used == "greedy" for r in with_graph)
    assert all("not available" in r.fallback_reason for r in with_graph)
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    audit = audit_flights([trajectory_from_plan(p) for p in approved], separation_m=100.0)
    assert not audit.losses


def test_bad_requests_are_rejected_with_reason_and_graph_keeps_running(ros_context, spin_until):
    from uam_msgs.msg import FlightRequest

    from uam_contract import names as c
    from uam_planner.nodes import conversions as m
    from uam_bringup import qos

    executor, nodes, obs = build_graph(ros_context, rate=2.0, seed=1, duration_s=150.0)
    bad_node = rclpy.create_node("bad_client", context=ros_context)
    executor.add_node(bad_node)
    try:
        pub = bad_node.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_LATCHED)
        bad = [
            FlightRequest(operator_id="console", request_id="bad1", origin_id="NOPE", destination_id="A",
                          earliest_departure=m.to_time(0), latest_departure=m.to_time(60)),
            FlightRequest(operator_id="console", request_id="bad2", origin_id="A", destination_id="A",
                          earliest_departure=m.to_time(0), latest_departure=m.to_time(60)),
            FlightRequest(operator_id="console", request_id="bad3", origin_id="A", destination_id="B",
                          earliest_departure=m.to_time(60), latest_departure=m.to_time(30)),
        ]
        for r in bad:
            pub.publish(r)
        assert spin_until(executor, lambda: nodes["simulator"].finished, timeout_s=120)
        assert spin_until(executor, lambda: all(b.request_id in {p.request_id for p in obs.plans} for b in bad), 10)
        by_id = {p.request_id: p for p in obs.plans}
        assert by_id["bad1"].outcome == FlightPlan.OUTCOME_REJECTED and "origin_id" in by_id["bad1"].reason \
            and "NOPE" in by_id["bad1"].reason
        assert by_id["bad2"].outcome == FlightPlan.OUTCOME_REJECTED and "same as origin" in by_id["bad2"].reason
        assert by_id["bad3"].outcome == FlightPlan.OUTCOME_REJECTED and "latest_departure" in by_id["bad3"].reason
        # the run went on: the good requests were planned in every epoch after the bad ones
        assert spin_until(executor, lambda: len(obs.reports) == 5, 10), len(obs.reports)
        assert any(p.outcome == FlightPlan.OUTCOME_APPROVED for p in obs.plans)
    finally:
        bad_node.destroy_node()
        shutdown(executor, nodes)


def test_planner_switches_backend_by_parameter(ros_context, spin_until):
    executor, nodes, obs = build_graph(ros_context, rate=3.0, seed=2, duration_s=90.0, backend="exact")
    planner = nodes["planner"]
    try:
        refused = planner.set_parameters([rclpy.parameter.Parameter("backend", value="no-such")])[0]
        assert not refused.successful and "no-such" in refused.reason and "greedy" in refused.reason
        assert planner.set_parameters([rclpy.parameter.Parameter("backend", value="greedy")])[0].successful
        assert spin_until(executor, lambda: nodes["simulator"].finished, timeout_s=60)
        assert spin_until(executor, lambda: len(obs.reports) == 3, timeout_s=10)
        solved = [r for r in obs.reports if r.vertices]
        assert solved and all(r.backend_requested == "greedy" and r.backend_used == "greedy" for r in solved)
        assert not any(r.fallback for r in solved)
    finally:
        shutdown(executor, nodes)
