"""Recorder node: every /uam/* topic and /clock into one .mcap file (as rosbag2), plus Rerun.

``ros2 run uam_sim recorder --ros-args -p output:=runs/run.mcap -p rerun:=save
-p network:=config/networks/tiny.yaml``

It subscribes raw (CDR bytes as DDS delivers them, like rosbag2), so the bytes in the file are
exactly the bytes on the wire. Log time and publish time of each message are its simulation
time on the scenario's UTC clock (``log_time_start_utc`` + simulation time, recorded in the MCAP
record ``uam_clock``, which the readers subtract): the message's own stamp (``header.stamp``, ``clock``, ``epoch_time``, ``request_time``)
when it has one, else the latest ``/clock`` received; never earlier than the previous message of
the same topic (a topic with several publishers delivers stamps out of order), so every channel's
times are in order. (rosbag2 with ``--use-sim-time`` stamps
the receive time on the /clock timeline; taking the message's own stamp gives the same time
without the race between a message and the clock tick that announced it.)

The offered QoS written for each topic is what its publishers offer (asked from the graph when
the topic's first message arrives, as rosbag2 does); topics that never carried a message are
still listed, with the QoS the recorder subscribed with.

Stamps are read straight from the CDR bytes where the type starts with a stamp (/clock,
FleetState, PoseArray, FlightPlan, PlanningReport: :func:`uam_sim.recording.cdr.leading_stamp_ns`), so the
per-step messages are never deserialized (Rerun gets fleet positions from
:func:`uam_sim.recording.cdr.fleet_state_digest`); plans and reports, a few hundred a run, are deserialized
for the check below.

Views for generic viewers (:mod:`uam_sim.views.std_msgs_export`): with ``views`` on (the
default) the fleet, routes and network are also written in standard types (``/uam/view/*``:
PointCloud2, NavSatFix, MarkerArray), stamped in simulation time as every other topic (or in
real UTC from ``scenario_start_utc`` when it names an instant), for
Foxglove and Rerun's MCAP import; ``foxglove_port`` > 0 serves a live Foxglove WebSocket view
(:mod:`uam_sim.views.foxglove_live`).

It checks what it received against what was announced: the approvals the planning reports
announce, epoch by epoch, against the approved plans received. At the close it logs the result
(a warning on a mismatch) and writes it into the file as the MCAP metadata record
``uam_recorder_check`` (``ok``, ``announced_approvals``, ``approved_plans``, ``verdict``), which
``uam_sim.audit.analysis`` reads.

It watches who publishes (docs/security.md): the topics with one authority (the simulator's
/clock, fleet state and poses; the planner's plans and reports; one announcer each of the
simulator, the planner and the generator on uam/epoch_sync) are checked every
``PUBLISHER_CHECK_S``; more publishers at once (a second simulator or planner, a forger) make
the check fail, naming them, so the analysis never calls such a run OK. A publisher that comes
and goes between two looks is not seen: only SROS2 stops forged messages.

It stops and closes the file (summary, footer) when the simulator has announced the end of the run
(EpochSync with ``finished`` from sender "simulator"), no message has arrived for
``finish_quiet_s`` (messages of other topics can still be on their way when the announcement
arrives) and, after a clean end, the end's fleet state and every epoch's report are in (at most
``finish_timeout_s``); on Ctrl-C and on SIGTERM. While running it
finishes a chunk at least every ``flush_period_s`` of wall time, so a crash loses at most that.
"""

from __future__ import annotations

import json
import math
import sys
import time
from pathlib import Path

from rclpy.clock import Clock as RclClock
from rclpy.clock import ClockType
from rclpy.event_handler import SubscriptionEventCallbacks
from rclpy.node import Node
from rclpy.serialization import deserialize_message
from uam_msgs.msg import FlightPlan

# imported here, not where the first constraint set arrives: at nice 19 under load that import
# took more than run_fleet.sh's 10 s when it fell into the drain of a stopping recorder
from uam_planner.live_constraints import constraints_from_text
from uam_sim.audit.analysis import RUN_METADATA, format_steps, missing_steps, request_key
from uam_sim.audit.separation import AIRSPACE_METADATA, airspace_metadata
from uam_sim.recording.cdr import fleet_state_digest, fleet_state_step_index, leading_stamp_ns
from uam_sim.recording.mcap_reader import CLOCK_METADATA
from uam_sim.recording.mcap_schema import message_class
from uam_sim.recording.mcap_writer import McapRecorder
from uam_contract.stamps import scenario_start_ns, sim_stamp_ns, stamp_ns
from uam_sim.views.rerun_log import RerunLogger
from uam_sim.views.std_msgs_export import ViewExporter

from uam_contract import names as c
from uam_bringup.params import declare_table
from uam_contract.params import RECORDER
from uam_bringup.qos import profile
from uam_bringup.runtime import run_node

#: topic (relative, see uam_contract.names) -> (message class, subscription QoS)
RECORDED_TOPICS = {topic: (message_class(type_name), profile(spec))
                   for topic, (type_name, spec) in c.RECORDED_TOPICS.items()}


#: the topics only the simulator publishes (subscribed last when waiting for publishers)
SIMULATOR_TOPICS = (c.TOPIC_CLOCK, c.TOPIC_FLEET, c.TOPIC_POSES)


def _starts_with_stamp(cls: type) -> bool:
    """True if the type's first field is a Time or a Header (its stamp sits at a fixed CDR offset)."""
    fields = list(cls.get_fields_and_field_types().values())
    return bool(fields) and fields[0] in ("builtin_interfaces/Time", "std_msgs/Header")


#: wall time between two looks at who publishes the topics with one authority [s]
PUBLISHER_CHECK_S = 0.5
#: how many publishers each topic with one authority may have at once
SOLE_PUBLISHERS = {c.TOPIC_CLOCK: 1, c.TOPIC_FLEET: 1, c.TOPIC_POSES: 1, c.TOPIC_PLANS: 1, c.TOPIC_REPORTS: 1,
                   c.TOPIC_CONSTRAINTS: 1,
                   c.TOPIC_SYNC: 3, c.TOPIC_CONFORMANCE: 1}


class RecordingCheck:
    """Approvals announced by the planning reports vs approved plans received, per epoch; and
    fleet states missing between the first and the last received (one is published per step)."""

    def __init__(self) -> None:
        self.announced: dict[int, int] = {}      # epoch index -> approvals its report announced
        self.received: dict[int, set] = {}       # epoch index -> request ids of approved plans
        self.steps: list[int] = []               # step index of every fleet state received
        self.foreign: dict[str, str] = {}        # topic -> the first time it had too many publishers

    def on_fleet_state(self, data: bytes) -> None:
        step = fleet_state_step_index(data)
        if step is not None:
            self.steps.append(step)

    def on_report(self, msg) -> None:
        self.announced[int(msg.epoch_index)] = int(msg.approved)  # a repeated report counts once

    def on_plan(self, msg) -> None:
        if int(getattr(msg, "version", 0)) > 1:
            return  # a re-planned version of an approval: no report announces it as one
        if int(msg.outcome) == FlightPlan.OUTCOME_APPROVED:
            self.received.setdefault(int(msg.epoch_index), set()).add(request_key(msg))

    def result(self) -> dict:
        """{"ok", "announced_approvals", "approved_plans", "verdict"} (values as strings)."""
        announced = sum(self.announced.values())
        received = sum(len(v) for v in self.received.values())
        bad = [k for k in sorted(set(self.announced) | set(self.received))
               if self.announced.get(k, 0) != len(self.received.get(k, ()))]
        if not bad:
            verdict = f"every announced approval arrived: {announced} approvals, {received} approved plans"
        else:
            verdict = (f"the planning reports announce {announced} approvals but {received} approved "
                       f"plan(s) arrived; epochs differing: "
                       + ", ".join(f"{k} ({self.announced.get(k, 0)} announced, "
                                   f"{len(self.received.get(k, ()))} received)" for k in bad[:10]))
        lost, listed = missing_steps(self.steps)
        held = len(set(self.steps))
        # a run's fleet states start at step 0: those before the first received were not recorded
        # (a replay that began before the recorder subscribed), which "none missing" hid
        before = int(min(self.steps)) if self.steps else 0
        span = f"steps {min(self.steps)}..{max(self.steps)}" if self.steps else "no steps"
        if lost:
            verdict += (f"; {held} fleet states ({span}), {lost} fleet state(s) missing between the "
                        f"first and the last received (steps {format_steps(lost, listed)})")
        elif not self.steps:
            verdict += "; no fleet states"
        else:
            verdict += f"; {held} fleet states ({span}), none missing between the first and the last"
        if before:
            verdict += f", {before} before the first not received (steps 0..{before - 1})"
        if self.foreign:
            verdict += "; more publishers than the run has: " + "; ".join(
                f"{topic}: {who}" for topic, who in sorted(self.foreign.items()))
        return {"ok": "false" if bad or lost or self.foreign else "true", "announced_approvals": str(announced),
                "approved_plans": str(received), "fleet_states": str(len(self.steps)),
                "fleet_states_missing": str(lost), "fleet_states_before_first": str(before),
                "verdict": verdict}


class RecorderNode(Node):
    """Records the run; see the module docstring. ``finished`` turns true once the file is closed."""

    # long (over 80 lines): ROS glue that declares the node's parameters, state and interfaces
    # one by one; no logic to split into steps
    def __init__(self, **kwargs) -> None:
        super().__init__("recorder", **kwargs)
        # one table (uam_contract.params.RECORDER): declared read-only, checked at start-up
        p = declare_table(self, RECORDER)
        self._channel_last_ns: dict[str, int] = {}  # topic -> log time of its last message [ns]
        output = p["output"]
        rerun_mode = p["rerun"]
        rrd = p["rerun_rrd"] or str(Path(output).with_suffix(".rrd"))
        network = None
        if p["network"]:
            from uam_planner.network import load_network
            network = load_network(p["network"])
        # '' = the network's own model, as the planner resolves it
        model = p["separation_model"] or (network.separation_model if network is not None else "sphere")
        airspace = airspace_metadata(model, p["separation_m"], p["vertical_separation_m"], p["departure_slot_s"])

        self.output = Path(output)
        self.rrd_path = Path(rrd) if rerun_mode == "save" else None
        self.finished = False
        self.messages_written = 0
        self._recorded_subs = {}
        self._finish_timer = None
        self.recorder = McapRecorder(output, chunk_size_bytes=p["chunk_size_bytes"],
                                     compression=p["compression"],
                                     flush_period_s=p["flush_period_s"])
        self.views = None
        self.foxglove = None
        self.rerun = None
        self.recorder.add_metadata(AIRSPACE_METADATA, airspace)
        if p["run_choices"]:   # checked by its parameter rule: a JSON object of plain values
            self.recorder.add_metadata(RUN_METADATA, {k: json.dumps(v) for k, v in json.loads(p["run_choices"]).items()})
        # log times on the scenario's UTC clock: sim time + this; readers subtract it
        self._log_zero_ns = scenario_start_ns(p["log_time_start_utc"])
        self.recorder.add_metadata(CLOCK_METADATA, {"log_time_zero_ns": self._log_zero_ns,
                                                    "log_time_start_utc": p["log_time_start_utc"]})
        try:
            self.rerun = RerunLogger(rerun_mode, rrd, network=network,
                                     connect_url=p["rerun_url"] or None,
                                     utc_zero_ns=self._log_zero_ns or None)
            if p["views"]:
                self.views = ViewExporter(network, p["scenario_start_utc"], fix_period_s=p["view_fix_period_s"])
            if p["foxglove_port"] > 0:
                from uam_sim.views.foxglove_live import FoxgloveLive
                self.foxglove = FoxgloveLive(network, port=p["foxglove_port"], scenario_start_utc=p["scenario_start_utc"])
        except BaseException:
            self.recorder.close()
            if self.rerun is not None:
                self.rerun.close()
            raise
        self.view_messages_written = 0
        if self.views is not None:
            for vm in self.views.network_messages(0):
                self._write_view(vm)
        self.finish_requested = False
        self._end = None               # (end time [ns], epoch length [s]) of a clean end of run
        self._fleet_stamp_ns = -1      # the newest fleet state's stamp
        self._finish_quiet_s = p["finish_quiet_s"]
        self._finish_timeout_s = p["finish_timeout_s"]
        self._finish_requested_at = 0.0
        self._last_rx = time.monotonic()
        self._clock_ns = 0
        self._dirty = False
        self.check = RecordingCheck()
        self._sim_session: str | None = None
        self._stamp_first = {topic: _starts_with_stamp(cls) for topic, (cls, _qos) in RECORDED_TOPICS.items()}
        # recorded under the names they resolve to (namespace and remapping applied)
        self._names = {topic: self.resolve_topic_name(topic) for topic in RECORDED_TOPICS}
        # Readiness: the simulator starts once the recorder subscribes to the fleet state.
        # Subscribing to it (and /clock, poses) only when the planner's and the demand source's
        # topics have matched publishers means the run starts only once the recorder hears them:
        # before, a run stopped early (or a short one under load) could record fleet states and
        # none of the plans and requests, whose publishers the recorder had not matched yet.
        self._wait_for_publishers = [t for t in p["wait_for_publishers"] if t]
        late = SIMULATOR_TOPICS if self._wait_for_publishers else ()
        for topic in RECORDED_TOPICS:
            if topic not in late:
                self._subscribe(topic)
        steady = RclClock(clock_type=ClockType.STEADY_TIME)
        self._last_wait_log = time.monotonic()
        self._ready_timer = self.create_timer(0.05, self._subscribe_when_heard, clock=steady) if late else None
        self._flush_timer = self.create_timer(p["flush_period_s"], self._on_flush_timer,
                                              clock=steady)
        self._finish_timer = self.create_timer(0.05, self._maybe_close, clock=steady, autostart=False)
        self._publisher_timer = self.create_timer(PUBLISHER_CHECK_S, self._check_publishers, clock=steady)
        self.get_logger().info(f"recording {len(RECORDED_TOPICS)} topics to {self.output}"
                               + (f", Rerun {rerun_mode}" + (f" to {rrd}" if rerun_mode == "save" else "")
                                  if rerun_mode != "off" else ""))

    def _subscribe(self, topic: str) -> None:
        cls, qos = RECORDED_TOPICS[topic]
        self._recorded_subs[topic] = self.create_subscription(
            cls, topic, self._make_callback(topic, cls), qos, raw=True,
            event_callbacks=SubscriptionEventCallbacks(incompatible_qos=self._make_qos_warning(topic)))

    @property
    def ready(self) -> bool:
        """True once every recorded topic is subscribed (the simulator's last, see wait_for_publishers)."""
        return len(self._recorded_subs) == len(RECORDED_TOPICS)

    def _subscribe_when_heard(self) -> None:
        missing = [t for t in self._wait_for_publishers if self._recorded_subs[t].get_publisher_count() == 0]
        if missing:
            if time.monotonic() - self._last_wait_log > 10.0:
                self._last_wait_log = time.monotonic()
                self.get_logger().info(f"waiting for publishers of {', '.join(missing)} before "
                                       "subscribing to the fleet state (the simulator waits for that)")
            return
        self._ready_timer.cancel()
        for topic in SIMULATOR_TOPICS:
            self._subscribe(topic)
        self.get_logger().info(f"publishers of {', '.join(self._wait_for_publishers)} matched: "
                               "subscribed to the fleet state")

    def _check_publishers(self) -> None:
        """Note the topics that have more publishers at once than the run has (RecordingCheck.foreign)."""
        if self.finished:
            return
        for topic, most in SOLE_PUBLISHERS.items():
            if topic in self.check.foreign:
                continue
            try:
                infos = self.get_publishers_info_by_topic(self._names[topic])
            except Exception:  # noqa: BLE001 - graph queries can fail during shutdown
                continue
            names = [f"{i.node_namespace.rstrip('/')}/{i.node_name}" for i in infos]
            known = [n for n in names if "_NODE_NAME_UNKNOWN_" not in n]  # not discovered in full yet
            if len(infos) > most or len(set(known)) < len(known):
                self.check.foreign[topic] = f"{len(infos)} publishers at once ({', '.join(sorted(names))})"
                self.get_logger().error(f"{topic} has {len(infos)} publishers at once ({', '.join(sorted(names))}): "
                                        "the recording will not verify")

    def _make_callback(self, topic: str, cls: type):
        def callback(data: bytes) -> None:
            self._on_message(topic, cls, data)
        return callback

    def _make_qos_warning(self, topic: str):
        def warn(event) -> None:
            self.get_logger().error(
                f"{topic}: a publisher's QoS is incompatible with the recorder's "
                f"({RECORDED_TOPICS[topic][1].durability.name.lower()} reader; last policy "
                f"{event.last_policy_kind}); its messages are NOT recorded")
        return warn

    def _register(self, topic: str, cls: type) -> None:
        """Add the topic's channel with the QoS its publishers offer (as rosbag2 records it)."""
        offered = []
        try:
            offered = [info.qos_profile for info in self.get_publishers_info_by_topic(topic)]
        except Exception as exc:  # noqa: BLE001 - graph queries can fail during shutdown
            self.get_logger().debug(f"no publisher info for {topic}: {exc}")
        self.recorder.add_topic(self._names[topic], cls, RECORDED_TOPICS[topic][1], offered_qos_profiles=offered or None)

    def _on_message(self, topic: str, cls: type, data: bytes) -> None:
        if self.finished:
            return
        self._last_rx = time.monotonic()
        msg = self._write(topic, cls, data)
        if topic == c.TOPIC_SYNC and msg.sender == "simulator" and msg.session and self._sim_session is None:
            self._sim_session = msg.session  # the run's simulator: only its end closes the file
        if topic == c.TOPIC_SYNC and msg.finished and msg.sender == "simulator" \
                and msg.session == (self._sim_session or msg.session) and not self.finish_requested:
            self.get_logger().info("the simulator ended the run: closing the recording once the "
                                   "last messages are in")
            self.finish_requested = True
            self._finish_requested_at = time.monotonic()
            # a clean end: what it announces must be in before the file closes (under load the
            # recorder, niced, can be seconds behind: quiet alone closed it at step 467 of 600)
            self._end = None if msg.error else (stamp_ns(msg.epoch_time), float(msg.epoch_s))
            self._finish_timer.reset()
        if self.finish_requested:
            self._maybe_close()

    def _maybe_close(self) -> None:
        """After the end of the run: write what is queued, close once quiet or on the timeout."""
        if self.finished or not self.finish_requested:
            return
        if self._drain():
            self._last_rx = time.monotonic()
        now = time.monotonic()
        if now - self._finish_requested_at >= self._finish_timeout_s or \
                (now - self._last_rx >= self._finish_quiet_s and self._all_in()):
            self.close()

    def _all_in(self) -> bool:
        """After a clean end: the fleet state of the end's time and the report of every epoch
        before it have arrived (those of a topic that brought nothing at all are not waited for;
        after an end on an error, whatever came)."""
        if self._end is None:
            return True
        end_ns, epoch_s = self._end
        if 0 <= self._fleet_stamp_ns < end_ns - 1_000_000:
            return False
        n = math.ceil(end_ns * 1e-9 / epoch_s - 1e-9) if epoch_s > 0 and self.check.announced else 0
        return all(k in self.check.announced for k in range(n))

    def _write(self, topic: str, cls: type, data: bytes):
        """Write one message; returns it deserialized, or None for the per-step types (their
        stamp is read from the bytes: deserializing every FleetState was most of the CPU)."""
        msg = None
        stamp = leading_stamp_ns(data) if self._stamp_first.get(topic) else None
        if stamp is None:
            msg = deserialize_message(data, cls)
            stamp = sim_stamp_ns(msg)
        if topic == c.TOPIC_CLOCK and stamp is not None:
            self._clock_ns = max(self._clock_ns, stamp)
        if topic == c.TOPIC_FLEET and stamp is not None:
            self._fleet_stamp_ns = max(self._fleet_stamp_ns, stamp)
        log_ns = stamp if stamp is not None else self._clock_ns
        if not self.recorder.has_topic(self._names[topic]):
            self._register(topic, cls)
        self.recorder.write(self._names[topic], data, log_time_ns=self._channel_time_ns(self._names[topic], log_ns))
        self.messages_written += 1
        self._dirty = True
        if topic in (c.TOPIC_PLANS, c.TOPIC_REPORTS, c.TOPIC_SYNC) and msg is None:
            msg = deserialize_message(data, cls)
        if topic == c.TOPIC_PLANS:
            self.check.on_plan(msg)
        elif topic == c.TOPIC_REPORTS:
            self.check.on_report(msg)
        elif topic == c.TOPIC_FLEET:
            self.check.on_fleet_state(data)
        if not (self.rerun.enabled or self.views is not None or self.foxglove is not None):
            return msg
        if topic == c.TOPIC_FLEET:
            digest = fleet_state_digest(data, positions=True)
            if digest is None:  # big-endian bytes: decode in full
                full = deserialize_message(data, cls)
                ids = [v.vehicle_id for v in full.vehicles]
                pos = [(v.position.x, v.position.y, v.position.z) for v in full.vehicles]
            else:
                ids, pos = digest.vehicle_ids, digest.positions_m
            self.rerun.log_fleet(log_ns * 1e-9, ids, pos)
            if self.views is not None:
                for vm in self.views.fleet_messages(log_ns, ids, pos):
                    self._write_view(vm)
            if self.foxglove is not None:
                self.foxglove.on_fleet(log_ns, ids, pos)
        elif topic == c.TOPIC_PLANS:
            self.rerun.log_flight_plan_msg(msg)
            if self.views is not None:
                for vm in self.views.plan_messages(msg):
                    self._write_view(vm)
            if self.foxglove is not None:
                self.foxglove.on_flight_plan(msg)
        elif topic == c.TOPIC_REPORTS:
            self.rerun.log_planning_report_msg(msg)
            if self.foxglove is not None:
                self.foxglove.on_planning_report(msg)
        elif topic == c.TOPIC_REQUESTS and self.rerun.enabled:
            # the earliest departures, for the Rerun view's delay panel
            if msg is None:
                msg = deserialize_message(data, cls)
            self.rerun.log_request_msg(msg)
        elif topic == c.TOPIC_CONSTRAINTS:
            self._draw_constraints(msg, log_ns)
        return msg

    def _draw_constraints(self, msg, log_ns: int) -> None:
        """The constraint set (uam/constraints) in Rerun and the view topics."""
        try:
            t_s, found = constraints_from_text(msg.data)
        except ValueError as exc:  # recorded as it came; only the drawing is skipped
            self.get_logger().warning(f"{c.TOPIC_CONSTRAINTS}: not drawn: {exc}")
            return
        constraints = [k for k, _eff in found]
        self.rerun.log_constraints(t_s, constraints)
        if self.views is not None:   # at the instant the set took effect (a String has no stamp)
            for vm in self.views.constraint_messages(max(int(log_ns), int(round(t_s * 1e9))), constraints):
                self._write_view(vm)

    def _write_view(self, vm) -> None:
        """One view message (uam_sim.views.std_msgs_export.ViewMessage) at its simulation time."""
        if not self.recorder.has_topic(vm.topic):
            self.recorder.add_topic(vm.topic, vm.type_name)
        self.recorder.write(vm.topic, vm.data, log_time_ns=self._channel_time_ns(vm.topic, vm.sim_time_ns))
        self.view_messages_written += 1

    def _channel_time_ns(self, topic: str, stamp_ns: int) -> int:
        """The log time of a message of ``topic``: its stamp, but never before the topic's previous
        message. Several publishers share a topic (EpochSync of simulator, generator and planner,
        the simulator announcing epoch k+1 before the others report epoch k), so stamps arrive out
        of order; MCAP tools expect each channel's log times in order (`rerun mcap check`
        reported unordered chunks). The message's own stamp is in its bytes. Returned on the
        scenario's UTC clock (``log_time_start_utc`` + that simulation time)."""
        t = max(0, int(stamp_ns), self._channel_last_ns.get(topic, 0))
        self._channel_last_ns[topic] = t
        return t + self._log_zero_ns

    def _drain(self) -> int:
        """Write every message already delivered to our subscriptions but not yet taken.

        The end of the run can overtake messages of other topics still queued here (an executor
        serves each subscription once per wait, so a busy one lags); they belong in the file.
        """
        drained = 0
        for topic, sub in self._recorded_subs.items():
            cls = RECORDED_TOPICS[topic][0]
            while True:
                try:
                    with sub.handle:
                        taken = sub.handle.take_message(sub.msg_type, True)
                except Exception:  # noqa: BLE001 - destroyed handle or shut-down context: nothing left
                    break
                if taken is None:
                    break
                self._write(topic, cls, taken[0])
                drained += 1
        return drained

    def _on_flush_timer(self) -> None:
        if self._dirty and not self.finished:
            self.recorder.flush()
            self._dirty = False

    def close(self) -> None:
        """Close the MCAP file (listing every topic) and the Rerun sink. Idempotent."""
        if self.finished:
            return
        self.finished = True
        if self._finish_timer is not None:
            self._finish_timer.cancel()
        if getattr(self, "_ready_timer", None) is not None:
            self._ready_timer.cancel()
        try:
            drained = self._drain()
            if drained:
                self.get_logger().info(f"wrote {drained} messages still queued at the end")
            for topic, (cls, _qos) in RECORDED_TOPICS.items():
                if not self.recorder.has_topic(self._names[topic]):
                    self._register(topic, cls)
            check = self.check.result()
            self.recorder.add_metadata("uam_recorder_check", check)
            (self.get_logger().info if check["ok"] == "true" else self.get_logger().warning)(
                f"recorder check: {check['verdict']}")
            self.recorder.close()
        finally:
            self.rerun.close()
            if self.foxglove is not None:
                self.foxglove.close()
        self.get_logger().info(f"wrote {self.messages_written} messages to {self.output}"
                               + (f" and {self.rrd_path}" if self.rrd_path else ""))


def main(args=None) -> int:
    return run_node(RecorderNode, "recorder", args, events_executor=True)


if __name__ == "__main__":
    sys.exit(main())
