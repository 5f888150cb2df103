"""Figures of the study in the paper's form (matplotlib, Agg backend), and the numbers behind them.

Every figure function takes the cells of a sweep (dicts as written by ``uam_sim.studies.experiment``) and
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
from contextvars import ContextVar
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402

METHOD_ORDER = ("fifo", "firstfit", "greedy", "exact", "sa", "tabu", "qpu-emulator", "qpu", "kamis",
                "chils")
from uam_solvers.registry import sampling_backends  # noqa: E402

from ..runner.experiment_config import BASELINES  # noqa: E402  (planner policies, not MWIS solvers)
from ..world.flights import corridor_use_m, flight_metrics  # noqa: E402,F401  (re-exported)
# marker, line style and colour per method, so methods that overlap (exact, sa, tabu and the
# emulator often approve the same flights) stay distinguishable in print and in greyscale
STYLE = {"fifo": ("o", "-", "tab:blue"), "firstfit": ("s", "--", "tab:orange"),
         "greedy": ("^", "-.", "tab:green"), "exact": ("D", "-", "tab:red"),
         "sa": ("v", ":", "tab:purple"), "tabu": ("P", "--", "tab:brown"),
         "qpu-emulator": ("X", "-.", "tab:pink"), "qpu": ("*", ":", "tab:gray"),
         "kamis": ("<", "--", "tab:olive"), "chils": (">", ":", "tab:cyan")}


#: False inside ``make_figures(..., render=False)``: the figures' tables are computed, no
#: image is laid out or written (a third of a report's rebuild time is PNG rendering)
_RENDER: ContextVar[bool] = ContextVar("uam_figures_render", default=True)


def save_figure(fig, path) -> None:
    """Lay out, save (110 dpi) and close a figure: the end of every figure of the studies
    (only closed when rendering is off)."""
    if _RENDER.get():
        fig.tight_layout()
        fig.savefig(path, dpi=110)
    plt.close(fig)


def _finish_panels(fig, axes, ylabel: str, path) -> None:
    """Shared end of the per-rate panel figures: y label on the first panel, legend on the last, save."""
    axes[0][0].set_ylabel(ylabel)
    axes[0][-1].legend(fontsize=7)
    save_figure(fig, path)


def style(m: str, i: int = 0) -> dict:
    """matplotlib keyword arguments (marker, linestyle, colour) of a method."""
    mk, ls, col = STYLE.get(m, ("o", "-", f"C{i % 10}"))
    return {"marker": mk, "linestyle": ls, "color": col}


def mean_ci(values, level: float = 0.95) -> tuple[float, float, float]:
    """(mean, low, high) of a sample with a Student-t confidence interval; n = 1 gives a point.

    The interval is ``uam_sim.reports.stats.mean_interval``'s (the one CI helper); the figures only draw
    a single seed as a point (a zero-width band) where the statistics say "no interval"."""
    from .stats import mean_interval

    x = [v for v in values if v is not None and not (isinstance(v, float) and math.isnan(v))]
    m, lo, hi = mean_interval(x, level)
    if len(x) == 1:
        return m, m, m
    return m, lo, hi


def _methods(cells) -> list:
    present = {c["summary"]["method"] for c in cells}
    return [m for m in METHOD_ORDER if m in present] + sorted(present - set(METHOD_ORDER))


def _rates(cells) -> list:
    return sorted({c["summary"]["rate"] for c in cells})


def _label(m: str) -> str:
    return {"fifo": "shortest FIFO", "firstfit": "first-fit"}.get(m, f"MWIS {m}")


def select_rates(rates, wanted=None, n: int = 4) -> list:
    """The rates to show in per-rate panels: ``wanted`` if given, else up to n spread evenly."""
    if wanted:
        return [r for r in wanted if r in rates]
    if len(rates) <= n:
        return list(rates)
    idx = np.unique(np.round(np.linspace(0, len(rates) - 1, n)).astype(int))
    return [rates[i] for i in idx]


def cumulative_figure(cells, path: Path, rates_shown=None) -> dict:
    """Cumulative approved flights over time per method, one panel per rate (mean, 95 % CI band),
    each method with its own marker and line style."""
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
            i = methods.index(m)
            # markers every ~10 % of the run, shifted per method so overlapping lines show all
            every = max(len(t) // 10, 1)
            line, = ax.plot(t, stats[:, 0], label=_label(m), ms=4, lw=1.2,
                            markevery=(i * max(every // len(methods), 1) % every, every), **style(m, i))
            ax.fill_between(t, stats[:, 1], stats[:, 2], color=line.get_color(), alpha=0.12, lw=0)
            table.append({"rate": rate, "method": m, "final_mean": stats[-1, 0],
                          "final_lo": stats[-1, 1], "final_hi": stats[-1, 2], "seeds": len(runs)})
        ax.set_title(f"{rate} requests / interval")
        ax.set_xlabel("simulation time [s]")
        ax.grid(alpha=0.3)
    _finish_panels(fig, axes, "cumulative approved flights", path)
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
                        ms=4, capsize=3, label=_label(m), **style(m, _methods(cells).index(m)))
    ax.set_xlabel("request rate [requests / interval]")
    ax.set_ylabel(ylabel)
    ax.set_title(title)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    save_figure(fig, path)
    return {"path": str(path), "table": table}


def airborne_figure(cells, path: Path) -> dict:
    """Time-average number of aircraft in the air per rate and method (mean, 95 % CI)."""
    return _per_rate_lines(cells, "avg_airborne", path, "average aircraft in the air",
                           "Aircraft in the air (time average)")


def approved_figure(cells, path: Path) -> dict:
    """Total approved flights per run per rate and method (mean, 95 % CI)."""
    return _per_rate_lines(cells, "approved", path, "approved flights per run",
                           "Approved flights")


def approval_rate_figure(cells, path: Path, interval_s: float) -> dict:
    """Approval rate (approved / requested) against offered load [requests per hour] per method
    (mean, 95 % CI over seeds)."""
    per_hour = 3600.0 / interval_s
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    table = []
    methods = _methods(cells)
    for i, m in enumerate(methods):
        pts = []
        for rate in _rates(cells):
            vals = [c["summary"]["approval_rate"] for c in cells
                    if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            if vals:
                mu, lo, hi = mean_ci(vals)
                pts.append((rate * per_hour, mu, lo, hi))
                table.append({"method": m, "rate": rate, "offered_per_h": rate * per_hour,
                              "approval_rate": mu, "lo": lo, "hi": hi, "seeds": len(vals)})
        if pts:
            q = np.array(pts, dtype=float)
            ax.errorbar(q[:, 0], q[:, 1], yerr=[q[:, 1] - q[:, 2], q[:, 3] - q[:, 1]], ms=4,
                        capsize=3, label=_label(m), **style(m, i))
    ax.set_xscale("log")
    ax.set_xlabel("offered load [requests / hour] (log)")
    ax.set_ylabel("approval rate (approved / requested)")
    ax.set_title("Approval rate against offered load")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    save_figure(fig, path)
    return {"path": str(path), "table": table}


def warmup_time_s(t_s, active, steady_from: float = 0.5, level: float = 0.9) -> tuple[float, float]:
    """(warm-up time [s], steady level) of an active-aircraft curve.

    Steady level = mean of ``active`` over the last ``1 - steady_from`` of the run; the warm-up
    ends at the first epoch where the curve, smoothed over 5 epochs (2.5 min), reaches ``level``
    of it. nan when the curve never does or is empty.
    """
    t = np.asarray(t_s, dtype=float)
    a = np.asarray(active, dtype=float)
    if a.size == 0:
        return float("nan"), float("nan")
    steady = float(a[t >= steady_from * (t[-1] + (t[1] - t[0] if t.size > 1 else 0))].mean())
    w = min(5, a.size)
    smooth = np.convolve(a, np.ones(w) / w, mode="same")
    hit = np.flatnonzero(smooth >= level * steady)
    return (float(t[hit[0]]) if hit.size and steady > 0 else float("nan")), steady


def active_over_time_figure(cells, path: Path, rates_shown=None) -> dict:
    """Active (airborne) aircraft at each epoch over time per method, one panel per rate
    (mean over seeds), with the warm-up time (see :func:`warmup_time_s`) per method."""
    rates = select_rates(_rates(cells), rates_shown)
    methods = _methods(cells)
    fig, axes = plt.subplots(1, len(rates), figsize=(4.2 * len(rates), 3.6), squeeze=False)
    table = []
    for ax, rate in zip(axes[0], rates):
        for i, m in enumerate(methods):
            runs = [c for c in cells if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            if not runs:
                continue
            t = np.array([r["t_s"] for r in runs[0]["epochs"]])
            y = np.array([[r["active"] for r in c["epochs"]] for c in runs], dtype=float).mean(axis=0)
            warm, steady = warmup_time_s(t, y)
            every = max(len(t) // 10, 1)
            ax.plot(t, y, label=_label(m), ms=4, lw=1.1, markevery=(i % every, every), **style(m, i))
            table.append({"rate": rate, "method": m, "warmup_s": warm, "steady_active": steady,
                          "seeds": len(runs)})
        ax.set_title(f"{rate} requests / interval")
        ax.set_xlabel("simulation time [s]")
        ax.grid(alpha=0.3)
    _finish_panels(fig, axes, "aircraft in the air (mean over seeds)", path)
    return {"path": str(path), "table": table}


def mwis_size_figure(cells, path: Path, k: int, window_s: float, interval_s: float) -> dict:
    """MWIS variables (conflict-graph vertices) and MWIS size per epoch per rate, with bounds.

    Log scale, every outlier shown. Pooled over the MWIS methods and seeds, over epochs with a
    non-empty conflict graph (the epochs that have an MWIS instance at all).
    """
    rates = _rates(cells)
    mwis = [c for c in cells if c["summary"]["method"] not in BASELINES]
    per_instant = math.floor(window_s / interval_s + 1e-9) + 1
    fig, (a1, a2) = plt.subplots(1, 2, figsize=(11, 4.2))
    table = []
    vdata, sdata = [], []
    for rate in rates:
        eps = [r for c in mwis if c["summary"]["rate"] == rate for r in c["epochs"]]
        v = np.array([r["vertices"] for r in eps if r["vertices"] > 0], dtype=float)
        s = np.array([r["selected"] for r in eps if r["vertices"] > 0], dtype=float)
        e = np.array([r["eligible"] for r in eps], dtype=float)
        vdata.append(v if v.size else np.ones(1))
        sdata.append(s if s.size else np.ones(1))
        bound = math.ceil(rate) * per_instant
        table.append({"rate": rate, "instances": int(v.size),
                      "vertices_mean": float(v.mean()) if v.size else 0.0,
                      "vertices_median": float(np.median(v)) if v.size else 0.0,
                      "vertices_p99": float(np.percentile(v, 99)) if v.size else 0.0,
                      "vertices_max": float(v.max()) if v.size else 0.0,
                      "vertex_bound": k * bound,
                      "vertices_over_bound": (float(v.mean()) / (k * bound)) if v.size and bound else 0.0,
                      "selected_mean": float(s.mean()) if s.size else 0.0,
                      "selected_max": float(s.max()) if s.size else 0.0,
                      "eligible_mean": float(e.mean()) if e.size else 0.0,
                      "size_bound": bound,
                      "selected_over_bound": (float(s.mean()) / bound) if s.size and bound else 0.0})
    pos = np.arange(len(rates))
    flier = {"marker": ".", "markersize": 3, "alpha": 0.4}
    a1.boxplot(vdata, positions=pos, widths=0.6, showfliers=True, flierprops=flier)
    a1.plot(pos, [t["vertex_bound"] for t in table], "r--", marker="_",
            label=f"bound k x {per_instant} x rate")
    a1.plot(pos, [t["vertices_mean"] for t in table], "b:", marker="o", ms=4, label="mean")
    a1.set_title("MWIS variables (conflict-graph vertices) per instance")
    a1.set_ylabel("vertices (log)")
    a2.boxplot(sdata, positions=pos, widths=0.6, showfliers=True, flierprops=flier)
    a2.plot(pos, [t["eligible_mean"] for t in table], "g:", marker="x",
            label="eligible requests (mean)")
    a2.plot(pos, [t["size_bound"] for t in table], "r--", marker="_", label=f"bound {per_instant} x rate")
    a2.set_title("MWIS size (selected vertices) per instance")
    a2.set_ylabel("selected vertices (log)")
    for ax in (a1, a2):
        ax.set_yscale("log")
        ax.set_xticks(pos, [str(r) for r in rates])
        ax.set_xlabel("request rate [requests / interval]")
        ax.grid(alpha=0.3, which="both")
        ax.legend(fontsize=7)
    save_figure(fig, path)
    return {"path": str(path), "table": table, "eligible_per_instant": per_instant}


# backends whose proven_optimal flag is False whenever they ran on a non-empty graph, so a
# proven-optimal epoch is one the reductions and component splitting solved without them
#: the backends that never prove an answer optimal: the samplers (``Backend.samples``, through
#: the registry)
NEVER_PROVING = sampling_backends()


def solve_time_figure(cells, path: Path) -> dict:
    """Per-epoch MWIS solve-time distributions per backend (box plot with every outlier, log
    scale), the share of epochs proven optimal and, for backends that never prove optimality
    themselves, the share of epochs in which the backend was not called at all."""
    methods = [m for m in _methods(cells) if m not in BASELINES]
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
                      "share_backend_not_called": (float(opt.mean()) if t.size else float("nan"))
                      if m in NEVER_PROVING else float("nan"),
                      "fallbacks": int(fb.sum())})
    fig, ax = plt.subplots(figsize=(6.4, 4.2))
    if data:
        ax.boxplot(data, widths=0.6, showfliers=True,
                   flierprops={"marker": ".", "markersize": 3, "alpha": 0.4})
        ax.set_xticks(np.arange(1, len(methods) + 1), methods)
    ax.set_yscale("log")
    ax.axhline(0.1, color="r", ls="--", lw=1, label="0.1 s")
    ax.set_ylabel("solve time per epoch [s]")
    ax.set_title("MWIS solve time (epochs with a non-empty graph)")
    ax.grid(alpha=0.3, which="both")
    ax.legend(fontsize=7)
    save_figure(fig, path)
    return {"path": str(path), "table": table}


def _tts_value(row):
    for key in ("tts99_s", "tts_s", "tts"):
        if key in row and row[key] not in (None, ""):
            return float(row[key])
    return None


def _num(row, key):
    v = row.get(key)
    if v in (None, "") or (isinstance(v, float) and math.isnan(v)):
        return None
    return float(v)


def per_read_tts(row, p: float = 0.99):
    """TTS(p) per read as the paper defines it (one trial = one read), or None.

    Uses the row's own per-read value when the TTS module recorded one (``tts99_per_read_s``),
    else computes it from the recorded read statistics: t_read = t_c / num_reads (the call's
    wall time spread over its reads, so fixed per-call costs are included), p_read =
    read_opt_fraction, TTS = t_read log(1 - p) / log(1 - p_read), at least one read (t_read)
    when p_read >= p; None when no read reached the optimum or the row has no read statistics
    (deterministic backends).
    """
    own = _num(row, "tts99_per_read_s")
    if own is not None:
        return own
    f, n, tc = _num(row, "read_opt_fraction"), _num(row, "num_reads"), _num(row, "t_c_s")
    if f is None or not n or tc is None:
        return None
    from uam_solvers.tts import time_to_solution
    v, _rule = time_to_solution(tc / n, f, deterministic=False, target=p)
    return v


def _tts_by_backend(rows: list, p: float) -> tuple[dict, dict, dict, dict]:
    """The TTS rows grouped per backend: the finite TTS(p) per call [s], the count of instances
    that never reached the optimum, and, for the rows with per-read data, the per-read TTS [s]
    and its count not reached."""
    by: dict = {}
    missed: dict = {}
    per_read: dict = {}
    read_missed: dict = {}
    for r in rows:
        v = _tts_value(r)
        b = str(r.get("backend", "?"))
        by.setdefault(b, [])
        if v is not None and math.isfinite(v):
            by[b].append(v)
        else:
            missed[b] = missed.get(b, 0) + 1  # stochastic backend that never reached the optimum
        if _num(r, "read_opt_fraction") is not None or _num(r, "tts99_per_read_s") is not None:
            pr = per_read_tts(r, p)
            per_read.setdefault(b, [])
            if pr is not None and math.isfinite(pr):
                per_read[b].append(pr)
            else:
                read_missed[b] = read_missed.get(b, 0) + 1
    return by, missed, per_read, read_missed


def _tts_table_row(m: str, rows: list, p: float, by: dict, missed: dict, per_read: dict,
                   read_missed: dict) -> dict:
    """Backend ``m``'s row of the TTS table: quartiles of TTS(p) per call and per read [s], the
    instances not reached, the mean success probabilities, and a bootstrap 95 % interval of the
    per-read median (seeded) when it has two values or more."""
    x = np.array(by[m], dtype=float)
    n_all = x.size + missed.get(m, 0)
    mine = [r for r in rows if str(r.get("backend")) == m]
    rules = [r.get("rule") for r in mine]
    pe = [float(r["p_opt"]) for r in mine if r.get("p_opt") not in (None, "")]
    pr = np.array(per_read.get(m, []), dtype=float)
    fr = [_num(r, "read_opt_fraction") for r in mine]
    fr = [f for f in fr if f is not None]
    reads = [_num(r, "num_reads") for r in mine if _num(r, "num_reads")]
    row = {"backend": m, "instances": int(n_all),
           "median_s": float(np.median(x)) if x.size else float("nan"),
           "p25_s": float(np.percentile(x, 25)) if x.size else float("nan"),
           "p75_s": float(np.percentile(x, 75)) if x.size else float("nan"),
           "max_s": float(x.max()) if x.size else float("nan"),
           "not_reached": int(missed.get(m, 0)),
           "penalised": int(sum(r == "deterministic miss penalty" for r in rules)),
           "mean_p_opt": float(np.mean(pe)) if pe else float("nan"),
           # reached the optimum with 99 % confidence in under 0.1 s, over all instances
           "share_under_0.1s": float((x < 0.1).sum() / n_all) if n_all else float("nan"),
           "reads_per_call": float(np.median(reads)) if reads else float("nan"),
           "per_read_median_s": float(np.median(pr)) if pr.size else float("nan"),
           "per_read_p25_s": float(np.percentile(pr, 25)) if pr.size else float("nan"),
           "per_read_p75_s": float(np.percentile(pr, 75)) if pr.size else float("nan"),
           "per_read_not_reached": int(read_missed.get(m, 0)),
           "mean_p_read": float(np.mean(fr)) if fr else float("nan"),
           "share_p_read_below_p": float(np.mean(np.array(fr) < p)) if fr else float("nan")}
    if pr.size >= 2:
        from scipy.stats import bootstrap
        ci = bootstrap((pr,), np.median, confidence_level=0.95, n_resamples=2000,
                       method="percentile", random_state=np.random.default_rng(0)).confidence_interval
        row["per_read_median_lo"], row["per_read_median_hi"] = float(ci.low), float(ci.high)
    return row


def _tts_plot(names: list, p: float, by: dict, missed: dict, per_read: dict, read_missed: dict,
              path: Path) -> None:
    """The TTS box plots (log scale [s], every outlier, the 0.1 s line): per call for every
    backend of ``names`` and, beside it, per read for those with per-read values; saved to ``path``."""
    read_names = [m for m in names if per_read.get(m)]
    fig, axes = plt.subplots(1, 2 if read_names else 1, figsize=(11 if read_names else 6.4, 4.2),
                             squeeze=False)
    flier = {"marker": ".", "markersize": 3, "alpha": 0.4}
    ax = axes[0][0]
    ax.boxplot([np.maximum(by[m], 1e-7) if by[m] else [np.nan] for m in names], widths=0.6,
               showfliers=True, flierprops=flier)
    ax.set_xticks(np.arange(1, len(names) + 1),
                  [m + f"\nn={len(by[m]) + missed.get(m, 0)}"
                   + (f", {missed[m]} not reached" if missed.get(m) else "") for m in names])
    ax.set_title("per call (trial = one solver call)")
    ax.set_ylabel(f"TTS({p}) [s] (log)")
    if read_names:
        ax2 = axes[0][1]
        ax2.boxplot([np.maximum(per_read[m], 1e-7) for m in read_names], widths=0.6,
                    showfliers=True, flierprops=flier)
        ax2.set_xticks(np.arange(1, len(read_names) + 1),
                       [m + f"\nn={len(per_read[m]) + read_missed.get(m, 0)}"
                        + (f", {read_missed[m]} not reached" if read_missed.get(m) else "")
                        for m in read_names])
        ax2.set_title("per read (trial = one read, the paper's TTS)")
        ax2.sharey(ax)
    for a in axes[0]:
        a.axhline(0.1, color="r", ls="--", lw=1)
        a.set_yscale("log")
        a.grid(alpha=0.3, which="both")
    fig.suptitle("Time to solution, instances sampled from the runs")
    save_figure(fig, path)


def tts_figure(tts: dict, path: Path) -> dict:
    """TTS(p) per call (one trial = one solver call of ``reads`` reads) and, for the annealers,
    per read (one trial = one read, the paper's definition), box plots per backend (log scale,
    every outlier shown)."""
    rows = tts.get("rows") or []
    p = float(tts.get("p", 0.99))
    by, missed, per_read, read_missed = _tts_by_backend(rows, p)
    if not by:
        return {}
    names = [m for m in METHOD_ORDER if m in by] + sorted(set(by) - set(METHOD_ORDER))
    table = [_tts_table_row(m, rows, p, by, missed, per_read, read_missed) for m in names]
    _tts_plot(names, p, by, missed, per_read, read_missed, path)
    return {"path": str(path), "table": table}


# ---- flights: delay, detour, corridors ---------------------------------------------------------

def central_corridors(network, share: float = 0.10) -> tuple[np.ndarray, np.ndarray]:
    """(edge betweenness centrality per corridor, bool mask of the ``share`` most central).

    Centrality: networkx edge betweenness over length-weighted shortest paths between all node
    pairs, normalised; the top ceil(share x corridors) by centrality (ties by corridor index).
    """
    import networkx as nx
    g = network.graph
    eb = nx.edge_betweenness_centrality(g, weight="length_m", normalized=True)
    c = np.zeros(network.n_edges, dtype=float)
    for (u, v), val in eb.items():
        c[g.edges[u, v]["edge_index"]] = val
    top = np.zeros(network.n_edges, dtype=bool)
    n_top = max(int(math.ceil(share * network.n_edges)), 1)
    top[np.lexsort((np.arange(c.size), -c))[:n_top]] = True
    return c, top


def _network(cfg):
    try:
        from ..runner.network_spec import load_network_spec
        return load_network_spec(cfg.network)
    except Exception:  # a recording's network may not be loadable here; skip the corridor part
        return None


def flights_figure(cells, path: Path, rates_shown=None) -> dict:
    """Delay and detour distributions per method (box plots, every outlier shown) at the shown
    rates, and the per-run table of :func:`flight_metrics` (pooled flights)."""
    rates = select_rates(_rates(cells), rates_shown, n=2)
    methods = _methods(cells)
    fig, axes = plt.subplots(2, len(rates), figsize=(5.2 * len(rates), 7), squeeze=False)
    table = []
    flier = {"marker": ".", "markersize": 3, "alpha": 0.3}
    for j, rate in enumerate(rates):
        det, dly, names = [], [], []
        for m in methods:
            fl = [f for c in cells if c["summary"]["method"] == m and c["summary"]["rate"] == rate
                  for f in c.get("flights") or []]
            if not fl:
                continue
            names.append(m)
            det.append(100.0 * (1.0 / np.array([f["weight"] for f in fl]) - 1.0))
            dly.append(np.array([f["departure_s"] - f["earliest_departure_s"] for f in fl
                                 if f.get("earliest_departure_s") not in (None, "")], dtype=float))
        if not names:
            continue
        axes[0][j].boxplot(det, widths=0.6, showfliers=True, flierprops=flier)
        axes[0][j].set_title(f"route detour, {rate} requests / interval")
        axes[0][j].set_ylabel("detour over the shortest route [%]")
        axes[1][j].boxplot([d if d.size else [np.nan] for d in dly], widths=0.6, showfliers=True,
                           flierprops=flier)
        axes[1][j].set_title(f"departure delay, {rate} requests / interval")
        axes[1][j].set_ylabel("departure - earliest departure [s]")
        for a in (axes[0][j], axes[1][j]):
            a.set_xticks(np.arange(1, len(names) + 1), names, fontsize=7)
            a.grid(alpha=0.3)
    for rate in _rates(cells):
        for m in methods:
            runs = [flight_metrics(c) for c in cells
                    if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            runs = [r for r in runs if r]
            if runs:
                table.append({"rate": rate, "method": m, **{
                    k: float(np.mean([r[k] for r in runs])) for k in
                    ("route_length_mean_m", "detour_mean_pct", "shortest_share", "delay_mean_s",
                     "delayed_share")}, "seeds": len(runs)})
    save_figure(fig, path)
    return {"path": str(path), "table": table}


def corridor_figure(cells, network, path: Path, rate=None, share: float = 0.10) -> dict:
    """Corridor utilisation against centrality: maps of flown distance per corridor (FIFO and
    each other method at one rate, seeds pooled) with the most central corridors outlined, and
    per run the share of flown distance on the ``share`` most central corridors."""
    cent, top = central_corridors(network, share)
    methods = _methods(cells)
    rates = _rates(cells)
    rate = rate if rate in rates else (rates[len(rates) // 2] if rates else None)
    shown = [m for m in ("fifo", "firstfit", "exact", "greedy") if m in methods] or methods[:3]
    fig, axes = plt.subplots(1, len(shown) + 1, figsize=(4.4 * (len(shown) + 1), 4.4), squeeze=False)
    xy = np.asarray(network.enu_m)[:, :2] / 1000.0
    e = np.asarray(network.edges)
    L = np.asarray(network.edge_length_m)
    table = []
    use_by = {}
    for m in shown:
        runs = [c for c in cells if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
        use_by[m] = sum((corridor_use_m(network, c.get("flights") or []) for c in runs),
                        np.zeros(network.n_edges)) / max(len(runs), 1)
    vmax = max(float((u / L).max()) for u in use_by.values()) if use_by else 1.0
    for ax, m in zip(axes[0], shown):
        flights_per_corridor = use_by[m] / L
        for k in np.argsort(flights_per_corridor):
            (a, b) = e[k]
            w = 0.3 + 4.0 * flights_per_corridor[k] / max(vmax, 1e-9)
            ax.plot(xy[[a, b], 0], xy[[a, b], 1], color=plt.cm.viridis(flights_per_corridor[k] / max(vmax, 1e-9)),
                    lw=w, solid_capstyle="round", zorder=2)
        for k in np.flatnonzero(top):
            (a, b) = e[k]
            ax.plot(xy[[a, b], 0], xy[[a, b], 1], color="r", lw=0.6, ls="--", zorder=3)
        ax.set_title(f"{_label(m)}, rate {rate}: flights per corridor", fontsize=9)
        ax.set_aspect("equal")
        ax.set_xlabel("east [km]")
    axes[0][0].set_ylabel("north [km]")
    ax = axes[0][-1]
    for i, m in enumerate(shown):
        ax.scatter(cent, use_by[m] / L, s=8, alpha=0.6, label=_label(m),
                   marker=style(m, i)["marker"], color=style(m, i)["color"])
    ax.set_xlabel("corridor edge-betweenness centrality")
    ax.set_ylabel(f"flights per corridor per run (rate {rate})")
    ax.set_title("utilisation against centrality (red dashed: top 10 %)", fontsize=9)
    ax.grid(alpha=0.3)
    ax.legend(fontsize=7)
    save_figure(fig, path)
    for r in rates:
        for m in methods:
            vals = [flight_metrics(c, network, top).get("central_share") for c in cells
                    if c["summary"]["method"] == m and c["summary"]["rate"] == r]
            vals = [v for v in vals if v is not None]
            if vals:
                mu, lo, hi = mean_ci(vals)
                table.append({"rate": r, "method": m, "central_share": mu, "lo": lo, "hi": hi,
                              "seeds": len(vals)})
    return {"path": str(path), "table": table, "top_corridors": int(top.sum()),
            "corridors": int(network.n_edges), "map_rate": rate, "top_mask": top}


def make_figures(cells, cfg, tts: dict, out: Path, render: bool = True) -> dict:
    """Write every figure as PNG into ``out/figures``; returns name -> {path, table}.
    ``render=False``: the same dict (the tables the report prints), no image written."""
    token = _RENDER.set(bool(render))
    try:
        return _make_figures(cells, cfg, tts, Path(out))
    finally:
        _RENDER.reset(token)


def _make_figures(cells, cfg, tts: dict, out: Path) -> dict:
    d = out / "figures"
    d.mkdir(parents=True, exist_ok=True)
    figs = {
        "cumulative": cumulative_figure(cells, d / "cumulative_approved.png", cfg.cumulative_rates),
        "approved": approved_figure(cells, d / "approved_per_rate.png"),
        "approval_rate": approval_rate_figure(cells, d / "approval_rate_vs_load.png", cfg.interval_s),
        "airborne": airborne_figure(cells, d / "aircraft_in_air.png"),
        "active": active_over_time_figure(cells, d / "active_over_time.png", cfg.cumulative_rates),
    }
    if any(c.get("flights") for c in cells):
        figs["flights"] = flights_figure(cells, d / "delay_detour.png")
        net = _network(cfg)
        if net is not None:
            figs["corridors"] = corridor_figure(cells, net, d / "corridors_centrality.png")
    if any(c["summary"]["method"] not in BASELINES for c in cells):
        figs["mwis_size"] = mwis_size_figure(cells, d / "mwis_size.png", cfg.k, cfg.window_s,
                                             cfg.interval_s)
        figs["solve_time"] = solve_time_figure(cells, d / "solve_time.png")
    t = tts_figure(tts, d / "tts.png") if tts.get("status") == "ok" else {}
    if t:
        figs["tts"] = t
    return figs
