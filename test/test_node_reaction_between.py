"""The node graph's reaction between epochs (issue 23): with the simulator's ``reaction_period_s``
the simulator asks the planner to react (``uam/react``) every period between two epochs, in
lockstep, and flies the updates from that instant; the planner solves the reaction's MWIS graphs
through the solver service. Held to the in-process runner with the same configuration: the
same observations, approvals, plan versions and reaction updates (ids, versions, times, plans),
at the epochs and between them."""

from __future__ import annotations

import dataclasses

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import TINY, build_graph, decisions, run_to_end, shutdown  # noqa: E402

from uam_contract import wire  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402

pytestmark = pytest.mark.ros

RATE, SEED, DURATION = 3.0, 5, 300.0
#: +-30 % speed error: flights late or early by 10 s within a minute, so the reaction acts often
SPEED_ERROR = 0.3


class _Scoped:
    """The runner's demand with the node's request ids: the planner node keys every request by
    ``operator_id/request_id`` (wire.scoped_id) and the simulator draws each flight's speed error
    by that key, the runner by the request's own id; scoped here, both draw the same flights."""

    def __init__(self, demand):
        self.demand = demand

    def requests_at(self, t_s, interval_index):
        return [dataclasses.replace(r, request_id=wire.scoped_id("generator", r.request_id))
                for r in self.demand.requests_at(t_s, interval_index)]


class _Spy:
    """Every observation and plan update of each Planner instance (the runner's and the node's
    live in this process: one class, told apart by the instance)."""

    def __init__(self, monkeypatch):
        from uam_planner import planning
        self.observed: dict = {}     # id(planner) -> {(request id, t): position}
        self.between: dict = {}      # id(planner) -> [(t, PlanUpdate)] of react_between_steps
        spy = self
        observe, steps = planning.Planner.observe, planning.Planner.react_between_steps

        def _observe(planner, request_id, t_s, position_m):
            spy.observed.setdefault(id(planner), {}).setdefault((request_id, float(t_s)), tuple(position_m))
            return observe(planner, request_id, t_s, position_m)

        def _steps(planner, t_s, epoch_index):
            updates = yield from steps(planner, t_s, epoch_index)
            spy.between.setdefault(id(planner), []).extend((float(t_s), u) for u in updates)
            return updates

        monkeypatch.setattr(planning.Planner, "observe", _observe)
        monkeypatch.setattr(planning.Planner, "react_between_steps", _steps)


def _runner(spy_epochs: list, period: float):
    from uam_planner.network import load_network
    from uam_sim.world.demand import RequestGenerator
    from uam_sim.studies.experiment import make_config, run_scenario
    cfg = make_config(epoch_s=30.0, time_limit_s=5.0, audit=False, disturbance={"speed_error": SPEED_ERROR},
                      reaction=True, reaction_period_s=period)
    net = load_network(TINY)
    demand = _Scoped(RequestGenerator(net.aerodrome_ids, RATE, cfg.interval_s, cfg.window_s, SEED))

    def observer(t_s, _e, _submitted, _refused, res):
        spy_epochs.extend((float(t_s), u) for u in res.plan_updates)
    return run_scenario(net, "greedy", RATE, SEED, DURATION, cfg, demand=demand, observer=observer)


def _key(p) -> str:
    return wire.scoped_id(p.operator_id, p.request_id)


@pytest.mark.parametrize("period", [0.0, 10.0], ids=["at-epochs", "every-10s"])
def test_the_graph_reacts_as_the_runner_does(ros_context, spin_until, monkeypatch, period):
    """At the epochs only (period 0) and every 10 s between them too: the same observations,
    approvals and plan updates as the runner (before the simulator published an epoch's fleet
    state first and the planner observed at the runner's instants, the lockstep graph reacted to
    nothing at the epochs: its planner read fleet states 30 s old and refused every report)."""
    spy = _Spy(monkeypatch)
    served = []
    from uam_solvers.nodes.solver_node import SolverNode
    on_solve = SolverNode._on_solve

    def counting(node, request, response):   # every graph the solver service solved
        served.append(len(request.weights))
        return on_solve(node, request, response)
    monkeypatch.setattr(SolverNode, "_on_solve", counting)

    sim = {"speed_error": SPEED_ERROR, "disturbance_seed": SEED, "reaction_period_s": period}
    executor, nodes, obs = build_graph(ros_context, rate=RATE, seed=SEED, duration_s=DURATION, backend="greedy",
                                       simulator_extra=sim, planner_extra={"reaction": True}, conformance=True)
    try:
        run_to_end(executor, nodes, obs, spin_until, timeout_s=120.0)
    finally:
        shutdown(executor, nodes)
    planner, simulator = nodes["planner"], nodes["simulator"]
    assert not simulator.error, simulator.error
    at_epochs: list = []
    ref = _runner(at_epochs, period)
    node_id = id(planner.planner)
    runner_id = next(k for k in spy.observed if k != node_id)

    # the same observations: every (flight, time) the planner saw, at the same place, up to the
    # graph's last call (the runner goes on after the end until the last flight has landed: its
    # epoch at DURATION observes at DURATION - 20 and - 10 too)
    node_obs = spy.observed[node_id]
    last_call = DURATION - (period or 30.0)
    runner_obs = {k: v for k, v in spy.observed[runner_id].items() if k[1] <= last_call}
    assert set(node_obs) == set(runner_obs) and runner_obs
    assert max(float(np.max(np.abs(np.subtract(node_obs[k], runner_obs[k])))) for k in runner_obs) < 1e-6
    assert {t % 30.0 for _rid, t in runner_obs} == {0.0, 10.0, 20.0}   # t - 20, t - 10, t; t_k

    # the same approvals, and the same plan updates (flight, version, kind, instant) at the
    # epochs and between them
    assert {wire.scoped_id("generator", k): v for k, v in decisions(obs.plans).items()} == ref.decisions()
    graph_updates = sorted((_key(p), int(p.version), p.update_kind, m.from_time(p.effective_time))
                           for p in obs.plans if int(p.version) > 1)
    runner_updates = sorted((r["request_id"], int(r["version"]), r["kind"], float(r["t_s"]))
                            for r in ref.replans if r["t_s"] < DURATION)
    assert graph_updates == runner_updates, (graph_updates, runner_updates)
    between = [u for u in graph_updates if u[3] % 30.0 != 0.0]
    if period:
        assert between and len(between) < len(graph_updates), "updates both between epochs and at them"
    else:
        assert graph_updates and not between
    # ... on the same trajectories (the new version from its instant on, every waypoint)
    runner_plans = {(u.request_id, int(u.version)): u.flight.trajectory
                    for _t, u in at_epochs + spy.between.get(runner_id, []) if u.flight is not None}
    for p in obs.plans:
        if int(p.version) > 1:
            mine, theirs = m.trajectory_from_plan(p), runner_plans[(_key(p), int(p.version))]
            assert mine.times_s == pytest.approx(theirs.times_s, abs=1e-6)
            assert mine.points_m == pytest.approx(theirs.points_m, abs=1e-6)
    # the node's own accounts of it: every reaction instant asked and answered, every update flown
    assert simulator.reactions_asked == (int(DURATION // 30.0) * 2 if period else 0)
    assert simulator.react_versions_received == len(between) == planner.between_updates
    assert simulator.fly_errors == 0

    # the reaction's MWIS graphs went through the solver service, none solved in the planner:
    # every graph the solver served is an epoch's, an at-epoch reaction's or a between-epoch one
    assert planner.replan_graphs_by_service >= 1   # no constraint here: each is a reaction's
    assert (planner.between_graphs_by_service >= 1) == bool(period)
    epoch_graphs = sum(1 for r in obs.reports if r.vertices > 0)
    assert len(served) == epoch_graphs + planner.replan_graphs_by_service + planner.between_graphs_by_service


def test_reaction_calls_out_of_order_from_another_session_or_outside_the_epoch_are_refused(ros_context, spin_until):
    """The planner serves uam/react only for the simulator it bound to, after the epoch it planned
    last and strictly before the next, in time order; every other call is refused naming the field,
    and the planner goes on serving (here the caller plays the simulator)."""
    from rclpy.executors import MultiThreadedExecutor
    from uam_msgs.srv import PlanEpoch, React
    from uam_contract.names import SERVICE_REACT
    from uam_contract import names as c
    from graph_harness import make_planner
    planner = make_planner(ros_context, backend="greedy", reaction=True, use_solver_service=False,
                           request_wait_timeout_s=0.2)
    caller = rclpy.create_node("caller", context=ros_context)
    executor = MultiThreadedExecutor(num_threads=2, context=ros_context)
    for n in (planner, caller):
        executor.add_node(n)
    plan, react = caller.create_client(PlanEpoch, c.SERVICE_PLAN_EPOCH), caller.create_client(React, SERVICE_REACT)

    def call(client, request):
        assert spin_until(executor, client.service_is_ready, 30)
        fut = client.call_async(request)
        assert spin_until(executor, fut.done, 30), "the planner did not answer"
        return fut.result()

    def reacting(t_s, epoch_index=0, session="sim", epoch_s=30.0):
        return call(react, React.Request(epoch_index=epoch_index, react_time=m.to_time(t_s), epoch_s=epoch_s,
                                         session=session))
    try:
        early = reacting(10.0)   # nothing planned yet
        assert early.status == React.Response.STATUS_REFUSED and "no epoch planned yet" in early.message
        res = call(plan, PlanEpoch.Request(epoch_index=0, epoch_time=m.to_time(0.0), epoch_s=30.0, session="sim"))
        assert res.status == PlanEpoch.Response.STATUS_PLANNED
        refused = {
            "session": reacting(10.0, session="rogue"),
            "epoch_s": reacting(10.0, epoch_s=60.0),
            "epoch_index": reacting(40.0, epoch_index=1),
            "react_time": reacting(30.0),             # the next epoch's time, not between
        }
        for field, r in refused.items():
            assert r.status == React.Response.STATUS_REFUSED and r.message.startswith(field), (field, r.message)
        first = reacting(20.0)
        assert first.status == React.Response.STATUS_REACTED and list(first.plans) == [], first.message
        assert reacting(20.0).message == first.message     # a repeat: the same answer
        late = reacting(10.0)                                # out of order
        assert late.status == React.Response.STATUS_REFUSED and "not after the last reaction" in late.message
        # the planner still serves the run: the next epoch, then a reaction after it
        res = call(plan, PlanEpoch.Request(epoch_index=1, epoch_time=m.to_time(30.0), epoch_s=30.0, session="sim"))
        assert res.status == PlanEpoch.Response.STATUS_PLANNED, res.message
        assert reacting(40.0, epoch_index=1).status == React.Response.STATUS_REACTED
        assert planner.reactions_between == 2
    finally:
        for n in (planner, caller):
            executor.remove_node(n)
        executor.shutdown(timeout_sec=5)
        caller.destroy_node()
        planner.destroy_node()


@pytest.mark.parametrize("period,why", [(30.0, "is not less than epoch_s 30 s"),
                                        (2.5, "is not a multiple of step_s 1 s")])
def test_the_simulator_refuses_a_reaction_period_it_cannot_keep_at_start(ros_context, period, why):
    from graph_harness import params
    from uam_sim.nodes.simulator_node import SimulatorNode
    with pytest.raises(ValueError) as exc:
        SimulatorNode(context=ros_context, parameter_overrides=params(reaction_period_s=period))
    assert str(exc.value).startswith(f"parameter reaction_period_s: {period:g} s") and why in str(exc.value)


def test_observing_at_instants_keeps_the_first_position_of_each_vehicle(ros_context):
    """In the observe-at-instants mode the planner keeps, of each vehicle at each time, the first
    position received (as PositionBook keeps the first of a repeated sample): a second fleet state
    stamped like the real one, which moves one vehicle and leaves the other out, changes nothing;
    a vehicle absent from the state of the call's time is not observed at the earlier instants."""
    from geometry_msgs.msg import Point
    from rclpy.serialization import serialize_message
    from uam_msgs.msg import FleetState, VehicleState
    from graph_harness import make_planner
    planner = make_planner(ros_context, backend="greedy", reaction=True, use_solver_service=False)

    def state(t_s, vehicles, session="sim-1"):
        msg = FleetState(vehicles=[VehicleState(vehicle_id=v, position=Point(x=x, y=0.0, z=90.0))
                                   for v, x in vehicles], step_index=int(t_s), session=session)
        msg.header.stamp = m.to_time(t_s)
        return msg
    try:
        planner._observe_from_calls = True
        planner._bind("sim-1", resumed=False)
        for msg in (state(40.0, [("op/a", 1.0), ("op/b", 2.0), ("op/gone", 3.0)]),
                    state(50.0, [("op/a", 11.0), ("op/b", 12.0)]),
                    state(50.0, [("op/a", 500.0)], session="rogue"),   # another session: not taken
                    state(60.0, [("op/a", 21.0), ("op/b", 22.0)]),
                    state(60.0, [("op/a", 999.0)])):          # forged, session copied: a moved, b left out
            planner._on_fleet_msg(serialize_message(msg))   # the subscription is raw
        with planner._lock:
            planner._read_inbox(60.0, at_epoch=True)
        book = planner.planner.positions
        assert [o.position_m[0] for o in book.observations("op/a", 0.0, 60.0)] == [1.0, 11.0, 21.0]
        # the second state of step 60 with the bound session is a forgery: the next call is refused
        assert planner.source.refused("fleet state") == 1
        assert "two different messages of step 60" in planner.source.problem
        assert [o.position_m[0] for o in book.observations("op/b", 0.0, 60.0)] == [2.0, 12.0, 22.0]
        assert book.latest("op/gone") is None       # not airborne at 60 s: not observed at all
    finally:
        planner.destroy_node()


def test_states_that_arrived_before_the_simulator_called_count_for_the_wait(ros_context):
    """The simulator publishes the fleet state of t = 0 before its first epoch call: once the
    planner binds to that simulator the state counts for the wait of the reaction mode (it waited
    request_wait_timeout_s, 60 s, for a state it had), and another session's never does."""
    from rclpy.serialization import serialize_message
    from uam_msgs.msg import FleetState
    from graph_harness import make_planner
    planner = make_planner(ros_context, backend="greedy", reaction=True, use_solver_service=False)
    try:
        for session, t in (("rogue", 30.0), ("sim-1", 0.0)):
            msg = FleetState(session=session, step_index=int(t))
            msg.header.stamp = m.to_time(t)
            planner._on_fleet_msg(serialize_message(msg))   # the subscription is raw
        assert not planner._stamps_reached(0.0, False)
        planner._bind("sim-1", resumed=False)
        assert planner._stamps_reached(0.0, False) and not planner._stamps_reached(30.0, False)
    finally:
        planner.destroy_node()
