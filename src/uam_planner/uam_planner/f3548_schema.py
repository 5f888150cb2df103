"""Schema validation of the F3548 documents this project writes and serves.

The F3548-21 OpenAPI (``utm.yaml``, interuss/astm-utm-protocol) is not shipped in the
``uas_standards`` wheel and states no licence, so it is not copied into this repository. This
module restates, as JSON Schema (OpenAPI 3.0 / draft 4 style, ``components.schemas`` layout),
the constraints that ``utm.yaml`` puts on the schemas reachable from
``GetOperationalIntentDetailsResponse``, ``GetConstraintDetailsResponse``, ``ErrorResponse`` and
``OperationalIntent`` (read at commit ab589c8: UUIDv4 pattern of EntityID, OVN length 16..128,
RFC 3339 times, altitude W84 / M within -8000..100000 m, latitude and longitude ranges, polygons
of 3+ vertices, the state and availability enums, required fields); the ``geozone`` of a
constraint is left open (we never write one).

:func:`validate` takes any document of that layout, so the standard's own ``utm.yaml`` drops in
(``openapi=path``; ``docs/f3548.md``). :func:`validate_implicit` is the second, independent check:
``uas_standards``' own types parse the document (ImplicitDict: required fields and types).
"""

from __future__ import annotations

import functools
from typing import Any, Mapping

_REF = "#/components/schemas/"


def _ref(name: str) -> dict:
    return {"$ref": _REF + name}


_SCHEMAS: dict[str, Any] = {
    "UUIDv4Format": {
        "type": "string", "minLength": 36, "maxLength": 36, "format": "uuid",
        "pattern": "^[0-9a-fA-F]{8}\\-[0-9a-fA-F]{4}\\-4[0-9a-fA-F]{3}\\-[8-b][0-9a-fA-F]{3}"
                   "\\-[0-9a-fA-F]{12}$"},
    "EntityID": {"anyOf": [_ref("UUIDv4Format")]},
    "SubscriptionID": {"anyOf": [_ref("UUIDv4Format")]},
    "EntityOVN": {"type": "string", "minLength": 16, "maxLength": 128},
    "EntityVersion": {"type": "integer", "format": "int32",
                      "minimum": -2147483648, "maximum": 2147483647},
    "Time": {"type": "object", "required": ["value", "format"], "properties": {
        "value": {"type": "string", "format": "date-time",
                  "pattern": "^\\d{4}-\\d{2}-\\d{2}T\\d{2}:\\d{2}:\\d{2}(\\.\\d+)?Z$"},
        "format": {"type": "string", "enum": ["RFC3339"]}}},
    "Radius": {"type": "object", "required": ["value", "units"], "properties": {
        "value": {"type": "number", "minimum": 0, "exclusiveMinimum": True},
        "units": {"type": "string", "enum": ["M"]}}},
    "Altitude": {"type": "object", "required": ["value", "reference", "units"], "properties": {
        "value": {"type": "number", "minimum": -8000, "maximum": 100000},
        "reference": {"type": "string", "enum": ["W84"]},
        "units": {"type": "string", "enum": ["M"]}}},
    "Latitude": {"type": "number", "minimum": -90, "maximum": 90},
    "Longitude": {"type": "number", "minimum": -180, "maximum": 180},
    "LatLngPoint": {"type": "object", "required": ["lat", "lng"], "properties": {
        "lat": _ref("Latitude"), "lng": _ref("Longitude")}},
    "Polygon": {"type": "object", "required": ["vertices"], "properties": {
        "vertices": {"type": "array", "minItems": 3, "items": _ref("LatLngPoint")}}},
    "Circle": {"type": "object", "properties": {
        "center": _ref("LatLngPoint"), "radius": _ref("Radius")}},
    "Volume3D": {"type": "object", "properties": {
        "outline_circle": {"anyOf": [_ref("Circle")]},
        "outline_polygon": {"anyOf": [_ref("Polygon")]},
        "altitude_lower": {"anyOf": [_ref("Altitude")]},
        "altitude_upper": {"anyOf": [_ref("Altitude")]}}},
    "Volume4D": {"type": "object", "required": ["volume"], "properties": {
        "volume": _ref("Volume3D"),
        "time_start": {"anyOf": [_ref("Time")]},
        "time_end": {"anyOf": [_ref("Time")]}}},
    "ErrorResponse": {"type": "object", "properties": {"message": {"type": "string"}}},
    "UssBaseURL": {"type": "string"},
    "UssAvailabilityState": {"type": "string", "enum": ["Unknown", "Normal", "Down"]},
    "OperationalIntentState": {"type": "string",
                               "enum": ["Accepted", "Activated", "Nonconforming", "Contingent"]},
    "Priority": {"type": "integer"},
    "OperationalIntentReference": {
        "type": "object",
        "required": ["id", "manager", "uss_availability", "version", "state", "time_start",
                     "time_end", "uss_base_url", "subscription_id"],
        "properties": {
            "id": _ref("EntityID"), "manager": {"type": "string"},
            "uss_availability": _ref("UssAvailabilityState"), "version": _ref("EntityVersion"),
            "state": _ref("OperationalIntentState"), "ovn": {"anyOf": [_ref("EntityOVN")]},
            "time_start": {"anyOf": [_ref("Time")]}, "time_end": {"anyOf": [_ref("Time")]},
            "uss_base_url": {"anyOf": [_ref("UssBaseURL")]},
            "subscription_id": {"anyOf": [_ref("SubscriptionID")]}}},
    "OperationalIntentDetails": {"type": "object", "properties": {
        "volumes": {"type": "array", "items": _ref("Volume4D")},
        "off_nominal_volumes": {"type": "array", "items": _ref("Volume4D")},
        "priority": _ref("Priority")}},
    "OperationalIntent": {"type": "object", "required": ["reference", "details"], "properties": {
        "reference": _ref("OperationalIntentReference"),
        "details": _ref("OperationalIntentDetails")}},
    "GetOperationalIntentDetailsResponse": {
        "type": "object", "required": ["operational_intent"],
        "properties": {"operational_intent": _ref("OperationalIntent")}},
    "ConstraintReference": {
        "type": "object",
        "required": ["id", "manager", "uss_availability", "version", "time_start", "time_end",
                     "uss_base_url"],
        "properties": {
            "id": _ref("EntityID"), "manager": {"type": "string"},
            "uss_availability": _ref("UssAvailabilityState"), "version": _ref("EntityVersion"),
            "ovn": {"anyOf": [_ref("EntityOVN")]}, "time_start": _ref("Time"),
            "time_end": _ref("Time"), "uss_base_url": {"anyOf": [_ref("UssBaseURL")]}}},
    "ConstraintDetails": {"type": "object", "required": ["volumes"], "properties": {
        "volumes": {"type": "array", "minItems": 1, "items": _ref("Volume4D")},
        "type": {"type": "string"}, "geozone": {}}},
    "Constraint": {"type": "object", "required": ["reference", "details"], "properties": {
        "reference": _ref("ConstraintReference"), "details": _ref("ConstraintDetails")}},
    "GetConstraintDetailsResponse": {"type": "object", "required": ["constraint"],
                                     "properties": {"constraint": _ref("Constraint")}},
}

#: the document :func:`validate` uses by default (``components.schemas`` layout, as utm.yaml)
SUBSET = {"components": {"schemas": _SCHEMAS}}


@functools.lru_cache(maxsize=4)
def _load(path: str | None):
    if path is None:
        return SUBSET
    import yaml
    with open(path, encoding="utf-8") as fh:
        return yaml.safe_load(fh)


@functools.lru_cache(maxsize=64)
def _validator(name: str, path: str | None):
    import jsonschema
    doc = _load(path)
    if name not in doc.get("components", {}).get("schemas", {}):
        raise KeyError(f"schema {name!r} is not in components.schemas of "
                       f"{path or 'uam_planner.f3548_schema.SUBSET'}")
    schema = dict(doc)
    schema["$ref"] = _REF + name
    return jsonschema.Draft4Validator(schema, format_checker=jsonschema.Draft4Validator.FORMAT_CHECKER)


def errors(doc: Any, name: str, openapi: str | None = None) -> list[str]:
    """Every schema violation of ``doc`` against ``components.schemas.<name>`` (of
    :data:`SUBSET`, or of the OpenAPI file ``openapi``), each as 'path: message'; [] if valid."""
    v = _validator(name, openapi)
    return [f"{'/'.join(str(p) for p in e.absolute_path) or '(root)'}: {e.message}"
            for e in sorted(v.iter_errors(doc), key=lambda e: list(map(str, e.absolute_path)))]


def validate(doc: Any, name: str, openapi: str | None = None) -> None:
    """Raise ValueError listing the first violations if ``doc`` is not a valid ``name``."""
    errs = errors(doc, name, openapi)
    if errs:
        raise ValueError(f"not a valid F3548 {name}: " + "; ".join(errs[:5])
                         + (f" (and {len(errs) - 5} more)" if len(errs) > 5 else ""))


def validate_implicit(doc: Mapping, name: str) -> Any:
    """Parse ``doc`` with ``uas_standards``' type ``name`` (ImplicitDict); raises on a missing
    required field or a wrong type. Returns the parsed object."""
    from implicitdict import ImplicitDict
    from uas_standards.astm.f3548.v21 import api
    return ImplicitDict.parse(dict(doc), getattr(api, name))
