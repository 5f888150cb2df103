"""Stamps: a builtin_interfaces/Time in seconds or nanoseconds, and the simulation time a ROS
message carries (its log time in a recording). The one place stamps are converted: the analysis,
the audit, the Rerun logging, the movie and the nodes' conversions (uam_planner.nodes.conversions)
all use these. rclpy-free (duck-typed: anything with ``sec`` and ``nanosec``)."""

from __future__ import annotations

from datetime import datetime, timezone
from typing import Any

#: the scenario's start instant for header stamps in real UTC (std_msgs_export, foxglove_live)
DEFAULT_SCENARIO_START_UTC = "2025-01-06T00:00:00Z"
#: ``scenario_start_utc`` value for header stamps in simulation time, the clock of every other topic
SIM_CLOCK = "sim"
_NS = 1_000_000_000


def stamp_s(stamp: Any) -> float:
    """builtin_interfaces/Time (or anything with ``sec`` and ``nanosec``) -> seconds [s]."""
    return int(stamp.sec) + int(stamp.nanosec) * 1e-9


def stamp_ns(stamp: Any) -> int:
    """builtin_interfaces/Time -> nanoseconds [ns] (exact)."""
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def sim_stamp_ns(msg: Any) -> int | None:
    """The simulation time a message carries [ns], or None if its type carries none.

    ``header.stamp`` (FleetState, FlightPlan, PlanningReport, PoseArray), ``clock`` (/clock),
    ``epoch_time`` (EpochSync), ``request_time`` (FlightRequest). A zero stamp is simulation
    time 0 (the first step of a run), not a missing one.
    """
    for path in (("header", "stamp"), ("clock",), ("epoch_time",), ("request_time",)):
        obj = msg
        for attr in path:
            obj = getattr(obj, attr, None)
            if obj is None:
                break
        if obj is not None and hasattr(obj, "sec") and hasattr(obj, "nanosec"):
            return stamp_ns(obj)
    return None


def scenario_start_ns(text: str) -> int:
    """Nanoseconds since the Unix epoch of an ISO 8601 instant with a time zone, or 0 for
    :data:`SIM_CLOCK` (``"sim"``: stamps in simulation time).

    ``"2025-01-06T00:00:00Z"`` or ``"2025-01-06T08:00:00+08:00"``. Raises ValueError naming
    ``scenario_start_utc`` and the value if it does not parse, has no zone, or is before 1990
    (viewers take earlier stamps for relative times).
    """
    if text == SIM_CLOCK:
        return 0
    try:
        when = datetime.fromisoformat(str(text).replace("Z", "+00:00"))
    except ValueError:
        raise ValueError(f"scenario_start_utc: {text!r} is not an ISO 8601 time like "
                         f"{DEFAULT_SCENARIO_START_UTC!r}") from None
    if when.tzinfo is None:
        raise ValueError(f"scenario_start_utc: {text!r} has no time zone (end it with 'Z' for UTC)")
    if when.year < 1990 or when.year >= 2100:
        raise ValueError(f"scenario_start_utc: {text!r} must lie in 1990..2099")
    delta = when.astimezone(timezone.utc) - datetime(1970, 1, 1, tzinfo=timezone.utc)
    return (delta.days * 86400 + delta.seconds) * _NS + delta.microseconds * 1000
