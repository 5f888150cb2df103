"""InterUSS's flight_planning interface on the USS server (docs/f3548.md, "The flight_planning
interface"), driven over HTTP against a server whose decider is a real Planner in this process:
plan, modify, delete, clear area, a rejected plan, bad input (400 naming the field), unauthorised
(401 / 403); every answer parsed with uas_standards' own types, as InterUSS's client parses it."""

from types import SimpleNamespace

import numpy as np
import pytest
import requests
from implicitdict import ImplicitDict
from uas_standards.interuss.automated_testing.flight_planning.v1 import api

from uam_planner.constraints import Constraint
from uas_standards.astm.f3548.v21.api import GetOperationalIntentDetailsResponse
from uam_planner.f3548 import IntentContext, VolumeSpec, intent_id
from uam_planner.geo import enu_to_geodetic
from uam_planner.grants import PriorityGrants
from uam_planner.network import network_from_enu
from uam_planner.planning import Planner, PlanningConfig
from uam_sim.f3548.auth import TokenVerifier, default_audiences, generate_dev_keys, mint_token
from uam_sim.f3548.flight_planning import PREFIX, SCOPE_DIRECT, SCOPE_PLAN, FlightPlanning, InProcessDecider
from uam_sim.f3548.uss_server import SCOPE_INTENTS, IntentStore, UssServer, create_app

OP = "flight_planning"
FID = "5f0f6b52-8c55-4d4e-9d4a-1e2b3c4d5e6f"
FID2 = "0a1b2c3d-4e5f-4a6b-8c7d-8e9fa0b1c2d3"


def lanes():
    """Lane Wp (-1000, 0) - mp (0, 0) - Ep (1000, 0); a vertiport C (0, 480) off it."""
    ids = ["Wp", "mp", "Ep", "C"]
    enu = [(-1000, 0, 0), (0, 0, 0), (1000, 0, 0), (0, 480, 0)]
    return network_from_enu("lanes", ids, enu, [True, False, True, True],
                            [("Wp", "mp"), ("mp", "Ep"), ("mp", "C")])


def best_of_each(weights, edges, groups):
    """The best candidate of each request, greedily without conflicts (enough here)."""
    order = np.argsort(-np.asarray(weights), kind="stable")
    taken, blocked = [], set()
    nbrs = {}
    for a, b in np.asarray(edges).reshape(-1, 2):
        nbrs.setdefault(int(a), set()).add(int(b))
        nbrs.setdefault(int(b), set()).add(int(a))
    for v in order:
        if int(v) not in blocked:
            taken.append(int(v))
            blocked |= nbrs.get(int(v), set()) | {int(v)}
    return SimpleNamespace(selected=np.array(sorted(taken)), backend="best")


def volume(ctx, net, x0, x1, y0, y1, t0, t1):
    """A flight_planning Volume4D (JSON): the ENU box [x0, x1] x [y0, y1] from the ground to
    200 m, from t0 to t1 [s of simulation time]."""
    corners = [(x0, y0, 0.0), (x1, y0, 0.0), (x1, y1, 0.0), (x0, y1, 0.0)]
    lla = enu_to_geodetic(np.array(corners), net.origin_lat_lon_alt)
    h = float(net.origin_lat_lon_alt[2])
    return {"volume": {"outline_polygon": {"vertices": [{"lat": float(a), "lng": float(b)} for a, b, _ in lla]},
                       "altitude_lower": {"value": h - 10.0, "reference": "W84", "units": "M"},
                       "altitude_upper": {"value": h + 200.0, "reference": "W84", "units": "M"}},
            "time_start": {"value": ctx.time(t0).value, "format": "RFC3339"},
            "time_end": {"value": ctx.time(t1).value, "format": "RFC3339"}}


def upsert(ctx, net, request_id, t0=60.0, t1=180.0, priority=0, style="IfAllowed", west_to_east=True):
    """An UpsertFlightPlanRequest whose area runs along the lane (first volume at one end, last
    at the other)."""
    x0, x1 = (-1100, 900) if west_to_east else (900, -1100)
    a = volume(ctx, net, x0, x0 + 200, -100, 100, t0, t1)
    b = volume(ctx, net, x1, x1 + 200, -100, 100, t0, t1 + 300)
    return {"request_id": request_id, "execution_style": style,
            "flight_plan": {"basic_information": {"usage_state": "Planned", "uas_state": "Nominal",
                                                  "area": [a, b]},
                            "astm_f3548_21": {"priority": priority}}}


class Answer:
    """An HTTP answer, the same whether it came over a socket or from the WSGI test client."""

    def __init__(self, status_code, headers, body: bytes):
        self.status_code, self.headers, self._body = status_code, headers, body

    def json(self):
        import json
        return json.loads(self._body)


class Client:
    """The interface's HTTP operations: through the app's WSGI test client (fast), or over a
    socket to a running server (``base``)."""

    def __init__(self, app=None, base=""):
        self._client = app.test_client() if app is not None else None
        self.base = base

    def call(self, verb, path, json=None, headers=None):
        if self._client is not None:
            r = getattr(self._client, verb)(path, json=json, headers=headers or {})
            return Answer(r.status_code, r.headers, r.get_data())
        r = getattr(requests, verb)(self.base + path, json=json, headers=headers or {}, timeout=10)
        return Answer(r.status_code, r.headers, r.content)


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    return generate_dev_keys(tmp_path_factory.mktemp("keys"))


def make_uss(keys, served_over_http=False):
    net = lanes()
    spec = VolumeSpec.for_separation(100.0)
    ctx = IntentContext(net.origin_lat_lon_alt, spec)
    # a horizon of 4 epochs committed ahead: a flight plan is approved before its departure
    cfg = PlanningConfig(k=2, horizon_epochs=4, commit_ahead=True, priority_grants=PriorityGrants(default=0))
    planner = Planner(net, cfg, "mwis", solve_mwis=best_of_each)
    store = IntentStore(ctx)
    planning = FlightPlanning(InProcessDecider(planner, store=store), net, ctx, operator_id=OP)
    private, public = keys
    srv = None
    if served_over_http:
        srv = UssServer(store, port=0, auth_key=str(public), planning=planning).start()
        client = Client(base=srv.url)
    else:
        verifier = TokenVerifier.from_file(public, default_audiences(ctx.uss_base_url))
        client = Client(app=create_app(store, "verify", verifier, planning=planning))

    def headers(*scopes):
        return {"Authorization": f"Bearer {mint_token(private, 'localhost', list(scopes))}"}
    return SimpleNamespace(net=net, ctx=ctx, planner=planner, store=store, planning=planning, srv=srv,
                           client=client, headers=headers, user=headers(SCOPE_PLAN, SCOPE_INTENTS),
                           director=headers(SCOPE_DIRECT))


@pytest.fixture
def uss(keys):
    return make_uss(keys)


def put(uss, fid, body, headers=None):
    return uss.client.call("put", f"{PREFIX}/flight_plans/{fid}", body, uss.user if headers is None else headers)


def delete(uss, fid, headers=None):
    return uss.client.call("delete", f"{PREFIX}/flight_plans/{fid}", None, uss.user if headers is None else headers)


def post_clear(uss, body, headers=None):
    return uss.client.call("post", f"{PREFIX}/clear_area_requests", body,
                           uss.director if headers is None else headers)


def get_status(uss, headers=None):
    return uss.client.call("get", f"{PREFIX}/status", None, uss.director if headers is None else headers)


def parsed(r, kind):
    assert r.headers["Content-Type"] == "application/json"
    return ImplicitDict.parse(r.json(), kind)


def served(uss, request_id):
    return uss.client.call("get", f"/uss/v1/operational_intents/{intent_id(OP, request_id)}", None, uss.user)


def test_status_is_ready_for_the_test_director(uss):
    r = get_status(uss)
    assert r.status_code == 200, r.text
    got = parsed(r, api.StatusResponse)
    assert got.status == api.StatusResponseStatus.Ready
    assert got.api_name == "Flight Planning Automated Testing Interface"
    assert got.api_version == f"v{api.API_VERSION}"


def test_a_plan_goes_through_the_planner_is_served_as_an_intent_then_modified_and_deleted(uss):
    r = put(uss, FID, upsert(uss.ctx, uss.net, "req-1"))
    assert r.status_code == 200, r.text
    got = parsed(r, api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.Completed, got
    assert got.flight_plan_status == api.FlightPlanStatus.Planned
    f = uss.planner.flight(FID)
    assert (f.origin_id, f.destination_id, f.operator_id) == ("Wp", "Ep", OP)
    # as planned: the operational intent's volumes, which the USS serves to peers
    assert len(got.as_planned.basic_information.area) > 2
    assert served(uss, FID).status_code == 200
    # the same request id again: the first answer, nothing planned twice
    again = put(uss, FID, upsert(uss.ctx, uss.net, "req-1"))
    assert again.json() == r.json()
    assert sum(a.request_id.startswith(FID) for a in uss.planner.active) == 1

    # modified: the other way round -> a new version of the same flight, so of the same
    # operational intent (same id, a higher version, another OVN)
    before = served(uss, FID).json()["operational_intent"]["reference"]
    r = put(uss, FID, upsert(uss.ctx, uss.net, "req-2", west_to_east=False))
    got = parsed(r, api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.Completed, got
    assert got.flight_plan_status == api.FlightPlanStatus.Planned
    f2 = uss.planner.flight(FID)
    assert (f2.origin_id, f2.destination_id, f2.version) == ("Ep", "Wp", f.version + 1)
    assert sum(a.request_id == FID for a in uss.planner.active) == 1
    after = served(uss, FID).json()["operational_intent"]["reference"]
    assert after["id"] == before["id"] and after["version"] > before["version"] and after["ovn"] != before["ovn"]
    assert ImplicitDict.parse(served(uss, FID).json(), GetOperationalIntentDetailsResponse)
    updates = [(u.request_id, u.kind, u.version) for res in uss.planning.decider.results for u in res.plan_updates]
    assert updates == [(FID, "modified", f.version + 1)]

    r = delete(uss, FID)
    got = parsed(r, api.DeleteFlightPlanResponse)
    assert r.status_code == 200
    assert (got.planning_result, got.flight_plan_status) == (api.PlanningActivityResult.Completed,
                                                             api.FlightPlanStatus.Closed)
    assert uss.planner.flight(FID) is None and served(uss, FID).status_code == 404
    # the next epoch reports the cancellation as the planner reports any
    uss.planning.decider._epoch()
    kinds = [(u.request_id, u.kind, u.version) for res in uss.planning.decider.results for u in res.plan_updates]
    assert (FID, "cancelled", f.version + 2) in kinds
    # deleted twice: 404, with a body InterUSS's client can still read
    r = delete(uss, FID)
    assert r.status_code == 404
    assert parsed(r, api.DeleteFlightPlanResponse).flight_plan_status == api.FlightPlanStatus.NotPlanned


def test_a_rejected_modification_keeps_the_previous_version(uss):
    assert put(uss, FID, upsert(uss.ctx, uss.net, "a")).json()["planning_result"] == "Completed"
    r = put(uss, FID, upsert(uss.ctx, uss.net, "b", priority=7))
    got = parsed(r, api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.Rejected
    assert got.flight_plan_status == api.FlightPlanStatus.Planned
    assert "priority: 7 is above operator 'flight_planning''s grant 0" in got.notes
    assert "previous version stays in force" in got.notes
    assert uss.planner.flight(FID) is not None and served(uss, FID).status_code == 200


def test_a_modification_without_a_conflict_free_candidate_keeps_the_previous_version(uss):
    """The new version is decided at the next epoch only: a constraint closing the lane from then
    on leaves it no candidate; the old version (departing before the closure) stays in force,
    with its version, and nothing is reported."""
    assert put(uss, FID, upsert(uss.ctx, uss.net, "a")).json()["planning_result"] == "Completed"
    f = uss.planner.flight(FID)
    wall = Constraint("wall", 0, "closed lane", f.arrival_s + 1.0, np.inf,
                      rings_m=(np.array([[-1200.0, -300.0], [1200.0, -300.0], [1200.0, 300.0], [-1200.0, 300.0]]),))
    uss.planner.set_constraints([wall])
    # a later departure (within the planner's horizon) arrives after the closure begins
    r = put(uss, FID, upsert(uss.ctx, uss.net, "b", t0=f.departure_s + 30.0, t1=f.departure_s + 60.0))
    got = parsed(r, api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.Rejected, got
    assert got.flight_plan_status == api.FlightPlanStatus.Planned
    assert "previous version stays in force" in got.notes and got.notes.startswith("expired")
    assert uss.planner.flight(FID) == f
    assert [u for res in uss.planning.decider.results for u in res.plan_updates] == []


def test_a_plan_that_cannot_be_deconflicted_is_rejected_and_nothing_is_served(uss):
    wall = Constraint("wall", 0, "closed lane", -np.inf, np.inf,
                      rings_m=(np.array([[-1200.0, -300.0], [1200.0, -300.0], [1200.0, 300.0], [-1200.0, 300.0]]),))
    uss.planner.set_constraints([wall])
    r = put(uss, FID, upsert(uss.ctx, uss.net, "x", t1=90.0))
    got = parsed(r, api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.Rejected, got
    assert got.flight_plan_status == api.FlightPlanStatus.NotPlanned
    assert got.notes.startswith("expired")
    assert uss.planner.flight(FID) is None and served(uss, FID).status_code == 404


def test_clear_area_closes_our_flights_in_it_and_says_so(uss):
    assert put(uss, FID, upsert(uss.ctx, uss.net, "a")).json()["planning_result"] == "Completed"
    body = {"request_id": "clear-1", "extent": volume(uss.ctx, uss.net, -50, 50, -50, 50, 0.0, 3600.0)}
    r = post_clear(uss, body)
    got = parsed(r, api.ClearAreaResponse)
    assert got.outcome.success is True
    assert r.json()["outcome"]["details"]["closed"] == [FID]
    assert uss.planner.flight(FID) is None
    # an area the flight never enters closes nothing
    assert put(uss, FID2, upsert(uss.ctx, uss.net, "b")).json()["planning_result"] == "Completed"
    body = {"request_id": "clear-2", "extent": volume(uss.ctx, uss.net, -50, 50, 2000, 2100, 0.0, 3600.0)}
    r = post_clear(uss, body)
    assert parsed(r, api.ClearAreaResponse).outcome.success is True
    assert r.json()["outcome"]["details"]["closed"] == []
    assert uss.planner.flight(FID2) is not None


def test_what_this_usS_does_not_do_is_not_supported(uss):
    got = parsed(put(uss, FID, upsert(uss.ctx, uss.net, "h", style="Hypothetical")), api.UpsertFlightPlanResponse)
    assert got.planning_result == api.PlanningActivityResult.NotSupported
    assert "execution_style: 'Hypothetical'" in got.notes
    assert uss.planner.flight(FID) is None and not uss.planner.pending


BAD_INPUT = [
    (lambda b: b.pop("execution_style"), "execution_style"),
    (lambda b: b["flight_plan"]["astm_f3548_21"].update(priority=1000), "flight_plan.astm_f3548_21.priority: 1000"),
    (lambda b: b["flight_plan"]["basic_information"].update(area=[]), "flight_plan.basic_information.area"),
    (lambda b: b["flight_plan"]["basic_information"]["area"][0].pop("time_end"),
     "flight_plan.basic_information.area[0].time_end"),
    (lambda b: b["flight_plan"]["basic_information"]["area"][1]["volume"]["altitude_lower"].update(reference="SFC"),
     "flight_plan.basic_information.area[1].volume.altitude_lower"),
    (lambda b: b["flight_plan"].update(additional_information={"origin_id": "mp", "destination_id": "Ep"}),
     "flight_plan.additional_information.origin_id: 'mp'"),
]


def test_bad_input_is_400_naming_the_field(uss):
    for n, (change, field) in enumerate(BAD_INPUT):
        body = upsert(uss.ctx, uss.net, f"bad-{n}")
        change(body)
        r = put(uss, FID, body)
        assert r.status_code == 400, (field, r.json())
        assert field in r.json()["message"], (field, r.json())
    assert uss.planner.flight(FID) is None and not uss.planner.pending


def test_a_bad_flight_plan_id_is_400(uss):
    r = put(uss, "not-a-uuid", upsert(uss.ctx, uss.net, "x"))
    assert r.status_code == 400 and "flight_plan_id: 'not-a-uuid'" in r.json()["message"]


def test_without_a_token_or_the_operations_scope_the_answer_is_401_or_403(uss):
    body = upsert(uss.ctx, uss.net, "x")
    r = put(uss, FID, body, headers={})
    assert r.status_code == 401 and r.headers["WWW-Authenticate"].startswith("Bearer")
    r = put(uss, FID, body, headers=uss.director)   # the director may not plan as a user
    assert r.status_code == 403 and SCOPE_PLAN in r.json()["message"]
    r = get_status(uss, uss.headers(SCOPE_PLAN))
    assert r.status_code == 403 and SCOPE_DIRECT in r.json()["message"]
    r = post_clear(uss, {}, uss.user)
    assert r.status_code == 403
    assert uss.planner.flight(FID) is None and not uss.planner.pending


@pytest.mark.slow
def test_over_http_through_the_pooled_server(keys):
    """The same interface over a socket, through the server's pool of workers."""
    uss = make_uss(keys, served_over_http=True)
    try:
        assert parsed(get_status(uss), api.StatusResponse).status == api.StatusResponseStatus.Ready
        got = parsed(put(uss, FID, upsert(uss.ctx, uss.net, "h1")), api.UpsertFlightPlanResponse)
        assert got.planning_result == api.PlanningActivityResult.Completed
        assert served(uss, FID).status_code == 200
        assert parsed(delete(uss, FID), api.DeleteFlightPlanResponse).flight_plan_status == \
            api.FlightPlanStatus.Closed
        assert put(uss, FID, {"request_id": "h2"}).status_code == 400
        assert put(uss, FID, upsert(uss.ctx, uss.net, "h3"), headers={}).status_code == 401
    finally:
        uss.srv.stop()


ROOT = __import__("pathlib").Path(__file__).resolve().parents[3]
DRIVER = ROOT / "test" / "interuss" / "drive_flight_planning.py"


def interuss_python():
    """The Python of the InterUSS environment scripts/setup.sh makes (scripts/interuss_env.sh),
    or a skip saying why there is none."""
    import subprocess

    env_dir = subprocess.run(["bash", str(ROOT / "scripts" / "interuss_env.sh"), "dir"], capture_output=True,
                             text=True, check=True).stdout.strip()
    why = subprocess.run(["bash", str(ROOT / "scripts" / "interuss_env.sh"), "why"], capture_output=True,
                         text=True, check=True).stdout.strip()
    if not why.startswith("ready: "):
        pytest.skip(f"InterUSS's code is not installed: {why}")
    return f"{env_dir}/bin/python"


@pytest.mark.slow
def test_interuss_monitorlib_plans_modifies_and_ends_a_flight_and_reads_our_version(keys, tmp_path):
    """InterUSS's own code (interuss-monitoring's monitorlib, in its Python 3.13 environment)
    drives the interface over HTTP as uss_qualifier does: V1FlightPlannerClient plans, modifies
    and ends a flight, InterUSSVersioningClient reads our version, and every served intent passes
    monitorlib.schema_validation with uas_standards' F3548 type."""
    import json
    import subprocess

    from uam_sim.f3548.uss_server import SCOPE_VERSIONS, system_version

    python = interuss_python()
    uss = make_uss(keys, served_over_http=True)
    try:
        token = mint_token(keys[0], "127.0.0.1", [SCOPE_PLAN, SCOPE_DIRECT, SCOPE_INTENTS, SCOPE_VERSIONS])
        spec = {"base_url": uss.srv.url, "token": token, "flight_plan_id": FID, "intent_id": intent_id(OP, FID),
                "plan": upsert(uss.ctx, uss.net, "m1")["flight_plan"],
                "modified": upsert(uss.ctx, uss.net, "m2", west_to_east=False)["flight_plan"]}
        (tmp_path / "spec.json").write_text(json.dumps(spec))
        run = subprocess.run([python, str(DRIVER), str(tmp_path / "spec.json")], capture_output=True, text=True,
                             timeout=120)
        assert run.returncode == 0, run.stderr[-2000:]
        got = json.loads(run.stdout)
    finally:
        uss.srv.stop()
    assert got["readiness"] == {"errors": []}, got
    assert (got["plan"]["activity_result"], got["plan"]["flight_plan_status"]) == ("Completed", "Planned"), got
    assert got["plan"]["as_planned_volumes"] > 2   # the intent's volumes, read by monitorlib's FlightInfo
    planned, modified = got["intent_planned"], got["intent_modified"]
    assert planned["status"] == 200 and planned["schema_errors"] == [] and planned["volumes"] > 2, planned
    assert (got["modify"]["activity_result"], got["modify"]["flight_plan_status"]) == ("Completed", "Planned"), got
    assert modified["status"] == 200 and modified["schema_errors"] == [], modified
    # a modification is a new version of the same operational intent
    assert modified["id"] == planned["id"] == intent_id(OP, FID)
    assert modified["version"] > planned["version"] and modified["ovn"] != planned["ovn"]
    assert got["version"] == {"version": system_version()}, got
    assert (got["end"]["activity_result"], got["end"]["flight_plan_status"]) == ("Completed", "Closed"), got
    assert got["intent_ended"]["status"] == 404, got
