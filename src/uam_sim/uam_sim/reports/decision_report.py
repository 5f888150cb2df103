"""The decision study's report, from its tables alone.

    python -m uam_sim.decision_report docs/decision-study

Reads ``study.json`` (the declared experiments and comparisons), ``runs.csv``, ``windows.csv``
and ``e0.csv.gz`` (whichever exist) and writes ``comparisons.csv``, ``power.csv``,
``e0_summary.csv`` and ``REPORT.md``. Every sentence that states a result is computed from those
rows here: a comparison whose interval excludes 0 is called a difference in its direction; one
whose interval includes 0 is reported as "not resolved at this power" with its half-width, never
as "no effect". No number is written by hand.

Statistics: paired per seed (every method of one cell at one seed plans the same requests),
Student t intervals (``uam_sim.reports.stats.mean_interval``), two-sided one-sample t p-values
(``scipy.stats.ttest_1samp``). Pooled rows stack the per-seed relative differences of every
group of a comparison with a t interval over all pairs (what the power rows use); beside them
the fixed- and random-effects pools with Cochran's Q and I^2, and a pooled claim only where
heterogeneity allows; Holm over exactly the claims the Answers make
(:mod:`uam_sim.reports.decision_review`).
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from ..runner.files import write_csv
from . import decision_review as review
from .decision_groups import _groups, fmt_number
from .markdown import table_lines as _table
from .stats import mean_interval, seeds_needed

SIZE_BINS = [1, 8, 16, 32, 64, 128, 256, 512, 1024, 4096, 100000]
E0_ORDER = ["firstfit", "greedy", "auto", "exact", "sa", "tabu", "qpu-emulator", "reference"]


def _f(x, nd=1, sign=False) -> str:
    return fmt_number(x, nd, sign)


# -- comparisons -------------------------------------------------------------------------------

def comparison_rows(runs: pd.DataFrame, study: dict) -> list:
    """One row per (experiment, comparison, group) plus a pooled row per comparison."""
    from scipy.stats import ttest_1samp
    level = float(study["power"]["level"])
    out = []
    for exp in study["experiments"]:
        for kind in ("primary", "secondary"):
            for comp in exp[kind]:
                neg = next(j for j, t in enumerate(comp["terms"]) if t["sign"] < 0)
                rel_all = []
                for label, vals in _groups(runs, exp, comp):
                    seeds = sorted(set.intersection(*[set(v) for v in vals.values()])) if vals else []
                    if not seeds:
                        out.append({"experiment": exp["name"], "kind": kind, "comparison": comp["name"],
                                    "metric": comp["metric"], "group": label, "seeds": 0})
                        continue
                    d = np.array([sum(comp["terms"][j]["sign"] * vals[j][s] for j in vals) for s in seeds])
                    base = np.array([vals[neg][s] for s in seeds])
                    m, lo, hi = mean_interval(d, level)
                    ok = base != 0
                    rel = 100.0 * d[ok] / base[ok]
                    rm, rlo, rhi = mean_interval(rel, level)
                    rel_all += rel.tolist()
                    p = (float(ttest_1samp(d, 0.0).pvalue) if d.size >= 2 and np.std(d) > 0
                         else (1.0 if d.size >= 2 and np.all(d == 0) else float("nan")))
                    row = {"experiment": exp["name"], "kind": kind, "comparison": comp["name"],
                           "metric": comp["metric"], "group": label, "seeds": len(seeds),
                           "mean_base": float(base.mean()), "diff": m, "diff_lo": lo, "diff_hi": hi,
                           "sd": float(d.std(ddof=1)) if d.size >= 2 else float("nan"),
                           "rel_pct": rm, "rel_lo": rlo, "rel_hi": rhi,
                           "positive": int((d > 0).sum()), "negative": int((d < 0).sum()), "p": p}
                    out.append(row)
                if len(rel_all) >= 2:
                    rm, rlo, rhi = mean_interval(rel_all, level)
                    out.append({"experiment": exp["name"], "kind": f"{kind}-pooled",
                                "comparison": comp["name"], "metric": comp["metric"],
                                "group": "pooled", "seeds": len(rel_all),
                                "rel_pct": rm, "rel_lo": rlo, "rel_hi": rhi,
                                "positive": int((np.array(rel_all) > 0).sum()),
                                "negative": int((np.array(rel_all) < 0).sum())})
    return out


def missing_runs(seeds_per_arm: list, target: int) -> int:
    """Runs missing for every arm to have ``target`` seeds: the sum over arms of
    max(0, target - seeds of the arm) (one run is one arm at one seed)."""
    return int(sum(max(0, int(target) - int(n)) for n in seeds_per_arm))


def paper_figures_text(study: dict) -> str:
    """Which experiment stands for which of the paper's figures, with the model each runs on read
    from the config (the paper's model is airspace mode ``paper``)."""
    parts = []
    for exp in study["experiments"]:
        if exp["name"] != "E3":
            continue
        for c in exp["cells"]:
            net = c["network"] if isinstance(c["network"], str) else "a synthetic city"
            model = ("the paper's model" if c.get("mode") == "paper"
                     else f"airspace mode `{c.get('mode')}`, not the paper's model (mode `paper`)")
            parts.append(f"{exp['name']}'s approvals against the request rate (cell {c['name']}: "
                         f"network {net}, {model}, rates {', '.join(map(str, c['rates']))})")
    lead = ("; ".join(parts) + " stand beside the paper's Fig. 3 (cumulative approvals) in kind, "
            "not in numbers") if parts else "No experiment sweeps the request rate"
    return (lead + "; E0's solve time per size bin beside its Fig. 6 (time to solution). The "
            "figures side by side, with the paper's statements and our values of the same "
            "quantities, are in docs/paper-study/REPORT.md (\"The paper's figures side by side\"). "
            "The paper gives no value for the expanded airspace, the objectives or the horizon.")


def mde(sd: float, n: int, level: float = 0.95, power: float = 0.8) -> float:
    """The minimal detectable effect of a paired mean of ``n`` differences with SD ``sd``: the
    true difference a two-sided t test at ``level`` detects with probability ``power``,
    (t_{(1+level)/2, n-1} + t_{power, n-1}) * sd / sqrt(n) (the usual approximation; n >= 2)."""
    from scipy.stats import t as student_t
    if n < 2 or not math.isfinite(sd):
        return float("nan")
    return float((student_t.ppf(0.5 + level / 2, n - 1) + student_t.ppf(power, n - 1))
                 * sd / math.sqrt(n))


def power_rows(runs: pd.DataFrame, study: dict) -> list:
    """Per primary comparison and group: the paired SD of the seeds run so far, the seeds a 95 %
    CI half-width of ``half_width_pct`` % of the reference arm's approvals needs, the half-width
    and the minimal detectable effect (:func:`mde`, at ``power.mde_power``) the seeds run and the
    cap give. Where the comparison has several groups, also its pooled row: the stacked per-seed
    relative differences [%] (the same question asked in every group), whose seeds needed are
    per group (the stack grows by one difference per group for each seed)."""
    from scipy.stats import t as student_t
    pw = study["power"]
    level = float(pw["level"])
    mp = float(pw.get("mde_power", 0.8))
    cap = int(pw["max_seeds"])
    rows = []
    groups: dict = {}
    for r in comparison_rows(runs, study):
        if r["kind"] == "primary" and r.get("seeds", 0) >= 1:
            groups.setdefault((r["experiment"], r["comparison"]), []).append(r)
        if r["kind"] != "primary" or r.get("seeds", 0) < 2:
            continue
        target = pw["half_width_pct"] / 100.0 * abs(r["mean_base"])
        n_need = seeds_needed(r["sd"], target, level) if target > 0 else float("nan")
        q = student_t.ppf(0.5 + level / 2, r["seeds"] - 1)
        rows.append({"experiment": r["experiment"], "comparison": r["comparison"],
                     "metric": r["metric"], "group": r["group"], "seeds_run": r["seeds"],
                     "paired_sd": r["sd"], "base_mean": r["mean_base"], "target_half": target,
                     "seeds_needed": n_need,
                     "half_now": q * r["sd"] / math.sqrt(r["seeds"]),
                     "max_seeds": cap,
                     "half_at_cap": student_t.ppf(0.5 + level / 2, cap - 1) * r["sd"] / math.sqrt(cap),
                     "mde_now": mde(r["sd"], r["seeds"], level, mp),
                     "mde_at_cap": mde(r["sd"], cap, level, mp),
                     "reachable": bool(n_need <= cap) if isinstance(n_need, int) else False,
                     "decides": _per(study, r) == "cell"})
    for r in comparison_rows(runs, study):
        mine = groups.get((r["experiment"], r["comparison"]), [])
        if r["kind"] != "primary-pooled" or len(mine) < 2:
            continue
        rel = _stacked_relative(runs, study, r["experiment"], r["comparison"])
        if len(rel) < 3:
            continue
        k = len(mine)
        sd = float(np.std(rel, ddof=1))
        target = float(pw["half_width_pct"])
        n_total = seeds_needed(sd, target, level) if sd > 0 else len(rel)
        per_group = int(math.ceil(n_total / k)) if isinstance(n_total, int) else float("nan")
        q = student_t.ppf(0.5 + level / 2, len(rel) - 1)
        n_cap = cap * k
        rows.append({"experiment": r["experiment"], "comparison": r["comparison"],
                     "metric": r["metric"] + " [% of base]", "group": f"pooled over {k} groups",
                     "seeds_run": len(rel), "paired_sd": sd, "base_mean": 100.0,
                     "target_half": target, "seeds_needed": per_group,
                     "half_now": q * sd / math.sqrt(len(rel)), "max_seeds": cap,
                     "half_at_cap": student_t.ppf(0.5 + level / 2, n_cap - 1) * sd / math.sqrt(n_cap),
                     "mde_now": mde(sd, len(rel), level, mp), "mde_at_cap": mde(sd, n_cap, level, mp),
                     "reachable": bool(per_group <= cap) if isinstance(per_group, int) else False,
                     "decides": _per(study, r) == "pooled"})
    return rows


def _per(study: dict, r: dict) -> str:
    """The declared ``per`` of a comparison row's comparison: which power rows set its seeds
    ("cell": every group's; "pooled": the pooled row's)."""
    exp = next(e for e in study["experiments"] if e["name"] == r["experiment"])
    comp = next(c for c in exp["primary"] + exp["secondary"] if c["name"] == r["comparison"])
    return comp.get("per", "cell")


def _stacked_relative(runs: pd.DataFrame, study: dict, experiment: str, comparison: str) -> list:
    """The per-seed relative differences [%] of one comparison, stacked over its groups (the
    numbers behind its pooled row)."""
    exp = next(e for e in study["experiments"] if e["name"] == experiment)
    comp = next(c for c in exp["primary"] + exp["secondary"] if c["name"] == comparison)
    neg = next(j for j, t in enumerate(comp["terms"]) if t["sign"] < 0)
    out = []
    for _label, vals in _groups(runs, exp, comp):
        seeds = sorted(set.intersection(*[set(v) for v in vals.values()])) if vals else []
        for sd in seeds:
            base = vals[neg][sd]
            if base:
                out.append(100.0 * sum(comp["terms"][j]["sign"] * vals[j][sd] for j in vals) / base)
    return out


# -- E0 ----------------------------------------------------------------------------------------

def e0_gaps(e0: pd.DataFrame) -> pd.DataFrame:
    """Each (run, epoch, solver) row with the best known objective (the best of every solver and
    the reference on that instance), whether it is proven, and the gaps in objective and count."""
    key = ["run", "epoch"]
    best = e0.groupby(key)["objective"].max().rename("best_known")
    proven = (e0[e0["proven_optimal"].astype(str) == "True"].groupby(key)["objective"].max()
              .rename("proven_value"))
    ref = e0[e0["solver"] == "reference"].set_index(key)
    g = e0.join(best, on=key).join(proven, on=key)
    g["best_proven"] = g["proven_value"].notna() & (np.isclose(g["proven_value"], g["best_known"]))
    g["ref_count"] = g.set_index(key).index.map(ref["count"].to_dict() if not ref.empty else {})
    g["gap_pct"] = np.where(g["best_known"] > 0, 100.0 * (g["best_known"] - g["objective"])
                            / g["best_known"], 0.0)
    g["count_gap"] = g["ref_count"] - g["count"]
    g["bin"] = pd.cut(g["vertices"], SIZE_BINS, right=False).astype(str)
    return g


def e0_summary(e0: pd.DataFrame) -> list:
    g = e0_gaps(e0)
    rows = []
    solvers = [s for s in E0_ORDER if s in set(g["solver"])] + sorted(set(g["solver"]) - set(E0_ORDER))
    for s in solvers:
        for lo, hi in zip(SIZE_BINS[:-1], SIZE_BINS[1:]):
            x = g[(g["solver"] == s) & (g["vertices"] >= lo) & (g["vertices"] < hi)]
            if x.empty:
                continue
            rows.append({"solver": s, "bin": f"[{lo}, {hi})", "instances": len(x),
                         "gap_mean_pct": float(x["gap_pct"].mean()),
                         "gap_max_pct": float(x["gap_pct"].max()),
                         "at_best_share": float((x["gap_pct"] <= 1e-9).mean()),
                         "count_gap_mean": float(x["count_gap"].mean()),
                         "best_proven_share": float(x["best_proven"].mean()),
                         "proven_share": float((x["proven_optimal"].astype(str) == "True").mean()),
                         "fallbacks": int((x["fallback"].astype(str) == "True").sum()),
                         "wall_median_s": float(x["wall_s"].median()),
                         "wall_max_s": float(x["wall_s"].max())})
    return rows


# -- the report ---------------------------------------------------------------------------------

def _read(d: Path, name: str):
    p = d / name
    return pd.read_csv(p) if p.exists() and p.stat().st_size > 0 else None


def _verdict(r: dict, unit: str) -> str:
    lo, hi = r.get("diff_lo", float("nan")), r.get("diff_hi", float("nan"))
    txt = (f"{_f(r['diff'], 2, True)} {unit} [{_f(lo, 2, True)}, {_f(hi, 2, True)}] "
           f"({_f(r['rel_pct'], 2, True)} % [{_f(r['rel_lo'], 2, True)}, {_f(r['rel_hi'], 2, True)}]), "
           f"{r['seeds']} seeds, {r['positive']} positive / {r['negative']} negative")
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return txt + ": no interval (fewer than 2 seeds)."
    if lo > 0 or hi < 0:
        return txt + f": the interval excludes 0, a difference {'above' if lo > 0 else 'below'} 0."
    half = (hi - lo) / 2
    return (txt + f": the interval includes 0, so the difference is not resolved at this power "
            f"(half-width {_f(half, 2)} {unit}; effects smaller than that are neither shown nor "
            f"excluded).")


UNITS = {"approved_ss": "flights", "expired_ss": "requests", "requests_ss": "requests",
         "approval_rate_ss": "(share)", "delay_mean_s": "s", "delay_p95_s": "s",
         "detour_mean_m": "m", "detour_mean_pct": "%-points", "jain_index": "(index)",
         "weight_sum_ss": "(weight)"}


def _load_text(ex: pd.DataFrame) -> str:
    """The machine's load during an experiment's runs (1-min average before and after each run,
    sweep.run_cell), and where the fallbacks were: solve limits are wall-clock, so load can
    decide a fallback; '' for runs from before the load was recorded."""
    if "load_before" not in ex or not ex["load_before"].notna().any():
        return ""
    lo = ex[["load_before", "load_after"]].max(axis=1)
    known = lo.notna()
    txt = (f" Machine load (1-min average, the larger of before and after each run) median "
           f"{_f(lo[known].median(), 1)}, max {_f(lo[known].max(), 1)} over {int(known.sum())} runs")
    fb = ex[known & (ex["fallbacks"] > 0)]
    if len(fb):
        txt += (f"; the {int(fb['fallbacks'].sum())} fallbacks were in {len(fb)} runs at load "
                f"{_f(lo[fb.index].min(), 1)} to {_f(lo[fb.index].max(), 1)}")
    if known.sum() < len(ex):
        txt += f"; {int(len(ex) - known.sum())} runs have no load recorded"
    return txt + "."


def _terms_text(comp: dict) -> str:
    return " ".join(("+ " if t["sign"] > 0 else "- ") + t["method"]
                    + (" (" + ", ".join(f"{k} {v}" for k, v in t["where"].items()) + ")"
                       if t["where"] else "") for t in comp["terms"]).lstrip("+ ")


# complexity over 25: the report as one sequence of sections; to be split into a function per section
def _record_lines(runs, e0) -> list:
    """The "Record" section: the commits and code versions that ran the cells, counted per table
    from each row's own ``commit`` and ``code_version`` columns."""
    L = ["## Record", ""]
    commits = []
    for name, df in (("runs.csv", runs), ("e0.csv.gz", e0)):
        if df is not None and "commit" in df:
            for c, n in df["commit"].astype(str).value_counts().sort_index().items():
                commits.append(f"`{c}` ({n} rows of {name})")
    L.append("Commits that ran the cells (from each cell's own record): "
             + ("; ".join(commits) if commits else "none yet") + ".")
    versions = []
    parts = [(f"runs.csv, {x}", runs[runs["experiment"] == x]) for x in
             sorted(set(runs["experiment"].astype(str)))] if runs is not None and \
        "experiment" in runs else [("runs.csv", runs)]
    for name, df in parts + [("e0.csv.gz", e0)]:
        if df is not None and "code_version" in df:
            for c, n in df["code_version"].astype(str).value_counts().sort_index().items():
                versions.append(f"`{c}` ({n} rows of {name})")
    if versions:
        L.append("")
        L.append("Code versions of the cells, per table (`uam_sim.runner.sweep.code_version`, a hash of "
                 "the run code that is part of each cell key; a cell of other code is never "
                 "reused): " + "; ".join(versions) + ". Every number below is of the code "
                 "versions named here: a checkout whose run code differs (any later merge of run "
                 "code) has a code version of its own, at which none of these cells has run; "
                 "the study would compute them again (`stale_cells` in its summary line).")
    L.append("")
    return L


def _missing_lines(runs, e0, study: dict, prow: list) -> list:
    """The "What has run and what is missing" section: per experiment the runs per seed, the runs
    present, the seeds present and the runs still missing for the pilot and for the seeds the
    power rows ``prow`` need; then the E0 (reference run, solver) cells not yet in ``e0``."""
    L = ["## What has run and what is missing", ""]
    miss = []
    arm_keys = ["cell", "variant", "rate", "method"]
    for exp in study["experiments"]:
        have = runs[runs["experiment"] == exp["name"]] if runs is not None else None
        n_arms = len(exp["cells"]) * int(np.prod([len(v) for v in exp["vary"].values()]) if exp["vary"] else 1)
        n_runs = 0 if have is None else len(have)
        seeds = sorted(set(have["seed"].astype(int))) if have is not None and len(have) else []
        need = [r["seeds_needed"] for r in prow if r["experiment"] == exp["name"]
                and r["decides"] and isinstance(r["seeds_needed"], int)]
        target = min(max(need), study["power"]["max_seeds"]) if need else None
        per_seed_runs = sum(len(c["rates"]) for c in exp["cells"]) * (n_arms // max(1, len(exp["cells"]))) \
            * len(exp["methods"])
        pilot = int(study["power"]["pilot_seeds"])
        per_arm = (have.groupby([k for k in arm_keys if k in have])["seed"].nunique().tolist()
                   if have is not None and len(have) else [])
        per_arm += [0] * max(0, per_seed_runs - len(per_arm))  # arms with no run at all
        miss.append([exp["name"], per_seed_runs, n_runs, ", ".join(map(str, seeds)) or "none",
                     missing_runs(per_arm, pilot),
                     target if target is not None else "pilot not complete",
                     "-" if target is None else missing_runs(per_arm, target)])
    L += _table(miss, ["experiment", "runs per seed", "runs in runs.csv", "seeds present (any arm)",
                       f"pilot runs missing ({study['power']['pilot_seeds']} seeds in every arm)",
                       "seeds the power needs (capped)", "runs still missing at that"])
    e0_runs = [r["name"] for r in study["e0"]["runs"]]
    solvers = list(study["e0"]["backends"]) + ["reference"]
    if e0 is not None:
        done = set(zip(e0["run"].astype(str), e0["solver"].astype(str)))
    else:
        done = set()
    absent = [f"{r} / {s}" for r in e0_runs for s in solvers if (r, s) not in done]
    L += ["", "E0 cells (reference run / solver) missing: " + (", ".join(absent) if absent else "none") + ".", ""]
    return L


def _steady_state_lines(windows, study: dict) -> list:
    """The "Steady-state window" section: how the window is chosen, and the table of each
    experiment cell's truncation epoch and warm-up [s] from ``windows``."""
    ss = study["steady_state"]
    L = ["## Steady-state window", "",
         f"Chosen from the data: {ss['method'].upper()} (White's MSER with batches of 5 epochs, "
         f"truncation searched over the first half of the run) on the mean over seeds of the "
         f"reference method's ({ss['reference_method']}) per-epoch `{ss['series']}` (flights in "
         "the air), per variant; then one window per experiment cell and rate, the latest of "
         "its variants' truncations, which every method and variant uses (so a comparison "
         "across variants, as E2's horizons, counts the same requests in both arms). A request "
         "counts when its earliest departure is at or after the truncation and its latest "
         "departure at or before the run's end.", ""]
    if windows is not None:
        own = "variant_truncation_epoch" in windows.columns
        L += _table([[r["experiment"], r["cell"], r["variant"], r["rate"], r["reference_method"],
                      r["variant_truncation_epoch"] if own else "-", r["truncation_epoch"],
                      _f(r["warmup_s"], 0)] for r in windows.to_dict("records")],
                    ["experiment", "cell", "variant", "rate", "reference method",
                     "variant's own truncation", "truncation epoch (used)", "warm-up [s]"])
    else:
        L.append("No run yet.")
    L.append("")
    return L


def _power_lines(study: dict, prow: list) -> list:
    """The "Seeds from power" section: the power rows ``prow`` as a table (paired SD, half-widths
    and MDEs in the metric's units) and a line per deciding comparison the cap cannot reach."""
    pw = study["power"]
    L = ["## Seeds from power", "",
         f"Per primary comparison, the paired SD of the seeds run so far gives the seeds a "
         f"{int(round(pw['level'] * 100))} % CI half-width of {_f(pw['half_width_pct'], 1)} % of the "
         f"reference arm's mean needs (t interval; `uam_sim.reports.stats.seeds_needed`); the "
         f"study runs that many, capped at {pw['max_seeds']}. A comparison declared `per: pooled` "
         "(the same question in every group) takes its seeds from its pooled row (per-seed "
         "relative differences stacked over the groups, in % of the base arm); the others from "
         "their groups (\"sets seeds\"). MDE: the minimal detectable effect, the true difference "
         f"a two-sided test at {int(round(pw['level'] * 100))} % finds with probability "
         f"{_f(pw.get('mde_power', 0.8) * 100, 0)} %, at the seeds run and at the cap.", ""]
    if prow:
        L += _table([[r["experiment"], r["comparison"], r["group"], "yes" if r["decides"] else "no",
                      r["seeds_run"], _f(r["paired_sd"], 2),
                      _f(r["target_half"], 2), r["seeds_needed"] if isinstance(r["seeds_needed"], int) else "-",
                      _f(r["half_now"], 2), _f(r["half_at_cap"], 2), _f(r["mde_now"], 2),
                      _f(r["mde_at_cap"], 2)] for r in prow],
                    ["experiment", "primary", "group", "sets seeds", "seeds run", "paired SD",
                     "target half-width", "seeds needed", "half-width now",
                     f"half-width at {pw['max_seeds']} seeds", "MDE now",
                     f"MDE at {pw['max_seeds']} seeds"])
        L.append("")
        for r in prow:
            if not r["reachable"] and r["decides"]:
                L.append(f"- {r['experiment']} {r['comparison']} ({r['group']}): "
                         f"{r['seeds_needed'] if isinstance(r['seeds_needed'], int) and r['seeds_needed'] <= 10000 else 'more than 10,000'} "
                         f"seeds would be needed, more than the cap of {r['max_seeds']}: the study "
                         f"could not reach the target; at the cap the half-width is "
                         f"{_f(r['half_at_cap'], 2)} (target {_f(r['target_half'], 2)}) and the "
                         f"smallest effect it would detect is {_f(r['mde_at_cap'], 2)}.")
    else:
        L.append("No pilot rows yet (`--stage pilot`).")
    L.append("")
    return L


def _comparison_line(r: dict) -> str:
    """One comparison row ``r`` (from comparison_rows) as a bullet: a pooled estimate with its
    interval [%], "no common seeds yet", or the group's verdict in the metric's units."""
    if r["kind"].endswith("pooled"):
        return (f"- {r['kind']} `{r['comparison']}` over every group: "
                f"{_f(r['rel_pct'], 2, True)} % [{_f(r['rel_lo'], 2, True)}, {_f(r['rel_hi'], 2, True)}] "
                f"({r['seeds']} pairs, {r['positive']} positive)"
                + (": the interval excludes 0." if (r["rel_lo"] > 0 or r["rel_hi"] < 0)
                   else ": the interval includes 0 (not resolved at this power)."))
    if r.get("seeds", 0) == 0:
        return f"- {r['kind']} `{r['comparison']}` ({r['group']}): no common seeds yet."
    holm_txt = (f" (unadjusted p {_f(r['p'], 3)}; claims and Holm in the Answers)"
                if r["kind"] == "secondary" and math.isfinite(r.get("p", math.nan)) else "")
    return (f"- {r['kind']} `{r['comparison']}` ({r['group']}): "
            + _verdict(r, UNITS.get(r["metric"], ""))[:-1] + holm_txt + ".")


def _arm_means_table(ex: pd.DataFrame) -> list:
    """One experiment's runs ``ex`` as a table of per-arm means over seeds: approvals and expiries
    in the window, delays [s], detour [m], Jain's index, solve times [s], overruns and fallbacks."""
    keys = ["cell", "variant", "rate", "method"]
    agg = ex.groupby(keys, sort=True)
    prio = sorted(c for c in ex.columns if c.startswith("delay_p95_s_prio") and ex[c].notna().any())
    out = []
    for k, g in agg:
        out.append([*k, len(g), _f(g["approved_ss"].mean()), _f(g["expired_ss"].mean()),
                    _f(g["delay_mean_s"].mean()), _f(g["delay_p95_s"].mean()),
                    _f(g["detour_mean_m"].mean(), 0),
                    *[_f(g[c].mean()) for c in prio], _f(g["jain_index"].mean(), 3),
                    _f(g["solve_time_median_s"].mean(), 3), _f(g["solve_time_max_s"].max(), 2),
                    int(g["overruns"].sum()), int(g["fallbacks"].sum())])
    return _table(out, [*keys, "seeds", "approved (window)", "expired (window)", "delay mean [s]",
                        "delay p95 [s]", "detour [m]", *[f"p95 delay prio {c[16:]} [s]" for c in prio],
                        "Jain", "solve median [s]", "solve max [s]", "overruns", "fallbacks"])


def _experiment_lines(d: Path, runs, exp: dict, comps: list) -> list:
    """One experiment's section: its declared comparisons (marked where amended after data), a
    line per computed comparison of ``comps``, and its table of per-arm means."""
    L = [f"## {exp['name']}: {exp['question']}", ""]
    L.append("Declared in config/decision-study.yaml (copied to study.json); what was changed "
             "after data is marked and listed under \"Amendments after seeing data\":")
    for kind in ("primary", "secondary"):
        for c in exp[kind]:
            am = review.amended(d, exp["name"], c["name"])
            L.append(f"- {kind}: `{c['name']}`: {_terms_text(c)}, in `{c['metric']}`"
                     + (f" (`per: {c['per']}`)" if c.get("per") else "")
                     + (f"; amended after data in {', '.join(f'`{x}`' for x in am)}" if am else ""))
    L.append("")
    rows = [r for r in comps if r["experiment"] == exp["name"]]
    if not rows:
        return L + ["No runs yet.", ""]
    L += [_comparison_line(r) for r in rows]
    L.append("")
    L += _arm_means_table(runs[runs["experiment"] == exp["name"]])
    L.append("")
    return L


def _answers_lines(runs, study: dict, prow: list) -> list:
    """The heterogeneity section and the "Answers": one line per claim, and per experiment the
    solve times [s], overruns and fallbacks of its MWIS runs."""
    het = review.heterogeneity_rows(runs, study) if runs is not None else []
    L = review.heterogeneity_lines(het)
    claims = review.answer_claims(runs, study) if runs is not None else []
    L += ["## Answers", "",
          "One line per claim: per declared comparison its pooled estimate where heterogeneity "
          "allows (fixed effect, random effects beside it), else each group, absolute and relative. "
          + (review.holm_family_text(claims) if claims else ""), ""]
    for exp in study["experiments"]:
        mine = [c for c in claims if c["experiment"] == exp["name"]]
        L += review.answer_lines(mine, prow, UNITS)
        if runs is not None:
            mw = runs[(runs["experiment"] == exp["name"]) & ~runs["method"].isin(["fifo", "firstfit"])]
            if len(mw):
                L.append(f"- {exp['name']} solve time of the MWIS runs ({len(mw)}): median of the "
                         f"runs' medians {_f(mw['solve_time_median_s'].median(), 3)} s, longest "
                         f"{_f(mw['solve_time_max_s'].max(), 2)} s; {int(mw['overruns'].sum())} "
                         f"solves past limit + 0.4 s, {int(mw['fallbacks'].sum())} fallbacks."
                         + _load_text(runs[runs["experiment"] == exp["name"]]))
    L.append("")
    return L


def _e0_lines(e0, study: dict, e0s: list) -> list:
    """The "E0: matched shadow solves" section: the summary rows ``e0s`` as a table (gaps [%],
    wall times [s]), a line per solver with its mean gap and interval, and the figure's link."""
    L = ["## E0: matched shadow solves", "",
         f"Each epoch's recorded instance of the reference runs (method {study['e0']['method']}), "
         + (f"a seeded sample of up to {study['e0']['per_bin']} per size bin, " if study['e0'].get('per_bin')
            else "every epoch's instance (no sampling), ")
         + f"solved by every solver at "
         f"{_f(study['e0']['time_limit_s'], 1)} s and by the reference "
         f"({study['e0']['reference']['backend']}, {_f(study['e0']['reference']['time_limit_s'], 0)} s). "
         "Gap = (best known - objective) / best known, the best known being the best of every "
         "solver on that instance; \"best proven\" = a proven-optimal answer reached it. Count gap "
         "= the reference's number of approvals minus the solver's (negative: the solver approved "
         "more flights with less weight).", ""]
    if not e0s:
        return L + ["No E0 rows yet.", ""]
    L += _table([[r["solver"], r["bin"], r["instances"], _f(r["gap_mean_pct"], 3), _f(r["gap_max_pct"], 3),
                  _f(100 * r["at_best_share"], 1), _f(r["count_gap_mean"], 2),
                  _f(100 * r["best_proven_share"], 1), _f(100 * r["proven_share"], 1),
                  r["fallbacks"], _f(r["wall_median_s"], 3), _f(r["wall_max_s"], 2)] for r in e0s],
                ["solver", "vertices", "instances", "gap mean [%]", "gap max [%]", "at best [%]",
                 "count gap mean", "best proven [%]", "proven [%]", "fallbacks", "wall median [s]",
                 "wall max [s]"])
    L.append("")
    g = e0_gaps(e0)
    for s in [x for x in E0_ORDER if x in set(g["solver"])]:
        x = g[g["solver"] == s]
        m, lo, hi = mean_interval(x["gap_pct"].to_numpy(dtype=float))
        over = int((x["wall_s"] > x["time_limit_s"] + 0.4).sum())
        L.append(f"- {s}: mean gap {_f(m, 3)} % [{_f(lo, 3)}, {_f(hi, 3)}] over {len(x)} instances "
                 f"({int((x['gap_pct'] <= 1e-9).sum())} at the best known); "
                 f"{over} solves past limit + 0.4 s.")
    L += [""] + review.e0_clustered_lines(g, [x for x in E0_ORDER if x in set(g["solver"])])
    L += [f"Instances: {g[['run', 'epoch']].drop_duplicates().shape[0]}; proven optimum known "
          f"for {int(g.drop_duplicates(['run', 'epoch'])['best_proven'].sum())} of them.", "",
          f"![E0: mean gap per solver and size bin]({E0_FIGURE})", ""]
    return L


def report_text(d: Path, shown: str | None = None) -> tuple[str, dict]:
    """The report's text and its derived tables; ``shown``: the directory as the report names it
    (default ``d``), so a copy elsewhere rebuilds the same bytes."""
    study = json.loads((d / "study.json").read_text(encoding="utf-8"))
    runs, windows, e0 = _read(d, "runs.csv"), _read(d, "windows.csv"), _read(d, "e0.csv.gz")
    L = ["# The decision study: where optimisation matters", "",
         "Written by `uam_sim.reports.decision_report` from the tables in this directory alone "
         "(`study.json`, `runs.csv`, `windows.csv`, `e0.csv.gz`, `amendments.csv`, "
         "`superseded_runs.csv`): "
         f"`python -m uam_sim.decision_report {shown or d.as_posix()}` writes it again, byte for byte "
         "(src/uam_sim/test/test_decision_study.py checks). The cells are run by "
         "`python -m uam_sim.decision_study --config config/decision-study.yaml --stage "
         "e0|pilot|full` (see its docstring and docs/decision-study/README.md).", ""]
    tables = {}
    L += _record_lines(runs, e0)
    prow = power_rows(runs, study) if runs is not None else []
    tables["power"] = prow
    L += _missing_lines(runs, e0, study, prow)
    L += _steady_state_lines(windows, study)
    L += _power_lines(study, prow)
    comps = comparison_rows(runs, study) if runs is not None else []
    tables["comparisons"] = comps
    for exp in study["experiments"]:
        L += _experiment_lines(d, runs, exp, comps)
    L += _answers_lines(runs, study, prow)
    cup_lines, cup_txt = (review.cuped_lines(review.cuped_rows(runs, study), UNITS, study)
                          if runs is not None else ([], "no runs"))
    L += cup_lines
    if runs is not None:
        L += review.fairness_lines(runs, study)
    L += review.amendments_lines(d, runs, study, prow, cup_txt) if runs is not None else []
    e0s = e0_summary(e0) if e0 is not None else []
    tables["e0_summary"] = e0s
    L += _e0_lines(e0, study, e0s)
    L += ["## The paper's figures", "", paper_figures_text(study), ""]
    if runs is not None:
        L += review.not_answered_lines(runs, study, int(e0["vertices"].max()) if e0 is not None else None,
                                       (Path(d) / "epochs.csv.gz").exists())
    return "\n".join(L).rstrip() + "\n", tables


E0_FIGURE = "figures/e0_gap_by_size.png"


def e0_figure(rows: list, path: Path) -> Path:
    """E0's matched gaps per solver against the size bin (from e0_summary's rows): the mean gap in
    the objective [%] and the mean count gap (reference's approvals minus the solver's)."""
    from .figures import plt, save_figure, style
    df = pd.DataFrame(rows)
    df["lo"] = df["bin"].str.extract(r"\[(\d+),")[0].astype(int)
    fig, axes = plt.subplots(1, 2, figsize=(11, 3.8))
    solvers = [x for x in E0_ORDER if x in set(df["solver"]) and x != "reference"]
    for i, sv in enumerate(solvers):
        x = df[df["solver"] == sv].sort_values("lo")
        st = style(sv, i)
        axes[0].plot(x["lo"], x["gap_mean_pct"].clip(lower=1e-4), label=sv, markersize=4, **st)
        axes[1].plot(x["lo"], x["count_gap_mean"], label=sv, markersize=4, **st)
    axes[0].set_yscale("log")
    axes[0].set_ylabel("mean gap in the objective [%] (0 drawn at 1e-4)")
    axes[1].set_ylabel("mean count gap [flights] (reference - solver)")
    axes[1].axhline(0.0, color="grey", linewidth=0.8)
    for ax in axes:
        ax.set_xscale("log", base=2)
        ax.set_xlabel("instance size bin: vertices from")
        ax.grid(alpha=0.3)
    axes[0].legend(fontsize=7, ncol=2)
    axes[0].set_title("E0: same instances, same limit", fontsize=9)
    path.parent.mkdir(parents=True, exist_ok=True)
    save_figure(fig, path)
    return path


def write_decision_report(d, shown: str | None = None) -> dict:
    d = Path(d)
    text, tables = report_text(d, shown)
    (d / "REPORT.md").write_text(text, encoding="utf-8")
    write_csv(d / "comparisons.csv", tables.get("comparisons") or [])
    write_csv(d / "power.csv", tables.get("power") or [])
    write_csv(d / "e0_summary.csv", tables.get("e0_summary") or [])
    out = {"report": str(d / "REPORT.md")}
    if tables.get("e0_summary"):
        out["e0_figure"] = str(e0_figure(tables["e0_summary"], d / E0_FIGURE))
    return out


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="decision_report", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", nargs="?", default="docs/decision-study")
    args = ap.parse_args(argv)
    d = Path(args.dir)
    if not (d / "study.json").exists():
        print(f"decision_report: {d / 'study.json'}: not found (run uam_sim.studies.decision_study first)",
              file=sys.stderr)
        return 2
    print(write_decision_report(d)["report"])
    return 0


if __name__ == "__main__":
    sys.exit(main())
