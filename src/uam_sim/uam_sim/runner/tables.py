"""The study's tidy outputs: runs.csv, epochs.csv, flights.csv, the MWIS corpus
(instances.jsonl) and the timing table printed at the end."""

from __future__ import annotations

import hashlib
import json
from pathlib import Path

import numpy as np

from .files import write_csv
from .sweep import SweepResult


def write_tables(sweep: SweepResult) -> dict:
    """runs.csv, epochs.csv, flights.csv in cfg.out; returns their paths."""
    out = Path(sweep.config.out)
    runs, epochs, flights = [], [], []
    for c in sweep.cells:
        s = c["summary"]
        runs.append(dict(s))
        tag = {"method": s["method"], "rate": s["rate"], "seed": s["seed"]}
        epochs.extend({**tag, **r} for r in c["epochs"])
        flights.extend({**tag, **f} for f in c["flights"])
    paths = {"runs": out / "runs.csv", "epochs": out / "epochs.csv", "flights": out / "flights.csv"}
    write_csv(paths["runs"], runs)
    write_csv(paths["epochs"], epochs)
    write_csv(paths["flights"], flights)
    return paths


def write_corpus(sweep: SweepResult) -> tuple[Path | None, list]:
    """Save every collected MWIS instance (deduplicated) to <out>/instances.jsonl."""
    from uam_solvers.instances import CorpusEntry, save_corpus
    from uam_solvers import MwisProblem
    entries, seen = [], set()
    for c in sweep.cells:
        s = c["summary"]
        for inst in c["instances"]:
            sig = hashlib.sha1(json.dumps([inst["weights"], inst["edges"]]).encode()).hexdigest()
            if sig in seen:
                continue
            seen.add(sig)
            prob = MwisProblem.from_arrays(inst["weights"], inst["edges"], groups=inst["groups"] or None)
            name = f"{s['method']}-r{s['rate']}-s{s['seed']}-e{inst['epoch']:04d}"
            entries.append(CorpusEntry(name=name, problem=prob,
                                       source=f"uam_sim.experiment cell {c['key']} epoch {inst['epoch']}"))
    if not entries:
        return None, []
    path = save_corpus(Path(sweep.config.out) / "instances.jsonl", entries)
    return path, entries


def format_timing_table(cells) -> str:
    """Per method and rate: cells, mean wall time per run [s], mean real-time factor."""
    lines = [f"{'method':<14}{'rate':>6}{'cells':>7}{'wall/run [s]':>14}{'real-time x':>13}"]
    groups: dict = {}
    for c in cells:
        s = c["summary"]
        groups.setdefault((s["method"], s["rate"]), []).append(s)
    for (m, r), ss in groups.items():
        w = [x["wall_s"] for x in ss if x.get("wall_s") == x.get("wall_s")]
        f = [x["real_time_factor"] for x in ss if x.get("real_time_factor") == x.get("real_time_factor")]
        lines.append(f"{m:<14}{r:>6}{len(ss):>7}{(np.mean(w) if w else float('nan')):>14.2f}"
                     f"{(np.mean(f) if f else float('nan')):>13.0f}")
    total = sum(x["summary"].get("wall_s") or 0.0 for x in cells)
    lines.append(f"sum of per-run wall times: {total:.1f} s")
    return "\n".join(lines)
