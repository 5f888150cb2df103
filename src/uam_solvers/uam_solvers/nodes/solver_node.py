"""Solver node: serves MWIS on uam/solve_mwis with a selectable backend.

    ros2 run uam_solvers solver --ros-args --params-file config/solver.yaml

Parameters: uam_bringup.params.SOLVER (docs/parameters.md); every change at run time is
validated (a backend must be known and available, max_vertices at least 1000).

Glue only: requests are converted to uam_solvers.MwisProblem and solved by uam_solvers.solve_problem
(validation and greedy fallback included). Malformed requests get success=false with a message
naming the field and value; the node keeps serving. Requests are served concurrently (reentrant
callback group on a multi-threaded executor) so a slow solve does not block the others.
"""

from __future__ import annotations

import math
import sys

from diagnostic_msgs.msg import KeyValue
from rclpy.callback_groups import ReentrantCallbackGroup
from rclpy.node import Node
from uam_msgs.srv import SolveMwis

from uam_bringup import contract as c
from uam_bringup.conversions import problem_from_solve_request
from uam_bringup.runtime import run_node
from uam_bringup.params import SOLVER, backend_problem, declare_table
from uam_solvers import MwisInputError, solve_problem


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
    """Serves SolveMwis; algorithms live in uam_solvers."""

    def __init__(self, **kwargs):
        super().__init__("solver", **kwargs)
        declare_table(self, SOLVER)  # every change validated (backend known and available, ranges)
        self._group = ReentrantCallbackGroup()
        self.create_service(SolveMwis, c.SERVICE_SOLVE, self._on_solve, callback_group=self._group)
        self.get_logger().info(
            f"serving {self.resolve_service_name(c.SERVICE_SOLVE)}; default backend "
            f"{self.get_parameter('default_backend').value!r}")

    def _on_solve(self, request: SolveMwis.Request, response: SolveMwis.Response) -> SolveMwis.Response:
        backend = request.backend or self.get_parameter("default_backend").value
        limit = request.time_limit_s or self.get_parameter("default_time_limit_s").value
        try:
            if not math.isfinite(limit) or limit <= 0:
                raise MwisInputError(f"time_limit_s: {request.time_limit_s!r} must be a positive number")
            problem_text = backend_problem(backend)
            if problem_text:
                raise MwisInputError(f"backend: {problem_text}")
            problem = problem_from_solve_request(request, int(self.get_parameter("max_vertices").value))
            options = {kv.key: parse_option(kv.value) for kv in request.options}
            result = solve_problem(problem, backend=backend, time_limit_s=float(limit), seed=int(request.seed),
                                   options=options, layers=bool(self.get_parameter("layers").value))
        except (MwisInputError, ValueError, TypeError) as exc:
            response.success = False
            response.message = str(exc)
            self.get_logger().warning(f"refused a SolveMwis request: {exc}")
            return response
        except Exception as exc:  # noqa: BLE001 - the node must keep serving after any failure
            response.success = False
            response.message = f"{type(exc).__name__}: {exc}"
            self.get_logger().error(f"SolveMwis failed: {response.message}")
            return response
        response.success = True
        response.selected = [int(v) for v in result.selected]
        response.objective = float(result.objective)
        response.solve_time_s = float(result.solve_time_s)
        response.proven_optimal = bool(result.proven_optimal)
        response.backend_used = result.backend
        response.fallback = bool(result.fallback)
        response.message = result.message or (
            f"{len(result.selected)} of {problem.n} vertices, objective {result.objective:.6g}")
        response.stats = [KeyValue(key=str(k), value=str(v)) for k, v in sorted(result.stats.items())]
        if result.fallback:
            self.get_logger().warning(f"backend {backend!r} fell back: {result.message}")
        return response


def main(args=None) -> int:
    return run_node(SolverNode, "solver", args, threads=4)


if __name__ == "__main__":
    sys.exit(main())
