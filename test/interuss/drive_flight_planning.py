"""Drive a USS with InterUSS's own code (interuss-monitoring's monitorlib), as uss_qualifier does.

Runs in the Python 3.13 environment of requirements-interuss.txt (scripts/interuss_env.sh), not
in the project's: it imports nothing of this project. Input: a JSON file (argv[1]) with

    base_url         the USS's base URL (http://HOST:PORT)
    token            a bearer token with every scope used below (a static token: no auth server)
    flight_plan_id   the flight plan's id (a UUIDv4)
    intent_id        the id of the operational intent the USS publishes for it
    plan, modified   two flight_planning v1 FlightPlan documents (the first plan, its change)

Steps, each with monitorlib's clients: the interface's readiness (V1FlightPlannerClient.
report_readiness), plan, read and validate the published intent, modify, read and validate
again, the F3548 version (InterUSSVersioningClient), end the flight, read the intent once more.
Each served intent is checked by monitorlib.schema_validation.validate_implicitdict_object with
uas_standards' GetOperationalIntentDetailsResponse and parsed as it. Output: one JSON object on
stdout, the results of every step (errors as text, never a traceback alone).
"""

from __future__ import annotations

import json
import sys

from implicitdict import ImplicitDict
from monitoring.monitorlib.clients.flight_planning.client_v1 import V1FlightPlannerClient
from monitoring.monitorlib.clients.flight_planning.flight_info import ExecutionStyle, FlightInfo
from monitoring.monitorlib.clients.versioning.client_interuss import InterUSSVersioningClient
from monitoring.monitorlib.infrastructure import AdditionalHeaders, AuthAdapter, UTMClientSession
from monitoring.monitorlib.schema_validation import validate_implicitdict_object
from uas_standards.astm.f3548.v21 import api as f3548
from uas_standards.astm.f3548.v21.constants import Scope as F3548Scope
from uas_standards.interuss.automated_testing.flight_planning.v1 import api as fp

PARTICIPANT = "uam_fleet"
SYSTEM_IDENTITY = "astm.f3548.v21"


class StaticTokenAuth(AuthAdapter):
    """monitorlib's auth adapter for one token issued elsewhere (the test mints it).

    ``get_headers`` reports no issuance time: monitorlib's describe_request formats it with
    ``.4g`` ("3.1e-06s" for a token issued in microseconds, as here), which its
    StringBasedTimeDelta cannot parse, so the first query of each scope would fail to be
    described (interuss-monitoring 0.37.0; an auth server taking >= 0.1 ms never meets it)."""

    def __init__(self, token: str):
        super().__init__()
        self._token = token

    def issue_token(self, intended_audience: str, scopes: list[str]) -> str:
        return self._token

    def get_headers(self, url: str, scopes: list[str] | None = None) -> AdditionalHeaders:
        return AdditionalHeaders(headers={"Authorization": f"Bearer {self._token}"})


def _value(enum_or_str) -> str:
    return getattr(enum_or_str, "value", enum_or_str)


def activity(resp) -> dict:
    """A PlanningActivityResponse as JSON."""
    return {"activity_result": _value(resp.activity_result), "flight_plan_status": _value(resp.flight_plan_status),
            "notes": resp.notes or "", "as_planned_volumes": (len(resp.as_planned.basic_information.area)
                                                               if resp.as_planned else None)}


def served_intent(session: UTMClientSession, intent_id: str) -> dict:
    """GET the operational intent's details; the schema errors monitorlib finds in it."""
    op = f3548.OPERATIONS[f3548.OperationID.GetOperationalIntentDetails]
    r = session.request(op.verb, op.path.format(entityid=intent_id), scope=F3548Scope.StrategicCoordination)
    out = {"status": r.status_code}
    if r.status_code != 200:
        out["body"] = r.text[:300]
        return out
    doc = r.json()
    errors = validate_implicitdict_object(doc, f3548.GetOperationalIntentDetailsResponse)
    out["schema_errors"] = [f"{e.json_path}: {e.message}" for e in errors]
    parsed = ImplicitDict.parse(doc, f3548.GetOperationalIntentDetailsResponse)
    ref = parsed.operational_intent.reference
    out.update(id=ref.id, version=ref.version, ovn=ref.ovn, state=_value(ref.state),
               volumes=len(parsed.operational_intent.details.volumes))
    return out


def step(results: dict, name: str, fn) -> None:
    """Run one step; its result, or the error that stopped it, goes into ``results[name]``."""
    try:
        results[name] = fn()
    except Exception as exc:  # noqa: BLE001 -- every failure is reported to the test as text
        results[name] = {"error": f"{type(exc).__name__}: {exc}"}


def main(path: str) -> int:
    spec = json.load(open(path))
    auth = StaticTokenAuth(spec["token"])
    base = spec["base_url"].rstrip("/")
    planner = V1FlightPlannerClient(UTMClientSession(base + "/flight_planning/v1", auth), PARTICIPANT)
    uss = UTMClientSession(base, auth)
    fid, oid = spec["flight_plan_id"], spec["intent_id"]
    info = {k: FlightInfo.from_flight_plan(ImplicitDict.parse(spec[k], fp.FlightPlan)) for k in ("plan", "modified")}

    results: dict = {}
    step(results, "readiness", lambda: {"errors": planner.report_readiness().errors or []})
    step(results, "plan", lambda: activity(planner.try_plan_flight(info["plan"], ExecutionStyle.IfAllowed,
                                                                    flight_id=fid)))
    step(results, "intent_planned", lambda: served_intent(uss, oid))
    step(results, "modify", lambda: activity(planner.try_update_flight(fid, info["modified"],
                                                                       ExecutionStyle.IfAllowed)))
    step(results, "intent_modified", lambda: served_intent(uss, oid))
    versioning = InterUSSVersioningClient(UTMClientSession(base, auth), PARTICIPANT)
    step(results, "version", lambda: {"version": versioning.get_version(SYSTEM_IDENTITY).version})
    step(results, "end", lambda: activity(planner.try_end_flight(fid, ExecutionStyle.IfAllowed)))
    step(results, "intent_ended", lambda: served_intent(uss, oid))
    json.dump(results, sys.stdout)
    return 0


if __name__ == "__main__":
    raise SystemExit(main(sys.argv[1]))
