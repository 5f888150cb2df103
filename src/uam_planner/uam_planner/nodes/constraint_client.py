"""Announce a constraint to a running planner: a client of ``uam/update_constraint``.

    python -m uam_planner.nodes.constraint_client add FEATURE.geojson [--ros-args ...]
    python -m uam_planner.nodes.constraint_client change FEATURE.geojson
    python -m uam_planner.nodes.constraint_client withdraw ID VERSION [--reason TEXT]

``FEATURE.geojson``: one GeoJSON Feature (or a FeatureCollection of exactly one; its ``frame``
is carried over), as in docs/constraints.md; its ``properties.id`` and ``version`` name the
update. For the PyPI wheels, which have no ``ros2 service call``. Prints the planner's answer;
exit 0 when accepted, 1 when refused (the reason names the field and the value), 2 when no
planner serves the service within ``--timeout`` seconds.
"""

from __future__ import annotations

import argparse
import json
import sys

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
    args = ap.parse_args(remove_ros_args(argv)[1:])
    if args.action == "withdraw" and args.version is None:
        ap.error("withdraw needs ID VERSION")
    try:
        req = build_request(args.action, args.what, args.what, args.version or 0, args.reason)
    except ValueError as exc:
        print(f"constraint_client: {exc}", file=sys.stderr)
        return 1
    rclpy.init(args=argv)
    node = rclpy.create_node("constraint_client")
    try:
        client = node.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
        if not client.wait_for_service(timeout_sec=args.timeout):
            print(f"constraint_client: no planner serves {client.srv_name} within {args.timeout:g} s",
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
