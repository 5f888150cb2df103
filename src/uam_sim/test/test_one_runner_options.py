"""The experiment runner takes the planning and demand options the node graph takes
(scripts/run_fleet.sh), by the same names and with the same defaults."""

from __future__ import annotations

import re
from pathlib import Path

from uam_sim.runner.experiment_config import ExperimentConfig
from uam_sim.studies.experiment import build_parser

ROOT = Path(__file__).resolve().parents[3]

# run_fleet.sh option -> ExperimentConfig field
SHARED = {
    "--objective": "objective", "--baseline-order": "baseline_order", "--priority-share": "priority_share",
    "--horizon": "horizon_epochs", "--commit-ahead": "commit_ahead", "--lead-time": "lead_time_s",
    "--reaction-period": "reaction_period_s", "--probe": "conflict_probe_s",
    "--probe-margin": "conflict_probe_margin_m", "--spatial-buffer-m": "spatial_buffer_m",
    "--temporal-buffer-s": "temporal_buffer_s", "--slot-s": "departure_slot_s", "--climb-rate": "climb_rate_mps",
    "--descent-rate": "descent_rate_mps", "--vertical-separation-m": "vertical_separation_m",
}


def _launch_defaults() -> dict:
    """The launchers' one table (uam_contract.launch_options): flag -> default."""
    from uam_contract.launch_options import LAUNCH_OPTIONS
    return {o.flag: o.default for o in LAUNCH_OPTIONS if o.flag}


def _run_fleet_defaults() -> dict:
    """run_fleet.sh: option -> the default of the variable it sets."""
    text = (ROOT / "scripts" / "run_fleet.sh").read_text()
    inits = {}
    for line in text.splitlines():
        if re.match(r"^[A-Z_]+=\S*( [A-Z_]+=\S*)+\s*$", line):
            inits.update(kv.split("=", 1) for kv in line.split())
    out = {}
    for opt, var in re.findall(r"^\s+(--[a-z-]+)\) ([A-Z_]+)=", text, re.M):
        out[opt] = inits.get(var)
    return out


def _same(shell: str, value) -> bool:
    if isinstance(value, bool):
        return shell == str(value).lower()
    if isinstance(value, (int, float)):
        return float(shell) == float(value)
    return shell.strip('"') == value


def test_the_runner_takes_run_fleets_planning_options_with_its_defaults():
    flags = {a for action in build_parser()._actions for a in action.option_strings}
    shell, table = _run_fleet_defaults(), _launch_defaults()
    cfg = ExperimentConfig()
    for opt, field in SHARED.items():
        assert opt in flags, f"python -m uam_sim.experiment has no {opt}"
        assert opt in shell, f"scripts/run_fleet.sh has no {opt}"
        assert shell[opt] is not None and _same(shell[opt], getattr(cfg, field)), \
            (opt, shell[opt], field, getattr(cfg, field))
        if opt in table:  # the launchers' table, where it lists the option
            assert _same(table[opt], getattr(cfg, field)), (opt, table[opt], field, getattr(cfg, field))


def test_the_objectives_are_one_registry_everywhere_they_are_named():
    """uam_planner.objectives' registry is the list: the planner node's parameter takes its rule
    (no list of its own), the runner's flag its names, and neither run_fleet.sh nor the launchers'
    help hold a copy of the names (test_extending.py adds one and finds it everywhere)."""
    from uam_contract.launch_options import LAUNCH_OPTIONS
    from uam_contract.params import PLANNER
    from uam_planner.objectives import objective_names

    param = next(p for p in PLANNER if p.name == "objective")
    assert param.rule == "objective_name" and param.choices is None
    assert next(a for a in build_parser()._actions if "--objective" in a.option_strings).choices == objective_names()
    help_text = next(o.help for o in LAUNCH_OPTIONS if o.flag == "--objective")
    assert "registered objective" in help_text, help_text
    assert not re.search(r'\$OBJECTIVE" =~', (ROOT / "scripts" / "run_fleet.sh").read_text())


def test_a_flag_reaches_the_config():
    args = build_parser().parse_args(["--objective", "count", "--horizon", "5", "--lead-time", "300",
                                      "--probe", "120", "--probe-margin", "50"])
    assert (args.objective, args.horizon_epochs, args.lead_time_s, args.conflict_probe_s,
            args.conflict_probe_margin_m) == ("count", 5, 300.0, 120.0, 50.0)


def test_the_montecarlo_takes_run_fleets_defaults_for_what_they_share():
    """The Monte-Carlo's network, rate and disturbances default to run_fleet.sh's (a tiny
    Monte-Carlo with no flag is the graph's world, not the disturbance study's)."""
    from uam_sim.studies.montecarlo import build_parser
    table = _launch_defaults()
    args = build_parser().parse_args([])
    for flag, dest in (("--network", "network"), ("--rate", "rate"), ("--gust", "gust"), ("--wind", "wind"),
                       ("--delay-mean", "delay_mean"), ("--reaction-period", "reaction_period"),
                       ("--probe", "probe"), ("--probe-margin", "probe_margin")):
        assert _same(table[flag], getattr(args, dest)), (flag, table[flag], getattr(args, dest))
    assert args.reaction == [False]   # run_fleet.sh's --reaction false
