"""Access tokens at the F3548 USS-USS server, attacked as a client would: each forged, unsigned,
expired or misdirected token carrying the right scope is refused with 401 and an F3548
ErrorResponse; a valid token without the endpoint's scope gets 403; a valid one 200. Auth off is
announced when the server starts; a bad key setting stops the server from starting."""

import base64
import hashlib
import hmac
import json
import time

import numpy as np
import pytest
import requests
from joserfc import jwk, jwt

from uam_planner.f3548 import IntentContext, VolumeSpec
from uam_planner.f3548_schema import errors
from uam_planner.planning import Flight
from uam_planner.trajectory import Trajectory
from uam_sim.f3548.auth import generate_dev_keys, mint_token
from uam_sim.f3548.uss_server import SCOPE_CONSTRAINTS, SCOPE_INTENTS, IntentStore, UssServer, main

ORIGIN = (1.29, 103.85, 0.0)
BOTH = [SCOPE_INTENTS, SCOPE_CONSTRAINTS]


def _b64(doc) -> str:
    return base64.urlsafe_b64encode(json.dumps(doc).encode()).decode().rstrip("=")


def _claims(**over):
    claims = {"iss": "dummyoauth", "sub": "uss2", "aud": "localhost", "scope": " ".join(BOTH),
              "exp": int(time.time()) + 600}
    claims.update(over)
    return {k: v for k, v in claims.items() if v is not None}


def _store():
    store = IntentStore(IntentContext(ORIGIN, VolumeSpec.for_separation(100.0)))
    traj = Trajectory(np.array([30.0, 50.0]), np.array([[0.0, 0, 120], [200.0, 0, 120]]))
    oid = store.put_flight(Flight("r1", "A", "B", ("A", "B"), traj, 30.0, 50.0, 200.0, 1.0, 0, "mwis",
                                  "greedy", 0, operator_id="op"))
    return store, oid


@pytest.fixture(scope="module")
def keys(tmp_path_factory):
    """The auth server's key pair (private.pem, public.pem) and an attacker's."""
    return (generate_dev_keys(tmp_path_factory.mktemp("auth-server")),
            generate_dev_keys(tmp_path_factory.mktemp("attacker")))


@pytest.fixture(scope="module")
def served(keys):
    store, oid = _store()
    srv = UssServer(store, port=0, auth_key=str(keys[0][1])).start()
    yield srv, f"/uss/v1/operational_intents/{oid}"
    srv.stop()


def _signed(private_pem, claims, alg="RS256"):
    key = jwk.import_key(private_pem.read_bytes(), "RSA")
    return jwt.encode({"alg": alg, "typ": "JWT"}, claims, key, algorithms=[alg])


def _ask(srv, path, token):
    headers = {"Authorization": f"Bearer {token}"} if token is not None else {}
    return requests.get(srv.url + path, headers=headers, timeout=10)


def _refused(r, status, *words):
    assert r.status_code == status, (r.status_code, r.text[:300])
    assert errors(r.json(), "ErrorResponse") == [] and set(r.json()) == {"message"}
    for w in words:
        assert w in r.json()["message"], (w, r.json()["message"])
    challenge = r.headers["WWW-Authenticate"]
    assert challenge.startswith('Bearer realm="')
    return challenge


def test_a_valid_token_is_served(served, keys):
    srv, path = served
    token = mint_token(keys[0][0], "localhost", BOTH)
    assert _ask(srv, path, token).status_code == 200
    # InterUSS's clients ask for the host they call as the audience: 127.0.0.1 here too
    assert _ask(srv, path, mint_token(keys[0][0], "127.0.0.1", [SCOPE_INTENTS])).status_code == 200
    assert _ask(srv, path, _signed(keys[0][0], _claims(aud=["other", "localhost"]))).status_code == 200
    r = _ask(srv, "/uam_fleet/v1/operational_intents", token)
    assert r.status_code == 200 and len(r.json()["ids"]) == 1


def test_no_token_is_401_with_a_bare_challenge(served):
    srv, path = served
    challenge = _refused(_ask(srv, path, None), 401, "bearer access token is required")
    assert "error=" not in challenge  # RFC 6750 3.1: no error code when no credentials were sent
    challenge = _refused(requests.get(srv.url + path, headers={"Authorization": "Basic dXNzOnB3"}, timeout=10),
                         401, "'Basic' is not a bearer access token")
    assert "error=" not in challenge
    _refused(_ask(srv, "/uam_fleet/v1/operational_intents", None), 401)  # the listing too


def test_an_unsigned_token_alg_none_is_401(served):
    srv, path = served
    for alg in ("none", "None", "NONE"):
        unsigned = f"{_b64({'alg': alg, 'typ': 'JWT'})}.{_b64(_claims())}."
        assert 'error="invalid_token"' in _refused(_ask(srv, path, unsigned), 401, f"alg '{alg}' is not accepted")


def test_a_bogus_signature_is_401(served, keys):
    srv, path = served
    header = _b64({"alg": "RS256", "typ": "JWT"})
    bogus = f"{header}.{_b64(_claims())}.{base64.urlsafe_b64encode(b'x' * 256).decode().rstrip('=')}"
    _refused(_ask(srv, path, bogus), 401, "signature does not verify")
    # a valid token's signature over other claims (scope widened after signing)
    good = mint_token(keys[0][0], "localhost", [SCOPE_CONSTRAINTS]).split(".")
    _refused(_ask(srv, path, f"{good[0]}.{_b64(_claims())}.{good[2]}"), 401, "signature does not verify")
    _refused(_ask(srv, path, "abc.def"), 401, "not a signed JWT")


def test_a_token_signed_by_another_key_is_401(served, keys):
    srv, path = served
    _refused(_ask(srv, path, mint_token(keys[1][0], "localhost", BOTH)), 401, "signature does not verify")


def test_hs256_with_the_public_key_as_secret_is_401(served, keys):
    """Key confusion: an HMAC over the token keyed with the server's (public) PEM."""
    srv, path = served
    signing_input = f"{_b64({'alg': 'HS256', 'typ': 'JWT'})}.{_b64(_claims())}"
    mac = hmac.new(keys[0][1].read_bytes(), signing_input.encode(), hashlib.sha256).digest()
    forged = f"{signing_input}.{base64.urlsafe_b64encode(mac).decode().rstrip('=')}"
    _refused(_ask(srv, path, forged), 401, "alg 'HS256' is not accepted")


def test_an_expired_token_is_401(served, keys):
    srv, path = served
    expired = mint_token(keys[0][0], "localhost", BOTH, lifetime_s=60, now_s=time.time() - 3600)
    assert 'error="invalid_token"' in _refused(_ask(srv, path, expired), 401, "expired")
    _refused(_ask(srv, path, _signed(keys[0][0], _claims(exp=None))), 401, "no exp claim")
    _refused(_ask(srv, path, _signed(keys[0][0], _claims(nbf=int(time.time()) + 600))), 401, "not valid for")


def test_a_token_for_another_audience_is_401(served, keys):
    srv, path = served
    _refused(_ask(srv, path, mint_token(keys[0][0], "uss9.example.com", BOTH)), 401,
             "aud 'uss9.example.com' is not this USS", "localhost")
    _refused(_ask(srv, path, _signed(keys[0][0], _claims(aud=None))), 401, "no aud claim")


def test_a_token_without_the_endpoints_scope_is_403(served, keys):
    srv, path = served
    r = _ask(srv, path, mint_token(keys[0][0], "localhost", [SCOPE_CONSTRAINTS]))
    challenge = _refused(r, 403, SCOPE_INTENTS, SCOPE_CONSTRAINTS)
    assert 'error="insufficient_scope"' in challenge and f'scope="{SCOPE_INTENTS}"' in challenge
    _refused(_ask(srv, path, _signed(keys[0][0], _claims(scope=None))), 403, SCOPE_INTENTS)


def test_es256_tokens_against_a_jwks(tmp_path):
    """A JWKS of two keys (RSA and EC P-256), a token naming its key by kid."""
    ec = jwk.ECKey.generate_key("P-256", parameters={"kid": "ec-1"})
    rsa = jwk.RSAKey.generate_key(2048, parameters={"kid": "rsa-1"})
    jwks = tmp_path / "jwks.json"
    jwks.write_text(json.dumps({"keys": [ec.as_dict(private=False), rsa.as_dict(private=False)]}))
    store, oid = _store()
    srv = UssServer(store, port=0, auth_key=str(jwks), auth_audience="uss1.example.com").start()
    try:
        path = f"/uss/v1/operational_intents/{oid}"
        token = jwt.encode({"alg": "ES256", "kid": "ec-1"}, _claims(aud="uss1.example.com"), ec,
                           algorithms=["ES256"])
        assert _ask(srv, path, token).status_code == 200
        no_kid = jwt.encode({"alg": "RS256"}, _claims(aud="uss1.example.com"), rsa, algorithms=["RS256"])
        assert _ask(srv, path, no_kid).status_code == 200
        unknown = jwt.encode({"alg": "ES256", "kid": "ec-9"}, _claims(aud="uss1.example.com"), ec,
                             algorithms=["ES256"])
        _refused(_ask(srv, path, unknown), 401, "kid 'ec-9'")
        _refused(_ask(srv, path, mint_token_rsa(rsa, "localhost")), 401, "aud 'localhost'")
    finally:
        srv.stop()


def mint_token_rsa(key, aud):
    return jwt.encode({"alg": "RS256"}, _claims(aud=aud), key, algorithms=["RS256"])


def test_auth_off_is_announced_at_start(capfd):
    store, oid = _store()
    srv = UssServer(store, port=0, auth="off").start()
    try:
        err = capfd.readouterr().err
        assert "auth is OFF" in err and srv.url in err and "without an access token" in err
        assert srv.auth == "off" and "auth is OFF" in srv.announcement
        assert _ask(srv, f"/uss/v1/operational_intents/{oid}", None).status_code == 200
    finally:
        srv.stop()


@pytest.mark.filterwarnings("ignore::joserfc.errors.SecurityWarning")  # the small keys made on purpose
def test_bad_auth_settings_stop_the_server_from_starting(keys, tmp_path):
    store, _ = _store()
    with pytest.raises(ValueError, match=r"auth_key: '' but auth is 'verify'"):
        UssServer(store, port=0)
    with pytest.raises(ValueError, match=r"auth_key: .*private.pem.*holds a private key"):
        UssServer(store, port=0, auth_key=str(keys[0][0]))
    with pytest.raises(ValueError, match=r"auth_key: .*nope.pem.*cannot be read"):
        UssServer(store, port=0, auth_key=str(tmp_path / "nope.pem"))
    (tmp_path / "junk.pem").write_text("not a key")
    with pytest.raises(ValueError, match=r"auth_key: .*junk.pem.*not a PEM public key"):
        UssServer(store, port=0, auth_key=str(tmp_path / "junk.pem"))
    small = jwk.RSAKey.generate_key(1024, private=True)
    (tmp_path / "small.pem").write_bytes(small.as_pem(private=False))
    with pytest.raises(ValueError, match=r"an RSA key of 1024 bits"):
        UssServer(store, port=0, auth_key=str(tmp_path / "small.pem"))
    (tmp_path / "oct.json").write_text(json.dumps({"kty": "oct", "k": "c2VjcmV0"}))
    with pytest.raises(ValueError, match=r"a oct key; only RSA"):
        UssServer(store, port=0, auth_key=str(tmp_path / "oct.json"))
    # the unverified 'scope' mode is gone
    with pytest.raises(ValueError, match=r"auth: 'scope' is not one of verify, off"):
        UssServer(store, port=0, auth="scope")


def test_the_dev_auth_server_commands(tmp_path, capsys):
    """`keys DIR` then `token --key DIR/private.pem`: a token the server takes."""
    assert main(["keys", str(tmp_path / "auth")]) == 0
    private = tmp_path / "auth" / "private.pem"
    assert private.stat().st_mode & 0o077 == 0  # the owner's only
    assert main(["keys", str(tmp_path / "auth")]) == 0  # kept
    capsys.readouterr()
    assert main(["token", "--key", str(private), "--scope", SCOPE_INTENTS]) == 0
    token = capsys.readouterr().out.strip()
    store, oid = _store()
    srv = UssServer(store, port=0, auth_key=str(tmp_path / "auth" / "public.pem")).start()
    try:
        assert _ask(srv, f"/uss/v1/operational_intents/{oid}", token).status_code == 200
        assert _ask(srv, "/uam_fleet/v1/constraints", token).status_code == 403
    finally:
        srv.stop()
    assert main(["token", "--key", str(tmp_path / "auth" / "public.pem")]) == 2
    assert "is a public key" in capsys.readouterr().err
