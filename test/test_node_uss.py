"""The uss node in the node graph, in-process, verifying access tokens as it does by default:
every approved plan of a run on the tiny network is served over HTTP as a schema-valid F3548
operational intent with the plan's version; the constraints the planner plans with are served as
F3548 constraints; a malformed id or a huge query is refused with the standard's 400 while the
run goes on to its end; a request without a token is refused with 401."""

from __future__ import annotations

import json

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")
requests = pytest.importorskip("requests")

from uam_msgs.msg import FlightPlan  # noqa: E402

from graph_harness import TINY, build_graph, params, run_to_end, shutdown  # noqa: E402
from uam_planner.f3548 import constraint_entity_id, intent_id, intent_version  # noqa: E402
from uam_planner.f3548_schema import errors  # noqa: E402
import flask  # noqa: E402,F401  the uss node's server, imported before any node's start-up thread
# imports the solvers (two threads importing werkzeug at once raised KeyError 'werkzeug')

pytestmark = pytest.mark.ros


def test_the_graph_serves_its_plans_as_f3548_intents(ros_context, spin_until, tmp_path):
    from uam_sim.f3548.auth import generate_dev_keys, mint_token
    private, public = generate_dev_keys(tmp_path / "uss-auth")
    token = mint_token(private, "localhost", ["utm.strategic_coordination", "utm.constraint_processing"])
    auth = {"Authorization": f"Bearer {token}"}
    cfile = tmp_path / "c.geojson"
    cfile.write_text(json.dumps({"type": "FeatureCollection", "frame": "enu", "features": [
        {"type": "Feature", "geometry": {"type": "Point", "coordinates": [2000.0, 2000.0]},
         "properties": {"id": "far", "version": 1, "reason": "test", "radius_m": 100.0,
                        "lower_m": 0, "upper_m": 300, "start_s": 0, "end_s": 10000}}]}))
    executor, nodes, obs = build_graph(ros_context, rate=3.0, duration_s=180.0, backend="greedy",
                                       planner_extra={"constraints_file": str(cfile)})
    from uam_sim.nodes.uss_node import UssNode
    uss = UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY, auth_key=str(public)))
    nodes["uss"] = uss
    executor.add_node(uss)
    base = uss.server.url
    done = False
    try:
        assert spin_until(executor, lambda: uss.plans >= 2, timeout_s=60)
        r = requests.get(f"{base}/uam_fleet/v1/operational_intents", timeout=10)
        assert r.status_code == 401 and errors(r.json(), "ErrorResponse") == []
        for bad in ("nope", "x" * 5000):
            r = requests.get(f"{base}/uss/v1/operational_intents/{bad}", headers=auth, timeout=10)
            assert r.status_code == 400 and errors(r.json(), "ErrorResponse") == []
        r = requests.get(f"{base}/uss/v1/operational_intents/{intent_id('generator', 'x')}",
                         params={"q": "y" * 5000}, headers=auth, timeout=10)
        assert r.status_code == 400
        run_to_end(executor, nodes, obs, spin_until)
        approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
        assert spin_until(executor, lambda: uss.plans >= len(approved), timeout_s=10)
        assert len(approved) >= 5
        shutdown(executor, nodes)  # the graph is done (no more /clock); the HTTP server goes on:
        done = True                # ask as at the start of the run, when every intent is live
        pruned_at = uss.store._pruned_s  # the store drops intents that ended before its last prune
        uss.store._t_s = 0.0
        served = 0
        for p in approved:
            r = requests.get(f"{base}/uss/v1/operational_intents/{intent_id(p.operator_id, p.request_id)}",
                             headers=auth, timeout=10)
            if p.arrival_time.sec + p.arrival_time.nanosec * 1e-9 < pruned_at:
                assert r.status_code == 404
                continue
            served += 1
            assert r.status_code == 200, (p.request_id, r.text[:200])
            assert errors(r.json(), "GetOperationalIntentDetailsResponse") == []
            ref = r.json()["operational_intent"]["reference"]
            departs = p.departure_time.sec + p.departure_time.nanosec * 1e-9
            assert ref["state"] == ("Activated" if departs <= 0.0 else "Accepted")  # at t = 0
            assert ref["version"] == intent_version(int(p.version), ref["state"])
        assert served >= 5
        r = requests.get(f"{base}/uss/v1/constraints/{constraint_entity_id('far')}", headers=auth, timeout=10)
        assert r.status_code == 200 and errors(r.json(), "GetConstraintDetailsResponse") == []
    finally:
        if not done:
            shutdown(executor, nodes)
        uss.close()


def test_the_node_does_not_start_verifying_without_a_key(ros_context):
    """auth is 'verify' by default: without the auth server's key the node refuses to start,
    naming the parameter; with auth 'off' it starts and says so."""
    from uam_sim.nodes.uss_node import UssNode
    with pytest.raises(ValueError, match="auth_key: '' but auth is 'verify'"):
        UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY))
    uss = UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY, auth="off"))
    try:
        assert uss.server.auth == "off" and "auth is OFF" in uss.server.announcement
        assert requests.get(f"{uss.server.url}/uam_fleet/v1/operational_intents", timeout=10).status_code == 200
    finally:
        uss.close()
        uss.destroy_node()


def test_the_uss_serves_the_planners_journal_not_what_anyone_publishes(ros_context, spin_until, tmp_path):
    """Findings: a forged cancellation removed a flying aircraft's intent, a forged plan was served
    as a real intent, a forged constraint set was served, and one forged /clock at 2^31 - 1 s
    dropped every served intent. With the planner's journal the USS serves the planner's own
    record and the clock of the simulator the journal names: none of these reaches a peer."""
    from builtin_interfaces.msg import Time
    from rosgraph_msgs.msg import Clock
    from std_msgs.msg import String
    from uam_bringup import qos
    from uam_contract import names as c
    from uam_msgs.msg import FleetState, Waypoint
    from uam_planner.constraints import Constraint
    from uam_planner.live_constraints import set_geojson
    from uam_sim.nodes.uss_node import UssNode

    journal = tmp_path / "planner-journal.jsonl"
    executor, nodes, obs = build_graph(ros_context, rate=3.0, duration_s=240.0, backend="greedy",
                                       planner_extra={"journal": str(journal)})
    uss = UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY, auth="off",
                                                                  journal=str(journal)))
    rogue = rclpy.create_node("rogue_uss", context=ros_context)
    plans = rogue.create_publisher(FlightPlan, c.TOPIC_PLANS, qos.QOS_LATCHED)
    sets = rogue.create_publisher(String, c.TOPIC_CONSTRAINTS, qos.QOS_CONSTRAINTS)
    clock = rogue.create_publisher(Clock, c.TOPIC_CLOCK, qos.QOS_CLOCK)
    fleet = rogue.create_publisher(FleetState, c.TOPIC_FLEET, qos.QOS_STREAM)
    nodes["uss"], nodes["rogue"] = uss, rogue
    for n in (uss, rogue):
        executor.add_node(n)
    try:
        sim = nodes["simulator"]
        assert spin_until(executor, lambda: uss.plans >= 2 and sim.t_s >= 60.0, timeout_s=60)
        flying = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
        victim = flying[0]
        oid = intent_id(victim.operator_id, victim.request_id)
        assert oid in uss.store.intent_ids()
        fake = FlightPlan(operator_id="rogue", request_id="ghost", outcome=FlightPlan.OUTCOME_APPROVED, version=1)
        fake.waypoints = [Waypoint(time=Time(sec=100)), Waypoint(time=Time(sec=200))]
        fake.waypoints[1].position.x = 1000.0
        cancel = FlightPlan(operator_id=victim.operator_id, request_id=victim.request_id,
                            outcome=FlightPlan.OUTCOME_REJECTED, version=int(victim.version) + 1)
        sky = Constraint("sky", 1, "forged", 0.0, 1e6, center_m=(0.0, 0.0), radius_m=5e4, lower_m=0.0, upper_m=1e4)
        for _ in range(3):
            plans.publish(fake)
            plans.publish(cancel)
            sets.publish(String(data=set_geojson([sky], 0.0)))
            clock.publish(Clock(clock=Time(sec=2**31 - 1)))
            ahead = FleetState(session=sim.session, step_index=10**9)
            ahead.header.stamp = Time(sec=2**31 - 1)
            fleet.publish(ahead)
            spin_until(executor, lambda: uss.clock_refused >= 1, timeout_s=5)
        ids = uss.store.intent_ids()
        assert oid in ids and intent_id("rogue", "ghost") not in ids
        assert uss.store.constraint_ids() == [] and uss.store.time_s < 1000.0
        assert uss.clock_refused >= 1
        run_to_end(executor, nodes, obs, spin_until)
        approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED and p.operator_id != "rogue"]
        assert spin_until(executor, lambda: uss.plans >= len(approved), timeout_s=10), (uss.plans, len(approved))
        # the simulator's clock (its fleet states are best effort: the last ones may be dropped)
        assert 150.0 <= uss.store.time_s <= sim.t_s
    finally:
        shutdown(executor, nodes)


def test_a_peers_intent_reaches_the_planner_through_the_uss_authority(ros_context, spin_until, tmp_path):
    """A peer posts its operational intent to our USS: the uss node passes it to the planner as a
    live constraint signed by the USS's own airspace authority (not an admin), and the planner
    holds it, authored by that authority, for its next epoch."""
    import numpy as np
    from uam_planner.authority import write_authority
    from uam_planner.f3548 import IntentContext, VolumeSpec, as_json, operational_intent
    from uam_planner.network import load_network
    from uam_planner.planning import Flight
    from uam_planner.trajectory import Trajectory
    from uam_sim.nodes.uss_node import UssNode

    listing, _caa = write_authority(tmp_path / "auth", "caa")
    _listing, peers_key = write_authority(tmp_path / "auth", "uss-peers", admin=False, add=True)
    executor, nodes, obs = build_graph(ros_context, rate=3.0, duration_s=240.0, backend="greedy",
                                       planner_extra={"authorities_file": str(listing)})
    uss = UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY, auth="off",
                                                                  authority_key=str(peers_key)))
    nodes["uss"] = uss
    executor.add_node(uss)
    try:
        planner = nodes["planner"]
        assert spin_until(executor, lambda: planner.epochs_planned >= 2, timeout_s=60)
        net = load_network(TINY)
        ctx = IntentContext(net.origin_lat_lon_alt, VolumeSpec(10.0, 5.0, 1000.0), manager="uss2")
        traj = Trajectory(np.array([60.0, 1000.0]), np.array([[0.0, -50.0, 100.0], [0.0, 50.0, 100.0]]))
        f = Flight("theirs", "X", "Y", ("X", "Y"), traj, 60.0, 1000.0, 0.0, 1.0, 0, "mwis", "greedy", 0,
                   operator_id="uss2-op", version=1)
        doc = as_json(operational_intent(f, 0.0, ctx))
        body = {"operational_intent_id": doc["reference"]["id"], "operational_intent": doc,
                "subscriptions": [{"subscription_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f",
                                   "notification_index": 1}]}
        r = requests.post(f"{uss.server.url}/uss/v1/operational_intents", json=body, timeout=10)
        assert r.status_code == 204, r.text
        assert spin_until(executor, lambda: uss.peer_updates_accepted >= 1, timeout_s=20)
        held = list(planner._projected_constraints().values())
        assert len(held) == 1 and held[0].author == "uss-peers"
    finally:
        shutdown(executor, nodes)
