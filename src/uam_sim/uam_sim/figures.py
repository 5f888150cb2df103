"""Figures of the study in the paper's form (matplotlib, Agg backend), and the numbers behind them.

Every figure function takes the cells of a sweep (dicts as written by ``uam_sim.experiment``) and
returns the table it plotted, so the report shows the same numbers. Mean and a 95 % confidence
interval over seeds (Student t, n - 1 degrees of freedom) wherever the paper shows one line.

Bounds on the MWIS figure: a request can be eligible at epoch t only if it was issued in
[t - window_s, t], i.e. at one of floor(window_s / interval_s) + 1 demand instants, so at most
``ceil(rate) * (floor(window_s / interval_s) + 1)`` requests are eligible (3 x rate in the paper's
setup). The conflict graph holds a clique per request, so at most one vertex per eligible request
is selected: the MWIS size is bounded by the number of eligible requests (plotted per epoch as
measured) and, a priori, by the bound above; the graph itself has at most k vertices per eligible
request.
"""

from __future__ import annotations

import math
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

METHOD_ORDER = ("fifo", "greedy", "exact", "sa", "tabu", "qpu-emulator", "qpu", "kamis", "chils")


def mean_ci(values, level: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high) of a sample with a Student-t confidence interval; n = 1 gives a point."""
    x = np.asarray([v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))],
                   dtype=np.float64)
    if x.size == 0:
        return float("nan"), float("nan"), float("nan")
    m = float(x.mean())
    if x.size < 2:
        return m, m, m
    from scipy.stats import t as student_t
    half = float(student_t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
    return m, m - half, m + half


def _methods(cells) -> list:
    present = {c["summary"]["method"] for c in cells}
    return [m for m in METHOD_ORDER if m in present] + sorted(present - set(METHOD_ORDER))


def _rates(cells) -> list:
    return sorted({c["summary"]["rate"] for c in cells})


def _label(m: str) -> str:
    return "shortest FIFO" if m == "fifo" else f"MWIS {m}"


def select_rates(rates, wanted=None, n: int = 4) -> list:
    """The rates to show in per-rate panels: ``wanted`` if given, else up to n spread evenly."""
    if wanted:
        return [r for r in wanted if r in rates]
    if len(rates) <= n:
        return list(rates)
    idx = np.unique(np.round(np.linspace(0, len(rates) - 1, n)).astype(int))
    return [rates[i] for i in idx]


def cumulative_figure(cells, path: Path, rates_shown=None) -> dict:
    """Cumulative approved flights over time per method, one panel per rate (mean, 95 % CI)."""
    rates = select_rates(_rates(cells), rates_shown)
    methods = _methods(cells)
    fig, axes = plt.subplots(1, len(rates), figsize=(4.2 * len(rates), 3.6), squeeze=False,
                             sharey=False)
    table = []
    for ax, rate in zip(axes[0], rates):
        for m in methods:
            runs = [c for c in cells if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            if not runs:
                continue
            t = np.array([r["t_s"] for r in runs[0]["epochs"]])
            y = np.array([[r["approved_cum"] for r in c["epochs"]] for c in runs], dtype=float)
            stats = np.array([mean_ci(y[:, j]) for j in range(y.shape[1])])
            line, = ax.plot(t, stats[:, 0], label=_label(m))
            ax.fill_between(t, stats[:, 1], stats[:, 2], color=line.get_color(), alpha=0.2, lw=0)
            table.append({"rate": rate, "method": m, "final_mean": stats[-1, 0],
                          "final_lo": stats[-1, 1], "final_hi": stats[-1, 2], "seeds": len(runs)})
        ax.set_title(f"{rate} requests / interval")
        ax.set_xlabel("simulation time [s]")
        ax.grid(alpha=0.3)
    axes[0][0].set_ylabel("cumulative approved flights")
    axes[0][-1].legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"path": str(path), "table": table}


def _per_rate_lines(cells, key, path, ylabel, title) -> dict:
    rates = _rates(cells)
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    table = []
    for m in _methods(cells):
        pts = []
        for rate in rates:
            vals = [c["summary"][key] for c in cells
                    if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            if vals:
                mu, lo, hi = mean_ci(vals)
                pts.append((rate, mu, lo, hi))
                table.append({"rate": rate, "method": m, "mean": mu, "lo": lo, "hi": hi,
                              "seeds": len(vals)})
        if pts:
            p = np.array(pts, dtype=float)
            ax.errorbar(p[:, 0], p[:, 1], yerr=[p[:, 1] - p[:, 2], p[:, 3] - p[:, 1]],
                        marker="o", ms=3, capsize=3, label=_label(m))
    ax.set_xlabel("request rate [requests / interval]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"path": str(path), "table": table}


def airborne_figure(cells, path: Path) -> dict:
    """Time-average number of aircraft in the air per rate and method (mean, 95 % CI)."""
    return _per_rate_lines(cells, "avg_airborne", path, "average aircraft in the air",
                           "Aircraft in the air (time average)")


def approved_figure(cells, path: Path) -> dict:
    """Total approved flights per run per rate and method (mean, 95 % CI)."""
    return _per_rate_lines(cells, "approved", path, "approved flights per run",
                           "Approved flights")


def mwis_size_figure(cells, path: Path, k: int, window_s: float, interval_s: float) -> dict:
    """Conflict-graph vertices and MWIS size per epoch per rate (MWIS methods), with bounds."""
    rates = _rates(cells)
    mwis = [c for c in cells if c["summary"]["method"] != "fifo"]
    per_instant = math.floor(window_s / interval_s + 1e-9) + 1
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    table = []
    vdata, sdata = [], []
    for rate in rates:
        eps = [r for c in mwis if c["summary"]["rate"] == rate for r in c["epochs"]]
        v = np.array([r["vertices"] for r in eps], dtype=float)
        s = np.array([r["selected"] for r in eps if r["vertices"] > 0], dtype=float)
        e = np.array([r["eligible"] for r in eps], dtype=float)
        vdata.append(v if v.size else np.zeros(1))
        sdata.append(s if s.size else np.zeros(1))
        bound = math.ceil(rate) * per_instant
        table.append({"rate": rate, "vertices_mean": float(v.mean()) if v.size else 0.0,
                      "vertices_max": float(v.max()) if v.size else 0.0,
                      "vertex_bound": k * bound,
                      "selected_mean": float(s.mean()) if s.size else 0.0,
                      "selected_max": float(s.max()) if s.size else 0.0,
                      "eligible_mean": float(e.mean()) if e.size else 0.0,
                      "size_bound": bound,
                      "selected_over_bound": (float(s.mean()) / bound) if s.size and bound else 0.0})
    pos = np.arange(len(rates))
    a1.boxplot(vdata, positions=pos, widths=0.6, showfliers=False)
    a1.plot(pos, [t["vertex_bound"] for t in table], "r--", label=f"bound k x {per_instant} x rate")
    a1.set_title("Conflict-graph vertices per epoch")
    a2.boxplot(sdata, positions=pos, widths=0.6, showfliers=False)
    a2.plot(pos, [t["eligible_mean"] for t in table], "g:", marker="x",
            label="eligible requests (mean)")
    a2.plot(pos, [t["size_bound"] for t in table], "r--", label=f"bound {per_instant} x rate")
    a2.set_title("MWIS size (selected vertices) per epoch")
    for ax in (a1, a2):
        ax.set_xticks(pos, [str(r) for r in rates])
        ax.set_xlabel("request rate [requests / interval]")
        ax.grid(alpha=0.3)
        ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"path": str(path), "table": table, "eligible_per_instant": per_instant}


def solve_time_figure(cells, path: Path) -> dict:
    """Per-epoch MWIS solve-time distributions per backend (box plot, log scale)."""
    methods = [m for m in _methods(cells) if m != "fifo"]
    data, table = [], []
    for m in methods:
        eps = [r for c in cells if c["summary"]["method"] == m for r in c["epochs"]
               if r["vertices"] > 0]
        t = np.array([r["solve_time_s"] for r in eps], dtype=float)
        opt = np.array([r["proven_optimal"] for r in eps], dtype=bool)
        fb = np.array([r["fallback"] for r in eps], dtype=bool)
        data.append(np.maximum(t, 1e-6) if t.size else np.array([1e-6]))
        table.append({"method": m, "epochs": int(t.size),
                      "median_s": float(np.median(t)) if t.size else float("nan"),
                      "p95_s": float(np.percentile(t, 95)) if t.size else float("nan"),
                      "max_s": float(t.max()) if t.size else float("nan"),
                      "share_under_0.1s": float((t < 0.1).mean()) if t.size else float("nan"),
                      "share_proven_optimal": float(opt.mean()) if t.size else float("nan"),
                      "fallbacks": int(fb.sum())})
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if data:
        ax.boxplot(data, widths=0.6)
        ax.set_xticks(np.arange(1, len(methods) + 1), methods)
    ax.set_yscale("log")
    ax.axhline(0.1, color="r", ls="--", lw=1, label="0.1 s")
    ax.set_ylabel("solve time per epoch [s]")
    ax.set_title("MWIS solve time (epochs with a non-empty graph)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"path": str(path), "table": table}


def _tts_value(row):
    for key in ("tts99_s", "tts_s", "tts"):
        if key in row and row[key] not in (None, ""):
            return float(row[key])
    return None


def tts_figure(tts: dict, path: Path) -> dict:
    """TTS(p) box plots per backend from the TTS study's rows (log scale)."""
    rows = tts.get("rows") or []
    by: dict = {}
    missed: dict = {}
    for r in rows:
        v = _tts_value(r)
        b = str(r.get("backend", "?"))
        by.setdefault(b, [])
        if v is not None and math.isfinite(v):
            by[b].append(v)
        else:
            missed[b] = missed.get(b, 0) + 1  # stochastic backend that never reached the optimum
    if not by:
        return {}
    names = [m for m in METHOD_ORDER if m in by] + sorted(set(by) - set(METHOD_ORDER))
    table = []
    for m in names:
        x = np.array(by[m], dtype=float)
        n_all = x.size + missed.get(m, 0)
        rules = [r.get("rule") for r in rows if str(r.get("backend")) == m]
        pe = [float(r["p_opt"]) for r in rows if str(r.get("backend")) == m and r.get("p_opt") is not None]
        table.append({"backend": m, "instances": int(n_all),
                      "median_s": float(np.median(x)) if x.size else float("nan"),
                      "p25_s": float(np.percentile(x, 25)) if x.size else float("nan"),
                      "p75_s": float(np.percentile(x, 75)) if x.size else float("nan"),
                      "max_s": float(x.max()) if x.size else float("nan"),
                      "not_reached": int(missed.get(m, 0)),
                      "penalised": int(sum(r == "deterministic miss penalty" for r in rules)),
                      "mean_p_opt": float(np.mean(pe)) if pe else float("nan"),
                      # reached the optimum with 99 % confidence in under 0.1 s, over all instances
                      "share_under_0.1s": float((x < 0.1).sum() / n_all) if n_all else float("nan")})
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    ax.boxplot([np.maximum(by[m], 1e-7) if by[m] else [np.nan] for m in names], widths=0.6)
    ax.set_xticks(np.arange(1, len(names) + 1),
                  [m + f"\nn={len(by[m]) + missed.get(m, 0)}"
                   + (f", {missed[m]} not reached" if missed.get(m) else "") for m in names])
    ax.axhline(0.1, color="r", ls="--", lw=1)
    ax.set_yscale("log")
    ax.set_ylabel(f"TTS({tts.get('p', 0.99)}) [s]")
    ax.set_title(f"Time to solution, instances sampled from the runs (n per backend)")
    ax.grid(alpha=0.3, which="both")
    fig.tight_layout()
    fig.savefig(path, dpi=110)
    plt.close(fig)
    return {"path": str(path), "table": table}


def make_figures(cells, cfg, tts: dict, out: Path) -> dict:
    """Write every figure as PNG into ``out/figures``; returns name -> {path, table}."""
    d = Path(out) / "figures"
    d.mkdir(parents=True, exist_ok=True)
    figs = {
        "cumulative": cumulative_figure(cells, d / "cumulative_approved.png", cfg.cumulative_rates),
        "approved": approved_figure(cells, d / "approved_per_rate.png"),
        "airborne": airborne_figure(cells, d / "aircraft_in_air.png"),
    }
    if any(c["summary"]["method"] != "fifo" for c in cells):
        figs["mwis_size"] = mwis_size_figure(cells, d / "mwis_size.png", cfg.k, cfg.window_s,
                                             cfg.interval_s)
        figs["solve_time"] = solve_time_figure(cells, d / "solve_time.png")
    t = tts_figure(tts, d / "tts.png") if tts.get("status") == "ok" else {}
    if t:
        figs["tts"] = t
    return figs
