"""The uam_msgs interfaces: every type round-trips through rclpy serialization, and publishers,
subscribers, services and clients of these types work inside one process."""

from __future__ import annotations

import math

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from builtin_interfaces.msg import Time  # noqa: E402
from diagnostic_msgs.msg import KeyValue  # noqa: E402
from geometry_msgs.msg import Point, Vector3  # noqa: E402
from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from rclpy.serialization import deserialize_message, serialize_message  # noqa: E402
from uam_msgs.msg import (  # noqa: E402
    EpochSync,
    FleetState,
    FlightPlan,
    FlightRequest,
    MwisInstance,
    PlanningReport,
    VehicleState,
    Waypoint,
)
from uam_msgs.srv import SolveMwis  # noqa: E402

pytestmark = pytest.mark.ros


def _time(sec: float) -> Time:
    return Time(sec=int(sec), nanosec=int(round((sec - int(sec)) * 1e9)))


def _filled_examples():
    """One fully populated instance of every message type (nested fields, arrays, constants)."""
    request = FlightRequest(
        request_id="r000042", origin_id="AD_TAMPINES", destination_id="AD_JURONG",
        request_time=_time(30.0), earliest_departure=_time(30.0), latest_departure=_time(90.0),
    )
    waypoints = [Waypoint(position=Point(x=1.5 * i, y=-2.0 * i, z=120.0), time=_time(30.0 + 10 * i)) for i in range(4)]
    plan = FlightPlan(
        request_id="r000042", outcome=FlightPlan.OUTCOME_APPROVED, reason="",
        origin_id="AD_TAMPINES", destination_id="AD_JURONG", epoch_index=1,
        departure_time=_time(30.0), arrival_time=_time(60.0), route_node_ids=["a", "b", "c", "d"],
        waypoints=waypoints, length_m=4567.25, weight=0.875, candidate_index=2, method="mwis", backend="exact",
    )
    plan.header.stamp = _time(30.0)
    plan.header.frame_id = "enu"
    vehicle = VehicleState(
        vehicle_id="r000042", position=Point(x=1.0, y=2.0, z=3.0), velocity=Vector3(x=10.0, y=0.0, z=0.0),
        phase=VehicleState.PHASE_CRUISE, segment_index=3, distance_flown_m=100.0, distance_remaining_m=50.5,
    )
    fleet = FleetState(step_index=7, vehicles=[vehicle, vehicle])
    instance = MwisInstance(
        weights=[1.0, 0.5, 0.25], edges_u=[0, 1], edges_v=[1, 2],
        vertex_request_ids=["r1", "r1", "r2"], vertex_candidate_index=[0, 1, 0], selected=[0, 2],
    )
    report = PlanningReport(
        epoch_index=3, policy="mwis", pending_requests=12, eligible_requests=10, candidates=50,
        candidates_discarded=4, vertices=46, edges=120, conflict_edges=30, approved=7, rejected=1,
        expired=2, active_flights=33, instance=instance, objective=1.25, solve_time_s=0.0021,
        planning_time_s=0.004, proven_optimal=True, backend_requested="exact", backend_used="exact",
        fallback=False, fallback_reason="",
    )
    sync = EpochSync(epoch_index=3, epoch_time=_time(90.0), sender="planner", requests_published=40,
                     plans_published=38, requests_received=40, finished=False)
    solve_request = SolveMwis.Request(
        weights=[1.0, 2.0, 3.0], edges_u=[0, 1], edges_v=[1, 2], vertex_group=[0, 0, 1], backend="exact",
        time_limit_s=1.5, seed=7, options=[KeyValue(key="num_reads", value="100")],
    )
    solve_response = SolveMwis.Response(
        success=True, message="ok", selected=[0, 2], objective=4.0, solve_time_s=0.001,
        proven_optimal=True, backend_used="exact", fallback=False, stats=[KeyValue(key="status", value="OPTIMAL")],
    )
    return [request, waypoints[0], plan, vehicle, fleet, instance, report, sync, solve_request, solve_response]


@pytest.mark.parametrize("message", _filled_examples(), ids=lambda m: type(m).__name__)
def test_every_interface_round_trips_through_serialization(message):
    data = serialize_message(message)
    assert isinstance(data, bytes) and len(data) > 4  # CDR header plus payload
    back = deserialize_message(data, type(message))
    assert back == message


def test_constants_are_distinct():
    outcomes = {FlightPlan.OUTCOME_APPROVED, FlightPlan.OUTCOME_REJECTED, FlightPlan.OUTCOME_EXPIRED}
    phases = {VehicleState.PHASE_TAKEOFF, VehicleState.PHASE_CRUISE, VehicleState.PHASE_LANDING}
    assert len(outcomes) == 3 and len(phases) == 3


def test_pub_sub_service_and_client_in_one_process(ros_context, spin_until):
    from rclpy.qos import DurabilityPolicy, QoSProfile, ReliabilityPolicy

    node = rclpy.create_node("interface_test", context=ros_context)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(node)
    try:
        received: list[FlightPlan] = []
        latched = QoSProfile(depth=10, reliability=ReliabilityPolicy.RELIABLE, durability=DurabilityPolicy.TRANSIENT_LOCAL)
        pub = node.create_publisher(FlightPlan, "/uam/flight_plans", latched)
        plan = _filled_examples()[2]
        pub.publish(plan)  # before the subscriber exists: transient local must still deliver it
        node.create_subscription(FlightPlan, "/uam/flight_plans", received.append, latched)
        assert spin_until(executor, lambda: len(received) == 1, timeout_s=10.0)
        assert received[0] == plan

        def handle(request, response):
            response.success = True
            response.selected = [i for i, w in enumerate(request.weights) if w > 1.5]
            response.objective = float(sum(request.weights[i] for i in response.selected))
            response.backend_used = request.backend or "default"
            return response

        node.create_service(SolveMwis, "/uam/solve_mwis", handle)
        client = node.create_client(SolveMwis, "/uam/solve_mwis")
        assert spin_until(executor, client.service_is_ready, timeout_s=10.0)
        future = client.call_async(SolveMwis.Request(weights=[1.0, 2.0, 3.0], edges_u=[], edges_v=[]))
        assert spin_until(executor, future.done, timeout_s=10.0)
        response = future.result()
        assert response.success and list(response.selected) == [1, 2]
        assert math.isclose(response.objective, 5.0)
        assert response.backend_used == "default"
    finally:
        executor.shutdown()
        node.destroy_node()
