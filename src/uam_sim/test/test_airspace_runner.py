"""The expanded airspace through the in-process runner, the audits and the analysis (issue 10,
Deliver 7): the runner takes the airspace options, and every audit checks the run's model."""

from __future__ import annotations

import numpy as np
import pytest

from uam_planner.network import load_network
from uam_planner.separation import SeparationModel
from uam_planner.trajectory import Trajectory
from uam_sim.audit.separation import (AIRSPACE_METADATA, airspace_metadata, audit_trajectories,
                           separation_from_metadata, sweep_audit)
from uam_sim.runner.experiment_config import REPO_ROOT, ExperimentError, make_config
from uam_sim.runner.scenario import run_scenario
from uam_sim.runner.sweep import cell_params

LAYERED = REPO_ROOT / "config" / "networks" / "singapore-layered.yaml"
PAPER = REPO_ROOT / "config" / "networks" / "singapore.yaml"
CYLINDER = SeparationModel("cylinder", 100.0, 30.0)


def _crossing(z_b: float) -> list:
    """Two straight flights crossing at the origin at t = 50 s: A east at z = 60 m, B north at z_b.
    Both at 10 m/s over [0, 100] s, so at time t they are (t - 50) * 10 m from the origin."""
    a = Trajectory(np.array([0.0, 100.0]), np.array([[-500.0, 0.0, 60.0], [500.0, 0.0, 60.0]]))
    b = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, -500.0, z_b], [0.0, 500.0, z_b]]))
    return [a, b]


def test_audits_use_the_run_model_crossing_one_level_apart():
    # one level (30 m) apart: a loss for the paper's 100 m sphere (30 m at t = 50 s), none for the
    # cylinder with V = 30 m (|dz| = 30 is not < 30: never vertically close)
    flights = _crossing(90.0)
    sphere = sweep_audit(flights, 100.0, labels=["a", "b"])
    assert sphere["losses"] == 1 and sphere["min_separation_m"] == pytest.approx(30.0)
    cyl = sweep_audit(flights, CYLINDER, labels=["a", "b"])
    assert cyl["losses"] == 0 and cyl["separation_model"] == "cylinder"
    pairs = [(f.times_s, f.points_m) for f in flights]
    assert len(audit_trajectories(pairs, ["a", "b"], 100.0).losses) == 1
    rec = audit_trajectories(pairs, ["a", "b"], CYLINDER)
    assert rec.ok and rec.separation_model == "cylinder"
    assert "30 m vertical" in rec.describe_minimum()


def test_audits_find_a_crossing_at_one_level_in_the_cylinder():
    # 20 m apart vertically (< V): horizontal distance 0 at t = 50 s is a loss in the cylinder
    flights = _crossing(80.0)
    cyl = sweep_audit(flights, CYLINDER, labels=["a", "b"])
    assert cyl["losses"] == 1
    assert cyl["min_separation_m"] == pytest.approx(0.0, abs=1e-9)
    a, b, dist, t = cyl["loss_pairs"][0]
    assert {a, b} == {"a", "b"} and t == pytest.approx(50.0)
    rec = audit_trajectories([(f.times_s, f.points_m) for f in flights], ["a", "b"], CYLINDER)
    assert len(rec.losses) == 1 and rec.losses[0][3] == pytest.approx(50.0)


def test_exact_tie_is_no_loss_in_either_audit():
    # one route, two departures 10 s apart at 10 m/s: exactly 100 m in trail all the way
    t = np.array([0.0, 100.0])
    a = Trajectory(t, np.array([[0.0, 0.0, 60.0], [1000.0, 0.0, 60.0]]))
    b = Trajectory(t + 10.0, np.array([[0.0, 0.0, 60.0], [1000.0, 0.0, 60.0]]))
    for model in (100.0, CYLINDER):
        res = sweep_audit([a, b], model)
        assert res["losses"] == 0 and res["min_separation_m"] == pytest.approx(100.0)


def test_airspace_metadata_round_trip_and_bad_values():
    meta = airspace_metadata("cylinder", 100.0, 30.0, 5.0)
    assert separation_from_metadata(meta) == CYLINDER
    assert separation_from_metadata({}) == SeparationModel("sphere", 100.0)
    with pytest.raises(ValueError, match="kind"):
        airspace_metadata("cube")
    with pytest.raises(ValueError, match="departure_slot_s"):
        airspace_metadata("sphere", 100.0, 30.0, -1.0)
    assert AIRSPACE_METADATA == "uam_airspace"


def test_experiment_config_checks_airspace_fields():
    with pytest.raises(ExperimentError, match="separation_model.*'cube'"):
        make_config(separation_model="cube")
    with pytest.raises(ExperimentError, match="departure_slot_s"):
        make_config(departure_slot_s=-5.0)
    cfg = make_config(separation_model="cylinder", departure_slot_s=5.0)
    assert cfg.planning_config("greedy", 0).airspace.departure_slot_s == 5.0
    assert cfg.separation() == CYLINDER and not cfg.paper_airspace


def test_paper_cells_keep_their_keys_airspace_cells_differ():
    paper = make_config(network=str(PAPER))
    params = cell_params(paper, "exact", 10, 0)
    assert "departure_slot_s" not in params and "separation_model" not in params
    slotted = cell_params(make_config(network=str(PAPER), departure_slot_s=5.0), "exact", 10, 0)
    assert slotted["departure_slot_s"] == 5.0 and slotted["separation_model"] == "sphere"


def test_runner_layered_with_slots_is_safe_in_the_cylinder_and_uses_levels_and_slots():
    cfg = make_config(network=str(LAYERED), separation_model="cylinder", vertical_separation_m=30.0,
                      departure_slot_s=5.0, audit=True, time_limit_s=5.0)
    res = run_scenario(load_network(LAYERED), "greedy", 6.0, 4, 240.0, cfg)
    s = res.summary
    assert s["approved"] > 0 and s["fallbacks"] == 0
    # the runner's audit ran in the run's model and found no loss of separation
    assert res.audit["separation_model"] == "cylinder"
    assert res.audit["losses"] == 0 and res.audit["pairs_checked"] > 0
    # the options took effect: departures between epochs (slots) and several cruise levels
    epochs_t = {round(f["epoch"] * 30.0, 6) for f in res.flights}
    assert any(round(f["departure_s"], 6) not in epochs_t for f in res.flights)
    assert all(f["departure_s"] % 5.0 == pytest.approx(0.0, abs=1e-9) or
               f["departure_s"] % 5.0 == pytest.approx(5.0, abs=1e-9) for f in res.flights)
    levels = {f["level_m"] for f in res.flights}
    assert len(levels) >= 2 and levels <= {60.0, 90.0, 120.0, 150.0}
    # and the same demand in paper mode approves fewer (same requests: same ids and seed)
    paper = run_scenario(load_network(PAPER), "greedy", 6.0, 4, 240.0,
                         make_config(network=str(PAPER), audit=True, time_limit_s=5.0))
    assert paper.summary["requests"] == s["requests"]
    assert paper.summary["approved"] < s["approved"]
    assert np.isnan(paper.flights[0]["level_m"])
