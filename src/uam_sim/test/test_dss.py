"""The DSS client (uam_sim.f3548.dss) against the stand-in DSS (uam_sim.f3548.dss_standin) over
HTTP: references created, updated with the right and a wrong OVN, keyed against intersecting
references, queried by area and time, deleted; subscriptions created, updated and deleted; the
stand-in's own checks (bad bodies 400 naming the field, tokens, its answers validated)."""

import math
import threading
import uuid

import pytest
from werkzeug.serving import make_server

from uam_sim.f3548.auth import TokenVerifier, generate_dev_keys
from uam_sim.f3548.dss import DssClient, DssError, DevTokens, StaticToken
from uam_sim.f3548.dss_standin import create_app

LAT0, LNG0 = 1.30, 103.80
URL = "http://127.0.0.1:1"  # the stand-in in process: only the path is used


def at(minutes: float) -> str:
    """T0 + ``minutes`` as RFC 3339."""
    from datetime import datetime, timedelta, timezone
    t = datetime(2025, 1, 6, tzinfo=timezone.utc) + timedelta(minutes=minutes)
    return t.strftime("%Y-%m-%dT%H:%M:%S.%fZ")


def box(x0_m, x1_m, y0_m=-50.0, y1_m=50.0, z0_m=30.0, z1_m=60.0, t0_min=0.0, t1_min=10.0) -> dict:
    """A Volume4D (JSON): east [x0, x1] m, north [y0, y1] m of (LAT0, LNG0), heights [z0, z1] m
    W84, minutes [t0, t1] after T0 (None: no time)."""
    dlat, dlng = 1 / 111_320.0, 1 / (111_320.0 * math.cos(math.radians(LAT0)))
    corners = [(x0_m, y0_m), (x1_m, y0_m), (x1_m, y1_m), (x0_m, y1_m)]
    v = {"volume": {"outline_polygon": {"vertices": [{"lat": LAT0 + y * dlat, "lng": LNG0 + x * dlng}
                                                     for x, y in corners]},
                    "altitude_lower": {"value": z0_m, "reference": "W84", "units": "M"},
                    "altitude_upper": {"value": z1_m, "reference": "W84", "units": "M"}}}
    if t0_min is not None:
        v["time_start"] = {"value": at(t0_min), "format": "RFC3339"}
        v["time_end"] = {"value": at(t1_min), "format": "RFC3339"}
    return v


class WsgiSession:
    """A requests-like session that calls a WSGI app in this process (no socket): the fast tests'
    transport. ``test_over_a_socket`` uses requests itself."""

    def __init__(self, app):
        self._client = app.test_client()

    def request(self, method, url, json=None, headers=None, timeout=None):
        from types import SimpleNamespace
        from urllib.parse import urlsplit

        r = self._client.open(urlsplit(url).path, method=method, json=json, headers=headers or {})
        body = r.get_data()
        return SimpleNamespace(status_code=r.status_code, content=body, text=body.decode(),
                               json=lambda: __import__("json").loads(body))


@pytest.fixture(scope="module")
def standin(tmp_path_factory):
    """The stand-in DSS app, and the private key its tokens are signed with."""
    private, public = generate_dev_keys(tmp_path_factory.mktemp("dss-keys"))
    app = create_app(TokenVerifier.from_file(public, ("127.0.0.1",)))
    # one call first: the imports and schema compilation of a first request (~0.3 s) belong to
    # the fixture, not to the first test
    DssClient(URL, DevTokens(private), session=WsgiSession(app)).query_operational_intent_references(box(0, 1))
    return app, private


def clients(app, private, session_for=WsgiSession, url=URL):
    return (DssClient(url, DevTokens(private, sub="uss1"), session=session_for(app)),
            DssClient(url, DevTokens(private, sub="uss2"), session=session_for(app)))


@pytest.fixture
def dss(standin):
    """Two USSs' clients of a stand-in emptied for the test."""
    app, private = standin
    state = app.dss
    state.intents.clear(), state.constraints.clear(), state.subscriptions.clear()
    return (*clients(app, private), state)


def new_id() -> str:
    return str(uuid.uuid4())


def create(client, extents, key=(), state="Accepted", url="http://uss1.example.com"):
    eid = new_id()
    return eid, client.put_operational_intent_reference(eid, extents, state, url, key=key)


def test_create_then_update_with_the_current_ovn_and_not_with_an_old_one(dss):
    uss1, _, _ = dss
    eid, made = create(uss1, [box(0, 100)])
    ref = made.operational_intent_reference
    assert (ref.id, ref.version, ref.manager, ref.state) == (eid, 1, "uss1", "Accepted")
    assert 16 <= len(ref.ovn) <= 128
    assert ref.time_start.value.startswith("2025-01-06T00:00:00") and ref.time_end.value.startswith("2025-01-06T00:10")
    changed = uss1.put_operational_intent_reference(eid, [box(0, 200)], "Activated", "http://uss1.example.com",
                                                    ovn=ref.ovn, subscription_id=ref.subscription_id)
    ref2 = changed.operational_intent_reference
    assert (ref2.version, ref2.state) == (2, "Activated") and ref2.ovn != ref.ovn
    # the old OVN no longer changes it; nor does a create of the same id
    with pytest.raises(DssError) as bad:
        uss1.put_operational_intent_reference(eid, [box(0, 300)], "Activated", "http://uss1.example.com", ovn=ref.ovn)
    assert bad.value.status == 409 and f"ovn: '{ref.ovn}'" in bad.value.message
    with pytest.raises(DssError) as again:
        uss1.put_operational_intent_reference(eid, [box(0, 300)], "Accepted", "http://uss1.example.com")
    assert again.value.status == 409 and eid in again.value.message
    assert uss1.get_operational_intent_reference(eid).version == 2


def test_a_reference_needs_the_key_of_every_intersecting_one(dss):
    uss1, uss2, _ = dss
    theirs, made = create(uss2, [box(0, 100)], url="http://uss2.example.com")
    their_ovn = made.operational_intent_reference.ovn
    # same place and time, no key: 409 naming the missing reference, parsed as AirspaceConflictResponse
    with pytest.raises(DssError) as conflict:
        create(uss1, [box(50, 150)])
    assert conflict.value.status == 409
    assert [r.id for r in conflict.value.conflict.missing_operational_intents] == [theirs]
    assert "ovn" not in conflict.value.conflict.missing_operational_intents[0]  # only its manager sees it
    # with the key: created; apart in time, height or area: no key needed
    create(uss1, [box(50, 150)], key=[their_ovn])
    create(uss1, [box(50, 150, t0_min=11, t1_min=20)])
    create(uss1, [box(50, 150, z0_m=61, z1_m=90)])
    create(uss1, [box(200, 300)])
    # a Nonconforming or Contingent intent is not keyed (its USS cannot deconflict it)
    create(uss1, [box(50, 150)], state="Nonconforming")


def test_query_by_area_and_time(dss):
    uss1, uss2, _ = dss
    a, _ = create(uss1, [box(0, 100, t0_min=0, t1_min=10)])
    b, _ = create(uss1, [box(500, 600, t0_min=0, t1_min=10)])
    c, _ = create(uss2, [box(0, 100, t0_min=20, t1_min=30)], url="http://uss2.example.com")
    ids = lambda refs: sorted(r.id for r in refs)  # noqa: E731
    assert ids(uss1.query_operational_intent_references(box(-50, 50, t0_min=5, t1_min=6))) == [a]
    assert ids(uss1.query_operational_intent_references(box(-50, 50, t0_min=None))) == sorted([a, c])
    assert ids(uss1.query_operational_intent_references(box(-1000, 1000, t0_min=0, t1_min=40))) == sorted([a, b, c])
    assert uss1.query_operational_intent_references(box(2000, 2100)) == []
    found = {r.id: r for r in uss1.query_operational_intent_references(box(-50, 50, t0_min=None))}
    assert found[a].ovn and "ovn" not in found[c]   # uss1 sees its own OVN, not uss2's


def test_delete_with_the_current_ovn_only(dss):
    uss1, uss2, state = dss
    eid, made = create(uss1, [box(0, 100)])
    ovn = made.operational_intent_reference.ovn
    with pytest.raises(DssError) as wrong:
        uss1.delete_operational_intent_reference(eid, "0" * 32)
    assert wrong.value.status == 409
    with pytest.raises(DssError) as other:
        uss2.delete_operational_intent_reference(eid, ovn)
    assert other.value.status == 403 and "managed by 'uss1'" in other.value.message
    gone = uss1.delete_operational_intent_reference(eid, ovn)
    assert gone.operational_intent_reference.id == eid
    assert uss1.query_operational_intent_references(box(0, 100)) == [] and not state.subscriptions
    with pytest.raises(DssError) as twice:
        uss1.delete_operational_intent_reference(eid, ovn)
    assert twice.value.status == 404


def test_subscriptions_created_notified_updated_and_deleted(dss):
    uss1, uss2, state = dss
    sid = new_id()
    made = uss2.put_subscription(sid, box(-500, 500, t0_min=0, t1_min=60), "http://uss2.example.com")
    sub = made.subscription
    assert (sub.id, sub.notification_index, sub.notify_for_operational_intents) == (sid, 0, True)
    # a reference in its area: uss2 is among the subscribers to notify, its index advanced
    _, change = create(uss1, [box(0, 100)])
    notified = {s.uss_base_url: [x.subscription_id for x in s.subscriptions] for s in change.subscribers}
    assert sid in notified["http://uss2.example.com"]
    assert state.subscriptions[sid].doc["notification_index"] == 1
    # a reference elsewhere: not notified
    _, far = create(uss1, [box(5000, 5100)])
    assert all(sid not in [x.subscription_id for x in s.subscriptions] for s in far.subscribers)
    # updated at its version only, then deleted at its new version only
    with pytest.raises(DssError) as stale:
        uss2.put_subscription(sid, box(-50, 50), "http://uss2.example.com", version="nope")
    assert stale.value.status == 409
    updated = uss2.put_subscription(sid, box(-50, 50), "http://uss2.example.com", version=sub.version).subscription
    assert updated.version != sub.version
    with pytest.raises(DssError) as old:
        uss2.delete_subscription(sid, sub.version)
    assert old.value.status == 409
    assert uss2.delete_subscription(sid, updated.version).id == sid
    assert sid not in state.subscriptions


def test_a_reference_on_an_explicit_subscription(dss):
    uss1, _, state = dss
    sid = new_id()
    uss1.put_subscription(sid, box(-500, 500, t0_min=0, t1_min=60), "http://uss1.example.com")
    eid = new_id()
    ref = uss1.put_operational_intent_reference(eid, [box(0, 100)], "Accepted", "http://uss1.example.com",
                                                subscription_id=sid).operational_intent_reference
    assert ref.subscription_id == sid and len(state.subscriptions) == 1
    with pytest.raises(DssError) as unknown:
        uss1.put_operational_intent_reference(new_id(), [box(300, 400)], "Accepted", "http://uss1.example.com",
                                              subscription_id=new_id())
    assert unknown.value.status == 400 and "subscription_id" in unknown.value.message


def test_constraint_references_are_queried_and_keyed(dss):
    uss1, uss2, _ = dss
    cid = new_id()
    made = uss2.put_constraint_reference(cid, [box(0, 100)], "http://uss2.example.com")
    assert made.constraint_reference.version == 1
    assert [c.id for c in uss1.query_constraint_references(box(50, 60))] == [cid]
    assert uss1.query_constraint_references(box(1000, 1100)) == []
    with pytest.raises(DssError) as conflict:
        create(uss1, [box(50, 150)])
    assert [c.id for c in conflict.value.conflict.missing_constraints] == [cid]
    create(uss1, [box(50, 150)], key=[made.constraint_reference.ovn])


BAD = [
    (lambda b: b.pop("extents"), "extents"),
    (lambda b: b.update(extents=[]), "extents: empty"),
    (lambda b: b["extents"][0].pop("time_end"), "extents[0].time_end: missing"),
    (lambda b: b["extents"][0]["volume"]["altitude_lower"].update(reference="SFC"),
     "extents[0].volume.altitude_lower.reference: 'SFC'"),
    (lambda b: b["extents"][0]["volume"]["altitude_upper"].update(value=10.0),
     "extents[0].volume: altitude_upper 10.0 is below altitude_lower 30.0"),
    (lambda b: b["extents"][0]["volume"]["outline_polygon"]["vertices"].__delitem__(slice(2, None)),
     "extents[0].volume.outline_polygon.vertices: 2 vertices, fewer than 3"),
    (lambda b: b.update(state="Flying"), "Flying"),
    (lambda b: b.update(requested_ovn_suffix="x"), "requested_ovn_suffix: 'x'"),
]


def test_bad_requests_are_400_naming_the_field(dss, standin):
    app, private = standin
    token = DevTokens(private, sub="uss1").token("127.0.0.1", ["utm.strategic_coordination"])
    http = app.test_client()
    for change, field in BAD:
        body = {"extents": [box(0, 100)], "state": "Accepted", "uss_base_url": "http://uss1.example.com",
                "new_subscription": {"uss_base_url": "http://uss1.example.com"}}
        change(body)
        r = http.put(f"/dss/v1/operational_intent_references/{new_id()}", json=body,
                     headers={"Authorization": f"Bearer {token}"})
        assert r.status_code == 400 and field in r.get_json()["message"], (field, r.get_json())
    r = http.put("/dss/v1/operational_intent_references/not-a-uuid", json={},
                 headers={"Authorization": f"Bearer {token}"})
    assert r.status_code == 400 and "entityid: 'not-a-uuid'" in r.get_json()["message"]


def test_tokens_are_checked(dss, standin):
    app, private = standin
    with pytest.raises(DssError) as unsigned:
        DssClient(URL, StaticToken("not.a.token"), session=WsgiSession(app)).query_operational_intent_references(
            box(0, 1))
    assert unsigned.value.status == 401
    # a token without the operation's scope: 403 naming it

    class OneScope(DevTokens):
        def token(self, audience, scopes):
            return super().token(audience, ["utm.constraint_processing"])
    with pytest.raises(DssError) as scoped:
        DssClient(URL, OneScope(private), session=WsgiSession(app)).query_operational_intent_references(box(0, 1))
    assert scoped.value.status == 403 and "utm.strategic_coordination" in scoped.value.message


def test_the_standin_refuses_to_send_an_answer_that_is_not_the_standards_type(dss, standin):
    """Its answers are checked: a reference broken inside the stand-in is a 500, never a DSS answer."""
    uss1, _, state = dss
    eid, _ = create(uss1, [box(0, 100)])
    state.intents[eid].doc["ovn"] = "short"   # F3548: 16 to 128 characters
    with pytest.raises(DssError) as broken:
        uss1.get_operational_intent_reference(eid)
    assert broken.value.status == 500 and "stand-in DSS bug" in broken.value.message


@pytest.mark.slow
def test_over_a_socket(dss, standin):
    """The client's own transport (requests) against the stand-in on a loopback socket."""
    import requests

    app, private = standin
    server = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    try:
        uss1, uss2 = clients(app, private, lambda _: requests.Session(), f"http://127.0.0.1:{server.server_port}")
        eid, made = create(uss1, [box(0, 100)])
        with pytest.raises(DssError) as conflict:
            create(uss2, [box(0, 100)], url="http://uss2.example.com")
        assert conflict.value.status == 409 and conflict.value.conflict.missing_operational_intents[0].id == eid
        assert [r.id for r in uss2.query_operational_intent_references(box(0, 10))] == [eid]
        uss1.delete_operational_intent_reference(eid, made.operational_intent_reference.ovn)
        assert uss2.query_operational_intent_references(box(0, 10)) == []
    finally:
        server.shutdown()
        thread.join(timeout=5)
    with pytest.raises(DssError) as down:
        DssClient(f"http://127.0.0.1:{server.server_port}", StaticToken("t"), timeout_s=2).query_constraint_references(
            box(0, 1))
    assert down.value.status == 0


def test_the_client_refuses_bad_settings():
    with pytest.raises(ValueError, match="base_url: 'dss.example.com'"):
        DssClient("dss.example.com", StaticToken("t"))
    with pytest.raises(ValueError, match="token: ''"):
        StaticToken("")
