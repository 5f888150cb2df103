"""The planner node's ``constraints_file`` (issue 22): read at start-up, bad files refused naming
the parameter and the field, and the node graph plans around the constraints exactly as the
in-process runner with ``constraints_file`` does, its expiries naming the constraint."""

from __future__ import annotations

import json

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import TINY, build_graph, decisions, in_process, make_planner, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402

from uam_planner.constraints import load_constraints  # noqa: E402
from uam_planner.network import load_network  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402

pytestmark = pytest.mark.ros


def write_constraints(tmp_path, closure_end_s=150.0, upper_m=300.0):
    """A 500 m square over the tiny network's hub W7 (its ENU origin), 0-300 m, all run long,
    and vertiport C closed for [0, closure_end_s)."""
    doc = {"type": "FeatureCollection", "frame": "enu", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [
            [[-250, -250], [250, -250], [250, 250], [-250, 250], [-250, -250]]]},
         "properties": {"id": "hub", "version": 1, "reason": "event", "lower_m": 0,
                        "upper_m": upper_m, "start_s": 0, "end_s": 10000}},
        {"type": "Feature", "geometry": None,
         "properties": {"id": "C-closed", "version": 1, "reason": "maintenance", "vertiport_id": "C",
                        "start_s": 0, "end_s": closure_end_s}}]}
    path = tmp_path / "constraints.geojson"
    path.write_text(json.dumps(doc))
    return path


def test_constraints_file_is_read_at_start_up_and_bad_ones_are_refused(ros_context, tmp_path):
    planner = make_planner(ros_context, constraints_file=str(write_constraints(tmp_path)))
    try:
        assert [c.constraint_id for c in planner.config.constraints] == ["hub", "C-closed"]
    finally:
        planner.destroy_node()
    paper = make_planner(ros_context)
    try:
        assert paper.config.constraints is None
    finally:
        paper.destroy_node()
    with pytest.raises(ValueError) as err:
        make_planner(ros_context, constraints_file=str(write_constraints(tmp_path, upper_m=-1.0)))
    assert "constraints_file" in str(err.value) and "upper_m: -1" in str(err.value)


def test_graph_plans_around_constraints_as_the_runner_does(ros_context, spin_until, tmp_path):
    path = write_constraints(tmp_path)
    rate, seed, duration = 3.0, 5, 240.0
    executor, nodes, obs = build_graph(ros_context, rate=rate, seed=seed, duration_s=duration,
                                       planner_extra={"constraints_file": str(path)})
    try:
        run_to_end(executor, nodes, obs, spin_until)
    finally:
        shutdown(executor, nodes)
    ref = in_process(rate, seed, duration, "exact", constraints_file=str(path))
    assert decisions(obs.plans) == ref.decisions() and ref.decisions()
    net = load_network(TINY)
    cset = load_constraints(path, net)
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    trajs = [m.trajectory_from_plan(p) for p in approved]
    which, _ = cset.violations(trajs, [net.node_index(p.origin_id) for p in approved],
                               [net.node_index(p.destination_id) for p in approved])
    assert (which == -1).all(), "an approved plan enters a constraint"
    # requests to or from C while it is closed expire, the reason naming the closure
    expired = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_EXPIRED]
    named = [p for p in expired if "constraint 'C-closed' v1 (maintenance)" in p.reason]
    assert named, [p.reason for p in expired]
    assert all("C" in (p.origin_id, p.destination_id) for p in named)
    assert all(p.epoch_index * 30.0 < 150.0 for p in named)
