"""Probes of the open wire through the real node graph in one process: what anyone on the domain
can publish on uam/requests must not change another request's outcome, take its id, or blow up
the recording."""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from builtin_interfaces.msg import Time  # noqa: E402
from graph_harness import build_graph, decisions, in_process, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan, FlightRequest  # noqa: E402

from uam_contract import names as c  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402
from uam_bringup import qos
from uam_contract import wire  # noqa: E402
from uam_contract.wire import MAX_REASON_CHARS, check_id, echo  # noqa: E402

pytestmark = pytest.mark.ros


def _req(rid, origin="A", dest="B", t=0.0, earliest=None, latest=None, operator="probe", **times):
    msg = FlightRequest(operator_id=operator, request_id=rid, origin_id=origin, destination_id=dest,
                        request_time=m.to_time(t), earliest_departure=m.to_time(t if earliest is None else earliest),
                        latest_departure=m.to_time(t + 60.0 if latest is None else latest))
    for k, v in times.items():
        setattr(msg, k, v)
    return msg


class Probe:
    """A node anyone could start on the domain, publishing on uam/requests."""

    def __init__(self, context, executor):
        self.node = rclpy.create_node("probe", context=context)
        self.pub = self.node.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_REQUESTS)
        executor.add_node(self.node)

    def publish(self, msgs):
        for msg in msgs:
            self.pub.publish(msg)


def _run_with(ros_context, spin_until, probe_msgs, when=None, rate=3.0, seed=21, duration=150.0, planner_extra=None,
              answers=None):
    """Run the graph; publish ``probe_msgs`` at start, or once ``when(nodes, obs)`` holds; with
    ``answers``, also wait until the observer holds that many plans for the probe's operators."""
    executor, nodes, obs = build_graph(ros_context, rate=rate, seed=seed, duration_s=duration,
                                       planner_extra=planner_extra)
    probe = Probe(ros_context, executor)
    try:
        if when is None:
            probe.publish(probe_msgs)
        else:
            assert spin_until(executor, lambda: when(nodes, obs), timeout_s=60)
            probe.publish(probe_msgs(nodes, obs) if callable(probe_msgs) else probe_msgs)
        run_to_end(executor, nodes, obs, spin_until, timeout_s=180)  # every plan published is observed
        if answers is not None:
            assert spin_until(executor, lambda: sum(p.operator_id != "generator" for p in obs.plans) >= answers, 60)
        return obs, nodes
    finally:
        probe.node.destroy_node()
        shutdown(executor, nodes)


def test_malformed_and_implausible_requests_are_refused_naming_the_field(ros_context, spin_until):
    """Finding: accepted and approved were 100 kB ids, ids with newlines or escape codes, windows
    68 years ahead, nanosec 4294967295, a request_time 5,000 s after the earliest departure; a
    1 MB origin string was echoed whole into the reason."""
    big = "x" * 100_000
    probes = {
        "long_id": (_req(big), "request_id"),
        "newline_id": (_req("evil\nid"), "request_id"),
        "escape_id": (_req("esc\x1b[31m"), "request_id"),
        "long_operator": (_req("op1", operator="o" * 1000), "operator_id"),
        "no_operator": (_req("op2", operator=""), "operator_id"),
        "far_window": (_req("far", latest=68 * 365 * 86400.0), "latest_departure"),
        "nanosec": (_req("ns", earliest_departure=Time(sec=0, nanosec=4294967295)), "earliest_departure.nanosec"),
        "request_after_window": (_req("late", t=5000.0, earliest=0.0, latest=60.0), "request_time"),
        "huge_origin": (_req("orig", origin="O" * 1_000_000), "origin_id"),
    }
    obs, nodes = _run_with(ros_context, spin_until, [msg for msg, _ in probes.values()])
    refusals = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_REJECTED and p.operator_id != "generator"]
    for name, (msg, field) in probes.items():
        if check_id("operator_id", msg.operator_id) or check_id("request_id", msg.request_id):
            # a refusal cannot carry the id it refuses: it carries a stand-in that names it, escaped
            # and cut (wire.escaped_id: never a valid id), and shows the id cut short in the reason
            bad = msg.operator_id if check_id("operator_id", msg.operator_id) else msg.request_id
            match = [p for p in refusals if p.request_id == wire.escaped_id(msg.request_id)
                     and p.operator_id == wire.escaped_id(msg.operator_id) and echo(bad) in p.reason]
        else:
            match = [p for p in refusals if p.operator_id == "probe" and p.request_id == msg.request_id]
        assert len(match) == 1, (name, [p.reason for p in refusals])
        plan = match[0]
        assert plan.reason.startswith(field), (name, plan.reason)
        assert len(plan.reason) <= MAX_REASON_CHARS and "\n" not in plan.reason, name
        assert len(plan.origin_id) <= 128, name
    assert len(refusals) == len(probes)
    # nothing of it flies, and the legitimate run is the in-process one
    assert max(len(p.request_id) for p in obs.plans) <= 64
    assert decisions(obs.plans) == in_process(3.0, 21, 150.0, "exact").decisions()


def test_a_duplicate_id_never_changes_or_hides_a_decision(ros_context, spin_until):
    """Finding: re-sending a pending request's id published a REJECTED plan under the original's
    id, the analysis kept that one, and an approved flight dropped out of the audit."""
    target = "r00002_000"

    def target_published(nodes, obs):
        return any(r.request_id == target and r.operator_id == "generator" for r in obs.requests)

    def copies(nodes, obs):
        orig = next(r for r in obs.requests if r.request_id == target)
        return [_req(target, origin=orig.destination_id, dest=orig.origin_id, t=60.0, operator="generator")
                for _ in range(3)]
    obs, _ = _run_with(ros_context, spin_until, copies, when=target_published)
    plans = [p for p in obs.plans if p.request_id == target and p.operator_id == "generator"]
    dup = [p for p in plans if p.outcome == FlightPlan.OUTCOME_DUPLICATE]
    real = [p for p in plans if p.outcome != FlightPlan.OUTCOME_DUPLICATE]
    assert len(dup) == 3 and all("already" in p.reason for p in dup)
    assert len(real) == 1, [(p.outcome, p.reason) for p in real]
    assert decisions(obs.plans) == in_process(3.0, 21, 150.0, "exact").decisions()


def test_ids_cannot_be_squatted(ros_context, spin_until):
    """Finding: publishing r00015_000 at t = 60 s got it approved, and the generator's real
    request with that id was refused as a duplicate at t = 450 s."""
    squat = [_req("r00004_000", origin="C", dest="D", t=0.0, latest=40.0, operator="intruder"),
             _req("r00004_001", origin="C", dest="D", t=0.0, latest=40.0, operator="intruder")]
    obs, _ = _run_with(ros_context, spin_until, squat)
    gen = {p.request_id: p for p in obs.plans if p.operator_id == "generator"}
    for rid in ("r00004_000", "r00004_001"):
        if rid in gen:  # the generator's own request was decided on its merits
            assert gen[rid].outcome in (FlightPlan.OUTCOME_APPROVED, FlightPlan.OUTCOME_EXPIRED), gen[rid].reason
    assert "r00004_000" in gen
    theirs = [p for p in obs.plans if p.operator_id == "intruder"]
    assert len(theirs) == 2 and all(p.outcome != FlightPlan.OUTCOME_DUPLICATE for p in theirs)


@pytest.mark.slow
def test_a_flood_is_bounded_and_legitimate_requests_are_still_served(ros_context, spin_until):
    """Finding: 10,000 valid requests in 3 s left 36 of 121 legitimate requests approved, the
    rest rejected as "latest_departure before the current simulation time"."""
    n_flood, quota = 1500, 40
    flood = [_req(f"f{i:05d}", origin="A", dest="B", t=0.0, latest=900.0, operator="flood") for i in range(n_flood)]
    obs, nodes = _run_with(ros_context, spin_until, flood, planner_extra={"max_pending_per_operator": quota},
                           answers=n_flood - 2 * quota)
    theirs = [p for p in obs.plans if p.operator_id == "flood"]
    refused = [p for p in theirs if p.outcome == FlightPlan.OUTCOME_REJECTED]
    # at most `quota` of theirs wait at any time (a few more are accepted as earlier ones are
    # decided; those still waiting at the end have no answer yet)
    assert n_flood - 2 * quota <= len(refused) <= n_flood - quota
    assert all(p.reason.startswith("operator_id") and "quota" in p.reason for p in refused)
    gen = [p for p in obs.plans if p.operator_id == "generator"]
    assert gen and not any(p.outcome == FlightPlan.OUTCOME_REJECTED for p in gen), \
        [p.reason for p in gen if p.outcome == FlightPlan.OUTCOME_REJECTED][:3]
    # every legitimate request was planned at its first epoch: served, in order
    requested = {r.request_id: m.from_time(r.earliest_departure) for r in obs.requests if r.operator_id == "generator"}
    approved = [p for p in gen if p.outcome == FlightPlan.OUTCOME_APPROVED]
    assert approved
    decided = {p.request_id for p in gen}
    last_epoch_t = 120.0
    late = [(rid, t) for rid, t in requested.items() if t + 60.0 < last_epoch_t and rid not in decided]
    assert not late, (late, len(obs.plans), nodes["planner"].plans_published)
