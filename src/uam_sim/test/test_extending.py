"""The recipes of docs/extending.md, each made in this test module and found everywhere it must
appear: a backend (one class, one registration), an objective (one function, one registration)
and a disturbance effect (one class, one registration). If a recipe needs another file, it fails
here."""

from __future__ import annotations

import math
import time

import numpy as np
import pytest

from uam_planner.trajectory import Trajectory
from uam_solvers.base import Backend, make_result
from uam_sim.world.disturbance import Air, DisturbanceEffect

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


class HeadWind(DisturbanceEffect):
    """A head wind of ``head_wind_mps`` along every horizontal segment, whatever its direction:
    the ground speed there is the airspeed minus it (climbs and descents keep theirs)."""

    name = "test_head_wind"
    description = "test: a head wind of head_wind_mps along every horizontal segment"
    levels = ("head_wind_mps",)
    params = {"head_wind_mps": 0.0}

    def air(self, step):
        return Air(along=np.where(step.horizontal, -float(step.config.value("head_wind_mps")), 0.0))


@pytest.fixture
def head_wind():
    from uam_sim.world.disturbance import register_effect, unregister_effect
    effect = register_effect(HeadWind)
    yield effect
    unregister_effect(HeadWind.name)


#: up 50 m at 5 m/s, then east 1,000 m at 10 m/s
CLIMB_EAST = Trajectory(np.array([0.0, 10.0, 110.0]),
                        np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 50.0], [1000.0, 0.0, 50.0]]))


def test_a_disturbance_effect_in_one_class_is_found_everywhere(head_wind):
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario
    from uam_sim.studies.montecarlo import build_parser, point_configs
    from uam_contract.params import SIMULATOR
    from uam_sim.world.disturbance import (DisturbanceConfig, FlightDraws, effects, fly, flight_draws,
                                           from_simulator_params)

    assert effects()[-1] is head_wind
    # its field is a DisturbanceConfig field by name, and "are any disturbances on" sees its level
    cfg = DisturbanceConfig.from_mapping({"head_wind_mps": 2.0})
    assert cfg.enabled and cfg.value("head_wind_mps") == 2.0 and cfg.extra == {"head_wind_mps": 2.0}
    assert not DisturbanceConfig().enabled and DisturbanceConfig().value("head_wind_mps") == 0.0
    # the flight model sums it: the climb at 5 m/s (10 s), then 1,000 m at 10 - 2 = 8 m/s (125 s)
    flown = fly(CLIMB_EAST, FlightDraws(), cfg)
    assert flown.arrival_s == 135.0
    at = np.searchsorted(flown.times_s, 10.0 + 50.0)
    assert flown.times_s[at] == 60.0 and np.array_equal(flown.points_m[at], [400.0, 0.0, 50.0])
    # ... with the others: 1 m/s of wind from the east and its 2 m/s fly as a 3 m/s head wind
    both = fly(CLIMB_EAST, FlightDraws(), DisturbanceConfig.from_mapping(
        {"head_wind_mps": 2.0, "wind_speed_mps": 1.0, "wind_from_deg": 90.0}))
    alone = fly(CLIMB_EAST, FlightDraws(), DisturbanceConfig.from_mapping({"head_wind_mps": 3.0}))
    assert math.isclose(alone.arrival_s, 10.0 + 1000.0 / 7.0)
    assert np.array_equal(both.times_s, alone.times_s) and np.array_equal(both.points_m, alone.points_m)
    # it draws nothing: the others' draws are the same with it registered
    assert flight_draws(DisturbanceConfig(speed_error=0.1, seed=3), "a").extra == {}
    # the runner's disturbance mapping and the Monte-Carlo's --disturbance take its field
    run = run_scenario(load_network_spec(TINY), "firstfit", 3.0, 1, 240.0,
                       make_config({"network": TINY, "disturbance": {"head_wind_mps": 2.0}}))
    assert run.summary["approved"] > 0 and run.summary["conf_conformance_percent"] < 100.0
    args = build_parser().parse_args(["--disturbance", "head_wind_mps=2", "--network", TINY])
    assert all(conf["disturbance"]["head_wind_mps"] == 2 for _pt, conf in point_configs(args))
    # the simulator node's config takes it from a parameter of its name, when the node has one
    # (uam_contract.params.SIMULATOR does not: docs/extending.md)
    node_params = {p.name: p.default for p in SIMULATOR}
    assert from_simulator_params(node_params, 1.0) == DisturbanceConfig()
    assert from_simulator_params({**node_params, "head_wind_mps": 2.0}, 1.0) == cfg


def test_an_unregistered_effect_is_gone():
    from uam_sim.world.disturbance import DisturbanceConfig, effects, register_effect, unregister_effect

    register_effect(HeadWind)
    unregister_effect(HeadWind.name)
    assert HeadWind.name not in [e.name for e in effects()]
    with pytest.raises(ValueError, match="unknown field 'head_wind_mps'"):
        DisturbanceConfig.from_mapping({"head_wind_mps": 2.0})
    with pytest.raises(ValueError, match="'head_wind_mps' is no registered effect's field"):
        DisturbanceConfig(extra={"head_wind_mps": 2.0})


def test_a_registration_is_checked_naming_the_field():
    from uam_planner.objectives import register_objective
    from uam_solvers.registry import register_backend
    from uam_sim.world.disturbance import register_effect, unregister_effect

    with pytest.raises(ValueError, match="objective name: 'Bad Name'"):
        register_objective("Bad Name", "", lambda ctx: None)
    with pytest.raises(ValueError, match="objective name: 'paper' is already registered"):
        register_objective("paper", "", lambda ctx: None)
    with pytest.raises(ValueError, match="backend name: 'greedy' is empty or a built-in backend's"):
        register_backend("greedy", LightestFirst)
    with pytest.raises(ValueError, match="is neither a Backend subclass"):
        register_backend("x", object)
    with pytest.raises(ValueError, match="effect name: 'wind' is already registered"):
        register_effect(type("Wind2", (HeadWind,), {"name": "wind"}))
    with pytest.raises(ValueError, match="effect name: 'speed_error' is a built-in effect"):
        unregister_effect("speed_error")
    with pytest.raises(ValueError, match="field 'gust_std_mps' is already a DisturbanceConfig or effect field"):
        register_effect(type("Gusty", (HeadWind,), {"params": {"gust_std_mps": 0.0}}))
    with pytest.raises(ValueError, match="level 'head_wind' is neither a DisturbanceConfig field nor its own"):
        register_effect(type("Typo", (HeadWind,), {"levels": ("head_wind",)}))
    with pytest.raises(ValueError, match="DisturbanceConfig.head_wind_mps: -1 must be >= 0"):
        register_effect(type("Negative", (HeadWind,), {"params": {"head_wind_mps": -1}}))
    with pytest.raises(ValueError, match="is not a DisturbanceEffect"):
        register_effect(object())
