"""USS node: the planner's live plans and constraints served over F3548's USS-USS interface
(docs/f3548.md).

``install/uam_sim/lib/uam_sim/uss --ros-args -p port:=8090 -p network:=config/networks/tiny.yaml``
(``run_fleet.sh --uss-port 8090`` starts it with the run's network and separation model).

With ``journal`` (run_fleet.sh gives the planner's) it serves the planner's own record: it follows
the journal (``uam_bringup.journal.JournalTail``: every approved plan and new version becomes or
replaces an operational intent, a cancellation ends it, each with its request's priority class;
each constraint set replaces the served constraints), and takes simulation time only from the
fleet states of the simulator the journal names (``uam_planner.sources.BoundSource``: its
session, each step once, never back and never more than ``max_clock_step_s`` ahead), so nothing
published on the domain by anyone else reaches a peer. Without it (a warning at start) it
subscribes to ``uam/flight_plans``, ``uam/requests`` (the priorities), ``uam/constraints`` and
``/clock``. Either way it serves them with
:class:`uam_sim.f3548.uss_server.UssServer` (Flask on a bounded pool of worker threads; a bad
request is answered with the standard's error and never stops the node). Parameters:
``uam_contract.params.USS``. With ``auth`` ``verify`` (the default) the node does not start
without ``auth_key``; with ``off`` it logs a warning saying so when it starts.
"""

from __future__ import annotations

import sys
import time
from dataclasses import replace

from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from std_msgs.msg import String

from uam_bringup import qos
from uam_bringup.params import declare_table
from uam_bringup.runtime import run_node
from uam_contract import names as c
from uam_contract.params import USS
from uam_contract.stamps import stamp_s
from uam_msgs.msg import FleetState, FlightPlan, FlightRequest


class UssNode(Node):
    def __init__(self, **kwargs):
        super().__init__("uss", **kwargs)
        p = declare_table(self, USS)
        from uam_planner.f3548 import IntentContext, VolumeSpec
        from uam_planner.network import load_network
        from uam_planner.separation import SeparationModel
        from uam_sim.f3548.uss_server import IntentStore, UssServer, base_url

        if not p["network"]:
            raise ValueError("parameter network: a network file is needed (its origin places the volumes)")
        self.network = load_network(p["network"])
        kind = p["separation_model"] or self.network.separation_model
        model = SeparationModel(kind, p["separation_m"], p["vertical_separation_m"])
        spec = VolumeSpec.for_separation(model, p["volume_piece_s"])

        def context(port):
            return IntentContext.for_network(self.network, spec,
                                             scenario_start_utc=p["scenario_start_utc"],
                                             uss_base_url=p["uss_base_url"] or base_url(p["host"], port))
        self.store = IntentStore(context(p["port"]))
        self._priority: dict[tuple, int] = {}
        from uam_sim.f3548.peers import PeerInbox, PlannerForwarder
        # peers' notifications are validated and kept; with the USS's own airspace authority
        # (authority_key) each change goes to the planner as a signed live constraint update
        self.forward = None
        self.peer_updates_accepted = 0
        if p["authority_key"]:
            from pathlib import Path
            from uam_msgs.srv import UpdateConstraint
            key = Path(p["authority_key"]).read_bytes()   # OSError names the file
            # sequence numbers above any earlier run's: the wall clock in ns at start (the
            # planner only needs them to grow)
            self.forward = PlannerForwarder(p["authority_id"], key, time.time_ns())
            self._update_client = self.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
        self.inbox = PeerInbox(self.network, spec, p["scenario_start_utc"], listener=self._on_peer_change,
                               log=self.get_logger().info)
        self.server = UssServer(self.store, p["host"], p["port"], p["auth"], auth_key=p["auth_key"],
                                auth_audience=p["auth_audience"], workers=p["workers"],
                                max_connections=p["max_connections"], inbox=self.inbox)
        self.store.ctx = context(self.server.port)  # port 0: the port the server got (store empty)
        base = self.store.ctx.uss_base_url
        self.server.start()
        log = self.get_logger().warning if self.server.auth == "off" else self.get_logger().info
        log(f"{self.server.announcement}; base url {base}; {p['workers']} workers")
        self.plans = 0
        self.clock_refused = 0
        self.tail = None
        if p["journal"]:
            from uam_bringup.journal import JournalTail
            from uam_planner.sources import BoundSource
            self.tail = JournalTail(p["journal"])
            self.source = BoundSource()
            self._session = None
            self._max_step_s = float(p["max_clock_step_s"])
            self._clock_s = None
            self.create_timer(0.2, self._poll, clock=self._steady())
            self.create_subscription(FleetState, c.TOPIC_FLEET, self._on_fleet, qos.QOS_STREAM)
            self.get_logger().info(f"serving the planner's journal {p['journal']}")
        else:
            self.get_logger().warning("no journal: serving what anyone on the domain publishes on "
                                      f"{c.TOPIC_PLANS}, {c.TOPIC_CONSTRAINTS} and {c.TOPIC_CLOCK}")
            self.create_subscription(FlightPlan, c.TOPIC_PLANS, self._on_plan, qos.QOS_LATCHED)
            self.create_subscription(FlightRequest, c.TOPIC_REQUESTS, self._on_request, qos.QOS_REQUESTS)
            self.create_subscription(String, c.TOPIC_CONSTRAINTS, self._on_constraints, qos.QOS_CONSTRAINTS)
            self.create_subscription(Clock, c.TOPIC_CLOCK, self._on_clock, qos.QOS_CLOCK)

    @staticmethod
    def _steady():
        from rclpy.clock import Clock as RosClock, ClockType
        return RosClock(clock_type=ClockType.STEADY_TIME)

    def _poll(self) -> None:
        """The journal's new entries: the newest run's plans and constraint sets."""
        entries = self.tail.poll()
        if self.tail.restarted:
            self.store.clear()
            self._session = None
        for e in entries:
            if e["session"] != self._session:   # the planner serves a new run
                if self._session is not None:
                    self.store.clear()
                self._session = e["session"]
                self.source = type(self.source)()
                self.source.bind(self._session)
                self._clock_s = None
            if "constraints" in e:
                self._set_constraints(e["constraints"])
            else:
                msg = e["plan"]
                self._priority[(msg.operator_id, msg.request_id)] = int(e["priority"])
                self._on_plan(msg)

    def _on_fleet(self, msg) -> None:
        """Simulation time from the fleet states of the simulator the journal names."""
        from uam_planner.sources import fleet_digest
        if not self.source.take("fleet state", msg.session, msg.step_index, fleet_digest(msg)):
            return
        t = stamp_s(msg.header.stamp)
        if self.source.problem or (self._clock_s is not None and not
                                   self._clock_s <= t <= self._clock_s + self._max_step_s):
            self.clock_refused += 1
            if self.clock_refused == 1:
                self.get_logger().error(self.source.problem or (
                    f"clock: a fleet state at t = {t:g} s after {self._clock_s:g} s, more than max_clock_step_s "
                    f"{self._max_step_s:g} s ahead or back: refused"))
            return
        self._clock_s = t
        self.store.set_time(t)

    def _on_request(self, msg) -> None:
        self._priority[(msg.operator_id, msg.request_id)] = int(getattr(msg, "priority", 0))

    def _on_plan(self, msg) -> None:
        from uam_planner.nodes.conversions import flight_from_plan
        if msg.outcome != FlightPlan.OUTCOME_APPROVED:
            if int(getattr(msg, "version", 0) or 0) > 1 or msg.state == FlightPlan.STATE_ENDED:
                self.store.end(msg.operator_id, msg.request_id)  # a cancellation of a version
            return
        try:
            f = flight_from_plan(msg)
        except ValueError as exc:
            self.get_logger().warning(f"plan {msg.operator_id}/{msg.request_id}: not served: {exc}")
            return
        f = replace(f, operator_id=msg.operator_id,
                    priority=self._priority.get((msg.operator_id, msg.request_id), 0))
        self.store.put_flight(f)
        self.plans += 1

    def _on_constraints(self, msg) -> None:
        self._set_constraints(msg.data)

    def _set_constraints(self, text: str) -> None:
        from uam_planner.live_constraints import constraints_from_text
        try:
            _, pairs = constraints_from_text(text, self.network)
        except ValueError as exc:
            self.get_logger().warning(f"{c.TOPIC_CONSTRAINTS}: not served: {exc}")
            return
        self.store.set_constraints([con for con, _ in pairs])

    def _on_peer_change(self, updates, kind, entity_id) -> None:
        """A peer's change (an HTTP worker thread): to the planner as signed updates."""
        if self.forward is None:
            self.get_logger().warning(f"peer {kind} {entity_id}: {len(updates)} constraint updates "
                                      f"({', '.join(a for a, _ in updates)}) not passed to the planner: "
                                      "no authority_key (docs/f3548.md, \"Peers\")")
            return
        from uam_msgs.srv import UpdateConstraint
        for fields in self.forward.requests(updates):
            req = UpdateConstraint.Request(action=fields.action, constraint_id=fields.constraint_id,
                                           version=int(fields.version), reason=fields.reason,
                                           geojson=fields.geojson, authorization=fields.authorization)
            fut = self._update_client.call_async(req)
            fut.add_done_callback(lambda f, cid=req.constraint_id: self._peer_answer(cid, f))

    def _peer_answer(self, cid: str, fut) -> None:
        res = fut.result()
        if res is None or not res.accepted:
            self.get_logger().warning(f"peer constraint {cid!r}: the planner refused it: "
                                      f"{'no answer' if res is None else res.error}")
        else:
            self.peer_updates_accepted += 1

    def _on_clock(self, msg) -> None:
        self.store.set_time(stamp_s(msg.clock))

    def close(self) -> None:
        self.server.stop()


def main(args=None) -> int:
    return run_node(UssNode, "uss", sys.argv if args is None else args)


if __name__ == "__main__":
    sys.exit(main())
