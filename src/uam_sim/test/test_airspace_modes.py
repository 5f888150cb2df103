"""The airspace modes of the capacity study (paper, + slots, + levels, + both) through the
in-process runner: each mode is the preset it names, on the network it needs, and the paper mode
is untouched."""

import pytest

from uam_sim.runner.experiment_config import (AIRSPACE_PRESETS, REPO_ROOT, ExperimentConfig,
                                       ExperimentError, make_config)
from uam_sim.runner.network_spec import load_network_spec
from uam_sim.runner.scenario import run_scenario
from uam_sim.runner.sweep import cell_key, cell_params

SG = "config/networks/singapore.yaml"
SG_LAYERED = "config/networks/singapore-layered.yaml"


@pytest.mark.parametrize("mode", ["paper", "slots", "levels", "both"])
def test_each_mode_is_its_preset_on_the_network_it_needs(mode):
    cfg = make_config({"network": SG, "airspace_mode": mode})
    preset = AIRSPACE_PRESETS[mode]
    assert cfg.separation_model == preset["separation_model"]
    assert cfg.departure_slot_s == preset["departure_slot_s"]
    assert cfg.network == (SG_LAYERED if preset["layered"] else SG)
    assert bool(load_network_spec(cfg.network).levels_m) == preset["layered"]
    # the cell's worker rebuilds the config from the dumped fields: same config, same key
    from dataclasses import asdict
    again = make_config(asdict(cfg))
    assert cell_key(cell_params(again, "greedy", 10, 0)) == cell_key(cell_params(cfg, "greedy", 10, 0))


def test_the_paper_mode_keeps_its_cell_keys_and_the_modes_get_their_own():
    keys = {m: cell_key(cell_params(make_config({"network": SG, "airspace_mode": m}), "greedy", 10, 0))
            for m in ("paper", "slots", "levels", "both")}
    assert keys["paper"] == cell_key(cell_params(ExperimentConfig(network=SG), "greedy", 10, 0))
    assert len(set(keys.values())) == 4


def test_synthetic_networks_get_levels_and_pads_in_the_layered_modes():
    spec = {"synthetic": {"n_nodes": 40, "n_aerodromes": 6, "seed": 3}}
    flat = make_config({"network": spec, "airspace_mode": "slots"})
    both = make_config({"network": spec, "airspace_mode": "both"})
    assert "levels_m" not in flat.network["synthetic"]
    net = load_network_spec(both.network)
    assert list(net.levels_m) == [60.0, 90.0, 120.0, 150.0]
    with pytest.raises(ExperimentError, match="network: .* declares levels_m"):
        make_config({"network": both.network, "airspace_mode": "slots"})


def test_settings_that_contradict_the_mode_are_refused_naming_the_field(tmp_path):
    with pytest.raises(ExperimentError, match="departure_slot_s: 0.0 disagrees with airspace_mode 'slots'"):
        make_config({"network": SG, "airspace_mode": "slots", "departure_slot_s": 0.0})
    with pytest.raises(ExperimentError, match="separation_model: 'sphere' disagrees with airspace_mode 'both'"):
        make_config({"network": SG, "airspace_mode": "both", "separation_model": "sphere"})
    assert make_config({"network": SG, "airspace_mode": "both", "departure_slot_s": 10.0}).departure_slot_s == 10.0
    flat = tmp_path / "flat.yaml"
    flat.write_text((REPO_ROOT / SG).read_text())
    with pytest.raises(ExperimentError, match="has no cruise levels and no layered form"):
        make_config({"network": str(flat), "airspace_mode": "levels"})
    with pytest.raises(ExperimentError, match="is a layered network; airspace_mode 'slots' flies the flat one"):
        make_config({"network": SG_LAYERED, "airspace_mode": "slots"})


@pytest.mark.slow  # not in `make test-fast`: four airspace modes, 5 s
def test_the_expanded_modes_approve_more_than_the_paper_on_the_same_demand_without_losses():
    """Singapore at rate 20 for 300 s, greedy: every mode flies safely under its own model, and
    each expansion approves at least as many of the same requests as the paper's airspace."""
    approved = {}
    for mode in ("paper", "slots", "levels", "both"):
        cfg = make_config({"network": SG, "airspace_mode": mode, "duration_s": 300.0})
        res = run_scenario(load_network_spec(cfg.network), "greedy", 20, 0, 300.0, cfg)
        assert res.audit["losses"] == 0, mode
        assert res.audit.get("separation_model", "sphere") == cfg.separation_model
        approved[mode] = res.summary["approved"]
    assert approved["slots"] > approved["paper"]
    assert approved["levels"] > approved["paper"]
    assert approved["both"] >= max(approved["slots"], approved["levels"])
