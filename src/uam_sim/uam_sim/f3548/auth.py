"""Bearer access tokens of the F3548 USS-USS interface (docs/f3548.md, "Access tokens").

F3548 (and InterUSS's DSS, mock USS and dummy OAuth server) authorise a USS-USS request with an
OAuth 2.0 bearer access token (RFC 6750): a JWT signed by an auth server, RS256 in InterUSS's
deployments, with ``iss``, ``sub``, ``aud`` (the host name the client calls: InterUSS's clients
ask for a token whose audience is the URL's host), ``exp`` and ``scope`` (space-separated). A
USS verifies the signature against the auth server's public key and checks expiry, audience and
the endpoint's scope.

- :class:`TokenVerifier` does that with ``joserfc`` (Authlib's JOSE library, pinned; Authlib's
  own ``authlib.jose`` is deprecated in its favour): the algorithms are pinned to
  :data:`ALGORITHMS` (``alg=none`` and HMAC are refused, so a public key can never be used as a
  shared secret), ``exp`` and ``aud`` are required. A failure raises :class:`AuthError` carrying
  the HTTP status RFC 6750 and F3548 give it: 401 (``invalid_token``: missing, undecodable,
  unsigned, forged, expired, or for another audience) or 403 (``insufficient_scope``).
- :func:`generate_dev_keys` and :func:`mint_token` are the local stand-in for an auth server: a
  key pair in a run's folder and tokens signed with it (``python -m uam_sim.uss_server keys`` /
  ``token``), so that a local run keeps verification on.
"""

from __future__ import annotations

import json
import os
import time
import uuid
from dataclasses import dataclass
from pathlib import Path
from urllib.parse import urlparse

#: signature algorithms accepted (F3548 deployments use RS256; ES256 for EC P-256 keys)
ALGORITHMS = ("RS256", "ES256")
#: the key type each algorithm needs
_KEY_TYPE = {"RS256": "RSA", "ES256": "EC"}
MIN_RSA_BITS = 2048
#: keys read from one JWKS file at most (every key without a matching kid is tried)
MAX_KEYS = 16
#: a bearer token longer than this is refused before it is parsed
MAX_TOKEN_CHARS = 8192
#: the names this project's development auth server signs with
DEV_ISSUER = "uam_fleet-dev-auth"
DEV_SUBJECT = "uam_fleet-dev-client"
DEV_PRIVATE_KEY = "private.pem"
DEV_PUBLIC_KEY = "public.pem"
#: loopback host names: a server on the default http://localhost:<port> accepts either
_LOOPBACK = ("localhost", "127.0.0.1")


class AuthError(Exception):
    """A request refused for its access token: ``status`` 401 or 403, ``error`` the RFC 6750 code
    (``''`` when no bearer token was sent), ``message`` what was wrong, naming the claim and its value."""

    def __init__(self, status: int, error: str, message: str, scope: str = ""):
        super().__init__(message)
        self.status, self.error, self.message, self.scope = status, error, message, scope

    def www_authenticate(self, realm: str) -> str:
        """The ``WWW-Authenticate`` value of the answer (RFC 6750, 3)."""
        parts = [f'Bearer realm="{realm}"']
        if self.error:
            parts.append(f'error="{self.error}"')
            # error_description's characters: RFC 6750's %x20-21 / %x23-5B / %x5D-7E
            text = "".join(ch for ch in self.message if 0x20 <= ord(ch) <= 0x7E and ch not in '"\\')
            parts.append(f'error_description="{text[:200]}"')
        if self.scope:
            parts.append(f'scope="{self.scope}"')
        return ", ".join(parts)


@dataclass(frozen=True)
class Grant:
    """What a verified token says: who (``sub``), issued by whom (``iss``), and its ``scopes``."""
    sub: str
    iss: str
    scopes: tuple


def default_audiences(base_url: str) -> tuple:
    """The audiences a server at ``base_url`` accepts when none is configured: the URL's host
    (as InterUSS's clients ask); for a loopback host both ``localhost`` and ``127.0.0.1``."""
    host = (urlparse(base_url).hostname or "").lower()
    if not host:
        raise ValueError(f"uss_base_url: {base_url!r} has no host to take the token audience from")
    return _LOOPBACK if host in _LOOPBACK else (host,)


def _check_public_key(key, where: str):
    """Refuse private keys (the server needs only the public half), short RSA and non-P-256 EC."""
    from cryptography.hazmat.primitives.asymmetric import ec, rsa

    raw = key.raw_value
    if key.key_type not in ("RSA", "EC"):
        raise ValueError(f"{where}: a {key.key_type} key; only RSA (RS256) and EC P-256 (ES256) are accepted")
    if key.is_private:
        raise ValueError(f"{where}: holds a private key; give the auth server's public key only")
    if isinstance(raw, rsa.RSAPublicKey):
        if raw.key_size < MIN_RSA_BITS:
            raise ValueError(f"{where}: an RSA key of {raw.key_size} bits, fewer than {MIN_RSA_BITS}")
    elif not (isinstance(raw, ec.EllipticCurvePublicKey) and raw.curve.name == "secp256r1"):
        raise ValueError(f"{where}: a {key.key_type} key; only RSA (RS256) and EC P-256 (ES256) are accepted")
    return key


def load_keys(path) -> list:
    """The public keys of ``path``: a PEM public key, a JWK (JSON) or a JWKS (``{"keys": [...]}``).
    Raises ValueError naming the file and what is wrong with it."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import ec, rsa
    from joserfc import jwk
    from joserfc.errors import JoseError

    where = f"auth_key: {str(path)!r}"
    try:
        data = Path(path).read_bytes()
    except OSError as exc:
        raise ValueError(f"{where}: cannot be read ({exc.strerror})") from None
    if data.lstrip().startswith(b"{"):
        try:
            doc = json.loads(data)
            docs = doc["keys"] if isinstance(doc, dict) and "keys" in doc else [doc]
            if not isinstance(docs, list) or not docs:
                raise ValueError("no keys")
            if len(docs) > MAX_KEYS:
                raise ValueError(f"{len(docs)} keys, more than {MAX_KEYS}")
            keys = [jwk.import_key(d) for d in docs]
        except (ValueError, KeyError, TypeError, JoseError) as exc:
            raise ValueError(f"{where}: not a JWK or JWKS ({exc})") from None
    else:
        if b"PRIVATE KEY" in data:
            raise ValueError(f"{where}: holds a private key; give the auth server's public key only")
        try:
            raw = serialization.load_pem_public_key(data)
        except ValueError as exc:
            raise ValueError(f"{where}: not a PEM public key ({exc})") from None
        kind = "RSA" if isinstance(raw, rsa.RSAPublicKey) else "EC" if isinstance(raw, ec.EllipticCurvePublicKey) else ""
        if not kind:
            raise ValueError(f"{where}: a {type(raw).__name__}; only RSA and EC P-256 keys are accepted")
        keys = [jwk.import_key(data, kind)]
    return [_check_public_key(k, where) for k in keys]


class TokenVerifier:
    """Checks the ``Authorization`` header of a request against the auth server's ``keys``
    (:func:`load_keys`), the accepted ``audiences`` and the endpoint's scope.

    ``verify(header, scope)`` returns a :class:`Grant` or raises :class:`AuthError`. ``now_s``:
    the clock (a callable returning seconds since 1970; default ``time.time``). No leeway on
    ``exp`` (as InterUSS's mock USS): a client refreshes its token before it expires. Audiences
    are compared without case, as the host names they are.
    """

    def __init__(self, keys, audiences, now_s=None):
        if not keys:
            raise ValueError("auth_key: no public key to verify tokens with")
        audiences = tuple(a.strip().lower() for a in audiences if a.strip())
        if not audiences:
            raise ValueError("auth_audience: no audience to accept (a token's aud must name this USS)")
        self.keys, self.audiences = list(keys), audiences
        self._now_s = now_s or time.time

    @classmethod
    def from_file(cls, path, audiences) -> "TokenVerifier":
        return cls(load_keys(path), audiences)

    def verify(self, header: str | None, scope) -> Grant:
        """The grant of a valid token holding ``scope`` (a scope, or a tuple of scopes of which
        any one will do, as utm.yaml lists alternatives); raises AuthError (401 / 403)."""
        claims = self._verified_claims(self._bearer(header))
        scopes = claims.get("scope", "")
        scopes = tuple(scopes.split()) if isinstance(scopes, str) else ()
        wanted = (scope,) if isinstance(scope, str) else tuple(scope)
        if not any(w in scopes for w in wanted):
            raise AuthError(403, "insufficient_scope",
                            f"Authorization: the token's scope {' '.join(scopes)!r} does not include "
                            f"{' or '.join(repr(w) for w in wanted)}", scope=" ".join(wanted))
        return Grant(str(claims.get("sub", "")), str(claims.get("iss", "")), scopes)

    @staticmethod
    def _bearer(header: str | None) -> str:
        if not header:
            raise AuthError(401, "", "Authorization: a bearer access token is required (RFC 6750)")
        kind, _, token = header.strip().partition(" ")
        if kind.lower() != "bearer" or not token.strip():
            # other credentials (Basic, an empty Bearer) are no bearer token: the bare challenge
            raise AuthError(401, "", f"Authorization: {kind[:20]!r} is not a bearer access token (RFC 6750)")
        token = token.strip()
        if len(token) > MAX_TOKEN_CHARS:
            raise AuthError(401, "invalid_token",
                            f"Authorization: a token of {len(token)} characters, more than {MAX_TOKEN_CHARS}")
        return token

    def _candidate_keys(self, alg: str, kid) -> list:
        keys = [k for k in self.keys if k.key_type == _KEY_TYPE[alg]]
        if kid is not None:
            keys = [k for k in keys if k.kid == kid]
            if not keys:
                raise AuthError(401, "invalid_token", f"Authorization: no {alg} key of kid {str(kid)[:64]!r} "
                                                      "is configured")
        if not keys:
            raise AuthError(401, "invalid_token", f"Authorization: the token's alg {alg!r} needs a "
                                                  f"{_KEY_TYPE[alg]} key; none is configured")
        return keys

    def _verified_claims(self, token: str) -> dict:
        from joserfc import jws, jwt
        from joserfc.errors import BadSignatureError, JoseError

        try:
            header = jws.extract_compact(token.encode()).headers()
        except (JoseError, ValueError, UnicodeError) as exc:
            raise AuthError(401, "invalid_token", f"Authorization: the token is not a signed JWT "
                                                  f"(JWS compact: {str(exc)[:100]})") from None
        alg = header.get("alg")
        if alg not in ALGORITHMS:
            raise AuthError(401, "invalid_token", f"Authorization: the token's alg {str(alg)[:20]!r} is not "
                                                  f"accepted (only {', '.join(ALGORITHMS)})")
        claims = None
        for key in self._candidate_keys(alg, header.get("kid")):
            try:
                claims = jwt.decode(token, key, algorithms=[alg]).claims
                break
            except BadSignatureError:
                continue
            except (JoseError, ValueError) as exc:
                raise AuthError(401, "invalid_token", f"Authorization: the token does not decode "
                                                      f"({str(exc)[:100]})") from None
        if claims is None:
            raise AuthError(401, "invalid_token", "Authorization: the token's signature does not verify "
                                                  "against the configured key(s)")
        self._check_time(claims)
        self._check_audience(claims.get("aud"))
        return claims

    def _check_time(self, claims: dict) -> None:
        now = self._now_s()
        exp = claims.get("exp")
        if exp is None:
            raise AuthError(401, "invalid_token", "Authorization: the token has no exp claim (an expiry is required)")
        if isinstance(exp, bool) or not isinstance(exp, (int, float)):
            raise AuthError(401, "invalid_token", f"Authorization: the token's exp {str(exp)[:40]!r} is not a "
                                                  "NumericDate (an expiry is required)")
        if exp <= now:
            raise AuthError(401, "invalid_token", f"Authorization: the token expired {now - exp:.0f} s ago "
                                                  f"(exp {exp})")
        nbf = claims.get("nbf")
        if isinstance(nbf, (int, float)) and not isinstance(nbf, bool) and nbf > now:
            raise AuthError(401, "invalid_token", f"Authorization: the token is not valid for another "
                                                  f"{nbf - now:.0f} s (nbf {nbf})")

    def _check_audience(self, aud) -> None:
        if aud is None:
            raise AuthError(401, "invalid_token", f"Authorization: the token has no aud claim (this USS is one of: "
                                                  f"{', '.join(self.audiences)})")
        auds = [aud] if isinstance(aud, str) else aud if isinstance(aud, list) else []
        if not any(isinstance(a, str) and a.lower() in self.audiences for a in auds):
            raise AuthError(401, "invalid_token", f"Authorization: the token's aud {str(aud)[:100]!r} is not "
                                                  f"this USS (one of: {', '.join(self.audiences)})")


# ---- the local stand-in for an auth server ---------------------------------------------------

def generate_dev_keys(folder) -> tuple:
    """An RSA 2048 key pair in ``folder`` (``private.pem``, readable by its owner only, and
    ``public.pem``), kept if both files are there already. Returns their paths."""
    from cryptography.hazmat.primitives import serialization
    from cryptography.hazmat.primitives.asymmetric import rsa

    folder = Path(folder)
    private, public = folder / DEV_PRIVATE_KEY, folder / DEV_PUBLIC_KEY
    if private.is_file() and public.is_file():
        return private, public
    folder.mkdir(parents=True, exist_ok=True)
    key = rsa.generate_private_key(public_exponent=65537, key_size=2048)
    pem = key.private_bytes(serialization.Encoding.PEM, serialization.PrivateFormat.PKCS8,
                            serialization.NoEncryption())
    fd = os.open(private, os.O_WRONLY | os.O_CREAT | os.O_TRUNC, 0o600)
    with os.fdopen(fd, "wb") as fh:
        fh.write(pem)
    public.write_bytes(key.public_key().public_bytes(serialization.Encoding.PEM,
                                                     serialization.PublicFormat.SubjectPublicKeyInfo))
    return private, public


def mint_token(private_key, audience: str, scopes, lifetime_s: float = 3600.0, sub: str = DEV_SUBJECT,
               iss: str = DEV_ISSUER, now_s: float | None = None) -> str:
    """An RS256 access token as InterUSS's dummy auth server issues them (``aud``, ``scope``,
    ``iss``, ``sub``, ``exp``), signed with the PEM private key at ``private_key`` (a path)."""
    from joserfc import jwk, jwt

    try:
        key = jwk.import_key(Path(private_key).read_bytes(), "RSA")
    except OSError as exc:
        raise ValueError(f"key: {str(private_key)!r} cannot be read ({exc.strerror})") from None
    if not key.is_private:
        raise ValueError(f"key: {str(private_key)!r} is a public key; tokens are signed with the private one")
    now = time.time() if now_s is None else now_s
    claims = {"iss": iss, "sub": sub, "aud": audience, "scope": " ".join(scopes),
              "iat": int(now), "exp": int(now + lifetime_s), "jti": str(uuid.uuid4())}
    return jwt.encode({"alg": "RS256", "typ": "JWT"}, claims, key, algorithms=["RS256"])
