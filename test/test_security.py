"""Safety that no caller can talk the planner out of (issue 18, docs/security.md).

Each test is an attack made by an ordinary node on the run's domain (a rogue in the in-process
graph) while the graph runs. Each must end in one of two ways: the legitimate approvals of the
clean run (the in-process runner's, same seed), or a run that ends with a reason and a recording
the analysis does not call OK; never a flown pair under the minimum.
"""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import (between_epochs, build_graph, decisions, in_process, make_planner, params,  # noqa: E402
                           run_to_end, shutdown)
from uam_msgs.msg import EpochSync, FlightPlan, FlightRequest  # noqa: E402
from uam_msgs.srv import PlanEpoch, ReleaseDemand  # noqa: E402

from uam_contract import names as c  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402
from uam_bringup import qos
from uam_contract import wire  # noqa: E402
from uam_planner.audit import audit_flights  # noqa: E402

pytestmark = pytest.mark.ros

RATE, SEED, DURATION = 3.0, 13, 240.0


def _flown_audit(obs):
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    return audit_flights([m.trajectory_from_plan(p) for p in approved], separation_m=100.0)


def _flown_by_simulator_audit(sim):
    """The audit of what the simulator flew (its own record of the plans it flew)."""
    return audit_flights([m.trajectory_from_plan(p) for p in sim.flown_plans], separation_m=100.0)


class Rogue:
    """An ordinary node on the run's domain: calls the epoch services and publishes what it likes."""

    def __init__(self, context, name="rogue"):
        self.node = rclpy.create_node(name, context=context)
        self.plan = self.node.create_client(PlanEpoch, c.SERVICE_PLAN_EPOCH)
        self.release = self.node.create_client(ReleaseDemand, c.SERVICE_RELEASE_DEMAND)
        self.sync = self.node.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.requests = self.node.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_REQUESTS)

    def call(self, executor, spin_until, client, request):
        assert spin_until(executor, client.service_is_ready, 10)
        fut = client.call_async(request)
        assert spin_until(executor, fut.done, 30), "the server did not answer the rogue"
        return fut.result()


def _mid_run(executor, nodes, spin_until, t_s=100.0):
    sim = nodes["simulator"]
    assert spin_until(executor, lambda: sim.t_s >= t_s and nodes["planner"]._inflight is None, timeout_s=60)
    return sim


def _run_with_rogue(ros_context, spin_until, attack, tmp_path=None, **kw):
    """Run the clean scenario with ``attack(executor, nodes, rogue)`` made mid-run; returns
    (obs, nodes, what attack returned)."""
    executor, nodes, obs = build_graph(ros_context, rate=RATE, seed=SEED, duration_s=DURATION,
                                       record_to=None if tmp_path is None else tmp_path / "run.mcap", **kw)
    rogue = Rogue(ros_context)
    executor.add_node(rogue.node)
    try:
        out = attack(executor, nodes, rogue)
        sim = nodes["simulator"]
        assert spin_until(executor, lambda: sim.finished, timeout_s=120), f"the run did not end; t={sim.t_s}"
        if "recorder" in nodes:
            assert spin_until(executor, lambda: nodes["recorder"].finished, timeout_s=30)
        if not sim.error:
            run_to_end(executor, nodes, obs, spin_until)
        return obs, nodes, out
    finally:
        executor.remove_node(rogue.node)
        rogue.node.destroy_node()
        shutdown(executor, nodes)


def _clean():
    return in_process(RATE, SEED, DURATION, "exact").decisions()


def test_a_resume_with_an_empty_airborne_list_never_makes_the_planner_forget_the_fleet(ros_context, spin_until):
    """Finding: one PlanEpoch(resume=true, airborne=[]) made the planner forget every aircraft in
    the air; it then approved flights through them (55 flown pairs under 100 m)."""
    def attack(executor, nodes, rogue):
        sim = _mid_run(executor, nodes, spin_until)
        planner = nodes["planner"]
        held = len(planner.planner.active)
        assert held > 0, "the attack needs aircraft in the air"
        # with the simulator's own token (no DDS security: anyone on the domain can read it).
        # The simulator runs on in the same executor: when its own call of epoch k came first,
        # the answer is "in progress" (nothing applied either); then it is tried at the next
        for _attempt in range(20):
            assert spin_until(executor, lambda: planner._inflight is None, timeout_s=60)
            k, held = planner._next_epoch, len(planner.planner.active)
            res = rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(
                epoch_index=k, epoch_time=m.to_time(k * 30.0), epoch_s=30.0, resume=True,
                airborne=[], session=sim.session))
            assert len(planner.planner.active) >= held
            if res.status != PlanEpoch.Response.STATUS_IN_PROGRESS:
                break
        assert res.status == PlanEpoch.Response.STATUS_REFUSED and "resume" in res.message, res.message
        assert len(planner.planner.active) >= held
        return res
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack)
    assert not nodes["simulator"].error
    assert decisions(obs.plans) == _clean()
    assert _flown_audit(obs).ok


def test_epoch_calls_of_another_caller_or_another_epoch_length_are_refused(ros_context, spin_until):
    """Findings: an early PlanEpoch made the simulator fly rogue-triggered epochs; one PlanEpoch
    with epoch_s = 1e6 refused 20 legitimate requests; a million expected ids stalled an epoch."""
    def attack(executor, nodes, rogue):
        sim = _mid_run(executor, nodes, spin_until)
        k = nodes["planner"]._next_epoch
        answers = [
            rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(  # another simulator
                epoch_index=k, epoch_time=m.to_time(k * 30.0), epoch_s=30.0, session="rogue")),
            rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(  # the run's token, a huge epoch
                epoch_index=k, epoch_time=m.to_time(k * 1e6), epoch_s=1e6, session=sim.session)),
            rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(  # an epoch ahead
                epoch_index=k + 5, epoch_time=m.to_time((k + 5) * 30.0), epoch_s=30.0, session=sim.session)),
            rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(  # at the wrong time
                epoch_index=k, epoch_time=m.to_time(k * 30.0 + 7), epoch_s=30.0, session=sim.session)),
            rogue.call(executor, spin_until, rogue.plan, PlanEpoch.Request(  # a flood of expected ids
                epoch_index=k, epoch_time=m.to_time(k * 30.0), epoch_s=30.0, session=sim.session,
                expected_request_ids=[f"x/{i}" for i in range(20_000)])),
        ]
        return answers
    obs, nodes, answers = _run_with_rogue(ros_context, spin_until, attack)
    fields = ["session", "epoch_s", "epoch_index", "epoch_time", "expected_request_ids"]
    for res, field in zip(answers, fields):
        assert res.status == PlanEpoch.Response.STATUS_REFUSED and res.message.startswith(field), (field, res.message)
    assert not nodes["simulator"].error
    assert decisions(obs.plans) == _clean()


def test_release_demand_serves_only_the_bound_simulator_and_its_next_epoch(ros_context, spin_until):
    """Finding: one ReleaseDemand(10^6, t = 600) released all demand at t = 60 (51 of 116 served)."""
    def attack(executor, nodes, rogue):
        sim = _mid_run(executor, nodes, spin_until, t_s=60.0)
        return [
            rogue.call(executor, spin_until, rogue.release, ReleaseDemand.Request(
                epoch_index=10 ** 6, epoch_time=m.to_time(600.0), epoch_s=30.0, session=sim.session)),
            rogue.call(executor, spin_until, rogue.release, ReleaseDemand.Request(
                epoch_index=20, epoch_time=m.to_time(600.0), epoch_s=30.0, session="rogue")),
        ]
    obs, nodes, answers = _run_with_rogue(ros_context, spin_until, attack)
    assert [r.status for r in answers] == [ReleaseDemand.Response.STATUS_REFUSED] * 2
    assert answers[0].message.startswith("epoch_time") or answers[0].message.startswith("epoch_index")
    assert answers[1].message.startswith("session")
    assert not nodes["simulator"].error
    assert decisions(obs.plans) == _clean()


def test_a_second_planner_ends_the_run_with_a_reason_and_the_recording_does_not_verify(
        ros_context, spin_until, tmp_path):
    """Finding: a second planner on the domain took over; the simulator flew its answers."""
    from uam_sim.audit.analysis import summarize

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until)
        nodes["planner2"] = make_planner(ros_context, seed=SEED)
        executor.add_node(nodes["planner2"])
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, tmp_path=tmp_path)
    sim = nodes["simulator"]
    assert sim.error and ("serve" in sim.error or "second planner" in sim.error), sim.error
    assert _flown_by_simulator_audit(sim).ok
    s = summarize(tmp_path / "run.mcap")
    assert not s.verified and any("ended early" in p for p in s.problems), s.problems


def test_a_forged_end_of_run_changes_nothing_and_the_recording_does_not_verify(ros_context, spin_until, tmp_path):
    """Finding: a forged EpochSync(finished) cut the run short and the recording analysed as OK."""
    from uam_sim.audit.analysis import summarize

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until)
        rogue.sync.publish(EpochSync(epoch_index=4, epoch_time=m.to_time(120.0), sender="simulator",
                                     finished=True, session="rogue"))
        # the recorder sees a fourth announcer on the topic (it looks every PUBLISHER_CHECK_S)
        assert spin_until(executor, lambda: c.TOPIC_SYNC in nodes["recorder"].check.foreign, timeout_s=10)
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, tmp_path=tmp_path)
    assert not nodes["simulator"].error
    assert decisions(obs.plans) == _clean()  # planner, generator and recorder ran on to the true end
    s = summarize(tmp_path / "run.mcap")
    assert not s.verified, s.problems
    assert any("simulators announced" in p or "publishers" in p for p in s.problems), s.problems
    # the run's end is its simulator's, not the rogue's t = 120 s
    assert s.run_end == f"ended at t = {DURATION:g} s", s.run_end


def test_a_forged_constraint_set_is_left_out_of_the_audit_and_listed(ros_context, spin_until, tmp_path):
    """Finding: one std_msgs/String on uam/constraints dated t = 0 (a square over the whole network)
    made the analysis report an incursion of every flight back to t = 0. The planning reports now
    name (by SHA-256) every set the planner published; a set none names is listed as forged, left
    out of the audit, and the recording does not verify, naming it."""
    from std_msgs.msg import String
    from uam_planner.constraints import Constraint
    from uam_planner.live_constraints import set_geojson
    from uam_sim.audit.analysis import summarize

    sky = Constraint("sky", 1, "forged", 0.0, 1e6, rings_m=((( -5e4, -5e4), (5e4, -5e4), (5e4, 5e4), (-5e4, 5e4)),),
                     lower_m=-100.0, upper_m=1e4)

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until)
        pub = rogue.node.create_publisher(String, c.TOPIC_CONSTRAINTS, qos.QOS_CONSTRAINTS)
        pub.publish(String(data=set_geojson([sky], 0.0, {"sky": 0.0})))
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, tmp_path=tmp_path)
    assert decisions(obs.plans) == _clean()   # the planner never reads the topic
    s = summarize(tmp_path / "run.mcap")
    assert s.forged_constraint_sets and s.incursions == [] and s.constraints_in_force == 0, s.forged_constraint_sets
    assert not s.verified
    assert any("named by no planning report" in p and "listed as forged" in p for p in s.problems), s.problems


def test_a_third_partys_parameter_change_is_named_in_the_summary(ros_context, spin_until, tmp_path):
    """Finding: valid values set on the planner's request_wait_timeout_s by another node changed the
    run and left no trace. A change of a read-only parameter is refused; every accepted one is
    published by the node that took it, recorded, and named in the summary."""
    from rclpy.parameter import Parameter
    from rclpy.parameter_client import AsyncParameterClient
    from uam_sim.audit.analysis import format_summary, summarize

    answers = {}

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until)
        client = AsyncParameterClient(rogue.node, "planner")
        assert spin_until(executor, lambda: client.services_are_ready(), 10)
        for name, value in (("request_wait_timeout_s", 7.5), ("k", 2)):
            fut = client.set_parameters([Parameter(name, value=value)])
            assert spin_until(executor, fut.done, 10)
            answers[name] = fut.result().results[0]
    _obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, tmp_path=tmp_path)
    assert answers["request_wait_timeout_s"].successful and not answers["k"].successful
    assert "read-only" in answers["k"].reason
    s = summarize(tmp_path / "run.mcap")
    assert len(s.parameter_changes) == 1 and "/planner request_wait_timeout_s = 7.5" in s.parameter_changes[0]
    assert "Parameters       1 change(s) while running" in format_summary(s)


def test_use_sim_time_is_refused_at_run_time(ros_context, spin_until):
    """Finding: /simulator use_sim_time:=true was accepted at run time and froze it for good."""
    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until, t_s=60.0)
        results = {name: nodes[name].set_parameters([rclpy.parameter.Parameter("use_sim_time", value=True)])[0]
                   for name in ("simulator", "planner", "generator", "solver")}
        return results
    import rclpy.parameter
    obs, nodes, results = _run_with_rogue(ros_context, spin_until, attack)
    for name, res in results.items():
        assert not res.successful and "use_sim_time" in res.reason, (name, res.reason)
    assert decisions(obs.plans) == _clean()


def test_use_sim_time_at_start_up_is_refused_naming_it(ros_context):
    from uam_sim.nodes.simulator_node import SimulatorNode

    with pytest.raises(ValueError, match="use_sim_time"):
        SimulatorNode(context=ros_context, parameter_overrides=params(use_sim_time=True))


def test_a_planner_that_lost_its_memory_checks_the_claim_against_its_journal(ros_context, spin_until, tmp_path):
    """A restarted planner with a journal refuses a resume that leaves out aircraft it approved
    (a rogue's, which reaches it before the simulator's), then takes the simulator's true one."""
    from rclpy.executors import SingleThreadedExecutor

    journal = tmp_path / "journal.jsonl"
    executor, nodes, obs = build_graph(ros_context, rate=RATE, seed=SEED, duration_s=DURATION,
                                       planner_extra={"journal": str(journal)})
    rogue = Rogue(ros_context)
    sim = nodes["simulator"]
    try:
        old = nodes["planner"]
        assert spin_until(executor, lambda: sim.t_s >= 90.0 and between_epochs(sim, old) and any(
            f.arrival_s >= old._next_epoch * 30.0 for f in old.planner.active), timeout_s=60)
        k = old._next_epoch
        nodes.pop("planner")
        executor.remove_node(old)
        old.destroy_node()
        # the new planner and the rogue alone: the simulator does not spin, so the rogue is first
        new = make_planner(ros_context, seed=SEED, journal=str(journal))
        alone = SingleThreadedExecutor(context=ros_context)
        alone.add_node(new)
        alone.add_node(rogue.node)
        res = rogue.call(alone, spin_until, rogue.plan, PlanEpoch.Request(
            epoch_index=k, epoch_time=m.to_time(k * 30.0), epoch_s=30.0, resume=True, airborne=[],
            session=sim.session))
        alone.remove_node(new)
        alone.remove_node(rogue.node)
        alone.shutdown()
        assert res.status == PlanEpoch.Response.STATUS_REFUSED and "journal" in res.message \
            and "left out" in res.message, res.message
        assert not new.resumed and new.bound_simulator is None
        nodes["planner"] = new
        executor.add_node(new)
        assert spin_until(executor, lambda: sim.finished, timeout_s=120)
        assert not sim.error, sim.error
        run_to_end(executor, nodes, obs, spin_until)
        assert new.resumed and new.bound_simulator == sim.session
        assert decisions(obs.plans) == _clean()
        assert _flown_by_simulator_audit(sim).ok
    finally:
        rogue.node.destroy_node()
        shutdown(executor, nodes)


def test_refusals_keep_the_offending_id_escaped_so_two_are_never_one_decision(ros_context, spin_until):
    """Finding: refusals of requests with bad ids carried an empty id; two of them made the
    analysis report CONFLICTING decisions for ''."""
    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until, t_s=30.0)
        for rid in ("bad id", "x" * 100_000):
            rogue.requests.publish(FlightRequest(operator_id="console", request_id=rid, origin_id="A",
                                                 destination_id="B", earliest_departure=m.to_time(60),
                                                 latest_departure=m.to_time(120), request_time=m.to_time(30)))
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack)
    refused = [p for p in obs.plans if p.operator_id == "console"]
    assert sorted(p.request_id for p in refused)[0] == "!bad%20id"
    assert len({p.request_id for p in refused}) == 2 and all(len(p.request_id) <= 64 for p in refused)
    assert all(p.outcome == FlightPlan.OUTCOME_REJECTED and "request_id" in p.reason for p in refused)


def test_a_priority_above_the_operators_grant_is_refused_and_takes_no_slot(ros_context, spin_until, tmp_path):
    """Finding: under --objective priority, 340 priority-255 requests from an operator 'medevac'
    took legitimate slots (116 -> 102 approved). With the run's priority grants (medevac granted
    nothing above 0) each is refused naming the field, the value and the grant, and the
    generator's approvals are those of the same run without the attack."""
    from uam_planner.grants import PriorityGrants

    grants = tmp_path / "grants.yaml"
    grants.write_text(PriorityGrants(0, {"generator": 1}).as_yaml())
    extra = {"objective": "priority", "priority_grants": str(grants)}

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until, t_s=30.0)
        for k in range(40):
            for o, d in (("A", "B"), ("B", "C"), ("C", "A")):
                rogue.requests.publish(FlightRequest(
                    operator_id="medevac", request_id=f"m{k}{o}", origin_id=o, destination_id=d, priority=255,
                    earliest_departure=m.to_time(60), latest_departure=m.to_time(120), request_time=m.to_time(30)))
    clean, _n, _ = _run_with_rogue(ros_context, spin_until, lambda *a: None, planner_extra=extra)
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, planner_extra=extra)
    forged = [p for p in obs.plans if p.operator_id == "medevac"]
    assert len(forged) == 120 and all(p.outcome == FlightPlan.OUTCOME_REJECTED for p in forged)
    assert all("priority: 255 is above operator 'medevac''s grant 0" in p.reason for p in forged), forged[0].reason
    assert decisions(obs.plans) == decisions(clean.plans) and decisions(clean.plans)


def test_escaped_ids_name_the_value_and_never_collide():
    assert wire.escaped_id("ok-1.2_3") == "ok-1.2_3"
    assert wire.escaped_id("") == "!"
    assert wire.escaped_id("a b") == "!a%20b" and wire.escaped_id("a/b") == "!a%2Fb"
    long_a, long_b = "y" * 200 + "a", "y" * 200 + "b"
    assert wire.escaped_id(long_a) != wire.escaped_id(long_b)
    assert wire.escaped_id(long_a) == wire.escaped_id(long_a) and len(wire.escaped_id(long_a)) == 64
    assert wire.check_id("request_id", wire.escaped_id("a b"))  # never a valid id itself


def test_a_flood_of_new_operator_ids_cannot_push_out_the_operators_already_served(ros_context, spin_until):
    """Finding: 10,000 requests over 10,000 operator ids filled max_pending and 10 legitimate
    requests were refused "queue is full" (100 of 116 served)."""
    flood = 400  # above max_pending (200), so the queue fills

    def attack(executor, nodes, rogue):
        _mid_run(executor, nodes, spin_until, t_s=40.0)
        # valid requests that wait in the queue (their window opens after the run)
        for i in range(flood):
            rogue.requests.publish(FlightRequest(
                operator_id=f"op{i}", request_id="r", origin_id="A", destination_id="B",
                request_time=m.to_time(40.0), earliest_departure=m.to_time(1000.0),
                latest_departure=m.to_time(1060.0)))
        planner = nodes["planner"]
        assert spin_until(executor, lambda: planner.requests_received >= flood, timeout_s=60)
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack, planner_extra={
        "max_pending": 200, "max_pending_new_operators": 100, "max_window_s": 2000.0})
    refused = [p for p in obs.plans if p.operator_id.startswith("op") and p.outcome == FlightPlan.OUTCOME_REJECTED]
    # at most max_pending of the flood waits (new operators of one epoch hold at most 100 of it;
    # those accepted are established at the next epoch, and the next new ones get 100 more)
    assert len(refused) >= flood - 200 and all("operator_id" in p.reason or "queue" in p.reason for p in refused)
    assert decisions(obs.plans) == _clean()  # every legitimate request was served as in the clean run


def test_ids_in_a_demand_file_are_bounded_at_load_as_on_the_wire(tmp_path):
    from uam_sim.world.demand import DemandError, parse_demand

    with pytest.raises(DemandError, match=r"\[0\]\.id: 'xxxx.*\(100000 characters\) must be 1 to 64"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "id": "x" * 100_000}])
    with pytest.raises(DemandError, match=r"\[0\]\.origin: .*\(5000 characters\)"):
        parse_demand([{"t_s": 0, "origin": "A" * 5000, "destination": "B"}])
    with pytest.raises(DemandError, match=r"\[0\]\.id: 'a b'"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "id": "a b"}])


@pytest.mark.parametrize("seed,knows_token", [(0, False), (1, False), (0, True), (1, True)])
def test_whatever_a_rogue_caller_sends_the_flown_fleet_keeps_its_separation(ros_context, spin_until, seed,
                                                                            knows_token):
    """Property: a rogue that sends random epoch and release calls (resumes with empty or partial
    airborne lists, other epochs, other epoch lengths, ids that never arrive) never makes the
    simulator fly two flights closer than the minimum. Without the run's token it changes
    nothing: the run is the clean run, or ends with a reason. With the token (read off the open
    wire) it impersonates the simulator and can change who is served (e.g. plan the next epoch
    before the simulator asks, before its requests arrived): only DDS Security stops that
    (docs/security.md), but separation still holds."""
    import numpy as np

    rng = np.random.default_rng(seed)

    def attack(executor, nodes, rogue):
        sim = nodes["simulator"]
        assert spin_until(executor, lambda: sim.t_s >= 30.0, timeout_s=60)
        for _ in range(25):
            k = int(rng.integers(0, 12))
            epoch_s = float(rng.choice([30.0, 30.0, 1.0, 1e6]))
            session = sim.session if knows_token and rng.random() < 0.8 else f"rogue{int(rng.integers(3))}"
            if rng.random() < 0.7:
                seen = [p for p in sim.flown_plans]
                airborne = [] if rng.random() < 0.5 or not seen else \
                    [seen[i] for i in rng.choice(len(seen), size=min(len(seen), 2), replace=False)]
                req = PlanEpoch.Request(epoch_index=k, epoch_time=m.to_time(k * epoch_s), epoch_s=epoch_s,
                                        resume=bool(rng.random() < 0.6), airborne=airborne, session=session,
                                        expected_request_ids=[f"x/{i}" for i in range(int(rng.integers(0, 3)))])
                fut = rogue.plan.call_async(req)
            else:
                fut = rogue.release.call_async(ReleaseDemand.Request(
                    epoch_index=k, epoch_time=m.to_time(k * epoch_s), epoch_s=epoch_s, session=session))
            spin_until(executor, fut.done, timeout_s=5)
            if sim.finished:
                break
    obs, nodes, _ = _run_with_rogue(ros_context, spin_until, attack)
    sim = nodes["simulator"]
    assert _flown_by_simulator_audit(sim).ok
    if not knows_token:
        assert not sim.error and decisions(obs.plans) == _clean(), sim.error


def test_forged_conformance_reports_never_drop_a_flight_nor_change_a_conforming_one(ros_context, spin_until):
    """A rogue publishes on uam/conformance that every vehicle it sees (and some that do not
    exist) is nonconforming, at every fleet state. The planner (reaction on) takes a report as a
    claim: it checks it against its own plan and the fleet state it saw (issue 23,
    uam_planner.nonconformance). The fleet flies its plans exactly, so every claim is refused:
    the run is the clean run, no flight gets a new version, none is dropped, and what flew keeps
    its separation."""
    from uam_msgs.msg import Conformance, FleetState

    def attack(executor, nodes, rogue):
        pub = rogue.node.create_publisher(Conformance, c.TOPIC_CONFORMANCE, qos.QOS_STREAM)
        sent = []

        def forge(fs):
            ids = [v.vehicle_id for v in fs.vehicles] + ["nobody/x", "generator/never"]
            # with the simulator's session copied (anyone can read it): only the content is forged
            pub.publish(Conformance(header=fs.header, step_index=fs.step_index, session=fs.session, vehicle_ids=ids,
                                    conforming=[False] * len(ids), lateral_m=[500.0] * len(ids),
                                    vertical_m=[0.0] * len(ids), time_error_s=[60.0] * len(ids),
                                    excursion_s=[30.0] * len(ids)))
            sent.append(len(ids))
        rogue.node.create_subscription(FleetState, c.TOPIC_FLEET, forge, qos.QOS_STREAM)
        # and one malformed report (lengths that do not match)
        pub.publish(Conformance(vehicle_ids=["generator/a", "generator/b"], conforming=[False]))
        return sent

    obs, nodes, sent = _run_with_rogue(ros_context, spin_until, attack, planner_extra={"reaction": True})
    sim, planner = nodes["simulator"], nodes["planner"]
    assert not sim.error, sim.error
    assert sum(sent) > 50 and planner.conformance_reports > 50
    assert decisions(obs.plans) == _clean()
    assert [p for p in obs.plans if int(p.version) > 1] == []        # no flight was re-planned
    assert sim.fly_errors == 0 and _flown_by_simulator_audit(sim).ok
    # every approved flight flew: none was dropped from the fleet by a report
    flown = {f"{p.operator_id}/{p.request_id}" for p in sim.flown_plans}
    assert flown == {f"{p.operator_id}/{p.request_id}" for p in obs.plans
                     if p.outcome == FlightPlan.OUTCOME_APPROVED}


def test_a_fleet_state_forged_ahead_of_the_simulators_ends_the_run_naming_it(ros_context, spin_until):
    """A rogue that reads each fleet state publishes the next step's before the simulator does,
    with the simulator's session copied and every vehicle moved 60 m. The planner cannot tell
    which of the two it believed first, so it refuses the next epoch naming the forgery and the
    simulator ends the run with that reason (the recording is NOT VERIFIED). Without the session
    the forgery is not taken at all: the run is the clean run."""
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FleetState, VehicleState

    def attacker(copy_session: bool):
        def attack(executor, nodes, rogue):
            pub = rogue.node.create_publisher(FleetState, c.TOPIC_FLEET, qos.QOS_STREAM)
            sent = []

            def forge(fs):
                if fs.step_index % 2 or not fs.vehicles or sent and sent[-1] >= fs.step_index:
                    return   # one forgery per two steps, never one of its own
                t = m.from_time(fs.header.stamp) + 1.0
                fake = FleetState(step_index=fs.step_index + 1, session=fs.session if copy_session else "rogue",
                                  vehicles=[VehicleState(vehicle_id=v.vehicle_id, position=Point(
                                      x=v.position.x + 60.0, y=v.position.y, z=v.position.z)) for v in fs.vehicles])
                fake.header.stamp, fake.header.frame_id = m.to_time(t), fs.header.frame_id
                pub.publish(fake)
                sent.append(fake.step_index)
            rogue.node.create_subscription(FleetState, c.TOPIC_FLEET, forge, qos.QOS_STREAM)
            return sent
        return attack

    obs, nodes, sent = _run_with_rogue(ros_context, spin_until, attacker(True))
    sim, planner = nodes["simulator"], nodes["planner"]
    assert sent and "fleet state: two different messages of step" in sim.error, sim.error
    assert planner.source.problem and "forged" in planner.source.problem
    obs, nodes, sent = _run_with_rogue(ros_context, spin_until, attacker(False))
    sim, planner = nodes["simulator"], nodes["planner"]
    assert not sim.error, sim.error
    # (the planner reads its inbox, which keeps the newest messages, at each epoch)
    assert len(sent) > 10 and planner.source.refused("fleet state") > 0
    assert decisions(obs.plans) == _clean()


def test_forged_or_missing_fleet_states_never_make_the_planner_forget_a_late_flight_early():
    """Issue 23's safety gap: the planner holds a flight that flies past its plan (seen in its own
    fleet state, uam_planner.nonconformance.overruns). No observation can make it let go early:
    after a real sighting of the flight late, forged fleet states putting it on time at its
    destination, one stamped far in the future, malformed ones and then none at all (the vehicle
    vanishes) leave it held until the real sighting's projection lands; and forged sightings
    cannot hold it for ever (the bound: its planned arrival plus its planned flight time).
    By hand: P flies W (0, 0) -> E (6000, 0), planned 0 -> 600 s at 10 m/s, in fact at 9 m/s
    (x = 9 t, lands at 666.67 s); R asks to leave E for W at 630 s, head-on into it."""
    import numpy as np
    from uam_planner.network import network_from_enu
    from uam_planner.nonconformance import MAX_OVERRUN_SHARE
    from uam_planner.planning import Flight, FlightRequest as Request, Planner, PlanningConfig
    from uam_planner.trajectory import Trajectory

    net = network_from_enu("line", ["W", "E"], [(0, 0, 0), (6000, 0, 0)], [True, True], [("W", "E")])
    plan = Trajectory(np.array([0.0, 600.0]), np.array([[0.0, 0, 0], [6000.0, 0, 0]]))
    p_flight = Flight("P", "W", "E", ("W", "E"), plan, 0.0, 600.0, 6000.0, 1.0, 0, "greedy", "greedy", 0)

    def planner():
        p = Planner(net, PlanningConfig(), "mwis", solve_mwis=None)
        p.restore([p_flight])
        for t in np.arange(10.0, 631.0, 10.0):          # the real fleet state, up to 630 s
            assert p.observe("P", float(t), (9.0 * t, 0.0, 0.0)) is None
        return p

    p = planner()
    assert p.submit(Request("R", "E", "W", 630.0, 630.0, 700.0)) is None
    res = p.plan(630.0, 21)
    # seen at 630 s at 5670 m, planned there at 567 s: the rest of the plan 63 s late lands at 663 s
    assert res.approved == [] and res.report.overruns == {"P": pytest.approx(663.0)}
    # the attack: on time at E every second, far in the future at W, malformed; no real state after
    for t in range(631, 660):
        assert p.observe("P", float(t), (6000.0, 0.0, 0.0)) is None
    assert p.observe("P", 1e9, (0.0, 0.0, 0.0)) is None
    assert p.observe("P", 640.0, (float("nan"), 0.0, 0.0)).startswith("position_m:")
    assert p.observe("P", float("inf"), (0.0, 0.0, 0.0)).startswith("t_s:")
    res = p.plan(660.0, 22)
    assert res.approved == [] and res.report.overruns == {"P": pytest.approx(663.0)}   # still held
    (r,) = p.plan(690.0, 23).approved                                                 # landed: R goes
    assert r.departure_s == 690.0 and p.overruns == {}

    # forged sightings of P back at W every 10 s: held, but never past 600 + 600 s
    p = planner()
    cap = 600.0 + MAX_OVERRUN_SHARE * 600.0
    t = 640.0
    for k in range(21, 45):
        epoch = 30.0 * k
        while t <= epoch:
            p.observe("P", t, (0.0, 0.0, 0.0))
            t += 10.0
        held = p.plan(epoch, k).report.overruns
        # 630 s: the real sighting's projection; from 660 s the forged ones (at W at 660 s: the
        # whole plan again, landing at 1260 s), cut at the bound; then let go for good
        assert held == ({"P": pytest.approx(663.0)} if epoch == 630.0 else
                        {"P": pytest.approx(cap)} if epoch <= cap else {}), epoch
