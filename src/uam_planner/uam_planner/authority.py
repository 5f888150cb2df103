"""Who may change the airspace: the airspace authorities configured at the run's start, the
signed updates they send, and the bounds any constraint must keep.

The planner takes a live constraint update (``uam/update_constraint``) only from an authority
named in its authorities file (the ``authorities_file`` parameter), read once at start::

    authorities:
      - id: caa                    # the author recorded with each constraint it adds or changes
        public_key: caa.pub.pem    # its EC P-256 public key (PEM), relative to this file
        admin: true                # may change or withdraw any authority's constraint
      - id: hospital
        public_key: hospital.pub.pem
      - id: uss
        public_key: uss.pub.pem
        operators: [flight_planning]   # requests of these operators come only signed by this authority

An authority with ``operators`` is a USS that puts flight requests to the planner in those
operators' names (:mod:`uam_planner.signed_requests`, the service ``uam/uss_flight_plan``): the
planner takes requests of those operators only signed by it, never from ``uam/requests``.

Each update carries ``authorization``: a JWT (ES256, RFC 7519) signed with the authority's
private key, whose claims bind it to the request and to the authority's sequence:

- ``iss``: the authority's id; ``act``, ``cid``, ``ver``: the request's action, constraint id
  and version; ``sha256``: :func:`request_digest` of its GeoJSON and reason (the content);
- ``seq``: an integer above every ``seq`` of that authority this planner took before, so an
  update read off the open DDS domain and sent again is refused (a replay).

The JWT is verified by ``joserfc`` (Authlib's JOSE library, pinned): the algorithm is pinned to
ES256 (``alg: none`` and every other one refused), the signature against the key of the
authority the ``iss`` claim names. Only a constraint's author, or an admin authority, may change
or withdraw it (:meth:`Authorities.check_owner`). Every region must lie within the network's
extent plus :data:`EXTENT_MARGIN_M` (:func:`check_extent`): a square of 10^300 m is refused.

What this does not stop: a holder of an authority's private key, and a replay into another
planner that has not seen the authority's later ``seq`` (a restarted one; run_fleet.sh makes a
new key pair for every run). Without an authorities file the planner takes no live update.

rclpy-free; raises ``ConstraintError`` naming the field (``authorization``, ``constraint_id``,
``geojson``) and the value.
"""

from __future__ import annotations

import hashlib
import json
import math
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from uam_contract.ids import echo

from .constraints import Constraint, ConstraintError

#: the only signing algorithm taken
ALGORITHMS = ("ES256",)
#: the longest authorization text taken
MAX_TOKEN_CHARS = 8192
#: how far beyond the network's extent a constraint may reach [m]
EXTENT_MARGIN_M = 20_000.0
#: the authorities file run_fleet.sh writes into a run folder, and the key beside it
RUN_AUTHORITY_DIR = "authority"
RUN_AUTHORITY_ID = "run-authority"


def request_digest(geojson: str, reason: str) -> str:
    """SHA-256 (hex) of an update's content: its GeoJSON text and its reason."""
    return hashlib.sha256((str(geojson) + "\n" + str(reason)).encode("utf-8")).hexdigest()


@dataclass(frozen=True)
class Authority:
    """One airspace authority: its id, public key (a joserfc key) and whether it is an admin."""

    authority_id: str
    key: Any
    admin: bool = False
    operators: tuple = ()


@dataclass
class Authorities:
    """The authorities of one run and the highest ``seq`` taken from each."""

    by_id: dict
    seq: dict = field(default_factory=dict)

    @classmethod
    def load(cls, path) -> "Authorities":
        """Read an authorities file (see the module docstring); ValueError naming the entry."""
        from joserfc import jwk
        from joserfc.errors import JoseError

        from .grants import read_yaml

        p = Path(path)
        doc = read_yaml(p, "authorities_file")
        rows = doc.get("authorities") if isinstance(doc, dict) else None
        if not isinstance(rows, list) or not rows:
            raise ValueError(f"authorities_file: {p}: no 'authorities' list")
        by_id = {}
        for i, row in enumerate(rows):
            where = f"authorities_file: {p}: authorities[{i}]"
            if not isinstance(row, dict):
                raise ValueError(f"{where}: not a mapping")
            aid = row.get("id")
            if not isinstance(aid, str) or not aid.strip() or len(aid) > 200:
                raise ValueError(f"{where}.id: {echo(aid)} is not an id of 1 to 200 characters")
            if aid in by_id:
                raise ValueError(f"{where}.id: {aid!r} twice")
            key_file = row.get("public_key")
            if not isinstance(key_file, str) or not key_file:
                raise ValueError(f"{where}.public_key: {echo(key_file)} is not a file name")
            try:
                pem = (p.parent / key_file).read_bytes()
                key = jwk.import_key(pem, "EC")
            except (OSError, JoseError, ValueError) as exc:
                raise ValueError(f"{where}.public_key: {key_file}: {exc}") from None
            if key.is_private:
                raise ValueError(f"{where}.public_key: {key_file} holds a private key; give the public one")
            admin = row.get("admin", False)
            if not isinstance(admin, bool):
                raise ValueError(f"{where}.admin: {echo(admin)} is not true or false")
            ops = row.get("operators", [])
            if not isinstance(ops, list) or not all(isinstance(o, str) and o for o in ops):
                raise ValueError(f"{where}.operators: {echo(ops)} is not a list of operator ids")
            taken = [o for o in ops for other in by_id.values() if o in other.operators]
            if taken:
                raise ValueError(f"{where}.operators: {taken[0]!r} is another authority's already")
            by_id[aid] = Authority(aid, key, admin, tuple(ops))
        return cls(by_id)

    def operator_authority(self, operator_id: str) -> str | None:
        """The authority whose signed requests alone may speak for ``operator_id``, or None."""
        return next((a.authority_id for a in self.by_id.values() if operator_id in a.operators), None)

    def check_operator(self, author: str, operator_id: str) -> None:
        """Refuse (ConstraintError naming ``operator_id``) a request of ``operator_id`` signed by
        ``author`` unless ``author`` is that operator's authority."""
        if operator_id not in self.by_id[author].operators:
            raise ConstraintError(f"operator_id: {echo(operator_id)} is not an operator of authority {author!r} "
                                  f"(its operators: {', '.join(self.by_id[author].operators) or 'none'})")

    def verify(self, req: Any, action: str, channel: str = "") -> str:
        """The id of the authority that signed update ``req`` (anything with UpdateConstraint's
        fields) for ``action``; ConstraintError naming ``authorization`` otherwise. A verified
        update's ``seq`` is taken: the same update again is refused. ``channel``: the sequence
        the ``seq`` belongs to ('' for constraint updates; a USS's flight requests count apart,
        so that the two services' calls may arrive in any order)."""
        from joserfc import jws, jwt
        from joserfc.errors import JoseError

        token = getattr(req, "authorization", "")
        if not isinstance(token, str) or not token:
            raise ConstraintError("authorization: empty; live constraint updates are taken only from an "
                                  f"airspace authority of this run ({', '.join(sorted(self.by_id))}), signed")
        if len(token) > MAX_TOKEN_CHARS:
            raise ConstraintError(f"authorization: {len(token)} characters, more than {MAX_TOKEN_CHARS}")
        try:
            unverified = jws.extract_compact(token.encode("ascii"))
            claimed = json.loads(unverified.payload)
            iss = claimed.get("iss") if isinstance(claimed, dict) else None
        except (JoseError, ValueError, UnicodeError) as exc:
            raise ConstraintError(f"authorization: not a compact JWT ({exc})") from None
        authority = self.by_id.get(iss) if isinstance(iss, str) else None
        if authority is None:
            raise ConstraintError(f"authorization: issuer {echo(iss)} is not an airspace authority of this run "
                                  f"({', '.join(sorted(self.by_id))})")
        try:
            claims = jwt.decode(token, authority.key, algorithms=list(ALGORITHMS)).claims
        except (JoseError, ValueError) as exc:
            raise ConstraintError(f"authorization: not signed by {iss!r} with {'/'.join(ALGORITHMS)} ({exc})") from None
        expected = {"act": action, "cid": getattr(req, "constraint_id", ""), "ver": int(getattr(req, "version", 0)),
                    "sha256": request_digest(getattr(req, "geojson", ""), getattr(req, "reason", ""))}
        for name, value in expected.items():
            if claims.get(name) != value:
                raise ConstraintError(f"authorization: claim {name} {echo(claims.get(name))} does not match the "
                                      f"request's {echo(value)}")
        seq = claims.get("seq")
        if isinstance(seq, bool) or not isinstance(seq, int):
            raise ConstraintError(f"authorization: claim seq {echo(seq)} is not an integer")
        key = iss if not channel else f"{iss}#{channel}"
        last = self.seq.get(key)
        if last is not None and seq <= last:
            raise ConstraintError(f"authorization: seq {seq} of {iss!r} is not above {last}, the last taken "
                                  "(a replayed update)")
        self.seq[key] = seq
        return iss

    def check_owner(self, author: str, held: Constraint | None) -> None:
        """Refuse (ConstraintError) a change or withdrawal of ``held`` by ``author`` unless it
        is ``held``'s author or an admin authority."""
        if held is None or self.by_id[author].admin:
            return
        owner = getattr(held, "author", "")
        if owner != author:
            raise ConstraintError(f"constraint_id: {held.constraint_id!r} is {owner or 'the start set'}'s; "
                                  f"{author!r} may not change or withdraw it (only its author or an admin authority)")


def check_extent(c: Constraint, network, margin_m: float = EXTENT_MARGIN_M) -> None:
    """Refuse (ConstraintError naming ``geojson``) a region reaching beyond the network's extent
    plus ``margin_m``; closures have no region."""
    if network is None or c.kind == "closure":
        return
    xy = np.asarray(network.enu_m, dtype=np.float64)[:, :2]
    lo, hi = xy.min(axis=0) - margin_m, xy.max(axis=0) + margin_m
    if c.kind == "circle":
        cx, cy = float(c.center_m[0]), float(c.center_m[1])
        r = float(c.radius_m)
        pts = np.array([[cx - r, cy - r], [cx + r, cy + r]])
    else:
        pts = np.vstack([np.asarray(r, dtype=np.float64) for r in c.rings_m])
    if not np.all(np.isfinite(pts)) or np.any(pts < lo) or np.any(pts > hi):
        far = float(np.max(np.maximum(lo - pts, pts - hi))) if np.all(np.isfinite(pts)) else math.inf
        raise ConstraintError(f"geojson: constraint {c.constraint_id!r} reaches {far:.4g} m beyond the network's "
                              f"extent plus {margin_m:g} m")


def sign_update(req: Any, action: str, authority_id: str, private_key_pem: bytes, seq: int) -> str:
    """The ``authorization`` of update ``req`` for ``action`` by ``authority_id`` (its
    private key in PEM), with sequence number ``seq``."""
    from joserfc import jwk, jwt

    claims = {"iss": authority_id, "act": action, "cid": getattr(req, "constraint_id", ""),
              "ver": int(getattr(req, "version", 0)),
              "sha256": request_digest(getattr(req, "geojson", ""), getattr(req, "reason", "")), "seq": int(seq)}
    return jwt.encode({"alg": ALGORITHMS[0]}, claims, jwk.import_key(private_key_pem, "EC"))


def write_authority(folder, authority_id: str = RUN_AUTHORITY_ID, admin: bool = True,
                    add: bool = False, operators=()) -> tuple[Path, Path]:
    """A new EC P-256 key pair for ``authority_id`` in ``folder``, and an authorities file
    naming it (``add``: appended to the folder's file, which keeps its other authorities;
    ``operators``: the operators it alone may put requests for):
    (authorities file, private key file; readable by its owner only)."""
    import os

    from joserfc import jwk

    out = Path(folder)
    out.mkdir(parents=True, exist_ok=True)
    key = jwk.ECKey.generate_key("P-256")
    private = out / f"{authority_id}.key.pem"
    private.write_bytes(b"")
    os.chmod(private, 0o600)
    private.write_bytes(key.as_pem(private=True))
    (out / f"{authority_id}.pub.pem").write_bytes(key.as_pem(private=False))
    listing = out / "authorities.yaml"
    entry = (f"  - id: {authority_id}\n    public_key: {authority_id}.pub.pem\n"
             f"    admin: {'true' if admin else 'false'}\n")
    if operators:
        entry += f"    operators: [{', '.join(operators)}]\n"
    if add and listing.is_file():
        listing.write_text(listing.read_text(encoding="utf-8") + entry, encoding="utf-8")
    else:
        listing.write_text("# the run's airspace authorities (uam_planner.authority)\nauthorities:\n" + entry,
                           encoding="utf-8")
    return listing, private


def main(argv=None) -> int:
    """``python -m uam_planner.authority new FOLDER [--id ID] [--not-admin]``: a key pair and an
    authorities file (run_fleet.sh makes one per run)."""
    import argparse

    ap = argparse.ArgumentParser(prog="python -m uam_planner.authority",
                                 description="Make an airspace authority's key pair and authorities file.")
    sub = ap.add_subparsers(dest="cmd", required=True)
    new = sub.add_parser("new", help="a new key pair and authorities file in FOLDER")
    new.add_argument("folder")
    new.add_argument("--id", default=RUN_AUTHORITY_ID)
    new.add_argument("--not-admin", action="store_true", help="may change only its own constraints")
    new.add_argument("--add", action="store_true", help="add it to the folder's authorities file")
    new.add_argument("--operator", action="append", default=[],
                     help="an operator whose requests only this authority may put (a USS's; repeatable)")
    args = ap.parse_args(argv)
    listing, private = write_authority(args.folder, args.id, not args.not_admin, add=args.add,
                                       operators=args.operator)
    print(f"authorities file {listing}; private key {private}")
    return 0


if __name__ == "__main__":
    import sys
    sys.exit(main())
