"""The study's tables, figures and report from node-graph recordings (``--from-mcap``): each
recording becomes one cell, through :mod:`uam_sim.audit.analysis`."""

from __future__ import annotations

import math
import time
from pathlib import Path
from typing import Sequence

import numpy as np

from ..audit.analysis import summarize
from ..runner.experiment_config import ExperimentConfig, rate_label
from ..runner.machine import machine_info
from ..recording.recorded_instances import instances_from_mcap
from ..runner.scenario import epoch_statistics
from ..runner.sweep import SweepResult
from ..runner.tables import write_corpus, write_tables
from .tts_study import run_tts


def cell_from_summary(summary, instances=(), label: str = "", seed: int = 0,
                      interval_s: float = 30.0) -> dict:
    """A cell (the dict the figures and report read) from a recording's analysis RunSummary.

    The method is the backend the planner used (``fifo`` when no epoch names one, as the FIFO
    policy uses none); the rate is the requests per interval over the recorded epochs; ``seed``
    labels the recording. Flights are not listed (the audit holds their count).
    """
    eps = list(summary.epochs)
    used = [e.backend_used for e in eps if e.backend_used and e.vertices > 0]
    method = max(set(used), key=used.count) if used else "fifo"
    n_epochs = max(len(eps), 1)
    rate = rate_label(round(summary.requests / n_epochs, 2))
    duration = (eps[-1].t_s + interval_s) if eps else max(summary.sim_end_s - summary.sim_start_s, 1.0)
    rows, cum, cum_exp = [], 0, 0
    for e in eps:
        cum += e.approved
        cum_exp += e.expired
        rows.append({"epoch": e.epoch_index, "t_s": e.t_s, "eligible": e.eligible_requests,
                     "vertices": e.vertices, "edges": e.edges, "selected": e.selected if method != "fifo" else e.approved,
                     "approved_cum": cum, "expired": e.expired, "expired_cum": cum_exp,
                     "active": e.active_flights, "objective": e.objective,
                     "solve_time_s": e.solve_time_s, "proven_optimal": False,
                     "fallback": bool(e.fallback), "backend_used": e.backend_used})
    a = summary.audit
    audit = {}
    if a is not None:
        ms = a.min_separation_m if a.min_separation_m is not None and math.isfinite(a.min_separation_m) else None
        audit = {"min_separation_m": ms, "pair_of_min": a.closest_pair, "losses": len(a.losses),
                 "loss_pairs": [list(x) for x in a.losses[:20]], "pairs_checked": a.pairs_checked}
    s = {"method": method, "rate": rate, "seed": int(seed), "duration_s": float(duration),
         "epochs": len(eps), "requests": summary.requests, "rejected": summary.rejected,
         "approved": summary.approved, "expired": summary.expired,
         "pending_end": summary.undecided,
         "approval_rate": summary.approved / summary.requests if summary.requests else float("nan"),
         "avg_airborne": summary.average_active_aircraft,
         **epoch_statistics(rows),
         "proven_optimal_share": float("nan"), "fallbacks": summary.fallbacks,
         "min_separation_m": audit.get("min_separation_m"), "losses": audit.get("losses"),
         "wall_s": float("nan"), "real_time_factor": float("nan"), "source": summary.path}
    insts = [{"epoch": i, "weights": [float(w) for w in p.weights],
              "edges": np.asarray(p.edges).reshape(-1, 2).tolist(),
              "groups": [np.asarray(g).tolist() for g in p.groups]} for i, p in enumerate(instances)]
    return {"key": f"mcap_{label or Path(summary.path).stem}", "params": {"source": summary.path},
            "summary": s, "epochs": rows, "flights": [], "audit": audit, "instances": insts,
            "rejections": []}


def study_from_mcaps(paths: Sequence[str], cfg: ExperimentConfig, figures: bool = True) -> dict:
    """The same tables, corpus, TTS, figures and report from node-graph recordings.

    Each recording becomes one cell (seed = its position in ``paths``).
    """
    t0 = time.perf_counter()
    cells = []
    for i, p in enumerate(paths):
        summary = summarize(p, None, default_separation=cfg.separation())  # the run's own model when recorded
        inst = [x for x in instances_from_mcap(p) if x.n <= cfg.corpus_max_vertices]
        cells.append(cell_from_summary(summary, inst, label=Path(p).stem, seed=i,
                                       interval_s=cfg.interval_s))
    sweep = SweepResult(cfg, cells, [], [], time.perf_counter() - t0)
    Path(cfg.out).mkdir(parents=True, exist_ok=True)
    tables = write_tables(sweep)
    corpus_path, entries = write_corpus(sweep)
    tts = run_tts(cfg, entries) if entries else {"status": "skipped",
                                                 "reason": "no MWIS instance was recorded"}
    figs = {}
    if figures:
        from ..reports.figures import make_figures
        figs = make_figures(cells, cfg, tts, Path(cfg.out))
    outputs = {"sweep": sweep, "tables": tables, "corpus": corpus_path, "tts": tts,
               "figures": figs, "wall_s": time.perf_counter() - t0}
    if figures:
        from ..reports.report import write_report
        outputs["report"] = write_report(sweep, outputs, machine_info(), Path(cfg.out))
    return outputs
