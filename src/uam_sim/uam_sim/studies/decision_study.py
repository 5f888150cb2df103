"""The decision study: where does optimisation matter, with power, matched shadow
solves, objectives, horizon and contention.

    python -m uam_sim.decision_study --config config/decision-study.yaml --stage e0
    python -m uam_sim.decision_study --config config/decision-study.yaml --stage pilot
    python -m uam_sim.decision_study --config config/decision-study.yaml --stage full
    python -m uam_sim.decision_report docs/decision-study        # the report from the tables

Successor of the capacity study (``uam_sim.studies.capacity_study``), and built on it: every run-level
cell is an arm of a :class:`uam_sim.studies.capacity_study.CapacityConfig` and runs through
:func:`uam_sim.studies.capacity_study.run_capacity_sweep` (the sweep's cells, keys, resumption and Dask
cluster: ``--scheduler tcp://HOST:8786``, local by default). The E0 shadow solves run on the same
cluster through :func:`uam_sim.runner.dask_cluster.run_cells`, one resumable cell per (reference run,
solver).

Stages:

- ``e0``: matched shadow solves. Each reference run (``e0.runs``: airspace mode, network,
  objective, rate, seed) is re-run with an observer that keeps every epoch's MWIS instance; a
  seeded sample per size bin is solved by each solver in ``e0.backends`` at ``e0.time_limit_s``
  (first-fit is :func:`uam_planner.first_fit.first_fit_select` on the instance, the planner's own
  baseline; the rest through :class:`uam_solvers.executor.SolveService`, whose deadline holds
  for every backend) and by a long reference (``e0.reference``, e.g. exact for 30 s). One row per
  (instance, solver) in ``e0.csv.gz``; ``--backends`` runs a subset now and the rest later.
- ``pilot``: every experiment's cells at the pilot's seeds; the report's power table then says,
  per primary comparison, how many seeds a 95 % CI half-width of ``power.half_width_pct`` % of
  approvals needs (:func:`seeds_needed`).
- ``full``: every experiment at the seeds its primary comparisons need (from the pilot's rows in
  ``runs.csv``), capped at ``power.max_seeds`` (the report then states the CI that cap gives).

Outcomes are measured in a steady-state window computed from the data: MSER-5 (White 1997;
batch means of 5 epochs, truncation restricted to the first half of the run) on the mean over
the reference method's seeds of the number of flights in the air per epoch, per experiment cell
(the same window for every method of a cell, so pairs stay paired). A request counts in the
window when its earliest departure is at or after the truncation time and its latest departure
at or before the run's end (``uam_sim.world.flights.run_metrics``'s filter).

Outputs in ``--out`` (default docs/decision-study): ``runs.csv`` (one row per run: outcomes in
the window, solve bounds, the commit that ran it), ``windows.csv`` (the truncation per cell),
``e0.csv.gz``, ``study.json`` (the declared experiments and comparisons, copied from the config
before any run) and, from the report, ``REPORT.md``, ``comparisons.csv`` and ``power.csv``.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import math
import sys
import time
from dataclasses import asdict
from pathlib import Path
from typing import Annotated, Literal, Optional, Union

import numpy as np
import pydantic
import yaml

from .capacity_study import Arm, CapacityConfig, run_capacity_sweep
from ..runner.experiment_config import AIRSPACE_MODES, ExperimentError, make_config
from ..runner.files import write_csv, write_json_atomic

FORMAT = "uam-decision-study/1"
E0_FORMAT = "uam-decision-e0-cell/1"
STAGES = ("e0", "pilot", "full", "tables")
METRICS = ("approved_ss", "expired_ss", "requests_ss", "approval_rate_ss", "delay_mean_s",
           "delay_p95_s", "detour_mean_m", "detour_mean_pct", "jain_index", "weight_sum_ss")
FIRSTFIT = "firstfit"
REFERENCE = "reference"


# -- configuration -------------------------------------------------------------------------------
# The study file's schema (pydantic, style: uam_sim.runner.experiment_config, capacity_study):
# structure, types and ranges; a refusal names the path and the value (``experiments[0].primary[0]
# .metric: 'joy' is not one of ...``). What needs two fields at once (a term's ``where`` keys are
# the experiment's varied keys; a contrast's signs sum to 0) is checked after, in the same style.

_Str = Annotated[str, pydantic.Strict()]
_Int = Annotated[int, pydantic.Strict()]
_Num = Annotated[float, pydantic.Strict()]  # an int is a number too; True and "5" are not
_Rate = Union[_Int, _Num]  # kept as given (20 stays the int 20: a cell's key hashes its label)
_Pos = Annotated[float, pydantic.Strict(), pydantic.Field(gt=0)]
_Network = Union[_Str, dict]


class _Model(pydantic.BaseModel):
    model_config = pydantic.ConfigDict(extra="forbid", strict=True, allow_inf_nan=False)


class _Term(_Model):
    sign: Literal[1, -1]
    method: _Str
    where: Optional[dict] = None


class _Comparison(_Model):
    name: Union[_Str, _Int]
    metric: Literal[METRICS]
    terms: Annotated[list[_Term], pydantic.Field(min_length=2)]
    per: Literal["cell", "pooled"] = "cell"
    scale: Optional[_Num] = None  # accepted before the schema (unused)


class _Cell(_Model):
    name: Union[_Str, _Int]
    network: _Network
    mode: Literal[AIRSPACE_MODES]
    rates: Annotated[list[_Rate], pydantic.Field(min_length=1)]
    overrides: Optional[dict] = None


class _Experiment(_Model):
    name: Union[_Str, _Int]
    question: _Str = ""
    cells: Annotated[list[_Cell], pydantic.Field(min_length=1)]
    vary: dict[_Str, Annotated[list, pydantic.Field(min_length=1)]] = {}
    methods: Annotated[list[_Str], pydantic.Field(min_length=1)]
    primary: Annotated[list[_Comparison], pydantic.Field(min_length=1)]
    secondary: list[_Comparison] = []
    overrides: Optional[dict] = None


class _Power(_Model):
    pilot_seeds: Annotated[int, pydantic.Strict(), pydantic.Field(ge=2)] = 3
    half_width_pct: _Pos = 1.0
    max_seeds: Annotated[int, pydantic.Strict(), pydantic.Field(ge=2)] = 30
    level: Annotated[float, pydantic.Strict(), pydantic.Field(gt=0, lt=1)] = 0.95
    #: the power of the minimal detectable effect the report states at the seeds run
    mde_power: Annotated[float, pydantic.Strict(), pydantic.Field(gt=0, lt=1)] = 0.8


class _SteadyState(_Model):
    method: Literal["mser5", "none"] = "mser5"
    series: _Str = "active"
    reference_method: _Str = FIRSTFIT


class _Reference(_Model):
    backend: _Str = "exact"
    time_limit_s: _Pos = 30.0


class _E0Run(_Model):
    name: _Str
    network: _Network
    mode: Literal[AIRSPACE_MODES]
    objective: Optional[_Str] = None
    rate: _Rate
    seed: _Int
    overrides: Optional[dict] = None


class _E0(_Model):
    runs: list[_E0Run] = []
    backends: Annotated[list[_Str], pydantic.Field(min_length=1)] = [
        FIRSTFIT, "greedy", "auto", "exact", "sa", "tabu", "qpu-emulator"]
    time_limit_s: _Pos = 1.0
    reference: _Reference = _Reference()
    bins: Annotated[list[_Int], pydantic.Field(min_length=2)] = [
        1, 8, 16, 32, 64, 128, 256, 512, 1024, 4096, 100000]
    per_bin: Optional[Annotated[int, pydantic.Strict(), pydantic.Field(ge=1)]] = 4
    method: _Str = FIRSTFIT
    duration_s: Optional[_Pos] = None
    seed: _Int = 0


class _StudyFile(_Model):
    """config/decision-study.yaml (docs/decision-study/README.md)."""

    out: _Str = "docs/decision-study"
    cells: _Str = "results/decision-study"
    workers: Annotated[int, pydantic.Strict(), pydantic.Field(ge=1)] = 2
    scheduler: Optional[_Str] = None
    base: dict = {}
    power: _Power = _Power()
    steady_state: _SteadyState = _SteadyState()
    e0: _E0 = _E0()
    experiments: Annotated[list[_Experiment], pydantic.Field(min_length=1)]
    #: experiments whose first-fit cell is shared across the varied objective (first-fit's
    #: decisions do not depend on the weights: test_decision_study guards it); see
    #: :func:`shared_firstfit`
    share_firstfit_across: list[_Str] = []


def _check_comparison(c: _Comparison, where: str, variants: dict, methods: list) -> dict:
    """A comparison of the file as the study uses it; its terms checked against the experiment."""
    terms = []
    for j, t in enumerate(c.terms):
        tw = f"{where}.terms[{j}]"
        if t.method not in methods:
            raise ExperimentError(f"{tw}.method: {t.method!r} is not one of the experiment's "
                                  f"methods {methods}")
        sel = dict(t.where or {})
        for k, v in sel.items():
            if k not in variants and k not in ("rate", "cell"):
                raise ExperimentError(f"{tw}.where.{k}: not a varied key ({sorted(variants)}), "
                                      f"'rate' or 'cell'")
            if k in variants and v not in variants[k]:
                raise ExperimentError(f"{tw}.where.{k}: {v!r} is not one of {variants[k]}")
        terms.append({"sign": int(t.sign), "method": t.method, "where": sel})
    if sum(t["sign"] for t in terms) != 0:
        raise ExperimentError(f"{where}.terms: signs must sum to 0 (a contrast), got "
                              f"{[t['sign'] for t in terms]}")
    return {"name": str(c.name), "metric": c.metric, "terms": terms, "per": c.per}


def load_decision_config(path) -> dict:
    """Read config/decision-study.yaml into a plain dict (validated by :class:`_StudyFile`;
    errors name the field's path and the value)."""
    from uam_contract.validation import parse
    data = yaml.safe_load(Path(path).read_text(encoding="utf-8")) or {}
    if not isinstance(data, dict):
        raise ExperimentError(f"{path}: expected a mapping")
    study = parse(_StudyFile, data, error=ExperimentError)
    exps = []
    for i, e in enumerate(study.experiments):
        w = f"experiments[{i}]"
        variants = {str(k): list(v) for k, v in e.vary.items()}
        cells = [{"name": str(c.name), "network": c.network, "mode": c.mode, "rates": list(c.rates),
                  "overrides": dict(c.overrides or {})} for c in e.cells]
        primary = [_check_comparison(c, f"{w}.primary[{j}]", variants, e.methods)
                   for j, c in enumerate(e.primary)]
        secondary = [_check_comparison(c, f"{w}.secondary[{j}]", variants, e.methods)
                     for j, c in enumerate(e.secondary)]
        exps.append({"name": str(e.name), "question": e.question, "cells": cells,
                     "vary": variants, "methods": list(e.methods),
                     "overrides": dict(e.overrides or {}),
                     "primary": primary, "secondary": secondary})
    names = [e["name"] for e in exps]
    for i, name in enumerate(names):
        if name in names[:i]:
            raise ExperimentError(f"experiments[{i}].name: {name!r} is used twice")
    for j, name in enumerate(study.share_firstfit_across):
        if name not in names:
            raise ExperimentError(f"share_firstfit_across[{j}]: {name!r} is not an experiment "
                                  f"({names})")
        e = exps[names.index(name)]
        if FIRSTFIT not in e["methods"] or set(e["vary"]) != {"objective"}:
            raise ExperimentError(f"share_firstfit_across[{j}]: {name!r} must run {FIRSTFIT!r} "
                                  f"and vary only 'objective' (it varies {sorted(e['vary'])})")
    e0 = study.e0.model_dump()
    e0["runs"] = [{k: v for k, v in r.items() if v is not None} for r in e0["runs"]]
    cfg = {"format": FORMAT, "base": dict(study.base), "power": study.power.model_dump(),
           "steady_state": study.steady_state.model_dump(), "e0": e0, "experiments": exps,
           "out": study.out, "cells": study.cells, "workers": study.workers,
           "scheduler": study.scheduler, "share_firstfit_across": list(study.share_firstfit_across)}
    for key in ("network", "methods", "rates", "airspace_mode", "out", "workers", "scheduler",
                "seeds"):
        if key in cfg["base"]:
            raise ExperimentError(f"base.{key}: {cfg['base'][key]!r} is set per cell (or by the "
                                  f"study), not in base")
    arms(cfg, [0, 1])  # validates every cell x variant through make_config
    return cfg


def _variant_list(vary: dict) -> list:
    """Every combination of the varied keys, in the file's order (the last key fastest)."""
    out = [{}]
    for k, vals in vary.items():
        out = [{**v, k: x} for v in out for x in vals]
    return out


def variant_label(v: dict) -> str:
    return ",".join(f"{k}={v[k]}" for k in v) or "-"


def shares_firstfit(cfg: dict, e: dict) -> bool:
    """True when ``e``'s first-fit cells are shared across its objectives: first-fit ignores the
    weights (``uam_planner.first_fit``: vertices in request order, candidates in candidate order),
    so its decisions are the same under every objective; only each flight's recorded weight
    differs. The first variant's first-fit cell then stands for every variant (its
    ``weight_sum_ss`` is kept only in the row of its own objective). Guarded by
    test_decision_study's test that first-fit flies the same flights under every objective."""
    return e["name"] in cfg.get("share_firstfit_across", ()) and FIRSTFIT in e["methods"]


def primary_scope(e: dict) -> tuple[set, set | None, list]:
    """What the experiment's primary comparisons read: (methods, rates or None for every rate,
    variants [dicts] or [] for every variant) -- the cells a pilot needs for their paired SD."""
    methods = {t["method"] for c in e["primary"] for t in c["terms"]}
    terms = [t for c in e["primary"] for t in c["terms"]]
    rates = ({float(t["where"]["rate"]) for t in terms}
             if all("rate" in t["where"] for t in terms) else None)
    variants = [v for v in _variant_list(e["vary"])
                if any(all(v.get(k) == x for k, x in t["where"].items() if k in v) for t in terms)]
    return methods, rates, variants


def arms(cfg: dict, seeds, experiments=None, primary_only: bool = False) -> list:
    """[(experiment, cell, variant, Arm)] of the chosen experiments at ``seeds`` (with
    :func:`shares_firstfit`, first-fit only in each cell's first variant; with ``primary_only``
    only the methods, rates and variants the primary comparisons read, :func:`primary_scope`)."""
    out = []
    for e in cfg["experiments"]:
        if experiments and e["name"] not in experiments:
            continue
        p_methods, p_rates, p_variants = primary_scope(e)
        for c in e["cells"]:
            rates = [r for r in c["rates"] if not primary_only or p_rates is None
                     or float(r) in p_rates]
            for vi, v in enumerate(_variant_list(e["vary"])):
                ov = {**e["overrides"], **c["overrides"], **v, "seeds": list(seeds)}
                methods = [m for m in e["methods"]
                           if not (vi and m == FIRSTFIT and shares_firstfit(cfg, e))]
                if primary_only:
                    if v in p_variants:
                        keep = p_methods
                    elif vi == 0 and shares_firstfit(cfg, e):
                        keep = p_methods & {FIRSTFIT}  # the shared cell the primary reads
                    else:
                        keep = set()
                    methods = [m for m in methods if m in keep]
                    if not methods or not rates:
                        continue
                arm = Arm(f"{e['name']}/{c['name']}/{variant_label(v)}", c["network"], [c["mode"]],
                          methods, rates, ov)
                data = {**cfg["base"], **ov, "network": c["network"], "methods": arm.methods,
                        "rates": arm.rates, "airspace_mode": c["mode"]}
                try:
                    make_config(data)
                except ExperimentError as exc:
                    raise ExperimentError(f"{arm.name}: {exc}") from None
                out.append((e, c, v, arm))
    return out


def capacity_config(cfg: dict, seeds, out: Path, experiments=None,
                    primary_only: bool = False) -> tuple[CapacityConfig, list]:
    entries = arms(cfg, seeds, experiments, primary_only=primary_only)
    cc = CapacityConfig(base=dict(cfg["base"]), arms=[a for *_x, a in entries],
                        instances={"source": None}, out=str(out), workers=cfg["workers"],
                        scheduler=cfg["scheduler"])
    return cc, entries


from ..reports.stats import holm, mser_truncation, seeds_needed  # noqa: E402,F401  (the study's statistics)

# -- the tables --------------------------------------------------------------------------------

def windows(records: list, ss: dict, epoch_s: float) -> dict:
    """(experiment, cell, variant label, rate) -> (truncation epoch, warm-up [s], reference
    method, the variant's own truncation epoch): MSER-5 on the mean over the reference method's
    seeds of the epochs' ``ss['series']`` per variant, then one window per experiment cell and
    rate, the latest of its variants' truncations, which every variant uses. A comparison across
    variants (E2's horizons) then counts the same requests in both arms: with a window per
    variant, E2's pilot compared approvals over 3,750 s (H = 1) with approvals over 4,050 s
    (H = 5), 8 % more requests in one arm."""
    return _windows([((e["name"], c["name"], variant_label(v), cell["summary"]["rate"]),
                      cell["summary"]["method"], cell["epochs"]) for e, c, v, cell in records], ss)


def windows_from_epoch_rows(rows: list, ss: dict) -> dict:
    """:func:`windows` from the committed per-epoch series (``epochs.csv.gz``, rows of
    :func:`epoch_rows`): the same windows, so that a reader re-derives windows.csv."""
    runs: dict = {}
    for r in rows:
        key = (r["experiment"], r["cell"], r["variant"], r["rate"], r["method"], r["seed"])
        runs.setdefault(key, []).append(r)
    items = []
    for (en, cn, vl, rate, method, _seed), eps in runs.items():
        eps = sorted(eps, key=lambda r: int(r["epoch"]))
        items.append(((en, cn, vl, rate), method,
                      [{ss["series"]: float(r[ss["series"]]), "t_s": float(r["t_s"])}
                       for r in eps]))
    return _windows(items, ss)


def _windows(items: list, ss: dict) -> dict:
    """:func:`windows` on [((experiment, cell, variant label, rate), method, epochs)]."""
    groups: dict = {}
    for key, method, epochs in items:
        groups.setdefault(key, {}).setdefault(method, []).append(epochs)
    out = {}
    for key, by_method in groups.items():
        ref_method = ss["reference_method"] if ss["reference_method"] in by_method \
            else sorted(by_method)[0]
        ref = by_method[ref_method]
        if ss["method"] == "none":
            out[key] = (0, 0.0, ref_method)
            continue
        n = min(len(eps) for eps in ref)
        mean = np.mean([[float(ep[ss["series"]]) for ep in eps[:n]] for eps in ref], axis=0)
        d = mser_truncation(mean)
        out[key] = (d, float(ref[0][d]["t_s"]) if n else 0.0, ref_method)
    latest: dict = {}
    for (en, cn, _vl, rate), w in out.items():
        k = (en, cn, rate)
        if k not in latest or w[1] > latest[k][1]:
            latest[k] = w
    return {key: (*latest[(key[0], key[1], key[3])][:2], w[2], w[0]) for key, w in out.items()}


def epoch_rows(records: list) -> list:
    """One row per epoch of every run (``epochs.csv.gz``): the run's experiment, cell, variant,
    method, rate and seed, then the epoch's own fields (``active``, the series the windows are
    chosen on, among them), from which the windows re-derive (:func:`windows_from_epoch_rows`)."""
    rows = []
    for e, c, v, cell in records:
        s = cell["summary"]
        tag = {"experiment": e["name"], "cell": c["name"], "variant": variant_label(v),
               "method": s["method"], "rate": s["rate"], "seed": s["seed"]}
        rows.extend({**tag, "epoch": k, **ep} for k, ep in enumerate(cell["epochs"]))
    return rows


def run_row(e, c, v, cell, window, time_limit_s: float) -> dict:
    """One run's outcomes in its steady-state window, its solve bounds and its commit."""
    from uam_solvers.executor import DEFAULT_MARGIN_S

    from ..world.flights import run_metrics
    s = cell["summary"]
    d, warm_s = window[0], window[1]
    end = float(s["duration_s"])
    reqs = cell.get("requests") or []
    m = run_metrics(cell["flights"], reqs, warmup_s=warm_s, end_s=end)

    def inside(r):
        return float(r["earliest_departure_s"]) >= warm_s and float(r["latest_departure_s"]) <= end
    ids_in = {r["request_id"] for r in reqs if inside(r)}
    fl_in = [f for f in cell["flights"] if f["request_id"] in ids_in]
    refused = {rid for rid, _reason in cell.get("rejections") or []}
    approved = len(fl_in)
    n_in = len(ids_in)
    epochs = cell["epochs"]
    solve = [float(ep["solve_time_s"]) for ep in epochs if ep["vertices"] > 0]
    ran_under = s.get("objective", "paper")
    objective = v.get("objective", ran_under)
    row = {"experiment": e["name"], "cell": c["name"], "variant": variant_label(v), **v,
           "mode": c["mode"], "method": s["method"], "rate": s["rate"], "seed": s["seed"],
           "objective": objective,
           # a shared first-fit cell (shares_firstfit): the objective whose run it is
           "ran_under": ran_under,
           "duration_s": end, "warmup_epoch": d, "warmup_s": warm_s,
           "requests_ss": n_in, "approved_ss": approved,
           "expired_ss": n_in - approved - len(ids_in & refused),
           "refused_ss": len(ids_in & refused),
           "approval_rate_ss": approved / n_in if n_in else float("nan"),
           # the flights' weights are those of the objective the cell ran under
           "weight_sum_ss": (float(sum(float(f["weight"]) for f in fl_in))
                             if objective == ran_under else float("nan")),
           "approved": s["approved"], "expired": s["expired"], "requests": s["requests"],
           "delay_mean_s": m.get("delay_mean_s", float("nan")),
           "delay_p95_s": m.get("delay_p95_s", float("nan")),
           "detour_mean_m": m.get("detour_mean_m", float("nan")),
           "detour_mean_pct": m.get("detour_mean_pct", float("nan")),
           "jain_index": m.get("jain_index", float("nan")),
           **{k: val for k, val in m.items() if k.startswith("delay_p95_s_prio")},
           "losses": s.get("losses"), "min_separation_m": s.get("min_separation_m"),
           "time_limit_s": time_limit_s,
           "mwis_epochs": len(solve),
           "solve_time_median_s": float(np.median(solve)) if solve else float("nan"),
           "solve_time_max_s": max(solve) if solve else float("nan"),
           # the bound as stated: limit + the executor's kill margin; over_limit is looser
           "over_limit": sum(t > time_limit_s for t in solve),
           "overruns": sum(t > time_limit_s + DEFAULT_MARGIN_S for t in solve),
           "fallbacks": s.get("fallbacks", 0),
           "proven_optimal_share": s.get("proven_optimal_share", float("nan")),
           "wall_s": s.get("wall_s"), "commit": cell.get("ran_at", "unrecorded"),
           "code_version": cell.get("code_version", "unrecorded"),
           # the machine's load before / after the run and the run's CPU (sweep.run_cell; cells
           # from before they were recorded: empty)
           "load_before": (cell.get("load") or [None, None])[0],
           "load_after": (cell.get("load") or [None, None])[1],
           "cpu_s": cell.get("cpu_s")}
    return row


def tables(cfg: dict, results: list, entries: list) -> tuple[list, list, list]:
    """runs.csv, windows.csv and epochs.csv.gz rows from the swept cells."""
    by_arm = {a.name: (e, c, v) for e, c, v, a in entries}
    records = []
    limits = {}
    for arm, _mode, sweep in results:
        e, c, v = by_arm[arm.name]
        limits[arm.name] = sweep.config.time_limit_s
        records += [(e, c, v, cell) for cell in sweep.cells]
    # a shared first-fit cell (shares_firstfit) stands for every variant of its cell
    for e, c, v, a in entries:
        if shares_firstfit(cfg, e) and FIRSTFIT not in a.methods:
            first = _variant_list(e["vary"])[0]
            records += [(e, c, v, cell) for e2, c2, v2, cell in list(records)
                        if e2 is e and c2 is c and v2 == first
                        and cell["summary"]["method"] == FIRSTFIT]
    epoch_s = results[0][2].config.epoch_s if results else 30.0
    win = windows(records, cfg["steady_state"], epoch_s)
    rows = []
    for e, c, v, cell in records:
        key = (e["name"], c["name"], variant_label(v), cell["summary"]["rate"])
        arm_name = f"{e['name']}/{c['name']}/{variant_label(v)}"
        rows.append(run_row(e, c, v, cell, win[key], limits[arm_name]))
    wrows = [{"experiment": k[0], "cell": k[1], "variant": k[2], "rate": k[3],
              "method": cfg["steady_state"]["method"], "series": cfg["steady_state"]["series"],
              "reference_method": w[2], "variant_truncation_epoch": w[3],
              "truncation_epoch": w[0], "warmup_s": w[1]}
             for k, w in sorted(win.items(), key=lambda kv: tuple(map(str, kv[0])))]
    return rows, wrows, epoch_rows(records)


# -- E0: matched shadow solves --------------------------------------------------------------------

def e0_experiment_config(cfg: dict, run: dict) -> dict:
    data = {**cfg["base"], **(run.get("overrides") or {}), "network": run["network"],
            "methods": [cfg["e0"]["method"]], "rates": [run["rate"]],
            "airspace_mode": run["mode"], "seeds": [int(run["seed"])]}
    if run.get("objective"):
        data["objective"] = run["objective"]
    if cfg["e0"].get("duration_s"):
        data["duration_s"] = float(cfg["e0"]["duration_s"])
    data.setdefault("tts", {"enabled": False})
    return asdict(make_config(data))


def e0_key(conf: dict, solver: str) -> str:
    """The E0 cell's key: its run's parameters, solver and sample, and the code version (a cell
    of other code is stale: never reused, never deleted)."""
    from ..runner.sweep import cell_params, code_version
    ecfg = make_config(conf["experiment"])
    params = {"format": E0_FORMAT, "run": cell_params(ecfg, conf["method"], conf["rate"],
                                                       conf["seed"]),
              "solver": solver, "sample": {k: conf["e0"][k] for k in ("bins", "per_bin", "seed")},
              "limit": (conf["e0"]["reference"] if solver == REFERENCE else conf["e0"]["time_limit_s"])}
    digest = hashlib.sha256(json.dumps(params, sort_keys=True, default=str).encode()).hexdigest()[:16]
    return f"e0_{conf['name']}_{solver}_{digest}_c{code_version()}"


def record_instances(conf: dict) -> list:
    """Re-run the reference run with an observer; [(epoch, t_s, MwisProblem)] of every epoch."""
    from ..runner.network_spec import load_network_spec
    from ..runner.scenario import problem_from_report, run_scenario
    ecfg = make_config(conf["experiment"])
    found = []

    def keep(t_s, epoch, _submitted, _refused, result):
        problem = problem_from_report(result.report)
        if problem is not None:
            found.append((epoch, t_s, problem))
    run_scenario(load_network_spec(ecfg.network), conf["method"], conf["rate"], conf["seed"],
                 ecfg.duration_s, ecfg, observer=keep)
    return found


def e0_sample(found: list, bins: list, per_bin, seed: int) -> list:
    """Up to ``per_bin`` instances per size bin [bins[i], bins[i+1]) (seeded; None: all)."""
    rng = np.random.default_rng(seed)
    out = []
    for lo, hi in zip(bins[:-1], bins[1:]):
        pool = [x for x in found if lo <= x[2].n < hi]
        if per_bin is None or len(pool) <= int(per_bin):
            out.extend(pool)
            continue
        pick = rng.choice(len(pool), size=int(per_bin), replace=False)
        out.extend(pool[i] for i in sorted(pick))
    return sorted(out, key=lambda x: x[0])


def _wait_for_workers(svc, n: int = 2, timeout_s: float = 60.0) -> None:
    """Wait (a condition, polled) until ``svc``'s ``n`` workers are alive: after a backend that
    overran was killed, its replacement starts in the background, and on a loaded machine the
    next solve would otherwise fall back "all busy", a cost of the service's respawn, not of the
    solver E0 measures. The run-level cells keep the service's real behaviour."""
    end = time.perf_counter() + timeout_s
    while len(svc.worker_pids()) < n and time.perf_counter() < end:
        time.sleep(0.05)


def e0_solve_rows(sample: list, solver: str, backend: str, limit: float, seed: int) -> list:
    """One row per instance of ``sample`` ([(epoch, t_s, MwisProblem)]) solved by ``backend``
    within ``limit`` [s] (``solver``: the row's label, e.g. ``reference``): first-fit is
    :func:`uam_planner.first_fit.first_fit_select` on the instance, in process; every other
    backend goes through one :class:`uam_solvers.executor.SolveService`, whose deadline holds.
    ``wall_s`` is the answer's wall time [s], the service's wait for its workers left out."""
    from uam_planner.first_fit import first_fit_select
    from uam_solvers.executor import SolveService
    rows = []
    with SolveService(max_time_limit_s=max(limit, 1.0)) as svc:
        for epoch, t_s, prob in sample:
            t0 = time.perf_counter()
            if backend == FIRSTFIT:
                ans = first_fit_select(prob.weights, prob.all_edges(), [g.tolist() for g in prob.groups])
                sel = np.asarray(ans.selected, dtype=int)
                obj, proven, fb = float(prob.weights[sel].sum()), False, False
            else:
                _wait_for_workers(svc)
                t0 = time.perf_counter()
                res = svc.solve(prob, backend=backend, time_limit_s=limit, seed=seed)
                sel = np.asarray(res.selected, dtype=int)
                obj, proven, fb = float(res.objective), bool(res.proven_optimal), bool(res.fallback)
            wall = time.perf_counter() - t0
            rows.append({"epoch": int(epoch), "t_s": float(t_s), "vertices": int(prob.n),
                         "edges": int(len(prob.all_edges())), "solver": solver,
                         "backend": backend, "time_limit_s": limit, "objective": round(obj, 9),
                         "count": int(sel.size), "proven_optimal": proven, "fallback": fb,
                         "wall_s": wall})
    return rows


RECORD = "instances"  # the E0 cell that re-runs a reference run and keeps its sampled instances


def e0_cell(conf: dict, solver: str, _rate, _seed, cells_dir: str) -> dict:
    """One E0 cell, written to ``cells_dir/<key>.json`` (top-level, so a Dask worker can run it):
    ``solver == RECORD``: re-run the reference run and keep its sampled instances (weights,
    edges, groups); else: solve ``conf["sample"]`` (the instances of that run's RECORD cell,
    sent with the task, so workers need no shared file system) with ``solver``."""
    from uam_solvers.base import MwisProblem

    from ..runner.sweep import _commit, code_version
    _commit(), code_version()  # before the run: the code this process loaded
    key = e0_key(conf, solver)
    e0 = conf["e0"]
    if solver == RECORD:
        sample = e0_sample(record_instances(conf), list(e0["bins"]), e0["per_bin"], int(e0["seed"]))
        cell = {"key": key, "format": E0_FORMAT, "run": conf["name"], "ran_at": _commit(),
                "code_version": code_version(), "instances": [{"epoch": int(ep), "t_s": float(t), "weights": p.weights.tolist(),
                               "edges": p.edges.tolist(), "groups": [g.tolist() for g in p.groups]}
                              for ep, t, p in sample]}
        write_json_atomic(Path(cells_dir) / f"{key}.json", cell)
        return cell
    sample = [(x["epoch"], x["t_s"], MwisProblem.from_arrays(
        np.asarray(x["weights"], dtype=np.float64), np.asarray(x["edges"], dtype=np.int64).reshape(-1, 2),
        x["groups"])) for x in conf["sample"]]
    ref = e0["reference"]
    limit = float(ref["time_limit_s"] if solver == REFERENCE else e0["time_limit_s"])
    backend = ref["backend"] if solver == REFERENCE else solver
    rows = e0_solve_rows(sample, solver, backend, limit, int(conf["seed"]))
    cell = {"key": key, "format": E0_FORMAT, "run": conf["name"], "rows": rows,
            "instances": len(sample), "ran_at": _commit(), "code_version": code_version()}
    write_json_atomic(Path(cells_dir) / f"{key}.json", cell)
    return cell


def _run_e0_cells(cfg, todo, confs, keys, cells_dir, progress) -> dict:
    def say(c, _cell):
        if progress:
            print(f"e0: {confs[c]['name']} {c[1]} done", flush=True)
    if not todo:
        return {}
    remote = cfg["scheduler"] not in (None, "local")
    if not remote and cfg["workers"] <= 1:
        out = {}
        for c in todo:
            out[c] = e0_cell(confs[c], c[1], c[2], c[3], str(cells_dir))
            say(c, out[c])
        return out
    from ..runner.dask_cluster import run_cells
    return run_cells(None, todo, keys, cells_dir, e0_cell, scheduler=cfg["scheduler"] or "local",
                     n_workers=min(cfg["workers"], len(todo)), cell_configs=confs, on_done=say)


def run_e0(cfg: dict, backends=None, progress: bool = True, compute: bool = True,
           runs=None, stale: list | None = None) -> list:
    """Every missing (reference run, solver) E0 cell, then the rows of all finished ones: first
    the RECORD cell of each run that still needs a solver (in parallel), then the solvers.
    Cells of another code version are appended to ``stale`` (paths; not reused)."""
    from ..runner.sweep import _read_cell, stale_cells
    e0 = cfg["e0"]
    all_solvers = list(e0["backends"]) + [REFERENCE]
    solvers = [s for s in all_solvers if not backends or s in backends]
    cells_dir = Path(cfg["cells"]) / "cells-e0"
    cells_dir.mkdir(parents=True, exist_ok=True)
    confs, keys, todo, found, records = {}, {}, [], {}, {}
    stale = [] if stale is None else stale
    for i, run in enumerate(e0["runs"]):
        conf = {"name": run["name"], "experiment": e0_experiment_config(cfg, run),
                "method": e0["method"], "rate": run["rate"], "seed": int(run["seed"]), "e0": e0,
                "mode": run["mode"], "objective": run.get("objective", "paper")}
        for s in all_solvers:
            c = (i, s, run["rate"], int(run["seed"]))
            key = e0_key(conf, s)
            cell = _read_cell(cells_dir / f"{key}.json", key)
            if cell is not None:
                found[c] = cell
            else:
                stale.extend(stale_cells(cells_dir, key))
                if s in solvers and (not runs or run["name"] in runs):
                    todo.append(c)
            confs[c], keys[c] = conf, key
        rc = (i, RECORD, run["rate"], int(run["seed"]))
        confs[rc], keys[rc] = conf, e0_key(conf, RECORD)
        records[i] = rc
    if compute and todo:
        need = sorted({c[0] for c in todo})
        rec = {}
        missing_rec = []
        for i in need:
            cell = _read_cell(cells_dir / f"{keys[records[i]]}.json", keys[records[i]])
            if cell is None:
                missing_rec.append(records[i])
            else:
                rec[i] = cell
        for c, cell in _run_e0_cells(cfg, missing_rec, confs, keys, cells_dir, progress).items():
            rec[c[0]] = cell
        for c in todo:
            confs[c] = {**confs[c], "sample": rec[c[0]]["instances"]}
        # the longest first (the reference), so the pool's tail is short
        todo.sort(key=lambda c: (c[1] != REFERENCE, c[0]))
        found.update(_run_e0_cells(cfg, todo, confs, keys, cells_dir, progress))
    rows = []
    for c in sorted(found, key=lambda c: (c[0], all_solvers.index(c[1]))):
        conf = confs[c]
        for r in found[c]["rows"]:
            rows.append({"run": conf["name"], "mode": conf["mode"],
                         "network": json.dumps(conf["experiment"]["network"]) if isinstance(
                             conf["experiment"]["network"], dict) else conf["experiment"]["network"],
                         "run_objective": conf["objective"], "rate": conf["rate"], "seed": conf["seed"],
                         **r, "commit": found[c].get("ran_at", "unrecorded"),
                         "code_version": found[c].get("code_version", "unrecorded")})
    return rows


# -- the driver ----------------------------------------------------------------------------------

def with_committed_rows(path: Path, rows: list, key: str, order: list, cells: str) -> list:
    """``rows`` (from the cells in ``cells``) and the rows of the table at ``path`` whose ``key``
    (an experiment; an E0 reference run) has no row in ``rows``, kept as they are (text), in
    the config's ``order`` of the keys. Why: cells live where they ran (``results/``, not
    committed), so a stage run on another machine, or after the cells were lost, would
    otherwise replace the finished tables of every experiment it did not compute with nothing
    (the cells of d3795b835634 were lost with their machine). A kept group is
    named on stderr with its rows and code versions; a group with rows here replaces the
    committed one whole (its window and its pairs come from one computation)."""
    if not path.exists():
        return rows
    import pandas as pd
    old = pd.read_csv(path, dtype=str, keep_default_na=False)
    if key not in old.columns:
        return rows
    have = {str(r[key]) for r in rows}
    kept = old[~old[key].isin(have)]
    for value, group in kept.groupby(key, sort=False):
        codes = ", ".join(sorted(set(group["code_version"]))) if "code_version" in group else "unrecorded"
        print(f"decision_study: {key} {value}: no cell of it in {cells}; its {len(group)} row(s) of "
              f"{path.name} kept as committed (code version {codes})", file=sys.stderr)
    if not rows or kept.empty:  # one source only: its own order (a rebuild changes no byte)
        return list(rows) + kept.to_dict("records")
    rank = {str(v): i for i, v in enumerate(order)}
    merged = list(rows) + kept.to_dict("records")
    return sorted(merged, key=lambda r: rank.get(str(r[key]), len(rank)))  # stable: rows' order kept


def pilot_seeds(cfg: dict) -> list:
    return list(range(cfg["power"]["pilot_seeds"]))


def full_seeds(cfg: dict, out: Path, experiment: str) -> list:
    """Seeds the experiment's primary comparisons need, from the pilot rows in runs.csv."""
    from ..reports.decision_report import power_rows
    import pandas as pd
    runs = pd.read_csv(out / "runs.csv") if (out / "runs.csv").exists() else None
    if runs is None:
        raise ExperimentError(f"{out / 'runs.csv'}: run the pilot first (--stage pilot)")
    rows = [r for r in power_rows(runs, cfg) if r["experiment"] == experiment]
    need = [int(r["seeds_needed"]) for r in rows if r["decides"]
            and r.get("seeds_needed") not in (None, "")
            and not (isinstance(r["seeds_needed"], float) and math.isnan(r["seeds_needed"]))]
    if not need:
        raise ExperimentError(f"{experiment}: the pilot has no rows for its primary comparisons")
    return list(range(max(cfg["power"]["pilot_seeds"], min(max(need), cfg["power"]["max_seeds"]))))


def run_stage(cfg: dict, stage: str, out: Path, experiments=None, backends=None,
              compute: bool = True, progress: bool = True, runs=None,
              primary_only: bool = False) -> dict:
    """One stage; ``primary_only`` (pilot, full): only the cells the primary comparisons read
    (:func:`primary_scope`), the rest of each experiment later."""
    out.mkdir(parents=True, exist_ok=True)
    t0 = time.perf_counter()
    study = {k: cfg[k] for k in ("format", "base", "power", "steady_state", "e0", "experiments")}
    (out / "study.json").write_text(json.dumps(study, indent=1, default=str) + "\n")
    info: dict = {"stage": stage}
    stale: list = []
    if stage == "e0":
        rows = run_e0(cfg, backends=backends, progress=progress, compute=compute, runs=runs,
                      stale=stale)
        rows = with_committed_rows(out / "e0.csv.gz", rows, "run", [r["name"] for r in cfg["e0"]["runs"]],
                                   cfg["cells"])
        write_csv(out / "e0.csv.gz", rows)
        info["e0_rows"] = len(rows)
    else:
        names = [e["name"] for e in cfg["experiments"] if not experiments or e["name"] in experiments]
        results, entries = [], []
        for name in names:
            seeds = pilot_seeds(cfg) if stage == "pilot" else (
                full_seeds(cfg, out, name) if stage == "full" else pilot_seeds(cfg))
            cc, ent = capacity_config(cfg, seeds, Path(cfg["cells"]), [name],
                                      primary_only=primary_only)
            if not cc.arms:
                continue
            results += run_capacity_sweep(cc, compute=compute and stage != "tables", progress=progress)
            entries += ent
        # every experiment's finished cells, whatever stage made them (the tables stay whole);
        # the tables stage with --experiments: only those, the others' rows kept as committed
        # (E1 and E2 share some cells with E3 - same network, rate, method and
        # parameters - so cells computed for E3 alone would have replaced their whole tables)
        all_results, all_entries = [], []
        for e in cfg["experiments"]:
            if stage == "tables" and experiments and e["name"] not in experiments:
                continue
            seeds = list(range(cfg["power"]["max_seeds"]))
            cc, ent = capacity_config(cfg, seeds, Path(cfg["cells"]), [e["name"]])
            done = run_capacity_sweep(cc, compute=False, progress=False)
            all_results += done
            all_entries += ent
            stale += [p for _a, _m, sw in done for p in sw.stale]
        rows, wrows, erows = tables(cfg, all_results, all_entries)
        names_all = [e["name"] for e in cfg["experiments"]]
        rows = with_committed_rows(out / "runs.csv", rows, "experiment", names_all, cfg["cells"])
        wrows = with_committed_rows(out / "windows.csv", wrows, "experiment", names_all, cfg["cells"])
        erows = with_committed_rows(out / "epochs.csv.gz", erows, "experiment", names_all, cfg["cells"])
        if rows or not (out / "runs.csv").exists():
            write_csv(out / "runs.csv", rows)
            write_csv(out / "windows.csv", wrows)
            write_csv(out / "epochs.csv.gz", erows)
        else:  # as for e0.csv.gz below: an empty table never replaces a finished one
            print(f"decision_study: no finished run cell at this code version in {cfg['cells']}; "
                  f"{out / 'runs.csv'} and windows.csv kept as they were", file=sys.stderr)
        info["runs"] = len(rows)
        info["missing_at_max_seeds"] = sum(len(sw.missing) for _a, _m, sw in all_results)
        if stage == "tables":  # the finished E0 cells too
            e0_rows = run_e0(cfg, progress=False, compute=False, stale=stale)
            e0_rows = with_committed_rows(out / "e0.csv.gz", e0_rows, "run",
                                          [r["name"] for r in cfg["e0"]["runs"]], cfg["cells"])
            if e0_rows or not (out / "e0.csv.gz").exists():
                write_csv(out / "e0.csv.gz", e0_rows)
            else:
                # no E0 cell at this code version: the table of an earlier one is kept (writing
                # an empty one threw away a committed table, and the report then failed on it)
                print(f"decision_study: no E0 cell at this code version in {cfg['cells']}; "
                      f"{out / 'e0.csv.gz'} kept as it was", file=sys.stderr)
            info["e0_rows"] = len(e0_rows)
    stale = sorted(set(stale))
    info["stale_cells"] = len(stale)
    if stale:
        # reported, never reused or deleted: cells of other run code (another code version)
        print(f"decision_study: {len(stale)} stale cell(s) in {cfg['cells']} (another code "
              f"version; not reused, not deleted), e.g. {stale[0]}", file=sys.stderr)
    info["wall_s"] = time.perf_counter() - t0
    from ..reports.decision_report import write_decision_report
    write_decision_report(out)
    return info


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="decision_study",
                                 description=__doc__.split("\n\n")[0])
    ap.add_argument("--config", default="config/decision-study.yaml")
    ap.add_argument("--stage", choices=STAGES, required=True)
    ap.add_argument("--out", default=None, help="default: the config's out (docs/decision-study)")
    ap.add_argument("--cells", default=None, help="where cells are kept (default: the config's cells)")
    ap.add_argument("--workers", type=int, default=None)
    ap.add_argument("--scheduler", default=None, help="local or tcp://HOST:8786")
    ap.add_argument("--experiments", default=None,
                    help="comma list (default: every one); with --stage tables, only these are "
                         "collected from the cells, the others' rows kept as committed")
    ap.add_argument("--backends", default=None, help="E0: comma list of solvers to run now")
    ap.add_argument("--runs", default=None, help="E0: comma list of e0.runs names to run now")
    ap.add_argument("--duration", type=float, default=None, help="override base.duration_s")
    ap.add_argument("--primary-only", action="store_true",
                    help="pilot/full: only the methods, rates and variants the primary "
                         "comparisons read (their power first; the rest of the cells later)")
    ap.add_argument("--no-progress", action="store_true")
    ap.add_argument("--code-version", default=None, metavar="V",
                    help="tables only: collect the cells of run code version V (12 hex digits, "
                         "e.g. computed in a worktree at the study's frozen code) instead of "
                         "this checkout's")
    args = ap.parse_args(argv)
    try:
        if args.code_version is not None:
            if args.stage != "tables":
                raise ExperimentError(f"--code-version {args.code_version}: only with --stage "
                                      f"tables (a cell computed here is of this checkout's code, "
                                      f"not {args.code_version}), got --stage {args.stage}")
            from ..runner.sweep import pin_code_version
            try:
                pin_code_version(args.code_version)
            except ValueError as exc:
                raise ExperimentError(f"--code-version: {exc}") from None
        cfg = load_decision_config(args.config)
        if args.cells is not None:
            cfg["cells"] = args.cells
        if args.workers is not None:
            cfg["workers"] = args.workers
        if args.scheduler is not None:
            cfg["scheduler"] = args.scheduler
        if args.duration is not None:
            cfg["base"]["duration_s"] = args.duration
        exps = [x for x in (args.experiments or "").split(",") if x] or None
        backends = [x for x in (args.backends or "").split(",") if x] or None
        if backends:
            bad = [b for b in backends if b not in cfg["e0"]["backends"] + [REFERENCE]]
            if bad:
                raise ExperimentError(f"--backends: {bad[0]!r} is not one of e0.backends "
                                      f"{cfg['e0']['backends']} or 'reference'")
        out = Path(args.out or cfg["out"])
        e0_runs = [x for x in (args.runs or "").split(",") if x] or None
        bad = [r for r in e0_runs or [] if r not in [x["name"] for x in cfg["e0"]["runs"]]]
        if bad:
            raise ExperimentError(f"--runs: {bad[0]!r} is not a name in e0.runs")
        info = run_stage(cfg, args.stage, out, experiments=exps, backends=backends,
                         progress=not args.no_progress, runs=e0_runs,
                         primary_only=args.primary_only)
    except ExperimentError as exc:
        print(f"decision_study: {exc}", file=sys.stderr)
        return 2
    print(f"decision study {args.stage}: {json.dumps(info, default=str)}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
