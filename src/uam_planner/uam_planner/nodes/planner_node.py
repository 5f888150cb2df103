"""Planner node: keeps the pending requests and runs the planning cycle at each epoch.

    ros2 run uam_planner planner --ros-args --params-file config/planner.yaml

Subscribes /uam/requests (FlightRequest) and /uam/epoch_sync (EpochSync); publishes
/uam/flight_plans (FlightPlan, reliable + transient local), /uam/planning_reports
(PlanningReport) and its own EpochSync acknowledgements; calls /uam/solve_mwis (SolveMwis).

Lockstep: when the simulator announces epoch k at time t, the planner waits for the request
generator's acknowledgement of epoch k and for every request it counted, then plans, publishes
the plans and the report, and acknowledges epoch k with the number of plans published so far, so
the simulator moves on only when the epoch's outcome is complete.

A request with an unknown aerodrome, the same origin and destination, or an impossible time
window is answered at once with a rejected plan whose reason names the field. If the solver
service is absent, late or fails, the planning cycle falls back to greedy locally, logs a warning
and marks the report; every answer is checked, so no conflicting pair is ever approved.
The planning itself is uam_planner.planning.Planner, shared with the in-process experiment runner.
"""

from __future__ import annotations

import dataclasses
import sys
import threading
import time
from functools import partial

from rcl_interfaces.msg import SetParametersResult
from rclpy.callback_groups import MutuallyExclusiveCallbackGroup, ReentrantCallbackGroup
from rclpy.node import Node
from rclpy.parameter import Parameter
from uam_msgs.msg import EpochSync, FlightPlan, FlightRequest, PlanningReport
from uam_msgs.srv import SolveMwis

from uam_planner.network import load_network
from uam_bringup import contract as c
from uam_bringup import conversions as m
from uam_bringup import qos
from uam_bringup.runtime import run_node
from uam_bringup.params import check, declare
from uam_planner.planning import POLICIES, Planner, PlanningConfig, default_solve_mwis


class PlannerNode(Node):
    """ROS glue around uam_planner.planning.Planner."""

    def __init__(self, **kwargs):
        kwargs.setdefault("parameter_overrides", [])
        if not any(p.name == "use_sim_time" for p in kwargs["parameter_overrides"]):
            kwargs["parameter_overrides"].append(Parameter("use_sim_time", Parameter.Type.BOOL, True))
        super().__init__("planner", **kwargs)
        d = partial(declare, self)
        params = {
            "network": d("network", "", "routing network file (.yaml, .geojson, .graphml), e.g. config/networks/singapore.yaml"),
            "policy": d("policy", "mwis", "planning policy: conflict graph + MWIS, or the shortest-FIFO baseline", choices=POLICIES),
            "backend": d("backend", "exact", "MWIS backend asked of the solver service (`ros2 run uam_solvers backends` lists them)"),
            "time_limit_s": d("time_limit_s", 5.0, "MWIS solve time limit [s]", 0.001, 3600.0),
            "seed": d("seed", 0, "seed passed to stochastic MWIS backends", 0, 2**31 - 1),
            "epoch_s": d("epoch_s", 30.0, "time between planning epochs [s] (the simulator announces epochs)", 0.001, 86400.0),
            "separation_m": d("separation_m", 100.0, "separation minimum [m]", 0.001, 100000.0),
            "k": d("k", 5, "candidate routes per request", 1, 100),
            "penalty_factor": d("penalty_factor", 5.0, "penalised Dijkstra factor for diverse candidates", 0.0, 1000.0),
            "speed_mps": d("speed_mps", 10.0, "cruise speed [m/s]", 0.001, 1000.0),
            "precompute_routes": d("precompute_routes", True, "compute every aerodrome pair's candidate routes "
                                   "at start-up (1-2 s for Singapore) instead of on first use; same routes"),
        }
        d("solver_timeout_margin_s", 5.0, "extra wall time [s] to wait for the solver service before the local greedy fallback", 0.0, 3600.0)
        d("solver_startup_timeout_s", 30.0, "wall time [s] to wait for the solver service at the first epoch "
          "(nodes start in any order); later a missing service means the local greedy fallback at once", 0.0, 3600.0)
        d("use_solver_service", True, "call /uam/solve_mwis; false solves in-process with the same backend")
        d("wait_for_generator", True, "in lockstep, plan epoch k only after the request generator acknowledged it")
        if not params["network"]:
            raise ValueError("parameter network: empty; give a network file, e.g. config/networks/singapore.yaml")
        self.network = load_network(params["network"])
        config = PlanningConfig(
            epoch_s=params["epoch_s"], separation_m=params["separation_m"], k=params["k"],
            penalty_factor=params["penalty_factor"], speed_mps=params["speed_mps"], backend=params["backend"],
            time_limit_s=params["time_limit_s"], seed=params["seed"], precompute_routes=params["precompute_routes"])
        self.policy = params["policy"]
        self.planner = Planner(self.network, config, self.policy, solve_mwis=self._solve_mwis)
        self.add_on_set_parameters_callback(self._on_set_parameters)

        self._lock = threading.RLock()
        self.stopping = threading.Event()  # set on shutdown: a callback waiting on the solver gives up
        self._plan_group = MutuallyExclusiveCallbackGroup()
        self._client_group = ReentrantCallbackGroup()
        self._plan_pub = self.create_publisher(FlightPlan, c.TOPIC_PLANS, qos.QOS_LATCHED)
        self._report_pub = self.create_publisher(PlanningReport, c.TOPIC_REPORTS, qos.QOS_LATCHED)
        self._sync_pub = self.create_publisher(EpochSync, c.TOPIC_SYNC, qos.QOS_LATCHED)
        self.create_subscription(FlightRequest, c.TOPIC_REQUESTS, self._on_request, qos.QOS_LATCHED,
                                 callback_group=self._plan_group)
        self.create_subscription(EpochSync, c.TOPIC_SYNC, self._on_sync, qos.QOS_LATCHED,
                                 callback_group=self._plan_group)
        self._client = self.create_client(SolveMwis, c.SERVICE_SOLVE, callback_group=self._client_group)
        self._startup_waited = False  # the first epoch waits for the solver to come up

        self._announced: dict[int, float] = {}       # simulator: epoch -> time [s]
        self._generator_acks: dict[int, int] = {}    # generator: epoch -> requests published so far
        self._next_epoch = 0
        self._last_t_s = float("-inf")
        self.requests_received = 0
        self.plans_published = 0
        self.finished = False
        self.get_logger().info(
            f"planner ready: network {self.network.name!r} ({len(self.network.node_ids)} nodes, "
            f"{len(self.network.aerodrome_ids)} aerodromes), policy {self.policy}, backend {self.config.backend}")

    @property
    def config(self) -> PlanningConfig:
        """The planner's current configuration (backend, time limit and seed can change at run time)."""
        return self.planner.config

    # ---- parameters --------------------------------------------------------------------------
    def _on_set_parameters(self, params) -> SetParametersResult:
        fixed = {"network", "policy", "epoch_s", "separation_m", "k", "penalty_factor", "speed_mps"}
        for prm in params:
            if prm.name in fixed:
                return SetParametersResult(successful=False, reason=f"{prm.name} cannot change during a run")
            if prm.name == "backend":
                from uam_solvers.registry import UnknownBackendError, backend_names, get_backend
                try:
                    get_backend(prm.value)
                except (UnknownBackendError, TypeError):
                    return SetParametersResult(successful=False, reason=(
                        f"backend: unknown backend {prm.value!r}; known: {', '.join(backend_names())}"))
        for prm in params:
            try:
                if prm.name == "time_limit_s":
                    check("time_limit_s", prm.value, 1.0, 0.001, 3600.0)
                elif prm.name == "seed":
                    check("seed", prm.value, 0, 0, 2**31 - 1)
                elif prm.name == "solver_timeout_margin_s":
                    check(prm.name, prm.value, 1.0, 0.0, 3600.0)
            except ValueError as exc:
                return SetParametersResult(successful=False, reason=str(exc))
        for prm in params:  # accepted: backend, time limit and seed take effect at the next epoch
            if prm.name in ("backend", "time_limit_s", "seed"):
                with self._lock:
                    fields = {prm.name: float(prm.value) if prm.name == "time_limit_s" else prm.value}
                    self.planner.config = dataclasses.replace(self.planner.config, **fields)
        return SetParametersResult(successful=True)

    # ---- MWIS through the service --------------------------------------------------------------
    def _solve_mwis(self, weights, edges, groups):
        """Injected into Planner: solve via /uam/solve_mwis; raise so the cycle falls back to greedy."""
        if not self.get_parameter("use_solver_service").value:
            return default_solve_mwis(self.config)(weights, edges, groups)
        if not self._client.service_is_ready() and not self._startup_waited:
            self._startup_waited = True
            self._client.wait_for_service(timeout_sec=self.get_parameter("solver_startup_timeout_s").value)
        if not self._client.service_is_ready():
            msg = f"solver service {c.SERVICE_SOLVE} is not available"
            self.get_logger().warning(msg + "; solving with greedy locally")
            raise RuntimeError(msg)
        self._startup_waited = True
        req = m.solve_request(weights, edges, groups, self.config.backend, self.config.time_limit_s,
                              self.config.seed)
        done = threading.Event()
        future = self._client.call_async(req)
        future.add_done_callback(lambda _f: done.set())
        timeout = self.config.time_limit_s + self.get_parameter("solver_timeout_margin_s").value
        deadline = time.monotonic() + timeout
        while not done.wait(0.05):
            if self.stopping.is_set():
                self._client.remove_pending_request(future)
                raise RuntimeError("the planner is shutting down")
            if time.monotonic() > deadline:
                self._client.remove_pending_request(future)
                msg = f"solver service {c.SERVICE_SOLVE} did not answer within {timeout:.1f} s"
                self.get_logger().warning(msg + "; solving with greedy locally")
                raise TimeoutError(msg)
        res = future.result()
        if res is None or not res.success:
            msg = f"solver service refused or failed: {getattr(res, 'message', 'no response')}"
            self.get_logger().warning(msg + "; solving with greedy locally")
            raise RuntimeError(msg)
        return m.solve_answer(res)

    # ---- requests ----------------------------------------------------------------------------
    def _publish_plan(self, plan: FlightPlan) -> None:
        self._plan_pub.publish(plan)
        self.plans_published += 1

    def _on_request(self, msg: FlightRequest) -> None:
        with self._lock:
            self.requests_received += 1
            try:
                req = m.request_from_msg(msg)
                # What is wrong with the request itself first, then whether it came too late.
                reason = self.planner.validate(req)
                if reason is None and req.latest_departure_s < self._last_t_s:
                    reason = (f"latest_departure: {req.latest_departure_s:g} s is before the current "
                              f"simulation time {self._last_t_s:g} s")
            except ValueError as exc:
                req, reason = None, f"request: {exc}"
            if reason is None:
                reason = self.planner.submit(req)
            else:
                self.planner.record_rejection()
            if reason is not None:
                epoch = max(self._next_epoch - 1, 0)
                self._publish_plan(m.unapproved_plan(
                    msg.request_id, msg.origin_id, msg.destination_id, FlightPlan.OUTCOME_REJECTED, reason,
                    max(self._last_t_s, 0.0), epoch, self.policy))
                self.get_logger().warning(f"rejected request {msg.request_id!r}: {reason}")
            self._try_plan()

    # ---- epochs ------------------------------------------------------------------------------
    def _on_sync(self, msg: EpochSync) -> None:
        with self._lock:
            if msg.sender == "simulator":
                if msg.finished:
                    self.finished = True
                    return
                self._announced.setdefault(msg.epoch_index, m.from_time(msg.epoch_time))
            elif msg.sender == "request_generator":
                self._generator_acks[msg.epoch_index] = int(msg.requests_published)
            self._try_plan()

    def _try_plan(self) -> None:
        while self._next_epoch in self._announced:
            k = self._next_epoch
            if self.get_parameter("wait_for_generator").value:
                expected = self._generator_acks.get(k)
                if expected is None or self.requests_received < expected:
                    return
            self._plan(k, self._announced[k])
            self._next_epoch += 1

    def _plan(self, k: int, t_s: float) -> None:
        self._last_t_s = t_s
        result = self.planner.plan(t_s, k)
        report = result.report
        for flight in result.approved:
            self._publish_plan(m.approved_plan(flight, t_s, self.policy))
        for req in result.expired:
            self._publish_plan(m.unapproved_plan(
                req.request_id, req.origin_id, req.destination_id, FlightPlan.OUTCOME_EXPIRED,
                f"no conflict-free departure found by latest_departure {req.latest_departure_s:g} s",
                t_s, k, self.policy))
        self._report_pub.publish(m.report_to_msg(report))
        if report.fallback:
            self.get_logger().warning(f"epoch {k}: MWIS fallback to {report.backend_used}: {report.fallback_reason}")
        self._sync_pub.publish(EpochSync(
            epoch_index=k, epoch_time=m.to_time(t_s), sender="planner", plans_published=self.plans_published,
            requests_received=self.requests_received))
        self.get_logger().debug(
            f"epoch {k} t={t_s:g}s: eligible {report.eligible}, approved {report.approved}, expired {report.expired}")


def main(args=None) -> int:
    return run_node(PlannerNode, "planner", args, threads=3)


if __name__ == "__main__":
    sys.exit(main())
