"""What the planner accepts from the open wire (uam/requests), before the planning library sees it.

rclpy-free and duck-typed (a FlightRequest message or anything with its fields). Every refusal
names the field and shows at most :data:`MAX_ECHO_CHARS` of the offending value, so a 1 MB
string never comes back in a reason, a log line or a recording; reasons are at most
:data:`MAX_REASON_CHARS` long.

Ids are scoped by operator: the decision key is ``operator_id/request_id`` (neither may contain
``/``), so one operator cannot take another's id. Nothing on an open ROS graph proves who an
operator is (see docs/security.md, "What an open ROS graph cannot protect against").
"""

from __future__ import annotations

import hashlib
from typing import Any

from uam_contract.ids import ID_PATTERN, MAX_ECHO_CHARS, MAX_ID_LENGTH, MAX_NODE_ID_LENGTH, check_id, echo  # noqa: F401 (the wire's rule)

MAX_REASON_CHARS = 300
NS_PER_S = 1_000_000_000
SCOPE_SEPARATOR = "/"


def bounded(reason: str) -> str:
    """A reason cut to MAX_REASON_CHARS characters."""
    return reason if len(reason) <= MAX_REASON_CHARS else reason[: MAX_REASON_CHARS - 3] + "..."


def escaped_id(value: Any) -> str:
    """``value`` itself when it is a valid id; else a stand-in that names it and is never a valid
    id: ``!`` then the value with every character outside the id alphabet as ``%XX`` (its code
    point), cut so that the stand-in is at most MAX_ID_LENGTH characters, ending in ``~`` and 8 hex
    digits of its hash when cut (so two different bad ids never share a stand-in, and one bad id
    always gets the same)."""
    if isinstance(value, str) and ID_PATTERN.fullmatch(value):
        return value
    text = value if isinstance(value, str) else repr(value)
    escaped = "".join(ch if ID_PATTERN.fullmatch(ch) else f"%{ord(ch):02X}" for ch in text[: MAX_ID_LENGTH * 2])
    if 1 + len(escaped) > MAX_ID_LENGTH or len(text) > MAX_ID_LENGTH * 2:
        digest = hashlib.sha256(text.encode("utf-8", "surrogatepass")).hexdigest()[:8]
        escaped = escaped[: MAX_ID_LENGTH - 10] + "~" + digest  # at most MAX_ID_LENGTH in all
    return "!" + escaped


def scoped_id(operator_id: str, request_id: str) -> str:
    """The decision key of a request: unique per operator."""
    return f"{operator_id}{SCOPE_SEPARATOR}{request_id}"


def split_scoped(key: str) -> tuple[str, str]:
    """Inverse of :func:`scoped_id`."""
    operator_id, _, request_id = key.partition(SCOPE_SEPARATOR)
    return operator_id, request_id


def _time_s(field: str, stamp: Any) -> tuple[float | None, str]:
    sec, nanosec = getattr(stamp, "sec", None), getattr(stamp, "nanosec", None)
    if not isinstance(sec, int) or not isinstance(nanosec, int):
        return None, f"{field}: {echo(stamp)} is not a time (sec, nanosec)"
    if not 0 <= nanosec < NS_PER_S:
        return None, f"{field}.nanosec: {nanosec} is outside [0, {NS_PER_S - 1}]"
    if sec < 0:
        return None, f"{field}.sec: {sec} is before the start of simulation time"
    return sec + nanosec * 1e-9, ""


def check_request(msg: Any, now_s: float, *, max_window_s: float, max_request_lead_s: float) -> str:
    """'' if the FlightRequest ``msg`` may be queued, else why not; ``now_s`` [s] is the time of the
    next planning epoch (the first at which the request could be planned).

    Checks, in order: operator and request ids (length, characters), origin and destination
    (type and length; whether they are aerodromes is the planning library's check), the three
    times (well-formed, nanosec in range, not negative), request_time not after the earliest
    departure nor more than ``max_request_lead_s`` after now, latest departure not already past
    and not more than ``max_window_s`` after now.
    """
    for field in ("operator_id", "request_id"):
        why = check_id(field, getattr(msg, field, None))
        if why:
            return why
    for field in ("origin_id", "destination_id"):
        v = getattr(msg, field, None)
        if not isinstance(v, str) or not v or len(v) > MAX_NODE_ID_LENGTH:
            return f"{field}: {echo(v)} is not a network node id (1 to {MAX_NODE_ID_LENGTH} characters)"
    times = {}
    for field in ("request_time", "earliest_departure", "latest_departure"):
        times[field], why = _time_s(field, getattr(msg, field, None))
        if why:
            return why
    if times["latest_departure"] < times["earliest_departure"]:
        return (f"latest_departure: {times['latest_departure']:g} s is before earliest_departure "
                f"{times['earliest_departure']:g} s")
    if times["request_time"] > times["latest_departure"]:
        return (f"request_time: {times['request_time']:g} s is after latest_departure "
                f"{times['latest_departure']:g} s")
    if times["request_time"] > now_s + max_request_lead_s:
        return (f"request_time: {times['request_time']:g} s is more than {max_request_lead_s:g} s after the "
                f"current simulation time {now_s:g} s")
    if times["latest_departure"] < now_s:
        return (f"latest_departure: {times['latest_departure']:g} s is before the next planning epoch at "
                f"{now_s:g} s")
    if times["latest_departure"] > now_s + max_window_s:
        return (f"latest_departure: {times['latest_departure']:g} s is more than {max_window_s:g} s after the "
                f"current simulation time {now_s:g} s")
    return ""
