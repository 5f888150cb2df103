"""The in-process runner's constraints (``--constraints FILE``, ``constraints_file``; issue 22):
checked when configured and when loaded, part of the cell key only when given, and planned
around: every approved flight of the run stays out of every constraint."""

import json

import pytest

from uam_planner.constraints import load_constraints
from uam_sim.studies.experiment import build_parser
from uam_sim.runner.experiment_config import ExperimentConfig, ExperimentError, make_config
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.scenario import run_scenario
from uam_sim.runner.sweep import cell_key, cell_params

TINY = "config/networks/tiny.yaml"


def write(tmp_path, upper_m=300.0):
    doc = {"type": "FeatureCollection", "frame": "enu", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [
            [[-250, -250], [250, -250], [250, 250], [-250, 250], [-250, -250]]]},
         "properties": {"id": "hub", "version": 1, "reason": "event", "lower_m": 0,
                        "upper_m": upper_m, "start_s": 0, "end_s": 10000}}]}
    path = tmp_path / "c.geojson"
    path.write_text(json.dumps(doc))
    return path


def test_constraints_file_is_checked_and_keyed(tmp_path):
    with pytest.raises(ExperimentError, match="constraints_file: file 'nope.geojson' does not exist"):
        make_config({"network": TINY, "constraints_file": "nope.geojson"})
    path = write(tmp_path)
    plain = cell_key(cell_params(make_config({"network": TINY}), "greedy", 2, 0))
    assert plain == cell_key(cell_params(ExperimentConfig(network=TINY), "greedy", 2, 0))
    keyed = cell_key(cell_params(make_config({"network": TINY, "constraints_file": str(path)}), "greedy", 2, 0))
    assert keyed != plain
    assert build_parser().parse_args(["--constraints", str(path)]).constraints_file == str(path)


def test_runner_plans_around_the_constraints_and_refuses_bad_ones(tmp_path):
    net = load_network_spec(TINY)
    path = write(tmp_path)
    cfg = make_config({"network": TINY, "constraints_file": str(path), "audit": False})
    flown = {"free": [], "constrained": []}

    def keep(name):
        return lambda t, k, submitted, rejected, result: flown[name].extend(result.approved)

    run_scenario(net, "greedy", 3.0, 4, 300.0, make_config({"network": TINY, "audit": False}),
                 observer=keep("free"))
    run_scenario(net, "greedy", 3.0, 4, 300.0, cfg, observer=keep("constrained"))
    cset = load_constraints(path, net)
    for name, flights in flown.items():
        which, _ = cset.violations([f.trajectory for f in flights],
                                   [net.node_index(f.origin_id) for f in flights],
                                   [net.node_index(f.destination_id) for f in flights])
        flown[name] = (len(flights), int((which >= 0).sum()))
    # the hub is on the free run's routes; with the constraint no approved flight enters it
    assert flown["free"][1] > 0 and flown["constrained"][0] > 0 and flown["constrained"][1] == 0
    bad = make_config({"network": TINY, "constraints_file": str(write(tmp_path, upper_m=-5.0))})
    with pytest.raises(ExperimentError, match=r"constraints_file: .*upper_m: -5.0 is not above lower_m"):
        run_scenario(net, "greedy", 3.0, 4, 60.0, bad)
