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
