"""What the decision study's report (:mod:`uam_sim.reports.decision_report`) and its review
(:mod:`uam_sim.reports.decision_review`) share: selecting a comparison's arms from the runs
table, and writing a number."""

from __future__ import annotations

import math

import pandas as pd


def _equal(col: pd.Series, v) -> pd.Series:
    """col == v, numerically when v is a number (a column with blanks reads back as float: 5
    must match 5.0), else as text."""
    if isinstance(v, (int, float)) and not isinstance(v, bool):
        return pd.to_numeric(col, errors="coerce") == float(v)
    return col.astype(str) == str(v)


def _groups(runs: pd.DataFrame, exp: dict, comp: dict) -> list:
    """[(label, {term index: {seed: value}}, scale {seed: value})] of one comparison."""
    rows = runs[runs["experiment"] == exp["name"]]
    if rows.empty:
        return []
    fixed = set()
    for t in comp["terms"]:
        fixed |= set(t["where"])
    free = [k for k in exp["vary"] if k not in fixed]
    keys = (["cell"] if "cell" not in fixed else []) + (["rate"] if "rate" not in fixed else []) + free
    out = []
    combos = rows[keys].drop_duplicates().sort_values(keys).to_dict("records") if keys else [{}]
    for g in combos:
        vals = {}
        for j, t in enumerate(comp["terms"]):
            sel = rows[rows["method"] == t["method"]]
            for k, v in {**g, **t["where"]}.items():
                sel = sel[_equal(sel[k], v)]
            vals[j] = dict(zip(sel["seed"].astype(int), sel[comp["metric"]].astype(float)))
        label = ", ".join(f"{k} {g[k]}" for k in keys) or "all"
        out.append((label, vals))
    return out


def fmt_number(x, nd: int, sign: bool = False) -> str:
    """``x`` with ``nd`` decimals and thousands separators (a sign when ``sign``); "-" for a
    missing or non-finite value."""
    try:
        x = float(x)
    except (TypeError, ValueError):
        return "-"
    if not math.isfinite(x):
        return "-"
    return f"{x:+,.{nd}f}" if sign else f"{x:,.{nd}f}"
