"""The UAM node graph for users of /opt/ros/jazzy: the same five nodes and parameter files as
scripts/run_fleet.sh.

    ros2 launch uam_bringup uam.launch.py config_dir:=$PWD/config backend:=exact rate:=10 \
        duration:=600 seed:=0 out:=runs/launch-demo

Every name of the graph is relative (uam_contract.names), so ``namespace:=/fleet2`` moves the
whole graph. The launch ends when the simulator ends the run (the recorder closes its file by
itself and exits; the launch then stops the solver, a server). Needs ``launch`` and
``launch_ros``, which the PyPI wheels do not ship (use scripts/run_fleet.sh there).
"""

from __future__ import annotations


from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, GroupAction, RegisterEventHandler
from launch.conditions import IfCondition, UnlessCondition
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node, PushRosNamespace
from launch_ros.parameter_descriptions import ParameterValue
from uam_contract.launch_options import LAUNCH_OPTIONS
from uam_contract.names import RECORDER_WAITS_FOR

# one table for both launchers (uam_contract.launch_options; test/test_launchers.py holds
# run_fleet.sh to it)
ARGS = {o.arg: (o.default, o.help) for o in LAUNCH_OPTIONS if o.only != "run_fleet"}


# long (over 80 lines): one Node per process of the graph with its parameters, read top to
# bottom as the graph it launches (the options themselves come from uam_contract.launch_options)
def generate_launch_description() -> LaunchDescription:
    a = {name: LaunchConfiguration(name) for name in ARGS}
    cfg = a["config_dir"]

    def params_file(node: str):
        return PathJoinSubstitution([cfg, f"{node}.yaml"])

    network = a["network"]
    out = PythonExpression(["'", a["out"], "' or 'runs/launch'"])
    mcap = PathJoinSubstitution([out, "run.mcap"])
    rrd = PathJoinSubstitution([out, "run.rrd"])
    # the planner's airspace ('' separation: the network's own, as both nodes resolve it); the
    # recorder writes it into the MCAP for the analysis' audit
    airspace = {"separation_model": a["separation"], "separation_m": a["separation_m"],
                "vertical_separation_m": a["vertical_separation_m"], "departure_slot_s": a["slot_s"]}
    # as run_fleet.sh: the conformance monitor runs when asked, or with auto when a
    # disturbance is set (an undisturbed fleet flies its plans exactly) or the planner reacts to
    # its reports (reaction:=true); the simulator then
    # waits for it as for the recorder
    # (the one rule: uam_contract.disturbances.conformance_monitor_on, as run_fleet.sh calls it)
    conformance_on = PythonExpression([
        "uam_contract.disturbances.conformance_monitor_on('", a["conformance"], "', '", a["reaction"], "', '",
        a["wind_speed_mps"], "', '", a["gust_std_mps"], "', '", a["speed_error"], "', '", a["delay_mean_s"], "', '",
        a["vertical_gust_std_mps"], "', '", a["altitude_error_m"], "')"],
        python_modules=["uam_contract", "uam_contract.disturbances"])
    # the run's choices for the analysis' header (uam_contract.run_choices, as run_fleet.sh
    # writes them); a string parameter, not read as YAML
    choices = {"policy": "policy", "backend": "backend", "objective": "objective",
               "baseline_order": "baseline_order", "rate": "rate", "seed": "seed",
               "priority_share": "priority_share", "horizon": "horizon_epochs", "commit_ahead": "commit_ahead",
               "lead_time_s": "lead_time_s", "departure_slot_s": "slot_s", "spatial_buffer_m": "spatial_buffer_m",
               "temporal_buffer_s": "temporal_buffer_s", "reaction": "reaction",
               "reaction_period_s": "reaction_period_s", "probe_s": "conflict_probe_s",
               "probe_margin_m": "conflict_probe_margin_m", "wind_mps": "wind_speed_mps",
               "wind_from_deg": "wind_from_deg", "gust_mps": "gust_std_mps", "speed_error": "speed_error",
               "delay_mean_s": "delay_mean_s", "vertical_gust_mps": "vertical_gust_std_mps",
               "altitude_error_m": "altitude_error_m"}
    expr = ["uam_contract.run_choices.as_json("]
    for name, arg in choices.items():
        expr += [f"{name}='", a[arg], "', "]
    # the USS server's auth, only when it runs (verify or off: an 'off' run says so in its header)
    expr += ["**({'uss_auth': '", a["uss_auth"], "'} if int('", a["uss_port"], "') > 0 else {}), "]
    run_choices = ParameterValue(PythonExpression(expr + [")"], python_modules=["uam_contract.run_choices"]),
                                 value_type=str)
    recorder_prefix = "nice -n 19"
    sim_params = {"duration_s": a["duration"], "mode": a["mode"], "real_time_factor": a["rtf"],
                  # disturbances, seeded by the run's seed
                  "disturbance_seed": a["seed"], "wind_speed_mps": a["wind_speed_mps"],
                  "wind_from_deg": a["wind_from_deg"], "gust_std_mps": a["gust_std_mps"],
                  "speed_error": a["speed_error"], "delay_mean_s": a["delay_mean_s"],
                  "vertical_gust_std_mps": a["vertical_gust_std_mps"], "altitude_error_m": a["altitude_error_m"],
                  # the reaction between epochs (with reaction:=true)
                  "reaction_period_s": a["reaction_period_s"]}
    # as run_fleet.sh: the recorder is not in the lockstep loop, so it runs at a lower priority
    recorder = Node(package="uam_sim", executable="recorder", name="recorder", output="screen",
                    prefix=recorder_prefix,
                    parameters=[{"output": mcap, "network": network, "rerun": a["rerun"], "rerun_rrd": rrd,
                                 "foxglove_port": a["foxglove_port"],
                                 # as run_fleet.sh: the run starts once the recorder hears these
                                 "wait_for_publishers": list(RECORDER_WAITS_FOR),
                                 "run_choices": run_choices, **airspace}])
    nodes = [
        Node(package="uam_solvers", executable="solver", name="solver", output="screen",
             parameters=[params_file("solver"), {"default_backend": a["backend"]}]),
        Node(package="uam_planner", executable="planner", name="planner", output="screen",
             parameters=[params_file("planner"), {"network": network, "policy": a["policy"],
                                                   "backend": a["backend"], "seed": a["seed"],
                                                   "objective": a["objective"],
                                                   "baseline_order": a["baseline_order"],
                                                   "horizon_epochs": a["horizon_epochs"],
                                                   "commit_ahead": a["commit_ahead"],
                                                   "reaction": a["reaction"],
                                                   "conflict_probe_s": a["conflict_probe_s"],
                                                   "conflict_probe_margin_m": a["conflict_probe_margin_m"],
                                                   "replan_policy": a["replan_policy"],
                                                   "journal": PathJoinSubstitution([out, "planner-journal.jsonl"]),
                                                   "climb_rate_mps": a["climb_rate"],
                                                   "descent_rate_mps": a["descent_rate"],
                                                   "constraints_file": a["constraints_file"],
                                                   "authorities_file": a["authorities_file"],
                                                   "priority_grants": a["priority_grants"],
                                                   "spatial_buffer_m": a["spatial_buffer_m"],
                                                   "temporal_buffer_s": a["temporal_buffer_s"],
                                                   # F3548 mode: with the USS serving, its volumes
                                                   "intent_volume_piece_s": ParameterValue(PythonExpression(
                                                       ["float('", a["volume_piece_s"], "') if int('",
                                                        a["uss_port"], "') > 0 else 0.0"]), value_type=float),
                                                   **airspace}]),
        Node(package="uam_sim", executable="request_generator", name="request_generator", output="screen",
             parameters=[params_file("request_generator"), {"network": network, "rate": a["rate"],
                                                             "seed": a["seed"], "demand_file": a["demand_file"],
                                                             "priority_share": a["priority_share"],
                                                             "lead_time_s": a["lead_time_s"]}]),
        recorder,
        # compares every fleet state with the approved plans, publishes uam/conformance
        # (only when asked, or with a disturbance set: conformance:=auto; at the recorder's nice value)
        Node(package="uam_sim", executable="conformance_monitor", name="conformance_monitor", output="screen",
             condition=IfCondition(conformance_on), prefix=recorder_prefix),
        # the simulator, waiting for the observers that run (one of the two starts)
        Node(package="uam_sim", executable="simulator", name="simulator", output="screen",
             condition=IfCondition(conformance_on),
             parameters=[params_file("simulator"),
                         {**sim_params, "wait_for_subscribers": ["recorder", "conformance_monitor"]}]),
        Node(package="uam_sim", executable="simulator", name="simulator", output="screen",
             condition=UnlessCondition(conformance_on),
             parameters=[params_file("simulator"), {**sim_params, "wait_for_subscribers": ["recorder"]}]),
    ]
    # the F3548 USS-USS interface, only with uss_port > 0 (docs/f3548.md); auth verify (the
    # default) needs uss_auth_key:=FILE (the node refuses to start without it)
    nodes.append(Node(package="uam_sim", executable="uss", name="uss", output="screen",
                      condition=IfCondition(PythonExpression(["int('", a["uss_port"], "') > 0"])),
                      parameters=[{"port": a["uss_port"], "network": network,
                                   # the planner's own record, not the topics anyone can publish
                                   "journal": PathJoinSubstitution([out, "planner-journal.jsonl"]), "auth": a["uss_auth"],
                                   "auth_key": a["uss_auth_key"], "auth_audience": a["uss_audience"],
                                   "separation_model": a["separation"],
                                   "separation_m": a["separation_m"],
                                   "vertical_separation_m": a["vertical_separation_m"],
                                   "volume_piece_s": a["volume_piece_s"], "dss_url": a["dss_url"],
                                   "dss_token_file": a["dss_token_file"], "dss_auth_url": a["dss_auth_url"]}]))
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, (default, text) in ARGS.items()]
        + [GroupAction([PushRosNamespace(a["namespace"]), *nodes]),
           # the recorder exits once the simulator ended the run and the file is closed; the
           # solver (a server) is stopped with it
           RegisterEventHandler(OnProcessExit(target_action=recorder,
                                              on_exit=[EmitEvent(event=Shutdown(reason="run finished"))]))])
