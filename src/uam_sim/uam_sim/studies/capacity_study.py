"""The capacity study: does the solver decide the throughput once the airspace has room?

    python -m uam_sim.capacity_study --config config/capacity-study.yaml --out results/capacity

The paper's airspace (one cruise altitude, departure at the epoch time) saturates early and keeps
its MWIS instances at a few vertices, where a first-fit over the candidates approves as many
flights as the optimiser. This study sweeps *arms* (a network with methods x rates x seeds) in
*airspace modes* (paper, + departure slots, + flight levels, + both;
``uam_sim.runner.experiment_config.AIRSPACE_PRESETS``), with the runner of the paper's study
(``uam_sim.runner.sweep``, the same cells, keys, resumption and Dask cluster), then measures solve time
and optimality gap against instance size per backend on instances of one recorded cell, and
writes tables, figures and ``REPORT.md`` with paired per-seed statistics (``uam_sim.reports.stats``).

Outputs in ``--out``: ``runs.csv`` (one row per run, with arm / mode / network), ``epochs.csv.gz``
(one row per epoch per run), ``flights.csv.gz`` (departure delay, length and level per flown
flight), ``instances.csv`` (the size study), ``figures/``, ``report_inputs.json`` and
``REPORT.md``. ``python -m uam_sim.capacity_report DIR`` writes the report and figures again
from those tables alone.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
import time
from dataclasses import asdict, dataclass, field, replace
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

import numpy as np
import pydantic
import yaml

from uam_contract.validation import parse

from ..runner.experiment_config import AIRSPACE_MODES, ExperimentError, make_config
from ..runner.files import write_csv
from ..runner.machine import machine_info
from ..runner.sweep import cell_key, cell_params, run_cell, run_sweep

FORMAT = "uam-capacity-study/1"
INSTANCE_DEFAULTS = {"source": None, "bins": [8, 16, 32, 64, 128, 256, 512, 1024, 4096],
                     "per_bin": 4, "backends": ["greedy", "auto", "exact"], "time_limit_s": 1.0,
                     "best_known_limit_s": 10.0, "seed": 0}


@dataclass
class Arm:
    """One arm: a network swept over methods x rates x seeds in each of ``modes``."""

    name: str
    network: object
    modes: list
    methods: list
    rates: list
    overrides: dict = field(default_factory=dict)


@dataclass
class CapacityConfig:
    """The study: shared ExperimentConfig keys (``base``), the arms, the instance study."""

    base: dict
    arms: list
    instances: dict
    out: str = "results/capacity"
    workers: int = 2
    scheduler: str | None = None

    def combos(self) -> list:
        """[(arm, mode, ExperimentConfig)] in arm order then mode order (validated)."""
        out = []
        for arm in self.arms:
            for mode in arm.modes:
                data = {**self.base, **arm.overrides, "network": arm.network, "methods": arm.methods,
                        "rates": arm.rates, "airspace_mode": mode, "out": self.out,
                        "workers": self.workers, "scheduler": self.scheduler}
                data.setdefault("tts", {"enabled": False})
                try:
                    cfg = make_config(data)
                except ExperimentError as exc:
                    i = self.arms.index(arm)
                    raise ExperimentError(f"arms[{i}] ({arm.name}, mode {mode}): {exc}") from None
                out.append((arm, mode, cfg))
        return out


class _ArmFile(pydantic.BaseModel):
    """One arm as the study file writes it (structure and types; make_config checks the values)."""

    model_config = pydantic.ConfigDict(extra="forbid", strict=True)
    name: Union[str, int]
    network: Union[str, dict]
    modes: list[Literal[AIRSPACE_MODES]]
    methods: list
    rates: list
    overrides: Optional[dict] = None


class _StudyFile(pydantic.BaseModel):
    """config/capacity-study.yaml: the study's keys (unknown keys refused, naming the path)."""

    model_config = pydantic.ConfigDict(extra="forbid", strict=True)
    base: Optional[dict] = None
    arms: Optional[list[_ArmFile]] = None
    instances: Optional[dict] = None
    out: str = "results/capacity"
    workers: Annotated[int, pydantic.Strict(False)] = 2  # "2" and 2.0 were accepted (int())
    scheduler: Optional[str] = None


def load_capacity_config(path, **overrides) -> CapacityConfig:
    """Read config/capacity-study.yaml; raises ExperimentError naming a bad field (its path, e.g.
    ``arms[2].modes[0]``) and the value."""
    data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    if not isinstance(data, dict):
        raise ExperimentError(f"{path}: expected a mapping")
    study = parse(_StudyFile, data, error=ExperimentError)
    for key in ("network", "methods", "rates", "airspace_mode", "out", "workers", "scheduler"):
        if key in (study.base or {}):
            raise ExperimentError(f"base.{key}: {study.base[key]!r} is set per arm (or by a flag), not in base")
    names = [a.name for a in study.arms or []]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ExperimentError(f"arms[{i}].name: {name!r} is used twice")
    arms = [Arm(str(a.name), a.network, list(a.modes), list(a.methods), list(a.rates),
                dict(a.overrides or {})) for a in study.arms or []]
    if not arms:
        raise ExperimentError(f"arms: {path} defines no arm")
    inst = {**INSTANCE_DEFAULTS, **(study.instances or {})}
    cfg = CapacityConfig(dict(study.base or {}), arms, inst, out=study.out, workers=study.workers,
                         scheduler=study.scheduler)
    cfg = replace(cfg, **{k: v for k, v in overrides.items() if v is not None})
    cfg.combos()  # validates every arm x mode
    return cfg


# -- the sweep ---------------------------------------------------------------------------------

def run_capacity_sweep(cfg: CapacityConfig, compute: bool = True, progress: bool = True) -> list:
    """Run every missing cell of every arm and mode (one pool for all, so the tail of one arm
    overlaps the next), then collect them; returns [(arm, mode, SweepResult)]."""
    combos = cfg.combos()
    cells_dir = Path(cfg.out) / "cells"
    cells_dir.mkdir(parents=True, exist_ok=True)
    todo = []  # (combo index, method, rate, seed)
    cfg_dicts, keys = {}, {}
    for ci, (_arm, _mode, ecfg) in enumerate(combos):
        done = run_sweep(ecfg, progress=False, compute=False)
        d = asdict(ecfg)
        for m, r, s in done.missing:
            cell = (ci, m, r, s)
            todo.append(cell)
            cfg_dicts[cell] = d
            keys[cell] = cell_key(cell_params(ecfg, m, r, s))
    # arms in the file's order (the first arm is the core of the study), seeds outermost within
    # an arm: an interrupted study has the first arms whole and the next one with whole seeds
    arm_rank = {ci: [a.name for a in cfg.arms].index(arm.name) for ci, (arm, _m, _c) in enumerate(combos)}
    todo.sort(key=lambda c: (arm_rank[c[0]], c[3], c[0]))
    if compute and todo:
        bar = None
        if progress:
            from tqdm import tqdm
            bar = tqdm(total=len(todo), desc="capacity cells", unit="cell")
        remote = cfg.scheduler not in (None, "local")
        if not remote and cfg.workers <= 1:
            for cell in todo:
                run_cell(cfg_dicts[cell], *cell[1:], str(cells_dir))
                if bar:
                    bar.update(1)
        else:
            from ..runner.dask_cluster import run_cells
            run_cells(None, todo, keys, cells_dir, run_cell, scheduler=cfg.scheduler or "local",
                      n_workers=min(cfg.workers, len(todo)), cell_configs=cfg_dicts,
                      on_done=(lambda _c, _cell: bar.update(1)) if bar else None)
        if bar:
            bar.close()
    return [(arm, mode, run_sweep(ecfg, progress=False, compute=False)) for arm, mode, ecfg in combos]


# -- tables ------------------------------------------------------------------------------------

def _network_label(network) -> str:
    if isinstance(network, dict):
        s = network.get("synthetic", {})
        return (f"synthetic {s.get('n_nodes')} nodes / {s.get('n_aerodromes')} vertiports"
                + (f" / {len(s['levels_m'])} levels" if s.get("levels_m") else ""))
    return str(network)


def tidy_tables(results: list) -> dict:
    """runs, epochs and flights rows of every cell, tagged with arm, mode and network."""
    runs, epochs, flights = [], [], []
    for arm, mode, sweep in results:
        for c in sweep.cells:
            s = c["summary"]
            tag = {"arm": arm.name, "mode": mode, "method": s["method"], "rate": s["rate"],
                   "seed": s["seed"]}
            delays = [f["departure_s"] - f["earliest_departure_s"] for f in c["flights"]
                      if f.get("earliest_departure_s") is not None]
            fl = c["flights"]
            peak = airborne_peak(fl, s["duration_s"])
            verts = [e["vertices"] for e in c["epochs"]]
            runs.append({**tag, "network": _network_label(arm.network),
                         "network_flown": _network_label(sweep.config.network),
                         "separation_model": sweep.config.separation_model,
                         "departure_slot_s": sweep.config.departure_slot_s,
                         **{k: v for k, v in s.items() if k not in ("method", "rate", "seed")},
                         "airborne_peak": peak,
                         "vertices_median": float(np.median(verts)) if verts else 0.0,
                         "vertices_max": int(max(verts)) if verts else 0,
                         "delay_mean_s": float(np.mean(delays)) if delays else float("nan"),
                         "length_mean_m": float(np.mean([f["length_m"] for f in fl])) if fl else float("nan"),
                         "pairs_checked": c["audit"].get("pairs_checked"),
                         "audit_model": c["audit"].get("separation_model", "sphere")})
            for e in c["epochs"]:
                epochs.append({**tag, **{k: e[k] for k in (
                    "epoch", "t_s", "requests_cum", "pending", "eligible", "candidates", "discarded",
                    "vertices", "edges", "selected", "approved_cum", "expired_cum", "active",
                    "objective", "solve_time_s", "planning_time_s", "proven_optimal", "fallback",
                    "backend_used")}})
            for f in fl:
                flights.append({**tag, "epoch": f["epoch"],
                                "delay_s": (f["departure_s"] - f["earliest_departure_s"]
                                            if f.get("earliest_departure_s") is not None else ""),
                                "length_m": round(float(f["length_m"]), 2),
                                "level_m": f["level_m"], "candidate_index": f["candidate_index"]})
    return {"runs": runs, "epochs": epochs, "flights": flights}


def airborne_peak(flights, duration_s: float, step_s: float = 5.0) -> int:
    """Most flights airborne at once, sampled every ``step_s`` [s]."""
    if not flights:
        return 0
    dep = np.sort(np.array([f["departure_s"] for f in flights]))
    arr = np.sort(np.array([f["arrival_s"] for f in flights]))
    grid = np.arange(0.0, duration_s + step_s, step_s)
    return int((np.searchsorted(dep, grid, "right") - np.searchsorted(arr, grid, "left")).max())


# -- solve time and gap against instance size ----------------------------------------------------

def source_instances(cfg: CapacityConfig) -> tuple[list, str]:
    """Re-run the instance study's source cell with an observer and keep every MWIS instance
    (the cells keep none above corpus_max_vertices); returns ([(epoch, MwisProblem)], label)."""
    from ..runner.network_spec import load_network_spec
    from ..runner.scenario import problem_from_report, run_scenario

    src = cfg.instances.get("source")
    if not src:
        return [], ""
    match = [ecfg for arm, mode, ecfg in cfg.combos() if arm.name == src["arm"] and mode == src["mode"]]
    if not match:
        raise ExperimentError(f"instances.source: no arm {src['arm']!r} in mode {src['mode']!r}")
    ecfg = match[0]
    found = []

    def keep(t_s, epoch, submitted, refused, result):
        problem = problem_from_report(result.report)
        if problem is not None:
            found.append((epoch, problem))

    run_scenario(load_network_spec(ecfg.network), src["method"], src["rate"], src["seed"],
                 ecfg.duration_s, ecfg, observer=keep)
    label = f"{src['arm']} / {src['mode']} / {src['method']} / rate {src['rate']} / seed {src['seed']}"
    return found, label


def sample_by_size(found: list, bins: list, per_bin: int, seed: int) -> list:
    """Up to ``per_bin`` instances per size bin [bins[i], bins[i+1]) (seeded), smallest bin first."""
    rng = np.random.default_rng(seed)
    out = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        pool = [x for x in found if lo <= x[1].n < hi]
        if not pool:
            continue
        pick = rng.choice(len(pool), size=min(per_bin, len(pool)), replace=False)
        out.extend(pool[i] for i in sorted(pick))
    return out


def instance_study(cfg: CapacityConfig) -> list:
    """Every backend on the sampled instances with the same limit through a SolveService (the
    deadline holds for every backend); rows with objective, wall time, proven, gap to best known."""
    from uam_solvers.executor import SolveService
    from uam_solvers.registry import get_backend

    ic = cfg.instances
    found, label = source_instances(cfg)
    sample = sample_by_size(found, list(ic["bins"]), int(ic["per_bin"]), int(ic["seed"]))
    backends = [b for b in ic["backends"] if get_backend(b).available()[0]]
    rows = []
    limit = float(ic["time_limit_s"])
    with SolveService(max_time_limit_s=max(limit, float(ic["best_known_limit_s"]))) as svc:
        for epoch, prob in sample:
            best = -math.inf
            inst_rows = []
            for b in backends:
                t0 = time.perf_counter()
                res = svc.solve(prob, backend=b, time_limit_s=limit, seed=int(ic["seed"]))
                wall = time.perf_counter() - t0
                best = max(best, res.objective)
                inst_rows.append({"source": label, "epoch": epoch, "vertices": prob.n,
                                  "edges": int(len(prob.all_edges())), "backend": b,
                                  "time_limit_s": limit, "objective": res.objective,
                                  "wall_s": wall, "proven_optimal": bool(res.proven_optimal),
                                  "fallback": bool(res.fallback)})
            proven = any(r["proven_optimal"] for r in inst_rows)
            if not proven and ic.get("best_known_limit_s"):
                ref = svc.solve(prob, backend="auto", time_limit_s=float(ic["best_known_limit_s"]),
                                seed=int(ic["seed"]))
                best = max(best, ref.objective)
                proven = bool(ref.proven_optimal)
            for r in inst_rows:
                r["best_known"] = best
                r["best_proven"] = proven
                r["gap_pct"] = 100.0 * (best - r["objective"]) / best if best > 0 else 0.0
            rows.extend(inst_rows)
    return rows


# -- the whole study ---------------------------------------------------------------------------

def run_capacity_study(cfg: CapacityConfig, compute: bool = True, progress: bool = True,
                       instances: bool = True, report: bool = True) -> dict:
    t0 = time.perf_counter()
    out = Path(cfg.out)
    results = run_capacity_sweep(cfg, compute=compute, progress=progress)
    missing = sum(len(sw.missing) for _a, _m, sw in results)
    tables = tidy_tables(results)
    write_csv(out / "runs.csv", tables["runs"])
    write_csv(out / "epochs.csv.gz", tables["epochs"])
    write_csv(out / "flights.csv.gz", tables["flights"])
    inst_rows = []
    if instances and compute:
        inst_rows = instance_study(cfg)
        write_csv(out / "instances.csv", inst_rows)
    elif (out / "instances.csv").exists():
        from ..reports.capacity_report import read_csv
        inst_rows = read_csv(out / "instances.csv")
    inputs = {"format": FORMAT, "config": {"base": cfg.base, "instances": cfg.instances,
                                           "arms": [asdict(a) for a in cfg.arms]},
              "machine": machine_info(), "missing_cells": missing,
              "sweep_wall_s": time.perf_counter() - t0,
              "cells": sum(len(sw.cells) for _a, _m, sw in results),
              "computed": sum(len(sw.computed) for _a, _m, sw in results)}
    (out / "report_inputs.json").write_text(json.dumps(inputs, indent=1, default=str) + "\n")
    paths = {}
    if report:
        from ..reports.capacity_report import write_capacity_report
        paths = write_capacity_report(out)
    return {"results": results, "tables": tables, "instances": inst_rows, "missing": missing,
            "report": paths, "wall_s": time.perf_counter() - t0}


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="capacity_study", description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="config/capacity-study.yaml")
    ap.add_argument("--out", default=None)
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None, help="local or tcp://HOST:8786")
    ap.add_argument("--seeds", default=None, help="override base.seeds (a count or a comma list)")
    ap.add_argument("--duration", type=float, default=None, help="override base.duration_s")
    ap.add_argument("--no-compute", action="store_true", help="only collect finished cells")
    ap.add_argument("--no-instances", action="store_true", help="skip the instance-size study")
    ap.add_argument("--instances-only", action="store_true",
                    help="only the instance-size study (instances.csv; re-runs its source cell)")
    ap.add_argument("--no-progress", action="store_true")
    args = ap.parse_args(argv)
    try:
        cfg = load_capacity_config(args.config, out=args.out, workers=args.workers,
                                   scheduler=args.scheduler)
        if args.seeds is not None:
            cfg.base["seeds"] = args.seeds
        if args.duration is not None:
            cfg.base["duration_s"] = args.duration
        cfg.combos()
    except ExperimentError as exc:
        print(f"capacity_study: {exc}", file=sys.stderr)
        return 2
    if args.instances_only:
        rows = instance_study(cfg)
        Path(cfg.out).mkdir(parents=True, exist_ok=True)
        write_csv(Path(cfg.out) / "instances.csv", rows)
        print(f"instance study: {len(rows)} rows in {Path(cfg.out) / 'instances.csv'}")
        return 0
    res = run_capacity_study(cfg, compute=not args.no_compute, progress=not args.no_progress,
                             instances=not args.no_instances)
    print(f"capacity study: {sum(len(sw.cells) for _a, _m, sw in res['results'])} cells "
          f"({res['missing']} missing), {len(res['instances'])} instance rows, "
          f"wall {res['wall_s']:.0f} s; report: {res['report'].get('report', '-')}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
