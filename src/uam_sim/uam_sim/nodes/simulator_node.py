"""Simulator node: owns simulation time, moves the fleet, publishes /clock and the fleet state.

    ros2 run uam_sim simulator --ros-args --params-file config/simulator.yaml

Publishes /clock (rosgraph_msgs/Clock; every other node runs with use_sim_time), /uam/fleet_state
(uam_msgs/FleetState) and /uam/fleet_poses (geometry_msgs/PoseArray, for generic viewers) at
every step, and announces planning epochs on /uam/epoch_sync. Subscribes /uam/flight_plans and
flies every approved plan exactly as planned.

Lockstep (mode "lockstep", the default): at each epoch time t the simulator announces the epoch
and does not move past t until the planner has acknowledged it and every plan the planner
counted has arrived; between epochs it steps as fast as it can. /clock alone cannot give this
(rclpy takes /clock best effort, depth 1, and timers fire once after a jump), so a run's result
does not depend on CPU speed only because of this handshake. Mode "realtime" keeps the same
handshake but paces steps at `real_time_factor` x wall time, for watching live.

The run ends at `duration_s`: the simulator announces `finished`, and the other nodes exit.
"""

from __future__ import annotations

import math
import sys
import time
from functools import partial

from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from uam_msgs.msg import EpochSync, FleetState, FlightPlan

from uam_bringup import contract as c
from uam_bringup import conversions as m
from uam_bringup import qos
from uam_bringup.runtime import run_node
from uam_bringup.params import declare
from uam_sim.cdr import encode_fleet_state, encode_pose_array, yaw_quaternions
from uam_sim.fleet import Fleet

MODES = ("lockstep", "realtime")


class SimulatorNode(Node):
    def __init__(self, **kwargs):
        super().__init__("simulator", **kwargs)
        d = partial(declare, self)
        self.step_s = d("step_s", 1.0, "simulation step [s]", 0.001, 3600.0)
        self.duration_s = d("duration_s", 3500.0, "simulated time after which the run ends [s]", 0.0, 1e7)
        self.epoch_s = d("epoch_s", 30.0, "time between planning epochs [s]; a multiple of step_s", 0.001, 86400.0)
        self.mode = d("mode", "lockstep", "'lockstep': as fast as the planner allows, result independent of CPU "
                      "speed; 'realtime': paced at real_time_factor", choices=MODES)
        self.rtf = d("real_time_factor", 1.0, "in realtime mode: simulated seconds per wall second", 0.001, 1e5)
        self.expected_subscribers = d("expected_subscribers", 2, "start only when this many nodes subscribe to "
                                      "/uam/epoch_sync (planner, request_generator, recorder)", 0, 100)
        self.expected_stream_subscribers = d(
            "expected_stream_subscribers", 0, "also wait until this many nodes subscribe to /uam/fleet_state and "
            "/uam/fleet_poses (1 with the recorder), so a recording starts at t = 0", 0, 100)
        self.ack_timeout_s = d("ack_timeout_s", 120.0, "wall time [s] to wait for an epoch acknowledgement "
                               "before ending the run with an error", 0.1, 86400.0)
        ratio = self.epoch_s / self.step_s
        if not math.isclose(ratio, round(ratio), rel_tol=0, abs_tol=1e-9):
            raise ValueError(f"parameter epoch_s: {self.epoch_s} is not a multiple of step_s {self.step_s}")
        self.steps_per_epoch = int(round(ratio))

        self._clock_pub = self.create_publisher(Clock, c.TOPIC_CLOCK, qos.QOS_CLOCK)
        self._fleet_pub = self.create_publisher(FleetState, c.TOPIC_FLEET, qos.QOS_STREAM)
        self._pose_pub = self.create_publisher(PoseArray, c.TOPIC_POSES, qos.QOS_STREAM)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.create_subscription(FlightPlan, c.TOPIC_PLANS, self._on_plan, qos.QOS_LATCHED)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)

        self.fleet = Fleet()
        self.step_index = 0                 # t = step_index * step_s
        self.plans_received = 0
        self._planner_acks: dict[int, int] = {}
        self._waiting_epoch: int | None = None
        self._wait_started = 0.0
        self.started = False
        self.finished = False
        self.error = ""
        self.active_samples: list[int] = []  # airborne vehicles at each step, for the summary
        self._wall_start = 0.0
        period = self.step_s / self.rtf if self.mode == "realtime" else 0.02
        self._timer = self.create_timer(period, self._on_timer)  # wall clock: this node owns sim time
        self.get_logger().info(
            f"simulator: {self.mode}, step {self.step_s:g} s, epoch {self.epoch_s:g} s, duration {self.duration_s:g} s; "
            f"waiting for {self.expected_subscribers} subscriber(s) of {c.TOPIC_SYNC}")

    @property
    def exit_code(self) -> int:
        """1 when the run ended on an error (no acknowledgement from the planner), else 0."""
        return 1 if self.error else 0

    @property
    def t_s(self) -> float:
        return self.step_index * self.step_s

    # ---- inputs ------------------------------------------------------------------------------
    def _on_plan(self, plan: FlightPlan) -> None:
        self.plans_received += 1
        if plan.outcome == FlightPlan.OUTCOME_APPROVED:
            try:
                self.fleet.add(plan.request_id, m.trajectory_from_plan(plan))
            except ValueError as exc:
                self.get_logger().error(f"cannot fly plan {plan.request_id!r}: {exc}")
        self._maybe_resume()

    def _on_sync(self, msg: EpochSync) -> None:
        if msg.sender == "planner":
            self._planner_acks[int(msg.epoch_index)] = int(msg.plans_published)
            self._maybe_resume()

    # ---- stepping ------------------------------------------------------------------------------
    def _epoch_at(self, step_index: int) -> int | None:
        return step_index // self.steps_per_epoch if step_index % self.steps_per_epoch == 0 else None

    def _acked(self, k: int) -> bool:
        need = self._planner_acks.get(k)
        return need is not None and self.plans_received >= need

    def _maybe_resume(self) -> None:
        if self._waiting_epoch is not None and self._acked(self._waiting_epoch):
            self._waiting_epoch = None
            self._publish_state()
            self.step_index += 1
            if self.mode == "lockstep":
                self._run_until_blocked()

    def _on_timer(self) -> None:
        if self.finished:
            return
        if not self.started:
            if (self._sync_pub.get_subscription_count() < self.expected_subscribers
                    or self._fleet_pub.get_subscription_count() < self.expected_stream_subscribers
                    or self._pose_pub.get_subscription_count() < self.expected_stream_subscribers):
                return
            self.started = True
            self._wall_start = time.monotonic()
            self.get_logger().info("all subscribers present: starting the run")
            if self.mode == "lockstep":
                self._timer.timer_period_ns = int(0.5e9)  # from now on only a watchdog
            self._run_until_blocked()
            return
        if self._waiting_epoch is not None:
            if time.monotonic() - self._wait_started > self.ack_timeout_s:
                self.error = (f"no acknowledgement of epoch {self._waiting_epoch} from the planner within "
                              f"{self.ack_timeout_s:g} s")
                self.get_logger().error(self.error + "; ending the run")
                self._finish()
            return
        if self.mode == "realtime":
            self._step_once()

    def _run_until_blocked(self) -> None:
        while not self.finished and self._waiting_epoch is None:
            self._step_once()

    def _step_once(self) -> None:
        if self.t_s > self.duration_s + 1e-9:
            self._finish()
            return
        k = self._epoch_at(self.step_index)
        if k is not None:
            self._waiting_epoch = k
            self._wait_started = time.monotonic()
            self._sync_pub.publish(EpochSync(epoch_index=k, epoch_time=m.to_time(self.t_s), sender="simulator"))
            if self._acked(k):  # (only after a restart of the planner with latched acks)
                self._maybe_resume()
            return
        self._publish_state()
        self.step_index += 1

    def _publish_state(self) -> None:
        t = self.t_s
        stamp = m.to_time(t)
        self._clock_pub.publish(Clock(clock=stamp))
        fs = self.fleet.sample(t)
        self.active_samples.append(len(fs))
        # Serialized directly from the fleet arrays (uam_sim.cdr): same bytes as the message objects,
        # a fraction of the cost (see uam_sim/cdr.py).
        self._fleet_pub.publish(encode_fleet_state(
            stamp.sec, stamp.nanosec, c.FRAME_ID, self.step_index, fs.vehicle_ids, fs.positions_m,
            fs.velocities_mps, fs.phases, fs.segment_indices, fs.flown_m, fs.remaining_m))
        self._pose_pub.publish(encode_pose_array(
            stamp.sec, stamp.nanosec, c.FRAME_ID, fs.positions_m, yaw_quaternions(fs.velocities_mps)))

    def _finish(self) -> None:
        if self.finished:
            return
        self.finished = True
        self._sync_pub.publish(EpochSync(epoch_index=self.step_index // self.steps_per_epoch,
                                         epoch_time=m.to_time(min(self.t_s, self.duration_s)),
                                         sender="simulator", finished=True))
        wall = time.monotonic() - self._wall_start if self.started else 0.0
        sim = min(self.t_s, self.duration_s)
        avg = sum(self.active_samples) / len(self.active_samples) if self.active_samples else 0.0
        self.get_logger().info(
            f"run finished at t={sim:g} s: {self.fleet.total_added} approved flights flown, "
            f"{self.plans_received} plans received, average airborne {avg:.2f}; wall {wall:.2f} s, "
            f"real-time factor {sim / wall if wall > 0 else float('inf'):.1f}")


def main(args=None) -> int:
    return run_node(SimulatorNode, "simulator", args, linger_s=1.0)


if __name__ == "__main__":
    sys.exit(main())
