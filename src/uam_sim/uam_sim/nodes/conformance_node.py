"""Conformance monitor node: each flight compared with its plan at every fleet state.

    ros2 run uam_sim conformance_monitor --ros-args -p lateral_m:=30.0 -p time_s:=10.0

Subscribes to uam/flight_plans (the approved plans: the reference) and uam/fleet_state (the
positions as flown), publishes uam/conformance (uam_msgs/Conformance) for every fleet state: per
vehicle with a plan, conforming or not, the lateral, vertical and time errors and how long its
excursion has lasted (uam_sim.world.conformance.ConformanceMonitor). The recorder records it. At the
end of the run (the simulator's ``finished`` announcement, once the fleet state of that time
was compared) it logs the run's F3548 statistics and exits.

Why a node of its own (docs/disturbances.md): conformance monitoring is a USS function that
sees what any USS sees, the published intents and the reported positions, not the simulator's
truth (the simulator flies the disturbance model) nor the planner's state; as a separate
publisher its output is recorded and can be audited, and the reaction (re-planning a
nonconforming flight) subscribes to it. The first approved plan of a vehicle id is its
reference (a later one with the same id is ignored until plan versions exist).
Parameters: uam_contract.params.CONFORMANCE_MONITOR (docs/parameters.md).
"""

from __future__ import annotations

import sys

from rclpy.node import Node
from uam_msgs.msg import Conformance, EpochSync, FleetState, FlightPlan

from uam_bringup import qos
from uam_bringup.params import declare_table
from uam_bringup.runtime import run_node
from uam_contract import names as c
from uam_contract import wire
from uam_contract.params import CONFORMANCE_MONITOR
from uam_planner.nodes import conversions as m
from uam_sim.world.conformance import ConformanceBounds, ConformanceMonitor


class ConformanceNode(Node):
    def __init__(self, **kwargs):
        super().__init__("conformance_monitor", **kwargs)
        p = declare_table(self, CONFORMANCE_MONITOR)
        self.bounds = ConformanceBounds(p["lateral_m"], p["vertical_m"], p["time_s"])
        self.monitor = ConformanceMonitor(self.bounds)
        self._versions: dict[str, int] = {}
        self.finished = False
        self.samples = 0
        self._end_t: float | None = None     # the run's end, once the simulator announced it
        self._last_t = -float("inf")         # the time of the last fleet state compared
        self._pub = self.create_publisher(Conformance, c.TOPIC_CONFORMANCE, qos.QOS_STREAM)
        self.create_subscription(FlightPlan, c.TOPIC_PLANS, self._on_plan, qos.QOS_LATCHED)
        self.create_subscription(FleetState, c.TOPIC_FLEET, self._on_fleet, qos.QOS_STREAM)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)
        self.get_logger().info(f"conformance monitor: lateral {self.bounds.lateral_m:g} m, vertical "
                               f"{self.bounds.vertical_m:g} m, time {self.bounds.time_s:g} s")

    def _on_plan(self, plan: FlightPlan) -> None:
        if plan.outcome != FlightPlan.OUTCOME_APPROVED:
            return
        key = wire.scoped_id(plan.operator_id, plan.request_id)
        version = int(getattr(plan, "version", 0) or 0)
        if self.monitor.has_plan(key) and version <= self._versions.get(key, 1):
            return   # the first approved plan, then each newer version, is the reference
        self._versions[key] = max(version, 1)
        try:
            self.monitor.set_plan(key, m.trajectory_from_plan(plan))
        except ValueError as exc:
            self.get_logger().warning(f"plan {wire.echo(key)} has no valid trajectory: {exc}")

    def _on_fleet(self, msg: FleetState) -> None:
        t = m.from_time(msg.header.stamp)
        ids = [v.vehicle_id for v in msg.vehicles]
        pos = [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]
        states = self.monitor.update(t, ids, pos)
        self.samples += 1
        out = Conformance(header=msg.header, step_index=msg.step_index, session=msg.session,
                          vehicle_ids=[s.flight_id for s in states],
                          conforming=[s.conforming for s in states],
                          lateral_m=[s.lateral_m for s in states],
                          vertical_m=[s.vertical_m for s in states],
                          time_error_s=[s.time_err_s for s in states],
                          excursion_s=[0.0 if s.excursion_start_s is None else t - s.excursion_start_s
                                       for s in states],
                          lateral_bound_m=self.bounds.lateral_m, vertical_bound_m=self.bounds.vertical_m,
                          time_bound_s=self.bounds.time_s,
                          excursions=len(self.monitor.excursions) + self.monitor.open_excursions)
        self._pub.publish(out)
        self._last_t = t
        self._maybe_finish()

    def _on_sync(self, msg: EpochSync) -> None:
        if msg.sender == "simulator" and msg.finished and self._end_t is None:
            self._end_t = m.from_time(msg.epoch_time)   # the last fleet state's time
            self._maybe_finish()

    def _maybe_finish(self) -> None:
        """Done once the run ended and its last fleet state was compared (states may still be
        queued when the end is announced)."""
        if self._end_t is not None and self._last_t >= self._end_t - 1e-9 and not self.finished:
            st = self.monitor.statistics()
            self.get_logger().info(
                f"run finished: {self.samples} fleet states, {st.flights} flights, {st.flight_hours:.2f} flight "
                f"hours: {st.conformance_percent:.2f} % in conformance, {st.excursions} excursions "
                f"({st.excursions_per_flight_hour:.2f} per flight hour), longest {st.longest_excursion_s:.0f} s")
            self.finished = True


def main(args=None) -> int:
    return run_node(ConformanceNode, "conformance_monitor", args, linger_s=0.5)


if __name__ == "__main__":
    sys.exit(main())
