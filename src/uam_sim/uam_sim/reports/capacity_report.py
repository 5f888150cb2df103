"""The capacity study's report and figures, from its tables alone.

    python -m uam_sim.capacity_report docs/capacity-study

Reads ``runs.csv``, ``epochs.csv.gz``, ``flights.csv.gz``, ``instances.csv`` and
``report_inputs.json`` (written by :mod:`uam_sim.studies.capacity_study`) and writes ``REPORT.md`` and
``figures/``. Every comparison is paired per seed (the demand of a seed is the same for every
method and every airspace mode of an arm: the generator draws from the aerodrome ids, which the
flat and layered networks share), with the 95 % Student-t interval of ``uam_sim.reports.stats``; a
difference is called supported only when its interval excludes 0.
"""

from __future__ import annotations

import argparse
import json
import math
import sys
from pathlib import Path

import numpy as np
import pandas as pd

from .figures import STYLE, mean_ci, plt, save_figure
from .markdown import table_lines
from .stats import paired

MODES = ["paper", "slots", "levels", "both"]
MODE_TEXT = {"paper": "paper (one level, depart at the epoch)", "slots": "+ slots (5 s)",
             "levels": "+ levels (4, cylinder 100/30 m)", "both": "+ slots + levels"}
BASE_ORDER = ["fifo", "firstfit", "greedy", "auto", "exact", "sa", "tabu", "qpu-emulator", "qpu"]


def read_csv(path: Path) -> list:
    """Rows of a CSV as dicts of text (for callers that only pass them on)."""
    return pd.read_csv(path).to_dict("records") if Path(path).exists() else []


def _order(methods) -> list:
    return sorted(set(methods), key=lambda m: (BASE_ORDER.index(m) if m in BASE_ORDER else 99, m))


def ref_method(df) -> str:
    """The MWIS method the per-mode figures show: auto where it ran, else the first MWIS method."""
    methods = _order(df.method)
    mwis = [m for m in methods if m not in ("fifo", "firstfit")]
    return "auto" if "auto" in mwis else (mwis[0] if mwis else methods[0])


def _modes(df) -> list:
    return [m for m in MODES if m in set(df["mode"])]


def _fmt(x, nd=1) -> str:
    if x is None or (isinstance(x, float) and not math.isfinite(x)):
        return "-"
    return f"{x:,.{nd}f}"


def _ci(p, nd=1) -> str:
    if p.n < 2 or not math.isfinite(p.lo):
        return f"{p.mean:+,.{nd}f} ({p.n} seed{'s' if p.n != 1 else ''}: no interval)"
    return f"{p.mean:+,.{nd}f} [{p.lo:+,.{nd}f}, {p.hi:+,.{nd}f}] ({p.positive}+ / {p.negative}-)"


def _table(rows: list, heads: list) -> str:
    return "\n".join(table_lines(rows, heads))


def per_seed(runs: pd.DataFrame, arm: str, mode: str, method: str, rate, col: str = "approved") -> dict:
    sel = runs[(runs.arm == arm) & (runs["mode"] == mode) & (runs.method == method) & (runs.rate == rate)]
    return {int(s): float(v) for s, v in zip(sel.seed, sel[col])}


def compare(runs, arm, rate, a, b, col="approved", relative=False):
    """Paired (a - b) per seed; a and b are (mode, method) pairs. None when no common seed."""
    xa = per_seed(runs, arm, a[0], a[1], rate, col)
    xb = per_seed(runs, arm, b[0], b[1], rate, col)
    if not set(xa) & set(xb):
        return None
    return paired(xa, xb, relative=relative)


# -- figures -------------------------------------------------------------------------------------

def _style(m, i):
    mk, ls, col = STYLE.get(m, ("o", "-", f"C{i % 10}"))
    if m == "auto":
        mk, ls, col = "D", "-", "black"
    return {"marker": mk, "linestyle": ls, "color": col}


def approvals_figure(runs: pd.DataFrame, path: Path) -> Path:
    """Approved flights per airspace mode, one panel per (network, rate) (arms on the same network
    share a panel, e.g. the annealers beside the core methods), a line per method (mean and 95 % CI
    over seeds, slightly offset per method so the bars do not hide each other)."""
    panels = [(n, r) for n in dict.fromkeys(runs.network) for r in sorted(runs[runs.network == n].rate.unique())]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.6 * len(panels), 3.8), squeeze=False)
    for ax, (net, rate) in zip(axes[0], panels):
        sub = runs[(runs.network == net) & (runs.rate == rate)]
        modes = _modes(sub)
        methods = _order(sub.method)
        for i, m in enumerate(methods):
            s = sub[sub.method == m]
            xs = [j for j, md in enumerate(modes) if (s["mode"] == md).any()]
            ys = [mean_ci(s[s["mode"] == modes[j]].approved) for j in xs]
            x = np.array(xs, dtype=float) + (i - (len(methods) - 1) / 2) * 0.05
            ax.errorbar(x, [y[0] for y in ys], yerr=[[y[0] - y[1] for y in ys], [y[2] - y[0] for y in ys]],
                        label=m, capsize=2, markersize=5, **_style(m, i))
        ax.set_xticks(range(len(modes)), modes)
        ax.set_title(f"{net}, rate {rate} / 30 s", fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    axes[0][0].set_ylabel("approved flights per run")
    save_figure(fig, path)
    return path


def approval_share_figure(runs: pd.DataFrame, path: Path, interval_s: float = 30.0) -> Path:
    """Share of requests approved against offered load [requests/h], per mode (auto or the best
    MWIS method present) and shortest FIFO."""
    nets = list(dict.fromkeys(runs.network))
    flat = runs.network
    fig, axes = plt.subplots(1, len(nets), figsize=(4.5 * len(nets), 3.6), squeeze=False)
    for ax, net in zip(axes[0], nets):
        sub = runs[flat == net]
        for j, mode in enumerate(_modes(sub)):
            for m, ls in ((ref_method(sub), "-"), ("firstfit", "--"), ("fifo", ":")):
                s = sub[(sub["mode"] == mode) & (sub.method == m)]
                if s.empty:
                    continue
                g = s.groupby("rate").approval_rate.mean()
                # the colour says the mode, the marker and line the method (a marker per mode
                # drew auto, first-fit and FIFO of one mode alike)
                ax.plot(g.index * 3600.0 / interval_s, 100 * g.values, linestyle=ls, marker=_style(m, j)["marker"],
                        color=f"C{j}", label=f"{mode} {m}")
        ax.set_xlabel("offered load [requests / h]")
        ax.set_title(net, fontsize=8)
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6, ncol=2)
    axes[0][0].set_ylabel("requests approved [%]")
    save_figure(fig, path)
    return path


def variables_figure(epochs: pd.DataFrame, path: Path, k: int = 5, window_s: float = 60.0,
                     interval_s: float = 30.0, slot_s: float = 5.0) -> Path:
    """MWIS variables (conflict-graph vertices) per epoch by mode and rate (box plots, log y,
    outliers shown) with the bound k x (eligible requests) x (departure times)."""
    ref = ref_method(epochs)
    e = epochs[(epochs.method == ref) & (epochs.vertices > 0)]
    arms = list(e.arm.unique()) or list(epochs.arm.unique())
    fig, axes = plt.subplots(1, len(arms), figsize=(5.0 * len(arms), 3.8), squeeze=False)
    for ax, arm in zip(axes[0], arms):
        sub = e[e.arm == arm]
        data, labels, bounds = [], [], []
        for mode in _modes(sub):
            for rate in sorted(sub.rate.unique()):
                v = sub[(sub["mode"] == mode) & (sub.rate == rate)].vertices.values
                if v.size:
                    data.append(v)
                    labels.append(f"{mode}\n{rate}")
                    slots = (1 + int(window_s // slot_s)) if mode in ("slots", "both") else 1
                    bounds.append(k * rate * (1 + window_s / interval_s) * slots)
        ax.boxplot(data, showfliers=True, flierprops={"markersize": 2})
        ax.plot(range(1, len(bounds) + 1), bounds, "r_", markersize=14, label="bound k x eligible x departure times")
        ax.set_yscale("log")
        ax.set_xticks(range(1, len(labels) + 1), labels, fontsize=7)
        ax.set_title(f"{arm}: MWIS variables per epoch ({ref})", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("vertices (log)")
    axes[0][-1].legend(fontsize=7)
    save_figure(fig, path)
    return path


def size_figure(inst: pd.DataFrame, epochs: pd.DataFrame, path: Path) -> Path:
    """Solve time and optimality gap against instance size per backend (the instance study:
    same instances, same limit, deadlines enforced), and the in-loop solve time per epoch."""
    fig, axes = plt.subplots(1, 3, figsize=(14, 3.9))
    for i, b in enumerate(_order(inst.backend)):
        s = inst[inst.backend == b].sort_values("vertices")
        st = _style(b, i)
        axes[0].plot(s.vertices, 1e3 * s.wall_s, linestyle="none", marker=st["marker"], color=st["color"],
                     markersize=4, label=b)
        axes[1].plot(s.vertices, s.gap_pct.clip(lower=1e-4), linestyle="none", marker=st["marker"],
                     color=st["color"], markersize=4, label=b)
    limit = float(inst.time_limit_s.iloc[0]) if len(inst) else 1.0
    axes[0].axhline(1e3 * limit, color="grey", linestyle=":", label="limit")
    for ax in axes[:2]:
        ax.set_xscale("log")
        ax.set_yscale("log")
        ax.set_xlabel("vertices")
        ax.grid(alpha=0.3)
    axes[0].set_ylabel("wall time per solve [ms]")
    axes[0].set_title(f"instance study, limit {limit:g} s", fontsize=9)
    axes[1].set_ylabel("gap to best known [%] (0 drawn at 1e-4)")
    axes[1].set_title("optimality gap", fontsize=9)
    axes[1].legend(fontsize=6, ncol=2)
    e = epochs[(epochs.vertices > 0) & ~epochs.method.isin(["fifo", "firstfit"])]
    for i, m in enumerate(_order(e.method)):
        s = e[e.method == m]
        st = _style(m, i)
        axes[2].plot(s.vertices, 1e3 * s.solve_time_s.clip(lower=1e-5), linestyle="none",
                     marker=st["marker"], color=st["color"], markersize=2, alpha=0.4, label=m)
    axes[2].set_xscale("log")
    axes[2].set_yscale("log")
    axes[2].set_xlabel("vertices")
    axes[2].set_ylabel("solve time in the loop [ms]")
    axes[2].set_title("every epoch of the sweep", fontsize=9)
    axes[2].legend(fontsize=6, markerscale=3)
    axes[2].grid(alpha=0.3)
    save_figure(fig, path)
    return path


def active_figure(epochs: pd.DataFrame, path: Path) -> Path:
    """Aircraft in the air over time, mean over seeds, per mode (auto and fifo)."""
    panels = [(a, r) for a in epochs.arm.unique() for r in sorted(epochs[epochs.arm == a].rate.unique())]
    fig, axes = plt.subplots(1, len(panels), figsize=(4.2 * len(panels), 3.4), squeeze=False)
    for ax, (arm, rate) in zip(axes[0], panels):
        sub = epochs[(epochs.arm == arm) & (epochs.rate == rate)]
        for j, mode in enumerate(_modes(sub)):
            for m, ls in ((ref_method(sub), "-"), ("fifo", ":")):
                s = sub[(sub["mode"] == mode) & (sub.method == m)]
                if s.empty:
                    continue
                g = s.groupby("t_s").active.mean()
                ax.plot(g.index, g.values, linestyle=ls, color=f"C{j}", label=f"{mode} {m}")
        ax.set_title(f"{arm}, rate {rate}", fontsize=9)
        ax.set_xlabel("t [s]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=6)
    axes[0][0].set_ylabel("aircraft in the air")
    save_figure(fig, path)
    return path


def delay_figure(flights: pd.DataFrame, path: Path) -> Path:
    """Departure delay (departure - earliest departure) per mode, auto, every rate pooled."""
    ref = ref_method(flights)
    f = flights[(flights.method == ref)]
    arms = list(f.arm.unique())
    fig, axes = plt.subplots(1, len(arms), figsize=(4.5 * len(arms), 3.4), squeeze=False)
    for ax, arm in zip(axes[0], arms):
        sub = f[f.arm == arm]
        modes = _modes(sub)
        ax.boxplot([sub[sub["mode"] == m].delay_s.dropna().values for m in modes], showfliers=False)
        ax.set_xticks(range(1, len(modes) + 1), modes)
        ax.set_title(f"{arm}: departure delay ({ref})", fontsize=9)
        ax.grid(alpha=0.3, axis="y")
    axes[0][0].set_ylabel("delay [s]")
    save_figure(fig, path)
    return path


# -- report --------------------------------------------------------------------------------------

def _load(d: Path) -> tuple:
    runs = pd.read_csv(d / "runs.csv")
    epochs = pd.read_csv(d / "epochs.csv.gz")
    flights = pd.read_csv(d / "flights.csv.gz")
    inst = pd.read_csv(d / "instances.csv") if (d / "instances.csv").exists() else pd.DataFrame()
    inputs = json.loads((d / "report_inputs.json").read_text()) if (d / "report_inputs.json").exists() else {}
    return runs, epochs, flights, inst, inputs


def solver_rows(runs: pd.DataFrame) -> list:
    """Every paired solver comparison of the study: (arm, mode, rate, a, b, Paired)."""
    out = []
    pairs = [("auto", "greedy"), ("auto", "firstfit"), ("greedy", "firstfit"), ("firstfit", "fifo"),
             ("auto", "fifo")]
    for arm in runs.arm.unique():
        for mode in _modes(runs[runs.arm == arm]):
            for rate in sorted(runs[(runs.arm == arm) & (runs["mode"] == mode)].rate.unique()):
                for a, b in pairs:
                    p = compare(runs, arm, rate, (mode, a), (mode, b))
                    if p is not None:
                        out.append((arm, mode, rate, a, b, p))
    return out


def write_capacity_report(d) -> dict:
    d = Path(d)
    runs, epochs, flights, inst, inputs = _load(d)
    figdir = d / "figures"
    figdir.mkdir(parents=True, exist_ok=True)
    figs = {"approvals": approvals_figure(runs, figdir / "approvals_by_mode.png"),
            "share": approval_share_figure(runs, figdir / "approval_rate_vs_load.png"),
            "variables": variables_figure(epochs, figdir / "mwis_variables.png"),
            "active": active_figure(epochs, figdir / "active_over_time.png"),
            "delay": delay_figure(flights, figdir / "delay.png")}
    if len(inst):
        figs["size"] = size_figure(inst, epochs, figdir / "solve_time_gap_vs_size.png")
    text = _report_text(runs, epochs, flights, inst, inputs, figs, d)
    path = d / "REPORT.md"
    path.write_text(text, encoding="utf-8")
    return {"report": path, **figs}


def _rel(p: Path, d: Path) -> str:
    return str(Path(p).relative_to(d))


def _report_text(runs, epochs, flights, inst, inputs, figs, d) -> str:
    """REPORT.md's text from the tables; one helper per section, in the report's order."""
    L = []
    _setup_section(L, runs, inputs)
    _departures_section(L, inputs.get("config", {}).get("base", {}))
    _safety_section(L, runs)
    _runs_section(L, runs, figs, d)
    _airspace_section(L, runs)
    _solver_section(L, runs)
    _variables_section(L, epochs, inst, figs, d)
    _delay_section(L, flights, figs, d)
    return "\n".join(L) + "\n"


def _setup_section(L: list, runs, inputs) -> None:
    cfg = inputs.get("config", {})
    base = cfg.get("base", {})
    mach = inputs.get("machine", {})
    L.append("# The capacity study: does the solver decide the throughput once the airspace has room?\n")
    L.append("Written by `python -m uam_sim.capacity_study --config config/capacity-study.yaml` "
             "(tables) and `python -m uam_sim.capacity_report` (this file and the figures, from the "
             "tables alone). Every number below is computed from `runs.csv`, `epochs.csv.gz`, "
             "`flights.csv.gz` and `instances.csv` beside it.\n")
    L.append("## Setup\n")
    rows = []
    for a in cfg.get("arms", []):
        net = a["network"] if isinstance(a["network"], str) else json.dumps(a["network"])
        seeds = sorted(runs[runs.arm == a["name"]].seed.unique())
        rows.append([a["name"], f"`{net}`", ", ".join(a["modes"]), ", ".join(a["methods"]),
                     ", ".join(str(r) for r in a["rates"]), ", ".join(str(x) for x in seeds)])
    L.append(_table(rows, ["arm", "network", "airspace modes", "methods", "rates (requests / 30 s)",
                           "seeds run"]))
    L.append(f"\nSeeds as listed per arm (the core arm 5; the secondary arms fewer, to fit the 2-core "
             f"budget), {base.get('duration_s', 3500):g} s "
             f"simulated per run, epoch 30 s, window 60 s, k = 5 candidate routes, 10 m/s, "
             f"separation 100 m (horizontal in the cylinder modes, with 30 m vertically), MWIS "
             f"time limit {base.get('time_limit_s', 2):g} s per epoch. {len(runs)} runs"
             + (f", {inputs.get('missing_cells')} cells missing" if inputs.get("missing_cells") else "")
             + f". Machine: {mach.get('cpu', '?')}, {mach.get('cores', '?')} cores, commit "
             f"{str(mach.get('commit', '?'))[:10]}. Sum of the runs' wall times "
             f"{runs.wall_s.sum() / 3600:.1f} h (the machine was shared, so wall times and solve "
             f"times are inflated; approvals are not).\n")
    L.append("Airspace modes (`uam_sim.runner.experiment_config.AIRSPACE_PRESETS`): " + "; ".join(
        f"**{m}** = {MODE_TEXT[m]}" for m in MODES) + ". The layered modes fly the layered form of "
        "the network (Singapore: `singapore-layered.yaml`, the same corridors with vertiports as "
        "route terminals, 4 pads per vertiport and cruise levels 60/90/120/150 m under the "
        "semicircular rule; the synthetic city: the same generator with those levels and pads). "
        "Slots: a request may depart at any 5 s slot of its window, so each candidate route comes "
        "in up to 13 departure times. `auto` is the solver node's default backend (exact "
        "reductions, then KaMIS or CP-SAT on small kernels and CHILS on large ones; it claims "
        "optimality only when proven).\n")


def _departures_section(L: list, base: dict) -> None:
    L.append("## Departures from the paper\n")
    L.append("- The paper's airspace is one cruise level with departures at the epoch time; the "
             "expanded modes are ours (the paper predicts, without testing, that more airspace "
             "structure makes the optimiser matter). The Singapore network is our own, the "
             "synthetic city is generated.\n"
             f"- MWIS time limit {base.get('time_limit_s', 2):g} s per epoch instead of the paper's "
             "10 s, to fit the 2-core machine (the instance study below shows what 1 s buys per "
             "backend; `auto` proves most instances well inside it).\n"
             "- `auto` (reductions + KaMIS / CP-SAT / CHILS) stands in for Gurobi; the QPU is "
             "absent (no token): `qpu-emulator` is classical annealing on a Pegasus embedding of "
             "decomposed subproblems, with no QPU times.\n"
             "- Every backend runs behind the same layers in the loop (component split, exact "
             "reductions, answer check and greedy fallback).\n"
             "- Shortest FIFO keeps the paper's rule in every mode: the shortest route at its "
             "lowest allowed level, departing at the first slot (the epoch time) or waiting for "
             "the next epoch; it does not search the slots, so its slots - paper difference is 0 "
             "by construction. First-fit is the baseline that uses the slots and the "
             "alternatives without optimising.\n")


def _safety_section(L: list, runs) -> None:
    L.append("## Safety audit\n")
    losses = int(runs.losses.fillna(0).sum())
    pairs = int(runs.pairs_checked.fillna(0).sum())
    L.append(f"Every run was audited after the fact in its own separation model (exact closest "
             f"approach of every overlapping pair of flown trajectories, `uam_sim.audit.separation`): "
             f"**{losses} losses of separation** over {pairs:,} pairs in {len(runs)} runs; smallest "
             f"separation {runs.min_separation_m.min():.1f} m (the minimum is 100 m).\n")


def _runs_section(L: list, runs, figs, d) -> None:
    L.append("## Runs (mean over seeds)\n")
    rows = []
    g = runs.groupby(["arm", "mode", "rate", "method"], sort=False)
    for (arm, mode, rate, m), s in sorted(g, key=lambda kv: (list(runs.arm.unique()).index(kv[0][0]),
                                                             MODES.index(kv[0][1]), kv[0][2],
                                                             _order(runs.method).index(kv[0][3]))):
        rows.append([arm, mode, rate, m, _fmt(s.approved.mean()), _fmt(100 * s.approval_rate.mean()),
                     _fmt(s.expired.mean()), _fmt(s.avg_airborne.mean()), _fmt(s.airborne_peak.mean(), 0),
                     _fmt(s.vertices_median.mean(), 0), _fmt(s.vertices_max.max(), 0),
                     _fmt(1e3 * s.solve_time_mean_s.mean(), 1) if m not in ("fifo", "firstfit") else "-",
                     _fmt(100 * s.proven_optimal_share.mean(), 1) if m not in ("fifo", "firstfit") else "-",
                     _fmt(s.fallbacks.sum(), 0), _fmt(s.delay_mean_s.mean(), 1)])
    L.append(_table(rows, ["arm", "mode", "rate", "method", "approved", "approved %", "expired",
                           "airborne mean", "airborne peak", "MWIS vertices median", "max",
                           "solve mean ms", "proven %", "fallbacks", "delay mean s"]))
    L.append(f"\n![approvals]({_rel(figs['approvals'], d)})\n")
    L.append(f"![approval rate]({_rel(figs['share'], d)})\n")


def _airspace_section(L: list, runs) -> None:
    """What the expanded airspace changes, paired per seed against paper mode."""
    L.append("## What the expanded airspace changes (same demand, paired per seed)\n")
    rows = []
    for arm in runs.arm.unique():
        sub = runs[runs.arm == arm]
        modes = _modes(sub)
        if "paper" not in modes:
            continue
        for rate in sorted(sub.rate.unique()):
            for m in ("fifo", "firstfit", "auto"):
                for mode in modes:
                    if mode == "paper":
                        continue
                    p = compare(runs, arm, rate, (mode, m), ("paper", m))
                    r = compare(runs, arm, rate, (mode, m), ("paper", m), relative=True)
                    if p is None:
                        continue
                    base_mean = np.mean(list(per_seed(runs, arm, "paper", m, rate).values()))
                    rows.append([arm, rate, m, f"{mode} - paper", _ci(p), f"{r.mean:+.0f} %",
                                 f"{(base_mean + p.mean) / base_mean:.2f}x" if base_mean else "-"])
    L.append(_table(rows, ["arm", "rate", "method", "comparison", "approvals, paired diff [95 % CI]",
                           "relative", "ratio"]))
    L.append("")


def _solver_section(L: list, runs) -> None:
    """The question: does the solver decide the throughput (and the annealers' rows)?"""
    L.append("## Does the solver decide the throughput?\n")
    sr = solver_rows(runs)
    rows = [[arm, mode, rate, f"{a} - {b}", _ci(p), "yes" if p.supported else "no"]
            for arm, mode, rate, a, b, p in sr]
    L.append(_table(rows, ["arm", "mode", "rate", "comparison", "approvals, paired diff [95 % CI]",
                           "interval excludes 0"]))
    L.append("")
    L.extend(_verdict(runs, sr))
    ann = runs[runs.method.isin(["sa", "tabu", "qpu-emulator", "qpu", "exact"])]
    if len(ann):
        L.append("\n### Annealers and the emulator in the largest instances\n")
        L.append("Paired with the methods of any arm on the same network, mode, rate and seeds (the "
                 "same demand).\n")
        rows = []
        for (net, mode, rate), s in ann.groupby(["network", "mode", "rate"]):
            same = runs[(runs.network == net) & (runs["mode"] == mode) & (runs.rate == rate)]
            for m in _order(s.method):
                xa = {int(a): float(b) for a, b in zip(s[s.method == m].seed, s[s.method == m].approved)}
                for ref in ("auto", "greedy", "firstfit"):
                    r = same[same.method == ref]
                    xb = {int(a): float(b) for a, b in zip(r.seed, r.approved)}
                    if set(xa) & set(xb):
                        p = paired(xa, xb)
                        rows.append([net, mode, rate, f"{m} - {ref}", _ci(p), "yes" if p.supported else "no",
                                     _fmt(s[s.method == m].fallbacks.sum(), 0)])
        L.append(_table(rows, ["network", "mode", "rate", "comparison", "approvals, paired diff [95 % CI]",
                               "interval excludes 0", "fallbacks (its runs)"]))
        L.append("")


def _variables_section(L: list, epochs, inst, figs, d) -> None:
    """MWIS instance sizes per epoch, and the instance study when it ran."""
    L.append("## MWIS variables per epoch\n")
    e = epochs[(epochs.vertices > 0) & (epochs.method == "auto")]
    rows = []
    for (arm, mode, rate), s in e.groupby(["arm", "mode", "rate"]):
        v = s.vertices
        rows.append([arm, mode, rate, _fmt(v.mean(), 1), _fmt(v.median(), 0), _fmt(v.quantile(0.95), 0),
                     _fmt(v.max(), 0), _fmt(100 * s.proven_optimal.mean(), 1),
                     _fmt(1e3 * s.solve_time_s.median(), 1), _fmt(1e3 * s.solve_time_s.max(), 0)])
    rows.sort(key=lambda r: (r[0], MODES.index(r[1]), r[2]))
    L.append(_table(rows, ["arm", "mode", "rate", "mean", "median", "p95", "max", "auto proven %",
                           "auto solve median ms", "max ms"]))
    L.append(f"\n![variables]({_rel(figs['variables'], d)})\n")
    if len(inst):
        L.extend(_instance_section(inst, figs, d))


def _delay_section(L: list, flights, figs, d) -> None:
    L.append("## Aircraft in the air and departure delay\n")
    L.append(f"![active]({_rel(figs['active'], d)})\n")
    L.append(f"![delay]({_rel(figs['delay'], d)})\n")
    rows = []
    f = flights[flights.method == "auto"]
    for (arm, mode), s in f.groupby(["arm", "mode"]):
        dl = s.delay_s.dropna()
        rows.append([arm, mode, _fmt(dl.mean(), 1), _fmt(dl.median(), 0), _fmt(dl.quantile(0.95), 0),
                     _fmt(s.length_m.mean() / 1e3, 2)])
    rows.sort(key=lambda r: (r[0], MODES.index(r[1])))
    L.append(_table(rows, ["arm", "mode", "delay mean s (auto)", "median", "p95", "flown route mean km"]))
    L.append("")


def _verdict(runs, sr) -> list:
    """Sentences answering the question from the paired rows (no number typed by hand)."""
    L = []
    opt = [(arm, mode, rate, p) for arm, mode, rate, a, b, p in sr if (a, b) == ("auto", "firstfit")]
    grd = [(arm, mode, rate, p) for arm, mode, rate, a, b, p in sr if (a, b) == ("auto", "greedy")]
    alt = [(arm, mode, rate, p) for arm, mode, rate, a, b, p in sr if (a, b) == ("firstfit", "fifo")]
    def listing(rows):
        return "; ".join(f"{arm} {mode} rate {rate}: {_ci(p)}" for arm, mode, rate, p in rows)
    sup_opt = [r for r in opt if r[3].supported]
    L.append(f"- **Optimising against first-fit over the same candidates** (`auto` - `firstfit`): "
             f"the interval excludes 0 in {len(sup_opt)} of {len(opt)} (arm, mode, rate) cells"
             + (f" ({listing(sup_opt)})" if sup_opt else "") + ".")
    sup_g = [r for r in grd if r[3].supported]
    L.append(f"- **Exact against greedy MWIS** (`auto` - `greedy`): supported in {len(sup_g)} of "
             f"{len(grd)} cells" + (f" ({listing(sup_g)})" if sup_g else "") + ".")
    sup_a = [r for r in alt if r[3].supported]
    L.append(f"- **Alternatives against the shortest route** (`firstfit` - `fifo`): supported in "
             f"{len(sup_a)} of {len(alt)} cells.")
    # size of the effects: airspace vs optimisation
    eff = []
    for arm in runs.arm.unique():
        sub = runs[runs.arm == arm]
        modes = _modes(sub)
        for rate in sorted(sub.rate.unique()):
            if "paper" in modes and "both" in modes:
                air = compare(runs, arm, rate, ("both", "auto"), ("paper", "auto"))
                o = compare(runs, arm, rate, ("both", "auto"), ("both", "firstfit"))
                if air is not None and o is not None:
                    eff.append(f"{arm} rate {rate}: airspace (both - paper, auto) {air.mean:+,.0f} "
                               f"flights, optimisation (auto - firstfit, both) {o.mean:+,.1f}")
    if eff:
        L.append("- **Airspace against optimisation, in flights per run**: " + "; ".join(eff) + ".")
    return L


def _instance_section(inst: pd.DataFrame, figs: dict, d: Path) -> list:
    L = ["## Solve time and optimality gap against instance size, per backend\n"]
    src = inst.source.iloc[0]
    n_inst = inst.groupby(["epoch", "vertices"]).ngroups
    limit = float(inst.time_limit_s.iloc[0])
    L.append(f"{n_inst} instances of one recorded run ({src}), sampled in log-spaced size bins; "
             f"every backend solves the same instances with a {limit:g} s limit through "
             f"`uam_solvers.executor.SolveService` (worker processes, killed at the limit plus "
             f"0.4 s; a killed solve answers greedy, flagged). Best known: the best any backend "
             f"found, or `auto` with a longer limit where nothing was proven; proven where a "
             f"backend proved it.\n")
    bins = [0, 32, 128, 512, 2048, 10**9]
    inst = inst.copy()
    inst["bin"] = pd.cut(inst.vertices, bins, right=False,
                         labels=[f"{a}-{b - 1}" if b < 10**9 else f">={a}" for a, b in zip(bins[:-1], bins[1:])])
    rows = []
    for (b, be), s in inst.groupby(["backend", "bin"], observed=True):
        rows.append([be, b, len(s), _fmt(1e3 * s.wall_s.median(), 1), _fmt(1e3 * s.wall_s.max(), 0),
                     _fmt(s.gap_pct.mean(), 3), _fmt(s.gap_pct.max(), 3),
                     f"{int((s.gap_pct <= 1e-9).sum())}/{len(s)}", f"{int(s.proven_optimal.sum())}/{len(s)}",
                     int(s.fallback.sum())])
    rows.sort(key=lambda r: (bins.index(int(str(r[0]).split('-')[0].lstrip('>='))), _order(inst.backend).index(r[1])))
    L.append(_table(rows, ["vertices", "backend", "instances", "wall median ms", "wall max ms",
                           "gap mean %", "gap max %", "at best known", "proven", "fallbacks"]))
    L.append(f"\n![size]({_rel(figs['size'], d)})\n")
    return L


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(allow_abbrev=False, prog="capacity_report", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", help="a capacity study's output (docs/capacity-study)")
    args = ap.parse_args(argv)
    paths = write_capacity_report(Path(args.dir))
    print(f"wrote {paths['report']}")
    return 0


if __name__ == "__main__":
    sys.exit(main())
