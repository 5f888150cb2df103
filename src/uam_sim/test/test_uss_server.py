"""The F3548 USS-USS interface: a real Flask server on loopback answering with the standard's
documents and errors; a malformed id or a huge query is refused and the server keeps serving;
states and volumes follow the clock. The server runs as deployed, verifying access tokens
(tokens themselves: test_uss_auth.py; the worker pool: test_uss_pool.py)."""

import numpy as np
import pytest
import requests

from uam_planner.constraints import Constraint
from uam_planner.f3548 import IntentContext, VolumeSpec, constraint_entity_id, intent_id
from uam_planner.f3548_schema import errors
from uam_planner.planning import Flight
from uam_planner.trajectory import Trajectory
from uam_sim.f3548.auth import generate_dev_keys, mint_token
from uam_sim.f3548.uss_server import MAX_URL_CHARS, SCOPE_CONSTRAINTS, SCOPE_INTENTS, IntentStore, UssServer

ORIGIN = (1.29, 103.85, 0.0)


def flight(request_id, t0, version=1, priority=0, contingent=False):
    traj = Trajectory(np.array([t0, t0 + 20.0]), np.array([[0.0, 0, 120], [200.0, 0, 120]]))
    return Flight(request_id, "A", "B", ("A", "B"), traj, t0, t0 + 20.0, 200.0, 1.0, 0, "mwis",
                  "greedy", 0, operator_id="op", priority=priority, version=version,
                  contingent=contingent)


@pytest.fixture(scope="module")
def dev_keys(tmp_path_factory):
    """A development key pair (private.pem, public.pem) for the module's servers."""
    return generate_dev_keys(tmp_path_factory.mktemp("uss-keys"))


@pytest.fixture
def server(dev_keys):
    ctx = IntentContext(ORIGIN, VolumeSpec.for_separation(100.0))
    store = IntentStore(ctx)
    srv = UssServer(store, port=0, auth_key=str(dev_keys[1])).start()
    srv.token = mint_token(dev_keys[0], "localhost", [SCOPE_INTENTS, SCOPE_CONSTRAINTS])
    yield srv
    srv.stop()


def get(srv, path, **kw):
    """GET with the server's valid token (the requests of a peer USS)."""
    headers = {"Authorization": f"Bearer {srv.token}", **kw.pop("headers", {})}
    return requests.get(srv.url + path, headers=headers, timeout=10, **kw)


def test_details_unknown_ids_and_the_clock(server):
    store = server.store
    oid = store.put_flight(flight("r1", 30.0, priority=2))
    assert oid == intent_id("op", "r1")
    r = get(server, f"/uss/v1/operational_intents/{oid}")
    assert r.status_code == 200 and r.headers["Content-Type"] == "application/json"
    doc = r.json()
    assert errors(doc, "GetOperationalIntentDetailsResponse") == []
    ref, det = doc["operational_intent"]["reference"], doc["operational_intent"]["details"]
    assert (ref["id"], ref["state"], ref["version"], det["priority"]) == (oid, "Accepted", 1, 2)
    accepted = doc
    assert len(det["volumes"]) == 4 and det["off_nominal_volumes"] == []  # 20 s in 5 s pieces
    assert ref["time_start"]["value"] == "2025-01-06T00:00:30.000000Z"
    # unknown: the standard's 404 with an ErrorResponse
    unknown = "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f"
    r = get(server, f"/uss/v1/operational_intents/{unknown}")
    assert r.status_code == 404 and errors(r.json(), "ErrorResponse") == [] \
        and unknown in r.json()["message"]
    # the same version later: the same document (InterUSS: details never change without a
    # new version)
    store.set_time(29.0)
    assert get(server, f"/uss/v1/operational_intents/{oid}").json() == accepted
    # the clock: airborne at 42 s, Activated: a state change is a new version and OVN; every
    # volume is still served (details are pruned only by a new version), ended after 50 s
    store.set_time(42.0)
    doc = get(server, f"/uss/v1/operational_intents/{oid}").json()
    ref = doc["operational_intent"]["reference"]
    assert (ref["state"], ref["version"]) == ("Activated", 2) and ref["ovn"] != accepted["operational_intent"]["reference"]["ovn"]
    assert doc["operational_intent"]["details"] == accepted["operational_intent"]["details"]
    store.set_time(47.0)
    assert get(server, f"/uss/v1/operational_intents/{oid}").json() == doc
    # a new version replaces it, an older one does not
    store.put_flight(flight("r1", 60.0, version=3, contingent=True))
    store.put_flight(flight("r1", 90.0, version=2))
    doc = get(server, f"/uss/v1/operational_intents/{oid}").json()["operational_intent"]
    assert doc["reference"]["version"] == 7 and doc["reference"]["state"] == "Accepted"  # plan v3
    store.set_time(61.0)
    doc = get(server, f"/uss/v1/operational_intents/{oid}").json()["operational_intent"]
    assert doc["reference"]["state"] == "Contingent" and doc["details"]["volumes"] == [] \
        and len(doc["details"]["off_nominal_volumes"]) == 4
    assert errors({"operational_intent": doc}, "GetOperationalIntentDetailsResponse") == []
    store.set_time(81.0)
    assert get(server, f"/uss/v1/operational_intents/{oid}").status_code == 404  # ended
    # ended intents are dropped every 30 s of simulation time: at 81 s (81 s after the last
    # prune, at 0) r1, ended at 80 s, is gone; r2, ended at 100 s, goes at the first move 30 s
    # after the prune at 81 s
    assert get(server, "/uam_fleet/v1/operational_intents").json() == {"t_s": 81.0, "ids": []}
    assert not store.end("op", "r1")
    store.put_flight(flight("r3", 200.0))
    assert store.end("op", "r3") and get(server, "/uam_fleet/v1/operational_intents").json()["ids"] == []
    store.put_flight(flight("r2", 80.0))   # flies [80, 100] s
    store.set_time(105.0)                 # 24 s after the prune at 81 s: kept
    assert get(server, "/uam_fleet/v1/operational_intents").json()["ids"] == [intent_id("op", "r2")]
    store.set_time(111.0)                 # 30 s after it: r2 ended at 100 s, dropped
    assert get(server, "/uam_fleet/v1/operational_intents").json()["ids"] == []


def test_a_malformed_id_or_a_huge_query_is_refused_and_the_server_keeps_serving(server):
    oid = server.store.put_flight(flight("r1", 30.0))
    for bad in ("not-a-uuid", "0b6d5e4c-3a2b-5c1d-8e9f-0a1b2c3d4e5f",  # version 5, not 4
                "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f0", "a/b/c", "x" * 1500):
        r = get(server, f"/uss/v1/operational_intents/{bad}")
        assert r.status_code == 400, bad
        assert r.json()["message"].startswith("entityid: ") and len(r.json()["message"]) < 200
        assert errors(r.json(), "ErrorResponse") == []
    r = get(server, f"/uss/v1/operational_intents/{oid}", params={"q": "y" * 10000})
    assert r.status_code == 400
    assert r.json()["message"].startswith("request: the URL has ") and str(MAX_URL_CHARS) in r.json()["message"]
    from uam_sim.f3548.uss_server import MAX_BODY_BYTES
    r = get(server, f"/uss/v1/operational_intents/{oid}", data=b"z" * (MAX_BODY_BYTES + 1))
    assert r.status_code == 400 and f"body of {MAX_BODY_BYTES + 1} bytes" in r.json()["message"]
    r = requests.post(f"{server.url}/uss/v1/operational_intents/{oid}", timeout=10,
                      headers={"Authorization": f"Bearer {server.token}"})
    assert r.status_code == 405 and "message" in r.json()
    # still serving
    assert get(server, f"/uss/v1/operational_intents/{oid}").status_code == 200


def test_constraint_details(server):
    store = server.store
    store.set_constraints([
        Constraint("storm", 2, "storm", 100.0, 900.0, center_m=(0.0, 0.0), radius_m=300.0,
                   lower_m=0.0, upper_m=400.0),
        Constraint("closed", 0, "", 0.0, 10.0, vertiport_id="A")])  # no F3548 form: not served
    cid = constraint_entity_id("storm")
    r = get(server, f"/uss/v1/constraints/{cid}")
    assert r.status_code == 200 and errors(r.json(), "GetConstraintDetailsResponse") == []
    c = r.json()["constraint"]
    assert c["reference"]["version"] == 2 and c["details"]["volumes"][0]["volume"]["outline_circle"]["radius"] \
        == {"value": 300.0, "units": "M"}
    assert get(server, "/uam_fleet/v1/constraints").json()["ids"] == [cid]
    assert get(server, f"/uss/v1/constraints/{constraint_entity_id('closed')}").status_code == 404
    assert get(server, "/uss/v1/constraints/nope").status_code == 400
    # a version's document never changes: a constraint without an end, served, then the set
    # republished later with another constraint added: the same reference and details
    import math
    forever = Constraint("zone", 1, "", 0.0, math.inf, center_m=(500.0, 0.0), radius_m=100.0)
    store.set_constraints([forever])
    first = get(server, f"/uss/v1/constraints/{constraint_entity_id('zone')}").json()
    store.set_time(5000.0)
    store.set_constraints([forever, Constraint("other", 1, "", 0.0, 50.0, center_m=(0.0, 0.0), radius_m=10.0)])
    assert get(server, f"/uss/v1/constraints/{constraint_entity_id('zone')}").json() == first


def test_fetch_another_usss_intents_into_a_constraints_file(server, tmp_path):
    """Intents in over HTTP: fetched from a USS, they load as constraints the planner avoids."""
    from uam_planner.airspace_files import load_airspace as load_constraints
    from uam_planner.network import load_network
    from uam_sim.f3548.uss_server import main

    a = server.store.put_flight(flight("r1", 30.0))
    server.store.put_flight(flight("r2", 60.0))
    out = tmp_path / "theirs.json"
    assert main(["fetch", server.url, "--out", str(out)]) == 2  # no token: 401
    assert main(["fetch", server.url, "--out", str(out), "--token", server.token]) == 0
    cset = load_constraints(out, load_network("config/networks/tiny.yaml"))
    assert len(list(cset)) == 8  # 2 intents x 4 volumes, each a prism
    token_file = tmp_path / "token"
    token_file.write_text(server.token + "\n")
    assert main(["fetch", server.url, a, "--out", str(out), "--token", f"@{token_file}"]) == 0
    assert len(list(load_constraints(out, load_network("config/networks/tiny.yaml")))) == 4
    assert main(["fetch", server.url, "0b6d5e4c-3a2b-4c1d-8e9f-0a1b2c3d4e5f", "--out", str(out),
                 "--token", server.token]) == 2


def test_every_refusal_has_an_error_response_and_ids_are_case_insensitive(server):
    """A request line over 65,536 bytes (414) and a malformed one (400) are refused by the HTTP
    layer, with an F3548 ErrorResponse like every other refusal; an upper-case id is the same
    id (RFC 4122); the server's URL is the address it is bound to."""
    import socket

    oid = server.store.put_flight(flight("r1", 30.0))
    r = get(server, f"/uss/v1/operational_intents/{oid.upper()}")
    assert r.status_code == 200 and r.json()["operational_intent"]["reference"]["id"] == oid
    r = get(server, "/uss/v1/operational_intents/" + "x" * 70000)
    assert r.status_code == 414 and r.headers["Content-Type"] == "application/json"
    assert errors(r.json(), "ErrorResponse") == [] and "HTTP 414" in r.json()["message"]
    with socket.create_connection(("127.0.0.1", server.port), timeout=10) as s:
        s.sendall(b'GET /a" b\\ HTTP/1.1\r\n\r\n')  # bad syntax, with a quote and a backslash
        answer = b""
        while chunk := s.recv(65536):  # until the server closes
            answer += chunk
    head, body = answer.decode().split("\r\n\r\n", 1)
    assert head.startswith("HTTP/1.1 400") and "application/json" in head
    import json
    assert "HTTP 400" in json.loads(body)["message"]
    assert server.url == f"http://127.0.0.1:{server.port}"
    assert get(server, f"/uss/v1/operational_intents/{oid}").status_code == 200


def test_the_base_url_is_the_address_the_server_has():
    import socket

    from uam_sim.f3548.uss_server import base_url
    assert base_url("127.0.0.1", 8090) == "http://127.0.0.1:8090"
    assert base_url("uss1.example.com", 443) == "http://uss1.example.com:443"
    assert base_url("::1", 8090) == "http://[::1]:8090"
    assert base_url("0.0.0.0", 8090) == f"http://{socket.getfqdn()}:8090"
