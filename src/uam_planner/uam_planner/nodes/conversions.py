"""Conversions between uam_msgs messages and the libraries' types. rclpy-free.

Reading is duck-typed: any object with the message's field names works, so the same functions
read generated messages, messages decoded from a recording by ``rosbags`` or ``mcap_ros2``, and
plain namespaces. Building messages imports the generated classes lazily (only the nodes do it).

The library works in float seconds and numpy arrays; the messages carry builtin_interfaces/Time
and geometry_msgs. Shared by every node of the graph so they agree (the planner's and the
simulation's nodes; the solver's own service conversions are uam_solvers.nodes.conversions).
"""

from __future__ import annotations

import math
from typing import Any

import numpy as np

from uam_contract.names import FRAME_ID
from uam_contract.stamps import stamp_ns as _stamp_ns
from uam_contract.stamps import stamp_s
from uam_planner.planning import EpochReport, Flight
from uam_planner.planning import FlightRequest as LibRequest
from uam_planner.trajectory import Trajectory
from uam_solvers.nodes.conversions import problem_from_solve_request, solve_answer, solve_request  # noqa: F401

NS_PER_S = 1_000_000_000


# ---- time ----------------------------------------------------------------------------------------

def time_fields(t_s: float) -> tuple[int, int]:
    """Simulation seconds -> (sec, nanosec), rounded to the nanosecond."""
    if not math.isfinite(t_s):
        raise ValueError(f"time {t_s!r} is not finite")
    total_ns = int(round(t_s * 1e9))
    return total_ns // NS_PER_S, total_ns % NS_PER_S


def to_time(t_s: float):
    """Simulation seconds -> builtin_interfaces/Time (rounded to the nanosecond)."""
    from builtin_interfaces.msg import Time

    sec, nanosec = time_fields(t_s)
    return Time(sec=sec, nanosec=nanosec)


#: builtin_interfaces/Time -> nanoseconds (uam_contract.stamps.stamp_ns)
stamp_ns = _stamp_ns


#: builtin_interfaces/Time (or anything with ``sec`` and ``nanosec``) -> seconds: the one helper
#: (uam_contract.stamps.stamp_s), under the name the nodes use.
from_time = stamp_s


# ---- requests ------------------------------------------------------------------------------------

def request_to_msg(req: LibRequest, operator_id: str = ""):
    """uam_msgs/FlightRequest of a library request (its id unscoped, see :func:`scoped_id`)."""
    from uam_msgs.msg import FlightRequest

    msg = FlightRequest(
        request_id=req.request_id, origin_id=req.origin_id, destination_id=req.destination_id,
        request_time=to_time(req.request_time_s), earliest_departure=to_time(req.earliest_departure_s),
        latest_departure=to_time(req.latest_departure_s), priority=int(req.priority))
    if operator_id and hasattr(msg, "operator_id"):
        msg.operator_id = operator_id
    return msg


def request_from_msg(msg: Any, request_id: str | None = None) -> LibRequest:
    """Library request of a FlightRequest message; ``request_id`` replaces the message's id
    (the planner node passes the operator-scoped id)."""
    return LibRequest(
        request_id=msg.request_id if request_id is None else request_id,
        origin_id=msg.origin_id, destination_id=msg.destination_id,
        request_time_s=from_time(msg.request_time), earliest_departure_s=from_time(msg.earliest_departure),
        latest_departure_s=from_time(msg.latest_departure), priority=int(msg.priority))


# ---- plans ---------------------------------------------------------------------------------------

def _plan_header(plan, t_s: float) -> None:
    plan.header.stamp = to_time(t_s)
    plan.header.frame_id = FRAME_ID


def approved_plan(flight: Flight, t_s: float, policy: str, request_id: str | None = None):
    """FlightPlan message for an approved flight decided at ``t_s`` [s]."""
    from geometry_msgs.msg import Point
    from uam_msgs.msg import FlightPlan, Waypoint

    traj = flight.trajectory
    plan = FlightPlan(
        request_id=flight.request_id if request_id is None else request_id,
        outcome=FlightPlan.OUTCOME_APPROVED, reason="",
        origin_id=flight.origin_id, destination_id=flight.destination_id, epoch_index=int(flight.epoch_index),
        departure_time=to_time(flight.departure_s), arrival_time=to_time(flight.arrival_s),
        route_node_ids=list(flight.route_node_ids),
        waypoints=[Waypoint(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])), time=to_time(float(t)))
                   for t, p in zip(traj.times_s, traj.points_m)],
        length_m=float(flight.length_m), weight=float(flight.weight), candidate_index=int(flight.candidate_index),
        method=policy, backend=flight.backend or "")
    if hasattr(plan, "version"):  # plan versions (FlightPlan.msg, docs/replanning.md)
        plan.version = int(getattr(flight, "version", 1))
        plan.effective_time = to_time(float(getattr(flight, "effective_s", flight.departure_s)))
        plan.state = plan_state(flight, t_s)
    _plan_header(plan, t_s)
    return plan


#: F3548 state names (uam_planner.replanning.flight_state) -> FlightPlan.STATE_* values
STATES = {"Accepted": 1, "Activated": 2, "Nonconforming": 3, "Contingent": 4, "Ended": 5}


def plan_state(flight: Flight, t_s: float) -> int:
    """FlightPlan.STATE_* of ``flight`` (its newest version) at ``t_s`` [s]."""
    from uam_planner.replanning import flight_state
    return STATES[flight_state(flight, t_s)]


def plan_update_msg(update: Any, t_s: float, policy: str, request_id: str | None = None):
    """FlightPlan message of a re-plan (a ``uam_planner.replanning.PlanUpdate``) decided at the
    epoch at ``t_s``: the new version of the flight, from ``effective_time`` on, naming the
    constraint(s) and the kind in ``update_kind`` and the sentence in ``reason``. A cancellation
    is OUTCOME_REJECTED with no waypoints and state Ended; every other kind is OUTCOME_APPROVED
    with the new trajectory (a contingency: state Contingent; a nonconforming flight's update,
    uam_planner.nonconformance: state Nonconforming, the state it was in until this version)."""
    from uam_msgs.msg import FlightPlan

    rid = update.request_id if request_id is None else request_id
    if update.flight is None:
        prev = update.previous
        plan = unapproved_plan(rid, prev.origin_id if prev is not None else "",
                               prev.destination_id if prev is not None else "", FlightPlan.OUTCOME_REJECTED,
                               str(update.reason), t_s, int(prev.epoch_index) if prev is not None else 0, policy)
        plan.state = FlightPlan.STATE_ENDED
    else:
        plan = approved_plan(update.flight, t_s, policy, request_id=rid)
        plan.reason = str(update.reason)
        if update.kind == "contingency":
            plan.state = FlightPlan.STATE_CONTINGENT
        elif update.kind == "nonconforming":   # it was outside its intent until now
            plan.state = FlightPlan.STATE_NONCONFORMING
    plan.version = int(update.version)
    plan.effective_time = to_time(float(update.effective_s))
    plan.constraint_ids = [str(c) for c in update.constraint_ids]
    plan.update_kind = str(update.kind)
    # the reaction's updates carry the observed progress rate they were re-timed from
    plan.observed_progress_rate = float(getattr(update, "observed_rate", 0.0) or 0.0)
    return plan


def unapproved_plan(request_id: str, origin_id: str, destination_id: str, outcome: int, reason: str,
                    t_s: float, epoch_index: int, policy: str):
    """FlightPlan message for a rejected or expired request."""
    from uam_msgs.msg import FlightPlan

    plan = FlightPlan(request_id=request_id, outcome=outcome, reason=reason, origin_id=origin_id,
                      destination_id=destination_id, epoch_index=int(epoch_index), method=policy)
    _plan_header(plan, t_s)
    return plan


def plan_waypoints(plan: Any) -> tuple[np.ndarray, np.ndarray]:
    """(times_s (p,), points_m (p, 3)) of a FlightPlan's waypoints."""
    times = np.array([from_time(w.time) for w in plan.waypoints], dtype=np.float64)
    points = np.array([[w.position.x, w.position.y, w.position.z] for w in plan.waypoints],
                      dtype=np.float64).reshape(-1, 3)
    return times, points


def trajectory_from_plan(plan: Any) -> Trajectory:
    """The 4D trajectory of an approved FlightPlan (waypoint times and ENU positions)."""
    return Trajectory(*plan_waypoints(plan))


def flight_from_plan(plan: Any, request_id: str | None = None) -> Flight:
    """The library Flight of an approved FlightPlan (e.g. to restore a restarted planner)."""
    traj = trajectory_from_plan(plan)
    return Flight(request_id=plan.request_id if request_id is None else request_id,
                  origin_id=plan.origin_id, destination_id=plan.destination_id,
                  route_node_ids=tuple(plan.route_node_ids), trajectory=traj,
                  departure_s=from_time(plan.departure_time), arrival_s=from_time(plan.arrival_time),
                  length_m=float(plan.length_m), weight=float(plan.weight),
                  candidate_index=int(plan.candidate_index), method=str(plan.method),
                  backend=str(plan.backend), epoch_index=int(plan.epoch_index),
                  version=max(1, int(getattr(plan, "version", 1) or 1)),
                  effective_s=from_time(plan.effective_time) if int(getattr(plan, "version", 0) or 0) > 1
                  else float("nan"),
                  contingent=int(getattr(plan, "state", 0) or 0) == 4)


# ---- reports -------------------------------------------------------------------------------------

def report_to_msg(report: EpochReport):
    """PlanningReport message (with the MWIS instance as solved) from the library's EpochReport."""
    from uam_msgs.msg import MwisInstance, PlanningReport

    edges = np.asarray(report.edges_array, dtype=np.int64).reshape(-1, 2)
    msg = PlanningReport(
        epoch_index=int(report.epoch_index), policy=report.policy, pending_requests=int(report.pending),
        eligible_requests=int(report.eligible), candidates=int(report.candidates),
        candidates_discarded=int(report.discarded), vertices=int(report.vertices), edges=int(report.edges),
        conflict_edges=int(report.conflict_edges), approved=int(report.approved), rejected=int(report.rejected),
        expired=int(report.expired), active_flights=int(report.active_flights),
        instance=MwisInstance(
            weights=[float(w) for w in report.weights],
            edges_u=[int(u) for u in edges[:, 0]], edges_v=[int(v) for v in edges[:, 1]],
            vertex_request_ids=[str(r) for r in report.vertex_request_ids],
            vertex_candidate_index=[int(c) for c in report.vertex_candidate_index],
            selected=[int(s) for s in report.selected]),
        objective=float(report.objective), solve_time_s=float(report.solve_time_s),
        planning_time_s=float(report.planning_time_s), proven_optimal=bool(report.proven_optimal),
        backend_requested=report.backend_requested, backend_used=report.backend_used,
        fallback=bool(report.fallback), fallback_reason=report.fallback_reason)
    msg.header.stamp = to_time(report.t_s)
    msg.header.frame_id = FRAME_ID
    return msg


# the SolveMwis conversions are the solver's (uam_solvers.nodes.conversions); re-exported for the planner


def plan_level_m(plan: Any) -> float:
    """The cruise level [m] of an approved FlightPlan on a layered network: its highest waypoint z.

    A layered flight climbs vertically from its pad to one level, keeps it over the corridors and
    descends at the destination (level changes only at vertiports), so the level is the highest z
    of the plan; FlightPlan has no level field because the waypoints already say it. NaN for a
    plan without waypoints. (On a paper network this is the highest corridor node's altitude.)
    """
    if not plan.waypoints:
        return float("nan")
    return float(max(w.position.z for w in plan.waypoints))
