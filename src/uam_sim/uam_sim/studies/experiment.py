"""The paper's study, in process: methods x request rates x seeds, with results, figures and a report.

    python -m uam_sim.experiment --config config/experiment.yaml \
        [--rates 1,2 --methods fifo,greedy --seeds 1 --duration 600 --workers 2 --out results/]

Each *cell* (method, rate, seed) is one scenario run by :func:`uam_sim.runner.scenario.run_scenario`: a
:class:`~uam_planner.planning.Planner` driven epoch by epoch with the requests of a
:class:`~uam_sim.world.demand.RequestGenerator` seeded by ``seed`` alone, so every method at one
(rate, seed) plans the *same* requests, and the ROS node graph with the same seed gets the same
stream. Cells run in parallel over processes (no shared RNG, each cell is a pure function of its
parameters; wall-clock solve times are the only fields that differ between runs). Each finished
cell is written to ``<out>/cells/<cell-key>.json`` atomically and skipped next time when its key
(a hash of every parameter that affects it) matches, so an interrupted sweep resumes.

After the cells: ``runs.csv`` (one row per cell), ``epochs.csv`` (one row per epoch per cell),
``flights.csv``, the MWIS instances of the runs as a corpus (``instances.jsonl``), the TTS study on
a sample of them (``tts.csv``, reused when its sample and settings are unchanged), the figures
(:mod:`uam_sim.reports.figures`) and ``REPORT.md`` (:mod:`uam_sim.reports.report`). Every run is audited for loss
of separation by :func:`uam_sim.audit.separation.sweep_audit` (exact, all flight pairs); the command exits 1 on any loss.

Other modes: ``--no-compute`` reports on the finished cells of a partial sweep; ``--from-mcap
FILES`` computes the same tables, figures and report from node-graph recordings (through
:mod:`uam_sim.audit.analysis`). The cell key covers every parameter but not the code: after changing
the planning core or a backend, use a new ``--out`` (or delete ``<out>/cells``).

This module is the command line and :func:`run_experiment`; the parts: :mod:`uam_sim.runner.experiment_config`
(parameters), :mod:`uam_sim.runner.network_spec` (the network), :mod:`uam_sim.runner.scenario` (one cell),
:mod:`uam_sim.audit.separation` (:func:`~uam_sim.audit.separation.sweep_audit`), :mod:`uam_sim.runner.sweep` (cells, keys,
resumption, processes), :mod:`uam_sim.runner.tables` (CSV, corpus, timing table), :mod:`uam_sim.studies.tts_study`,
:mod:`uam_sim.studies.recorded_study` (``--from-mcap``), :mod:`uam_sim.reports.figures`, :mod:`uam_sim.reports.report`.
"""

from __future__ import annotations

import argparse
import sys
import time
from pathlib import Path

import yaml

from ..runner.experiment_config import AIRSPACE_MODES, ExperimentConfig, ExperimentError, load_config, make_config
from ..runner.machine import machine_info
from .recorded_study import study_from_mcaps
from ..runner.scenario import run_scenario
from ..runner.sweep import run_sweep
from ..runner.tables import format_timing_table, write_corpus, write_tables
from .tts_study import run_tts

#: The study's entry points, importable from here as before the split.
__all__ = ["ExperimentConfig", "ExperimentError", "build_parser", "load_config", "main", "make_config",
           "run_experiment", "run_scenario", "run_sweep", "study_from_mcaps"]


def run_experiment(cfg: ExperimentConfig, progress: bool = True, figures: bool = True,
                   report: bool = True, compute: bool = True) -> dict:
    """The whole study: sweep, tables, corpus, TTS, figures and REPORT.md. Returns the outputs.

    ``compute=False``: use only the cells already finished (see :func:`run_sweep`).
    """
    t0 = time.perf_counter()
    sweep = run_sweep(cfg, progress=progress, compute=compute)
    tables = write_tables(sweep)
    corpus_path, entries = write_corpus(sweep)
    tts = run_tts(cfg, entries) if entries else {"status": "skipped",
                                                 "reason": "no MWIS instance was collected"}
    figs = {}
    if figures:
        from ..reports.figures import make_figures
        figs = make_figures(sweep.cells, cfg, tts, Path(cfg.out))
    outputs = {"sweep": sweep, "tables": tables, "corpus": corpus_path, "tts": tts,
               "figures": figs, "wall_s": time.perf_counter() - t0}
    if report:
        from ..reports.report import write_report
        outputs["report"] = write_report(sweep, outputs, machine_info(), Path(cfg.out))
    return outputs


def key_values(text: str) -> dict:
    """'a=1,b=true' -> {'a': 1, 'b': True} (YAML scalars); argparse reports a bad item."""
    out = {}
    for item in (x.strip() for x in text.split(",")):
        if not item:
            continue
        key, sep, value = item.partition("=")
        if not sep or not key.strip():
            raise argparse.ArgumentTypeError(f"{item!r} is not KEY=VALUE")
        out[key.strip()] = yaml.safe_load(value)
    return out


def build_parser() -> argparse.ArgumentParser:
    p = argparse.ArgumentParser(prog="experiment", description=__doc__.split("\n\n")[0],
                                allow_abbrev=False)
    p.add_argument("--config", help="YAML experiment file (config/experiment.yaml)")
    p.add_argument("--network", help="network file (overrides the config)")
    p.add_argument("--rates", help="comma list of requests per interval, e.g. 1,2,4")
    p.add_argument("--methods", help="comma list: fifo, firstfit and MWIS backend names")
    p.add_argument("--seeds", help="a count n (seeds 0..n-1) or a comma list of seeds")
    p.add_argument("--duration", type=float, dest="duration_s", help="simulated seconds per run")
    p.add_argument("--time-limit", type=float, dest="time_limit_s", help="MWIS time limit [s]")
    p.add_argument("--workers", type=int, help="processes (1 = serial; more: a local Dask cluster)")
    p.add_argument("--scheduler", help="Dask scheduler: 'local' (a LocalCluster of --workers "
                   "processes) or an address tcp://HOST:8786 (see docs/dask.md)")
    p.add_argument("--out", help="output directory")
    p.add_argument("--demand", dest="demand_file", help="replay a demand file instead")
    p.add_argument("--constraints", dest="constraints_file", metavar="FILE",
                   help="airspace constraints to plan around (GeoJSON or ED-269, docs/constraints.md)")
    p.add_argument("--airspace-mode", dest="airspace_mode", choices=AIRSPACE_MODES,
                   help="paper (default), slots, levels or both (uam_sim.runner.experiment_config.AIRSPACE_PRESETS)")
    p.add_argument("--separation", dest="separation_model", choices=("sphere", "cylinder"),
                   help="separation model: the paper's sphere (default) or the cylinder")
    p.add_argument("--vertical-separation-m", type=float, dest="vertical_separation_m",
                   help="the cylinder's vertical minimum [m] (default 30)")
    p.add_argument("--slot-s", type=float, dest="departure_slot_s",
                   help="departure slot [s] inside the epoch; 0 = the paper's rule (default)")
    p.add_argument("--climb-rate", type=float, dest="climb_rate_mps",
                   help="climb rate at vertiports of a layered network [m/s] (default 5)")
    p.add_argument("--descent-rate", type=float, dest="descent_rate_mps",
                   help="descent rate at vertiports of a layered network [m/s] (default 3)")
    p.add_argument("--spatial-buffer-m", type=float, dest="spatial_buffer_m",
                   help="planning buffer on the separation [m] (docs/disturbances.md; default 0)")
    p.add_argument("--temporal-buffer-s", type=float, dest="temporal_buffer_s",
                   help="temporal planning buffer [s] (docs/disturbances.md; default 0)")
    p.add_argument("--disturbance", type=key_values, metavar="K=V,...",
                   help="disturbances flown (uam_sim.world.disturbance.DisturbanceConfig fields), e.g. "
                        "speed_error=0.1,gust_std_mps=1.5,delay_mean_s=10 (default none)")
    p.add_argument("--reaction", action="store_true", default=None,
                   help="the planner reacts to nonconforming flights (needs --disturbance)")
    p.add_argument("--conformance", type=key_values, metavar="K=V,...",
                   help="conformance bounds (uam_sim.world.conformance.ConformanceBounds), e.g. lateral_m=30,time_s=10")
    # the planning and demand options of run_fleet.sh, by the same names and defaults
    # (uam_sim.runner.experiment_config.ExperimentConfig; test_one_runner_options holds them equal)
    from uam_planner.objectives import BASELINE_ORDERS, objective_names
    p.add_argument("--objective", choices=objective_names(),
                   help="what the MWIS maximises (docs/objectives.md; default paper)")
    p.add_argument("--baseline-order", dest="baseline_order", choices=BASELINE_ORDERS,
                   help="the order of fifo and firstfit (default arrival)")
    p.add_argument("--priority-share", type=float, dest="priority_share",
                   help="share of random requests of priority class 1 (default 0)")
    p.add_argument("--horizon", type=int, dest="horizon_epochs",
                   help="epochs the MWIS plans jointly (rolling horizon; default 1, the paper's)")
    p.add_argument("--commit-ahead", action="store_true", default=None, dest="commit_ahead",
                   help="with --horizon > 1, commit the horizon's later departures now as reservations")
    p.add_argument("--lead-time", type=float, dest="lead_time_s",
                   help="requests are filed this many seconds before their earliest departure (default 0)")
    p.add_argument("--reaction-period", type=float, dest="reaction_period_s",
                   help="with --reaction, also react every S seconds between epochs (default 0: at epochs)")
    p.add_argument("--probe", type=float, dest="conflict_probe_s",
                   help="with --reaction, the conflict probe's look-ahead [s] (default 0: off)")
    p.add_argument("--probe-margin", type=float, dest="conflict_probe_margin_m",
                   help="with --probe, the probe's margin [m] (default 0)")
    p.add_argument("--tts-reads", type=int, help="reads per annealing run in the TTS study")
    p.add_argument("--tts-instances", type=int, help="instances in the TTS study")
    p.add_argument("--no-tts", action="store_true", help="skip the TTS study")
    p.add_argument("--no-figures", action="store_true", help="skip figures and report")
    p.add_argument("--no-progress", action="store_true", help="no progress bar")
    p.add_argument("--no-compute", action="store_true",
                   help="only collect finished cells (report on a partial sweep)")
    p.add_argument("--from-mcap", nargs="+", metavar="FILE",
                   help="summarise node-graph recordings instead of running the sweep")
    return p


def main(argv: list | None = None) -> int:
    args = build_parser().parse_args(argv)
    over = {k: getattr(args, k) for k in ("network", "rates", "methods", "seeds", "duration_s",
                                          "time_limit_s", "workers", "out", "demand_file",
                                          "constraints_file",
                                          "scheduler", "airspace_mode",
                                          "separation_model", "vertical_separation_m",
                                          "departure_slot_s", "climb_rate_mps", "descent_rate_mps",
                                          "spatial_buffer_m", "temporal_buffer_s", "disturbance",
                                          "conformance", "reaction", "objective", "baseline_order",
                                          "priority_share", "horizon_epochs", "commit_ahead", "lead_time_s",
                                          "reaction_period_s", "conflict_probe_s", "conflict_probe_margin_m")}
    try:
        base = yaml.safe_load(Path(args.config).read_text()) if args.config else {}
        base = base or {}
        tts = dict(base.get("tts") or {})
        if args.tts_reads is not None:
            tts["reads"] = args.tts_reads
        if args.tts_instances is not None:
            tts["instances"] = args.tts_instances
        if args.no_tts:
            tts["enabled"] = False
        if tts:
            base["tts"] = tts
        cfg = make_config(base, **over)
    except (ExperimentError, OSError, yaml.YAMLError) as exc:
        print(f"experiment: {exc}", file=sys.stderr)
        return 2
    try:
        if args.from_mcap:
            outputs = study_from_mcaps(args.from_mcap, cfg, figures=not args.no_figures)
        else:
            outputs = run_experiment(cfg, progress=not args.no_progress, figures=not args.no_figures,
                                     report=not args.no_figures, compute=not args.no_compute)
    except ExperimentError as exc:  # a bad value found only when it is used (e.g. a demand file)
        print(f"experiment: {exc}", file=sys.stderr)
        return 2
    sweep = outputs["sweep"]
    print(format_timing_table(sweep.cells))
    print(f"{len(sweep.cells)} cells ({len(sweep.computed)} computed, {len(sweep.reused)} reused) "
          f"in {outputs['wall_s']:.1f} s; results in {cfg.out}")
    losses = sum((c["summary"].get("losses") or 0) for c in sweep.cells)
    if losses:
        print(f"experiment: SAFETY AUDIT FOUND {losses} LOSSES OF SEPARATION", file=sys.stderr)
        return 1
    if "report" in outputs:
        print(f"report: {outputs['report']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
