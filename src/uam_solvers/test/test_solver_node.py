"""The solver node in-process: answers clients, refuses malformed requests with a message naming
the problem and keeps serving, switches backend by parameter, serves concurrently."""

from __future__ import annotations

import threading

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from diagnostic_msgs.msg import KeyValue  # noqa: E402
from rclpy.executors import MultiThreadedExecutor  # noqa: E402
from rclpy.parameter import Parameter  # noqa: E402
from uam_msgs.srv import SolveMwis  # noqa: E402

from uam_bringup.contract import SERVICE_SOLVE as SERVICE_NAME  # noqa: E402
from uam_solvers.nodes.solver_node import SolverNode  # noqa: E402

pytestmark = pytest.mark.ros

# A 5-cycle with weights: the optimum is {1, 3} (2 + 3 = 5) over e.g. {0, 2} (1 + 1.5).
WEIGHTS = [1.0, 2.0, 1.5, 3.0, 0.5]
EDGES_U = [0, 1, 2, 3, 4]
EDGES_V = [1, 2, 3, 4, 0]


@pytest.fixture
def solver_setup(ros_context, spin_until):
    node = SolverNode(context=ros_context, parameter_overrides=[Parameter("default_backend", value="exact")])
    client_node = rclpy.create_node("solver_client", context=ros_context)
    client = client_node.create_client(SolveMwis, SERVICE_NAME)
    executor = MultiThreadedExecutor(num_threads=4, context=ros_context)
    executor.add_node(node)
    executor.add_node(client_node)
    assert spin_until(executor, client.service_is_ready, timeout_s=10)

    def call(**fields):
        req = SolveMwis.Request(**{"weights": WEIGHTS, "edges_u": EDGES_U, "edges_v": EDGES_V, **fields})
        future = client.call_async(req)
        assert spin_until(executor, future.done, timeout_s=30)
        return future.result()

    yield node, call, executor, client
    executor.shutdown()
    client_node.destroy_node()
    node.destroy_node()


def test_answers_with_the_optimum_and_default_backend(solver_setup):
    _, call, _, _ = solver_setup
    res = call()
    assert res.success, res.message
    assert list(res.selected) == [1, 3]
    assert res.objective == pytest.approx(5.0)
    assert res.proven_optimal and res.backend_used == "exact" and not res.fallback
    assert call(backend="greedy", vertex_group=[0, 0, 1, 1, 2]).success


@pytest.mark.parametrize("fields, words", [
    ({"edges_u": [0, 1, 9], "edges_v": [1, 2, 3]}, ["edges", "9", "out of range"]),
    ({"edges_u": [0, 2], "edges_v": [1, 2]}, ["edges", "self-loop"]),
    ({"weights": [1.0, float("nan"), 1.0, 1.0, 1.0]}, ["weights[1]", "nan"]),
    ({"weights": [1.0, -2.0, 1.0, 1.0, 1.0]}, ["weights[1]", "negative"]),
    ({"edges_u": [0, 1], "edges_v": [1]}, ["edges_u/edges_v", "lengths differ"]),
    ({"vertex_group": [0, 1]}, ["vertex_group", "length 2"]),
    ({"backend": "no-such-solver"}, ["backend", "no-such-solver", "greedy", "exact"]),
])
def test_refuses_malformed_requests_and_keeps_serving(solver_setup, fields, words):
    _, call, _, _ = solver_setup
    res = call(**fields)
    assert not res.success
    for w in words:
        assert w in res.message, (w, res.message)
    assert list(res.selected) == []
    again = call()  # still serving, same answer as before
    assert again.success and list(again.selected) == [1, 3]


def test_refuses_graphs_over_the_size_limit(solver_setup):
    node, call, _, _ = solver_setup
    assert node.set_parameters([Parameter("max_vertices", value=1000)])[0].successful  # the smallest allowed
    res = call(weights=[1.0] * 1001, edges_u=[0], edges_v=[1])
    assert not res.success and "max_vertices=1000" in res.message


def test_switches_default_backend_by_parameter_and_refuses_unknown_names(solver_setup):
    node, call, _, _ = solver_setup
    result = node.set_parameters([Parameter("default_backend", value="greedy")])[0]
    assert result.successful
    assert call().backend_used == "greedy"
    refused = node.set_parameters([Parameter("default_backend", value="quantum-magic")])[0]
    assert not refused.successful
    assert "quantum-magic" in refused.reason and "exact" in refused.reason
    assert node.get_parameter("default_backend").value == "greedy"


def test_backend_options_reach_the_backend(solver_setup):
    _, call, _, _ = solver_setup
    res = call(backend="greedy", options=[KeyValue(key="rule", value="gwmax")])
    assert res.success and res.backend_used == "greedy"
    bad = call(backend="greedy", options=[KeyValue(key="rule", value="nonsense")])
    assert not bad.success or bad.fallback  # an unknown rule is refused or falls back, never silently used


def test_a_slow_solve_does_not_block_other_requests(solver_setup, spin_until, monkeypatch):
    """A backend blocked on an event holds one request; another request is answered meanwhile."""
    import uam_solvers
    import uam_solvers.registry
    from uam_solvers.base import Backend
    from uam_solvers.greedy import GreedyBackend
    from uam_solvers.registry import get_backend

    gate = threading.Event()

    class Blocking(Backend):
        name = "blocking-test"
        description = "waits for the test's gate, then solves greedily"

        def solve(self, problem, *, time_limit_s, seed, options):
            gate.wait(30)
            return GreedyBackend().solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)

    def lookup(name):
        return Blocking() if name == "blocking-test" else get_backend(name)

    monkeypatch.setattr(uam_solvers, "get_backend", lookup)
    monkeypatch.setattr(uam_solvers.registry, "get_backend", lookup)  # the node checks names there
    _, call, executor, client = solver_setup
    try:
        slow = client.call_async(SolveMwis.Request(weights=WEIGHTS, edges_u=EDGES_U, edges_v=EDGES_V,
                                                   backend="blocking-test", time_limit_s=60.0))
        fast = call(backend="greedy")
        assert fast.success and not slow.done()
        gate.set()
        assert spin_until(executor, slow.done, timeout_s=30)
        assert slow.result().success
    finally:
        gate.set()
