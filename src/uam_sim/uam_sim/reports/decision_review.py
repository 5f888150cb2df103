"""The decision report's sections a reviewer asks for, computed from the same tables.

- :func:`heterogeneity_rows`: per comparison with several groups, the fixed-effect and
  random-effects (DerSimonian-Laird, and its Hartung-Knapp-Sidik-Jonkman t interval) pools of
  the groups' mean relative differences, Cochran's Q and I^2, and whether a pooled claim is
  allowed (:data:`POOL_RULE`).
- :func:`answer_claims`: the claims the Answers make, one per declared comparison (its pooled
  estimate where heterogeneity allows, else each group), duplicates (the same paired
  differences claimed twice) merged, Holm-adjusted over exactly that family.
- :func:`e0_clustered`: E0's mean gaps with intervals clustered by reference run.
- :func:`amendments_lines`: the rules changed and runs re-run after data, with their effect on
  the primary, from ``amendments.csv`` and ``superseded_runs.csv``.
- :func:`cuped_rows`: whether the requests in the window vary between seeds and what CUPED on
  them would do to each primary.
- :func:`fairness_rows`: Jain's index per experiment and method, whether it is at its ceiling,
  and the per-operator min/max ratio it bounds.
"""

from __future__ import annotations

import math

import numpy as np
import pandas as pd

from .decision_groups import _equal, _groups, fmt_number
from .markdown import table_lines as _table
from .stats import (cluster_bootstrap_mean, cuped, holm, jain_min_max_bound,
                    mean_interval, random_effects)

#: A pooled claim is made only when the groups agree: Cochran's Q p-value at least ``q_p`` and
#: I^2 below ``i2_pct`` (the usual "low heterogeneity" reading).
POOL_RULE = {"q_p": 0.10, "i2_pct": 50.0}
#: Holm's family-wise level for the Answers' claims.
ALPHA = 0.05
#: Jain's index at or above this counts as at its ceiling (cannot move by more than 1 %).
JAIN_CEILING = 0.99
CLUSTER_RESAMPLES = 4_000


def _f(x, nd=2, sign=False) -> str:
    return fmt_number(x, nd, sign)


def _p(x) -> str:
    """A p-value: 3 decimals, or '< 0.001'."""
    x = float(x)
    return "< 0.001" if x < 0.001 else f"{x:.3f}"


def group_pairs(runs: pd.DataFrame, exp: dict, comp: dict) -> list:
    """[(label, seeds, d, base)] of one comparison: per group its common seeds, the paired
    differences (units of the metric) and the base arm's values, in seed order."""
    neg = next(j for j, t in enumerate(comp["terms"]) if t["sign"] < 0)
    out = []
    for label, vals in _groups(runs, exp, comp):
        seeds = sorted(set.intersection(*[set(v) for v in vals.values()])) if vals else []
        if not seeds:
            continue
        d = np.array([sum(comp["terms"][j]["sign"] * vals[j][s] for j in vals) for s in seeds])
        base = np.array([vals[neg][s] for s in seeds])
        out.append((label, seeds, d, base))
    return out


def _rel(d, base):
    ok = base != 0
    return 100.0 * d[ok] / base[ok]


# -- heterogeneity -------------------------------------------------------------------------------

def pool(groups: list, level: float) -> dict | None:
    """The pooled row of one comparison's groups (``group_pairs``): stacked t (the study's
    declared pooled row), fixed and random effects of the groups' mean relative differences [%]
    and of their mean differences (units), Q, I^2 and ``allowed``; None with fewer than 2 groups
    of >= 2 seeds; ``reason`` says why no meta-analysis when a group's SE is 0."""
    g = [(lab, s, d, b) for lab, s, d, b in groups if len(s) >= 2]
    if len(g) < 2:
        return None
    rels = [_rel(d, b) for _, _, d, b in g]
    stacked = np.concatenate(rels)
    sm, slo, shi = mean_interval(stacked, level)
    row = {"k": len(g), "pairs": int(stacked.size), "stacked": sm, "stacked_lo": slo,
           "stacked_hi": shi, "groups": [lab for lab, *_ in g]}
    ses = [float(np.std(r, ddof=1) / math.sqrt(r.size)) for r in rels]
    if min(ses) <= 0:
        flat = [lab for (lab, *_), se in zip(g, ses) if se <= 0]
        return {**row, "allowed": False,
                "reason": f"no meta-analysis: every pair of {', '.join(flat)} has the same difference "
                          "(standard error 0)"}
    rel = random_effects([r.mean() for r in rels], ses, level)
    ab_se = [float(np.std(d, ddof=1) / math.sqrt(d.size)) for _, _, d, _ in g]
    ab = random_effects([d.mean() for _, _, d, _ in g], ab_se, level) if min(ab_se) > 0 else None
    allowed = rel["q_p"] >= POOL_RULE["q_p"] and rel["i2_pct"] < POOL_RULE["i2_pct"]
    return {**row, **rel, "abs_fe": ab["fe"] if ab else math.nan,
            "abs_fe_lo": ab["fe_lo"] if ab else math.nan, "abs_fe_hi": ab["fe_hi"] if ab else math.nan,
            "allowed": allowed, "reason": "" if allowed else (
                f"heterogeneity: Q = {_f(rel['q'], 1)} (df {rel['q_df']}, p {_p(rel['q_p'])}), "
                f"I^2 = {_f(rel['i2_pct'], 0)} %")}


def heterogeneity_rows(runs: pd.DataFrame, study: dict) -> list:
    """One row per (experiment, comparison) with >= 2 groups of >= 2 seeds (:func:`pool`)."""
    level = float(study["power"]["level"])
    out = []
    for exp in study["experiments"]:
        for kind in ("primary", "secondary"):
            for comp in exp[kind]:
                p = pool(group_pairs(runs, exp, comp), level)
                if p is not None:
                    out.append({"experiment": exp["name"], "kind": kind, "comparison": comp["name"],
                                "metric": comp["metric"], **p})
    return out


def heterogeneity_lines(rows: list) -> list:
    L = ["## Pooling and heterogeneity", "",
         "Per comparison with several groups (cells, rates, free variants): the declared pooled row "
         "(per-seed relative differences stacked over the groups, t interval), the fixed-effect "
         "(inverse-variance) pool of the groups' mean relative differences, the random-effects pool "
         "(DerSimonian-Laird; its interval with normal quantiles and with the Hartung-Knapp-Sidik-"
         "Jonkman SE and a t quantile on k - 1 df), Cochran's Q and I^2 "
         "(`uam_sim.reports.stats.random_effects`). Rule: a pooled estimate is claimed only when "
         f"Q's p >= {POOL_RULE['q_p']:.2f} and I^2 < {POOL_RULE['i2_pct']:.0f} %; otherwise the "
         "Answers give each group and say the pooled one is not claimed.", ""]
    if not rows:
        return L + ["No comparison with several groups yet.", ""]
    tab = []
    for r in rows:
        meta = "fe" in r
        tab.append([r["experiment"], r["comparison"], r["k"], r["pairs"],
                    f"{_f(r['stacked'], 2, True)} [{_f(r['stacked_lo'], 2, True)}, {_f(r['stacked_hi'], 2, True)}]",
                    f"{_f(r['fe'], 2, True)} [{_f(r['fe_lo'], 2, True)}, {_f(r['fe_hi'], 2, True)}]" if meta else "-",
                    f"{_f(r['re'], 2, True)} [{_f(r['re_lo'], 2, True)}, {_f(r['re_hi'], 2, True)}]" if meta else "-",
                    f"[{_f(r['hk_lo'], 2, True)}, {_f(r['hk_hi'], 2, True)}]" if meta else "-",
                    f"{_f(r['q'], 1)} ({r['q_df']})" if meta else "-", _p(r["q_p"]) if meta else "-",
                    _f(r["i2_pct"], 0) if meta else "-", "yes" if r["allowed"] else "no"])
    L += _table(tab, ["experiment", "comparison", "groups", "pairs", "stacked [%]",
                      "fixed effect [%]", "random effects DL [%]", "random effects HKSJ [%]",
                      "Q (df)", "Q's p", "I^2 [%]", "pooled claimed"])
    return L + [""]


# -- the Answers' claims and their Holm family ----------------------------------------------------

def _t_p(d: np.ndarray) -> float:
    from scipy.stats import ttest_1samp
    if d.size < 2:
        return math.nan
    if np.std(d) == 0:
        return 1.0 if np.all(d == 0) else 0.0
    return float(ttest_1samp(d, 0.0).pvalue)


def answer_claims(runs: pd.DataFrame, study: dict) -> list:
    """The claims of the Answers, in declaration order: per declared comparison either its
    pooled estimate (several groups, heterogeneity within :data:`POOL_RULE`; fixed effect, z
    test) or each group with >= 2 seeds (paired t test). A claim whose paired differences are
    those of an earlier claim (the same runs compared twice under two names) is merged into it
    (``same_as``) and not counted again. ``p_holm``: Holm over the distinct claims' p-values;
    ``claimed``: p_holm < :data:`ALPHA`."""
    level = float(study["power"]["level"])
    out, seen = [], {}
    for exp in study["experiments"]:
        for kind in ("primary", "secondary"):
            for comp in exp[kind]:
                groups = group_pairs(runs, exp, comp)
                pooled = pool(groups, level)
                base = {"experiment": exp["name"], "kind": kind, "comparison": comp["name"],
                        "metric": comp["metric"], "pool": pooled}
                if pooled is not None and pooled["allowed"]:
                    out.append({**base, "group": "pooled", "rel": pooled["fe"],
                                "rel_lo": pooled["fe_lo"], "rel_hi": pooled["fe_hi"],
                                "abs": pooled["abs_fe"], "abs_lo": pooled["abs_fe_lo"],
                                "abs_hi": pooled["abs_fe_hi"], "p": pooled["fe_p"], "seeds": pooled["pairs"]})
                    continue
                for label, seeds, d, b in groups:
                    if len(seeds) < 2:
                        continue
                    key = (exp["name"], comp["metric"], tuple(seeds), tuple(np.round(d, 9)))
                    m, lo, hi = mean_interval(d, level)
                    rm, rlo, rhi = mean_interval(_rel(d, b), level)
                    row = {**base, "group": label, "rel": rm, "rel_lo": rlo, "rel_hi": rhi,
                           "abs": m, "abs_lo": lo, "abs_hi": hi, "p": _t_p(d), "seeds": len(seeds)}
                    if key in seen:
                        row["same_as"] = seen[key]
                    else:
                        seen[key] = f"{kind} `{comp['name']}` ({label})"
                    out.append(row)
    fam = [r for r in out if "same_as" not in r and math.isfinite(r["p"])]
    for r, a in zip(fam, holm([r["p"] for r in fam])):
        r["p_holm"] = a
        r["claimed"] = a < ALPHA and (r["rel_lo"] > 0 or r["rel_hi"] < 0)
    return out


def answer_lines(claims: list, prow: list, units: dict) -> list:
    """The Answers' lines of one experiment's claims (in order), the pooled-not-claimed notes
    before the groups that replace it, and the primary's MDE from the power rows."""
    L = []
    done, mde_done = set(), set()
    for r in claims:
        name = (r["experiment"], r["kind"], r["comparison"])
        head = f"- {r['experiment']} {r['kind']} `{r['comparison']}` ({r['metric']}"
        if name not in done and r["group"] != "pooled" and r["pool"] is not None:
            pl = r["pool"]
            meta = (f": fixed effect {_f(pl['fe'], 2, True)} % [{_f(pl['fe_lo'], 2, True)}, "
                    f"{_f(pl['fe_hi'], 2, True)}], random effects {_f(pl['re'], 2, True)} % "
                    f"[{_f(pl['re_lo'], 2, True)}, {_f(pl['re_hi'], 2, True)}] (HKSJ "
                    f"[{_f(pl['hk_lo'], 2, True)}, {_f(pl['hk_hi'], 2, True)}])") if "fe" in pl else ""
            L.append(f"{head}): the pooled estimate is not claimed ({pl['reason']}){meta}; "
                     "each group:")
        done.add(name)
        unit = units.get(r["metric"], "")
        where = "pooled, fixed effect" if r["group"] == "pooled" else r["group"]
        txt = (f"{head}, {where}): {_f(r['abs'], 2, True)} {unit} [{_f(r['abs_lo'], 2, True)}, "
               f"{_f(r['abs_hi'], 2, True)}], {_f(r['rel'], 2, True)} % [{_f(r['rel_lo'], 2, True)}, "
               f"{_f(r['rel_hi'], 2, True)}]")
        if r["group"] == "pooled":
            pl = r["pool"]
            txt += (f" (random effects {_f(pl['re'], 2, True)} % [{_f(pl['re_lo'], 2, True)}, "
                    f"{_f(pl['re_hi'], 2, True)}]; Q = {_f(pl['q'], 1)}, df {pl['q_df']}, p "
                    f"{_p(pl['q_p'])}; I^2 = {_f(pl['i2_pct'], 0)} %; {r['seeds']} pairs)")
        else:
            txt += f" ({r['seeds']} seeds)"
        if "same_as" in r:
            txt += f": the same paired runs as {r['same_as']}, counted once in the Holm family."
        elif "p_holm" not in r:
            txt += ": no p-value."
        elif r["claimed"]:
            txt += (f": {'above' if r['rel_lo'] > 0 else 'below'} 0 (p {_p(r['p'])}, Holm-adjusted "
                    f"{_p(r['p_holm'])}).")
        elif r["rel_lo"] > 0 or r["rel_hi"] < 0:
            txt += (f": the interval excludes 0 but the Holm-adjusted p is {_p(r['p_holm'])} "
                    f"(>= {ALPHA}): not claimed.")
        else:
            half = (r["rel_hi"] - r["rel_lo"]) / 2
            txt += (f": not resolved at this power (Holm-adjusted p {_p(r['p_holm'])}; half-width "
                    f"{_f(half, 2)} %), an effect of that size neither shown nor excluded; not "
                    "evidence of no effect.")
        if r["kind"] == "primary" and name not in mde_done:
            txt += _mde_text(r, prow, units)
            mde_done.add(name)
        L.append(txt)
    return L


def _mde_text(r: dict, prow: list, units: dict) -> str:
    pr = [p for p in prow if p["experiment"] == r["experiment"] and p["comparison"] == r["comparison"]
          and p.get("decides")]
    if not pr or not math.isfinite(float(pr[0].get("mde_now", math.nan))):
        return ""
    p = pr[0]
    pooled = str(p["group"]).startswith("pooled")
    u = "%" if pooled else units.get(r["metric"], "")
    return (f" MDE (80 % power) at the {p['seeds_run']} {'pairs' if pooled else 'seeds'} run "
            f"({p['group']}): {_f(p['mde_now'], 2)} {u}; at the cap of {p['max_seeds']} seeds"
            f"{' per group' if pooled else ''}: {_f(p['mde_at_cap'], 2)} {u}.")


def holm_family_text(claims: list) -> str:
    fam = [r for r in claims if "p_holm" in r]
    dup = [r for r in claims if "same_as" in r]
    return (f"Holm over exactly the {len(fam)} distinct claims below (family-wise {ALPHA}; "
            f"{len(dup)} lines repeat the paired runs of an earlier claim and are not counted "
            f"again); {sum(r['claimed'] for r in fam)} of them hold after the adjustment. A pooled "
            "claim is tested with its fixed-effect z test, a group with its paired t test.")


# -- E0 clustered by run --------------------------------------------------------------------------

def graph_families(g: pd.DataFrame) -> dict:
    """{run: family}: reference runs whose instances are the same graphs (the same vertex and
    edge counts at every epoch of the reference method) share a family, named by its first run."""
    ref = g[g["solver"] == g["solver"].iloc[0]].sort_values(["run", "epoch"])
    sig = {run: tuple(zip(x["vertices"], x["edges"])) for run, x in ref.groupby("run", sort=True)}
    fam, first = {}, {}
    for run, s in sig.items():
        first.setdefault(s, run)
        fam[run] = first[s]
    return fam


def e0_clustered(g: pd.DataFrame, solvers: list, level: float = 0.95) -> list:
    """Per solver: the mean gap [%] with its instance-level t interval, the cluster bootstrap
    interval by reference run and by graph family (:func:`graph_families`)."""
    fam = graph_families(g)
    out = []
    for s in solvers:
        x = g[g["solver"] == s]
        v = x["gap_pct"].to_numpy(dtype=float)
        m, lo, hi = mean_interval(v, level)
        _, clo, chi = cluster_bootstrap_mean(v, x["run"].astype(str), level, CLUSTER_RESAMPLES)
        _, flo, fhi = cluster_bootstrap_mean(v, x["run"].map(fam).astype(str), level, CLUSTER_RESAMPLES)
        out.append({"solver": s, "instances": len(x), "mean": m, "t_lo": lo, "t_hi": hi,
                    "run_lo": clo, "run_hi": chi, "family_lo": flo, "family_hi": fhi})
    return out


def e0_clustered_lines(g: pd.DataFrame, solvers: list, level: float = 0.95) -> list:
    rows = e0_clustered(g, solvers, level)
    fam = graph_families(g)
    n_runs, n_fam = len(fam), len(set(fam.values()))
    shared = sorted({f for f in fam.values() if list(fam.values()).count(f) > 1})
    share_txt = "; ".join(f"{', '.join(r for r in sorted(fam) if fam[r] == f)}" for f in shared)
    L = [f"Instances are not independent: the {n_runs} reference runs are {n_fam} families of "
         "identical graphs (the same vertex and edge counts at every epoch"
         + (f"; sharing: {share_txt}" if shared else "") + "), and the instances of one run share "
         "its traffic. The intervals below resample whole clusters (cluster bootstrap, "
         f"{CLUSTER_RESAMPLES:,} resamples, seed 0, percentile interval) by run and by family; "
         "the instance-level t interval, which treats every instance as independent, is beside "
         "them for comparison.", ""]
    L += _table([[r["solver"], r["instances"], _f(r["mean"], 3),
                  f"[{_f(r['t_lo'], 3)}, {_f(r['t_hi'], 3)}]",
                  f"[{_f(r['run_lo'], 3)}, {_f(r['run_hi'], 3)}]",
                  f"[{_f(r['family_lo'], 3)}, {_f(r['family_hi'], 3)}]"] for r in rows],
                ["solver", "instances", "mean gap [%]", "instances independent (t)",
                 f"clustered by run ({n_runs})", f"clustered by graph family ({n_fam})"])
    samplers = [s for s in ("sa", "tabu", "qpu-emulator") if s in set(g["solver"])]
    if len(samplers) >= 2:
        w = g[g["solver"].isin(samplers)].pivot_table(index=["run", "epoch"], columns="solver",
                                                      values="objective")
        same = np.all(np.isclose(w[samplers].to_numpy(), w[[samplers[0]]].to_numpy()), axis=1)
        L += ["", f"{', '.join(samplers)} return the same objective on {_f(100 * same.mean(), 1)} % "
              f"of the {len(w)} instances: after the pipeline's reductions the sampler seldom decides."]
    return L + [""]


# -- amendments after seeing data -------------------------------------------------------------------

def _primary_answer(runs: pd.DataFrame, study: dict, exp_name: str, comp_name: str) -> str:
    exp = next(e for e in study["experiments"] if e["name"] == exp_name)
    comp = next(c for c in exp["primary"] + exp["secondary"] if c["name"] == comp_name)
    level = float(study["power"]["level"])
    groups = group_pairs(runs, exp, comp)
    if not groups:
        return "no paired seeds"
    rel = np.concatenate([_rel(d, b) for _, _, d, b in groups])
    m, lo, hi = mean_interval(rel, level)
    return f"{_f(m, 2, True)} % [{_f(lo, 2, True)}, {_f(hi, 2, True)}] ({rel.size} pairs)"


def _rerun_effect(runs, superseded, study, a) -> str:
    keys = ["experiment", "cell", "variant", "method", "rate", "seed"]
    old = superseded[superseded["experiment"] == a["experiment"]]
    if old.empty:
        return "no superseded rows recorded"
    idx = runs.set_index(keys).index
    oidx = old.set_index(keys).index
    before = pd.concat([runs[~idx.isin(oidx)], old], ignore_index=True)
    exp = next(e for e in study["experiments"] if e["name"] == a["experiment"])
    comp = next(c for c in exp["primary"] if c["name"] == a["comparison"])
    arms = {}
    for t in comp["terms"]:
        sel = old[old["method"] == t["method"]]
        for k, v in t["where"].items():
            sel = sel[_equal(sel[k], v)]
        arms["treatment" if t["sign"] > 0 else "control"] = len(sel)
    moved = pd.merge(old, runs, on=keys, suffixes=("_old", "_new"))
    m = comp["metric"]
    ups = int((moved[f"{m}_new"] > moved[f"{m}_old"]).sum())
    return (f"{len(old)} runs re-run ({arms.get('treatment', 0)} in the primary's treatment arm, "
            f"{arms.get('control', 0)} in its control arm; `{m}` rose in {ups} of {len(moved)}); "
            f"the primary `{a['comparison']}` was {_primary_answer(before, study, a['experiment'], a['comparison'])} "
            f"with the earlier rows and is {_primary_answer(runs, study, a['experiment'], a['comparison'])} now")


def _per_effect(prow: list, a) -> str:
    mine = [r for r in prow if r["experiment"] == a["experiment"] and r["comparison"] == a["comparison"]]
    cells = [r for r in mine if not str(r["group"]).startswith("pooled")]
    pooled = [r for r in mine if str(r["group"]).startswith("pooled")]
    need = [r["seeds_needed"] for r in cells if isinstance(r["seeds_needed"], int)]
    if not (need and pooled):
        return "not computable from the power rows"
    cap = cells[0]["max_seeds"]
    return (f"per cell the primary would need {max(need)} seeds (capped at {cap}: "
            f"{min(max(need), cap)}); pooled it needs {pooled[0]['seeds_needed']} per group, and "
            "the Answers' primary became the pooled row instead of one line per cell")


def amendments_lines(d, runs: pd.DataFrame, study: dict, prow: list, cuped_txt: str) -> list:
    """The section "Amendments after seeing data": each rule changed or run re-run after data
    (``amendments.csv``: commit, date, the look at the data before it) with its effect on the
    primary, computed here (re-runs from ``superseded_runs.csv``)."""
    from pathlib import Path
    L = ["## Amendments after seeing data", ""]
    p = Path(d) / "amendments.csv"
    if not p.exists():
        return L + ["No amendments recorded (`amendments.csv` absent).", ""]
    am = pd.read_csv(p, dtype=str).fillna("")
    sp = Path(d) / "superseded_runs.csv"
    superseded = pd.read_csv(sp) if sp.exists() else pd.DataFrame()
    L += ["Each change below was made after the data named beside it had been seen, so none of "
          "them was declared before running; the declared lists above show the config as it is "
          "now. Commits and dates from git history (`git log -- docs/decision-study "
          "config/decision-study.yaml`), effects computed from the tables.", ""]
    rows = []
    for a in am.to_dict("records"):
        if a["kind"] == "rerun":
            eff = _rerun_effect(runs, superseded, study, a)
        elif a["comparison"] and a["change"].startswith("`per: pooled`"):
            eff = _per_effect(prow, a)
        elif "CUPED" in a["change"]:
            eff = cuped_txt
        elif a["experiment"] == "E0":
            eff = "none on the primaries (E0 has none); it sets E0's instances"
        else:
            eff = "none on the primaries' values (first-fit flies the same flights under every objective; tested)"
        rows.append([a["date"][:10], f"`{a['commit']}`", a["kind"], a["experiment"],
                     a["comparison"] or "-", a["change"],
                     f"`{a['after_look_commit']}` {a['after_look_date'][:16].replace('T', ' ')}: {a['after_look']}",
                     eff])
    L += _table(rows, ["date", "commit", "kind", "experiment", "comparison", "change",
                       "after seeing", "effect on the primary"])
    return L + [""]


def amended(d, exp_name: str, comp_name: str) -> list:
    """The amendments of one comparison (commits), for its declaration line."""
    from pathlib import Path
    p = Path(d) / "amendments.csv"
    if not p.exists():
        return []
    am = pd.read_csv(p, dtype=str).fillna("")
    return am[(am["experiment"] == exp_name) & (am["comparison"] == comp_name)
              & (am["kind"] == "rule")]["commit"].tolist()


# -- CUPED --------------------------------------------------------------------------------------------

COVARIATE = "requests_ss"
#: Below this share of variance removed, CUPED is not worth its degree of freedom.
CUPED_MIN_REDUCTION = 0.10


def cuped_rows(runs: pd.DataFrame, study: dict) -> list:
    """Per primary comparison and group: how the covariate (the requests in the window, the same
    for every arm of one seed) varies over the seeds, and CUPED's adjusted mean difference, t
    interval (n - 2 df) and variance reduction."""
    from scipy.stats import t as student_t
    level = float(study["power"]["level"])
    out = []
    for exp in study["experiments"]:
        for comp in exp["primary"]:
            neg = next(t for t in comp["terms"] if t["sign"] < 0)
            for label, seeds, d, _b in group_pairs(runs, exp, comp):
                sel = runs[(runs["experiment"] == exp["name"]) & (runs["method"] == neg["method"])]
                for part in label.split(", "):
                    k, _, v = part.partition(" ")
                    if k in sel and k not in neg["where"]:
                        sel = sel[_equal(sel[k], _num(v))]
                for k, v in neg["where"].items():
                    sel = sel[_equal(sel[k], v)]
                x = sel.drop_duplicates("seed").set_index("seed")[COVARIATE].reindex(seeds).to_numpy(float)
                row = {"experiment": exp["name"], "comparison": comp["name"], "group": label,
                       "seeds": len(seeds), "x_min": np.nanmin(x), "x_max": np.nanmax(x),
                       "x_sd": float(np.nanstd(x, ddof=1)) if len(seeds) > 1 else math.nan}
                if len(seeds) >= 3 and np.all(np.isfinite(x)):
                    c = cuped(d, x)
                    n = len(seeds)
                    half = float(student_t.ppf(0.5 + level / 2, n - 2)
                                 * np.std(c["adjusted"], ddof=1) / math.sqrt(n))
                    m0, lo0, hi0 = mean_interval(d, level)
                    row.update(theta=c["theta"], reduction=c["variance_reduction"], mean=m0,
                               half=(hi0 - lo0) / 2, adj_mean=float(c["adjusted"].mean()),
                               adj_half=half)
                out.append(row)
    return out


def _num(v: str):
    try:
        return float(v)
    except ValueError:
        return v


def cuped_lines(rows: list, units: dict, study: dict) -> tuple:
    """(lines, one-sentence summary for the amendments table)."""
    L = ["## Variance reduction on the demand (CUPED)", "",
         f"Covariate: `{COVARIATE}`, the requests whose window lies in the steady state, the same "
         "for every arm of one seed (common random numbers). CUPED subtracts theta (x - mean x) "
         "from each paired difference, theta = cov(d, x) / var(x); its interval is a t interval "
         f"on n - 2 df. Rule: applied only if it removes at least {CUPED_MIN_REDUCTION:.0%} of the "
         "variance, and then as a sensitivity beside the declared, unadjusted primary (it was not "
         "declared before the data).", ""]
    if not rows:
        return L + ["No primary with paired seeds yet.", ""], "no primary rows yet"
    tab = []
    for r in rows:
        tab.append([r["experiment"], r["comparison"], r["group"], r["seeds"],
                    f"{_f(r['x_min'], 0)}-{_f(r['x_max'], 0)}", _f(r["x_sd"], 1),
                    _f(r.get("theta"), 3, True), _f(100 * r.get("reduction", math.nan), 1),
                    f"{_f(r.get('mean'), 2, True)} +- {_f(r.get('half'), 2)}",
                    f"{_f(r.get('adj_mean'), 2, True)} +- {_f(r.get('adj_half'), 2)}"])
    L += _table(tab, ["experiment", "primary", "group", "seeds", "requests in window (min-max)",
                      "SD", "theta", "variance removed [%]", "unadjusted", "CUPED"])
    varying = [r for r in rows if r["x_sd"] > 0]
    fitted = [r for r in rows if "reduction" in r]
    best = max(fitted, key=lambda r: r["reduction"]) if fitted else None
    if not varying:
        s = "the requests in the window do not vary between seeds in any primary group: nothing to adjust on"
    else:
        s = (f"the requests in the window vary between seeds in {len(varying)} of {len(rows)} primary "
             f"groups (SD up to {_f(max(r['x_sd'] for r in varying), 1)}), so the premise of zero "
             "variance is false")
        if best is not None:
            worth = best["reduction"] >= CUPED_MIN_REDUCTION
            s += (f"; CUPED removes at most {_f(100 * best['reduction'], 1)} % of the paired "
                  f"variance ({best['experiment']} {best['group']}), "
                  + ("so it is shown above as a sensitivity, the primary unchanged" if worth
                     else f"under the {CUPED_MIN_REDUCTION:.0%} rule: not applied"))
    return L + ["", s[0].upper() + s[1:] + ".", ""], s


# -- fairness -----------------------------------------------------------------------------------------

def fairness_lines(runs: pd.DataFrame, study: dict) -> list:
    ops = list(study.get("base", {}).get("operators") or [])
    L = ["## Metrics that can move", ""]
    if "jain_index" not in runs or not runs["jain_index"].notna().any():
        return L + ["No Jain index in runs.csv.", ""]
    rows = []
    for (e, m), x in runs.groupby(["experiment", "method"], sort=True):
        j = x["jain_index"].dropna()
        if j.empty:
            continue
        bound = jain_min_max_bound(float(j.min()), len(ops)) if len(ops) >= 2 else math.nan
        rows.append([e, m, len(j), _f(j.min(), 4), _f(j.max(), 4),
                     _f(100 * (j >= JAIN_CEILING).mean(), 1), _f(bound, 3)])
    L += _table(rows, ["experiment", "method", "runs", "Jain min", "Jain max",
                       f"runs at the ceiling (>= {JAIN_CEILING}) [%]",
                       "per-operator min/max ratio at least"])
    j = runs.dropna(subset=["jain_index"])
    by = j.groupby("method")["jain_index"].min()
    ceil = [m for m, v in by.items() if v >= JAIN_CEILING]
    below = [f"{m} (down to {_f(v, 4)})" for m, v in by.items() if v < JAIN_CEILING]
    L += ["", f"Jain's index of the {len(ops)} operators' approval shares is at its ceiling "
          f"(>= {JAIN_CEILING}) in every run of {', '.join(ceil) or 'no method'}: there it cannot "
          "show a difference between methods"
          + (f"; below the ceiling in some runs of {', '.join(below)}" if below else "") + ". "
          "The per-operator approval rates themselves are not in runs.csv; with "
          f"{len(ops)} operators the index bounds their min/max ratio from below (the last column, "
          "`uam_sim.reports.stats.jain_min_max_bound`); the ratio itself needs per-operator "
          "counts (new runs). Absolute effects are given beside relative ones in the Answers.", ""]
    return L


#: the report that answers what E0's instances are too small for (uam_sim.studies.large_instances)
LARGE_INSTANCES_REPORT = "docs/large-instances/REPORT.md"
#: the load sweeps (docs/<dir>, config/load-sweep*.yaml): the rates, arms and per-class
#: metrics E1-E3 lack, on the three airspaces
LOAD_SWEEPS = (("load-sweep-paper", "Singapore, the paper's model"),
               ("load-sweep", "layered Singapore, mode both"),
               ("load-sweep-city", "the synthetic city, mode both"))


def not_answered_lines(runs: pd.DataFrame, study: dict, e0_max_vertices: int | None = None,
                       epoch_series: bool = False) -> list:
    """What the committed tables cannot answer, each with what it needs; a column's absence is
    read from runs.csv, not assumed (``epoch_series``: whether epochs.csv.gz is there)."""
    cols = set(runs.columns)
    rates = sorted({r for e in study["experiments"] for c in e["cells"] for r in c["rates"]})
    methods = sorted({m for e in study["experiments"] for m in e["methods"]})
    sweeps = ", ".join(f"[{label}](../{d}/REPORT.md)" for d, label in LOAD_SWEEPS)
    rerun = ("in E1-E3 themselves they need the experiments run again at one code version, "
             "every arm (`--stage full`, hours on 2 cores)")
    items = []
    if not any(c.startswith("approved_ss_prio") for c in cols):
        items.append("Per-class approvals (runs.csv has p95 delay per priority class, no approvals "
                     f"per class): answered beside E1-E3 by the load sweeps ({sweeps}: approvals "
                     f"and delay per priority class, from their own runs.csv); {rerun}.")
    if not any(c.startswith("approval_rate_op") or c.startswith("approved_ss_op") for c in cols):
        items.append("Per-operator approval rates and their min/max ratio (runs.csv has Jain's "
                     "index only; its bound is above): new runs recording them (the runner's "
                     "summaries now carry them, `operator_share_min/max/ratio`; the load sweeps' "
                     "demand names no operator).")
    if "greedy" not in methods:
        items.append(f"Weighted greedy as a run-level arm (run-level methods: {', '.join(methods)}; "
                     f"greedy is in E0 only): answered beside E1-E3 by the load sweeps ({sweeps}: "
                     "weighted greedy beside first-fit, auto and FIFO; first-fit by priority in "
                     f"the paper's model and the city, in arrival order on layered Singapore); "
                     f"{rerun}.")
    items.append(f"The knee: run-level rates are {', '.join(map(str, rates))} only; the load sweeps "
                 f"({sweeps}) run from where every request is approved to saturation and locate "
                 "each method's knee from their tables.")
    items.append("Where optimisation pays on the large city's instances (>= 10,000 vertices) and "
                 "re-planning after a restriction: beyond E0, whose largest instance has "
                 f"{e0_max_vertices if e0_max_vertices is not None else 'no'} vertices; answered "
                 f"from their own tables in [{LARGE_INSTANCES_REPORT}](../large-instances/REPORT.md) (the city-30k's epochs "
                 "solved by every backend, and MWIS against first-fit re-planning).")
    if not epoch_series:
        items.append("Per-epoch series from which the steady-state windows re-derive: not "
                     "committed with these runs (windows.csv holds the truncations only; the "
                     "cells that had them are gone). The tables stage writes them "
                     "(`epochs.csv.gz`, re-derived by `decision_study.windows_from_epoch_rows`) "
                     "for every run it collects, so a rerun commits them.")
    return ["## Not answered from these tables", ""] + [f"- {t}" for t in items] + [""]
