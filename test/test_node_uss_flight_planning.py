"""InterUSS's flight_planning interface through the node graph: a flight plan PUT over HTTP to the
uss node goes to the planner node signed by the USS's airspace authority, is planned at the
planner's next epoch and answered Planned once the planner's journal holds it; a modification is
a new version of the same operational intent; a DELETE cancels it; a request forged on the ROS
domain in the USS's name (on uam/requests, unsigned, or signed by another key) is refused by the
planner, which logs and counts it (and publishes the refusal of the topic's request)."""

from __future__ import annotations

import concurrent.futures
import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")
requests = pytest.importorskip("requests")

from graph_harness import TINY, build_graph, params, shutdown  # noqa: E402
import flask  # noqa: E402,F401  the uss node's server, imported before any node's start-up thread
# imports the solvers (two threads importing werkzeug at once raised KeyError 'werkzeug')

pytestmark = [pytest.mark.ros, pytest.mark.slow]

FID = "5f0f6b52-8c55-4d4e-9d4a-1e2b3c4d5e6f"
OP = "flight_planning"


def area(ctx, net, t0, t1, x_m=0.0):
    """A flight_planning area: one Volume4D, an ENU box around (x_m, 0) from the ground to 300 m,
    from t0 to t1 [s of simulation time] (the ends are given as aerodromes)."""
    from uam_planner.geo import enu_to_geodetic
    corners = [(x_m - 100, -100, 0.0), (x_m + 100, -100, 0.0), (x_m + 100, 100, 0.0), (x_m - 100, 100, 0.0)]
    lla = enu_to_geodetic(np.array(corners), net.origin_lat_lon_alt)
    h = float(net.origin_lat_lon_alt[2])
    return [{"volume": {"outline_polygon": {"vertices": [{"lat": float(a), "lng": float(b)} for a, b, _ in lla]},
                        "altitude_lower": {"value": h - 10.0, "reference": "W84", "units": "M"},
                        "altitude_upper": {"value": h + 300.0, "reference": "W84", "units": "M"}},
             "time_start": {"value": ctx.time(t0).value, "format": "RFC3339"},
             "time_end": {"value": ctx.time(t1).value, "format": "RFC3339"}}]


def upsert(ctx, net, request_id, t0, t1, origin="A", destination="B"):
    return {"request_id": request_id, "execution_style": "IfAllowed",
            "flight_plan": {"basic_information": {"usage_state": "Planned", "uas_state": "Nominal",
                                                  "area": area(ctx, net, t0, t1)},
                            "astm_f3548_21": {"priority": 0},
                            "additional_information": {"origin_id": origin, "destination_id": destination}}}


def call(executor, spin_until, fn, timeout_s=60.0):
    """``fn()`` (an HTTP call) in a thread while the graph spins; its result."""
    with concurrent.futures.ThreadPoolExecutor(1) as pool:
        fut = pool.submit(fn)
        assert spin_until(executor, fut.done, timeout_s=timeout_s), "no HTTP answer in time"
        return fut.result()


def test_flight_plans_go_to_the_planner_signed_and_forgeries_are_refused(ros_context, spin_until, tmp_path):
    from uam_bringup import qos
    from uam_contract import names as c
    from uam_msgs.msg import FlightPlan, FlightRequest
    from uam_msgs.srv import UpdateConstraint
    from uam_planner.authority import write_authority
    from uam_planner.f3548 import intent_id
    from uam_planner.planning import FlightRequest as LibRequest
    from uam_planner.signed_requests import FlightPlanSigner
    from uam_sim.f3548.auth import generate_dev_keys, mint_token
    from uam_sim.f3548.flight_planning import PREFIX, SCOPE_PLAN
    from uam_sim.f3548.uss_server import SCOPE_INTENTS
    from uam_sim.nodes.uss_node import UssNode

    listing, _caa = write_authority(tmp_path / "auth", "caa")
    _listing, uss_key = write_authority(tmp_path / "auth", "uss-peers", admin=False, add=True, operators=[OP])
    _other, rogue_key = write_authority(tmp_path / "rogue", "uss-peers", admin=False)   # same id, another key
    private, public = generate_dev_keys(tmp_path / "uss-auth")
    user = {"Authorization": f"Bearer {mint_token(private, 'localhost', [SCOPE_PLAN, SCOPE_INTENTS])}"}
    journal = tmp_path / "planner-journal.jsonl"
    # reservations: a plan whose area starts later is approved before it departs (so it can be
    # modified and cancelled); in real time, so the HTTP calls meet the run where they expect it
    executor, nodes, obs = build_graph(
        ros_context, rate=0.3, duration_s=900.0, backend="greedy",
        planner_extra={"authorities_file": str(listing), "journal": str(journal), "horizon_epochs": 4,
                       "commit_ahead": True, "intent_volume_piece_s": 5.0},   # F3548 mode, as run_fleet.sh
        simulator_extra={"mode": "realtime", "real_time_factor": 15.0})
    uss = UssNode(context=ros_context, parameter_overrides=params(
        port=0, network=TINY, auth_key=str(public), journal=str(journal), authority_key=str(uss_key)))
    rogue = rclpy.create_node("rogue_uss", context=ros_context)
    forged_requests = rogue.create_publisher(FlightRequest, c.TOPIC_REQUESTS, qos.QOS_REQUESTS)
    forged_calls = rogue.create_client(UpdateConstraint, c.SERVICE_USS_FLIGHT_PLAN)
    nodes["uss"], nodes["rogue"] = uss, rogue
    for n in (uss, rogue):
        executor.add_node(n)
    base = uss.server.url
    planner, sim = nodes["planner"], nodes["simulator"]
    assert planner.planner.config.intent_volumes.max_piece_s == 5.0   # the parameter reached the Planner
    ctx, net = uss.store.ctx, uss.network
    try:
        assert spin_until(executor, lambda: planner.epochs_planned >= 1 and uss.decider.ready(), timeout_s=60)
        t = sim.t_s
        r = call(executor, spin_until, lambda: requests.put(
            f"{base}{PREFIX}/flight_plans/{FID}", json=upsert(ctx, net, "r1", t + 150.0, t + 400.0),
            headers=user, timeout=60))
        assert r.status_code == 200, r.text
        got = r.json()
        assert (got["planning_result"], got["flight_plan_status"]) == ("Completed", "Planned"), got
        key = f"{OP}/{FID}"
        f1 = planner.planner.flight(key)
        assert f1 is not None and (f1.origin_id, f1.destination_id, f1.version) == ("A", "B", 1)
        oid = intent_id(OP, FID)
        doc = requests.get(f"{base}/uss/v1/operational_intents/{oid}", headers=user, timeout=10).json()
        ref1 = doc["operational_intent"]["reference"]

        # forged in the USS's name: on the topic, unsigned, and signed by another key
        forged_requests.publish(FlightRequest(operator_id=OP, request_id="forged-1", origin_id="A",
                                              destination_id="C", priority=0))
        lib = LibRequest("forged-2", "A", "C", sim.t_s, sim.t_s, sim.t_s + 300.0, operator_id=OP)
        unsigned = FlightPlanSigner("uss-peers", rogue_key.read_bytes(), 1).operation("plan", lib, version=1)
        unsigned.authorization = ""
        other_key = FlightPlanSigner("uss-peers", rogue_key.read_bytes(), 10**20).operation("plan", lib, version=1)
        answers = []
        for fields in (unsigned, other_key):
            fut = forged_calls.call_async(UpdateConstraint.Request(**vars(fields)))
            assert spin_until(executor, fut.done, timeout_s=20)
            answers.append(fut.result())
        assert [a.accepted for a in answers] == [False, False]
        assert answers[0].error.startswith("authorization: empty")
        assert answers[1].error.startswith("authorization: not signed by 'uss-peers'")
        assert planner.uss_requests_refused == 2
        assert spin_until(executor, lambda: any(p.request_id == "forged-1" for p in obs.plans), timeout_s=10)
        refusal = next(p for p in obs.plans if p.request_id == "forged-1")
        assert refusal.outcome == FlightPlan.OUTCOME_REJECTED and "operator_id: 'flight_planning'" in refusal.reason
        assert planner.planner.flight(f"{OP}/forged-1") is None and planner.planner.flight(f"{OP}/forged-2") is None

        # modified (another destination): a new version of the same intent
        t = sim.t_s
        r = call(executor, spin_until, lambda: requests.put(
            f"{base}{PREFIX}/flight_plans/{FID}", json=upsert(ctx, net, "r2", t + 100.0, t + 400.0, "A", "C"),
            headers=user, timeout=60))
        got = r.json()
        assert (got["planning_result"], got["flight_plan_status"]) == ("Completed", "Planned"), got
        f2 = planner.planner.flight(key)
        assert (f2.origin_id, f2.destination_id, f2.version) == ("A", "C", 2)
        doc = requests.get(f"{base}/uss/v1/operational_intents/{oid}", headers=user, timeout=10).json()
        ref2 = doc["operational_intent"]["reference"]
        assert ref2["id"] == ref1["id"] and ref2["version"] > ref1["version"] and ref2["ovn"] != ref1["ovn"]

        # deleted before it departs: the planner cancels it; its intent ends with the journal's record
        r = call(executor, spin_until, lambda: requests.delete(f"{base}{PREFIX}/flight_plans/{FID}", headers=user,
                                                               timeout=60))
        got = r.json()
        assert r.status_code == 200 and (got["planning_result"], got["flight_plan_status"]) == ("Completed", "Closed")
        assert planner.planner.flight(key) is None
        assert spin_until(executor, lambda: oid not in uss.store.intent_ids(), timeout_s=30)
        assert spin_until(executor, lambda: len([p for p in obs.plans if p.request_id == FID]) >= 3, timeout_s=10)
        versions = [(max(1, int(p.version)), p.update_kind) for p in obs.plans if p.operator_id == OP and
                    p.request_id == FID]
        assert versions == [(1, ""), (2, "modified"), (3, "cancelled")]
    finally:
        shutdown(executor, nodes)
        uss.close()


def test_without_its_authority_the_planner_refuses_a_uss_request(ros_context, spin_until, tmp_path):
    """A planner with no authorities file takes no USS request, naming why."""
    from uam_contract import names as c
    from uam_msgs.srv import UpdateConstraint
    from uam_planner.authority import write_authority
    from uam_planner.planning import FlightRequest as LibRequest
    from uam_planner.signed_requests import FlightPlanSigner

    from graph_harness import make_planner
    _listing, key = write_authority(tmp_path / "auth", "uss-peers", admin=False, operators=[OP])
    planner = make_planner(ros_context, use_solver_service=False)
    caller = rclpy.create_node("caller", context=ros_context)
    client = caller.create_client(UpdateConstraint, c.SERVICE_USS_FLIGHT_PLAN)
    from rclpy.executors import MultiThreadedExecutor
    executor = MultiThreadedExecutor(2, context=ros_context)
    nodes = {"planner": planner, "caller": caller}
    for n in nodes.values():
        executor.add_node(n)
    try:
        fields = FlightPlanSigner("uss-peers", key.read_bytes(), 1).operation(
            "plan", LibRequest("r", "A", "B", 0.0, 0.0, 60.0, operator_id=OP), version=1)
        assert spin_until(executor, client.service_is_ready, timeout_s=10)
        fut = client.call_async(UpdateConstraint.Request(**vars(fields)))
        assert spin_until(executor, fut.done, timeout_s=10)
        assert not fut.result().accepted and "no airspace authority is configured" in fut.result().error
        assert planner.uss_requests_refused == 1
    finally:
        shutdown(executor, nodes)
