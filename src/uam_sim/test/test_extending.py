"""The recipes of docs/extending.md, each made in this test module and found everywhere it must
appear: a backend (one class, one registration) and an objective (one function, one
registration). If a recipe needs another file, it fails here."""

from __future__ import annotations

import time

import numpy as np
import pytest

from uam_solvers.base import Backend, make_result

TINY = "config/networks/tiny.yaml"


class LightestFirst(Backend):
    """A deliberately plain backend: vertices by increasing degree, kept when independent."""

    name = "test-lightest-first"
    description = "test: vertices by increasing degree, kept when independent"
    bounded_in_process = True

    def solve(self, problem, *, time_limit_s=10.0, seed=0, options=None):
        self.validate_options(options)
        t0 = time.perf_counter()
        edges = problem.all_edges()
        degree = np.bincount(edges.reshape(-1), minlength=problem.n) if edges.size else np.zeros(problem.n, int)
        nbrs = {v: set() for v in range(problem.n)}
        for a, b in edges.tolist():
            nbrs[a].add(b)
            nbrs[b].add(a)
        chosen: set = set()
        for v in sorted(range(problem.n), key=lambda v: (degree[v], v)):
            if not nbrs[v] & chosen:
                chosen.add(v)
        return make_result(problem, sorted(chosen), proven_optimal=False,
                           solve_time_s=time.perf_counter() - t0, backend=self.name)


@pytest.fixture
def lightest_first():
    from uam_solvers.registry import register_backend, unregister_backend
    register_backend(LightestFirst.name, LightestFirst)
    yield LightestFirst.name
    unregister_backend(LightestFirst.name)


def test_a_backend_in_one_class_is_found_everywhere(lightest_first):
    import uam_solvers
    from uam_solvers.nodes.param_rules import backend_name_problem
    from uam_solvers.registry import backend_names, get_backend, sampling_backends
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario

    name = lightest_first
    assert name in backend_names() and isinstance(get_backend(name), LightestFirst)
    assert name not in sampling_backends()          # its traits are its class attributes
    assert backend_name_problem(name) == ""          # the planner's and solver's parameter rule
    res = uam_solvers.solve([1.0, 2.0, 1.0], [(0, 1), (1, 2)], backend=name, time_limit_s=1.0)
    assert sorted(res.selected.tolist()) == [0, 2]
    # the runner takes it as a method, and the planner solves its epochs with it
    run = run_scenario(load_network_spec(TINY), name, 3.0, 1, 240.0, make_config({"network": TINY}))
    assert run.summary["approved"] > 0 and {r["backend_used"] for r in run.epochs if r["vertices"]} == {name}


@pytest.fixture
def shortest_squared():
    from uam_planner.objectives import EpochWeights, register_objective, unregister_objective
    calls = []

    def weights(ctx):
        calls.append(ctx.t_s)
        return EpochWeights(np.asarray(ctx.paper_weights, dtype=np.float64) ** 2, step_s=0,
                            exact_for_integer_backends=False)
    register_objective("test_shortest_squared", "test: the paper's weights squared", weights)
    yield "test_shortest_squared", calls
    unregister_objective("test_shortest_squared")


def test_an_objective_in_one_function_is_found_everywhere(shortest_squared):
    from uam_planner.objectives import objective_names, objective_problem
    from uam_planner.planning_config import PlanningConfig
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.preflight import NodeParams, PreflightError, check_params
    from uam_sim.runner.scenario import run_scenario
    from uam_sim.studies.experiment import build_parser

    name, calls = shortest_squared
    assert name in objective_names() and objective_problem(name) == ""
    assert PlanningConfig(objective=name).objective == name
    # the planner node's parameter rule, as run_fleet.sh's preflight applies it
    assert check_params([NodeParams("planner", {"objective": (name, "-p")})])["planner"]["objective"] == name
    with pytest.raises(PreflightError, match=f"'nope' is not an objective; known: .*{name}"):
        check_params([NodeParams("planner", {"objective": ("nope", "-p")})])
    # the runner's flag
    assert name in next(a for a in build_parser()._actions if "--objective" in a.option_strings).choices
    run = run_scenario(load_network_spec(TINY), "exact", 3.0, 1, 240.0,
                       make_config({"network": TINY, "objective": name}))
    assert calls and run.summary["approved"] > 0


def test_a_registration_is_checked_naming_the_field():
    from uam_planner.objectives import register_objective
    from uam_solvers.registry import register_backend

    with pytest.raises(ValueError, match="objective name: 'Bad Name'"):
        register_objective("Bad Name", "", lambda ctx: None)
    with pytest.raises(ValueError, match="objective name: 'paper' is already registered"):
        register_objective("paper", "", lambda ctx: None)
    with pytest.raises(ValueError, match="backend name: 'greedy' is empty or a built-in backend's"):
        register_backend("greedy", LightestFirst)
    with pytest.raises(ValueError, match="is neither a Backend subclass"):
        register_backend("x", object)
