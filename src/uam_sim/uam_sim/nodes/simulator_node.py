"""Simulator node: owns simulation time, drives the epoch protocol, moves the fleet.

    ros2 run uam_sim simulator --ros-args --params-file config/simulator.yaml

Publishes /clock (rosgraph_msgs/Clock, for recordings and viewers with use_sim_time; the nodes
of the graph take time from the epoch protocol instead), uam/fleet_state
(uam_msgs/FleetState) and uam/fleet_poses (geometry_msgs/PoseArray, for generic viewers) at
every step, and announces each epoch and the end of the run on uam/epoch_sync (for the recorder
and observers). Parameters: uam_contract.params.SIMULATOR (docs/parameters.md).

The epoch protocol, at each epoch time t = k * epoch_s < duration_s: ask the demand source to
release the epoch's requests (uam/release_demand; it answers with their ids), then ask the
planner to plan epoch k at t (uam/plan_epoch, naming those ids), and fly the approvals of the
answer (exactly as planned, or, with disturbances on, as the path-following model of
uam_sim.world.disturbance flies them: the fleet state is what flew); only then step on. Between epochs it steps as fast as it can
(lockstep) or at ``real_time_factor`` x wall time (realtime): the result does not depend on CPU
speed. It starts once the planner's and the demand source's services are up and the nodes named
in ``wait_for_subscribers`` subscribe to the fleet state (explicit readiness, no counts). A call
without an answer is sent again every RESEND_S, the earlier ones kept (the planner answers a
repeat of the epoch in progress with STATUS_IN_PROGRESS, and whichever call it answers counts); a
planner that restarted lost the first call, answers the repeat with STATUS_NEED_STATE and gets
the state (flights in the air, requests decided). Plans on uam/flight_plans are not flown: only the planner's answers are.

The run ends at ``duration_s``: the simulator announces ``finished``, and the other nodes exit.

The reaction between epochs (``reaction_period_s`` > 0, less than ``epoch_s``): at every
instant epoch time + k x period strictly between two epochs the fleet stops, its state of that
instant is published, the planner is asked to react (uam/react, uam_msgs/srv/React) and the new
plan versions of its answer are flown from that instant (a nonconforming update from where the
aircraft is, at its airspeed, uam_sim.world.disturbance.fly_on). In that mode an epoch's fleet state is
published before the epoch is asked for (its departures appear from the next step) and the next
epoch is asked for only when the fleet reaches it, so the planner sees the fleet at the instants
the in-process runner's monitor does (docs/disturbances.md).

One partner each (docs/security.md): every call carries this simulator's run token
(``session``); it binds to the first planner and the first demand source that answer (their
tokens, announced on uam/epoch_sync as ``partners``) and ends the run, with the reason, when an
answer comes from another, or when more than one node serves either service. A planner that
restarted (a new token answering STATUS_NEED_STATE while it is the only server) is taken on.
Every wait is bounded (``startup_timeout_s``, ``ack_timeout_s``); a run that ends early
announces why (``error`` of the ``finished`` announcement), so no recording of it reads as
complete.
"""

from __future__ import annotations

import math
import secrets
import sys
import time

from geometry_msgs.msg import PoseArray
from rclpy.node import Node
from rosgraph_msgs.msg import Clock
from uam_msgs.msg import EpochSync, FleetState, FlightPlan
from uam_msgs.srv import PlanEpoch, React, ReleaseDemand

from uam_contract import names as c
from uam_planner.nodes import conversions as m
from uam_bringup import qos
from uam_contract import wire
from uam_bringup.params import declare_table
from uam_contract.params import SIMULATOR
from uam_bringup.runtime import run_node
from uam_sim.recording.cdr import encode_clock, encode_fleet_state, encode_pose_array, yaw_quaternions
from uam_sim.world.disturbance import WindField, fly_plans, from_simulator_params
from uam_planner.conformance import RATE_RANGE
from uam_sim.world.fleet import Fleet

RESEND_S = 2.0  # wall time after which an unanswered call is sent again (a restarted server lost it)
# Lockstep steps this many fleet steps per executor turn, so the answers of the next epoch's calls
# (sent as soon as an epoch is flown) are handled while the fleet is stepped towards that epoch.
STEPS_PER_TURN = 3



def observed_rate(plan) -> float | None:
    """The observed progress rate a plan update of the reaction carries
    (``FlightPlan.observed_progress_rate``), or None: 0 (every other plan), or a value
    outside the rates the planner estimates (``uam_planner.nonconformance.RATE_RANGE``)."""
    v = float(getattr(plan, "observed_progress_rate", 0.0) or 0.0)
    return v if math.isfinite(v) and RATE_RANGE[0] <= v <= RATE_RANGE[1] else None

class SimulatorNode(Node):
    # long (over 80 lines): ROS glue that declares the node's parameters, state and interfaces
    # one by one; no logic to split into steps
    def __init__(self, **kwargs):
        super().__init__("simulator", **kwargs)
        self.p = declare_table(self, SIMULATOR, on_change=self._on_change)
        self.step_s, self.duration_s, self.epoch_s = self.p["step_s"], self.p["duration_s"], self.p["epoch_s"]
        self.mode, self.rtf = self.p["mode"], self.p["real_time_factor"]
        self.ack_timeout_s = self.p["ack_timeout_s"]
        self.startup_timeout_s = self.p["startup_timeout_s"]
        self.wait_for = [n for n in self.p["wait_for_subscribers"] if n]
        ratio = self.epoch_s / self.step_s
        if not math.isclose(ratio, round(ratio), rel_tol=0, abs_tol=1e-9):
            raise ValueError(f"parameter epoch_s: {self.epoch_s} is not a multiple of step_s {self.step_s}")
        self.steps_per_epoch = int(round(ratio))
        # the reaction between epochs: every reaction_period_s between two epochs the
        # planner is asked to react (uam/react), in lockstep, and its updates are flown from there
        self.reaction_period_s = float(self.p["reaction_period_s"])
        self.react_steps = 0
        if self.reaction_period_s > 0:
            if not self.reaction_period_s < self.epoch_s:
                raise ValueError(f"parameter reaction_period_s: {self.reaction_period_s:g} s is not less than "
                                 f"epoch_s {self.epoch_s:g} s (0 = react at epochs only)")
            r = self.reaction_period_s / self.step_s
            if not math.isclose(r, round(r), rel_tol=0, abs_tol=1e-9):
                raise ValueError(f"parameter reaction_period_s: {self.reaction_period_s:g} s is not a multiple "
                                 f"of step_s {self.step_s:g} s")
            self.react_steps = int(round(r))

        self._clock_pub = self.create_publisher(Clock, c.TOPIC_CLOCK, qos.QOS_CLOCK)
        self._fleet_pub = self.create_publisher(FleetState, c.TOPIC_FLEET, qos.QOS_STREAM)
        self._pose_pub = self.create_publisher(PoseArray, c.TOPIC_POSES, qos.QOS_STREAM)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self._plan_client = self.create_client(PlanEpoch, c.SERVICE_PLAN_EPOCH)
        self._demand_client = self.create_client(ReleaseDemand, c.SERVICE_RELEASE_DEMAND) \
            if self.p["use_demand_service"] else None
        self._react_client = self.create_client(React, c.SERVICE_REACT) if self.react_steps else None
        self._waiting_react: int | None = None   # the step index of the reaction asked for
        self.reactions_asked = 0            # reactions between epochs answered
        self.react_versions_received = 0    # plan versions in their answers, flown from their instant

        self.fleet = Fleet()
        # what flies (off by default: the plans themselves)
        self.disturbance = from_simulator_params(self.p, self.step_s)
        self.wind = WindField(self.disturbance) if self.disturbance.enabled else None
        # with disturbances (what flies is not the plan) or a reaction between epochs,
        # the fleet state of an epoch is published before the epoch is asked for, the next epoch
        # is asked for only when the fleet is there, and the planner observes the fleet at the
        # in-process runner's instants (PlanEpoch.observe_at_instants): its view is the runner's
        self.observe_mode = bool(self.react_steps) or self.wind is not None
        self._plan_trajs: dict = {}  # with disturbances: each flight's plan (spliced over its versions)
        self._speed_errors: dict = {}  # after a nonconforming update: the speed error against its plan
        self.step_index = 0                 # t = step_index * step_s
        self.plans_received = 0             # decisions in the epoch answers: approved, expired, rejected
        self.approvals_received = 0         # of which approved
        self.flown_plans: list[FlightPlan] = []   # every approved plan flown, in order (for audits)
        self.fly_errors = 0                 # approved plans that could not be flown (should stay 0)
        self.versions_received = 0          # re-planned versions and cancellations flown
        self._flying: dict[str, FlightPlan] = {}   # scoped id -> approved plan, while it may be airborne
        self._decided: list[str] = []       # scoped ids of every request decided in an epoch answer
        self._waiting_epoch: int | None = None
        self._epoch_t = 0.0                 # simulation time of the epoch being asked for [s]
        self._early = None                  # its outcome, when it came before the fleet reached it
        self._step_timer = None             # lockstep: re-arms the stepping while not blocked
        self._expected: list[str] = []
        self._call = None
        self._calls: list = []              # outstanding calls of the current stage
        self._stage = 0                     # one stage per call (release, plan, resume), answered once
        self._call_sent = 0.0
        self._resume = False
        self._wait_started = 0.0
        self.started = False
        self.finished = False
        self.error = ""
        self.session = secrets.token_hex(8)      # this run's token (docs/security.md)
        self.partners: dict[str, str] = {}       # "planner" / "request_generator" -> its session
        self._foreign_answers = 0                # NEED_STATE answers of a new planner while two serve
        self.active_samples: list[int] = []  # airborne vehicles at each step, for the summary
        self._wall_start = 0.0
        self._cpu_start = 0.0
        self._blocked_since: float | None = None  # lockstep: wall time since the fleet waits at an epoch
        self.blocked_wall_s = 0.0           # wall time the fleet waited for epoch outcomes, for the summary
        self._last_wait_log = time.monotonic()
        self._created = time.monotonic()
        period = self.step_s / self.rtf if self.mode == "realtime" else 0.02
        self._timer = self.create_timer(period, self._on_timer)  # wall clock: this node owns sim time
        self.get_logger().info(
            f"simulator: {self.mode}, step {self.step_s:g} s, epoch {self.epoch_s:g} s, duration {self.duration_s:g} s; "
            f"waiting for {self._plan_client.srv_name}"
            + (f", {self._demand_client.srv_name}" if self._demand_client else "")
            + (f" and subscriber(s) {', '.join(self.wait_for)}" if self.wait_for else ""))

    def _on_change(self, name: str, value) -> None:
        if name == "real_time_factor":
            self.rtf = value
            if self.started and self.mode == "realtime":
                self._timer.timer_period_ns = int(self.step_s / value * 1e9)

    @property
    def exit_code(self) -> int:
        """1 when the run ended on an error (no answer from the planner), else 0."""
        return 1 if self.error else 0

    @property
    def t_s(self) -> float:
        return self.step_index * self.step_s

    # ---- readiness -----------------------------------------------------------------------------
    def _servers(self) -> list[str]:
        """Why the services are not served by exactly one node each ('' entries dropped)."""
        out = []
        for client in (self._plan_client, self._demand_client, self._react_client):
            if client is None:
                continue
            n = self.count_services(client.srv_name)
            if n > 1:
                out.append(f"{n} nodes serve {client.srv_name} (one expected)")
        return out

    def _missing(self) -> list[str]:
        missing = []
        if not self._plan_client.service_is_ready():
            missing.append(self._plan_client.srv_name)
        if self._demand_client is not None and not self._demand_client.service_is_ready():
            missing.append(self._demand_client.srv_name)
        if self._react_client is not None and not self._react_client.service_is_ready():
            missing.append(self._react_client.srv_name)
        missing += self._servers()
        if self.wait_for:
            subscribers = {info.node_name for info in
                           self.get_subscriptions_info_by_topic(self.resolve_topic_name(c.TOPIC_FLEET))}
            missing += [f"subscriber {n}" for n in self.wait_for if n not in subscribers]
            # seen in the graph is not yet matched: the first (volatile) fleet states would be lost
            if not missing and self._fleet_pub.get_subscription_count() < len(self.wait_for):
                missing.append("the fleet state's subscribers to match")
        return missing

    # ---- the epoch protocol --------------------------------------------------------------------
    def _start_epoch(self, k: int, t_s: float) -> None:
        """Ask for epoch k at simulation time ``t_s``: release its demand, then plan it. In
        lockstep this is sent as soon as epoch k-1 is flown, while the fleet is stepped from
        t_{k-1} to t_k (the planner needs only its own approvals and the released requests), and
        the outcome is flown when the fleet reaches t_k."""
        self._waiting_epoch = k
        self._epoch_t = float(t_s)
        self._early = None
        self._wait_started = time.monotonic()
        self._expected = []
        self._resume = False
        self._sync_pub.publish(self._sync(k, t_s))
        servers = self._servers()
        if servers:
            self._end_with_error(f"epoch {k}: {'; '.join(servers)}: another node took a partner's name")
            return
        if self._demand_client is not None:
            self._send(self._demand_client, ReleaseDemand.Request(
                epoch_index=k, epoch_time=m.to_time(t_s), epoch_s=float(self.epoch_s), session=self.session),
                self._on_demand)
        else:
            self._ask_planner()

    def _send(self, client, request, on_done, again: bool = False) -> None:
        """Call ``client``; ``on_done`` gets the first useful answer of this stage. A call sent
        ``again`` (no answer within RESEND_S) keeps the earlier ones: whichever answers counts."""
        if not again:
            self._stage += 1
            self._calls = []
        fut = client.call_async(request)
        self._calls.append(fut)
        self._call = (client, fut, request, on_done)
        self._call_sent = time.monotonic()
        stage = self._stage
        fut.add_done_callback(lambda f: self._done(f, stage, on_done))

    def _done(self, fut, stage, on_done) -> None:
        if self.finished or stage != self._stage:
            return  # a later answer of a stage already answered, or after the end
        if fut.cancelled() or fut.result() is None:
            return
        res = fut.result()
        if getattr(res, "status", None) == PlanEpoch.Response.STATUS_IN_PROGRESS:
            return  # an earlier call of this stage gets the outcome
        self._stage += 1  # answered: the other calls of this stage are ignored
        for other in self._calls:
            if other is not fut and not other.done():
                self._call[0].remove_pending_request(other)
        self._calls = []
        on_done(res)

    def _sync(self, k: int, t_s: float, finished: bool = False) -> EpochSync:
        return EpochSync(epoch_index=k, epoch_time=m.to_time(t_s), sender="simulator", finished=finished,
                         session=self.session, partners=[f"{r}={s}" for r, s in sorted(self.partners.items())],
                         duration_s=float(self.duration_s), epoch_s=float(self.epoch_s),
                         error=wire.bounded(self.error) if finished else "")

    def _end_with_error(self, error: str) -> None:
        self.error = error
        self.get_logger().error(self.error + "; ending the run")
        self._finish()

    def _partner(self, role: str, session: str, restarted: bool = False) -> bool:
        """Bind ``role`` to the first ``session`` that answers; False (the run ends) for another
        one, unless a planner ``restarted`` (then taken on, logged)."""
        bound = self.partners.get(role)
        if bound is None or bound == session:
            if bound is None:
                self.partners[role] = session
                self.get_logger().info(f"bound to the {role} of session {session!r}")
            return True
        if restarted:
            self.get_logger().warning(f"the {role} restarted: session {bound!r} -> {session!r}")
            self.partners[role] = session
            return True
        self._end_with_error(f"an answer from a second {role} (session {wire.echo(session)}; bound to {bound!r})")
        return False

    def _on_demand(self, res: ReleaseDemand.Response) -> None:
        if not res.session or len(res.session) > wire.MAX_ID_LENGTH:
            self._end_with_error(f"the request generator's answer has no valid session ({wire.echo(res.session)})")
            return
        if not self._partner("request_generator", res.session):
            return
        if res.status != ReleaseDemand.Response.STATUS_RELEASED:
            self._end_with_error(f"the request generator refused epoch {self._waiting_epoch}: "
                                 f"{wire.bounded(res.message)}")
            return
        self._expected = list(res.request_ids)
        self._ask_planner()

    def _ask_planner(self) -> None:
        t = self._epoch_t
        req = PlanEpoch.Request(epoch_index=self._waiting_epoch, epoch_time=m.to_time(t), epoch_s=float(self.epoch_s),
                                expected_request_ids=self._expected, resume=self._resume, session=self.session,
                                observe_at_instants=self.observe_mode)
        if self._resume:
            req.airborne = [p for p in self._flying.values() if m.from_time(p.arrival_time) >= t]
            req.decided_request_ids = list(self._decided)
        self._send(self._plan_client, req, self._on_outcome)

    def _on_outcome(self, res: PlanEpoch.Response) -> None:
        if not res.session or len(res.session) > wire.MAX_ID_LENGTH:
            self._end_with_error(f"the planner's answer for epoch {self._waiting_epoch} has no valid session "
                                 f"({wire.echo(res.session)})")
            return
        bound = self.partners.get("planner")
        if bound is not None and res.session != bound and res.status == PlanEpoch.Response.STATUS_NEED_STATE:
            # a restarted planner, or a second one: taken on only while it is the only server
            # (the old one may take a moment to leave the graph: asked again a few times)
            if self.count_services(self._plan_client.srv_name) != 1:
                self._foreign_answers += 1
                if self._foreign_answers >= 3:
                    self._end_with_error(f"a second planner (session {wire.echo(res.session)}) answered while "
                                         f"{self.count_services(self._plan_client.srv_name)} nodes serve "
                                         f"{self._plan_client.srv_name}")
                else:
                    self._ask_planner()
                return
        if not self._partner("planner", res.session, restarted=res.status == PlanEpoch.Response.STATUS_NEED_STATE):
            return
        self._foreign_answers = 0
        if res.status == PlanEpoch.Response.STATUS_NEED_STATE:
            self.get_logger().warning(f"the planner restarted: sending it the state at epoch {self._waiting_epoch}")
            self._resume = True
            self._ask_planner()
            return
        if res.status != PlanEpoch.Response.STATUS_PLANNED:
            self._end_with_error(f"the planner refused epoch {self._waiting_epoch}: {wire.bounded(res.message)}")
            return
        self._call = None
        if self.step_index < self._waiting_epoch * self.steps_per_epoch:
            self._early = res  # flown when the fleet reaches the epoch (_step_once)
            return
        if self._blocked_since is not None:
            self.blocked_wall_s += time.monotonic() - self._blocked_since
            self._blocked_since = None
        self._fly(res)
        if self.mode == "lockstep":
            self._run_until_blocked()

    def _fly(self, res: PlanEpoch.Response) -> None:
        """Fly a planned epoch's approvals at its time (the fleet is there), then go on; in
        lockstep ask for the next epoch at once."""
        if res.missing_request_ids:
            self.get_logger().warning(f"epoch {self._waiting_epoch} was planned without "
                                      f"{len(res.missing_request_ids)} released request(s) that did not arrive")
        epoch = self._waiting_epoch
        t = self.t_s
        self._flying = {k: p for k, p in self._flying.items() if m.from_time(p.arrival_time) >= t}
        if self._plan_trajs:
            self._plan_trajs = {k: v for k, v in self._plan_trajs.items() if k in self._flying}
        for plan in res.plans:
            self.plans_received += 1
            key = wire.scoped_id(plan.operator_id, plan.request_id)
            if int(getattr(plan, "version", 0)) > 1:   # a new version of a flight approved before
                self._fly_version(key, plan)
                continue
            self._decided.append(key)
            if plan.outcome == FlightPlan.OUTCOME_APPROVED:
                self.approvals_received += 1
                try:
                    traj = m.trajectory_from_plan(plan)
                    if self.wind is not None:
                        self._plan_trajs[key] = traj   # a later version is spliced onto the plan
                        traj = fly_plans([traj], [key], self.disturbance, self.wind)[0]
                    self.fleet.add(key, traj)
                    self._flying[key] = plan
                    self.flown_plans.append(plan)
                except ValueError as exc:
                    self.fly_errors += 1
                    self.get_logger().error(f"cannot fly plan {key!r}: {exc}")
        self._call = None
        self._waiting_epoch = None
        self._early = None
        t_next = (epoch + 1) * self.epoch_s
        self._log_progress(epoch, t)
        if self.observe_mode:
            # reacting between epochs: the state of this instant was published before the call
            # (_step_once), and the next epoch is asked for only when the fleet is there, after
            # the reactions in between (they change what the planner holds)
            self.step_index += 1
            return
        if self.mode == "lockstep" and t_next < self.duration_s - 1e-9:
            # asked before this step's state is published: the demand source and the planner
            # start on the next epoch meanwhile (their answers are handled on later turns)
            self._start_epoch(epoch + 1, t_next)
        self._publish_state()
        self.step_index += 1

    def _log_progress(self, epoch: int, t: float) -> None:
        """Every progress_epochs epochs, one line a terminal can show: a lockstep run is otherwise
        silent for minutes (run_fleet.sh prints these lines)."""
        every = self.p["progress_epochs"]
        if not every or epoch == 0 or epoch % every:
            return
        wall = time.monotonic() - self._wall_start if self.started else 0.0
        self.get_logger().info(
            f"progress: t = {t:g} s of {self.duration_s:g} s (epoch {epoch}), {self.approvals_received} approvals, "
            f"{self.active_samples[-1] if self.active_samples else 0} airborne; wall {wall:.0f} s")

    def _fly_version(self, key: str, plan: FlightPlan) -> None:
        """Fly a re-planned version from the instant it takes effect (``Fleet.update``: the old
        trajectory before, the new one after; refused when they do not chain), or drop a
        cancelled flight (docs/replanning.md)."""
        self.versions_received += 1
        try:
            rate = observed_rate(plan) if plan.outcome == FlightPlan.OUTCOME_APPROVED else None
            if rate is not None and plan.waypoints and self.wind is not None and self.fleet.flown(key) is not None:
                # a nonconforming flight's intent, updated from where it is: flown on
                # from there at the airspeed it had (uam_sim.world.disturbance.fly_on), as the runner does
                from uam_sim.world.disturbance import flight_draws, fly_on
                new = m.trajectory_from_plan(plan)
                e = self._speed_errors.get(key, flight_draws(self.disturbance, key).speed_error)
                flown, self._speed_errors[key] = fly_on(self.fleet.flown(key), new, e, rate,
                                                        self.disturbance, self.wind)
                self._plan_trajs[key] = new
                self.fleet.replace(key, flown)
                self._flying[key] = plan
                self.flown_plans.append(plan)
            elif plan.outcome == FlightPlan.OUTCOME_APPROVED and plan.waypoints and self.wind is not None \
                    and key in self._plan_trajs:
                # disturbed: the new version chains onto the old plan, not onto what flew; the
                # spliced plan is flown by the model again (the same track up to the switch)
                from uam_planner.replanning import spliced
                new = spliced(self._plan_trajs[key], m.trajectory_from_plan(plan), m.from_time(plan.effective_time))
                self._plan_trajs[key] = new
                if key in self._speed_errors and self.fleet.flown(key) is not None:
                    # updated by the reaction before: flown on from that update (its start) with
                    # the speed error it left, what flew before kept (the runner's _Reaction.refly)
                    from uam_sim.world.disturbance import fly_from
                    self.fleet.replace(key, fly_from(self.fleet.flown(key), new, self._speed_errors[key],
                                                     self.disturbance, self.wind))
                else:
                    self.fleet.replace(key, fly_plans([new], [key], self.disturbance, self.wind)[0])
                self._flying[key] = plan
                self.flown_plans.append(plan)
            elif plan.outcome == FlightPlan.OUTCOME_APPROVED and plan.waypoints:
                self.fleet.update(key, m.trajectory_from_plan(plan), m.from_time(plan.effective_time))
                self._flying[key] = plan
                self.flown_plans.append(plan)
            else:
                self.fleet.remove(key)
                self._flying.pop(key, None)
                self._plan_trajs.pop(key, None)
        except ValueError as exc:
            self.fly_errors += 1
            self.get_logger().error(f"cannot fly version {plan.version} of {key!r}: {exc}")

    # ---- stepping ------------------------------------------------------------------------------
    def _epoch_at(self, step_index: int) -> int | None:
        return step_index // self.steps_per_epoch if step_index % self.steps_per_epoch == 0 else None

    def _react_at(self, step_index: int) -> bool:
        """A reaction instant: epoch time + k x reaction_period_s, strictly between two epochs."""
        r = step_index % self.steps_per_epoch
        return bool(self.react_steps) and r != 0 and r % self.react_steps == 0

    def _ask_react(self) -> None:
        """Ask the planner to react at this instant (its fleet state is published): the answer's
        versions are flown from here (_on_react) before the fleet steps on."""
        self._waiting_react = self.step_index
        self._wait_started = time.monotonic()
        req = React.Request(epoch_index=self.step_index // self.steps_per_epoch, react_time=m.to_time(self.t_s),
                            epoch_s=float(self.epoch_s), session=self.session)
        self._send(self._react_client, req, self._on_react)

    def _on_react(self, res: React.Response) -> None:
        t = self.t_s
        if not res.session or len(res.session) > wire.MAX_ID_LENGTH:
            self._end_with_error(f"the planner's answer for the reaction at t = {t:g} s has no valid session "
                                 f"({wire.echo(res.session)})")
            return
        if not self._partner("planner", res.session):
            return
        if res.status != React.Response.STATUS_REACTED:
            self._end_with_error(f"the planner refused the reaction at t = {t:g} s: {wire.bounded(res.message)}")
            return
        self._call = None
        for plan in res.plans:
            self.plans_received += 1
            if int(getattr(plan, "version", 0)) > 1:
                self.react_versions_received += 1
                self._fly_version(wire.scoped_id(plan.operator_id, plan.request_id), plan)
        self.reactions_asked += 1
        self._waiting_react = None
        if self._blocked_since is not None:
            self.blocked_wall_s += time.monotonic() - self._blocked_since
            self._blocked_since = None
        self.step_index += 1
        if self.mode == "lockstep":
            self._run_until_blocked()

    def _on_timer(self) -> None:
        if self.finished:
            return
        now = time.monotonic()
        if not self.started:
            missing = self._missing()
            if missing and now - self._created > self.startup_timeout_s:
                self._end_with_error(f"not started within startup_timeout_s {self.startup_timeout_s:g} s: "
                                     f"waiting for {', '.join(missing)}")
                return
            if missing:
                if now - self._last_wait_log > 10.0:
                    self._last_wait_log = now
                    self.get_logger().info(f"waiting for {', '.join(missing)}")
                return
            self.started = True
            self._wall_start = now
            self._cpu_start = time.process_time()
            self.get_logger().info("planner and demand source ready: starting the run")
            if self.mode == "lockstep":
                self._timer.timer_period_ns = int(0.5e9)  # from now on only a watchdog
                self._step_timer = self.create_timer(0.0, self._run_until_blocked)
            self._run_until_blocked()
            return
        if (self._waiting_epoch is not None or self._waiting_react is not None) and self._call is not None:
            if now - self._wait_started > self.ack_timeout_s:
                what = f"epoch {self._waiting_epoch}" if self._waiting_react is None else \
                    f"the reaction at t = {self.t_s:g} s"
                self._end_with_error(f"no answer for {what} within {self.ack_timeout_s:g} s")
            elif self._call is not None and now - self._call_sent > RESEND_S:
                client, _fut, request, on_done = self._call
                self._send(client, request, on_done, again=True)  # a restarted server lost the first
            return
        if self.mode == "realtime":
            self._step_once()

    def _blocked(self) -> bool:
        """At an epoch's step whose outcome has not arrived yet (one that arrived early is flown
        by the next step)."""
        k = self._epoch_at(self.step_index)
        if self._waiting_react is not None and self._waiting_react == self.step_index:
            return True
        return (k is not None and self.t_s < self.duration_s - 1e-9 and self._waiting_epoch == k
                and self._early is None)

    def _run_until_blocked(self) -> None:
        """Lockstep: step until the next epoch without an outcome (or the end), a few steps per
        executor turn so the calls under way are answered meanwhile."""
        for _ in range(STEPS_PER_TURN):
            if self.finished or self._blocked():
                break
            self._step_once()
        if self._step_timer is not None:
            if self.finished or self._blocked():
                if not self.finished and self._blocked_since is None:
                    self._blocked_since = time.monotonic()
                self._step_timer.cancel()
            elif self._step_timer.is_canceled():
                self._step_timer.reset()

    def _step_once(self) -> None:
        if self.t_s > self.duration_s + 1e-9:
            self._finish()
            return
        k = self._epoch_at(self.step_index)
        if k is not None and self.t_s < self.duration_s - 1e-9:  # epochs at t < duration, as the runner
            if self._waiting_epoch is None:
                if self.observe_mode:
                    # disturbed or reacting between epochs: the state of this instant (before the epoch's
                    # departures) is published first: the planner and the monitor see the fleet
                    # at t before the epoch, as the runner's monitor does
                    self._publish_state()
                self._start_epoch(k, self.t_s)
            elif self._waiting_epoch == k and self._early is not None:
                self._fly(self._early)  # planned while the fleet was stepped here
            return
        if self._react_at(self.step_index) and self.t_s < self.duration_s - 1e-9:
            if self._waiting_react is None:
                self._publish_state()
                self._ask_react()
            return
        self._publish_state()
        self.step_index += 1

    def _publish_state(self) -> None:
        t = self.t_s
        stamp = m.to_time(t)
        self._clock_pub.publish(encode_clock(stamp.sec, stamp.nanosec))
        fs = self.fleet.sample(t)
        self.active_samples.append(len(fs))
        # Serialized directly from the fleet arrays (uam_sim.recording.cdr): same bytes as the message objects,
        # a fraction of the cost (see uam_sim/recording/cdr.py).
        self._fleet_pub.publish(encode_fleet_state(
            stamp.sec, stamp.nanosec, c.FRAME_ID, self.step_index, fs.vehicle_ids, fs.positions_m,
            fs.velocities_mps, fs.phases, fs.segment_indices, fs.flown_m, fs.remaining_m, self.session))
        self._pose_pub.publish(encode_pose_array(
            stamp.sec, stamp.nanosec, c.FRAME_ID, fs.positions_m, yaw_quaternions(fs.velocities_mps)))

    def _finish(self) -> None:
        if self.finished:
            return
        self.finished = True
        if self._step_timer is not None:
            self._step_timer.cancel()
        for fut in self._calls:
            if not fut.done():
                self._call[0].remove_pending_request(fut)
        self._sync_pub.publish(self._sync(self.step_index // self.steps_per_epoch, min(self.t_s, self.duration_s),
                                          finished=True))
        wall = time.monotonic() - self._wall_start if self.started else 0.0
        cpu = time.process_time() - self._cpu_start if self.started else 0.0
        sim = min(self.t_s, self.duration_s)
        avg = sum(self.active_samples) / len(self.active_samples) if self.active_samples else 0.0
        self.get_logger().info(
            f"run finished at t={sim:g} s: {self.fleet.total_added} approved flights flown, "
            f"{self.approvals_received} approvals received ({self.plans_received} decisions in all, "
            f"expired and rejected included), average airborne {avg:.2f}; wall {wall:.2f} s "
            f"(simulator cpu {cpu:.2f} s), real-time factor {sim / wall if wall > 0 else float('inf'):.1f}"
            + (f"; waited {self.blocked_wall_s:.2f} s at epochs for the planner" if self.mode == "lockstep" else ""))


def main(args=None) -> int:
    return run_node(SimulatorNode, "simulator", args, linger_s=1.0, events_executor=True)


if __name__ == "__main__":
    sys.exit(main())
