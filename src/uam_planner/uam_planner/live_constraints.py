"""Live airspace constraints: the rules behind the planner node's ``uam/update_constraint``.

rclpy-free and duck-typed (anything with the fields of ``UpdateConstraint.Request``), so the
rules are tested without a ROS graph; the planner node calls :func:`parse_update` and the
planning library's ``Planner.update_constraint`` from its service callback.

Why the planner serves it (and not an authority node of its own): the planner owns the airspace
it plans in. An update must reach the planning exactly between two epochs, all at once, or an
epoch would be prepared against one set of constraints and committed against another; the
planner is the one process that knows where it is in that cycle. A separate authority node would
hold a second copy of the set and need its own protocol to hand each update over at the right
instant, and the recording would then have two sources of the airspace to reconcile. An
authority (a USS, a test harness) is a *client* of this service.

What happens to an update:

1. :func:`parse_update` reads it (the action, the GeoJSON Feature into a
   :class:`~uam_planner.constraints.Constraint`: geometry, band, vertex limit, window, all with the
   library's own rules) and ``Planner.update_constraint`` checks it against the set as it will be
   once the updates queued before are applied (id in use or not, version higher, vertiport
   known, window not over by the time it takes effect); either refuses it, naming the field and
   the value, changing nothing, or queues it;
2. the planner applies the queue at its next epoch, in one step, before that epoch's requests
   (``Planner.prepare``, under the node's lock that also guards the commit), and re-plans the
   flights the update affects (docs/replanning.md); the node then publishes the set on
   ``uam/constraints`` (:func:`set_geojson`).

Nothing accepted before is lost: a refused update changes nothing.
"""

from __future__ import annotations

import json
import math
from typing import Any, Iterable

from uam_contract.ids import echo
from uam_planner.authority import check_extent
from uam_planner.constraints import MAX_VERTICES, Constraint, ConstraintError, constraints_from_geojson

ACTION_ADD, ACTION_CHANGE, ACTION_WITHDRAW = 0, 1, 2
ACTIONS = {ACTION_ADD: "add", ACTION_CHANGE: "change", ACTION_WITHDRAW: "withdraw"}
#: the longest ``geojson`` text taken (a 10,000-vertex outline in lon/lat is about 0.5 MB)
MAX_GEOJSON_CHARS = 2_000_000
#: the most constraints the planner holds at once
MAX_CONSTRAINTS = 10_000


def _feature_constraint(text: str, network) -> Constraint:
    """The one constraint of a GeoJSON Feature (or a FeatureCollection of exactly one)."""
    if not isinstance(text, str) or not text.strip():
        raise ConstraintError("geojson: empty; add and change need the constraint's GeoJSON Feature")
    if len(text) > MAX_GEOJSON_CHARS:
        raise ConstraintError(f"geojson: {len(text)} characters, more than {MAX_GEOJSON_CHARS}")
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConstraintError(f"geojson: not JSON ({exc})") from None
    if isinstance(doc, dict) and doc.get("type") == "Feature":
        frame = (doc.get("properties") or {}).get("frame", "wgs84") if isinstance(doc.get("properties"), dict) else "wgs84"
        doc = {"type": "FeatureCollection", "frame": frame, "features": [doc]}
    if not isinstance(doc, dict) or doc.get("type") != "FeatureCollection":
        raise ConstraintError(f"geojson.type: {echo(doc.get('type') if isinstance(doc, dict) else doc)} "
                              "is not 'Feature'")
    if not isinstance(doc.get("features"), list) or len(doc["features"]) != 1:
        raise ConstraintError("geojson.features: one update carries exactly one constraint")
    try:
        found = constraints_from_geojson(doc, network)
    except ConstraintError as exc:
        raise ConstraintError(f"geojson: {exc}".replace("geojson: features[0] ", "geojson ")) from None
    return found[0]


def parse_update(req: Any, current: dict, network) -> tuple[str, Any]:
    """One UpdateConstraint request as the planning library takes it: (action name, Constraint,
    or the id for a withdrawal), for ``Planner.update_constraint``. Raises ConstraintError naming
    the field and the value for what the library does not check itself: the action, the
    request's id and version against its Feature, a withdrawal's version (above the current),
    the text. ``current``: id -> Constraint once the queued updates are applied."""
    action = getattr(req, "action", None)
    if action not in ACTIONS:
        raise ConstraintError(f"action: {echo(action)} is not 0 (add), 1 (change) or 2 (withdraw)")
    name = ACTIONS[action]
    cid = getattr(req, "constraint_id", "")
    version = getattr(req, "version", 0)
    if not isinstance(cid, str) or not cid.strip() or len(cid) > 200:
        raise ConstraintError(f"constraint_id: {echo(cid)} is not an id of 1 to 200 characters")
    if isinstance(version, bool) or not isinstance(version, int) or version < 0:
        raise ConstraintError(f"version: {echo(version)} is not an integer >= 0")
    if name == "withdraw":
        if getattr(req, "geojson", ""):
            raise ConstraintError("geojson: a withdrawal carries no geometry (leave it empty)")
        held = current.get(cid)
        if held is not None and version <= held.version:
            raise ConstraintError(f"version: {version} is not above {cid!r}'s version {held.version}")
        return name, cid
    if name == "add" and cid not in current and len(current) >= MAX_CONSTRAINTS:
        raise ConstraintError(f"constraint_id: the planner holds {len(current)} constraints, its most "
                              f"({MAX_CONSTRAINTS}); withdraw one first")
    c = _feature_constraint(getattr(req, "geojson", ""), network)
    check_extent(c, network)
    if c.constraint_id != cid:
        raise ConstraintError(f"geojson properties.id: {c.constraint_id!r} differs from constraint_id {cid!r}")
    if c.version != version:
        raise ConstraintError(f"geojson properties.version: {c.version} differs from version {version}")
    return name, c


def _num(x: float):
    """A float for JSON: infinities as null (RFC 8259 has no infinity)."""
    return None if math.isinf(x) else float(x)


def constraint_feature(c: Constraint, **extra) -> dict:
    """One constraint as a GeoJSON Feature in the network's ENU frame (``properties.frame``:
    "enu", as ``docs/constraints.md`` files may say), with ``extra`` properties."""
    props = {"id": c.constraint_id, "version": c.version, "reason": c.reason, "kind": c.kind,
             "start_s": _num(c.start_s), "end_s": _num(c.end_s), "frame": "enu"}
    if c.kind == "closure":
        props["vertiport_id"] = c.vertiport_id
        if c.pad_index is not None:
            props["pad"] = c.pad_index
        geometry = None
    else:
        props["lower_m"], props["upper_m"] = _num(c.lower_m), _num(c.upper_m)
        if c.kind == "circle":
            props["radius_m"] = c.radius_m
            geometry = {"type": "Point", "coordinates": [c.center_m[0], c.center_m[1]]}
        else:
            rings = [[[float(x), float(y)] for x, y in r] + [[float(r[0][0]), float(r[0][1])]] for r in c.rings_m]
            geometry = {"type": "Polygon", "coordinates": rings}
    if c.author:
        props["author"] = c.author
    props.update(extra)
    return {"type": "Feature", "geometry": geometry, "properties": props}


def set_geojson(constraints: Iterable[Constraint], t_s: float, effective_s: dict[str, float] | None = None,
                announced_s: dict[str, float] | None = None, withdrawn: list | None = None) -> str:
    """The set the planner plans with from ``t_s`` on, as the text of ``uam/constraints``: a
    GeoJSON FeatureCollection in ENU metres (``"frame": "enu"``), each feature with its window
    (``start_s``, ``end_s``, null = unbounded), band, ``effective_s`` (when the planner began
    planning with this version) and, where known, ``announce_s`` (when the authority announced
    it: ``announced_s``, else the constraint's own finite ``announce_s``; the audit reports what
    flew inside it between the two). ``withdrawn``: the withdrawals so far, each {"id",
    "version", "by" (the authority), "t_s" (when asked), "applied_s"}, written as the collection's
    ``withdrawn`` list (read with :func:`withdrawals_from_text`). Read back with
    :func:`constraints_from_text`."""
    eff, ann = effective_s or {}, announced_s or {}

    def extra(c):
        out = {"effective_s": float(eff.get(c.constraint_id, t_s))}
        when = ann.get(c.constraint_id, c.announce_s)
        if math.isfinite(when):
            out["announce_s"] = float(when)
        return out
    feats = [constraint_feature(c, **extra(c)) for c in sorted(constraints, key=lambda c: c.constraint_id)]
    doc = {"type": "FeatureCollection", "frame": "enu", "t_s": float(t_s), "features": feats}
    if withdrawn:
        doc["withdrawn"] = list(withdrawn)
    return json.dumps(doc, separators=(",", ":"), allow_nan=False)


def withdrawals_from_text(text: str) -> list[dict]:
    """The ``withdrawn`` list of a published set (:func:`set_geojson`); [] when it has none or
    is not readable (the set's own reader reports that)."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError:
        return []
    found = doc.get("withdrawn") if isinstance(doc, dict) else None
    return [w for w in found if isinstance(w, dict)] if isinstance(found, list) else []


def constraints_from_text(text: str, network=None) -> tuple[float, list[tuple[Constraint, float]]]:
    """Inverse of :func:`set_geojson`: (t_s, [(constraint, effective_s)]). Raises ConstraintError."""
    try:
        doc = json.loads(text)
    except json.JSONDecodeError as exc:
        raise ConstraintError(f"constraint set: not JSON ({exc})") from None
    feats = doc.get("features") if isinstance(doc, dict) else None
    if not isinstance(feats, list):
        raise ConstraintError("constraint set: no features list")
    for f in feats:  # null = unbounded
        p = f.get("properties", {}) if isinstance(f, dict) else {}
        for key, inf in (("start_s", -math.inf), ("end_s", math.inf), ("lower_m", -math.inf), ("upper_m", math.inf)):
            if key in p and p[key] is None:
                p[key] = inf
    found = constraints_from_geojson(doc, network)
    eff = [float(f["properties"].get("effective_s", doc.get("t_s", 0.0))) for f in feats]
    return float(doc.get("t_s", 0.0)), list(zip(found, eff))


__all__ = ["ACTIONS", "ACTION_ADD", "ACTION_CHANGE", "ACTION_WITHDRAW", "MAX_CONSTRAINTS",
           "MAX_GEOJSON_CHARS", "MAX_VERTICES", "constraint_feature", "constraints_from_text", "parse_update",
           "set_geojson", "withdrawals_from_text"]
