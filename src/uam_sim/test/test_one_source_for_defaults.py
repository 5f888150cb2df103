"""One source for every default (issue 19): the paper's model is defined once, in
uam_contract.defaults; the Python that can import it does (the planner library, the runner, the
audit, the node parameter tables, the launcher table), and the files that cannot (the YAML files in
config/, scripts/run_fleet.sh through test/test_launchers.py) are held to it here, so a value that
drifts in one place fails this test. No ROS needed."""

from __future__ import annotations

import dataclasses
import pathlib

import pytest
import yaml

from uam_contract import defaults as D
from uam_contract import params as P
from uam_contract.launch_options import LAUNCH_OPTIONS
from uam_planner import candidates, separation
from uam_planner.planning import AirspaceConfig, PlanningConfig
from uam_sim.runner.experiment_config import ExperimentConfig

ROOT = pathlib.Path(__file__).resolve().parents[3]
CONFIG = ROOT / "config"

#: the values typed by hand here, once, to catch a change of the one source itself: the paper's
#: model (Haba et al. 2025: 100 m sphere, 30 s epochs, 60 s window, k = 5, penalty 5, 10 m/s) and
#: the expanded airspace's documented defaults (docs/airspace.md)
PAPER = {"SEPARATION_M": 100.0, "VERTICAL_SEPARATION_M": 30.0, "DEPARTURE_SLOT_S": 0.0,
         "CLIMB_RATE_MPS": 5.0, "DESCENT_RATE_MPS": 3.0, "EPOCH_S": 30.0, "INTERVAL_S": 30.0,
         "WINDOW_S": 60.0, "K": 5, "PENALTY_FACTOR": 5.0, "SPEED_MPS": 10.0}

#: node YAML values that differ from their table's default on purpose: the table's default is
#: "unset" (a node must be told its network), the file names the run's
YAML_OVERRIDES = {("planner", "network"), ("request_generator", "network"),
                  ("simulator", "wait_for_subscribers")}


def test_the_one_source_holds_the_papers_model():
    assert {name: getattr(D, name) for name in PAPER} == PAPER
    assert D.as_text(D.SEPARATION_M) == "100" and D.as_text(D.DEPARTURE_SLOT_S) == "0"


def test_the_libraries_defaults_are_the_one_source():
    cfg, air = PlanningConfig(), AirspaceConfig()
    assert (cfg.epoch_s, cfg.separation_m, cfg.k, cfg.penalty_factor, cfg.speed_mps) == \
        (30.0, 100.0, 5, 5.0, 10.0)
    assert (air.vertical_separation_m, air.departure_slot_s, air.climb_rate_mps, air.descent_rate_mps) == \
        (30.0, 0.0, 5.0, 3.0)
    assert separation.DEFAULT_SEPARATION_M == 100.0 and separation.DEFAULT_VERTICAL_SEPARATION_M == 30.0
    assert (candidates.DEFAULT_CLIMB_RATE_MPS, candidates.DEFAULT_DESCENT_RATE_MPS) == (5.0, 3.0)
    exp = ExperimentConfig()
    for field in ("epoch_s", "interval_s", "window_s", "separation_m", "k", "penalty_factor", "speed_mps",
                  "vertical_separation_m", "departure_slot_s", "climb_rate_mps", "descent_rate_mps"):
        assert getattr(exp, field) == PAPER[field.upper()], field


def _tables() -> dict:
    return {"planner": P.PLANNER, "recorder": P.RECORDER, "replay": P.REPLAY,
            "request_generator": P.REQUEST_GENERATOR, "simulator": P.SIMULATOR, "solver": P.SOLVER}


def test_parameter_tables_and_launcher_table_take_the_one_source():
    planner = {p.name: p.default for p in P.PLANNER}
    for name in ("separation_m", "vertical_separation_m", "departure_slot_s", "climb_rate_mps",
                 "descent_rate_mps", "k", "penalty_factor", "speed_mps"):
        assert planner[name] == PAPER[name.upper()], name
    recorder = {p.name: p.default for p in P.RECORDER}
    assert (recorder["separation_m"], recorder["vertical_separation_m"], recorder["departure_slot_s"]) == \
        (100.0, 30.0, 0.0)
    simulator = {p.name: p.default for p in P.SIMULATOR}
    generator = {p.name: p.default for p in P.REQUEST_GENERATOR}
    assert simulator["epoch_s"] == 30.0 and generator["window_s"] == 60.0
    launch = {o.arg: o.default for o in LAUNCH_OPTIONS}
    assert (launch["separation_m"], launch["vertical_separation_m"], launch["slot_s"], launch["climb_rate"],
            launch["descent_rate"]) == ("100", "30", "0", "5", "3")


@pytest.mark.parametrize("node", ["planner", "request_generator", "simulator", "solver"])
def test_every_node_yaml_value_is_its_tables_default(node):
    """config/<node>.yaml holds the defaults of uam_contract.params (written out for a reader), so
    each value must equal the table's; only the YAML_OVERRIDES differ, on purpose."""
    body = yaml.safe_load((CONFIG / f"{node}.yaml").read_text())[node]["ros__parameters"]
    table = {p.name: p.default for p in _tables()[node]}
    unknown = set(body) - set(table)
    assert not unknown, f"config/{node}.yaml sets parameters the node does not have: {sorted(unknown)}"
    drift = {k: (v, table[k]) for k, v in body.items() if (node, k) not in YAML_OVERRIDES and v != table[k]}
    assert not drift, f"config/{node}.yaml differs from uam_contract.params ((yaml, table)): {drift}"


def test_the_experiment_yaml_model_values_are_the_runners_defaults():
    doc = yaml.safe_load((CONFIG / "experiment.yaml").read_text())
    defaults = {f.name: f.default for f in dataclasses.fields(ExperimentConfig)
                if f.default is not dataclasses.MISSING}
    for key in ("epoch_s", "interval_s", "window_s", "separation_m", "k", "penalty_factor", "speed_mps"):
        assert doc[key] == defaults[key], (key, doc[key], defaults[key])
