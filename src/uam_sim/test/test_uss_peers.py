"""What peers send this USS (docs/f3548.md, "Peers"): a peer's operational intent posted to
``POST /uss/v1/operational_intents`` re-plans our flight live (through a real Planner), its
deletion withdraws it; bad notifications are refused with the standard's 400; reports are kept
and answered 201; the versioning interface reads our version; telemetry is refused with 412."""

from types import SimpleNamespace

import numpy as np
import pytest
import requests

from uam_planner.f3548 import IntentContext, VolumeSpec, as_json, operational_intent
from uam_planner.f3548_schema import errors
from uam_planner.network import network_from_enu
from uam_planner.planning import Flight, FlightRequest, Planner, PlanningConfig
from uam_planner.trajectory import Trajectory
from uam_sim.f3548.auth import generate_dev_keys, mint_token
from uam_sim.f3548.peers import PeerInbox
from uam_sim.f3548.uss_server import (SCOPE_CONFORMANCE, SCOPE_CONSTRAINTS, SCOPE_INTENTS, SCOPE_VERSIONS,
                                      IntentStore, UssServer)


def lanes():
    """P's lane Wp (-1000, 0) - mp (0, 0) - Ep (1000, 0); a vertiport C (0, 480) off it."""
    ids = ["Wp", "mp", "Ep", "C"]
    enu = [(-1000, 0, 0), (0, 0, 0), (1000, 0, 0), (0, 480, 0)]
    return network_from_enu("lanes", ids, enu, [True, False, True, True],
                            [("Wp", "mp"), ("mp", "Ep"), ("mp", "C")])


def best_of_each(weights, edges, groups):
    """One request: its best candidate (enough for these tests)."""
    return SimpleNamespace(selected=np.array([int(np.argmax(weights))]), backend="best")


@pytest.fixture(scope="module")
def dev_keys(tmp_path_factory):
    """The servers' development key pair, made once for the module (RSA 2048 takes a while)."""
    return generate_dev_keys(tmp_path_factory.mktemp("keys"))


@pytest.fixture
def live(dev_keys):
    """A planner flying P (Wp at 0 s, Ep at 200 s), and a server whose inbox hands peers'
    changes to it, announced at the planner's clock (80 s here)."""
    net = lanes()
    planner = Planner(net, PlanningConfig(k=2), "mwis", solve_mwis=best_of_each)
    assert planner.submit(FlightRequest("P", "Wp", "Ep", 0.0, 0.0, 20.0)) is None
    assert [f.request_id for f in planner.plan(0.0, 0).approved] == ["P"]
    refused, logged = [], []

    def to_planner(updates, kind, entity_id):
        for action, c in updates:
            reason = planner.update_constraint(action, c, 80.0)
            if reason is not None:
                refused.append(reason)

    spec = VolumeSpec.for_separation(100.0)
    inbox = PeerInbox(net, spec, IntentContext(net.origin_lat_lon_alt, spec).scenario_start_utc,
                      listener=to_planner, log=logged.append)
    private, public = dev_keys
    srv = UssServer(IntentStore(IntentContext(net.origin_lat_lon_alt, spec)), port=0, auth_key=str(public),
                    inbox=inbox).start()
    token = mint_token(private, "localhost", [SCOPE_INTENTS, SCOPE_CONSTRAINTS, SCOPE_VERSIONS,
                                              SCOPE_CONFORMANCE], sub="uss2")
    yield SimpleNamespace(net=net, planner=planner, srv=srv, inbox=inbox, refused=refused, logged=logged,
                          headers={"Authorization": f"Bearer {token}"})
    srv.stop()


def their_intent(net, version=1):
    """uss2's intent hovering over P's lane at x = 500 from 60 s to 1000 s (one volume)."""
    ctx = IntentContext(net.origin_lat_lon_alt, VolumeSpec(10.0, 5.0, 1000.0), manager="uss2")
    traj = Trajectory(np.array([60.0, 1000.0]), np.array([[500.0, -50.0, 0.0], [500.0, 50.0, 0.0]]))
    f = Flight("theirs", "X", "Y", ("X", "Y"), traj, 60.0, 1000.0, 0.0, 1.0, 0, "mwis", "greedy", 0,
               operator_id="uss2-op", version=version)
    return as_json(operational_intent(f, 0.0, ctx))


def test_a_peers_notification_re_plans_our_flight_live_and_its_deletion_withdraws_it(live):
    doc = their_intent(live.net)
    oid = doc["reference"]["id"]
    body = {"operational_intent_id": oid, "operational_intent": doc,
            "subscriptions": [{"subscription_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "notification_index": 3}]}
    r = requests.post(f"{live.srv.url}/uss/v1/operational_intents", json=body, headers=live.headers, timeout=10)
    assert r.status_code == 204, r.text
    assert live.refused == [] and live.inbox.entity_ids() == [f"operational_intent:{oid}"]
    assert "from uss2" in live.logged[-1] and "1 constraint updates" in live.logged[-1]
    # P would reach x = 500 at 150 s, inside their volume: re-planned at the next epoch
    res = live.planner.plan(90.0, 3)
    (u,) = res.plan_updates
    assert u.request_id == "P" and u.version == 2 and u.constraint_ids == (f"oi:{oid}:0",)
    # the same version again changes nothing; a deletion withdraws it
    requests.post(f"{live.srv.url}/uss/v1/operational_intents", json=body, headers=live.headers, timeout=10)
    assert "0 constraint updates" in live.logged[-1]
    gone = {"operational_intent_id": oid, "subscriptions": body["subscriptions"]}
    r = requests.post(f"{live.srv.url}/uss/v1/operational_intents", json=gone, headers=live.headers, timeout=10)
    assert r.status_code == 204 and live.inbox.entity_ids() == [] and "deleted" in live.logged[-1]
    assert live.refused == []


def test_bad_notifications_are_refused_with_an_error_response(live):
    url = f"{live.srv.url}/uss/v1/operational_intents"
    doc = their_intent(live.net)
    subs = [{"subscription_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "notification_index": 0}]
    for body, field in (([1, 2], "body"), ({"operational_intent": doc}, "body: not an F3548"),
                        ({"operational_intent_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "operational_intent": doc,
                          "subscriptions": subs}, "operational_intent.reference.id")):
        r = requests.post(url, json=body, headers=live.headers, timeout=10)
        assert r.status_code == 400 and r.json()["message"].startswith(field), r.text
        assert errors(r.json(), "ErrorResponse") == []
    r = requests.post(url, data=b"{", headers={**live.headers, "Content-Type": "application/json"}, timeout=10)
    assert r.status_code == 400 and r.json()["message"] == "body: not a JSON document"
    r = requests.post(url, json={}, timeout=10)  # no token
    assert r.status_code == 401
    assert live.inbox.entity_ids() == []


def test_a_peer_notifies_of_its_own_intents_only(live, dev_keys):
    """The caller is its token's subject: a notification naming another manager is refused, an
    entity held changes or goes only by its manager's notification, and with a list of peers
    the others are refused; each a 403 ErrorResponse naming the field, nothing applied."""
    url = f"{live.srv.url}/uss/v1/operational_intents"
    private, _public = dev_keys
    scopes = [SCOPE_INTENTS, SCOPE_CONSTRAINTS]
    other = {"Authorization": f"Bearer {mint_token(private, 'localhost', scopes, sub='uss3')}"}
    doc = their_intent(live.net)   # managed by uss2
    oid = doc["reference"]["id"]
    subs = [{"subscription_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "notification_index": 1}]
    body = {"operational_intent_id": oid, "operational_intent": doc, "subscriptions": subs}
    r = requests.post(url, json=body, headers=other, timeout=10)   # uss3 posting uss2's intent
    assert r.status_code == 403 and r.json()["message"].startswith("operational_intent.reference.manager")
    assert errors(r.json(), "ErrorResponse") == [] and live.inbox.entity_ids() == []
    assert requests.post(url, json=body, headers=live.headers, timeout=10).status_code == 204
    # uss3 may neither delete nor replace what uss2 manages
    for b in ({"operational_intent_id": oid, "subscriptions": subs},):
        r = requests.post(url, json=b, headers=other, timeout=10)
        assert r.status_code == 403 and r.json()["message"].startswith("operational_intent_id")
    assert live.inbox.entity_ids() == [f"operational_intent:{oid}"]
    # a list of peers: uss2 is not on it
    live.inbox.peers = frozenset({"uss3"})
    r = requests.post(url, json={"operational_intent_id": oid, "subscriptions": subs},
                      headers=live.headers, timeout=10)
    assert r.status_code == 403 and r.json()["message"].startswith("manager: 'uss2'")
    assert live.inbox.entity_ids() == [f"operational_intent:{oid}"] and live.refused == []


def test_reports_versions_and_telemetry(live):
    report = {"exchange": {"url": "https://uss2/uss/v1/operational_intents/x", "method": "GET",
                           "recorder_role": "Client", "request_time": {"value": "2025-01-06T00:00:00Z",
                                                                       "format": "RFC3339"},
                           "response_code": 500, "problem": "timeout"}}
    r = requests.post(f"{live.srv.url}/uss/v1/reports", json=report, headers=live.headers, timeout=10)
    assert r.status_code == 201 and r.json()["report_id"] and r.json()["exchange"]["problem"] == "timeout"
    assert len(live.inbox.reports) == 1 and "timeout" in live.logged[-1]
    r = requests.get(f"{live.srv.url}/versions/astm.f3548.v21", headers=live.headers, timeout=10)
    assert r.status_code == 200 and r.json()["system_identity"] == "astm.f3548.v21"
    assert r.json()["system_version"].startswith("uam_fleet-")
    assert requests.get(f"{live.srv.url}/versions/other", headers=live.headers, timeout=10).status_code == 404
    oid = live.srv.store.put_flight(_some_flight())
    r = requests.get(f"{live.srv.url}/uss/v1/operational_intents/{oid}/telemetry", headers=live.headers, timeout=10)
    assert r.status_code == 412 and errors(r.json(), "ErrorResponse") == []
    r = requests.get(f"{live.srv.url}/uss/v1/operational_intents/0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f/telemetry",
                     headers=live.headers, timeout=10)
    assert r.status_code == 404


def _some_flight():
    traj = Trajectory(np.array([30.0, 50.0]), np.array([[0.0, 0, 0], [200.0, 0, 0]]))
    return Flight("r1", "A", "B", ("A", "B"), traj, 30.0, 50.0, 200.0, 1.0, 0, "mwis", "greedy", 0,
                  operator_id="op")


def test_a_peers_intent_reaches_the_planner_as_a_signed_update_of_the_uss_authority(tmp_path):
    """In the node graph the planner takes a live constraint only signed by an airspace authority:
    the USS forwards peers' changes as its own (non-admin) authority, and the planner's rules
    (uam_planner.authority, live_constraints) take them as they would from the node."""
    from uam_planner.authority import Authorities, write_authority
    from uam_planner.live_constraints import parse_update
    from uam_sim.f3548.peers import PlannerForwarder, constraint_updates
    from uam_planner.f3548 import constraints_from_f3548

    net = lanes()
    planner = Planner(net, PlanningConfig(k=2), "mwis", solve_mwis=best_of_each)
    listing, key = write_authority(tmp_path / "auth", "uss-peers", admin=False)
    authorities = Authorities.load(listing)
    forward = PlannerForwarder("uss-peers", key.read_bytes(), seq0=1000)
    doc = their_intent(net)
    spec = VolumeSpec.for_separation(100.0)
    start = IntentContext(net.origin_lat_lon_alt, spec).scenario_start_utc
    added = constraints_from_f3548({"operational_intent": doc}, net, start, spec=spec)

    def take(req):   # what the planner node does with a request
        current = planner._projected_constraints()
        action, what = parse_update(req, current, net)
        author = authorities.verify(req, action)
        authorities.check_owner(author, current.get(req.constraint_id))
        if action != "withdraw":
            import dataclasses
            what = dataclasses.replace(what, author=author)
        return planner.update_constraint(action, what, 80.0)
    for req in forward.requests(constraint_updates({}, added)):
        assert take(req) is None
    held = planner._projected_constraints()
    assert [(c.constraint_id, c.author) for c in held.values()] == [(added[0].constraint_id, "uss-peers")]
    for req in forward.requests(constraint_updates({c.constraint_id: c for c in added}, [])):
        assert take(req) is None
    assert planner._projected_constraints() == {}
    # a replayed request of the forwarder is refused
    (req,) = forward.requests(constraint_updates({}, added))
    assert take(req) is None
    with pytest.raises(ValueError, match="a replayed update"):
        take(req)


def test_the_largest_notification_f3548_allows_fits_the_body_bound():
    """OiMaxVertices (10,000) in volumes and again in off-nominal volumes, as a peer (or this USS)
    may send them: under MAX_BODY_BYTES, which refuses only what no F3548 notification can be."""
    import json

    from uas_standards.astm.f3548.v21.constants import OiMaxVertices

    from uam_sim.f3548.uss_server import MAX_BODY_BYTES

    vertex = {"lat": 1.2345678901234567, "lng": 103.8765432109876543}
    volume = {"volume": {"outline_polygon": {"vertices": [vertex] * 4},
                         "altitude_lower": {"value": 45.01, "reference": "W84", "units": "M"},
                         "altitude_upper": {"value": 74.99, "reference": "W84", "units": "M"}},
              "time_start": {"value": "2025-01-06T00:00:30.000000Z", "format": "RFC3339"},
              "time_end": {"value": "2025-01-06T00:00:35.000000Z", "format": "RFC3339"}}
    n = OiMaxVertices // 4
    body = {"operational_intent_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f",
            "operational_intent": {"details": {"volumes": [volume] * n, "off_nominal_volumes": [volume] * n,
                                               "priority": 0}},
            "subscriptions": [{"subscription_id": "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "notification_index": 3}]}
    size = len(json.dumps(body).encode())
    assert 1 << 20 < size < MAX_BODY_BYTES, size
