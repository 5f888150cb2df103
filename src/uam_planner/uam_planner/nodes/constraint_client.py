"""Announce a constraint to a running planner: a client of ``uam/update_constraint``.

    python -m uam_planner.nodes.constraint_client add FEATURE.geojson --run RUN_DIR
    python -m uam_planner.nodes.constraint_client change FEATURE.geojson --run RUN_DIR
    python -m uam_planner.nodes.constraint_client withdraw ID VERSION [--reason TEXT] --run RUN_DIR

``--run RUN_DIR``: the run folder run_fleet.sh made (its ``--out``): the client takes the run's
ROS domain (``RUN_DIR/run.env``) and signs as the run's airspace authority
(``RUN_DIR/authority/``; ``uam_planner.authority``). Without it, ``--key FILE --authority ID``
name an authority's private key, and the domain is the environment's ``ROS_DOMAIN_ID``.

``FEATURE.geojson``: one GeoJSON Feature (or a FeatureCollection of exactly one; its ``frame``
is carried over), as in docs/constraints.md; its ``properties.id`` and ``version`` name the
update. For the PyPI wheels, which have no ``ros2 service call``. Prints the planner's answer;
exit 0 when accepted, 1 when refused (the reason names the field and the value), 2 when no
planner serves the service within ``--timeout`` seconds.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from pathlib import Path

from uam_contract import names as c


def build_request(action: str, path: str = "", constraint_id: str = "", version: int = 0, reason: str = ""):
    """The UpdateConstraint request for the command line's arguments (ValueError naming the file)."""
    from uam_msgs.srv import UpdateConstraint

    codes = {"add": 0, "change": 1, "withdraw": 2}
    req = UpdateConstraint.Request(action=codes[action], reason=reason)
    if action == "withdraw":
        req.constraint_id, req.version = constraint_id, int(version)
        return req
    try:
        with open(path, encoding="utf-8") as f:
            doc = json.load(f)
    except (OSError, json.JSONDecodeError) as exc:
        raise ValueError(f"{path}: {exc}") from None
    if isinstance(doc, dict) and doc.get("type") == "FeatureCollection":
        feats = doc.get("features") or []
        if len(feats) != 1:
            raise ValueError(f"{path}: {len(feats)} features; one update carries exactly one")
        feature = feats[0]
        if doc.get("frame") and isinstance(feature.get("properties"), dict):
            feature["properties"].setdefault("frame", doc["frame"])
    else:
        feature = doc
    props = feature.get("properties") if isinstance(feature, dict) else None
    if not isinstance(props, dict) or "id" not in props or "version" not in props:
        raise ValueError(f"{path}: the Feature needs properties.id and properties.version")
    req.constraint_id, req.version = str(props["id"]), int(props["version"])
    req.reason = reason or str(props.get("reason", ""))
    req.geojson = json.dumps(feature)
    return req


def run_domain(run_dir: str) -> str:
    """The ROS domain id a run_fleet.sh run used (``RUN_DIR/run.env``); ValueError naming the file."""
    env = Path(run_dir) / "run.env"
    try:
        for line in env.read_text(encoding="utf-8").splitlines():
            if line.startswith("ROS_DOMAIN_ID="):
                return line.split("=", 1)[1].strip()
    except OSError as exc:
        raise ValueError(f"--run: {env}: {exc} (is {run_dir} a run_fleet.sh output folder?)") from None
    raise ValueError(f"--run: {env} names no ROS_DOMAIN_ID")


def signer(run_dir: str, key: str, authority: str) -> tuple[str, str]:
    """(private key file, authority id) to sign with: the run's authority (``--run``; its domain
    is set for this process) or ``--key`` and ``--authority``; ValueError naming what is missing."""
    from uam_planner.authority import RUN_AUTHORITY_DIR, RUN_AUTHORITY_ID

    if run_dir:
        os.environ["ROS_DOMAIN_ID"] = run_domain(run_dir)
        found = Path(run_dir) / RUN_AUTHORITY_DIR / f"{RUN_AUTHORITY_ID}.key.pem"
        return str(key or found), authority or RUN_AUTHORITY_ID
    if not key or not authority:
        raise ValueError("an update must be signed by an airspace authority: give --run RUN_DIR (the run "
                         "folder of run_fleet.sh), or --key FILE and --authority ID")
    return key, authority


def main(argv: list[str] | None = None) -> int:
    import rclpy
    from rclpy.utilities import remove_ros_args
    from uam_msgs.srv import UpdateConstraint

    argv = list(sys.argv if argv is None else ["constraint_client", *argv])
    ap = argparse.ArgumentParser(prog="python -m uam_planner.nodes.constraint_client",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("action", choices=("add", "change", "withdraw"))
    ap.add_argument("what", help="the Feature file (add, change) or the constraint id (withdraw)")
    ap.add_argument("version", nargs="?", type=int, default=None, help="withdraw: the new version")
    ap.add_argument("--reason", default="")
    ap.add_argument("--timeout", type=float, default=10.0, help="wait this long for the service [s wall]")
    ap.add_argument("--run", default="", help="the run folder (run_fleet.sh --out): its ROS domain and its "
                                                "airspace authority's key")
    ap.add_argument("--key", default="", help="an airspace authority's private key (PEM), without --run")
    ap.add_argument("--authority", default="", help="that authority's id (as in the planner's authorities file)")
    args = ap.parse_args(remove_ros_args(argv)[1:])
    if args.action == "withdraw" and args.version is None:
        ap.error("withdraw needs ID VERSION")
    try:
        key_file, authority = signer(args.run, args.key, args.authority)
        req = build_request(args.action, args.what, args.what, args.version or 0, args.reason)
        from uam_planner.authority import sign_update
        # a sequence number above every earlier one of this authority: the wall clock in ns
        # (this client is not part of the run's algorithms; the planner only needs it to grow)
        req.authorization = sign_update(req, args.action, authority, Path(key_file).read_bytes(), time.time_ns())
    except (ValueError, OSError) as exc:
        print(f"constraint_client: {exc}", file=sys.stderr)
        return 1
    rclpy.init(args=argv)
    node = rclpy.create_node("constraint_client")
    try:
        client = node.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
        if not client.wait_for_service(timeout_sec=args.timeout):
            domain = os.environ.get("ROS_DOMAIN_ID", "0 (unset)")
            print(f"constraint_client: no planner serves {client.srv_name} within {args.timeout:g} s on ROS domain "
                  f"{domain}; each run_fleet.sh run has its own domain: give its folder with --run DIR",
                  file=sys.stderr)
            return 2
        fut = client.call_async(req)
        rclpy.spin_until_future_complete(node, fut, timeout_sec=args.timeout)
        res = fut.result()
        if res is None:
            print("constraint_client: no answer", file=sys.stderr)
            return 2
        t = res.effective_time.sec + res.effective_time.nanosec * 1e-9
        if res.accepted:
            print(f"accepted: {args.action} {req.constraint_id!r} v{req.version}, from the epoch at t = {t:g} s; "
                  f"{res.constraints} constraint(s) then")
            return 0
        print(f"refused: {res.error}")
        return 1
    finally:
        node.destroy_node()
        rclpy.try_shutdown()


if __name__ == "__main__":
    sys.exit(main())
