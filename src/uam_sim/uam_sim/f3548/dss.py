"""A client of an F3548-21 DSS (Discovery and Synchronization Service) for this USS
(docs/f3548.md, "A DSS client"): the operations a USS needs to publish and discover operational
intents.

- operational intent references: create (``PUT .../{entityid}``), update
  (``PUT .../{entityid}/{ovn}``), delete (``DELETE .../{entityid}/{ovn}``), get, and query by a 4D
  area (``POST .../query``);
- subscriptions: create, update (``.../{subscriptionid}/{version}``), delete;
- constraint references: query by area (and create / delete, for a constraint-managing USS).

Paths and verbs come from ``uas_standards.astm.f3548.v21.api.OPERATIONS``; request bodies are
built as, and every answer parsed into, that module's types (``ImplicitDict.parse``), so an answer
that is not the type the standard gives for its status raises :class:`DssError` naming the
operation and status. The DSS issues the OVNs: ``put_operational_intent_reference`` returns the
``ChangeOperationalIntentReferenceResponse`` whose reference carries the new OVN, which the next
update or delete of that reference must name. A 409 of a create or update carries an
``AirspaceConflictResponse`` (the references whose OVNs the key lacked) as
:attr:`DssError.conflict`.

Auth: each call takes a bearer access token from a *token source* (``token(audience, scopes)``,
as InterUSS's auth adapters): :class:`StaticToken` (one token with every scope needed) or
:class:`DevTokens` (minted with a development key, :func:`uam_sim.f3548.auth.mint_token`). The
scope of each operation is :data:`SCOPES` (utm.yaml's security requirements; the first is the one
asked for). Synchronous, over ``requests``; no ROS.
"""

from __future__ import annotations

import json
import time
from urllib.parse import urlsplit

from implicitdict import ImplicitDict
from uas_standards.astm.f3548.v21 import api
from uas_standards.astm.f3548.v21.constants import Scope

Op = api.OperationID

#: the scopes a token may hold for each DSS operation (utm.yaml's security requirements, any one
#: will do); a client asks for the first
SCOPES = {
    Op.QueryOperationalIntentReferences: (Scope.StrategicCoordination.value,
                                          Scope.ConformanceMonitoringForSituationalAwareness.value),
    Op.GetOperationalIntentReference: (Scope.StrategicCoordination.value,
                                       Scope.ConformanceMonitoringForSituationalAwareness.value),
    Op.CreateOperationalIntentReference: (Scope.StrategicCoordination.value,),
    Op.UpdateOperationalIntentReference: (Scope.StrategicCoordination.value,),
    Op.DeleteOperationalIntentReference: (Scope.StrategicCoordination.value,),
    Op.QueryConstraintReferences: (Scope.ConstraintProcessing.value, Scope.ConstraintManagement.value),
    Op.GetConstraintReference: (Scope.ConstraintProcessing.value, Scope.ConstraintManagement.value),
    Op.CreateConstraintReference: (Scope.ConstraintManagement.value,),
    Op.UpdateConstraintReference: (Scope.ConstraintManagement.value,),
    Op.DeleteConstraintReference: (Scope.ConstraintManagement.value,),
    Op.QuerySubscriptions: (Scope.StrategicCoordination.value, Scope.ConstraintProcessing.value),
    Op.GetSubscription: (Scope.StrategicCoordination.value, Scope.ConstraintProcessing.value),
    Op.CreateSubscription: (Scope.StrategicCoordination.value, Scope.ConstraintProcessing.value),
    Op.UpdateSubscription: (Scope.StrategicCoordination.value, Scope.ConstraintProcessing.value),
    Op.DeleteSubscription: (Scope.StrategicCoordination.value, Scope.ConstraintProcessing.value),
}
#: the DSS operations this module speaks
DSS_OPERATIONS = tuple(SCOPES)


class DssError(Exception):
    """A DSS call that did not succeed: ``operation`` (its id), ``status`` (the HTTP status, 0 for
    no answer), ``message`` (the DSS's ErrorResponse message, or what was wrong with its answer),
    ``conflict`` (the parsed ``AirspaceConflictResponse`` of a 409 to a reference change, else
    None)."""

    def __init__(self, operation: str, status: int, message: str, conflict=None):
        super().__init__(f"DSS {operation}: HTTP {status}: {message}")
        self.operation, self.status, self.message, self.conflict = operation, status, message, conflict


class StaticToken:
    """One bearer token for every call (it must hold every scope the calls need)."""

    def __init__(self, token: str):
        if not token or any(c.isspace() for c in token):
            raise ValueError(f"token: {token[:20]!r} is not a bearer token (empty or with white space)")
        self._token = token

    def token(self, audience: str, scopes) -> str:
        return self._token


class DevTokens:
    """Tokens minted with a development private key (``python -m uam_sim.uss_server keys DIR``),
    one per (audience, scopes), renewed a minute before they expire. ``sub`` names this USS to the
    DSS (a reference's ``manager``)."""

    def __init__(self, private_key, sub: str = "uam_fleet", lifetime_s: float = 3600.0):
        self.private_key, self.sub, self.lifetime_s = private_key, sub, float(lifetime_s)
        self._cache: dict = {}

    def token(self, audience: str, scopes) -> str:
        from .auth import mint_token
        key = (audience, tuple(scopes))
        tok, exp = self._cache.get(key, ("", 0.0))
        if time.time() > exp - 60.0:
            tok = mint_token(self.private_key, audience, list(scopes), lifetime_s=self.lifetime_s, sub=self.sub)
            self._cache[key] = (tok, time.time() + self.lifetime_s)
        return tok


class AuthServerTokens:
    """Tokens asked of an auth server's token endpoint the way InterUSS's dummy OAuth server
    takes it (``GET {token_endpoint}?grant_type=client_credentials&scope=...&intended_audience=...
    &issuer=dummy&sub=...``, answered ``{"access_token": ...}``; monitorlib's ``DummyOAuth``
    adapter asks the same), one per (audience, scopes), asked again a minute before its ``exp``.
    ``sub`` names this USS (a reference's ``manager`` at the DSS)."""

    def __init__(self, token_endpoint: str, sub: str = "uam-fleet", timeout_s: float = 10.0, session=None):
        import requests

        parts = urlsplit(token_endpoint)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"token_endpoint: {token_endpoint!r} is not an http(s) URL with a host")
        if not sub:
            raise ValueError("sub: empty (the identity the tokens are asked for)")
        self.token_endpoint, self.sub, self.timeout_s = token_endpoint, str(sub), float(timeout_s)
        self._session = session or requests.Session()
        self._cache: dict = {}

    def token(self, audience: str, scopes) -> str:
        from urllib.parse import urlencode

        key = (audience, tuple(scopes))
        tok, exp = self._cache.get(key, ("", 0.0))
        if time.time() <= exp - 60.0:
            return tok
        query = urlencode({"grant_type": "client_credentials", "scope": " ".join(scopes),
                           "intended_audience": audience, "issuer": "dummy", "sub": self.sub})
        url = f"{self.token_endpoint}?{query}"
        r = self._session.request("GET", url, timeout=self.timeout_s)
        if r.status_code != 200:
            raise ValueError(f"token_endpoint: GET {self.token_endpoint}: HTTP {r.status_code}: {r.text[:200]}")
        tok = str(r.json().get("access_token") or "")
        if not tok:
            raise ValueError(f"token_endpoint: {self.token_endpoint}: no access_token in the answer")
        self._cache[key] = (tok, _expiry(tok))
        return tok


def _expiry(token: str) -> float:
    """The ``exp`` claim of a JWT (read, not verified: the client only needs to know when to ask
    again), or 0 (ask every time) when it has none."""
    import base64

    try:
        payload = token.split(".")[1]
        claims = json.loads(base64.urlsafe_b64decode(payload + "=" * (-len(payload) % 4)))
        return float(claims.get("exp", 0.0))
    except (IndexError, ValueError, TypeError):
        return 0.0


def token_source(token_file: str = "", dev_key: str = "", auth_url: str = "", sub: str = "uam-fleet"):
    """The token source of exactly one of: ``token_file`` (a file holding one bearer token with
    every scope needed: :class:`StaticToken`), ``dev_key`` (a development private key PEM:
    :class:`DevTokens` with ``sub``), ``auth_url`` (an auth server's token endpoint:
    :class:`AuthServerTokens` with ``sub``). ValueError naming the parameters otherwise."""
    given = {k: v for k, v in (("dss_token_file", token_file), ("dss_dev_key", dev_key),
                               ("dss_auth_url", auth_url)) if v}
    if len(given) != 1:
        raise ValueError(f"dss_token_file, dss_dev_key, dss_auth_url: {len(given)} given "
                         f"({', '.join(given) or 'none'}); a DSS needs exactly one way to get tokens")
    from pathlib import Path
    path = token_file or dev_key
    if path and not Path(path).is_file():
        raise ValueError(f"{next(iter(given))}: {path!r} is not a readable file")
    if token_file:
        return StaticToken(Path(token_file).read_text().strip())
    if dev_key:
        tokens = DevTokens(dev_key, sub=sub)
        tokens.token("localhost", ["utm.strategic_coordination"])   # a public key, or no key: refused now
        return tokens
    return AuthServerTokens(auth_url, sub=sub)


def _as_json(obj) -> dict:
    """An ImplicitDict (or plain dict) as JSON-ready data (enums and datetimes as strings)."""
    return json.loads(json.dumps(obj, default=str))


class DssClient:
    """The DSS at ``base_url`` (the URL its ``/dss/v1/...`` paths are under, e.g.
    ``https://dss.example.com``), with tokens from ``tokens`` (module docstring) for the audience
    ``audience`` (default: the host of ``base_url``, as InterUSS's clients ask). ``timeout_s``
    bounds each request."""

    def __init__(self, base_url: str, tokens, audience: str = "", timeout_s: float = 10.0, session=None):
        import requests

        parts = urlsplit(base_url)
        if parts.scheme not in ("http", "https") or not parts.hostname:
            raise ValueError(f"base_url: {base_url!r} is not an http(s) URL with a host")
        self.base_url = base_url.rstrip("/")
        self.audience = audience or parts.hostname
        self.tokens, self.timeout_s = tokens, float(timeout_s)
        self._session = session or requests.Session()

    # ---- the one call ----------------------------------------------------------------------
    def call(self, op: Op, body=None, **path):
        """Perform ``op`` with the path parameters ``path`` and the request ``body`` (an instance
        of the operation's request type); return the answer parsed as the type the operation
        gives for its status. Raises :class:`DssError` for a status other than the operation's
        success (200 / 201) or an answer that is not its type."""
        import requests

        spec = api.OPERATIONS[op]
        if (body is None) != (spec.request_body_type is None):
            raise ValueError(f"body: {op.value} takes {spec.request_body_type.__name__ if spec.request_body_type else 'none'}")
        url = self.base_url + spec.path.format(**path)
        headers = {"Authorization": f"Bearer {self.tokens.token(self.audience, SCOPES[op][:1])}"}
        try:
            r = self._session.request(spec.verb, url, json=None if body is None else _as_json(body),
                                      headers=headers, timeout=self.timeout_s)
        except requests.RequestException as exc:
            raise DssError(op.value, 0, f"{spec.verb} {url}: {exc}") from None
        kind = spec.response_body_type.get(r.status_code)
        try:
            doc = r.json() if r.content else {}
        except ValueError:
            raise DssError(op.value, r.status_code, f"the answer is not JSON: {r.text[:200]!r}") from None
        if r.status_code not in (200, 201):
            conflict = None
            if r.status_code == 409 and kind is api.AirspaceConflictResponse:
                conflict = ImplicitDict.parse(doc, api.AirspaceConflictResponse)
            message = doc.get("message", "") if isinstance(doc, dict) else ""
            raise DssError(op.value, r.status_code, message or r.text[:200], conflict)
        try:
            return ImplicitDict.parse(doc, kind)
        except (ValueError, KeyError, TypeError) as exc:
            raise DssError(op.value, r.status_code, f"the answer is not a {kind.__name__}: {str(exc)[:300]}") from None

    # ---- operational intent references -----------------------------------------------------
    def put_operational_intent_reference(self, entity_id: str, extents, state: str, uss_base_url: str,
                                         key=(), ovn: str | None = None, subscription_id: str | None = None,
                                         notify_for_constraints: bool = False):
        """Create (``ovn`` None) or update (``ovn``: the reference's current OVN) the reference
        ``entity_id`` over ``extents`` (Volume4Ds, each with its times) in ``state``; ``key``: the
        OVNs of every reference the USS knows to intersect it. With ``subscription_id`` the
        reference is tied to that subscription, without it the DSS makes an implicit one for
        ``uss_base_url``. Returns the ``ChangeOperationalIntentReferenceResponse`` (the new OVN
        in ``.operational_intent_reference.ovn``; ``.subscribers`` to notify)."""
        params = api.PutOperationalIntentReferenceParameters(
            extents=[ImplicitDict.parse(_as_json(v), api.Volume4D) for v in extents],
            key=list(key), state=api.OperationalIntentState(state), uss_base_url=uss_base_url)
        if subscription_id:
            params.subscription_id = subscription_id
        else:
            params.new_subscription = api.ImplicitSubscriptionParameters(
                uss_base_url=uss_base_url, notify_for_constraints=notify_for_constraints)
        if ovn is None:
            return self.call(Op.CreateOperationalIntentReference, params, entityid=entity_id)
        return self.call(Op.UpdateOperationalIntentReference, params, entityid=entity_id, ovn=ovn)

    def delete_operational_intent_reference(self, entity_id: str, ovn: str):
        """Delete the reference whose current OVN is ``ovn``; returns the
        ``ChangeOperationalIntentReferenceResponse`` (its subscribers to notify)."""
        return self.call(Op.DeleteOperationalIntentReference, entityid=entity_id, ovn=ovn)

    def get_operational_intent_reference(self, entity_id: str):
        return self.call(Op.GetOperationalIntentReference, entityid=entity_id).operational_intent_reference

    def query_operational_intent_references(self, area) -> list:
        """The references intersecting the Volume4D ``area`` (in space and time)."""
        body = api.QueryOperationalIntentReferenceParameters(
            area_of_interest=ImplicitDict.parse(_as_json(area), api.Volume4D))
        return list(self.call(Op.QueryOperationalIntentReferences, body).operational_intent_references)

    # ---- subscriptions ---------------------------------------------------------------------
    def put_subscription(self, subscription_id: str, extents, uss_base_url: str, version: str | None = None,
                         notify_for_operational_intents: bool = True, notify_for_constraints: bool = False):
        """Create (``version`` None) or update (its current ``version``) the subscription over the
        Volume4D ``extents``; returns the ``PutSubscriptionResponse`` (the subscription with its
        version, and the references already in its area)."""
        body = api.PutSubscriptionParameters(
            extents=ImplicitDict.parse(_as_json(extents), api.Volume4D), uss_base_url=uss_base_url,
            notify_for_operational_intents=notify_for_operational_intents,
            notify_for_constraints=notify_for_constraints)
        if version is None:
            return self.call(Op.CreateSubscription, body, subscriptionid=subscription_id)
        return self.call(Op.UpdateSubscription, body, subscriptionid=subscription_id, version=version)

    def delete_subscription(self, subscription_id: str, version: str):
        """Delete the subscription at its current ``version``; returns the deleted ``Subscription``."""
        return self.call(Op.DeleteSubscription, subscriptionid=subscription_id, version=version).subscription

    # ---- constraint references -------------------------------------------------------------
    def query_constraint_references(self, area) -> list:
        """The constraint references intersecting the Volume4D ``area``."""
        body = api.QueryConstraintReferenceParameters(
            area_of_interest=ImplicitDict.parse(_as_json(area), api.Volume4D))
        return list(self.call(Op.QueryConstraintReferences, body).constraint_references)

    def put_constraint_reference(self, entity_id: str, extents, uss_base_url: str, ovn: str | None = None):
        """Create (``ovn`` None) or update a constraint reference (a constraint-managing USS's)."""
        body = api.PutConstraintReferenceParameters(
            extents=[ImplicitDict.parse(_as_json(v), api.Volume4D) for v in extents], uss_base_url=uss_base_url)
        if ovn is None:
            return self.call(Op.CreateConstraintReference, body, entityid=entity_id)
        return self.call(Op.UpdateConstraintReference, body, entityid=entity_id, ovn=ovn)

    def delete_constraint_reference(self, entity_id: str, ovn: str):
        return self.call(Op.DeleteConstraintReference, entityid=entity_id, ovn=ovn)
