"""The conformance monitor node (issue 23): a flight pushed off its plan by a hand-set tail wind
is published as nonconforming at the right step on uam/conformance."""

from __future__ import annotations

import numpy as np
import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from uam_msgs.msg import Conformance, FleetState, FlightPlan, VehicleState  # noqa: E402

from uam_bringup import qos  # noqa: E402
from uam_contract import names as c  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402
from uam_planner.planning import Flight  # noqa: E402
from uam_planner.trajectory import Trajectory  # noqa: E402
from uam_sim.world.disturbance import DisturbanceConfig, FlightDraws, fly  # noqa: E402
from uam_sim.nodes.conformance_node import ConformanceNode  # noqa: E402

pytestmark = pytest.mark.ros


def test_a_flight_pushed_off_its_plan_is_flagged_at_the_right_step(ros_context, spin_until):
    # east 1,000 m in 100 s; a 2.5 m/s tail wind flies it at 12.5 m/s: time error -0.25 t,
    # beyond the 10 s bound from t = 41 s (hand-computed in test_disturbance_conformance.py)
    plan_traj = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0.0, 50.0], [1000.0, 0.0, 50.0]]))
    flown = fly(plan_traj, FlightDraws(), DisturbanceConfig(wind_speed_mps=2.5, wind_from_deg=270.0))
    flight = Flight("r1", "A", "B", ("A", "B"), plan_traj, 0.0, 100.0, 1000.0, 1.0, 0, "mwis", "greedy", 0,
                    operator_id="op")
    plan = m.approved_plan(flight, 0.0, "mwis")
    plan.operator_id = "op"
    monitor = ConformanceNode(context=ros_context)
    probe = rclpy.create_node("conformance_probe", context=ros_context)
    got: list = []
    probe.create_subscription(Conformance, c.TOPIC_CONFORMANCE, got.append, qos.QOS_STREAM)
    plans = probe.create_publisher(FlightPlan, c.TOPIC_PLANS, qos.QOS_LATCHED)
    fleet = probe.create_publisher(FleetState, c.TOPIC_FLEET, qos.QOS_STREAM)
    ex = SingleThreadedExecutor(context=ros_context)
    ex.add_node(monitor)
    ex.add_node(probe)
    try:
        plans.publish(plan)
        assert spin_until(ex, lambda: monitor.monitor.has_plan("op/r1"))
        assert spin_until(ex, lambda: fleet.get_subscription_count() >= 1
                          and probe.count_publishers(c.TOPIC_CONFORMANCE) >= 1 and len(
                              monitor.get_publishers_info_by_topic(probe.resolve_topic_name(c.TOPIC_CONFORMANCE))) >= 1)
        for k in range(0, 60):
            p = flown.position_at(float(k))
            msg = FleetState(step_index=k, vehicles=[VehicleState(vehicle_id="op/r1")])
            msg.header.stamp = m.to_time(float(k))
            msg.vehicles[0].position.x, msg.vehicles[0].position.y, msg.vehicles[0].position.z = map(float, p)
            fleet.publish(msg)
            assert spin_until(ex, lambda: len(got) > k, timeout_s=10.0), f"no conformance for step {k}"
        flags = [bool(g.conforming[0]) for g in got]
        assert flags == [True] * 41 + [False] * 19
        assert got[40].time_error_s[0] == pytest.approx(-10.0) and got[41].excursion_s[0] == 0.0
        assert got[50].excursion_s[0] == pytest.approx(9.0) and got[50].excursions == 1
        assert got[0].lateral_bound_m == 30.0 and got[0].time_bound_s == 10.0
    finally:
        ex.shutdown()
        probe.destroy_node()
        monitor.destroy_node()
