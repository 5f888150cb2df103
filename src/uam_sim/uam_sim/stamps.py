"""The simulation time a ROS message carries, for its log time in a recording."""

from __future__ import annotations

from typing import Any


def _time_ns(stamp: Any) -> int:
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
            return _time_ns(obj)
    return None
