"""Conversions between uam_msgs messages and the planning library's types, and the topic QoS.

Glue only: the library works in float seconds and numpy arrays, the messages carry
builtin_interfaces/Time and geometry_msgs. Shared by every node of the graph so they agree.
"""

from __future__ import annotations

import math

import numpy as np
from builtin_interfaces.msg import Time
from geometry_msgs.msg import Point
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from uam_msgs.msg import FlightPlan, FlightRequest, MwisInstance, PlanningReport, Waypoint

from uam_planner.planning import EpochReport, Flight
from uam_planner.planning import FlightRequest as LibRequest
from uam_planner.trajectory import Trajectory

FRAME_ID = "enu"

# Topics of the node graph.
TOPIC_REQUESTS = "/uam/requests"
TOPIC_PLANS = "/uam/flight_plans"
TOPIC_REPORTS = "/uam/planning_reports"
TOPIC_FLEET = "/uam/fleet_state"
TOPIC_POSES = "/uam/fleet_poses"
TOPIC_SYNC = "/uam/epoch_sync"
SERVICE_SOLVE = "/uam/solve_mwis"

# Nothing of the run may be lost, and a late subscriber (viewer, recorder) still gets every plan.
# (KEEP_LAST with a deep history rather than KEEP_ALL: a KEEP_ALL writer blocks when a reader lags.)
QOS_LATCHED = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=20000, reliability=ReliabilityPolicy.RELIABLE,
                         durability=DurabilityPolicy.TRANSIENT_LOCAL)
# High-rate streams (fleet state every step): reliable so recordings are complete.
QOS_STREAM = QoSProfile(history=HistoryPolicy.KEEP_LAST, depth=1000, reliability=ReliabilityPolicy.RELIABLE,
                        durability=DurabilityPolicy.VOLATILE)


def to_time(t_s: float) -> Time:
    """Simulation seconds -> builtin_interfaces/Time (rounded to the nanosecond)."""
    if not math.isfinite(t_s):
        raise ValueError(f"time {t_s!r} is not finite")
    total_ns = int(round(t_s * 1e9))
    return Time(sec=total_ns // 1_000_000_000, nanosec=total_ns % 1_000_000_000)


def from_time(t: Time) -> float:
    """builtin_interfaces/Time -> simulation seconds."""
    return t.sec + t.nanosec * 1e-9


def request_to_msg(req: LibRequest) -> FlightRequest:
    return FlightRequest(
        request_id=req.request_id, origin_id=req.origin_id, destination_id=req.destination_id,
        request_time=to_time(req.request_time_s), earliest_departure=to_time(req.earliest_departure_s),
        latest_departure=to_time(req.latest_departure_s))


def request_from_msg(msg: FlightRequest) -> LibRequest:
    return LibRequest(
        request_id=msg.request_id, origin_id=msg.origin_id, destination_id=msg.destination_id,
        request_time_s=from_time(msg.request_time), earliest_departure_s=from_time(msg.earliest_departure),
        latest_departure_s=from_time(msg.latest_departure))


def _plan_header(plan: FlightPlan, t_s: float) -> None:
    plan.header.stamp = to_time(t_s)
    plan.header.frame_id = FRAME_ID


def approved_plan(flight: Flight, t_s: float, policy: str) -> FlightPlan:
    """FlightPlan message for an approved flight decided at ``t_s``."""
    traj = flight.trajectory
    plan = FlightPlan(
        request_id=flight.request_id, outcome=FlightPlan.OUTCOME_APPROVED, reason="",
        origin_id=flight.origin_id, destination_id=flight.destination_id, epoch_index=int(flight.epoch_index),
        departure_time=to_time(flight.departure_s), arrival_time=to_time(flight.arrival_s),
        route_node_ids=list(flight.route_node_ids),
        waypoints=[Waypoint(position=Point(x=float(p[0]), y=float(p[1]), z=float(p[2])), time=to_time(float(t)))
                   for t, p in zip(traj.times_s, traj.points_m)],
        length_m=float(flight.length_m), weight=float(flight.weight), candidate_index=int(flight.candidate_index),
        method=policy, backend=flight.backend or "")
    _plan_header(plan, t_s)
    return plan


def unapproved_plan(request_id: str, origin_id: str, destination_id: str, outcome: int, reason: str,
                    t_s: float, epoch_index: int, policy: str) -> FlightPlan:
    """FlightPlan message for a rejected or expired request."""
    plan = FlightPlan(request_id=request_id, outcome=outcome, reason=reason, origin_id=origin_id,
                      destination_id=destination_id, epoch_index=int(epoch_index), method=policy)
    _plan_header(plan, t_s)
    return plan


def trajectory_from_plan(plan: FlightPlan) -> Trajectory:
    """The 4D trajectory of an approved FlightPlan (waypoint times and ENU positions)."""
    times = np.array([from_time(w.time) for w in plan.waypoints], dtype=np.float64)
    points = np.array([[w.position.x, w.position.y, w.position.z] for w in plan.waypoints], dtype=np.float64)
    return Trajectory(times, points)


def report_to_msg(report: EpochReport) -> PlanningReport:
    """PlanningReport message (with the MWIS instance as solved) from the library's EpochReport."""
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
