"""Node parameters: one table per node (uam_bringup.params) for declaration, run-time changes
and docs; run-time changes validated, read-only ones refused."""

from __future__ import annotations

import pathlib

import pytest

ROOT = pathlib.Path(__file__).resolve().parents[1]


def test_docs_parameters_md_is_the_tables():
    from uam_contract.params import markdown
    assert (ROOT / "docs" / "parameters.md").read_text() == markdown(), \
        "docs/parameters.md is stale: python -m uam_contract.params > docs/parameters.md"


rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")
from rclpy.parameter import Parameter  # noqa: E402

from graph_harness import TINY, make_planner, make_solver, params  # noqa: E402


def _set(node, **values):
    return node.set_parameters([Parameter(k, value=v) for k, v in values.items()])[0]


@pytest.mark.ros
def test_solver_refuses_a_max_vertices_that_would_refuse_every_epoch(ros_context):
    """Finding: `/solver max_vertices := 1` was accepted and every later epoch fell back to greedy."""
    solver = make_solver(ros_context)
    try:
        res = _set(solver, max_vertices=1)
        assert not res.successful and "max_vertices" in res.reason and "1" in res.reason
        assert solver.get_parameter("max_vertices").value == 20000
        assert _set(solver, max_vertices=50000).successful
        assert solver.get_parameter("max_vertices").value == 50000
        res = _set(solver, default_backend="no-such")
        assert not res.successful and "no-such" in res.reason and "greedy" in res.reason
    finally:
        solver.destroy_node()


@pytest.mark.ros
def test_read_only_parameters_refuse_changes(ros_context, tmp_path):
    """Finding: demand_file and output changes were accepted and silently ignored."""
    from uam_sim.nodes.recorder_node import RecorderNode
    from uam_sim.nodes.request_generator_node import RequestGeneratorNode

    gen = RequestGeneratorNode(context=ros_context, parameter_overrides=params(network=TINY))
    rec = RecorderNode(context=ros_context, parameter_overrides=params(output=str(tmp_path / "r.mcap")))
    planner = make_planner(ros_context)
    try:
        for node, name, value in [(gen, "demand_file", "config/demand_example.yaml"), (gen, "seed", 3),
                                  (rec, "output", str(tmp_path / "other.mcap")), (planner, "network", TINY),
                                  (planner, "policy", "fifo"), (planner, "k", 3),
                                  (planner, "objective", "count"), (planner, "baseline_order", "priority"),
                                  (planner, "horizon_epochs", 2), (gen, "priority_share", 0.5)]:
            before = node.get_parameter(name).value
            res = _set(node, **{name: value})
            assert not res.successful and name in res.reason, (name, res.reason)
            assert node.get_parameter(name).value == before
    finally:
        rec.close()
        for n in (gen, rec, planner):
            n.destroy_node()


@pytest.mark.ros
def test_run_time_parameters_are_validated_and_take_effect(ros_context):
    planner = make_planner(ros_context)
    try:
        assert not _set(planner, time_limit_s=-1.0).successful
        assert not _set(planner, seed=-4).successful
        assert _set(planner, backend="greedy", time_limit_s=2, seed=9).successful
        assert (planner.config.backend, planner.config.time_limit_s, planner.config.seed) == ("greedy", 2.0, 9)
    finally:
        planner.destroy_node()


@pytest.mark.ros
def test_each_node_declares_exactly_its_table(ros_context, tmp_path):
    from uam_contract.params import TABLES
    from uam_sim.nodes.request_generator_node import RequestGeneratorNode
    from uam_sim.nodes.simulator_node import SimulatorNode

    from rosgraph_msgs.msg import Clock

    from uam_sim.recording.mcap_writer import McapRecorder
    from uam_sim.nodes.recorder_node import RecorderNode
    from uam_sim.nodes.replay_node import ReplayNode

    recording = tmp_path / "in.mcap"
    with McapRecorder(recording) as rec:
        rec.add_topic("/clock", Clock)
        rec.write("/clock", Clock(), 0)
    nodes = {"planner": make_planner(ros_context), "solver": make_solver(ros_context),
             "simulator": SimulatorNode(context=ros_context),
             "request_generator": RequestGeneratorNode(context=ros_context, parameter_overrides=params(network=TINY)),
             # the recorder and the replay had no table (issue 9): declared by hand, missing from the docs
             "recorder": RecorderNode(context=ros_context, parameter_overrides=params(output=str(tmp_path / "r.mcap"))),
             "replay": ReplayNode(str(recording), context=ros_context)}
    try:
        for name, node in nodes.items():
            declared = set(node.list_parameters([], 0).names) - {"use_sim_time", "start_type_description_service"}
            assert declared == {p.name for p in TABLES[name]}, name
            for p in TABLES[name]:
                desc = node.describe_parameter(p.name)
                assert desc.read_only == p.read_only and desc.description, (name, p.name)
    finally:
        nodes["recorder"].close()
        for n in nodes.values():
            n.destroy_node()


def test_launch_file_starts_the_nodes_and_parameter_files_of_run_fleet():
    """launch/uam.launch.py (for /opt/ros/jazzy; launch_ros is not on PyPI, so it is read, not run)
    starts the same executables with the same parameter files as scripts/run_fleet.sh."""
    import ast
    import re

    tree = ast.parse((ROOT / "src" / "uam_bringup" / "launch" / "uam.launch.py").read_text())
    launched = set()
    for node in ast.walk(tree):
        if isinstance(node, ast.Call) and getattr(node.func, "id", "") == "Node":
            kw = {k.arg: k.value for k in node.keywords}
            launched.add((kw["package"].value, kw["executable"].value))
    files = {m.group(1) for m in re.finditer(r'params_file\("(\w+)"\)', (ROOT / "src" / "uam_bringup" / "launch"
                                                                           / "uam.launch.py").read_text())}
    script = (ROOT / "scripts" / "run_fleet.sh").read_text()
    started = set(re.findall(r"^\s*start (\w+) (\w+) ", script, re.M))
    script_files = set(re.findall(r"--params-file config/(\w+)\.yaml", script))
    # five always, + the conformance monitor (issue 23), + the F3548 server (issue 25) only with
    # a port in both (`--uss-port`, `uss_port:=`)
    assert launched == started and len(started) == 7
    assert files == script_files == {"solver", "planner", "request_generator", "simulator"}
    # the run's seed goes to both the demand and the planner, in both
    assert re.search(r'"seed": a\["seed"\]', (ROOT / "src" / "uam_bringup" / "launch" / "uam.launch.py").read_text())
    assert script.count('-p "seed:=$SEED"') == 2


@pytest.mark.ros
def test_recorder_and_replay_refuse_bad_values_and_run_time_changes_naming_the_parameter(ros_context, tmp_path):
    """The recorder's view settings were changeable at run time and silently ignored; bad start-up
    values of the recorder and the replay are refused naming the parameter and the value."""
    from uam_sim.nodes.recorder_node import RecorderNode
    from uam_sim.nodes.replay_node import ReplayNode

    for name, value, words in [("output", str(tmp_path / "x.bag"), "must end with .mcap"),
                               ("rerun", "live", "'live' is not one of"),
                               ("view_fix_period_s", -1.0, "below the minimum"),
                               ("scenario_start_utc", "yesterday", "'yesterday'"),
                               ("compression", "gzip", "'gzip' is not one of")]:
        overrides = {"output": str(tmp_path / "r.mcap"), name: value}
        with pytest.raises(ValueError) as err:
            RecorderNode(context=ros_context, parameter_overrides=params(**overrides))
        assert name in str(err.value) and words in str(err.value), (name, str(err.value))
    with pytest.raises(ValueError) as err:
        ReplayNode(str(tmp_path / "none.mcap"), context=ros_context, parameter_overrides=params(rate=-2.0))
    assert "rate" in str(err.value) and "-2.0" in str(err.value)
    rec = RecorderNode(context=ros_context, parameter_overrides=params(output=str(tmp_path / "r.mcap")))
    try:
        for name, value in [("views", False), ("view_fix_period_s", 1.0), ("foxglove_port", 8765)]:
            res = _set(rec, **{name: value})
            assert not res.successful and name in res.reason, (name, res.reason)
    finally:
        rec.close()
        rec.destroy_node()


def test_an_integer_out_of_range_or_of_the_wrong_type_at_start_up_is_refused_naming_it(ros_context):
    """rclpy checks an integer parameter's range and every parameter's type itself, with an
    exception of its own: it reached run_node as a crash (traceback, exit code 1). It is refused
    like every other bad value: a ValueError naming the parameter and the value (exit code 2)."""
    from uam_planner.nodes.planner_node import PlannerNode
    from uam_sim.nodes.simulator_node import SimulatorNode

    tiny = str(ROOT / "config" / "networks" / "tiny.yaml")
    for make, overrides, words in [
            (PlannerNode, {"network": tiny, "k": 500}, "parameter k: 500 is above the maximum 100"),
            (PlannerNode, {"network": tiny, "k": "five"}, "parameter k: 'five' is not an integer"),
            (SimulatorNode, {"duration_s": "long"}, "parameter duration_s: 'long' is not a finite number")]:
        with pytest.raises(ValueError) as err:
            make(context=ros_context, parameter_overrides=params(**overrides))
        assert words in str(err.value), str(err.value)


@pytest.mark.ros
def test_rerun_off_as_the_command_line_writes_it_is_accepted(ros_context, tmp_path):
    """`-p rerun:=off` (as the docs write it) failed with "False is not a string": ROS reads the
    value as YAML, where off is the boolean false. It means the choice 'off'."""
    from uam_sim.nodes.recorder_node import RecorderNode

    out = tmp_path / "r.mcap"
    rec = RecorderNode(context=ros_context,
                       cli_args=["--ros-args", "-p", "rerun:=off", "-p", f"output:={out}"])
    try:
        assert rec.rerun is None or not rec.rerun.enabled
        assert "Rerun" not in (rec.get_parameter("rerun").value or "")
    finally:
        rec.close()
        rec.destroy_node()
    with pytest.raises(ValueError, match="parameter rerun: 'on' is not one of"):
        RecorderNode(context=ros_context, cli_args=["--ros-args", "-p", "rerun:=on", "-p", f"output:={out}"])


def test_the_planner_takes_the_networks_own_separation_model_and_warns_of_a_contradiction(ros_context):
    """Issue 19: a layered network flown with the sphere gave nothing for its four levels."""
    from uam_planner.nodes.planner_node import PlannerNode

    layered = str(ROOT / "config" / "networks" / "singapore-layered.yaml")
    own = PlannerNode(context=ros_context, parameter_overrides=[
        Parameter("network", value=layered), Parameter("precompute_routes", value=False)])
    paper = PlannerNode(context=ros_context, parameter_overrides=[
        Parameter("network", value=str(ROOT / "config" / "networks" / "tiny.yaml")),
        Parameter("precompute_routes", value=False)])
    forced = PlannerNode(context=ros_context, parameter_overrides=[
        Parameter("network", value=layered), Parameter("precompute_routes", value=False),
        Parameter("separation_model", value="sphere")])
    try:
        assert own.config.airspace.separation_model == "cylinder"
        assert paper.config.airspace.separation_model == "sphere"
        assert forced.config.airspace.separation_model == "sphere"  # as asked, with a warning
    finally:
        for n in (own, paper, forced):
            n.destroy_node()


def test_planner_objective_and_baseline_order_reach_the_library_and_bad_ones_are_named(ros_context):
    """Issue 21: the read-only objective and baseline_order become the Planner's PlanningConfig."""
    from uam_planner.nodes.planner_node import PlannerNode

    planner = make_planner(ros_context, objective="priority", baseline_order="priority", horizon_epochs=3)
    try:
        cfg = planner.planner.config
        assert (cfg.objective, cfg.baseline_order, cfg.horizon_epochs) == ("priority", "priority", 3)
    finally:
        planner.destroy_node()
    tiny = str(ROOT / "config" / "networks" / "tiny.yaml")
    with pytest.raises(ValueError) as err:
        PlannerNode(context=ros_context, parameter_overrides=params(network=tiny, objective="speed"))
    assert "parameter objective: 'speed' is not an objective; known: paper, count, delay, priority, fair" in str(err.value)


def test_request_priority_survives_the_message_conversions():
    from uam_planner.nodes import conversions as m
    from uam_planner.planning import FlightRequest

    req = FlightRequest("r1", "A", "B", 0.0, 0.0, 60.0, priority=7)
    msg = m.request_to_msg(req, operator_id="medic")
    assert (msg.priority, msg.operator_id) == (7, "medic")
    back = m.request_from_msg(msg, request_id="medic/r1")
    assert (back.priority, back.request_id) == (7, "medic/r1")
