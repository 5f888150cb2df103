"""Planner node: decides requests as they arrive and plans an epoch when the simulator asks.

    ros2 run uam_planner planner --ros-args --params-file config/planner.yaml

Subscribes uam/requests (FlightRequest); serves uam/plan_epoch (PlanEpoch),
uam/update_constraint (UpdateConstraint: live airspace constraints, queued to the next epoch,
docs/constraints.md) and uam/uss_flight_plan (a USS's flight requests, modifications and
cancellations, signed by its airspace authority: uam_planner.signed_requests; answered once
decided); calls uam/solve_mwis (SolveMwis); publishes uam/flight_plans (every
decision, and every new version of a plan re-planned around a constraint, docs/replanning.md),
uam/planning_reports, uam/constraints (the set in force, latched) and its progress on
uam/epoch_sync (for the recorder). Names and QoS: uam_contract.names;
parameters: uam_contract.params.PLANNER (docs/parameters.md).

On arrival every request is accepted (queued) or refused at once with a reason that names the
field (those that come before the first epoch call, when the simulation time is not known yet,
are decided at that call, in arrival order) (uam_contract.wire, then the planning library's checks): ids bounded in length and
characters and unique per operator, times well-formed and plausible, per-operator quota and a
queue limit. A second request with a taken (operator_id, request_id) gets an
OUTCOME_DUPLICATE answer, which is not a decision: the first decision stands. Nothing is counted
to decide when to plan.

The epoch protocol: the simulator asks to plan epoch k at time t, naming the requests the
demand source released for it; the planner waits (asynchronously) until each has arrived or
``request_wait_timeout_s`` passed, prepares the epoch (conflict graph; the batch re-plan of a
constraint update first, its MWIS graphs through the solver service too), awaits the solver service
(asynchronously; ``time_limit_s + solver_timeout_margin_s`` at most), commits the checked answer
(the planning library is the one place that checks it and falls back to greedy) and answers with
the epoch's plans and report. Asking again for the last epoch returns its outcome, for the epoch
in progress STATUS_IN_PROGRESS (the first call gets the outcome); nothing is planned twice. A planner started mid-run answers STATUS_NEED_STATE and
resumes from the state the simulator then sends (flights in the air, requests decided).

What no caller can talk it out of (docs/security.md): it serves epochs only for the simulator
it bound to at its first served call (the run token ``session``), only the next epoch, at the
time ``epoch_index * epoch_s`` with the ``epoch_s`` of that first call, with at most
``max_pending`` expected ids. A resume is taken only by a planner that holds nothing yet, and
it adds flights, never removes them; with a ``journal`` the claim is checked against the
planner's own approvals and refused when it contradicts them. The end of the run is taken only
from the bound simulator.
The reaction between epochs: uam/react (React), called by the bound simulator at each
instant of its ``reaction_period_s`` strictly between the epoch planned last and the next, in
time order; the planner waits for the fleet state (and the monitor's report) of that instant,
runs Planner.react_between_steps with its MWIS graphs through uam/solve_mwis, publishes the new
versions and answers with them. From the first such call it observes the fleet at the in-process
runner's instants only (epoch t - 20, t - 10, t; each reaction instant): docs/disturbances.md.
The planning itself is uam_planner.planning.Planner, shared with the in-process experiment runner.
"""

from __future__ import annotations

import collections
import dataclasses
import hashlib
import math
import secrets
import sys
import threading
import time

from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.clock import Clock, ClockType
from rclpy.node import Node
from rclpy.task import Future
from std_msgs.msg import String
from uam_msgs.msg import Conformance, EpochSync, FleetState, FlightPlan, FlightRequest, PlanningReport
from uam_msgs.srv import PlanEpoch, React, SolveMwis, UpdateConstraint

from uam_contract import names as c
from uam_planner.nodes import conversions as m
from uam_bringup import qos
from uam_contract import wire
from uam_bringup.journal import Journal, newest_versions
from uam_bringup.params import declare_table
from uam_bringup.reaction import OBSERVE_BACK_S, stamp_key
from uam_contract.params import PLANNER
from uam_solvers.nodes import param_rules
from uam_bringup.runtime import run_node
from uam_planner.airspace_files import load_airspace
from uam_planner.constraints import ConstraintError
from uam_planner.live_constraints import parse_update, set_geojson
from uam_planner.network import load_network
from uam_planner.conformance import ConformanceBounds
from uam_planner.authority import Authorities
from uam_planner.grants import PriorityGrants
from uam_planner.objectives import objective_problem
from uam_planner import separation
from uam_planner.sources import BoundSource, FleetView, conformance_digest
from uam_planner.planning import AirspaceConfig, Planner, PlanningConfig, call_solver, default_solve_mwis


class PlannerNode(Node):
    """ROS glue around uam_planner.planning.Planner."""

    # long (over 80 lines): ROS glue that declares the node's state, publishers, services and
    # subscriptions one by one, each with its reason; no logic to split into steps
    def __init__(self, **kwargs):
        # No use_sim_time: the node takes simulation time from the epoch protocol, never from a
        # clock, and a /clock subscription would cost it a callback per simulated second (about
        # 3 CPU s of a paper run; BENCHMARKS.md).
        super().__init__("planner", **kwargs)
        self._lock = threading.RLock()
        self.p = declare_table(self, PLANNER, on_change=self._on_change,
                               rules={**param_rules.RULES, "objective_name": objective_problem})
        self.network = load_network(self.p["network"])
        given = self.p["separation_model"]
        self.p["separation_model"] = given or self.network.separation_model
        if given and given != self.network.separation_model:
            self.get_logger().warning(
                f"separation_model {given!r} contradicts network {self.network.name!r}, built for "
                f"{self.network.separation_model!r}" + (" (its flight levels are closer than the sphere: they "
                "separate nothing)" if self.network.layered else "") + "; planning with " + repr(given))
        config = PlanningConfig(
            separation_m=self.p["separation_m"], k=self.p["k"], penalty_factor=self.p["penalty_factor"],
            speed_mps=self.p["speed_mps"], backend=self.p["backend"], time_limit_s=self.p["time_limit_s"],
            seed=self.p["seed"], precompute_routes=self.p["precompute_routes"],
            objective=self.p["objective"], baseline_order=self.p["baseline_order"],
            horizon_epochs=self.p["horizon_epochs"], commit_ahead=self.p["commit_ahead"],
            replan_policy=self.p["replan_policy"],
            fair_window_s=self.p["fair_window_s"],
            spatial_buffer_m=self.p["spatial_buffer_m"], temporal_buffer_s=self.p["temporal_buffer_s"],
            conformance=ConformanceBounds(self.p["reaction_lateral_m"], self.p["reaction_vertical_m"],
                                          self.p["reaction_time_s"]) if self.p["reaction"] else None,
            conflict_probe_s=self.p["conflict_probe_s"] if self.p["reaction"] else 0.0,
            conflict_probe_margin_m=self.p["conflict_probe_margin_m"]
            if self.p["reaction"] and self.p["conflict_probe_s"] else 0.0,
            intent_volume_piece_s=self.p["intent_volume_piece_s"],
            # the classes each operator may ask for (ValueError naming the file and entry)
            priority_grants=PriorityGrants.load(self.p["priority_grants"]) if self.p["priority_grants"] else None,
            airspace=AirspaceConfig(**{f: self.p[f] for f in (
                "separation_model", "vertical_separation_m", "departure_slot_s", "climb_rate_mps",
                "descent_rate_mps")}))
        self.policy = self.p["policy"]
        self.planner = Planner(self.network, config, self.policy)
        if self.p["constraints_file"]:
            # the node starts at simulation time 0: a window over by then is refused as in the past
            try:
                cset = load_airspace(self.p["constraints_file"], self.network, now_s=0.0)
            except ValueError as exc:
                raise ValueError(f"constraints_file: {exc}") from None
            self.planner.set_constraints(cset)
        # who may change the airspace (uam_planner.authority): without an authorities file the
        # planner takes no live constraint update
        self.authorities = None
        if self.p["authorities_file"]:
            self.authorities = Authorities.load(self.p["authorities_file"])   # ValueError names the file
        # live constraints: uam/update_constraint, queued in the planner and applied at
        # its next epoch (Planner.update_constraint); the set in force is published on uam/constraints
        self._constraint_effective: dict[str, float] = {c.constraint_id: 0.0 for c in self.config.constraints or ()}
        # when the authority announced each live constraint version (the update's time)
        self._constraint_announced: dict[str, float] = {}
        # who withdrew which constraint, when asked and when applied (published with the set)
        self._withdrawals: list[dict] = []
        self._withdrawn_by: dict[tuple, tuple] = {}   # (id, version) -> (authority, t asked)
        self._constraints_logged = 0        # entries of planner.constraint_log published
        self._sets_unreported: list[str] = []   # SHA-256 of the sets published since the last report
        self.constraint_updates_refused = 0

        self._steady = Clock(clock_type=ClockType.STEADY_TIME)
        self._group = ReentrantCallbackGroup()  # the epoch service awaits; arrivals must go on meanwhile
        self._plan_pub = self.create_publisher(FlightPlan, c.TOPIC_PLANS, qos.QOS_LATCHED)
        self._report_pub = self.create_publisher(PlanningReport, c.TOPIC_REPORTS, qos.QOS_LATCHED)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self._constraints_pub = self.create_publisher(String, c.TOPIC_CONSTRAINTS, qos.QOS_CONSTRAINTS)
        self._publish_constraints(0.0)
        self._constraint_service = self.create_service(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT,
                                                       self._on_update_constraint)
        # a USS's signed flight requests (uam_planner.signed_requests): each call waits for its
        # decision (scoped request id -> Future of (accepted, why)); operations that change the
        # planner's flights wait until no epoch is being planned (_idle_waiters)
        self._uss_waiters: dict[str, Future] = {}
        self._idle_waiters: list[Future] = []
        self.uss_requests_refused = 0
        self._uss_service = self.create_service(UpdateConstraint, c.SERVICE_USS_FLIGHT_PLAN, self._on_uss_flight_plan,
                                                callback_group=self._group)
        self.create_subscription(FlightRequest, c.TOPIC_REQUESTS, self._on_request, qos.QOS_REQUESTS)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED)
        # the reaction to nonconformance (uam_planner.nonconformance): the fleet state is
        # the planner's own view of where the vehicles are; a report on uam/conformance is a claim
        # checked against it and against the planner's plan at the next epoch
        self.conformance_reports = 0
        self.conformance_reports_refused = 0
        self.held_past_plan: set = set()   # request ids the planner ever held past their plans
        # the messages go to an inbox (a deque: appends are atomic) from their own callback group,
        # so a busy epoch never holds them up; the planner reads the inbox before each epoch
        self._inbox: collections.deque = collections.deque()
        from rclpy.callback_groups import MutuallyExclusiveCallbackGroup
        group = MutuallyExclusiveCallbackGroup()
        # the fleet state always (safety gap: a flight seen flying past its plan is
        # held in the traffic picture until it lands, uam_planner.nonconformance.overruns); the
        # conformance reports only with the reaction on
        # raw: the fleet state is read from its bytes (uam_planner.fleet_state_cdr), not
        # deserialized into a VehicleState, a Point and a Vector3 object per vehicle (most of
        # this node's CPU in the paper scenario)
        self.create_subscription(FleetState, c.TOPIC_FLEET, self._on_fleet_msg, qos.QOS_STREAM,
                                 callback_group=group, raw=True)
        if self.p["reaction"]:
            self.create_subscription(Conformance, c.TOPIC_CONFORMANCE, self._on_conformance_msg, qos.QOS_STREAM,
                                     callback_group=group)
        # the reaction between epochs (uam/react): the simulator calls it at each
        # reaction instant; from the first such call on the planner takes its observations at the
        # in-process runner's instants only (_observe_at), waiting for the fleet state (and the
        # monitor's report) of each call's time
        self._react_service = None
        self._observe_from_calls = False
        # stamp (us) -> {vehicle id: position}, in that mode: the first position received of each
        # vehicle at each time is kept (as PositionBook keeps the first of a repeated sample), so
        # a forged state stamped like a real one neither hides nor moves a vehicle seen in it
        self._fleet_buffer: dict[int, dict] = {}
        self._stamp_lock = threading.Lock()
        self._latest_fleet_s = -math.inf    # the newest fleet state / conformance report received
        self._latest_conformance_s = -math.inf
        self._stamp_waiters: list = []
        self._react_inflight: tuple | None = None   # (epoch_index, stamp) of the reaction computed
        self._last_react: tuple | None = None       # ((epoch_index, stamp), response) of the last one
        self._last_react_s = -math.inf
        self.reactions_between = 0                  # reactions between epochs answered
        self.between_graphs_by_service = 0          # their MWIS graphs solved through uam/solve_mwis
        self.between_updates = 0                    # plan versions they published
        self._client = self.create_client(SolveMwis, c.SERVICE_SOLVE, callback_group=self._group)
        self._service = None  # offered once the solver is up (or its start-up wait is over)
        self._started_at = time.monotonic()
        self._ready_timer = self.create_timer(0.05, self._offer_service_when_ready, clock=self._steady)

        self._taken: set[str] = set()            # scoped ids decided or waiting: a reuse is a duplicate
        self._held: list | None = []             # requests that came before the first epoch call
        # requests that came while an epoch's prepare awaited the solver service for its re-plan
        # (Planner.prepare_steps): decided once the prepare is done, as if they came after it
        self._deferred: list | None = None
        self.replan_graphs_by_service = 0        # re-plan graphs solved through uam/solve_mwis
        self._waiting_per_operator: collections.Counter = collections.Counter()
        self._established: set[str] = set()      # operators with a request accepted before this epoch
        self._new_operators: set[str] = set()    # operators first accepted since the last epoch
        self._waiters: list[tuple[set, Future]] = []
        self._next_epoch = 0
        self._next_epoch_s = 0.0                 # time of the next epoch: what arrivals are checked against
        self._last_epoch_s = 0.0                 # time of the last epoch planned: the stamp of refusals
        self._inflight: int | None = None       # the epoch being planned
        self._last: tuple[int, PlanEpoch.Response] | None = None
        self._refusal_logged_at = float("-inf")
        self._call_refusal_logged_at = float("-inf")
        self._refused_unlogged = 0
        # the run tokens (docs/security.md): this planner's own, and the simulator's it serves
        self.session = secrets.token_hex(8)
        self.bound_simulator: str | None = None
        #: the fleet states and conformance reports taken from the bound simulator only
        self.source = BoundSource()
        self._epoch_s: float | None = None       # fixed by the first served call
        self.resumed = False
        self.journal = Journal(self.p["journal"]) if self.p["journal"] else None
        self.requests_received = 0
        self.plans_published = 0
        self.epochs_planned = 0
        self.finished = False
        self.get_logger().info(
            f"planner: network {self.network.name!r} ({len(self.network.node_ids)} nodes, "
            f"{len(self.network.aerodrome_ids)} aerodromes{', layered' if self.network.layered else ''}), "
            f"policy {self.policy}, backend {self.config.backend}, seed {self.config.seed}, separation "
            f"{self.config.separation.kind}, departure slot {self.config.airspace.departure_slot_s:g} s, "
            f"{len(self.config.constraints or ())} constraint(s)")

    def _on_fleet_msg(self, data: bytes) -> None:
        msg = FleetView.of_cdr(data)
        if msg is None:   # big-endian CDR: deserialized in full
            from rclpy.serialization import deserialize_message
            msg = FleetView.of_message(deserialize_message(data, FleetState))
        self._inbox.append(msg)
        if msg.session == self.bound_simulator:   # another session's stamp wakes no one
            self._stamped(msg.t_s, None)

    def _on_conformance_msg(self, msg: Conformance) -> None:
        self._inbox.append(msg)
        if msg.session == self.bound_simulator:
            self._stamped(None, m.from_time(msg.header.stamp))

    def _stamped(self, fleet_s, conformance_s) -> None:
        """A message arrived: wake the calls waiting for its time (``_await_stamps``)."""
        with self._stamp_lock:
            if fleet_s is not None:
                self._latest_fleet_s = max(self._latest_fleet_s, fleet_s)
            if conformance_s is not None:
                self._latest_conformance_s = max(self._latest_conformance_s, conformance_s)
            for t_s, need_conf, fut in self._stamp_waiters:
                if not fut.done() and self._stamps_reached(t_s, need_conf):
                    fut.set_result(True)

    def _stamps_reached(self, t_s: float, need_conformance: bool) -> bool:
        return self._latest_fleet_s >= t_s - 1e-6 and \
            (not need_conformance or self._latest_conformance_s >= t_s - 1e-6)

    async def _await_stamps(self, t_s: float) -> None:
        """In the reaction-between-epochs mode: wait (at most ``request_wait_timeout_s``) until the
        fleet state of ``t_s`` and, when a monitor publishes, its report of that fleet state have
        arrived. The simulator publishes them before it calls (it is blocked at t_s meanwhile),
        but a topic and a service are not ordered, so a call can come first."""
        if not self._observe_from_calls:
            return
        need_conf = bool(self.p["reaction"]) and \
            self.count_publishers(self.resolve_topic_name(c.TOPIC_CONFORMANCE)) > 0
        fut = Future()
        entry = (float(t_s), need_conf, fut)
        with self._stamp_lock:
            if self._stamps_reached(t_s, need_conf):
                return
            self._stamp_waiters.append(entry)
        timer = self.create_timer(self.p["request_wait_timeout_s"], lambda: fut.done() or fut.set_result(False),
                                  callback_group=self._group, clock=self._steady)
        try:
            ok = await fut
        finally:
            self.destroy_timer(timer)
            with self._stamp_lock:
                self._stamp_waiters.remove(entry)
        if not ok:
            self.get_logger().warning(
                f"t = {t_s:g} s: the fleet state{' and the conformance report' if need_conf else ''} of that "
                f"time did not arrive within {self.p['request_wait_timeout_s']:g} s; going on with what came")

    def _read_inbox(self, t_s: float | None = None, at_epoch: bool = True) -> None:
        """Under the lock, before an epoch (or a reaction between epochs) at ``t_s``: every fleet
        state and conformance report received, in the order received. In the reaction-between-
        epochs mode the fleet states are kept aside and observed at the runner's instants only
        (:meth:`_observe_at`)."""
        while self._inbox:
            msg = self._inbox.popleft()
            # only the bound simulator's, each step once (uam_planner.sources)
            if not isinstance(msg, FleetView):
                if self.source.take("conformance report", msg.session, msg.step_index, conformance_digest(msg)):
                    self._on_conformance(msg)
                continue
            if not self.source.take("fleet state", msg.session, msg.step_index, msg.digest):
                continue
            t = msg.t_s
            if self._observe_from_calls:
                seen = self._fleet_buffer.setdefault(stamp_key(t), {})
                for vid, pos in zip(msg.vehicle_ids, msg.positions_m.tolist()):
                    seen.setdefault(vid, tuple(pos))
            else:   # the planner's own observation of every vehicle in the fleet state
                self.planner.observe_fleet(msg.vehicle_ids, t, msg.positions_m)
        if self._observe_from_calls and t_s is not None:
            self._observe_at(float(t_s), at_epoch)

    def _observe_at(self, t_s: float, at_epoch: bool) -> None:
        """The planner's observations for a call at ``t_s``, as the in-process runner's monitor
        makes them (``uam_sim.runner.scenario._Reaction``): before an epoch, every vehicle airborne at
        t_s (in its fleet state) at t_s - 20, t_s - 10 and t_s; between epochs, at t_s only.

        Why the node follows the runner and not the other way round: the runner is the run code of
        the studies (their cells are keyed by its version, and the Monte-Carlo numbers of
        docs/disturbances.md were measured with it), and the progress rate a nonconforming update
        is timed at is estimated from these sightings, so a planner that counted every 1 s fleet
        state would time its updates differently from what was measured; one sighting every 10 s
        is also what a USS gets from a real surveillance feed more than a 1 Hz truth stream."""
        now = self._fleet_buffer.get(stamp_key(t_s))
        if now is None:
            self.get_logger().warning(f"t = {t_s:g} s: no fleet state of that time received; no vehicle observed")
        else:
            for back in (OBSERVE_BACK_S if at_epoch else (0.0,)):
                tb = t_s - back
                for vid, pos in (self._fleet_buffer.get(stamp_key(tb)) or {}).items():
                    if vid in now:   # airborne at t_s
                        self.planner.observe(vid, tb, pos)
        lo = stamp_key(t_s - max(OBSERVE_BACK_S))
        for key in [k for k in self._fleet_buffer if k < lo]:
            del self._fleet_buffer[key]

    def _on_conformance(self, msg: Conformance) -> None:
        """Each vehicle the monitor calls nonconforming: a claim, queued for the next epoch, where
        the planner checks it against its own view (``Planner.report_nonconforming``)."""
        ids, ok = list(msg.vehicle_ids), list(msg.conforming)
        if len(ids) != len(ok):
            self.conformance_reports_refused += 1
            self.get_logger().warning(f"conformance: {len(ids)} vehicle_ids but {len(ok)} conforming "
                                      f"flags: refused")
            return
        t = m.from_time(msg.header.stamp)
        for vid, good in zip(ids, ok):
            if good:
                continue
            self.conformance_reports += 1
            if self.planner.report_nonconforming(vid, t, "conformance_monitor") is not None:
                self.conformance_reports_refused += 1

    @property
    def config(self) -> PlanningConfig:
        """The planner's current configuration (backend, time limit and seed can change at run time)."""
        return self.planner.config

    def _on_change(self, name: str, value) -> None:
        if name in ("backend", "time_limit_s", "seed"):  # take effect at the next epoch
            with self._lock:
                self.planner.config = dataclasses.replace(self.planner.config, **{name: value})

    def _offer_service_when_ready(self) -> None:
        waited = time.monotonic() - self._started_at
        if self.p["use_solver_service"] and not self._client.service_is_ready() \
                and waited < self.p["solver_startup_timeout_s"]:
            return
        self._ready_timer.cancel()
        self.destroy_timer(self._ready_timer)
        if not self.p["use_solver_service"]:
            # local solves go through this process's solve service (uam_solvers.solve_bounded):
            # its workers start and warm up now, before the first epoch is asked for
            from uam_solvers.executor import shared_service

            shared_service()
        # the compiled check that decides (uam_planner.separation), compiled or loaded from its
        # cache now: seconds when cold, paid before the first epoch is asked for
        separation.warm_up()
        self._service = self.create_service(PlanEpoch, c.SERVICE_PLAN_EPOCH, self._on_plan_epoch,
                                            callback_group=self._group)
        self._react_service = self.create_service(React, c.SERVICE_REACT, self._on_react, callback_group=self._group)
        self.get_logger().info(f"serving {self.resolve_service_name(c.SERVICE_PLAN_EPOCH)}")

    # ---- live constraints (uam_planner.live_constraints) ---------------------------
    def _projected_constraints(self) -> dict:
        """constraint id -> Constraint once every queued update is applied."""
        cur = {k.constraint_id: k for k in self.config.constraints or ()}
        for u in self.planner.queued_updates:
            if u.action == "withdraw":
                cur.pop(u.constraint.constraint_id, None)
            else:
                cur[u.constraint.constraint_id] = u.constraint
        return cur

    def _on_update_constraint(self, request, response):
        """Queue (for the next epoch) or refuse one constraint update, naming the field and value."""
        with self._lock:
            now = self._next_epoch_s
            author = ""
            try:
                current = self._projected_constraints()
                action, what = parse_update(request, current, self.network)
                if self.authorities is None:
                    raise ConstraintError("authorization: no airspace authority is configured for this run "
                                          "(parameter authorities_file): live constraint updates are off")
                author = self.authorities.verify(request, action)
                self.authorities.check_owner(author, current.get(request.constraint_id))
                if action != "withdraw":
                    what = dataclasses.replace(what, author=author)
                error = self.planner.update_constraint(action, what, now) or ""
                if not error and action == "withdraw":
                    self._withdrawn_by[(request.constraint_id, int(request.version))] = (author, now)
            except ConstraintError as exc:
                action, error = str(request.action), str(exc)
            if error:
                self.constraint_updates_refused += 1
            response.accepted = not error
            response.error = wire.bounded(error)
            response.constraints = len(self._projected_constraints())
            response.effective_time = m.to_time(now)
        if error:
            self.get_logger().warning(f"refused a constraint update ({action} {wire.echo(request.constraint_id)}): "
                                      f"{response.error}")
        else:
            self.get_logger().info(f"constraint update accepted: {action} {request.constraint_id!r} "
                                   f"v{request.version} by {author!r}, from the epoch at t = {now:g} s")
        return response

    def _publish_constraint_changes(self, t_s: float) -> None:
        """After an epoch's prepare (under the lock): the set in force, if updates were applied."""
        log = self.planner.constraint_log
        if len(log) == self._constraints_logged:
            return
        for u in log[self._constraints_logged:]:
            if u.action == "withdraw":
                self._constraint_effective.pop(u.constraint.constraint_id, None)
                self._constraint_announced.pop(u.constraint.constraint_id, None)
                by = next((v for (cid, _ver), v in self._withdrawn_by.items()
                           if cid == u.constraint.constraint_id), ("", u.t_s))
                self._withdrawals.append({"id": u.constraint.constraint_id, "version": int(u.constraint.version),
                                          "by": by[0], "t_s": float(u.t_s), "applied_s": float(u.applied_s)})
                self._withdrawn_by = {k: v for k, v in self._withdrawn_by.items()
                                      if k[0] != u.constraint.constraint_id}
            else:
                self._constraint_effective[u.constraint.constraint_id] = float(u.applied_s)
                self._constraint_announced[u.constraint.constraint_id] = float(u.t_s)
        self._constraints_logged = len(log)
        self._publish_constraints(t_s)
        self.get_logger().info(f"epoch at t = {t_s:g} s: constraint update(s) applied, "
                               f"{len(self.config.constraints or ())} constraint(s) in force")

    def _publish_constraints(self, t_s: float) -> None:
        text = set_geojson(self.config.constraints or (), t_s, self._constraint_effective,
                           self._constraint_announced, self._withdrawals)
        self._sets_unreported.append(hashlib.sha256(text.encode("utf-8")).hexdigest())
        self._last_set_text = text
        journal = getattr(self, "journal", None)   # the first set is published before the journal opens
        if journal is not None and journal.started:
            journal.append_constraints(text)
        self._constraints_pub.publish(String(data=text))

    # ---- a USS's signed flight requests (uam_planner.signed_requests) ---------------------------
    def _decided(self, key: str, accepted: bool, why: str, t_s: float | None = None) -> None:
        """The decision on ``key``: to the USS call waiting for it, if one is."""
        fut = self._uss_waiters.pop(key, None)
        if fut is not None and not fut.done():
            fut.set_result((accepted, why, self._last_epoch_s if t_s is None else t_s))

    def _decided_at_epoch(self, result, t_s: float) -> None:
        """Under the lock, after an epoch's commit: its decisions to the USS calls waiting."""
        from uam_planner.replanning import KIND_MODIFIED
        if not self._uss_waiters:
            return
        for f in result.approved:
            self._decided(f.request_id, True, "", t_s)
        for u in result.plan_updates:
            if u.kind == KIND_MODIFIED:
                self._decided(u.request_id, True, "", t_s)
        refusals = result.report.constraint_refusals
        for r in result.expired:
            self._decided(r.request_id, False, refusals.get(r.request_id) or
                          f"no conflict-free departure found by latest_departure {r.latest_departure_s:g} s", t_s)
        for rid, (why, _kept) in result.refused_modifications.items():
            self._decided(rid, False, why, t_s)

    def _wake_idle(self) -> None:
        waiting, self._idle_waiters = self._idle_waiters, []
        for fut in waiting:
            if not fut.done():
                fut.set_result(True)

    def _busy(self) -> bool:
        """An epoch or a reaction is being planned (the planner's flights may not change now)."""
        return self._inflight is not None or self._react_inflight is not None or self._deferred is not None

    def _uss_refused(self, request, response, error: str, signed: bool):
        response.accepted, response.error = False, wire.bounded(error)
        response.effective_time = m.to_time(self._last_epoch_s)
        if not signed:   # not the USS's: recorded apart from its own refused requests
            self.uss_requests_refused += 1
            self.get_logger().warning(f"refused a flight request on {c.SERVICE_USS_FLIGHT_PLAN} "
                                      f"({wire.echo(request.constraint_id)}): {response.error}")
        return response

    async def _on_uss_flight_plan(self, request, response):
        """One operation of a USS (plan, modify, cancel), signed by the airspace authority that
        holds the request's operator; answered once decided (plan, modify: at the epoch that
        decides; cancel: at once), naming the field and value when refused."""
        from uam_planner import signed_requests as sr
        with self._lock:
            try:
                op = sr.op_of(request.action)
                if self.authorities is None:
                    raise ConstraintError("authorization: no airspace authority is configured for this run "
                                          "(parameter authorities_file): a USS's requests are refused")
                author = self.authorities.verify(request, sr.ACT_PREFIX + op, channel=sr.CHANNEL)
                fields = sr.request_fields(request.geojson, op)
                self.authorities.check_operator(author, fields["operator_id"])
                problem = wire.check_id("request_id", request.constraint_id)
                if problem:
                    raise ConstraintError(problem)
            except ConstraintError as exc:
                return self._uss_refused(request, response, str(exc), signed=False)
        key = wire.scoped_id(fields["operator_id"], request.constraint_id)
        while True:   # act between epochs only
            with self._lock:
                if self._held is not None:
                    return self._uss_refused(request, response, "planner: no epoch planned yet (the run has not "
                                             "started); ask again", signed=True)
                if not self._busy():
                    fut = self._uss_act(op, key, fields, request, author)
                    break
                idle = Future()
                self._idle_waiters.append(idle)
            await idle
        accepted, why, t_s = await fut
        response.accepted, response.error = bool(accepted), wire.bounded(why)
        response.effective_time = m.to_time(t_s)
        response.constraints = len(self.config.constraints or ())
        self.get_logger().info(f"{op} {key!r} by {author!r}: {'done' if accepted else 'refused: ' + response.error}")
        return response

    def _uss_act(self, op: str, key: str, fields: dict, request, author: str) -> Future:
        """Under the lock, between epochs: do ``op`` on ``key``; the Future of its decision."""
        fut = Future()
        now = self._next_epoch_s
        if op == "cancel":
            why = self.planner.cancel(key, now, request.reason or "cancelled by its USS") or ""
            fut.set_result((not why, why, now))
            return fut
        msg = FlightRequest(operator_id=fields["operator_id"], request_id=request.constraint_id,
                            origin_id=fields["origin_id"], destination_id=fields["destination_id"],
                            request_time=m.to_time(fields["request_time_s"]),
                            earliest_departure=m.to_time(fields["earliest_departure_s"]),
                            latest_departure=m.to_time(fields["latest_departure_s"]), priority=fields["priority"])
        self._uss_waiters[key] = fut
        if op == "plan":
            self.requests_received += 1
            got = self._decide(msg, signed_by=author)
            if got is not None and not fut.done():
                self._arrived(got)
            return fut
        why = wire.check_request(msg, now, max_window_s=self.p["max_window_s"],
                                 max_request_lead_s=self.p["max_request_lead_s"]) or \
            self.planner.modify(m.request_from_msg(msg, request_id=key), now)
        if why:
            self._decided(key, False, why, now)
        return fut

    # ---- requests ----------------------------------------------------------------------------
    def _publish_plan(self, plan: FlightPlan) -> None:
        self._plan_pub.publish(plan)
        self.plans_published += 1

    def _answer(self, msg: FlightRequest, outcome: int, reason: str, ids_ok: bool) -> None:
        """Publish the refusal of ``msg`` (and, when ``ids_ok``, answer the USS call waiting for
        its id, if one is)."""
        reason = wire.bounded(reason)
        origin = msg.origin_id if len(msg.origin_id) <= wire.MAX_NODE_ID_LENGTH else ""
        dest = msg.destination_id if len(msg.destination_id) <= wire.MAX_NODE_ID_LENGTH else ""
        # a bad id is kept, escaped and cut (wire.escaped_id), so two refusals never look like
        # two decisions on one id
        plan = m.unapproved_plan(wire.escaped_id(msg.request_id), origin, dest, outcome, reason,
                                 self._last_epoch_s, max(self._next_epoch - 1, 0), self.policy)
        plan.operator_id = wire.escaped_id(msg.operator_id)
        self._publish_plan(plan)
        if ids_ok:
            self._decided(wire.scoped_id(msg.operator_id, msg.request_id), False, reason)
        self.planner.record_rejection()
        # at most one log line a second: rclpy's logger costs milliseconds a call, which a flood
        # would turn into minutes (its own throttling pays that cost on every call too)
        self._refused_unlogged += 1
        now = time.monotonic()
        if now - self._refusal_logged_at >= 1.0:
            more = f" (and {self._refused_unlogged - 1} more since the last such line)" if self._refused_unlogged > 1 else ""
            self.get_logger().warning(f"refused a request: {reason}{more}")
            self._refusal_logged_at, self._refused_unlogged = now, 0

    def _on_request(self, msg: FlightRequest) -> None:
        with self._lock:
            self.requests_received += 1
            if self._held is not None:  # the simulation time is not known yet: decided at the first epoch
                self._held.append(msg)
                return
            if self._deferred is not None:  # an epoch's prepare awaits the solver: decided after it
                self._deferred.append(msg)
                return
            key = self._decide(msg)
            if key is not None:
                self._arrived(key)

    def _decide_held(self, t_s: float, resumed: bool) -> None:
        """Decide the requests that arrived before the first epoch call, in arrival order. After a
        resume, those the simulator says were decided, or whose window has closed (they were decided
        before the restart), come from the generator's latched history: nothing is answered twice."""
        held, self._held = self._held or [], None
        self._next_epoch_s = t_s
        for msg in held:
            if resumed:
                key = wire.scoped_id(msg.operator_id, msg.request_id)
                if key in self._taken or m.from_time(msg.latest_departure) < t_s:
                    continue
            self._decide(msg)

    def _decide(self, msg: FlightRequest, signed_by: str = "") -> str | None:
        """Accept or refuse ``msg`` now; return its scoped id when the ids are valid. ``signed_by``:
        the authority that signed it (uam/uss_flight_plan); a request of an operator that an
        authority holds is taken only signed by that authority."""
        ids_ok = not (wire.check_id("operator_id", msg.operator_id) or wire.check_id("request_id", msg.request_id))
        key = wire.scoped_id(msg.operator_id, msg.request_id) if ids_ok else None
        holder = self.authorities.operator_authority(msg.operator_id) if self.authorities is not None else None
        if holder is not None and signed_by != holder:
            # neither taken nor answered as a decision on the id: a forger can neither use up
            # the operator's ids nor pass for the planner's answer to its USS
            self._answer(msg, FlightPlan.OUTCOME_REJECTED,
                         f"operator_id: {msg.operator_id!r}'s requests are taken only signed by airspace authority "
                         f"{holder!r} on {c.SERVICE_USS_FLIGHT_PLAN}", False)
            return None
        if key is not None and key in self._taken:
            self._answer(msg, FlightPlan.OUTCOME_DUPLICATE,
                         f"request_id: {msg.request_id!r} of operator {msg.operator_id!r} is already taken; "
                         "its decision stands", True)
            return key
        reason = wire.check_request(msg, self._next_epoch_s, max_window_s=self.p["max_window_s"],
                                    max_request_lead_s=self.p["max_request_lead_s"])
        if not reason:
            if self._waiting_per_operator[msg.operator_id] >= self.p["max_pending_per_operator"]:
                reason = (f"operator_id: {msg.operator_id!r} has {self._waiting_per_operator[msg.operator_id]} "
                          "requests waiting, its quota (max_pending_per_operator); send more once they are decided")
            elif len(self.planner.pending) >= self.p["max_pending"]:
                reason = f"request: the planner's queue is full ({len(self.planner.pending)} waiting, max_pending)"
            elif msg.operator_id not in self._established and \
                    self._waiting_new() >= self.p["max_pending_new_operators"]:
                # operators that came before this epoch keep their share of the queue: a flood of
                # new operator ids cannot push them out (docs/security.md)
                reason = (f"operator_id: {msg.operator_id!r} is new and operators new in this epoch hold "
                          f"{self._waiting_new()} waiting requests (max_pending_new_operators); send again later")
        if not reason:
            reason = self.planner.submit(m.request_from_msg(msg, request_id=key)) or ""
            if not reason:
                self._taken.add(key)
                self._waiting_per_operator[msg.operator_id] += 1
                if msg.operator_id not in self._established:
                    self._new_operators.add(msg.operator_id)
                return key
        if key is not None:
            self._taken.add(key)
        self._answer(msg, FlightPlan.OUTCOME_REJECTED, reason, ids_ok)
        return key

    def _arrived(self, key: str) -> None:
        for missing, fut in self._waiters:
            missing.discard(key)
            if not missing and not fut.done():
                fut.set_result(True)

    def _on_sync(self, msg: EpochSync) -> None:
        # only the simulator this planner serves ends its run (a forged announcement does not)
        if msg.sender == "simulator" and msg.finished and self.bound_simulator is not None \
                and msg.session == self.bound_simulator:
            self.finished = True

    # ---- the epoch protocol ------------------------------------------------------------------
    def _refuse_call(self, request: PlanEpoch.Request, response: PlanEpoch.Response, status: int,
                     message: str) -> PlanEpoch.Response:
        response.status = status
        response.message = wire.bounded(message)
        response.session = self.session
        if status == PlanEpoch.Response.STATUS_REFUSED:
            self._log_refused_call(message)
        return response

    def _log_refused_call(self, message: str) -> None:
        now = time.monotonic()
        if now - self._call_refusal_logged_at >= 1.0:
            self._call_refusal_logged_at = now
            self.get_logger().warning(f"refused an epoch call: {wire.bounded(message)}")

    def _check_call(self, request: PlanEpoch.Request) -> str:
        """Why this epoch call is not one of the bound simulator's (or malformed), or ''."""
        session = request.session
        if not session or len(session) > wire.MAX_ID_LENGTH:
            return f"session: {wire.echo(session)} must be the simulator's run token (1 to {wire.MAX_ID_LENGTH} characters)"
        if self.bound_simulator is not None and session != self.bound_simulator:
            # (the bound simulator's token is not echoed to a caller that does not hold it)
            return (f"session: {wire.echo(session)} is not the simulator this planner serves; "
                    "a second simulator is refused")
        if self.source.problem:
            return self.source.problem
        if not (math.isfinite(request.epoch_s) and request.epoch_s > 0):
            return f"epoch_s: {request.epoch_s!r} must be a positive number of seconds"
        if self._epoch_s is not None and request.epoch_s != self._epoch_s:
            return f"epoch_s: {request.epoch_s!r} differs from the run's epoch length {self._epoch_s!r} s (fixed at start)"
        t_s = m.from_time(request.epoch_time)
        if not math.isclose(t_s, request.epoch_index * request.epoch_s, rel_tol=1e-9, abs_tol=1e-6):
            return (f"epoch_time: {t_s!r} s is not epoch_index {request.epoch_index} x epoch_s "
                    f"{request.epoch_s!r} s")
        if len(request.expected_request_ids) > self.p["max_pending"]:
            return (f"expected_request_ids: {len(request.expected_request_ids)} ids, more than the planner "
                    f"can hold waiting (max_pending {self.p['max_pending']})")
        if request.resume and len(request.airborne) > self.p["max_pending"] * 10:
            return f"airborne: {len(request.airborne)} flights is not a plausible airborne fleet"
        return ""

    async def _on_plan_epoch(self, request: PlanEpoch.Request, response: PlanEpoch.Response):
        k = int(request.epoch_index)
        with self._lock:
            problem = self._check_call(request)
            if problem:
                return self._refuse_call(request, response, PlanEpoch.Response.STATUS_REFUSED, problem)
            if self._last is not None and self._last[0] == k:
                return self._last[1]
            if self._react_inflight is not None:
                return self._refuse_call(request, response, PlanEpoch.Response.STATUS_REFUSED,
                                         f"epoch_index: {k} asked while the reaction at t = "
                                         f"{self._react_inflight[1] * 1e-6:g} s is being computed")
            if self._inflight is not None:
                # answered at once: a waiting repeat would be one more suspended task that the
                # executor resumes at every wake-up
                same = self._inflight == k
                return self._refuse_call(
                    request, response,
                    PlanEpoch.Response.STATUS_IN_PROGRESS if same else PlanEpoch.Response.STATUS_REFUSED,
                    f"epoch {self._inflight} is being planned" if same else
                    f"epoch_index: {k} asked while epoch {self._inflight} is being planned")
            fresh = self._fresh()
            if request.resume and not fresh:
                # the resume path is for a planner that restarted and holds nothing: one that
                # holds flights never lets a caller replace (or wipe) them
                return self._refuse_call(request, response, PlanEpoch.Response.STATUS_REFUSED, (
                    f"resume: refused, this planner holds {len(self.planner.active)} flights and "
                    f"{len(self.planner.pending)} waiting requests of its own (next epoch {self._next_epoch}); "
                    "a resume may not replace them"))
            if k != self._next_epoch:
                if fresh and not request.resume:
                    return self._refuse_call(request, response, PlanEpoch.Response.STATUS_NEED_STATE,
                                             f"planner started mid-run (epoch {k}): send the flights and decisions")
                if not (fresh and request.resume):
                    return self._refuse_call(request, response, PlanEpoch.Response.STATUS_REFUSED,
                                             f"epoch_index: {k} asked, the next epoch is {self._next_epoch}")
            t_s = m.from_time(request.epoch_time)
            if request.resume:
                problem = self._resume(request, t_s)
                if problem:
                    return self._refuse_call(request, response, PlanEpoch.Response.STATUS_REFUSED, problem)
            if self.bound_simulator is None:
                self._bind(request.session, resumed=bool(request.resume))
            if request.observe_at_instants:   # the simulator stops at each instant it asks about
                self._observe_from_calls = True
            self._epoch_s = float(request.epoch_s)
            if self._held is not None:
                self._decide_held(t_s, bool(request.resume))
            if self.config.epoch_s != request.epoch_s:
                self.planner.config = dataclasses.replace(self.planner.config, epoch_s=float(request.epoch_s))
            self._inflight = k
        try:
            return await self._plan(k, t_s, list(request.expected_request_ids), response)
        finally:
            with self._lock:
                self._inflight = None
                self._wake_idle()

    def _fresh(self) -> bool:
        """True while this planner holds nothing of a run: no epoch planned, no resume taken."""
        return self._next_epoch == 0 and self.epochs_planned == 0 and not self.resumed and \
            self.bound_simulator is None and not self.planner.active

    def _journal(self, plans, flights) -> None:
        """Journal ``plans`` with the priority class of each one's flight (``flights``; None for
        a cancellation): the planner's own record, which the USS node serves."""
        if self.journal is None:
            return
        classes = {}
        for f in flights:
            if f is not None:
                classes[tuple(wire.split_scoped(f.request_id))] = int(getattr(f, "priority", 0))
        self.journal.append(plans, classes)

    def _bind(self, session: str, resumed: bool) -> None:
        self.bound_simulator = session
        self.source.bind(session)
        # the fleet states and reports of this simulator that arrived before it called: their
        # stamps count for the waits (_await_stamps) from now on (a t = 0 state waited 60 s)
        for msg in list(self._inbox):
            if msg.session != session:
                continue
            if isinstance(msg, FleetView):
                self._stamped(msg.t_s, None)
            else:
                self._stamped(None, m.from_time(msg.header.stamp))
        if self.journal is not None:
            self.journal.start(session, keep=resumed)
            self.journal.append_constraints(self._last_set_text)   # the set in force from the start
        self.get_logger().info(f"serving the simulator of session {session!r} (this planner: {self.session!r})")

    def _resume(self, request: PlanEpoch.Request, t_s: float) -> str:
        """A planner started mid-run takes the simulator's state: what flies, what was decided.
        With a journal of the same run, the claim must agree with the planner's own approvals
        (none left out while still flying, none added, none changed); returns why not, or ''."""
        claimed = {}
        for p in request.airborne:
            if p.outcome != FlightPlan.OUTCOME_APPROVED or wire.check_id("operator_id", p.operator_id) \
                    or wire.check_id("request_id", p.request_id):
                return f"airborne: {wire.echo(p.operator_id)}/{wire.echo(p.request_id)} is not an approved plan with valid ids"
            claimed[wire.scoped_id(p.operator_id, p.request_id)] = p
        if self.journal is not None:
            try:
                journaled = self.journal.read(request.session)
            except ValueError as exc:
                return f"resume: {exc}"
            # approvals of this epoch or later never reached the simulator (it asks for this
            # epoch again): they never flew, and none can be claimed; of the rest, each flight's
            # newest version (re-plans) is what flies
            k = int(request.epoch_index)
            own = newest_versions(journaled, k, t_s)
            flying = {key for key, p in own.items() if p.outcome == FlightPlan.OUTCOME_APPROVED
                      and m.from_time(p.arrival_time) >= t_s}
            left_out = sorted(flying - set(claimed))
            unknown = sorted(set(claimed) - set(own))
            changed = sorted(key for key in set(claimed) & set(own) if claimed[key].waypoints != own[key].waypoints)
            if left_out or unknown or changed:
                why = "; ".join(part for part in (
                    f"{len(left_out)} flight(s) it approved and still flying are left out ({left_out[:3]})" if left_out else "",
                    f"{len(unknown)} it never approved are claimed ({unknown[:3]})" if unknown else "",
                    f"{len(changed)} are changed ({changed[:3]})" if changed else "") if part)
                self.get_logger().error(f"resume refused: the claim contradicts the planner's journal: {why}")
                return f"resume: the claim contradicts the planner's journal {self.journal.path}: {why}"
        elif claimed or request.decided_request_ids:
            self.get_logger().warning("resume without a journal: the claimed airborne set cannot be checked "
                                      "against this planner's own approvals (parameter journal)")
        flights = [m.flight_from_plan(p, request_id=key) for key, p in claimed.items()]
        decided = set(request.decided_request_ids)
        self.planner.restore(flights, decided)
        self._taken |= decided | set(claimed)
        self._count_waiting()
        self.resumed = True
        self.get_logger().warning(
            f"resumed at epoch {request.epoch_index} (t={t_s:g} s): {len(flights)} flights in the air, "
            f"{len(decided)} requests decided before, {len(self.planner.pending)} waiting")
        return ""

    def _count_waiting(self) -> None:
        self._waiting_per_operator = collections.Counter(
            wire.split_scoped(r.request_id)[0] for r in self.planner.pending)

    def _waiting_new(self) -> int:
        return sum(self._waiting_per_operator[op] for op in self._new_operators)

    def _new_epoch_for_operators(self) -> None:
        """At an epoch: the operators first accepted since the last one are established now."""
        self._established |= self._new_operators
        self._new_operators = set()

    async def _wait_for(self, expected: list[str]) -> list[str]:
        """Wait until every expected request arrived or request_wait_timeout_s; return the missing."""
        with self._lock:
            missing = set(expected) - self._taken
            if not missing:
                return []
            fut = Future()
            entry = (missing, fut)
            self._waiters.append(entry)
        timer = self.create_timer(self.p["request_wait_timeout_s"], lambda: fut.done() or fut.set_result(False),
                                  callback_group=self._group, clock=self._steady)
        try:
            await fut
        finally:
            self.destroy_timer(timer)
            with self._lock:
                self._waiters.remove(entry)
        return sorted(missing)

    async def _plan(self, k: int, t_s: float, expected: list[str], response: PlanEpoch.Response):
        missing = await self._wait_for(expected)
        if missing:
            self.get_logger().warning(f"epoch {k}: planning without {len(missing)} expected request(s) that did "
                                      f"not arrive within {self.p['request_wait_timeout_s']:g} s: {missing[:5]}")
        prep = await self._prepare(t_s, k)
        t0 = time.perf_counter()
        answer = await self._solve(prep.graph) if prep.needs_solver else None
        solve_s = time.perf_counter() - t0
        with self._lock:
            result = self.planner.commit(prep, answer, solve_s)
            self.held_past_plan.update(result.report.overruns)
            plans = [m.approved_plan(f, t_s, self.policy, request_id=wire.split_scoped(f.request_id)[1])
                     for f in result.approved]
            for plan, f in zip(plans, result.approved):
                plan.operator_id = wire.split_scoped(f.request_id)[0]
            for u in result.plan_updates:   # new versions and cancellations
                if u.kind == "kept":
                    continue
                op, rid = wire.split_scoped(u.request_id)
                plan = m.plan_update_msg(u, t_s, self.policy, request_id=rid)
                plan.operator_id = op
                plans.append(plan)
            # before anyone can hold them
            self._journal(plans, [*result.approved, *(u.flight for u in result.plan_updates)])
            refusals = result.report.constraint_refusals
            for req in result.expired:
                op, rid = wire.split_scoped(req.request_id)
                why = refusals.get(req.request_id) or \
                    f"no conflict-free departure found by latest_departure {req.latest_departure_s:g} s"
                plan = m.unapproved_plan(
                    rid, req.origin_id, req.destination_id, FlightPlan.OUTCOME_EXPIRED,
                    wire.bounded(why), t_s, k, self.policy)
                plan.operator_id = op
                plans.append(plan)
            for plan in plans:
                self._publish_plan(plan)
            self._decided_at_epoch(result, t_s)
            report = m.report_to_msg(result.report)
            # the constraint sets published since the previous report: what the analysis tells
            # the planner's sets on uam/constraints from forged ones by
            report.constraint_set_sha256 = " ".join(self._sets_unreported)
            self._sets_unreported = []
            self._report_pub.publish(report)
            if result.report.fallback:
                self.get_logger().warning(
                    f"epoch {k}: MWIS fallback to {result.report.backend_used}: {result.report.fallback_reason}")
            self._count_waiting()
            self._new_epoch_for_operators()
            self._next_epoch = k + 1
            self._next_epoch_s = t_s + self.config.epoch_s
            self._last_epoch_s = t_s
            self.epochs_planned += 1
            self._sync_pub.publish(EpochSync(
                epoch_index=k, epoch_time=m.to_time(t_s), sender="planner", plans_published=self.plans_published,
                requests_received=self.requests_received, session=self.session))
            response.status = PlanEpoch.Response.STATUS_PLANNED
            response.session = self.session
            response.message = f"epoch {k}: {len(result.approved)} approved, {len(result.expired)} expired"
            response.plans = plans
            response.report = report
            response.missing_request_ids = missing
            self._last = (k, response)
        return response

    async def _prepare(self, t_s: float, k: int):
        """``Planner.prepare`` with its batch re-plan's MWIS graphs (the constraint updates due,
        docs/replanning.md) solved through the solver service, awaited as the epoch's own graph
        is, so ``backend`` and the solver node's deadlines apply to them too. The lock is held
        while the planner computes, not while it awaits; requests arriving meanwhile are decided
        after the prepare (they wait for the next epoch, as in the in-process runner)."""
        prep = None
        await self._await_stamps(t_s)   # in the reaction-between-epochs mode only
        with self._lock:
            self._read_inbox(t_s)   # the fleet states and conformance reports received so far
            steps = self.planner.prepare_steps(t_s, k)
            self._deferred = []
        try:
            prep = await self._drive_steps(steps, "replan_graphs_by_service")
        finally:
            with self._lock:
                deferred, self._deferred = self._deferred or [], None
                for msg in deferred:
                    key = self._decide(msg)
                    if key is not None:
                        self._arrived(key)
        with self._lock:
            self._publish_constraint_changes(t_s)
        return prep

    # ---- the reaction between epochs ------------------------------------------------
    def _check_react(self, request: React.Request, t_s: float) -> str:
        """Why this reaction call is not one this planner serves now, or ''."""
        session = request.session
        if not session or len(session) > wire.MAX_ID_LENGTH:
            return f"session: {wire.echo(session)} must be the simulator's run token (1 to {wire.MAX_ID_LENGTH} characters)"
        if self.bound_simulator is None:
            return "react: no epoch planned yet; a reaction comes between two epochs of the bound simulator"
        if session != self.bound_simulator:
            # (the bound simulator's token is not echoed to a caller that does not hold it)
            return (f"session: {wire.echo(session)} is not the simulator this planner serves; "
                    "a second simulator is refused")
        if self.source.problem:
            return self.source.problem
        if not self.p["reaction"]:
            return "reaction: the planner's reaction to nonconformance is off (parameter reaction); nothing to react with"
        if not (math.isfinite(request.epoch_s) and request.epoch_s == self._epoch_s):
            return f"epoch_s: {request.epoch_s!r} is not the run's epoch length {self._epoch_s!r} s"
        if self._inflight is not None:
            return f"react: epoch {self._inflight} is being planned"
        last = self._next_epoch - 1
        if int(request.epoch_index) != last:
            return f"epoch_index: {request.epoch_index} is not the epoch planned last ({last})"
        lo, hi = self._last_epoch_s, self._last_epoch_s + self._epoch_s
        if not (math.isfinite(t_s) and lo + 1e-6 < t_s < hi - 1e-6):
            return (f"react_time: {t_s!r} s is not strictly between the epoch at {lo:g} s and the next "
                    f"at {hi:g} s")
        return ""

    async def _on_react(self, request: React.Request, response: React.Response):
        """The simulator's call at a reaction instant between epochs: the claims due are checked
        and acted on now (``Planner.react_between_steps``, its MWIS graphs through the solver
        service), the new versions published and returned. A repeat of the last call gets its
        answer again; an older instant, another session or a time outside the epoch is refused."""
        t_s = m.from_time(request.react_time)
        k = int(request.epoch_index)
        with self._lock:
            problem = self._check_react(request, t_s)
            key = (k, stamp_key(t_s))
            if not problem and self._last_react is not None and self._last_react[0] == key:
                return self._last_react[1]
            if not problem and self._react_inflight is not None:
                if self._react_inflight == key:
                    response.status, response.session = React.Response.STATUS_IN_PROGRESS, self.session
                    response.message = f"the reaction at t = {t_s:g} s is being computed"
                    return response
                problem = (f"react_time: {t_s:g} s asked while the reaction at "
                           f"{self._react_inflight[1] * 1e-6:g} s is being computed")
            if not problem and t_s <= self._last_react_s + 1e-6:
                problem = (f"react_time: {t_s:g} s is not after the last reaction, at "
                           f"{self._last_react_s:g} s (reactions come in time order)")
            if problem:
                response.status, response.session = React.Response.STATUS_REFUSED, self.session
                response.message = wire.bounded(problem)
                self._log_refused_call("react: " + problem)
                return response
            self._react_inflight = key
            self._observe_from_calls = True
        try:
            return await self._react(k, t_s, key, response)
        finally:
            with self._lock:
                self._react_inflight = None
                self._wake_idle()

    async def _drive_steps(self, steps, served_counter: str):
        """Run a planner step generator (``prepare_steps``, ``react_between_steps``) to its value:
        each MWIS graph it yields is solved through ``_solve`` (awaited outside the lock), and
        the attribute ``served_counter`` counts the graphs the solver service answered."""
        with self._lock:
            try:
                graph = next(steps)
            except StopIteration as done:
                return done.value
        while True:
            answer = await self._solve(graph)
            if self.p["use_solver_service"] and not isinstance(answer, (str, BaseException)):
                setattr(self, served_counter, getattr(self, served_counter) + 1)
            with self._lock:
                try:
                    graph = steps.send(answer)
                except StopIteration as done:
                    return done.value

    async def _react(self, k: int, t_s: float, key: tuple, response: React.Response):
        await self._await_stamps(t_s)
        with self._lock:
            self._read_inbox(t_s, at_epoch=False)
            steps = self.planner.react_between_steps(t_s, k)
            self._deferred = []
        updates, error = None, ""
        try:
            updates = await self._drive_steps(steps, "between_graphs_by_service")
        except (ValueError, RuntimeError) as exc:   # the planner's own refusal: nothing changed
            error = f"react: {exc}"
        finally:
            with self._lock:
                deferred, self._deferred = self._deferred or [], None
                for msg in deferred:
                    rid = self._decide(msg)
                    if rid is not None:
                        self._arrived(rid)
        with self._lock:
            response.session = self.session
            if error:
                response.status, response.message = React.Response.STATUS_REFUSED, wire.bounded(error)
                self._log_refused_call(error)
                return response
            plans = []
            for u in updates:
                if u.kind == "kept":
                    continue
                op, rid = wire.split_scoped(u.request_id)
                plan = m.plan_update_msg(u, t_s, self.policy, request_id=rid)
                plan.operator_id = op
                plans.append(plan)
            self._journal(plans, [u.flight for u in updates])  # before anyone can hold them
            for plan in plans:
                self._publish_plan(plan)
            self.reactions_between += 1
            self.between_updates += len(plans)
            self._last_react_s = t_s
            response.status = React.Response.STATUS_REACTED
            response.message = f"reaction at t = {t_s:g} s (after epoch {k}): {len(plans)} update(s)"
            response.plans = plans
            self._last_react = (key, response)
        return response

    async def _solve(self, graph):
        """The solver's answer for ``graph``, or why there is none (the commit then falls back)."""
        cfg = self.config
        if not self.p["use_solver_service"]:
            return call_solver(default_solve_mwis(cfg), graph)
        name = self.resolve_service_name(c.SERVICE_SOLVE)
        if not self._client.service_is_ready():
            self.get_logger().warning(f"solver service {name} is not available; solving with greedy locally")
            return f"solver service {name} is not available"
        timeout_s = cfg.time_limit_s + self.p["solver_timeout_margin_s"]
        fut = self._client.call_async(m.solve_request(graph.weights, graph.edges, graph.groups, cfg.backend,
                                                      cfg.time_limit_s, cfg.seed))
        timer = self.create_timer(timeout_s, lambda: fut.done() or fut.cancel(), callback_group=self._group,
                                  clock=self._steady)
        try:
            res = await fut
        finally:
            self.destroy_timer(timer)
        if fut.cancelled():
            self._client.remove_pending_request(fut)
            msg = f"solver service {name} did not answer within {timeout_s:.1f} s"
            self.get_logger().warning(msg + "; solving with greedy locally")
            return msg
        if res is None or not res.success:
            msg = f"solver service refused or failed: {wire.bounded(getattr(res, 'message', 'no response'))}"
            self.get_logger().warning(msg + "; solving with greedy locally")
            return msg
        return m.solve_answer(res)


def main(args=None) -> int:
    return run_node(PlannerNode, "planner", args)


if __name__ == "__main__":
    sys.exit(main())
