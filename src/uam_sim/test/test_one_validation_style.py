"""One validation style for the six kinds of input (issue 19): node parameters, MWIS backend
options, network files, demand files, the experiment config and the capacity-study config each
refuse a bad value with a ValueError subclass the callers catch, whose message starts with the
field's path (``demand[17].priority``, ``arms[2].modes[0]``) and shows the value; unknown keys are
refused naming the key and its value. Node parameters and backend options are rows of one class
with one validator (uam_contract.validation.Param)."""

from __future__ import annotations

import copy
import re
from pathlib import Path

import pytest
import yaml

from uam_contract.params import PLANNER, SIMULATOR
from uam_contract.validation import Param
from uam_planner.network import NetworkError, network_from_dict
from uam_sim.studies.capacity_study import load_capacity_config
from uam_sim.world.demand import DemandError, parse_demand
from uam_sim.runner.experiment_config import ExperimentError, make_config
from uam_solvers.errors import MwisInputError
from uam_solvers.options import parse_options
from uam_solvers.registry import get_backend

REPO = Path(__file__).resolve().parents[3]
NETWORK = yaml.safe_load((REPO / "config/networks/singapore.yaml").read_text())
ARM = {"name": "a", "network": "config/networks/singapore.yaml", "modes": ["paper"],
       "methods": ["greedy"], "rates": [2]}


def _row(table, name):
    return next(p for p in table if p.name == name)


def _node_param(value):
    return _row(PLANNER, "k").validate(value)


def _backend_option(options):
    return parse_options("greedy", get_backend("greedy").options_spec, options)


def _network(mutate):
    doc = copy.deepcopy(NETWORK)
    mutate(doc)
    return network_from_dict(doc)


def _demand(entry, i=17):
    ok = [{"t_s": t, "origin": "AD_TUAS", "destination": "AD_JURONG_EAST"} for t in range(i)]
    return parse_demand(ok + [{"t_s": 0, "origin": "AD_TUAS", "destination": "AD_JURONG_EAST", **entry}])


def _capacity(tmp_path, arm):
    p = tmp_path / "study.yaml"
    p.write_text(yaml.safe_dump({"base": {"seeds": 1}, "arms": [ARM, {**ARM, "name": "b"},
                                                                 {**ARM, "name": "c", **arm}]}))
    return load_capacity_config(p)


# (kind, the call that refuses, error type, the field path the message starts with, the value)
BAD_VALUES = [
    ("node parameter", lambda _t: _node_param(500), ValueError, "parameter k", 500),
    ("node parameter type", lambda _t: _row(SIMULATOR, "duration_s").validate("long"), ValueError,
     "parameter duration_s", "long"),
    ("backend option", lambda _t: _backend_option({"rule": "best"}), MwisInputError, "options['rule']", "best"),
    ("network file", lambda _t: _network(lambda d: d["nodes"][3].update(lat=95.2)), NetworkError,
     f"nodes[3] (id {NETWORK['nodes'][3]['id']!r}).lat", 95.2),
    ("demand file", lambda _t: _demand({"priority": 300}), DemandError, "demand[17].priority", 300),
    ("experiment config", lambda _t: make_config({"duration_s": "long"}), ExperimentError, "duration_s", "long"),
    ("capacity-study config", lambda t: _capacity(t, {"modes": ["wide"]}), ExperimentError,
     "arms[2].modes[0]", "wide"),
]

UNKNOWN_KEYS = [
    ("backend option", lambda _t: _backend_option({"colour": 1}), MwisInputError, "options['colour']"),
    ("network file", lambda _t: _network(lambda d: d["corridors"][2].update(colour=1)), NetworkError,
     "corridors[2].colour"),
    ("demand file", lambda _t: _demand({"colour": 1}), DemandError, "demand[17].colour"),
    ("experiment config", lambda _t: make_config({"colour": 1}), ExperimentError, "colour"),
    ("capacity-study config", lambda t: _capacity(t, {"colour": 1}), ExperimentError, "arms[2].colour"),
]


@pytest.mark.parametrize("kind, call, error, path, value", BAD_VALUES, ids=[c[0] for c in BAD_VALUES])
def test_every_input_kind_refuses_a_bad_value_naming_field_and_value(tmp_path, kind, call, error, path, value):
    with pytest.raises(error) as info:
        call(tmp_path)
    assert isinstance(info.value, ValueError)  # what every caller catches
    assert str(info.value).startswith(f"{path}: {value!r} "), str(info.value)


@pytest.mark.parametrize("kind, call, error, path", UNKNOWN_KEYS, ids=[c[0] for c in UNKNOWN_KEYS])
def test_every_input_kind_refuses_an_unknown_key_naming_it_and_its_value(tmp_path, kind, call, error, path):
    with pytest.raises(error) as info:
        call(tmp_path)
    text = str(info.value)
    assert text.startswith(f"{path}: unknown"), text
    assert re.search(r"\(value 1[;)]", text), text


def test_node_parameters_and_backend_options_are_rows_of_one_class_with_one_validator():
    option = get_backend("greedy").options_spec["rule"]
    assert type(option) is Param and type(_row(PLANNER, "k")) is Param
    # the same check, only the field's name and the error type differ by the caller
    with pytest.raises(ValueError, match=r"^parameter rule: 'best' is not one of "):
        option.validate("best")
    with pytest.raises(MwisInputError, match=r"^options\['rule'\]: 'best' is not one of .*\(backend 'greedy'\)$"):
        _backend_option({"rule": "best"})


def test_the_experiment_schema_keeps_values_as_given():
    # a cell's key hashes the values: 3500 must stay the int 3500, not become 3500.0
    cfg = make_config({"duration_s": 3500, "rates": [2]})
    assert type(cfg.duration_s) is int and cfg.duration_s == 3500
    assert make_config({"duration_s": 3500.0, "rates": [2]}).duration_s == 3500.0
    with pytest.raises(ExperimentError, match=r"^duration_s: True is not a finite number"):
        make_config({"duration_s": True})
    with pytest.raises(ExperimentError, match=r"^workers: 0 is below the minimum 1"):
        make_config({"workers": 0})
