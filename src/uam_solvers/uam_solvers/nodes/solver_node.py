"""Solver node: serves MWIS on uam/solve_mwis with a selectable backend and deadlines that hold.

    ros2 run uam_solvers solver --ros-args --params-file config/solver.yaml

Parameters: uam_contract.params.SOLVER (docs/parameters.md); every change at run time is
validated (a backend must be known and available, max_vertices at least 1000, max_time_limit_s
at most 3600 s).

Glue only: requests are converted to uam_solvers.MwisProblem and solved by a
uam_solvers.executor.SolveService, which runs each solve in-process (tiny graphs) or in a warm
worker process that is killed at ``time_limit_s + margin`` (the answer is then greedy, flagged),
with a small and a large lane so small requests never wait behind large ones. Malformed requests,
time limits over ``max_time_limit_s`` and graphs over ``max_vertices`` get success=false with a
message naming the field and value; the node keeps serving. Every answer says what happened:
``fallback``, ``message`` and the stats ``executor`` (inline, worker, killed, worker-crashed,
no-free-worker) and ``queue_wait_s`` [s].

Start-up: starting the worker processes takes 5-12 s under load, so it runs on a thread; the
node is responsive meanwhile (parameters, logging) and offers uam/solve_mwis once the workers
are up (clients wait for the service, as the planner does at start-up). Requests are served
concurrently (reentrant callback group on a multi-threaded executor). ``close()`` (also called
by ``destroy_node``) stops every worker process.
"""

from __future__ import annotations

import math
import sys
import threading

from diagnostic_msgs.msg import KeyValue
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from uam_msgs.srv import SolveMwis

from uam_contract import names as c
from uam_solvers.nodes.conversions import problem_from_solve_request
from uam_bringup.params import declare_table
from uam_contract.params import SOLVER
from uam_solvers.nodes import param_rules
from uam_bringup.runtime import run_node
from uam_solvers import BackendUnavailable, MwisInputError, UnknownBackendError

# Worker layout of the SolveService: uam_solvers.executor.NODE_LAYOUT (node_service builds it,
# so benchmarks of this node's path use the same service without ROS).
#: how long close() waits for a start-up in progress [s]
STARTER_JOIN_S = 2.0


def parse_option(value: str):
    """Backend option values arrive as strings: 'true'/'false', ints and floats are converted."""
    low = value.strip().lower()
    if low in ("true", "false"):
        return low == "true"
    for cast in (int, float):
        try:
            return cast(value)
        except ValueError:
            pass
    return value


class SolverNode(Node):
    """Serves SolveMwis; algorithms (and the worker processes) live in uam_solvers."""

    def __init__(self, **kwargs):
        super().__init__("solver", **kwargs)
        self._p = declare_table(self, SOLVER, on_change=self._on_param, rules=param_rules.RULES)  # every change validated
        if self._p["default_time_limit_s"] > self._p["max_time_limit_s"]:
            raise ValueError(f"parameter default_time_limit_s: {self._p['default_time_limit_s']!r} s exceeds "
                             f"max_time_limit_s={self._p['max_time_limit_s']!r} s")
        self._group = ReentrantCallbackGroup()
        self._lock = threading.Lock()
        self._closed = False
        self.solve_service = None  # uam_solvers.executor.SolveService once its workers are up
        self.ready = threading.Event()  # set when uam/solve_mwis is offered
        self.start_error = ""
        # The service is created on the executor's thread (a guard condition triggered by the
        # starter), not from the starter thread, so the executor never sees a half-made entity.
        self._offer = self.create_guard_condition(self._create_service, callback_group=self._group)
        self._starter = threading.Thread(target=self._start_workers, name="uam-solver-start", daemon=True)
        self._starter.start()
        self.get_logger().info(
            f"starting solver workers; then serving {self.resolve_service_name(c.SERVICE_SOLVE)} with "
            f"default backend {self._p['default_backend']!r}")

    # -- start-up and shut-down ----------------------------------------------------------------

    def _start_workers(self) -> None:
        from uam_solvers.executor import node_service

        try:
            svc = node_service(max_time_limit_s=float(self._p["max_time_limit_s"]),
                               max_vertices=int(self._p["max_vertices"]))
        except Exception as exc:  # noqa: BLE001 - reported; the node stays up without the service
            self.start_error = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"solver workers did not start: {self.start_error}")
            return
        with self._lock:
            if self._closed:  # the node went away while the workers started
                svc.close()
                return
            # a parameter change made while the workers started
            svc.max_time_limit_s = float(self._p["max_time_limit_s"])
            svc.max_vertices = int(self._p["max_vertices"])
            self.solve_service = svc
        self._offer.trigger()

    def _create_service(self) -> None:
        with self._lock:
            if self._closed or self.ready.is_set():
                return
            self.create_service(SolveMwis, c.SERVICE_SOLVE, self._on_solve, callback_group=self._group)
            self.ready.set()
        self.get_logger().info(f"serving {self.resolve_service_name(c.SERVICE_SOLVE)}; worker processes "
                               f"{self.solve_service.worker_pids()}")

    def close(self) -> None:
        """Stop every worker process. A start-up still in progress (the workers' warm-up takes
        seconds, more under load) is waited for at most STARTER_JOIN_S: it closes what it made
        itself once it sees the node closed, and its worker processes are daemonic (and get
        SIGTERM when the node's process dies), so none survives, and a SIGINT is never answered
        later than run_fleet.sh's 10 s (a run stopped during the start-up failed that)."""
        with self._lock:
            if self._closed and self.solve_service is None:
                return  # closed already (close() and then destroy_node())
            self._closed = True
        if self._starter.is_alive() and threading.current_thread() is not self._starter:
            self._starter.join(STARTER_JOIN_S)
        with self._lock:
            svc, self.solve_service = self.solve_service, None
        if svc is not None:
            svc.close()

    def destroy_node(self):
        self.close()
        return super().destroy_node()

    def _on_param(self, name: str, value) -> None:
        svc = self.solve_service
        if svc is None:
            return  # the starter reads the values once the workers are up
        if name == "max_time_limit_s":
            svc.max_time_limit_s = float(value)
        elif name == "max_vertices":
            svc.max_vertices = int(value)

    # -- the service -----------------------------------------------------------------------------

    def _time_limit(self, request) -> float:
        """The request's time limit [s] (or the default), refused above max_time_limit_s."""
        limit_max = self._p["max_time_limit_s"]
        if request.time_limit_s == 0.0:
            limit = self._p["default_time_limit_s"]
            if limit > limit_max:
                raise MwisInputError(f"time_limit_s: 0 asks the default default_time_limit_s={limit:g} s, which "
                                     f"exceeds the solver's max_time_limit_s={limit_max:g} s")
            return float(limit)
        limit = request.time_limit_s
        if not math.isfinite(limit) or limit <= 0:
            raise MwisInputError(f"time_limit_s: {limit!r} must be a finite number of seconds > 0 "
                                 "(0 for the default)")
        if limit > limit_max:
            raise MwisInputError(f"time_limit_s: {limit!r} s exceeds the solver's max_time_limit_s="
                                 f"{limit_max:g} s")
        return float(limit)

    def _on_solve(self, request: SolveMwis.Request, response: SolveMwis.Response) -> SolveMwis.Response:
        backend = request.backend or self._p["default_backend"]
        svc = self.solve_service
        try:
            if svc is None:
                raise RuntimeError("the solver node is shutting down")
            limit = self._time_limit(request)
            problem = problem_from_solve_request(request, int(self._p["max_vertices"]))
            options = {kv.key: parse_option(kv.value) for kv in request.options}
            result = svc.solve(problem, backend=backend, time_limit_s=limit, seed=int(request.seed),
                               options=options, layers=bool(self._p["layers"]))
        except (MwisInputError, UnknownBackendError, BackendUnavailable, ValueError, TypeError) as exc:
            response.success = False
            response.message = str(exc)
            self.get_logger().warning(f"refused a SolveMwis request: {exc}")
            return response
        except Exception as exc:  # noqa: BLE001 - the node must keep serving after any failure
            response.success = False
            response.message = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"SolveMwis failed: {response.message}")
            return response
        how = result.stats.get("executor", "?")
        waited_s = float(result.stats.get("queue_wait_s", 0.0))
        response.success = True
        response.selected = [int(v) for v in result.selected]
        response.objective = float(result.objective)
        response.solve_time_s = float(result.solve_time_s)
        response.proven_optimal = bool(result.proven_optimal)
        response.backend_used = result.backend
        response.fallback = bool(result.fallback)
        summary = (f"{len(result.selected)} of {problem.n} vertices, objective {result.objective:.6g}; "
                   f"ran {how}, waited {waited_s:.3f} s for a worker")
        response.message = f"{result.message}; {summary}" if result.message else summary
        response.stats = [KeyValue(key=str(k), value=str(v)) for k, v in sorted(result.stats.items())]
        if result.fallback:
            self.get_logger().warning(f"backend {backend!r} fell back ({how}): {result.message}")
        return response


def main(args=None) -> int:
    return run_node(SolverNode, "solver", args, threads=4, stateless=True)


if __name__ == "__main__":
    sys.exit(main())
