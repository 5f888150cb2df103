"""The UAM node graph for users of /opt/ros/jazzy: the same five nodes and parameter files as
scripts/run_fleet.sh.

    ros2 launch uam_bringup uam.launch.py config_dir:=$PWD/config backend:=exact rate:=10 \
        duration:=600 seed:=0 out:=runs/launch-demo

Every name of the graph is relative (uam_bringup.contract), so ``namespace:=/fleet2`` moves the
whole graph. The launch ends when the simulator ends the run (the recorder closes its file by
itself and exits; the launch then stops the solver, a server). Needs ``launch`` and
``launch_ros``, which the PyPI wheels do not ship (use scripts/run_fleet.sh there).
"""

from __future__ import annotations

import os

from launch import LaunchDescription
from launch.actions import DeclareLaunchArgument, EmitEvent, GroupAction, RegisterEventHandler
from launch.event_handlers import OnProcessExit
from launch.events import Shutdown
from launch.substitutions import LaunchConfiguration, PathJoinSubstitution, PythonExpression
from launch_ros.actions import Node, PushRosNamespace

ARGS = {
    "config_dir": (os.path.join(os.getcwd(), "config"), "folder of the parameter files and networks"),
    "network": ("", "network file (default: <config_dir>/networks/singapore.yaml)"),
    "backend": ("exact", "MWIS backend of the solver and the planner"),
    "policy": ("mwis", "mwis, fifo or firstfit"),
    "objective": ("paper", "what the MWIS maximises: paper, count, delay, priority or fair (docs/objectives.md)"),
    "baseline_order": ("arrival", "order of fifo and firstfit: arrival or priority"),
    "priority_share": ("0.0", "share of random requests of priority class 1 (e.g. 0.05)"),
    "horizon_epochs": ("1", "epochs the MWIS plans jointly (rolling horizon; 1 = the paper's)"),
    "lead_time_s": ("0.0", "requests are filed this long before their earliest departure [s]"),
    "rate": ("10.0", "requests per 30 s"),
    "duration": ("3500.0", "simulated seconds"),
    "seed": ("0", "seed of the demand and of stochastic solvers"),
    "demand_file": ("", "replay a demand file instead of random requests"),
    "mode": ("lockstep", "lockstep or realtime"),
    "rtf": ("1.0", "real-time factor in realtime mode"),
    "rerun": ("save", "off, save, spawn or connect"),
    "out": ("runs/launch", "output folder (run.mcap, run.rrd)"),
    "namespace": ("", "namespace of the whole graph"),
    "separation": ("sphere", "separation model: sphere (the paper's) or cylinder"),
    "separation_m": ("100.0", "separation minimum, the cylinder's horizontal H [m]"),
    "vertical_separation_m": ("30.0", "the cylinder's vertical minimum V [m]"),
    "slot_s": ("0.0", "departure slot [s]; 0 = depart at the epoch time (the paper's rule)"),
}


def generate_launch_description() -> LaunchDescription:
    a = {name: LaunchConfiguration(name) for name in ARGS}
    cfg = a["config_dir"]

    def params_file(node: str):
        return PathJoinSubstitution([cfg, f"{node}.yaml"])

    network = PythonExpression(["'", a["network"], "' or '", cfg, "/networks/singapore.yaml'"])
    mcap = PathJoinSubstitution([a["out"], "run.mcap"])
    rrd = PathJoinSubstitution([a["out"], "run.rrd"])
    # the planner's airspace; the recorder writes it into the MCAP for the analysis' audit
    airspace = {"separation_model": a["separation"], "separation_m": a["separation_m"],
                "vertical_separation_m": a["vertical_separation_m"], "departure_slot_s": a["slot_s"]}
    # as run_fleet.sh: the recorder is not in the lockstep loop, so it runs at a lower priority
    recorder = Node(package="uam_sim", executable="recorder", name="recorder", output="screen",
                    prefix="nice -n 19",
                    parameters=[{"output": mcap, "network": network, "rerun": a["rerun"], "rerun_rrd": rrd,
                                 # as run_fleet.sh: the run starts once the recorder hears these
                                 "wait_for_publishers": ["uam/flight_plans", "uam/planning_reports",
                                                         "uam/requests", "uam/epoch_sync"],
                                 **airspace}])
    nodes = [
        Node(package="uam_solvers", executable="solver", name="solver", output="screen",
             parameters=[params_file("solver"), {"default_backend": a["backend"]}]),
        Node(package="uam_planner", executable="planner", name="planner", output="screen",
             parameters=[params_file("planner"), {"network": network, "policy": a["policy"],
                                                   "backend": a["backend"], "seed": a["seed"],
                                                   "objective": a["objective"],
                                                   "baseline_order": a["baseline_order"],
                                                   "horizon_epochs": a["horizon_epochs"],
                                                   "journal": PathJoinSubstitution([a["out"], "planner-journal.jsonl"]),
                                                   **airspace}]),
        Node(package="uam_sim", executable="request_generator", name="request_generator", output="screen",
             parameters=[params_file("request_generator"), {"network": network, "rate": a["rate"],
                                                             "seed": a["seed"], "demand_file": a["demand_file"],
                                                             "priority_share": a["priority_share"],
                                                             "lead_time_s": a["lead_time_s"]}]),
        recorder,
        Node(package="uam_sim", executable="simulator", name="simulator", output="screen",
             parameters=[params_file("simulator"), {"duration_s": a["duration"], "mode": a["mode"],
                                                     "real_time_factor": a["rtf"]}]),
    ]
    return LaunchDescription(
        [DeclareLaunchArgument(name, default_value=default, description=text)
         for name, (default, text) in ARGS.items()]
        + [GroupAction([PushRosNamespace(a["namespace"]), *nodes]),
           # the recorder exits once the simulator ended the run and the file is closed; the
           # solver (a server) is stopped with it
           RegisterEventHandler(OnProcessExit(target_action=recorder,
                                              on_exit=[EmitEvent(event=Shutdown(reason="run finished"))]))])
