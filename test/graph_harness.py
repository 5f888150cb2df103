"""Build and run the whole node graph inside one process for tests (one Context, one executor)."""

from __future__ import annotations

import gc
import pathlib
from dataclasses import dataclass, field

from rclpy.executors import MultiThreadedExecutor
from rclpy.parameter import Parameter

ROOT = pathlib.Path(__file__).resolve().parents[1]
TINY = str(ROOT / "config" / "networks" / "tiny.yaml")


def params(**values) -> list[Parameter]:
    return [Parameter(k, value=v) for k, v in values.items()]


@dataclass
class Observer:
    """Collects what the graph publishes, like an operator's console."""

    plans: list = field(default_factory=list)
    reports: list = field(default_factory=list)
    requests: list = field(default_factory=list)
    fleet: list = field(default_factory=list)


def make_observer(context):
    import rclpy
    from uam_msgs.msg import FleetState, FlightPlan, FlightRequest, PlanningReport

    from uam_bringup import contract as c
    from uam_bringup import qos

    obs = Observer()
    node = rclpy.create_node("test_observer", context=context)
    node.create_subscription(FlightPlan, c.TOPIC_PLANS, obs.plans.append, qos.QOS_LATCHED)
    node.create_subscription(PlanningReport, c.TOPIC_REPORTS, obs.reports.append, qos.QOS_LATCHED)
    node.create_subscription(FlightRequest, c.TOPIC_REQUESTS, obs.requests.append, qos.QOS_LATCHED)
    node.create_subscription(FleetState, c.TOPIC_FLEET, obs.fleet.append, qos.QOS_STREAM)
    return node, obs


def build_graph(context, *, network=TINY, rate=2.0, seed=3, duration_s=300.0, policy="mwis", backend="exact",
                with_solver=True, planner_extra=None, expected_subscribers=3, record_to=None):
    """The graph's nodes on one multi-threaded executor; returns (executor, nodes dict, observer).

    The simulator starts once planner, generator, itself (and the recorder, with ``record_to``)
    subscribe to /uam/epoch_sync and, with ``record_to``, the recorder to the fleet streams.
    """
    from uam_planner.nodes.planner_node import PlannerNode
    from uam_sim.nodes.request_generator_node import RequestGeneratorNode
    from uam_sim.nodes.simulator_node import SimulatorNode
    from uam_solvers.nodes.solver_node import SolverNode

    nodes = {}
    if with_solver:
        nodes["solver"] = SolverNode(context=context, parameter_overrides=params(default_backend=backend))
    nodes["planner"] = PlannerNode(context=context, parameter_overrides=params(
        network=network, policy=policy, backend=backend, **(planner_extra or {})))
    nodes["generator"] = RequestGeneratorNode(context=context, parameter_overrides=params(
        network=network, rate=float(rate), seed=int(seed)))
    if record_to is not None:
        from uam_sim.nodes.recorder_node import RecorderNode
        nodes["recorder"] = RecorderNode(context=context, parameter_overrides=params(
            output=str(record_to), network=network, rerun="off"))
        expected_subscribers += 1
    observer_node, obs = make_observer(context)
    nodes["observer"] = observer_node
    nodes["simulator"] = SimulatorNode(context=context, parameter_overrides=params(
        duration_s=float(duration_s), expected_subscribers=int(expected_subscribers),
        expected_stream_subscribers=0 if record_to is None else 1))
    executor = MultiThreadedExecutor(num_threads=4, context=context)
    for n in nodes.values():
        executor.add_node(n)
    return executor, nodes, obs


def shutdown(executor, nodes):
    for n in nodes.values():
        if hasattr(n, "stopping"):
            n.stopping.set()  # a planner callback waiting on the solver gives up
        executor.remove_node(n)
    executor.shutdown(timeout_sec=10)
    for n in nodes.values():
        n.destroy_node()
    # Callbacks that were mid-flight when the nodes went away end with rclpy's "destruction was
    # requested" error; collect those tasks now (inside the test, where output is captured)
    # instead of at interpreter exit, where rclpy prints them after pytest's summary.
    with executor._tasks_lock:
        tasks = [t for t, _entity, _node in executor._tasks]
        executor._tasks.clear()
    for task in tasks:
        if task.done():
            task.exception()  # marks it retrieved
    del tasks
    gc.collect()
