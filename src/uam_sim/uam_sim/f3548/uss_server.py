"""The F3548 USS-USS interface over HTTP (docs/f3548.md): a Flask app that serves the
operational intents and constraints of an :class:`IntentStore`, and a server thread.

Endpoints (F3548-21, utm.yaml):

- ``GET /uss/v1/operational_intents/{entityid}`` -> 200 ``GetOperationalIntentDetailsResponse``;
- ``GET /uss/v1/constraints/{entityid}`` -> 200 ``GetConstraintDetailsResponse``;
- errors as F3548 ``ErrorResponse`` ({"message": ...}): 400 for an id that is not F3548's UUIDv4
  format or a request too large (URL over :data:`MAX_URL_CHARS` characters, a body over
  :data:`MAX_BODY_BYTES`), 401 (no bearer token, or one that is not a valid token for this USS:
  unsigned, forged, expired, another audience) / 403 (a valid token without the endpoint's
  scope), 404 unknown (or ended) entity, 405 another method;
- ``POST /uss/v1/operational_intents``, ``/uss/v1/constraints`` (peers' notifications, with a
  :class:`uam_sim.f3548.peers.PeerInbox`), ``POST /uss/v1/reports``, ``GET .../{entityid}/telemetry``
  (412: no telemetry here), ``GET /versions/astm.f3548.v21`` (InterUSS's versioning interface);
- with a :class:`uam_sim.f3548.flight_planning.FlightPlanning`, InterUSS's flight_planning
  interface under ``/flight_planning/v1`` (status, upsert and delete flight plans, clear area);
- ``GET /uam_fleet/v1/operational_intents`` and ``/uam_fleet/v1/constraints`` (this project's, not
  F3548's: with no DSS, the ids a tool can ask for; under the same scopes as the details).

Auth (``auth``): ``verify`` (the default) checks every request's bearer access token with
:class:`uam_sim.f3548.auth.TokenVerifier`: its signature against the auth server's public key
(``auth_key``: a PEM public key or a JWKS file), its expiry, its audience (``auth_audience``,
by default the host of the server's base URL) and the endpoint's scope
(``utm.strategic_coordination`` for intents, ``utm.constraint_processing`` for constraints, as
utm.yaml says). ``off`` serves every caller without a token; the server announces it on stderr
when it starts (and the node in its log), since no one outside a local run should meet it.

The store holds each intent's volumes as JSON text once (from ``uam_planner.f3548``); a request
serves every volume of the plan version with the state at the store's time and the version of
that state (``uam_planner.f3548.intent_version``: a state change is a new version, so the
details of a version never change), at the cost of one string join. Thread-safe (one lock).
With a DSS (:class:`uam_sim.f3548.dss_sync.DssSync`) the reference of a version the DSS holds is
the DSS's own (its version, OVN, manager, subscription; :meth:`IntentStore.set_reference`);
a version the DSS does not hold is served with the local reference, as without a DSS.
The HTTP layer is :class:`uam_sim.f3548.pool.PooledWSGIServer`: a bounded pool of workers.
"""

from __future__ import annotations

import json
import re
import sys
import threading
from dataclasses import dataclass

from uam_planner.f3548 import (IntentContext, as_json, constraint_entity_id, f3548_constraint,
                               intent_id, intent_version, ovn, volume4d, volumes_for_limit)
from uam_planner.replanning import flight_state

from .auth import ALGORITHMS, DEV_SUBJECT

#: F3548 EntityID (UUIDv4) as a path parameter
ENTITY_ID = re.compile(r"^[0-9a-fA-F]{8}-[0-9a-fA-F]{4}-4[0-9a-fA-F]{3}-[89abAB][0-9a-fA-F]{3}-"
                       r"[0-9a-fA-F]{12}$")
MAX_URL_CHARS = 2048
#: a request body's bound: the largest notification F3548 allows (OiMaxVertices = 10,000 vertices,
#: 2,500 four-cornered volumes, in volumes and again in off-nominal volumes: about 2.6 MB of JSON)
#: fits; a long intent of ours is about 150 KiB on the Singapore network
MAX_BODY_BYTES = 4 << 20
AUTH_MODES = ("verify", "off")
#: the realm of the WWW-Authenticate challenge (RFC 6750)
REALM = "uam_fleet USS"
PRUNE_EVERY_S = 30.0
SCOPE_INTENTS = "utm.strategic_coordination"
SCOPE_CONSTRAINTS = "utm.constraint_processing"
SCOPE_CONFORMANCE = "utm.conformance_monitoring_sa"
#: makeUssReport takes a token with any F3548 scope (utm.yaml)
SCOPES_REPORT = (SCOPE_INTENTS, SCOPE_CONSTRAINTS, "utm.constraint_management", SCOPE_CONFORMANCE,
                 "utm.availability_arbitration")
#: InterUSS's versioning interface: the scope and the one system identity answered
SCOPE_VERSIONS = "interuss.versioning.read_system_versions"
SYSTEM_IDENTITY = "astm.f3548.v21"


def system_version() -> str:
    """This USS's version: the installed uam_sim package's (``0+unknown`` from a source tree)."""
    from importlib.metadata import PackageNotFoundError, version
    try:
        return f"uam_fleet-{version('uam_sim')}"
    except PackageNotFoundError:
        return "uam_fleet-0+unknown"


@dataclass
class _Intent:
    flight: object
    ends_s: list          # each volume's end [s], ascending
    volumes_json: list    # each volume's JSON text


@dataclass(frozen=True)
class IntentView:
    """An operational intent as served at one instant: what its DSS reference must say.
    ``version`` is the local F3548 version (``intent_version``: one per plan version and state),
    ``plan_version`` the plan's; ``volumes_json`` every volume's JSON text (served as ``volumes``,
    or as ``off_nominal_volumes`` when Contingent)."""
    entity_id: str
    version: int
    plan_version: int
    state: str
    volumes_json: tuple
    priority: int


class IntentStore:
    """The live operational intents and constraints of one USS (thread-safe).

    ``put_flight(flight)`` adds or replaces (a higher or equal version) the intent of a flight;
    ``end(operator_id, request_id)`` removes it (a cancellation); ``set_constraints`` replaces the
    constraint set; ``set_time`` moves the clock (simulation seconds) that states and volume
    clipping use. ``details(id)`` / ``constraint_details(id)``: the response's JSON text or None.
    ``views()``: every live intent as an :class:`IntentView`; ``set_reference``: the DSS's
    reference of a version. ``on_change`` (a callable without arguments, or None) is called
    after every change of the intents or the clock (outside the lock), e.g. to wake a DSS sync.
    """

    def __init__(self, ctx: IntentContext):
        self.ctx = ctx
        self.on_change = None
        self._lock = threading.Lock()
        self._intents: dict[str, _Intent] = {}
        self._constraints: dict[str, str] = {}
        self._dss_refs: dict[str, tuple] = {}   # entity id -> (local version, the DSS's reference, JSON)
        self._t_s = 0.0
        self._pruned_s = 0.0

    def _changed(self) -> None:
        if self.on_change is not None:
            self.on_change()

    # ---- updates ---------------------------------------------------------------------------
    def put_flight(self, flight) -> str:
        """Add or replace the intent of ``flight`` (an older version never replaces a newer one).
        Returns its entity id."""
        oid = intent_id(flight.operator_id, flight.request_id)
        vols, _ = volumes_for_limit(flight.trajectory, self.ctx.spec)
        entry = _Intent(flight, [v.t1_s for v in vols],
                        [json.dumps(as_json(volume4d(v, self.ctx)), separators=(",", ":"))
                         for v in vols])
        with self._lock:
            old = self._intents.get(oid)
            if old is None or int(old.flight.version) <= int(flight.version):
                self._intents[oid] = entry
        self._changed()
        return oid

    def clear(self) -> None:
        """Forget every intent and constraint (the planner started a new run)."""
        with self._lock:
            self._intents.clear()
            self._dss_refs.clear()
            self._constraints = {}
        self._changed()

    def end(self, operator_id: str, request_id: str) -> bool:
        oid = intent_id(operator_id, request_id)
        with self._lock:
            gone = self._intents.pop(oid, None) is not None
            self._dss_refs.pop(oid, None)
        self._changed()
        return gone

    def set_constraints(self, constraints) -> None:
        docs = {}
        for c in constraints:
            oc = f3548_constraint(c, self.ctx)
            if oc is not None:
                docs[constraint_entity_id(c.constraint_id)] = json.dumps(
                    {"constraint": as_json(oc)}, separators=(",", ":"))
        with self._lock:
            self._constraints = docs

    def set_time(self, t_s: float) -> None:
        """Move the clock; every ``PRUNE_EVERY_S`` of simulation time the intents that ended
        (arrival before the clock) are dropped, so a long run's store stays the size of what
        is live (an intent's volumes are ~150 KiB of JSON on the Singapore network)."""
        with self._lock:
            self._t_s = max(self._t_s, float(t_s))
            if self._t_s - self._pruned_s >= PRUNE_EVERY_S:
                self._pruned_s = self._t_s
                for oid in [k for k, e in self._intents.items() if e.flight.arrival_s < self._t_s]:
                    del self._intents[oid]
                    self._dss_refs.pop(oid, None)
        self._changed()

    @property
    def time_s(self) -> float:
        return self._t_s

    def intent_ids(self) -> list:
        with self._lock:
            return sorted(self._intents)

    def constraint_ids(self) -> list:
        with self._lock:
            return sorted(self._constraints)

    # ---- the DSS's references --------------------------------------------------------------
    def views(self) -> list:
        """Every intent served at the store's time (not Ended) as an :class:`IntentView`, by id."""
        with self._lock:
            entries = sorted(self._intents.items())
            t = self._t_s
        out = []
        for oid, entry in entries:
            view = self._view(oid, entry, t)
            if view is not None:
                out.append(view)
        return out

    @staticmethod
    def _view(oid: str, entry: _Intent, t: float):
        f = entry.flight
        state = flight_state(f, t)
        if state == "Ended" or not entry.volumes_json:
            return None
        return IntentView(oid, intent_version(f.version, state), int(f.version), state,
                          tuple(entry.volumes_json), int(f.priority))

    def set_reference(self, entity_id: str, version: int, reference: dict) -> None:
        """Serve ``reference`` (the DSS's OperationalIntentReference, JSON) as the reference of
        local version ``version`` of ``entity_id``: its version, OVN, manager and subscription
        are the DSS's. Kept while the intent stays at that version; an intent no longer served
        keeps none. The DSS issues one reference per change, so a version's OVN, once the
        DSS's, stays."""
        text = json.dumps(reference, separators=(",", ":"))
        with self._lock:
            if entity_id in self._intents:
                self._dss_refs[entity_id] = (int(version), text)

    def reference_of(self, entity_id: str):
        """(local version, the DSS's reference as a dict) held for ``entity_id``, or None."""
        with self._lock:
            held = self._dss_refs.get(entity_id)
        return None if held is None else (held[0], json.loads(held[1]))

    def document(self, view: IntentView, reference_json: str | None = None) -> str:
        """The OperationalIntent (``{"reference": ..., "details": ...}``) of ``view`` as JSON text,
        with ``reference_json`` as its reference (default: the local one)."""
        vols = view.volumes_json
        if reference_json is None:
            first, last = json.loads(vols[0]), json.loads(vols[-1])
            ref = {"id": view.entity_id, "manager": self.ctx.manager, "uss_availability": "Unknown",
                   "version": view.version, "state": view.state, "ovn": ovn(view.entity_id, view.version),
                   "time_start": first["time_start"], "time_end": last["time_end"],
                   "uss_base_url": self.ctx.uss_base_url, "subscription_id": self.ctx.subscription_id}
            reference_json = json.dumps(ref, separators=(",", ":"))
        joined = "[" + ",".join(vols) + "]"
        nominal, off = ("[]", joined) if view.state == "Contingent" else (joined, "[]")
        return ('{"reference":' + reference_json + ',"details":{"volumes":' + nominal
                + ',"off_nominal_volumes":' + off + ',"priority":' + str(int(view.priority)) + '}}')

    # ---- reads -----------------------------------------------------------------------------
    def details(self, entity_id: str) -> str | None:
        """The GetOperationalIntentDetailsResponse of ``entity_id`` at the store's time, as JSON
        text; None if unknown or Ended. The reference is the DSS's when the DSS holds this version
        (:meth:`set_reference`), else the local one (version ``intent_version``, OVN derived)."""
        with self._lock:
            entry = self._intents.get(entity_id)
            held = self._dss_refs.get(entity_id)
            t = self._t_s
        if entry is None:
            return None
        # every volume of the plan version, whenever asked: its details change only with a new
        # version (a new plan version or a state change, intent_version)
        view = self._view(entity_id, entry, t)
        if view is None:
            return None
        reference = held[1] if held is not None and held[0] == view.version else None
        return '{"operational_intent":' + self.document(view, reference) + '}'

    def constraint_details(self, entity_id: str) -> str | None:
        with self._lock:
            return self._constraints.get(entity_id)


def base_url(host: str, port: int) -> str:
    """The URL a server bound to ``host``:``port`` really has: ``http://HOST:PORT`` (the bound
    address as it is; for a wildcard bind, 0.0.0.0 or ::, the machine's fully qualified name,
    the one name that reaches every interface); an IPv6 address in brackets."""
    import socket
    if host in ("", "0.0.0.0", "::"):
        host = socket.getfqdn()
    if ":" in host and not host.startswith("["):
        host = f"[{host}]"
    return f"http://{host}:{int(port)}"


def _error(status: int, message: str):
    from flask import Response
    return Response(json.dumps({"message": message}), status=status, mimetype="application/json")


def _peer_routes(app, store: IntentStore, inbox, authorise) -> None:
    """The endpoints a peer or a test tool calls beyond the details: telemetry, InterUSS's
    versioning interface, and (with ``inbox``) notifications and reports. ``authorise(scope)``:
    None, or the 401 / 403 answer."""
    from flask import Response, g, request

    @app.get("/uss/v1/operational_intents/<entityid>/telemetry")
    def telemetry(entityid):
        bad = authorise(SCOPE_CONFORMANCE)
        if bad is not None:
            return bad
        if not ENTITY_ID.match(entityid) or store.details(entityid.lower()) is None:
            return _error(404, f"operational intent {entityid[:64]!r} is not managed here (unknown or ended)")
        # no position reports reach this USS (the fleet's states are the simulator's)
        return _error(412, f"operational intent {entityid}: no telemetry is available from this USS")

    @app.get("/versions/<system_identity>")
    def versions(system_identity):
        bad = authorise(SCOPE_VERSIONS)
        if bad is not None:
            return bad
        if system_identity != SYSTEM_IDENTITY:
            return _error(404, f"system_identity: {system_identity[:64]!r} is not one of this USS's "
                               f"({SYSTEM_IDENTITY})")
        return Response(json.dumps({"system_identity": SYSTEM_IDENTITY, "system_version": system_version()}),
                        mimetype="application/json")

    def _peer(scope, handle):
        """One endpoint a peer posts to: its token, a JSON body, then ``handle(body, manager)``."""
        from .peers import NotificationError
        bad = authorise(scope)
        if bad is not None:
            return bad
        if inbox is None:
            return _error(404, f"{request.path}: this server takes no notifications (no planner is wired)")
        body = request.get_json(silent=True)
        if body is None:
            return _error(400, "body: not a JSON document")
        manager = getattr(getattr(g, "grant", None), "sub", "") or ""
        try:
            return handle(body, manager)
        except NotificationError as exc:
            return _error(exc.status, exc.message)

    @app.post("/uss/v1/operational_intents")
    def notify_intent():
        return _peer(SCOPE_INTENTS, lambda body, who: (inbox.notify(body, "operational_intent", who), ("", 204))[1])

    @app.post("/uss/v1/constraints")
    def notify_constraint():
        return _peer(SCOPE_CONSTRAINTS, lambda body, who: (inbox.notify(body, "constraint", who), ("", 204))[1])

    @app.post("/uss/v1/reports")
    def report():
        return _peer(SCOPES_REPORT, lambda body, who: Response(json.dumps(inbox.report(body, who)), status=201,
                                                               mimetype="application/json"))


def _flight_planning_routes(app, planning, authorise) -> None:
    """InterUSS's flight_planning interface (``uam_sim.f3548.flight_planning``): each operation
    of the library's table at its path, behind its scopes."""
    from flask import Response, request

    from .flight_planning import SCOPES, route

    def answer(status_doc):
        status, doc = status_doc
        return Response(json.dumps(doc), status=status, mimetype="application/json")

    def body():
        return request.get_json(silent=True)

    def endpoint(op, call):
        def view(**params):
            bad = authorise(SCOPES[op])
            if bad is not None:
                return bad
            if request.method in ("PUT", "POST") and body() is None:
                return _error(400, "body: not a JSON document")
            return answer(call(**params))
        view.__name__ = f"flight_planning_{op.value}"
        verb, rule = route(op)
        app.add_url_rule(rule, view_func=view, methods=[verb])

    from uas_standards.interuss.automated_testing.flight_planning.v1.api import OperationID as Op
    endpoint(Op.GetStatus, lambda: planning.status())
    endpoint(Op.UpsertFlightPlan, lambda flight_plan_id: planning.upsert(flight_plan_id, body()))
    endpoint(Op.DeleteFlightPlan, lambda flight_plan_id: planning.delete(flight_plan_id))
    endpoint(Op.ClearArea, lambda: planning.clear_area(body()))


def _size_limits(app) -> None:
    """Refuse, before any route, a URL longer than MAX_URL_CHARS characters or a body larger
    than MAX_BODY_BYTES bytes with the standard's 400."""
    from flask import request

    @app.before_request
    def _limits():
        url = request.full_path if request.query_string else request.path
        if len(url) > MAX_URL_CHARS:
            return _error(400, f"request: the URL has {len(url)} characters, more than "
                               f"{MAX_URL_CHARS}")
        if (request.content_length or 0) > MAX_BODY_BYTES:
            return _error(400, f"request: a body of {request.content_length} bytes, more than "
                               f"{MAX_BODY_BYTES}")
        return None


def _authoriser(auth: str, verifier):
    """``authorise(scope)`` for the routes: None if the request's token grants ``scope`` (or
    ``auth`` is ``off``), else the 401 / 403 answer with its WWW-Authenticate header."""
    from flask import g, request

    from .auth import AuthError

    def _authorise(scope: str):
        """None if the request's token grants ``scope``, else the 401 / 403 answer."""
        if auth == "off":
            return None
        try:
            g.grant = verifier.verify(request.headers.get("Authorization"), scope)
        except AuthError as exc:
            answer = _error(exc.status, exc.message)
            answer.headers["WWW-Authenticate"] = exc.www_authenticate(REALM)
            return answer
        return None
    return _authorise


def _store_routes(app, store: IntentStore, authorise) -> None:
    """The details of an operational intent and of a constraint (F3548's USS interface), and
    the listings of their ids with the store's time [s]."""
    from flask import Response

    def _details(entityid, scope, lookup, missing: str):
        """One details endpoint: the auth and id checks, then the stored document or a 404."""
        bad = authorise(scope)
        if bad is not None:
            return bad
        if len(entityid) > 36 or not ENTITY_ID.match(entityid):
            shown = entityid if len(entityid) <= 64 else entityid[:64] + "..."
            return _error(400, f"entityid: {shown!r} is not an F3548 EntityID (a UUIDv4)")
        body = lookup(entityid.lower())  # ids are UUIDs: RFC 4122 reads them case-insensitively
        if body is None:
            return _error(404, missing.format(entityid))
        return Response(body, status=200, mimetype="application/json")

    def _listing(scope, ids):
        bad = authorise(scope)
        if bad is not None:
            return bad
        return Response(json.dumps({"t_s": store.time_s, "ids": ids()}), mimetype="application/json")

    @app.get("/uss/v1/operational_intents/<path:entityid>")
    def operational_intent(entityid):
        return _details(entityid, SCOPE_INTENTS, store.details,
                        "operational intent {} is not managed here (unknown or ended)")

    @app.get("/uss/v1/constraints/<path:entityid>")
    def constraint(entityid):
        return _details(entityid, SCOPE_CONSTRAINTS, store.constraint_details,
                        "constraint {} is not managed here")

    @app.get("/uam_fleet/v1/operational_intents")
    def list_intents():
        return _listing(SCOPE_INTENTS, store.intent_ids)

    @app.get("/uam_fleet/v1/constraints")
    def list_constraints():
        return _listing(SCOPE_CONSTRAINTS, store.constraint_ids)


def create_app(store: IntentStore, auth: str = "verify", verifier=None, inbox=None, planning=None):
    """The Flask app serving ``store`` (module docstring). ``auth`` ``verify`` needs ``verifier``
    (a :class:`uam_sim.f3548.auth.TokenVerifier`). With ``inbox`` (a
    :class:`uam_sim.f3548.peers.PeerInbox`) it takes peers' notifications and reports; with
    ``planning`` (a :class:`uam_sim.f3548.flight_planning.FlightPlanning`) it serves InterUSS's
    flight_planning interface under ``/flight_planning/v1``."""
    from flask import Flask, request
    from werkzeug.exceptions import HTTPException

    if auth not in AUTH_MODES:
        raise ValueError(f"auth: {auth!r} is not one of {', '.join(AUTH_MODES)}")
    if auth == "verify" and verifier is None:
        raise ValueError("auth: 'verify' needs the auth server's public key (auth_key: a PEM or JWKS file)")
    app = Flask("uam_uss")
    app.config["MAX_CONTENT_LENGTH"] = None  # refused below with the standard's 400
    _size_limits(app)
    authorise = _authoriser(auth, verifier)
    _store_routes(app, store, authorise)
    _peer_routes(app, store, inbox, authorise)
    if planning is not None:
        _flight_planning_routes(app, planning, authorise)

    @app.errorhandler(HTTPException)
    def _http_error(exc):
        return _error(exc.code or 500, f"{exc.name}: {request.method} {request.path[:200]}")

    return app


class UssServer:
    """The app on a :class:`uam_sim.f3548.pool.PooledWSGIServer` (``workers`` threads, at most
    ``max_connections`` connections) in a daemon thread: ``UssServer(store, port=0, auth_key=FILE)``
    (0 = a free port, see ``.port``), ``.start()``, ``.stop()``. Binds ``host`` (default loopback).

    ``auth`` ``verify`` (default) needs ``auth_key`` (the auth server's PEM public key or JWKS
    file); ``auth_audience`` is the comma-separated audiences a token may name ('' = the host of
    the store's base URL, :func:`uam_sim.f3548.auth.default_audiences`). ``auth`` ``off``:
    :attr:`announcement` is written to stderr at ``start()``. Raises ValueError naming the
    parameter of a bad setting (an unreadable key, a private key, an unknown mode)."""

    def __init__(self, store: IntentStore, host: str = "127.0.0.1", port: int = 0,
                 auth: str = "verify", auth_key: str = "", auth_audience: str = "",
                 workers: int = 8, max_connections: int = 256, inbox=None, planning=None, **pool_options):
        from werkzeug.serving import WSGIRequestHandler

        from .auth import TokenVerifier, default_audiences  # joserfc and cryptography on first use
        from .pool import PooledWSGIServer

        class _Quiet(WSGIRequestHandler):
            """No log line per request (a load of them is the job); what the HTTP layer refuses
            before the app sees it (a request line over 65,536 bytes: 414, a malformed request
            line: 400) answered with an F3548 ErrorResponse, not an HTML page."""
            def log_request(self, *args, **kwargs):
                pass

            def send_error(self, code, message=None, explain=None):
                short, long = self.responses.get(code, ("Error", ""))
                text = f"request: HTTP {int(code)} {message or short}: {explain or long}"
                body = json.dumps({"message": text[:500]}).encode()  # the client's bytes, escaped
                self.send_response(int(code), short)
                self.send_header("Connection", "close")
                self.send_header("Content-Type", "application/json")
                self.send_header("Content-Length", str(len(body)))
                self.end_headers()
                if self.command != "HEAD" and int(code) >= 200 and int(code) not in (204, 304):
                    self.wfile.write(body)
                self.close_connection = True

        if auth not in AUTH_MODES:
            raise ValueError(f"auth: {auth!r} is not one of {', '.join(AUTH_MODES)}")
        self.store, self.auth = store, auth
        self.verifier = None
        if auth == "verify":
            if not auth_key:
                raise ValueError("auth_key: '' but auth is 'verify': give the auth server's public key "
                                 "(PEM or JWKS file; python -m uam_sim.uss_server keys DIR makes a dev pair), "
                                 "or auth 'off' for a local run")
            audiences = auth_audience.split(",") if auth_audience.strip() else default_audiences(
                store.ctx.uss_base_url)
            self.verifier = TokenVerifier.from_file(auth_key, audiences)
        self._server = PooledWSGIServer(host, int(port), create_app(store, auth, self.verifier, inbox, planning), _Quiet,
                                        workers=workers, max_connections=max_connections, **pool_options)
        self.host, self.port = host, int(self._server.server_port)
        self._thread = threading.Thread(target=self._server.serve_forever, name="uss-http",
                                        daemon=True)

    @property
    def url(self) -> str:
        """The server's base URL as bound (:func:`base_url`)."""
        return base_url(self.host, self.port)

    @property
    def announcement(self) -> str:
        """One line saying how requests are authorised (a warning when auth is off)."""
        if self.auth == "off":
            return (f"WARNING: F3548 USS server on {self.url}: auth is OFF: every caller is served "
                    "without an access token (for local runs only; auth 'verify' checks tokens)")
        return (f"F3548 USS server on {self.url}: bearer tokens verified ({', '.join(ALGORITHMS)}; "
                f"audience {', '.join(self.verifier.audiences)}; {len(self.verifier.keys)} key(s))")

    def start(self) -> "UssServer":
        if self.auth == "off":
            print(f"uss_server: {self.announcement}", file=sys.stderr, flush=True)
        self._thread.start()
        return self

    def stop(self) -> None:
        self._server.shutdown()
        self._server.server_close()
        self._thread.join(timeout=5)


# ---- a client: another USS's intents into a file the planner reads --------------------------

def fetch(base_url: str, ids=(), out=None, token: str = "", timeout_s: float = 10.0) -> dict:
    """GET the details of operational intents ``ids`` (default: every id a uam_fleet server lists
    at /uam_fleet/v1/operational_intents) from the USS at ``base_url``; each answer is checked
    against the F3548 schema. Returns ``{"operational_intents": [...]}`` (written to ``out`` if
    given), which ``--constraints FILE`` reads (docs/f3548.md, "In"). Raises ValueError naming the
    id and the HTTP status of a failed request."""
    import requests

    from uam_planner.f3548_schema import errors

    headers = {"Authorization": f"Bearer {token}"} if token else {}
    base = base_url.rstrip("/")
    if not ids:
        r = requests.get(f"{base}/uam_fleet/v1/operational_intents", headers=headers, timeout=timeout_s)
        if r.status_code != 200:
            raise ValueError(f"{base}: listing the intents: HTTP {r.status_code}: {r.text[:200]}")
        ids = r.json()["ids"]
    docs = []
    for oid in ids:
        r = requests.get(f"{base}/uss/v1/operational_intents/{oid}", headers=headers, timeout=timeout_s)
        if r.status_code != 200:
            raise ValueError(f"operational intent {oid}: HTTP {r.status_code}: {r.text[:200]}")
        errs = errors(r.json(), "GetOperationalIntentDetailsResponse")
        if errs:
            raise ValueError(f"operational intent {oid}: not a valid F3548 answer: {errs[:3]}")
        docs.append(r.json()["operational_intent"])
    result = {"operational_intents": docs}
    if out is not None:
        from pathlib import Path
        Path(out).write_text(json.dumps(result))
    return result


def _cli_keys(args) -> int:
    from .auth import generate_dev_keys

    private, public = generate_dev_keys(args.folder)
    print(f"uss_server keys: private key {private} (signs tokens: keep it), public key {public} "
          f"(the server's auth_key)")
    return 0


def _cli_token(args) -> int:
    from .auth import mint_token

    print(mint_token(args.key, args.audience, args.scope or [SCOPE_INTENTS, SCOPE_CONSTRAINTS],
                     lifetime_s=args.lifetime_s, sub=args.sub))
    return 0


def _cli_fetch(args) -> int:
    token = args.token
    if token.startswith("@"):  # @FILE: the token from a file (keeps it out of the process list)
        from pathlib import Path
        token = Path(token[1:]).read_text().strip()
    got = fetch(args.base_url, args.ids, args.out, token)
    print(f"uss_server fetch: {len(got['operational_intents'])} operational intents in {args.out}")
    return 0


def main(argv=None) -> int:
    import argparse

    ap = argparse.ArgumentParser(prog="python -m uam_sim.uss_server",
                                 description="fetch: another USS's operational intents into a JSON file for "
                                             "--constraints FILE; keys, token: a development auth server "
                                             "(a key pair and access tokens signed with it)")
    sub = ap.add_subparsers(dest="cmd", required=True)
    f = sub.add_parser("fetch", help="GET a USS's operational intents into a file")
    f.add_argument("base_url")
    f.add_argument("ids", nargs="*", help="entity ids (default: all a uam_fleet server lists)")
    f.add_argument("--out", required=True)
    f.add_argument("--token", default="", help="bearer access token (or @FILE: read from FILE)")
    k = sub.add_parser("keys", help="make a development key pair (kept if already there)")
    k.add_argument("folder", help="folder for private.pem and public.pem")
    t = sub.add_parser("token", help="print an RS256 access token signed with a private key")
    t.add_argument("--key", required=True, help="PEM private key (e.g. DIR/private.pem of `keys DIR`)")
    t.add_argument("--audience", default="localhost", help="aud: the host the client calls (default localhost)")
    t.add_argument("--scope", action="append", help=f"a scope (repeatable; default {SCOPE_INTENTS} and "
                                                    f"{SCOPE_CONSTRAINTS})")
    t.add_argument("--lifetime-s", type=float, default=3600.0, help="seconds until exp (default 3600)")
    t.add_argument("--sub", default=DEV_SUBJECT, help="sub: the client's name")
    args = ap.parse_args(argv)
    try:
        return {"fetch": _cli_fetch, "keys": _cli_keys, "token": _cli_token}[args.cmd](args)
    except (ValueError, OSError) as exc:
        print(f"uss_server {args.cmd}: {exc}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    raise SystemExit(main())
