"""Replay node: re-publish a recording with its original timing, /clock included.

``ros2 run uam_sim replay run.mcap --ros-args -p rate:=10.0``

Every recorded topic is published with its recorded type and the QoS its publishers offered
(reliability and durability; see ``uam_sim.views.replay.replay_qos``), the CDR bytes as recorded. A
message recorded at log time t is published (t - t_first) / rate wall seconds after the start;
``rate:=0`` publishes everything as fast as possible. Because /clock is replayed too, nodes and
viewers running with ``use_sim_time`` follow the recorded simulation time. The node exits when
everything is published (unless ``exit_when_done:=false``).
"""

from __future__ import annotations

import sys
import time

from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.duration import Duration
from rclpy.node import Node
from rclpy.qos import DurabilityPolicy, HistoryPolicy, QoSProfile, ReliabilityPolicy
from rclpy.utilities import remove_ros_args

from uam_sim.recording.mcap_schema import message_class
from uam_contract.qos_spec import QosSpec
from uam_sim.views.replay import load_plan
from uam_bringup.params import declare_table
from uam_contract.params import REPLAY
from uam_bringup.runtime import run_node

_BATCH = 500  # messages per timer tick at most, so the executor stays responsive at rate 0
_WAIT_POLL_S = 0.05  # timer period while waiting for the start delay or for subscribers [s]
_MIN_PERIOD_S = 0.001  # shortest timer period [s]: the next message is due at once
_MAX_PERIOD_S = 1.0    # longest sleep [s], so the node still notices a shutdown request


def qos_profile(spec: QosSpec) -> QoSProfile:
    """An rclpy QoSProfile from a recorded QosSpec."""
    profile = QoSProfile(
        history=HistoryPolicy.KEEP_ALL if spec.history == "keep_all" else HistoryPolicy.KEEP_LAST,
        depth=max(1, int(spec.depth)),
        reliability=ReliabilityPolicy.BEST_EFFORT if spec.reliability == "best_effort" else ReliabilityPolicy.RELIABLE,
        durability=DurabilityPolicy.TRANSIENT_LOCAL if spec.durability == "transient_local" else DurabilityPolicy.VOLATILE,
    )
    if spec.lifespan_ns:
        profile.lifespan = Duration(nanoseconds=spec.lifespan_ns)
    return profile


class ReplayNode(Node):
    """Publishes a recording (parameter ``recording`` or the ``path`` argument); ``done`` when finished."""

    def __init__(self, path: str | None = None, **kwargs) -> None:
        super().__init__("replay", **kwargs)
        p = declare_table(self, REPLAY)   # uam_contract.params.REPLAY, read-only
        path = path or p["recording"]
        if not path:
            raise ValueError("recording: give the .mcap file as the first argument or -p recording:=FILE")
        rate = p["rate"]
        topics = [t for t in (p["topics"] or []) if t]
        self.plan = load_plan(path, rate=rate, topics=topics)
        self.exit_when_done = p["exit_when_done"]
        self._steady = RclClock(clock_type=ClockType.STEADY_TIME)
        self._replay_publishers = {}
        for topic, info in self.plan.topics.items():
            self._replay_publishers[topic] = self.create_publisher(message_class(info.type_name), topic,
                                                            qos_profile(info.qos))
        self.published = 0
        self._start: float | None = None
        self._delay_s = p["start_delay_s"]
        self._wait_for = p["wait_for_subscribers"]
        self._created = time.monotonic()
        self.wakeups = 0  # timer callbacks after the start: it sleeps until the next message is due
        # a steady wall-clock timer: replay timing must not follow the /clock it publishes itself
        self._timer = self.create_timer(_WAIT_POLL_S, self._on_timer, clock=self._steady)
        self.get_logger().info(
            f"replaying {self.plan.total} messages on {len(self.plan.topics)} topics from {path} "
            f"at rate {rate:g} ({'as fast as possible' if rate == 0 else f'{self.plan.duration_s:.1f} s'})")

    @property
    def done(self) -> bool:
        return self.plan.done

    @property
    def finished(self) -> bool:
        """Everything is published and the node should exit (``exit_when_done``)."""
        return self.plan.done and self.exit_when_done

    def _on_timer(self) -> None:
        now = time.monotonic()
        if self._start is not None:
            self.wakeups += 1
        if self._start is None:
            if now - self._created < self._delay_s:
                return
            if self._wait_for and any(p.get_subscription_count() < self._wait_for
                                      for p in self._replay_publishers.values()):
                return
            self._start = now
        for i in self.plan.due(now - self._start, limit=_BATCH):
            self._replay_publishers[self.plan.topic_of[i]].publish(self.plan.data[i])
            self.published += 1
        if self.plan.done:
            self._timer.cancel()
            self.get_logger().info(f"replay done: {self.published} messages published")
            return
        # sleep until the next message is due (a 1 ms timer kept a core busy: 32.9 CPU-s for a
        # 33 s replay)
        wait_s = self.plan.seconds_until_next(time.monotonic() - self._start)
        self._sleep(min(max(wait_s, _MIN_PERIOD_S), _MAX_PERIOD_S))

    def _sleep(self, period_s: float) -> None:
        """Next timer callback after ``period_s`` [s] from now."""
        self._timer.timer_period_ns = int(period_s * 1e9)
        self._timer.reset()


def main(args=None) -> int:
    argv = sys.argv if args is None else args
    positional = [a for a in remove_ros_args(argv)[1:] if not a.startswith("-")]
    # linger: give transient-local and reliable readers a moment to take the last messages
    return run_node(lambda: ReplayNode(positional[0] if positional else None), "replay", argv, linger_s=0.5)


if __name__ == "__main__":
    sys.exit(main())
