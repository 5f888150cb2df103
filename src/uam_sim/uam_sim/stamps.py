"""Stamps: a builtin_interfaces/Time in seconds or nanoseconds, and the simulation time a ROS
message carries (its log time in a recording). The one place stamps are converted: the analysis,
the audit, the Rerun logging, the movie and the nodes' conversions (uam_bringup.conversions)
all use these. rclpy-free (duck-typed: anything with ``sec`` and ``nanosec``)."""

from __future__ import annotations

from typing import Any


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
