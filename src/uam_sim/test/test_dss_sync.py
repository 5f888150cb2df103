"""DSS reference management (uam_sim.f3548.dss_sync) against the stand-in DSS, in process (WSGI
apps, no sockets): a served intent's reference created with the key of the references it meets,
a 409 answered by a retry with the missing OVNs (a peer's read from its details endpoint), a new
version and a state change put at the current OVN with the DSS's reference then served, the
reference deleted when the intent ends; a second USS server subscribed to the area receives the
notifications; a DSS that does not answer is counted, the intent stays served and the put is
retried once the DSS is back."""

import json
import uuid
from types import SimpleNamespace
from urllib.parse import urlsplit

import numpy as np
import pytest
import requests

from uam_planner.f3548 import IntentContext, VolumeSpec, intent_id, ovn
from uam_planner.f3548_schema import errors
from uam_planner.network import network_from_enu
from uam_planner.planning import Flight
from uam_planner.trajectory import Trajectory
from uam_sim.f3548.auth import TokenVerifier, generate_dev_keys
from uam_sim.f3548.dss import DevTokens, DssClient, token_source
from uam_sim.f3548.dss_standin import create_app as standin_app
from uam_sim.f3548.dss_sync import DssSync, bounding_volume, extents_of
from uam_sim.f3548.peers import PeerInbox
from uam_sim.f3548.uss_server import IntentStore, create_app as uss_app

DSS = "http://dss.test"
USS1, USS2 = "http://uss1.test", "http://uss2.test"


def lanes():
    ids = ["W", "m", "E"]
    return network_from_enu("lanes", ids, [(-1000, 0, 0), (0, 0, 0), (1000, 0, 0)], [True, False, True],
                            [("W", "m"), ("m", "E")])


NET = lanes()
SPEC = VolumeSpec.for_separation(100.0)


class Router:
    """A requests-like session that hands each request to the WSGI app of its URL's host (no
    socket); a host with no app is down (ConnectionError, as requests raises it)."""

    def __init__(self, apps: dict):
        self.apps = {urlsplit(u).netloc: app.test_client() for u, app in apps.items()}
        self.calls: list = []

    def request(self, method, url, json=None, headers=None, timeout=None):
        parts = urlsplit(url)
        self.calls.append((method, url))
        client = self.apps.get(parts.netloc)
        if client is None:
            raise requests.ConnectionError(f"{parts.netloc}: connection refused")
        path = parts.path + (f"?{parts.query}" if parts.query else "")
        r = client.open(path, method=method, json=json, headers=headers or {})
        body = r.get_data()
        return SimpleNamespace(status_code=r.status_code, content=body, text=body.decode(),
                               json=lambda: __import__("json").loads(body))


def flight(request_id, t0, x0=-500.0, x1=500.0, version=1, operator="op"):
    """A flight along the lane from x0 to x1 at 120 m, 100 s from t0."""
    traj = Trajectory(np.array([t0, t0 + 100.0]), np.array([[x0, 0.0, 120.0], [x1, 0.0, 120.0]]))
    return Flight(request_id, "W", "E", ("W", "E"), traj, t0, t0 + 100.0, abs(x1 - x0), 1.0, 0, "mwis",
                  "greedy", 0, operator_id=operator, version=version)


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    return generate_dev_keys(tmp_path_factory.mktemp("dss-sync-keys"))


@pytest.fixture
def world(keys):
    """The stand-in DSS, uss1 (our store, synced) and uss2 (a USS server with a peer inbox, and
    its own store and sync), all behind one Router."""
    private, public = keys
    dss_app = standin_app(TokenVerifier.from_file(public, ("dss.test",)))
    inbox_log, peer_changes = [], []
    inbox = PeerInbox(NET, SPEC, IntentContext(NET.origin_lat_lon_alt, SPEC).scenario_start_utc,
                      listener=lambda updates, kind, eid: peer_changes.append((kind, eid, updates)),
                      log=inbox_log.append)
    stores = {u: IntentStore(IntentContext(NET.origin_lat_lon_alt, SPEC, uss_base_url=u)) for u in (USS1, USS2)}
    uss2 = uss_app(stores[USS2], "verify", TokenVerifier.from_file(public, ("uss2.test",)), inbox=inbox)
    uss1 = uss_app(stores[USS1], "verify", TokenVerifier.from_file(public, ("uss1.test",)))
    router = Router({DSS: dss_app, USS2: uss2, USS1: uss1})
    syncs, logs = {}, {USS1: [], USS2: []}
    for u, sub in ((USS1, "uss1"), (USS2, "uss2")):
        client = DssClient(DSS, DevTokens(private, sub=sub), session=router)
        syncs[u] = DssSync(stores[u], client, session=router, log=logs[u].append, group=4)
    return SimpleNamespace(dss=dss_app.dss, router=router, stores=stores, syncs=syncs, logs=logs,
                           inbox=inbox, inbox_log=inbox_log, peer_changes=peer_changes, private=private)


def served(store, oid):
    text = store.details(oid)
    return None if text is None else json.loads(text)["operational_intent"]


def test_extents_hold_every_volume():
    store = IntentStore(IntentContext(NET.origin_lat_lon_alt, SPEC))
    store.put_flight(flight("r", 0.0))
    view = store.views()[0]
    vols = [json.loads(v) for v in view.volumes_json]
    ext = extents_of(view.volumes_json, group=4)
    assert len(ext) == -(-len(vols) // 4)
    assert ext[0]["time_start"] == vols[0]["time_start"] and ext[-1]["time_end"] == vols[-1]["time_end"]
    from shapely.geometry import Polygon
    for k, v in enumerate(vols):
        e = ext[k // 4]
        outline = Polygon([(p["lng"], p["lat"]) for p in v["volume"]["outline_polygon"]["vertices"]])
        hull = Polygon([(p["lng"], p["lat"]) for p in e["volume"]["outline_polygon"]["vertices"]])
        assert hull.buffer(1e-12).contains(outline)
        assert e["volume"]["altitude_lower"]["value"] <= v["volume"]["altitude_lower"]["value"]
    assert len(extents_of(view.volumes_json, group=1, max_extents=3)) == 3   # long flights: larger groups
    with pytest.raises(ValueError, match=r"volumes\[0\]\.volume\.altitude_lower: None"):
        bounding_volume([{"volume": {"outline_polygon": vols[0]["volume"]["outline_polygon"]}}])
    with pytest.raises(ValueError, match="group: 0"):
        extents_of(view.volumes_json, group=0)


def test_create_with_the_key_then_update_and_the_dss_reference_is_served(world):
    s1, st1 = world.syncs[USS1], world.stores[USS1]
    # uss2's intent over the same lane at the same time, already in the DSS
    world.stores[USS2].put_flight(flight("theirs", 20.0, operator="op2"))
    world.syncs[USS2].sync_once()
    theirs = intent_id("op2", "theirs")
    assert world.syncs[USS2].stats["created"] == 1
    oid = st1.put_flight(flight("r1", 10.0))
    s1.sync_once()
    assert s1.stats["created"] == 1 and s1.stats["key_retries"] == 0   # queried first: the key was whole
    ref = world.dss.intents[oid].doc
    assert (ref["manager"], ref["state"], ref["version"], ref["uss_base_url"]) == ("uss1", "Accepted", 1, USS1)
    # uss2's OVN (hidden by the DSS) was read from uss2's details endpoint
    assert ("GET", f"{USS2}/uss/v1/operational_intents/{theirs}") in world.router.calls
    doc = served(st1, oid)
    assert doc["reference"] == ref and errors({"operational_intent": doc}, "GetOperationalIntentDetailsResponse") == []
    assert doc["reference"]["ovn"] != ovn(oid, 1)     # the DSS's OVN, not the local one
    # the same version: nothing put again
    s1.sync_once()
    assert s1.stats["updated"] == 0 and world.dss.intents[oid].doc["ovn"] == ref["ovn"]
    # a new plan version: an update at the current OVN, on the same subscription
    st1.put_flight(flight("r1", 10.0, x0=-400.0, version=2))
    s1.sync_once()
    new = world.dss.intents[oid].doc
    assert s1.stats["updated"] == 1 and new["version"] == 2 and new["ovn"] != ref["ovn"]
    assert new["subscription_id"] == ref["subscription_id"]
    assert served(st1, oid)["reference"] == new
    # airborne: Activated is a new version, put too
    st1.set_time(11.0)
    s1.sync_once()
    act = world.dss.intents[oid].doc
    assert (act["state"], act["version"], s1.stats["updated"]) == ("Activated", 3, 2)
    assert served(st1, oid)["reference"] == act and s1.held(oid)[1] == act["ovn"]


def test_a_409_is_answered_by_a_retry_with_the_missing_ovns(world, monkeypatch):
    s1, st1 = world.syncs[USS1], world.stores[USS1]
    world.stores[USS2].put_flight(flight("theirs", 20.0, operator="op2"))
    world.syncs[USS2].sync_once()
    # a DSS whose query misses uss2's reference (e.g. a query made before it was created): the
    # put is refused with 409 naming it, and made once more with its OVN
    monkeypatch.setattr(s1.client, "query_operational_intent_references", lambda area: [])
    oid = st1.put_flight(flight("r1", 10.0))
    s1.sync_once()
    assert (s1.stats["key_retries"], s1.stats["created"], s1.stats["conflicts"]) == (1, 1, 0)
    assert oid in world.dss.intents
    assert any("the key lacked 1 reference(s)" in line for line in world.logs[USS1])
    # uss2 down: its OVN cannot be read, the retry is refused too: a conflict, counted; the intent
    # stays served with its local reference, and the put is retried once uss2 answers again
    st1.put_flight(flight("r2", 20.0))
    r2 = intent_id("op", "r2")
    apps = world.router.apps
    uss2 = apps.pop("uss2.test")
    s1.sync_once()
    assert (s1.stats["conflicts"], s1.stats["peer_ovn_failures"]) == (1, 1) and r2 not in world.dss.intents
    assert served(st1, r2)["reference"]["ovn"] == ovn(r2, 1)
    apps["uss2.test"] = uss2
    s1.sync_once(retry=False)
    assert r2 not in world.dss.intents          # a failed version waits for a retry pass
    s1.sync_once()
    assert r2 in world.dss.intents and served(st1, r2)["reference"] == world.dss.intents[r2].doc


def test_subscribers_are_notified_and_the_reference_deleted_when_the_intent_ends(world):
    s1, st1 = world.syncs[USS1], world.stores[USS1]
    # uss2's intent: its implicit subscription covers the lane, so uss2 is named to uss1
    world.stores[USS2].put_flight(flight("theirs", 20.0, operator="op2"))
    world.syncs[USS2].sync_once()
    oid = st1.put_flight(flight("r1", 10.0))
    s1.sync_once()
    assert s1.stats["notified"] == 1 and s1.stats["notify_failures"] == 0
    posts = [u for m, u in world.router.calls if m == "POST" and "/uss/" in u]
    assert posts == [f"{USS2}/uss/v1/operational_intents"]   # uss2 only: never this USS itself
    # uss2's inbox took it: uss1's intent at the DSS's version, with uss1 as its manager
    assert world.inbox.entity_ids() == [f"operational_intent:{oid}"]
    assert world.peer_changes[-1][:2] == ("operational_intent", oid) and world.peer_changes[-1][2][0][0] == "add"
    assert "version 1 of uss1" in world.inbox_log[-1]
    # the flight is cancelled: the reference deleted, uss2 told (a notification without the intent)
    st1.end("op", "r1")
    s1.sync_once()
    assert s1.stats["deleted"] == 1 and oid not in world.dss.intents and s1.held(oid) is None
    assert world.inbox.entity_ids() == [] and world.peer_changes[-1][2][0][0] == "withdraw"
    assert s1.stats["notified"] == 2
    # an intent that ends by the clock (arrival passed) goes too
    st1.put_flight(flight("r3", 10.0))
    s1.sync_once()
    st1.set_time(111.0)
    s1.sync_once()
    assert intent_id("op", "r3") not in world.dss.intents and s1.stats["deleted"] == 2
    # a subscriber that does not answer (uss3: a subscription over the lane, no server): counted,
    # the reference made all the same
    r4 = st1.put_flight(flight("r4", 105.0))
    area = bounding_volume(extents_of(next(v for v in st1.views() if v.entity_id == r4).volumes_json))
    uss3 = DssClient(DSS, DevTokens(world.private, sub="uss3"), session=world.router)
    uss3.put_subscription(str(uuid.uuid4()), area, "http://uss3.test")
    s1.sync_once()
    assert s1.stats["notify_failures"] == 1 and r4 in world.dss.intents
    assert any("subscriber http://uss3.test not notified" in line for line in world.logs[USS1])


def test_a_dss_that_does_not_answer_is_counted_and_the_intent_stays_served(world):
    s1, st1 = world.syncs[USS1], world.stores[USS1]
    dss = world.router.apps.pop("dss.test")
    oid = st1.put_flight(flight("r1", 10.0))
    s1.sync_once()
    assert s1.stats["failures"] == 1 and s1.held(oid) is None
    doc = served(st1, oid)
    assert doc is not None and doc["reference"]["ovn"] == ovn(oid, 1)   # served as without a DSS
    assert any("served with its local reference" in line for line in world.logs[USS1])
    world.router.apps["dss.test"] = dss
    s1.sync_once()
    assert s1.stats["created"] == 1 and served(st1, oid)["reference"] == world.dss.intents[oid].doc
    # a delete the DSS does not answer: kept and retried
    world.router.apps.pop("dss.test")
    st1.end("op", "r1")
    s1.sync_once()
    assert s1.stats["failures"] == 2 and oid in world.dss.intents
    world.router.apps["dss.test"] = dss
    s1.sync_once()
    assert oid not in world.dss.intents and s1.stats["deleted"] == 1


def test_a_reference_left_by_an_earlier_run_is_taken_over(world):
    """Intent ids are the same every run: a restarted USS finds its own reference in the DSS."""
    st1 = world.stores[USS1]
    oid = st1.put_flight(flight("r1", 10.0))
    world.syncs[USS1].sync_once()
    old = world.dss.intents[oid].doc
    again = DssSync(st1, world.syncs[USS1].client, session=world.router)   # a new process: knows nothing
    st1.put_flight(flight("r1", 10.0, version=2))
    again.sync_once()
    assert again.stats["updated"] == 1 and again.stats["failures"] == 0
    assert world.dss.intents[oid].doc["version"] == old["version"] + 1


def test_the_worker_thread_syncs_at_each_change(world):
    s1, st1 = world.syncs[USS1], world.stores[USS1]
    s1.start(retry_s=0.05)
    try:
        oid = st1.put_flight(flight("r1", 10.0))
        assert s1.wait_settled(oid, 1, 5.0) == "synced"
        st1.end("op", "r1")
        assert s1.wait_settled(oid, None, 5.0) == "deleted"
    finally:
        s1.stop()
    assert st1.on_change is None


def test_token_sources_are_checked(keys, tmp_path):
    private, public = keys
    with pytest.raises(ValueError, match="dss_token_file, dss_dev_key, dss_auth_url: 0 given"):
        token_source()
    with pytest.raises(ValueError, match="2 given"):
        token_source(token_file=str(private), dev_key=str(private))
    with pytest.raises(ValueError, match=f"dss_token_file: '{tmp_path}/none' is not a readable file"):
        token_source(token_file=str(tmp_path / "none"))
    with pytest.raises(ValueError, match="is a public key"):
        token_source(dev_key=str(public))
    (tmp_path / "token").write_text("abc.def.ghi\n")
    assert token_source(token_file=str(tmp_path / "token")).token("dss", ["s"]) == "abc.def.ghi"
    with pytest.raises(ValueError, match="token_endpoint: 'localhost:8085'"):
        token_source(auth_url="localhost:8085")


def test_tokens_from_an_auth_server_endpoint(keys):
    """AuthServerTokens asks as InterUSS's dummy OAuth server is asked, and reuses a token until
    a minute before its exp."""
    from flask import Flask, request

    from uam_sim.f3548.auth import mint_token
    private, _ = keys
    app, asked = Flask("oauth"), []

    @app.get("/token")
    def token():
        asked.append(dict(request.args))
        return {"access_token": mint_token(private, request.args["intended_audience"],
                                           request.args["scope"].split(), sub=request.args["sub"])}
    from uam_sim.f3548.dss import AuthServerTokens
    src = AuthServerTokens("http://oauth.test/token", sub="uss1", session=Router({"http://oauth.test": app}))
    t1 = src.token("dss.test", ["utm.strategic_coordination"])
    assert src.token("dss.test", ["utm.strategic_coordination"]) == t1 and len(asked) == 1
    assert asked[0] == {"grant_type": "client_credentials", "scope": "utm.strategic_coordination",
                        "intended_audience": "dss.test", "issuer": "dummy", "sub": "uss1"}
    src.token("uss2.test", ["utm.strategic_coordination"])
    assert len(asked) == 2
