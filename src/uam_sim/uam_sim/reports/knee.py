"""The load sweep's section of REPORT.md: the knee of each method, approvals per priority class
and the operators' spread, from the runs' summaries (the columns of ``runs.csv``).

The knee of a method is the lowest rate whose approval rate, averaged over the seeds, falls below
:data:`KNEE_APPROVAL` of the requests; below it (nearly) everything is approved. Per class the
approvals are pooled over the seeds (approved / requested of that class), so a class of a few per
cent is not an average of ratios of a handful of requests each.
"""

from __future__ import annotations

import math
import re

import numpy as np

from .markdown import table_lines

#: the share of the requests approved below which a rate is past the knee
KNEE_APPROVAL = 0.95

_CLASS_KEY = re.compile(r"^requests_prio(\d+)$")


def _num(x) -> float | None:
    """A finite float, or None for a missing, empty or NaN value (a CSV cell or a summary's)."""
    try:
        v = float(x)
    except (TypeError, ValueError):
        return None
    return v if math.isfinite(v) else None


def _pct(x: float | None, nd: int = 1) -> str:
    return "-" if x is None else f"{100.0 * x:.{nd}f}"


def _runs(cells, method: str, rate) -> list:
    return [c["summary"] for c in cells if c["summary"]["method"] == method and c["summary"]["rate"] == rate]


def approval_by_rate(cells, methods: list, rates: list) -> dict:
    """{(method, rate): mean approval rate over the seeds} of the runs present."""
    out = {}
    for m in methods:
        for r in rates:
            vals = [v for v in (_num(s.get("approval_rate")) for s in _runs(cells, m, r)) if v is not None]
            if vals:
                out[(m, r)] = float(np.mean(vals))
    return out


def knee_rows(cells, methods: list, rates: list, threshold: float = KNEE_APPROVAL,
              by: dict | None = None) -> list:
    """Per method: the last rate whose mean approval rate is at least ``threshold`` before the
    first that is below it (the knee), their approval rates and the one at the highest rate.
    A method that never falls below has no knee (None). ``by``: :func:`approval_by_rate`'s
    answer, when the caller has it."""
    by = approval_by_rate(cells, methods, rates) if by is None else by
    rows = []
    for m in methods:
        seen = [r for r in rates if (m, r) in by]
        if not seen:
            continue
        below = [r for r in seen if by[(m, r)] < threshold]
        knee = below[0] if below else None
        before = [r for r in seen if knee is None or r < knee]
        rows.append({"method": m, "last_above": before[-1] if before else None,
                     "rate_last_above": by[(m, before[-1])] if before else None,
                     "knee": knee, "rate_knee": by[(m, knee)] if knee is not None else None,
                     "top": seen[-1], "rate_top": by[(m, seen[-1])]})
    return rows


def priority_classes(cells) -> list:
    """The priority classes the runs' summaries have per-class columns for, ascending."""
    found = set()
    for c in cells:
        for k in c["summary"]:
            hit = _CLASS_KEY.match(k)
            if hit and _num(c["summary"][k]) is not None:
                found.add(int(hit.group(1)))
    return sorted(found)


def class_rows(cells, methods: list, rates: list, classes: list) -> list:
    """Per method and rate, per class: requests, approved (summed over the seeds), approval rate
    pooled over the seeds and the mean departure delay [s] (mean over the seeds' means)."""
    rows = []
    for m in methods:
        for r in rates:
            runs = _runs(cells, m, r)
            if not runs:
                continue
            row = {"method": m, "rate": r, "seeds": len(runs)}
            for c in classes:
                asked = sum(_num(s.get(f"requests_prio{c}")) or 0.0 for s in runs)
                got = sum(_num(s.get(f"approved_prio{c}")) or 0.0 for s in runs)
                delays = [v for v in (_num(s.get(f"delay_mean_s_prio{c}")) for s in runs) if v is not None]
                row[f"requests{c}"] = int(asked)
                row[f"approved{c}"] = int(got)
                row[f"rate{c}"] = got / asked if asked else None
                row[f"delay{c}"] = float(np.mean(delays)) if delays else None
            rows.append(row)
    return rows


def operator_rows(cells, methods: list, rates: list) -> list:
    """Per method and rate with named operators: the least and greatest operator's approval rate
    and their ratio, each the mean over the seeds."""
    rows = []
    for m in methods:
        for r in rates:
            runs = _runs(cells, m, r)
            vals = {k: [v for v in (_num(s.get(f"operator_share_{k}")) for s in runs) if v is not None]
                    for k in ("min", "max", "ratio")}
            if vals["ratio"]:
                rows.append({"method": m, "rate": r, "seeds": len(vals["ratio"]),
                             **{k: float(np.mean(v)) for k, v in vals.items()}})
    return rows


def _md(heads: list, rows: list) -> list:
    return table_lines(rows, heads) + [""]


def _rate_text(rate) -> str:
    return "-" if rate is None else f"{rate:g}"


def knee_section(cells, methods: list, rates: list, interval_s: float) -> list:
    """The report's lines: the approval rate per rate and method, each method's knee, the
    approvals and delays per priority class and the operators' spread."""
    by = approval_by_rate(cells, methods, rates)
    L = ["## The knee, the priority classes and the operators", "",
         f"Approval rate [%] per rate (requests per {interval_s:g} s), the mean over the seeds of "
         f"each run's approved / requested (`runs.csv` approval_rate). The knee of a method is the "
         f"lowest rate below {100 * KNEE_APPROVAL:g} %; below it (nearly) every request is approved.", ""]
    L += _md(["rate", *methods], [[_rate_text(r), *(_pct(by.get((m, r))) for m in methods)] for r in rates])
    knees = knee_rows(cells, methods, rates, by=by)
    L += _md(["method", f"last rate >= {100 * KNEE_APPROVAL:g} %", "approved [%]", "knee (first rate below)",
              "approved [%]", "highest rate", "approved [%]"],
             [[k["method"], _rate_text(k["last_above"]), _pct(k["rate_last_above"]), _rate_text(k["knee"]),
               _pct(k["rate_knee"]), _rate_text(k["top"]), _pct(k["rate_top"])] for k in knees])
    classes = priority_classes(cells)
    if len(classes) > 1:
        L += ["Per priority class (`runs.csv` requests_prio<c>, approved_prio<c>, delay_mean_s_prio<c>): "
              "requests and approvals summed over the seeds, the approval rate pooled over them "
              "(approved / requested), the mean departure delay the mean over the seeds. The "
              "objective is the paper's unless the parameters say otherwise, so a class is "
              "planned like any other by the MWIS methods; FIFO and first-fit serve by class "
              "only with baseline_order priority.", ""]
        heads = ["method", "rate", "seeds"]
        for c in classes:
            heads += [f"class {c} requests", f"class {c} approved [%]", f"class {c} delay [s]"]
        rows = []
        for r in class_rows(cells, methods, rates, classes):
            row = [r["method"], _rate_text(r["rate"]), r["seeds"]]
            for c in classes:
                d = r[f"delay{c}"]
                row += [r[f"requests{c}"], _pct(r[f"rate{c}"]), "-" if d is None else f"{d:.1f}"]
            rows.append(row)
        L += _md(heads, rows)
    ops = operator_rows(cells, methods, rates)
    if ops:
        L += ["Operators (`runs.csv` operator_share_min, _max, _ratio): the least and greatest "
              "operator's approval rate and their ratio, the mean over the seeds.", ""]
        L += _md(["method", "rate", "seeds", "least operator [%]", "greatest operator [%]", "ratio"],
                 [[o["method"], _rate_text(o["rate"]), o["seeds"], _pct(o["min"]), _pct(o["max"]),
                   f"{o['ratio']:.3f}"] for o in ops])
    else:
        L += ["Operators: the demand names none, so `runs.csv`'s operator_share columns are empty.", ""]
    return L
