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

With ``authority_key`` it also serves InterUSS's flight_planning interface
(:class:`uam_sim.f3548.flight_planning.FlightPlanning`) over :class:`NodeDecider`: each flight
plan, modification and cancellation goes to the planner node as a request signed by the USS's
authority (``uam/uss_flight_plan``, :mod:`uam_planner.signed_requests`), and an answer waits, at
most ``flight_planning_timeout_s``, for the planner's decision; an approval counts only once the
planner's journal (or, without one, its plans topic) holds the plan.

With ``dss_url`` it keeps a reference of every served intent in that DSS
(:class:`uam_sim.f3548.dss_sync.DssSync`, in a thread of its own: created, updated at each new
version, deleted when the intent ends; the DSS's reference then served; the subscribers the DSS
names notified), with tokens from ``dss_token_file``, ``dss_dev_key`` or ``dss_auth_url``. A
flight_planning answer then also waits (at most :data:`DSS_WAIT_S`) for the DSS's reference.
Without it no DSS is called and the OVNs are local, as before.
"""

from __future__ import annotations

import sys
import threading
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


#: the longest wall time [s] a flight_planning answer waits for the DSS's reference after the
#: planner's decision (a DSS that does not answer is logged and the answer goes out)
DSS_WAIT_S = 10.0


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
        peers = [x for x in p["peers"] if x]
        self.inbox = PeerInbox(self.network, spec, p["scenario_start_utc"], listener=self._on_peer_change,
                               log=self.get_logger().info, peers=peers or None)
        # the flights of the flight_planning interface's operator, newest version each, as the
        # planner's record (journal or plans topic) holds them: what the decider reads
        self.decider = None
        self.planning = None
        if p["authority_key"]:
            from uam_planner.signed_requests import FlightPlanSigner
            from uam_sim.f3548.flight_planning import DEFAULT_OPERATOR, FlightPlanning
            signer = FlightPlanSigner(p["authority_id"], key, time.time_ns())
            self.decider = NodeDecider(self, signer, DEFAULT_OPERATOR, p["flight_planning_timeout_s"])
            self.planning = FlightPlanning(self.decider, self.network, context(p["port"]), DEFAULT_OPERATOR,
                                           log=self.get_logger().info)
        self.server = UssServer(self.store, p["host"], p["port"], p["auth"], auth_key=p["auth_key"],
                                auth_audience=p["auth_audience"], workers=p["workers"],
                                max_connections=p["max_connections"], inbox=self.inbox, planning=self.planning)
        self.store.ctx = context(self.server.port)  # port 0: the port the server got (store empty)
        if self.planning is not None:
            self.planning.ctx = self.store.ctx
        base = self.store.ctx.uss_base_url
        self.dss_sync = self._dss_sync(p)   # a bad token source refuses the start before any thread runs
        self.server.start()
        log = self.get_logger().warning if self.server.auth == "off" else self.get_logger().info
        log(f"{self.server.announcement}; base url {base}; {p['workers']} workers")
        if self.dss_sync is not None:
            self.dss_sync.start(p["dss_retry_s"])
        self.plans = 0
        self.clock_refused = 0
        self._follow(p)

    def _dss_sync(self, p):
        """With ``dss_url``: the DSS's references of the served intents (a DssSync, started once
        the server is); None without (local OVNs, no DSS called: the node as it was)."""
        if not p["dss_url"]:
            unused = [k for k in ("dss_token_file", "dss_dev_key", "dss_auth_url") if p[k]]
            if unused:
                self.get_logger().warning(f"{', '.join(unused)} given without dss_url: not used (no DSS)")
            return None
        from uam_sim.f3548.dss import DssClient, token_source
        from uam_sim.f3548.dss_sync import DssSync
        tokens = token_source(p["dss_token_file"], p["dss_dev_key"], p["dss_auth_url"], p["dss_subject"])
        client = DssClient(p["dss_url"], tokens, audience=p["dss_audience"])
        self.get_logger().info(f"DSS {client.base_url} (token audience {client.audience}): every served intent's "
                               f"reference kept there, failures retried every {p['dss_retry_s']:g} s")
        return DssSync(self.store, client, log=self.get_logger().info, warn=self.get_logger().warning)

    def await_dss(self, operator_id: str, request_id: str, plan_version: int | None, timeout_s: float) -> str:
        """With a DSS: wait (at most ``timeout_s``) until the DSS holds the reference of the
        intent at ``plan_version`` (None: holds none), or its put or delete failed, so that a
        flight_planning answer follows the DSS's record, as a test director reading the DSS
        expects. The outcome (DssSync.wait_settled), '' without a DSS."""
        if self.dss_sync is None:
            return ""
        from uam_planner.f3548 import intent_id
        oid = intent_id(operator_id, request_id)
        outcome = self.dss_sync.wait_settled(oid, plan_version, timeout_s)
        if outcome not in ("synced", "deleted"):
            self.get_logger().warning(f"DSS: operational intent {oid} ({operator_id}/{request_id}): {outcome} "
                                      f"after {timeout_s:g} s; answered all the same (the planner's decision stands)")
        return outcome

    def _follow(self, p) -> None:
        """What the store serves: the planner's journal and the simulator's clock, or (no
        journal) the topics."""
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
                    if self.decider is not None:
                        self.decider.forget()
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
                if self.decider is not None:
                    self.decider.ended(msg.operator_id, msg.request_id)
            return
        try:
            f = flight_from_plan(msg)
        except ValueError as exc:
            self.get_logger().warning(f"plan {msg.operator_id}/{msg.request_id}: not served: {exc}")
            return
        f = replace(f, operator_id=msg.operator_id,
                    priority=self._priority.get((msg.operator_id, msg.request_id), 0))
        self.store.put_flight(f)
        if self.decider is not None:
            self.decider.held(f)
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
        if self.dss_sync is not None:
            self.dss_sync.stop()
        self.server.stop()


class NodeDecider:
    """The flight_planning interface's decider in the node graph (the library path's is
    ``InProcessDecider``): each operation is a signed call of ``uam/uss_flight_plan`` made from
    an HTTP worker thread, which waits (at most ``timeout_s`` of wall time) for the planner's
    answer; an approval or a new version counts only once the node's record of the planner's
    plans (its journal, or its plans topic) holds it (:meth:`held`), since anyone may answer a
    service call. The times are the served clock's (the simulator's, as the node takes it)."""

    def __init__(self, node, signer, operator_id: str, timeout_s: float):
        from uam_msgs.srv import UpdateConstraint
        self.node, self.signer, self.operator_id, self.timeout_s = node, signer, operator_id, float(timeout_s)
        # with a DSS, an answer also waits for the DSS's reference, at most this long
        self.dss_wait_s = min(self.timeout_s, DSS_WAIT_S)
        self.client = node.create_client(UpdateConstraint, c.SERVICE_USS_FLIGHT_PLAN)
        self._lock = threading.Condition()
        self._flights: dict = {}   # request id -> Flight (newest version), this operator's only

    # ---- the planner's record, from the node's journal or topic callbacks --------------------------
    def held(self, flight) -> None:
        if flight.operator_id != self.operator_id:
            return
        with self._lock:
            old = self._flights.get(flight.request_id)
            if old is None or int(flight.version) >= int(old.version):
                self._flights[flight.request_id] = flight
            self._lock.notify_all()

    def ended(self, operator_id: str, request_id: str) -> None:
        if operator_id == self.operator_id:
            with self._lock:
                self._flights.pop(request_id, None)
                self._lock.notify_all()

    def forget(self) -> None:
        with self._lock:
            self._flights.clear()
            self._lock.notify_all()

    # ---- the decider's surface (uam_sim.f3548.flight_planning) ------------------------------------
    @property
    def t_s(self) -> float:
        return self.node.store.time_s

    @property
    def now_s(self) -> float:
        return self.node.store.time_s

    def ready(self) -> bool:
        return self.client.service_is_ready()

    def flight(self, request_id: str):
        with self._lock:
            return self._flights.get(request_id)

    def _call(self, fields) -> tuple:
        """(accepted, error) of one signed call, or (None, why) with no answer in time."""
        from uam_msgs.srv import UpdateConstraint
        req = UpdateConstraint.Request(action=fields.action, constraint_id=fields.constraint_id,
                                       version=int(fields.version), reason=fields.reason, geojson=fields.geojson,
                                       authorization=fields.authorization)
        if not self.client.wait_for_service(timeout_sec=min(self.timeout_s, 5.0)):
            return None, f"the planner does not serve {c.SERVICE_USS_FLIGHT_PLAN}"
        done = threading.Event()
        fut = self.client.call_async(req)
        fut.add_done_callback(lambda _f: done.set())
        if not done.wait(self.timeout_s):
            self.client.remove_pending_request(fut)
            return None, f"no decision of the planner within {self.timeout_s:g} s (flight_planning_timeout_s)"
        res = fut.result()
        return bool(res.accepted), str(res.error)

    def _await(self, request_id: str, version: int):
        """The flight of ``request_id`` at ``version`` or later once the record holds it, or None."""
        deadline = time.monotonic() + self.timeout_s
        with self._lock:
            while True:
                f = self._flights.get(request_id)
                if f is not None and int(f.version) >= version:
                    return f
                left = deadline - time.monotonic()
                if left <= 0:
                    return None
                self._lock.wait(min(left, 0.5))

    def _withdraw(self, request_id: str) -> None:
        self._call(self.signer.operation("cancel", request_id=request_id, operator_id=self.operator_id,
                                         reason="withdrawn: no decision in time"))

    def decide(self, request):
        from uam_sim.f3548.flight_planning import Decision
        request = replace(request, operator_id=self.operator_id)
        ok, why = self._call(self.signer.operation("plan", request, version=1))
        if ok is None:
            self._withdraw(request.request_id)
            return Decision("failed", f"{why}; the request is withdrawn")
        if not ok:
            return Decision("rejected", why)
        f = self._await(request.request_id, 1)
        if f is None:
            return Decision("failed", "the planner's answer is not in its record (journal) in time")
        self.node.await_dss(self.operator_id, request.request_id, int(f.version), self.dss_wait_s)
        return Decision("approved", flight=f)

    def modify(self, request):
        from uam_sim.f3548.flight_planning import Decision
        current = self.flight(request.request_id)
        version = int(current.version) + 1 if current is not None else 1
        ok, why = self._call(self.signer.operation("modify", replace(request, operator_id=self.operator_id),
                                                   version=version))
        if ok is None:
            return Decision("failed", why, self.flight(request.request_id))
        if not ok:
            # Planner.modify's own sentence says whether the previous version stays in force
            kept = "could not be kept" not in why
            return Decision("rejected", why, self.flight(request.request_id) if kept else None)
        f = self._await(request.request_id, version)
        if f is None:
            return Decision("failed", "the planner's new version is not in its record (journal) in time",
                            self.flight(request.request_id))
        self.node.await_dss(self.operator_id, request.request_id, int(f.version), self.dss_wait_s)
        return Decision("approved", flight=f)

    def cancel(self, request_id: str, operator_id: str, reason: str) -> str | None:
        ok, why = self._call(self.signer.operation("cancel", request_id=request_id, operator_id=operator_id,
                                                   reason=reason))
        if ok:   # the store ends the intent once the journal records the cancellation
            self.node.await_dss(operator_id, request_id, None, self.dss_wait_s)
        return None if ok else why


def main(args=None) -> int:
    return run_node(UssNode, "uss", sys.argv if args is None else args)


if __name__ == "__main__":
    sys.exit(main())
