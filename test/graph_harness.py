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

    from uam_contract import names as c
    from uam_bringup import qos

    obs = Observer()
    node = rclpy.create_node("test_observer", context=context)
    node.create_subscription(FlightPlan, c.TOPIC_PLANS, obs.plans.append, qos.QOS_LATCHED)
    node.create_subscription(PlanningReport, c.TOPIC_REPORTS, obs.reports.append, qos.QOS_LATCHED)
    node.create_subscription(FlightRequest, c.TOPIC_REQUESTS, obs.requests.append, qos.QOS_LATCHED)
    node.create_subscription(FleetState, c.TOPIC_FLEET, obs.fleet.append, qos.QOS_STREAM)
    return node, obs


def build_graph(context, *, network=TINY, rate=2.0, seed=3, duration_s=300.0, policy="mwis", backend="exact",
                with_solver=True, with_planner=True, planner_extra=None, simulator_extra=None, generator_extra=None,
                record_to=None, threads=4, recorder_extra=None, conformance=False):
    """The graph's nodes on one multi-threaded executor; returns (executor, nodes dict, observer).

    Readiness is the epoch protocol: the simulator starts once the planner's and the generator's
    services are up (and, with ``record_to``, once the recorder subscribes to the fleet state).
    The run's ``seed`` goes to the generator and the planner (stochastic backends), as
    scripts/run_fleet.sh does.
    """
    nodes = {}
    if with_solver:
        nodes["solver"] = make_solver(context, backend)
    if with_planner:
        nodes["planner"] = make_planner(context, network=network, policy=policy, backend=backend, seed=seed,
                                        **(planner_extra or {}))
    from uam_sim.nodes.request_generator_node import RequestGeneratorNode
    nodes["generator"] = RequestGeneratorNode(context=context, parameter_overrides=params(
        network=network, rate=float(rate), seed=int(seed), **(generator_extra or {})))
    if record_to is not None:
        from uam_sim.nodes.recorder_node import RecorderNode
        nodes["recorder"] = RecorderNode(context=context, parameter_overrides=params(
            output=str(record_to), network=network, rerun="off", **(recorder_extra or {})))
    waits = ["recorder"] if record_to is not None else []
    if conformance:  # issue 23: the conformance monitor, which the simulator waits for
        from uam_sim.nodes.conformance_node import ConformanceNode
        nodes["conformance_monitor"] = ConformanceNode(context=context)
        waits.append("conformance_monitor")
    observer_node, obs = make_observer(context)
    nodes["observer"] = observer_node
    from uam_sim.nodes.simulator_node import SimulatorNode
    nodes["simulator"] = SimulatorNode(context=context, parameter_overrides=params(
        duration_s=float(duration_s), wait_for_subscribers=waits or [""],
        **(simulator_extra or {})))
    executor = MultiThreadedExecutor(num_threads=threads, context=context)
    for n in nodes.values():
        executor.add_node(n)
    return executor, nodes, obs


def make_solver(context, backend="exact"):
    from uam_solvers.nodes.solver_node import SolverNode
    return SolverNode(context=context, parameter_overrides=params(default_backend=backend))


def make_planner(context, *, network=TINY, policy="mwis", backend="exact", seed=3, **extra):
    from uam_planner.nodes.planner_node import PlannerNode
    return PlannerNode(context=context, parameter_overrides=params(
        network=network, policy=policy, backend=backend, seed=int(seed), **extra))


def between_epochs(sim, planner) -> bool:
    """The planner has answered the epoch the simulator waits for and plans nothing: no call of
    the simulator can reach it before the executor spins a few more times (the multi-threaded
    executor runs a callback in a worker after spin_once returns, so `_inflight is None` alone
    can be read just before a call that is already under way sets it)."""
    k = sim._waiting_epoch
    return k is not None and planner._inflight is None and planner._last is not None and planner._last[0] == k


def run_to_end(executor, nodes, obs, spin_until, timeout_s=120.0):
    """Spin until the simulator ended the run and the observer holds every plan and report."""
    sim = nodes["simulator"]
    assert spin_until(executor, lambda: sim.finished, timeout_s=timeout_s), f"run did not finish; t={sim.t_s}"
    assert not sim.error, sim.error
    if "recorder" in nodes:  # closes the file by itself once the last messages are in
        assert spin_until(executor, lambda: nodes["recorder"].finished, timeout_s=30)
    n_requests = nodes["generator"].published
    assert spin_until(executor, lambda: len(obs.requests) >= n_requests, timeout_s=10)
    assert spin_until(executor, lambda: len(obs.fleet) >= len(sim.active_samples), timeout_s=10)
    if "planner" in nodes:
        planner = nodes["planner"]
        assert spin_until(executor, lambda: len(obs.reports) >= planner.epochs_planned, timeout_s=10)
        assert spin_until(executor, lambda: len(obs.plans) >= planner.plans_published, timeout_s=10)
    return obs


def decisions(plans, operator_id="generator") -> dict:
    """request id -> (epoch, candidate) of the approvals of one operator (what must match a run);
    later versions of a plan (re-plans, issue 22) are not approvals and are left out."""
    from uam_msgs.msg import FlightPlan
    return {p.request_id: (int(p.epoch_index), int(p.candidate_index)) for p in plans
            if p.outcome == FlightPlan.OUTCOME_APPROVED and p.operator_id == operator_id
            and int(getattr(p, "version", 1)) <= 1}


def in_process(rate, seed, duration_s, backend, policy="mwis", epoch_s=30.0, network=TINY, time_limit_s=5.0,
               **airspace):
    """The same scenario through uam_sim.studies.experiment's in-process runner (``airspace``: its
    separation_model, vertical_separation_m, departure_slot_s, ... options)."""
    from uam_planner.network import load_network
    from uam_sim.studies.experiment import make_config, run_scenario
    method = policy if policy in ("fifo", "firstfit") else backend
    cfg = make_config(epoch_s=float(epoch_s), time_limit_s=float(time_limit_s), audit=False, **airspace)
    return run_scenario(load_network(network), method, rate, seed, duration_s, cfg)


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
