"""REPORT.md of a sweep: setup, departures from the paper, figures with the numbers behind them,
paired comparisons, and the paper's statements checked.

Every statement is phrased from measured values (never a hard-coded claim): each comparison with
the paper prints the numbers it rests on and says "agrees", "agrees in part" or "does not
agree". Every comparison between two methods is paired per seed (identical demand) with a 95 %
confidence interval (:mod:`uam_sim.reports.stats`); a difference is stated as a finding only when its
interval excludes 0.
"""

from __future__ import annotations

import math
from dataclasses import asdict
from pathlib import Path

import numpy as np

from .figures import BASELINES, NEVER_PROVING, flight_metrics
from .knee import knee_section
from .stats import compare

# The command that regenerates the committed study (docs/paper-study).
STUDY_COMMAND = ("python -m uam_sim.experiment --config config/experiment.yaml --out results/study "
                 "--workers 2")
# Each committed study's command, by the output folder its configuration names
STUDY_COMMANDS = {"results/study": STUDY_COMMAND,
                  "results/load-sweep": "python -m uam_sim.experiment --config config/load-sweep.yaml "
                                        "--out results/load-sweep --workers 2",
                  "results/load-sweep-paper": "python -m uam_sim.experiment --config "
                                              "config/load-sweep-paper.yaml --out results/load-sweep-paper "
                                              "--workers 1",
                  "results/load-sweep-city": "python -m uam_sim.experiment --config config/load-sweep-city.yaml "
                                             "--out results/load-sweep-city --workers 1"}


def _f(x, nd=2) -> str:
    if x is None:
        return "-"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return str(int(x))
    x = float(x)
    if math.isnan(x):
        return "-"
    if math.isinf(x):
        return "inf"
    if x != 0 and (abs(x) < 10 ** -nd or abs(x) >= 1e6):
        return f"{x:.2e}"
    return f"{x:.{nd}f}"


def _table(rows: list, cols: list, heads: list | None = None, nd: int = 2) -> str:
    if not rows:
        return "_(no data)_\n"
    heads = heads or cols
    out = ["| " + " | ".join(heads) + " |", "|" + "---|" * len(cols)]
    for r in rows:
        out.append("| " + " | ".join(_cell(r.get(c), c, nd) for c in cols) + " |")
    return "\n".join(out) + "\n"


def _cell(v, col: str, nd: int) -> str:
    """One table cell: text as it is, a number to ``nd`` decimals; a rate those decimals would
    round (0.25 at one decimal) in full, so that no two rates of a table read the same."""
    if isinstance(v, str):
        return v
    if col == "rate" and isinstance(v, float) and math.isfinite(v) and round(v, nd) != v:
        return f"{v:g}"
    return _f(v, nd)


def _rel(fig_path: str, out: Path) -> str:
    try:
        return str(Path(fig_path).relative_to(out))
    except ValueError:
        return fig_path


def _ci(row: dict, key: str = "diff", nd: int = 1, unit: str = "") -> str:
    """'+12.0 [-24.0, +48.0]' from a stats.compare row."""
    m, lo, hi = row[key], row[f"{key}_lo"], row[f"{key}_hi"]
    u = unit
    if lo is None or (isinstance(lo, float) and math.isnan(lo)):
        return f"{m:+.{nd}f}{u} (no interval)"
    return f"{m:+.{nd}f}{u} [{lo:+.{nd}f}, {hi:+.{nd}f}]"


def _rel_ci(row: dict, nd: int = 1) -> str:
    return _ci({"x": row["rel_pct"], "x_lo": row["rel_lo"], "x_hi": row["rel_hi"]}, "x", nd, " %")


def _methods(cells) -> list:
    from .figures import _methods as order
    return order(cells)


def mwis_methods(cells) -> list:
    return [m for m in _methods(cells) if m not in BASELINES]


def _rates(cells) -> list:
    return sorted({c["summary"]["rate"] for c in cells})


def paired_rows(cells, a: str, b: str, metric="approved") -> list:
    """stats.compare rows with display columns (difference and relative difference with CIs,
    seeds with a positive / negative difference)."""
    rows = compare(cells, a, b, metric)
    for r in rows:
        r["diff_ci"] = _ci(r)
        r["rel_ci"] = _rel_ci(r)
        r["signs"] = f"{r['positive']}+ / {r['negative']}-"
        r["verdict"] = ("higher" if r["diff_lo"] > 0 else "lower" if r["diff_hi"] < 0
                        else "no supported difference") if r["seeds"] >= 2 else "one seed"
    return rows


def gains_vs_fifo(cells) -> list:
    """Per rate and MWIS method (and first-fit): paired approvals against FIFO (count and %)."""
    out = []
    for m in [x for x in _methods(cells) if x != "fifo"]:
        out.extend(paired_rows(cells, m, "fifo"))
    return out


# ---- departures from the paper ---------------------------------------------------------------

def not_called_shares(figs: dict) -> dict:
    """backend -> share of epochs with an MWIS instance in which the backend was never called
    (measured: see figures.NEVER_PROVING)."""
    st = figs.get("solve_time") or {}
    return {r["method"]: r["share_backend_not_called"] for r in st.get("table", [])
            if r["method"] in NEVER_PROVING and r["epochs"]}


def departures(cfg, figs: dict, tts: dict) -> list:
    """The ways this study differs from the paper's, each with its consequence (text)."""
    out = []
    shares = not_called_shares(figs)
    sh = ", ".join(f"{m} {100 * v:.1f} %" for m, v in shares.items())
    out.append(
        "**The MWIS pipeline wraps every backend.** `uam_solvers.solve` splits the conflict graph into "
        "connected components, solves single vertices and cliques directly, applies exact reductions "
        "and calls the chosen backend only on what is left. In the paper the solver gets the whole "
        "instance. Measured here, the share of epochs with an MWIS instance in which the backend was never "
        f"called (the pipeline proved the optimum alone): {sh or 'not measured (no annealer in the sweep)'}. "
        "So in the planning loop the solvers are compared on a few percent of the epochs only; the TTS "
        "study below hands the backends whole instances to compare them directly.")
    out.append(
        "**The quantum annealer is emulated.** `qpu-emulator` runs the D-Wave embedding pipeline "
        "(minorminer embedding on a Pegasus P16 graph, chain strength, unembedding) with classical "
        "simulated annealing as the sampler. It reports no QPU access or anneal times, so its "
        "times are CPU times of the emulation and say nothing about a real QPU's times. `qpu` with a "
        "D-Wave token runs the real one; it was not available for this study.")
    out.append(
        "**CP-SAT stands in for Gurobi.** The exact backend is OR-Tools CP-SAT (the `gurobi` "
        "backend exists but needs a licence). Both prove optimality, so optimal values agree; "
        "solve times do not compare with the paper's Gurobi times.")
    out.append(
        f"**Our own network.** `{cfg.network}` is this project's Singapore corridor network "
        "(docs/network-format.md), not the paper's; counts of approvals depend on its geometry, "
        "so they are compared with the paper's trends, not its absolute values.")
    out.append(
        f"**Speed {cfg.speed_mps:g} m/s is our assumption** (the paper does not state the cruise "
        "speed used); it sets flight times and so how long each flight occupies airspace.")
    reads = tts.get("reads") if isinstance(tts, dict) else None
    if reads:
        out.append(
            f"**{reads} reads per annealing call instead of the paper's 10,000**, and TTS per call "
            "and per read are both given (see the TTS section for what the number of reads changes).")
    return out


# ---- the paper's statements -------------------------------------------------------------------

def paper_checks(cells, figs: dict, tts: dict) -> list:
    """The paper's statements, each with the measured numbers and a verdict."""
    out = []
    rates = _rates(cells)
    moderate = rates[1:-1] if len(rates) >= 3 else rates
    mm = mwis_methods(cells)
    vs_fifo = {(r["a"], r["rate"]): r for m in mm for r in paired_rows(cells, m, "fifo")}
    if vs_fifo:
        mod = [vs_fifo[(m, r)] for m in mm for r in moderate if (m, r) in vs_fifo]
        higher = [g for g in mod if g["verdict"] == "higher"]
        ok = bool(mod) and len(higher) == len(mod)
        lo = min(mod, key=lambda g: g["rel_pct"])
        hi = max(mod, key=lambda g: g["rel_pct"])
        out.append(("Optimisation approves more than FIFO at moderate rates",
                    f"At the moderate rates {moderate}, {len(higher)} of {len(mod)} (MWIS method, "
                    f"rate) pairs approve more than shortest FIFO with a paired 95 % CI above 0; "
                    f"relative gains from {_rel_ci(lo)} ({lo['a']}, rate {lo['rate']}) to "
                    f"{_rel_ci(hi)} ({hi['a']}, rate {hi['rate']}).",
                    "agrees" if ok else ("agrees in part" if higher else "does not agree")))
        ref = "exact" if "exact" in mm else mm[0]
        rows = [vs_fifo[(ref, r)] for r in rates if (ref, r) in vs_fifo]
        if len(rows) >= 2:
            peak = max((x for x in rows if x["rate"] in moderate), key=lambda x: x["rel_pct"],
                       default=rows[0])
            last = rows[-1]
            rel_shrinks = last["rel_hi"] < peak["rel_lo"] if last["seeds"] >= 2 else last["rel_pct"] < peak["rel_pct"]
            count_shrinks = last["diff_hi"] < peak["diff_lo"] if last["seeds"] >= 2 else last["diff"] < peak["diff"]
            big = max(rows, key=lambda x: x["diff"])
            verdict = ("agrees" if rel_shrinks and count_shrinks else
                       "agrees in relative terms only" if rel_shrinks else "does not agree")
            out.append(("The gap to FIFO shrinks at high rates",
                        f"{ref} - FIFO per rate, in flights per run (paired 95 % CI): "
                        + ", ".join(f"{x['rate']}: {x['diff_ci']}" for x in rows)
                        + "; relative: " + ", ".join(f"{x['rate']}: {x['rel_ci']}" for x in rows)
                        + f". Relative gain {'shrinks' if rel_shrinks else 'does not clearly shrink'} "
                        f"(rate {peak['rate']}: {peak['rel_ci']} against rate {last['rate']}: "
                        f"{last['rel_ci']}); the count {'shrinks' if count_shrinks else 'does not shrink'} "
                        f"(largest {big['diff']:+.1f} flights at rate {big['rate']}, "
                        f"{last['diff']:+.1f} at rate {last['rate']}). The paper's figure is in "
                        "counts.", verdict))
    ms = figs.get("mwis_size")
    if ms and ms["table"]:
        t = ms["table"]
        worst = max(t, key=lambda r: r["vertices_over_bound"])
        far = worst["vertices_over_bound"] < 0.2
        out.append(("The MWIS instances (variables) stay far below the bound",
                    "Mean number of MWIS variables (conflict-graph vertices, the paper's quantity) "
                    "against the bound k x 3 x rate per rate: " + ", ".join(
                        f"{r['rate']}: {_f(r['vertices_mean'], 1)} / {r['vertex_bound']} "
                        f"({_f(100 * r['vertices_over_bound'], 1)} %, max {_f(r['vertices_max'], 0)})"
                        for r in t)
                    + f". Largest mean ratio {_f(100 * worst['vertices_over_bound'], 1)} % at rate "
                    f"{worst['rate']} (\"far below\" taken as under 20 %).",
                    "agrees" if far else "does not agree"))
    st = figs.get("solve_time")
    tt = figs.get("tts")
    if st and st["table"]:
        parts = [f"{r['method']}: {_f(100 * r['share_under_0.1s'], 1)} % of epochs under 0.1 s"
                 for r in st["table"]]
        mostly = all(r["share_under_0.1s"] >= 0.5 for r in st["table"])
        txt = "In the planning loop: " + "; ".join(parts) + "."
        if tt and tt["table"]:
            txt += " TTS per call: " + "; ".join(
                f"{r['backend']} median {_f(1e3 * r['median_s'], 2)} ms" for r in tt["table"]) + "."
            pr = [r for r in tt["table"] if r["per_read_median_s"] == r["per_read_median_s"]]
            if pr:
                txt += " TTS per read (the paper's definition): " + "; ".join(
                    f"{r['backend']} median {_f(1e3 * r['per_read_median_s'], 2)} ms" for r in pr) + "."
            mostly = mostly and all(r["share_under_0.1s"] >= 0.5 for r in tt["table"])
        out.append(("Solvers mostly reach the optimum within 0.1 s", txt,
                    "agrees" if mostly else "does not agree"))
    return out


def alternatives_vs_optimisation(cells) -> list:
    """How much of the MWIS gain over FIFO first-fit (alternatives without optimising) already
    gives, per rate: (first-fit - FIFO) / (exact - FIFO) from the paired means, and the paired
    exact - first-fit difference."""
    mm = mwis_methods(cells)
    ref = "exact" if "exact" in mm else (mm[0] if mm else None)
    methods = {c["summary"]["method"] for c in cells}
    if ref is None or not {"fifo", "firstfit"} <= methods:
        return []
    a = {r["rate"]: r for r in paired_rows(cells, ref, "fifo")}
    b = {r["rate"]: r for r in paired_rows(cells, "firstfit", "fifo")}
    c = {r["rate"]: r for r in paired_rows(cells, ref, "firstfit")}
    rows = []
    for rate in sorted(set(a) & set(b) & set(c)):
        share = b[rate]["diff"] / a[rate]["diff"] if a[rate]["diff"] else float("nan")
        rows.append({"rate": rate, "ref": ref, "mwis_gain": a[rate]["diff_ci"],
                     "firstfit_gain": b[rate]["diff_ci"], "share_pct": 100 * share,
                     "mwis_vs_firstfit": c[rate]["diff_ci"], "rel": c[rate]["rel_ci"],
                     "signs": c[rate]["signs"], "verdict": c[rate]["verdict"]})
    return rows


def beyond_paper(cells) -> list:
    """Observations the paper does not state, computed from the runs (text, no verdict)."""
    out = []
    methods = {c["summary"]["method"] for c in cells}
    if {"greedy", "exact"} <= methods:
        rows = paired_rows(cells, "greedy", "exact")
        sup = [r for r in rows if r["verdict"] != "no supported difference" and r["seeds"] >= 2]
        text = ("Greedy against exact (which proves each epoch's MWIS optimal), approvals per run, "
                "paired per seed with 95 % CI: " + ", ".join(
                    f"rate {r['rate']}: {r['diff_ci']} ({r['signs']})" for r in rows) + ". ")
        if sup:
            text += ("The difference is supported (CI excludes 0) at rates "
                     + ", ".join(f"{r['rate']} (greedy {r['verdict']})" for r in sup) + "; at the "
                     "other rates neither approves more. ")
        else:
            text += ("No interval excludes 0: greedy does not approve more (or fewer) flights than "
                     "exact at any rate on this evidence. ")
        ahead = [r for r in sup if r["verdict"] == "higher"]
        text += ("Optimal per epoch need not be optimal per run (each epoch's optimum is myopic, "
                 "and the weight d*/d rewards short routes, not throughput)"
                 + (f"; here greedy is ahead at rates {', '.join(str(r['rate']) for r in ahead)}."
                    if ahead else ", but these runs show no rate where greedy is ahead."))
        out.append(text)
    alt = alternatives_vs_optimisation(cells)
    if alt:
        shares = [r["share_pct"] for r in alt if r["share_pct"] == r["share_pct"]]
        sup = [r for r in alt if r["verdict"] in ("higher", "lower")]
        med = float(np.median(shares)) if shares else float("nan")
    if alt and shares:
        out.append(
            f"First-fit, over the same candidates and without optimising, gets "
            f"{_f(min(shares), 0)} % to {_f(max(shares), 0)} % (median {_f(med, 0)} %) of "
            f"{alt[0]['ref']}'s paired gain over FIFO per rate. {alt[0]['ref']} - first-fit has an "
            "interval excluding 0 at " + (", ".join(f"rate {r['rate']} ({alt[0]['ref']} {r['verdict']}, "
                                                    f"{r['mwis_vs_firstfit']})" for r in sup) or "no rate")
            + ("; at the other rates neither approves more. " if sup else ". ")
            + ("So most of the gain over shortest FIFO comes from having alternative routes, not from "
               "optimising over them." if med >= 50 else
               "So optimising over the alternatives accounts for most of the gain over FIFO."))
    optimal_methods = [m for m in ("exact", "sa", "tabu", "qpu-emulator", "kamis", "chils")
                       if m in methods]
    if len(optimal_methods) >= 2:
        spread = []
        for r in _rates(cells):
            vals = {}
            for m in optimal_methods:
                v = [c["summary"]["approved"] for c in cells
                     if c["summary"]["method"] == m and c["summary"]["rate"] == r]
                if v:
                    vals[m] = float(np.mean(v))
            if len(vals) >= 2 and max(vals.values()) - min(vals.values()) > 0:
                spread.append(f"{r} ({_f(min(vals.values()), 1)} to {_f(max(vals.values()), 1)})")
        if spread:
            out.append(
                "Solvers that reach the epoch optimum almost always (" + ", ".join(optimal_methods)
                + ") still end with different mean totals at rates " + ", ".join(spread)
                + ": when several selections tie at the optimum, which one is taken changes the airspace "
                "for every later epoch, so the runs diverge. Comparing solvers by approvals over a run "
                "therefore measures tie-breaking and chance as much as solution quality; the TTS study "
                "and the per-epoch optimality rates are the fair comparison.")
    return out


def _metric_rows(cells, metric_fn, a: str, b: str) -> list:
    return paired_rows(cells, a, b, metric_fn)


def write_report(sweep, outputs: dict, machine: dict, out: Path) -> Path:
    """Write ``out/REPORT.md`` from a SweepResult and run_experiment's outputs; returns its path.
    One helper per part of the report, in the report's order."""
    cfg = sweep.config
    cells = sweep.cells
    figs = outputs.get("figures", {})
    tts = outputs.get("tts", {})
    methods = _methods(cells)
    mm = mwis_methods(cells)
    L = _intro_lines(cfg.out)
    _setup_section(L, sweep, outputs, machine, methods)
    L += ["## Departures from the paper", ""] + [f"- {d}" for d in departures(cfg, figs, tts)] + [""]
    _safety_section(L, cfg, cells)
    _runs_section(L, cells, methods)
    if cfg.priority_share > 0 or cfg.operators:  # a demand with classes or operators: the load sweeps
        L += knee_section(cells, methods, _rates(cells), cfg.interval_s)

    def fig(name, title, cols, heads=None, note="", nd=2):
        _fig_section(L, figs, out, name, title, cols, heads, note, nd)

    _approvals_section(L, fig, cells, methods, mm)
    _load_section(L, fig, figs, cfg)
    _routes_section(L, fig, figs, cells, methods, cfg)
    _mwis_section(fig, figs, cfg)
    _tts_section(L, fig, figs, tts, cfg)
    _closing_section(L, cells, figs, tts)
    path = Path(out) / "REPORT.md"
    path.write_text("\n".join(L), encoding="utf-8")
    _write_inputs(Path(out), sweep, outputs, machine)
    return path


def _intro_lines(out: str = "results/study") -> list:
    return ["# UAM fleet planning study: results", "",
         "Written by `uam_sim.studies.experiment` (the in-process runner). Every number below is computed "
         "from the tables in this directory (`runs.csv`, `epochs.csv`, `flights.csv`, `tts.csv`, "
         f"gzipped where large, and `{INPUTS}`): `python -m uam_sim.report DIR` writes this report "
         "and its figures again from them. The whole study (cells, TTS, tables, report):", "",
         f"    {STUDY_COMMANDS.get(str(out), f'python -m uam_sim.experiment --out {out}')}", "",
         "Comparisons between methods are paired per seed (every method plans the same requests "
         "at one rate and seed) and given as mean difference [95 % CI] over seeds (Student t, "
         "`uam_sim.reports.stats`); 'k+ / j-' counts the seeds with a positive / negative difference. A "
         "difference is called a finding only when its interval excludes 0.", ""]


def _setup_section(L: list, sweep, outputs: dict, machine: dict, methods: list) -> None:
    cfg = sweep.config
    cells = sweep.cells
    wall_total = sum(c["summary"]["wall_s"] for c in cells)
    L += ["## Setup", "",
          f"- network: `{cfg.network}`; methods: {', '.join(methods)} ({_baselines_text(cfg)}; "
          "the others are MWIS backends)",
          f"- rates (requests per {cfg.interval_s:g} s): {cfg.rates}; seeds: {cfg.seeds}",
          f"- duration {cfg.duration_s:g} s, epoch {cfg.epoch_s:g} s, departure window "
          f"{cfg.window_s:g} s, separation {_separation_text(cfg)}, k = {cfg.k} candidates, "
          f"penalty factor {cfg.penalty_factor:g}, speed {cfg.speed_mps:g} m/s, MWIS time limit "
          f"{cfg.time_limit_s:g} s, solver options {cfg.solver_options or '{}'}",
          f"- demand: {'file ' + str(cfg.demand_file) if cfg.demand_file else 'seeded random (uam_sim.world.demand.RequestGenerator; the same requests for every method at one rate and seed)'}",
          f"- machine: {machine.get('cpu')} ({machine.get('cores')} cores), {machine.get('platform')}, "
          f"Python {machine.get('python')}",
          f"- commit: `{machine.get('commit')}`",
          f"- cells: {len(cells)} ({len(sweep.computed)} computed now, {len(sweep.reused)} reused "
          f"from earlier runs); this invocation: sweep wall time {sweep.wall_s:.1f} s with {cfg.workers} worker(s), "
          f"whole study (incl. TTS, figures) {outputs.get('wall_s', 0):.1f} s; sum of per-cell "
          f"run times {wall_total:.1f} s", ""]
    if getattr(sweep, "missing", None):
        L += [f"**Partial sweep:** {len(sweep.missing)} configured cells are not finished and are "
              f"left out of everything below: " + ", ".join(f"{m}/r{r}/s{s}" for m, r, s in sweep.missing[:40])
              + (" ..." if len(sweep.missing) > 40 else ""), ""]
    full = {"workers": cfg.workers, **{k: v for k, v in asdict(cfg).items() if k != "tts"}}
    L += ["<details><summary>All parameters</summary>", "", "```", *(f"{k}: {v}" for k, v in full.items()),
          f"tts: {cfg.tts}", "```", "</details>", ""]


def _baselines_text(cfg) -> str:
    """What FIFO and first-fit are, in the order they serve requests (cfg.baseline_order)."""
    if getattr(cfg, "baseline_order", "arrival") == "priority":
        return ("fifo = shortest route, by priority class then earliest latest departure; firstfit = "
                "in that order the first conflict-free of the same k candidates")
    return ("fifo = shortest route in arrival order; firstfit = in arrival order the first "
            "conflict-free of the same k candidates")


def _safety_section(L: list, cfg, cells) -> None:
    seps = [c["audit"].get("min_separation_m") for c in cells if c.get("audit")]
    seps = [s for s in seps if s is not None]
    losses = sum(c["audit"].get("losses", 0) for c in cells if c.get("audit"))
    audited = sum(1 for c in cells if c.get("audit"))
    flights = sum(int(c["summary"]["approved"]) for c in cells)
    L += ["## Safety audit", "",
          f"The exact closest-approach audit ran on {audited} of {len(cells)} runs over {flights} "
          f"flown flights in total: every pair of straight segments of different flights that "
          f"share time, closest approach in closed form (`uam_sim.audit.separation.sweep_audit`, a "
          f"vectorised time sweep independent of the planner's separation kernel; its tests hold "
          f"it equal to the brute-force `uam_planner.audit.audit_flights`). Minimum "
          f"separation seen: **{_f(min(seps) if seps else None, 2)} m** (minimum required "
          f"{cfg.separation_m:g} m). Losses of separation: **{losses}**"
          + (" (as required)." if losses == 0 else " - THIS IS A SAFETY FAILURE."), ""]


def _runs_section(L: list, cells, methods: list) -> None:
    runs = []
    for m in methods:
        for rate in _rates(cells):
            s = [c["summary"] for c in cells if c["summary"]["method"] == m and c["summary"]["rate"] == rate]
            if s:
                runs.append({"method": m, "rate": rate,
                             "requests": float(np.mean([x["requests"] for x in s])),
                             "approved": float(np.mean([x["approved"] for x in s])),
                             "expired": float(np.mean([x["expired"] for x in s])),
                             "approval_rate": float(np.mean([x["approval_rate"] for x in s])),
                             "avg_airborne": float(np.mean([x["avg_airborne"] for x in s])),
                             "wall_s": float(np.mean([x["wall_s"] for x in s])),
                             "fallbacks": int(sum(x["fallbacks"] for x in s))})
    L += ["## Runs (mean over seeds)", "", "One row per run in `runs.csv`; wall = mean wall time "
          "of one run on this (shared, loaded) machine.", "",
          _table(runs, ["method", "rate", "requests", "approved", "expired", "approval_rate",
                        "avg_airborne", "wall_s", "fallbacks"],
                 ["method", "rate", "requests", "approved", "expired", "approval rate",
                  "avg airborne", "wall [s]", "fallbacks"])]


def _fig_section(L: list, figs: dict, out, name, title, cols, heads=None, note="", nd=2) -> None:
    """A figure's section: heading, image, note and its table (nothing when it was not drawn)."""
    f = figs.get(name)
    if not f:
        return
    L.extend([f"## {title}", "", f"![{title}]({_rel(f['path'], out)})", ""])
    if note:
        L.extend([note, ""])
    if cols:
        L.append(_table(f["table"], cols, heads, nd))



def _approvals_section(L: list, fig, cells, methods: list, mm: list) -> None:
    fig("cumulative", "Cumulative approved flights over time",
        ["rate", "method", "final_mean", "final_lo", "final_hi", "seeds"],
        ["rate", "method", "approved at end (mean)", "95 % CI low", "95 % CI high", "seeds"],
        "One panel per rate; line = mean over seeds (each method its own marker and line style), "
        "band = 95 % CI of the mean (Student t). Methods that approve the same flights overlap "
        "exactly; the markers show each of them.")
    fig("approved", "Approved flights per rate", [], note="Means and unpaired 95 % CIs; the "
        "paired comparisons below are the ones that decide.")
    L += ["## Paired comparisons of approvals", ""]
    if "fifo" in methods:
        rows = gains_vs_fifo(cells)
        L += ["### Each method against shortest FIFO", "",
              _table(rows, ["a", "rate", "mean_a", "mean_b", "diff_ci", "rel_ci", "signs", "verdict"],
                     ["method", "rate", "approved", "FIFO", "difference [flights]", "relative", "seeds",
                      "finding"], 1)]
    if "firstfit" in methods and mm:
        rows = [r for m in mm for r in paired_rows(cells, m, "firstfit")]
        L += ["### Each MWIS method against first-fit (same candidates, no optimisation)", "",
              _table(rows, ["a", "rate", "mean_a", "mean_b", "diff_ci", "rel_ci", "signs", "verdict"],
                     ["method", "rate", "approved", "first-fit", "difference [flights]", "relative",
                      "seeds", "finding"], 1)]
        alt = alternatives_vs_optimisation(cells)
        if alt:
            L += ["**Alternatives or optimisation?** Share of the MWIS gain over FIFO that first-fit "
                  "already gets (ratio of the paired mean gains):", "",
                  _table(alt, ["rate", "mwis_gain", "firstfit_gain", "share_pct", "mwis_vs_firstfit",
                               "signs", "verdict"],
                         ["rate", f"{alt[0]['ref']} - FIFO", "first-fit - FIFO", "share [%]",
                          f"{alt[0]['ref']} - first-fit", "seeds", "finding"], 1)]
    if {"greedy", "exact"} <= set(methods):
        rows = paired_rows(cells, "greedy", "exact")
        L += ["### Greedy against exact", "",
              _table(rows, ["rate", "mean_a", "mean_b", "diff_ci", "rel_ci", "signs", "verdict"],
                     ["rate", "greedy", "exact", "difference [flights]", "relative", "seeds",
                      "finding"], 1)]


def _load_section(L: list, fig, figs: dict, cfg) -> None:
    fig("approval_rate", "Approval rate against offered load", [],
        note="Offered load = requests per hour (rate x 3600 s / interval); approval rate = "
             "approved / requested per run (mean, 95 % CI over seeds). Table: `runs.csv` "
             "(approval_rate).")
    fig("airborne", "Average aircraft in the air", [],
        note="Time average over the run, integrated exactly from each flight's departure and "
             "arrival (clipped to the run); `runs.csv` avg_airborne.")
    act = figs.get("active")
    fig("active", "Active aircraft over time (warm-up)",
        ["rate", "method", "warmup_s", "steady_active", "seeds"],
        ["rate", "method", "warm-up [s]", "steady level (aircraft)", "seeds"],
        note="Aircraft in the air at each epoch (`epochs.csv` active), mean over seeds. Warm-up "
             "= the first time the curve, smoothed over 5 epochs, reaches 90 % of its mean over "
             "the second half of the run. Whole-run averages (approvals, aircraft in the air) "
             "include the warm-up.", nd=1)
    if act and act["table"]:
        w = [r["warmup_s"] for r in act["table"] if r["warmup_s"] == r["warmup_s"]]
        if w:
            L += [f"Warm-up over all shown (rate, method): median {_f(float(np.median(w)), 0)} s, "
                  f"range {_f(min(w), 0)} to {_f(max(w), 0)} s of the {cfg.duration_s:g} s run.", ""]


def _routes_section(L: list, fig, figs: dict, cells, methods: list, cfg) -> None:
    fl = figs.get("flights")
    if fl:
        fig("flights", "Route detour and departure delay",
            ["rate", "method", "route_length_mean_m", "detour_mean_pct", "shortest_share",
             "delay_mean_s", "delayed_share"],
            ["rate", "method", "route length (mean) [m]", "detour (mean) [%]", "share on shortest",
             "delay (mean) [s]", "share delayed"],
            note="Detour = route length over the shortest route of the same origin and destination "
                 "(d/d* = 1/weight) - 1; delay = departure - earliest departure (0, 30 or 60 s with "
                 "30 s epochs and a 60 s window). Per flight: `flights.csv`.", nd=2)
        if "fifo" in methods:
            rows = []
            for m in [x for x in methods if x != "fifo"]:
                rows += paired_rows(cells, m, "fifo", lambda c: flight_metrics(c).get(
                    "route_length_mean_m", float("nan")))
            L += ["Mean route length per flown flight against FIFO (paired per seed):", "",
                  _table(rows, ["a", "rate", "mean_a", "mean_b", "diff_ci", "rel_ci", "signs"],
                         ["method", "rate", "mean length [m]", "FIFO [m]", "difference [m]",
                          "relative", "seeds"], 1)]
    cor = figs.get("corridors")
    if cor:
        fig("corridors", "Corridor utilisation against centrality",
            ["rate", "method", "central_share", "lo", "hi", "seeds"],
            ["rate", "method", "share of flown distance on the top corridors", "95 % CI low",
             "95 % CI high", "seeds"],
            note=f"Corridor centrality = edge betweenness over length-weighted shortest paths "
                 f"(networkx); the top 10 % = the {cor['top_corridors']} most central of the "
                 f"{cor['corridors']} corridors (red dashed in the maps). Maps: flights per "
                 f"corridor per run at rate {cor['map_rate']}, seeds pooled. The paper argues "
                 "that MWIS spreads traffic away from the central corridors.")
        if "fifo" in methods:
            from ..runner.network_spec import load_network_spec
            net = load_network_spec(cfg.network)
            top = cor["top_mask"]
            rows = []
            for m in [x for x in methods if x != "fifo"]:
                rows += paired_rows(cells, m, "fifo", lambda c: 100 * flight_metrics(c, net, top).get(
                    "central_share", float("nan")))
            L += ["Share of flown distance on the top 10 % corridors against FIFO, in "
                  "percentage points (paired per seed):", "",
                  _table(rows, ["a", "rate", "mean_a", "mean_b", "diff_ci", "signs", "verdict"],
                         ["method", "rate", "share [%]", "FIFO [%]", "difference [points]",
                          "seeds", "finding"], 1)]


def _mwis_section(fig, figs: dict, cfg) -> None:
    ms = figs.get("mwis_size")
    fig("mwis_size", "MWIS variables and MWIS size per rate",
        ["rate", "instances", "vertices_mean", "vertices_median", "vertices_p99", "vertices_max",
         "vertex_bound", "selected_mean", "selected_max", "eligible_mean", "size_bound"],
        ["rate", "instances", "variables (mean)", "variables (median)", "variables (p99)",
         "variables (max)", "variable bound", "MWIS size (mean)", "MWIS size (max)",
         "eligible requests (mean)", "MWIS size bound"],
        (f"Variables = conflict-graph vertices = the QUBO's binary variables (the paper's "
         f"quantity). Bound: a request is eligible only in the {ms['eligible_per_instant']} demand "
         f"instants of its departure window and has k = {cfg.k} candidates, so variables <= k x "
         f"{ms['eligible_per_instant']} x ceil(rate); the clique per request bounds the MWIS size "
         f"by the eligible requests <= {ms['eligible_per_instant']} x ceil(rate). Log scale, every "
         f"outlier drawn; epochs with an instance, pooled over the MWIS methods and seeds.") if ms else "")
    fig("solve_time", "Solve time per epoch",
        ["method", "epochs", "median_s", "p95_s", "max_s", "share_under_0.1s", "share_proven_optimal",
         "share_backend_not_called", "fallbacks"],
        ["method", "epochs", "median [s]", "p95 [s]", "max [s]", "share < 0.1 s", "share proven optimal",
         "share backend not called", "fallbacks"],
        note="Wall time of `uam_solvers.solve` per epoch with a non-empty conflict graph (component "
             "split, exact reductions, the backend, validation). 'Backend not called': for "
             "backends that never prove optimality themselves (annealers), the share of epochs "
             "proven optimal is the share the pipeline solved without calling them. A fallback is "
             "an epoch where the backend failed or ran past its time limit and greedy answered "
             "(`epochs.csv`); those depend on machine load.")


def _tts_section(L: list, fig, figs: dict, tts: dict, cfg) -> None:
    if figs.get("tts"):
        reads = tts.get("reads")
        pr = [r for r in figs["tts"]["table"] if r["per_read_median_s"] == r["per_read_median_s"]]
        fig("tts", f"TTS({tts.get('p', 0.99)}) per call and per read",
            ["backend", "instances", "median_s", "p25_s", "p75_s", "max_s", "not_reached",
             "penalised", "mean_p_opt", "share_under_0.1s"],
            ["backend", "instances", "per call: median [s]", "p25 [s]", "p75 [s]", "max [s]",
             "not reached", "penalised", "mean p_opt (per call)", "share < 0.1 s"],
            note=(f"{tts.get('instances')} instances of {cfg.tts['min_vertices']} to "
                  f"{cfg.tts['max_vertices']} vertices sampled (seeded, without replacement) from "
                  f"the runs' MWIS instances (`{Path(tts.get('corpus', '')).name}`), "
                  f"{tts.get('repetitions')} calls per instance and backend, {reads} reads per "
                  f"annealing call, optimum proven by CP-SAT; the whole instance is handed to the "
                  f"backend (no reductions). TTS(p) = t log(1 - p) / log(1 - p_success). **Per "
                  f"call** (left): one trial is one solver call, t = t_c (wall time of a call), "
                  f"p_success = p_opt, the share of calls that returned an optimum. **Per read** "
                  f"(right, the paper's definition): one trial is one read, t = t_c / reads (so a "
                  f"call's fixed costs are spread over its reads, making this an upper bound on "
                  f"the sampling time per read), p_success = the share of reads that were optimal "
                  f"(`read_opt_fraction` in `tts.csv`); at least one read. Deterministic solvers "
                  f"count a non-optimal answer as 10 s as in the paper; 'not reached' = never hit "
                  f"the optimum (left out of the box). Study wall time {_f(tts.get('wall_s'), 1)} s"
                  + (f"; sub-samples for slow backends: {tts.get('backend_instances')}"
                     if tts.get('backend_instances') else "") + "."))
        no_read = [r for r in figs["tts"]["table"] if r["per_read_median_s"] != r["per_read_median_s"]
                   and r.get("per_read_not_reached")]
        for r in no_read:  # an annealer whose reads never reached an optimum: no per-read TTS
            L += [f"Per read, {r['backend']}: nothing to measure (no read reached the optimum on "
                  f"any of its {r['per_read_not_reached']} instances).", ""]
        if pr:
            L += ["Per read:", "",
                  _table(pr, ["backend", "reads_per_call", "per_read_median_s", "per_read_median_lo",
                              "per_read_median_hi", "per_read_p25_s", "per_read_p75_s",
                              "per_read_not_reached", "mean_p_read", "share_p_read_below_p"],
                         ["backend", "reads per call", "per read: median [s]", "median 95 % CI low",
                          "high", "p25 [s]", "p75 [s]", "not reached", "mean p_read",
                          "share with p_read < 0.99"]),
                  f"**What {reads} instead of 10,000 reads changes.** Per read, nothing in "
                  f"principle: a read's success probability does not depend on how many reads a "
                  f"call makes, so per-read TTS is comparable with the paper's (more reads only "
                  f"estimate p_read more precisely and spread a call's fixed cost thinner). Per "
                  f"call, fewer reads make TTS *smaller*, not larger: at {reads} reads the calls "
                  f"already return an optimum almost always (mean p_opt per call "
                  + ", ".join(f"{r['backend']} {_f(r['mean_p_opt'], 3)}" for r in pr)
                  + "), so TTS per call is about one call's time, and a call of 10,000 reads "
                  f"would take about {10000 // int(reads) if reads else 100} times longer for at "
                  f"most the same p_opt. So per-call TTS here understates what the paper's "
                  f"10,000-read calls would cost, and the per-read figure is the one to compare.", ""]
    else:
        L += ["## TTS study", "", f"Not run: {tts.get('reason', 'no result')}.", ""]


def _closing_section(L: list, cells, figs: dict, tts: dict) -> None:
    L += ["## Compared with the paper's statements", ""]
    for title, text, verdict in paper_checks(cells, figs, tts):
        L += [f"- **{title}: {verdict}.** {text}"]
    L.append("")
    from .paper_figures import side_by_side_lines
    L += side_by_side_lines(cells, figs, tts, _rates(cells))
    extra = beyond_paper(cells)
    if extra:
        L += ["## Beyond the paper's statements", ""] + [f"- {text}" for text in extra] + [""]
    L += ["## The expanded airspace", "",
          "The paper's open question - with departure slots and flight levels and MWIS instances "
          "of hundreds to thousands of vertices, does the solver decide the throughput? - is "
          "answered by the capacity study (`python -m uam_sim.capacity_study --config "
          "config/capacity-study.yaml`; committed in `docs/capacity-study/`, its REPORT.md), "
          "which runs the same cells as this study in the airspace modes paper, + slots, "
          "+ levels and + both (`airspace_mode`, `uam_sim.runner.experiment_config.AIRSPACE_PRESETS`) "
          "on Singapore and a synthetic city, with the same paired per-seed statistics.", ""]


# ---- the report again from the tidy tables ----------------------------------------------------

INPUTS = "report_inputs.json"


def _separation_text(cfg) -> str:
    """The separation model in words: the paper's sphere, or the cylinder with its vertical minimum;
    and the departure rule (the epoch time, or slots)."""
    if getattr(cfg, "separation_model", "sphere") == "cylinder":
        text = (f"{cfg.separation_m:g} m horizontally while within {cfg.vertical_separation_m:g} m "
                f"vertically (cylinder model)")
    else:
        text = f"{cfg.separation_m:g} m in 3D (the paper's sphere model)"
    slot = float(getattr(cfg, "departure_slot_s", 0.0) or 0.0)
    mode = getattr(cfg, "airspace_mode", "paper")
    return text + (f", departures in {slot:g} s slots" if slot > 0 else ", departure at the epoch time") + \
        f", airspace mode {mode}"


def _write_inputs(out: Path, sweep, outputs: dict, machine: dict) -> None:
    """What the report needs besides the CSVs (configuration, machine, sweep counts and times,
    TTS settings), so :func:`report_from_tables` can write the same report from the tables."""
    import json
    tts = {k: v for k, v in (outputs.get("tts") or {}).items() if k != "rows"}
    data = {"config": asdict(sweep.config), "machine": machine,
            "sweep": {"computed": len(sweep.computed), "reused": len(sweep.reused),
                      "wall_s": sweep.wall_s, "missing": [list(m) for m in getattr(sweep, "missing", [])]},
            "wall_s": outputs.get("wall_s", 0.0), "tts": tts}
    (out / INPUTS).write_text(json.dumps(data, indent=1, default=str), encoding="utf-8")


def _parse(v: str):
    """A CSV field back to the value written: '' -> None, True/False, int, float, else text
    (text with '_' or spaces stays text: ids like r00001_002 or routes)."""
    if v == "":
        return None
    if v in ("True", "False"):
        return v == "True"
    if "_" in v or " " in v:
        return v
    for cast in (int, float):
        try:
            return cast(v)
        except ValueError:
            pass
    return v


def _read_csv(d: Path, name: str) -> list:
    import csv
    import functools
    import gzip
    for p, opener in ((d / name, open), (d / f"{name}.gz", gzip.open)):
        if p.exists():
            # each distinct text parsed once: the values (None, bool, int, float, str) are
            # immutable, and a study's tables repeat most of theirs (methods, counts, flags)
            parse = functools.lru_cache(maxsize=1 << 16)(_parse)
            with opener(p, "rt", encoding="utf-8", newline="") as fh:
                return [{k: parse(v) for k, v in row.items()} for row in csv.DictReader(fh)]
    return []


def cells_from_tables(d: Path) -> list:
    """The cells (summary, epochs, flights, audit) rebuilt from runs.csv, epochs.csv[.gz] and
    flights.csv[.gz] in ``d``, in the order of runs.csv."""
    runs = _read_csv(d, "runs.csv")
    if not runs:
        raise FileNotFoundError(f"{d}: no runs.csv")
    by: dict = {}
    for name, field in (("epochs.csv", "epochs"), ("flights.csv", "flights")):
        for row in _read_csv(d, name):
            tag = (row.pop("method"), row.pop("rate"), row.pop("seed"))
            by.setdefault((field, tag), []).append(row)
    cells = []
    for s in runs:
        tag = (s["method"], s["rate"], s["seed"])
        cells.append({"key": f"{tag[0]}_r{tag[1]}_s{tag[2]}", "summary": s,
                      "epochs": by.get(("epochs", tag), []), "flights": by.get(("flights", tag), []),
                      "audit": {"min_separation_m": s.get("min_separation_m"),
                                "losses": s.get("losses") or 0} if s.get("losses") is not None else {},
                      "instances": [], "rejections": []})
    return cells


def report_from_tables(d, figures: bool = True, render: bool = True) -> Path:
    """Write ``d/REPORT.md`` (and the figures) again from the tables and ``report_inputs.json``
    of a finished study (e.g. docs/paper-study): every number of the report comes from them.
    ``render=False``: the figures' tables and the report's text the same, no image written
    (the committed reports' rebuild tests)."""
    import json
    from types import SimpleNamespace

    from ..runner.experiment_config import make_config
    from .figures import make_figures
    d = Path(d)
    inputs = json.loads((d / INPUTS).read_text(encoding="utf-8"))
    cfg = make_config(inputs["config"])  # as run (its "out" is printed); files go to d
    cells = cells_from_tables(d)
    tts = dict(inputs.get("tts") or {})
    if tts.get("status") == "ok":
        tts["rows"] = _read_csv(d, "tts.csv")
    sw = inputs["sweep"]
    sweep = SimpleNamespace(config=cfg, cells=cells, computed=[None] * sw["computed"],
                            reused=[None] * sw["reused"], wall_s=sw["wall_s"],
                            missing=[tuple(m) for m in sw.get("missing", [])])
    figs = make_figures(cells, cfg, tts, d, render=render) if figures else {}
    return write_report(sweep, {"figures": figs, "tts": tts, "wall_s": inputs.get("wall_s", 0.0)},
                        inputs["machine"], d)


def main(argv=None) -> int:
    """``python -m uam_sim.report DIR``: the report of a finished study again from its tables."""
    import argparse
    p = argparse.ArgumentParser(allow_abbrev=False, prog="uam_sim.report", description=report_from_tables.__doc__)
    p.add_argument("dir", help="study directory with runs.csv, epochs.csv[.gz], flights.csv[.gz], "
                               f"tts.csv and {INPUTS}")
    args = p.parse_args(argv)
    try:
        print(report_from_tables(args.dir))
    except (OSError, ValueError) as exc:
        print(f"uam_sim.report: {exc}", file=__import__("sys").stderr)
        return 2
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
