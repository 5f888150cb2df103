"""The large-instance study's report (``docs/large-instances/REPORT.md``), from its tables alone.

    python -m uam_sim.large_instances_report docs/large-instances

Reads ``config.json``, ``instances.csv``, ``solves.csv.gz`` and ``replanning.csv`` (written by
:mod:`uam_sim.studies.large_instances`) and writes ``summary.csv`` (one row per solver and size
bin) and ``REPORT.md``. Every number and every verdict word is computed here from those rows;
the same tables give the same bytes (``src/uam_sim/test/test_large_instances.py`` checks).

Definitions (stated in the report too):

- best known: the largest objective any solver (the reference included) reached on the instance;
- gap [%]: 100 (best known - objective) / best known;
- time to target [s]: the wall time of the solver's answer when its gap is at most
  :data:`TARGET_GAP_PCT`, else "not reached" (one answer per solver and instance, so this is the
  time to the target at the solver's limit, not a run-length distribution);
- gain over first-fit: per instance, 100 (objective - first-fit's) / first-fit's [%], and the
  approvals (count) minus first-fit's, as mean and 95 % t interval over the bin's instances
  (:func:`uam_sim.reports.stats.mean_interval`).
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
from .markdown import table_lines as _table
from .stats import mean_interval, paired

TARGET_GAP_PCT = 0.1
ORDER = ["firstfit", "greedy", "auto", "exact", "sa", "tabu", "qpu-emulator", "reference"]
#: the optimiser the paragraph reads: the planner's default MWIS backend
OPTIMISER = "auto"
BASELINE = "firstfit"
TABLES = ("config.json", "instances.csv", "solves.csv.gz", "replanning.csv")


def _f(x, nd: int = 2, sign: bool = False) -> str:
    if x is None or (isinstance(x, float) and math.isnan(x)):
        return "-"
    if isinstance(x, (bool, np.bool_)):
        return "yes" if x else "no"
    if isinstance(x, (int, np.integer)):
        return f"{int(x):+,d}" if sign else f"{int(x):,d}"
    return f"{float(x):+,.{nd}f}" if sign else f"{float(x):,.{nd}f}"


def _true(col: pd.Series) -> pd.Series:
    return col.astype(str) == "True"


def _bin_label(lo, hi) -> str:
    return f"[{lo:,}, {hi:,})"


def gaps(solves: pd.DataFrame, bins: list) -> pd.DataFrame:
    """Each (instance, solver) row with the best known objective, its gap [%], the time to
    target, the gain over first-fit (objective [%] and count) and the size bin."""
    key = ["run", "epoch"]
    g = solves.copy()
    g["best_known"] = g.groupby(key)["objective"].transform("max")
    g["gap_pct"] = np.where(g["best_known"] > 0,
                            100.0 * (g["best_known"] - g["objective"]) / g["best_known"], 0.0)
    g["reached"] = g["gap_pct"] <= TARGET_GAP_PCT
    g["time_to_target_s"] = np.where(g["reached"], g["wall_s"], np.nan)
    ff = g[g["solver"] == BASELINE].set_index(key)
    base = g.set_index(key).index
    ff_obj = base.map(ff["objective"].to_dict())
    ff_count = base.map(ff["count"].to_dict())
    g["gain_pct"] = 100.0 * (g["objective"].to_numpy() - ff_obj) / ff_obj
    g["count_gain"] = g["count"].to_numpy() - ff_count
    g["bin"] = pd.cut(g["vertices"], bins, right=False,
                      labels=[_bin_label(lo, hi) for lo, hi in zip(bins[:-1], bins[1:])]).astype(str)
    g["bin_lo"] = pd.cut(g["vertices"], bins, right=False, labels=bins[:-1]).astype(int)
    return g


def summary_rows(g: pd.DataFrame, bins: list, keys: set | None = None) -> list:
    """One row per solver and size bin: gaps, time to target, proofs, fallbacks, wall; of every
    instance (subset ``all``) or, with ``keys`` ({(run, epoch)}), of those instances alone
    (subset ``steady state``)."""
    rows = []
    if keys is not None:
        g = of_epochs(g, keys)
    for s in [x for x in ORDER if x in set(g["solver"])]:
        for lo, hi in zip(bins[:-1], bins[1:]):
            x = g[(g["solver"] == s) & (g["bin_lo"] == lo)]
            if x.empty:
                continue
            ttt = x["time_to_target_s"].dropna()
            rows.append({"subset": "all" if keys is None else STEADY,
                         "solver": s, "bin": _bin_label(lo, hi), "instances": len(x),
                         "vertices_max": int(x["vertices"].max()),
                         "gap_mean_pct": float(x["gap_pct"].mean()),
                         "gap_max_pct": float(x["gap_pct"].max()),
                         "reached_share": float(x["reached"].mean()),
                         "time_to_target_median_s": float(ttt.median()) if len(ttt) else float("nan"),
                         "gain_mean_pct": float(x["gain_pct"].mean()),
                         "count_gain_mean": float(x["count_gain"].mean()),
                         "proven_share": float(_true(x["proven_optimal"]).mean()),
                         "fallbacks": int(_true(x["fallback"]).sum()),
                         "wall_median_s": float(x["wall_s"].median()),
                         "wall_max_s": float(x["wall_s"].max())})
    return rows


# -- the recorded window -------------------------------------------------------------------------

STEADY, WARMUP, START = "steady state", "warm-up", "from the start"


def phases(inst: pd.DataFrame) -> pd.Series:
    """Each epoch row's phase: ``warm-up`` (before its run's ``record_from_s``: planned to fill
    the sky, its instance neither kept nor sampled), ``steady state`` (at or after a
    ``record_from_s`` > 0) or ``from the start`` (a run recorded from t = 0, no warm-up).
    Tables without the window's columns are read as recorded from the start."""
    start = inst["record_from_s"] if "record_from_s" in inst else pd.Series(0.0, inst.index)
    warm = _true(inst["warmup"]) if "warmup" in inst else pd.Series(False, inst.index)
    return pd.Series(np.where(warm, WARMUP, np.where(start.astype(float) > 0, STEADY, START)),
                     index=inst.index)


def check_window(inst: pd.DataFrame, solves: pd.DataFrame) -> None:
    """Every solved instance is an epoch of instances.csv marked sampled and not warm-up, and
    every epoch marked sampled was solved: ValueError naming the first (run, epoch) that is not."""
    ph = phases(inst)
    bad = inst[_true(inst["sampled"]) & (ph == WARMUP)]
    if len(bad):
        r = bad.iloc[0]
        raise ValueError(f"instances.csv: run {r['run']} epoch {int(r['epoch'])} (t = "
                         f"{r['t_s']} s) is sampled but in its warm-up (record_from_s = "
                         f"{r['record_from_s']})")
    picked = {(r, int(e)) for r, e in inst[_true(inst["sampled"])][["run", "epoch"]].itertuples(index=False)}
    solved = {(r, int(e)) for r, e in solves[["run", "epoch"]].drop_duplicates().itertuples(index=False)}
    for what, x in (("solved but not a sampled epoch of instances.csv", sorted(solved - picked)),
                    ("sampled in instances.csv but not solved", sorted(picked - solved))):
        if x:
            raise ValueError(f"solves.csv.gz: run {x[0][0]} epoch {x[0][1]} is {what}")


def of_epochs(g: pd.DataFrame, keys: set) -> pd.DataFrame:
    """The rows of ``g`` whose (run, epoch) is in ``keys``."""
    return g[[k in keys for k in zip(g["run"], g["epoch"].astype(int))]]


def steady_keys(inst: pd.DataFrame) -> set:
    """{(run, epoch)} of the steady-state epochs."""
    x = inst[phases(inst) == STEADY]
    return {(r, int(e)) for r, e in x[["run", "epoch"]].itertuples(index=False)}


# -- sections ------------------------------------------------------------------------------------

def _instances_lines(cfg: dict, inst: pd.DataFrame) -> list:
    rec = cfg["record"]
    L = ["## Recorded instances", "",
         f"The city `{rec['city']}` (seed {rec['city_seed']}), planned in process under the policy "
         f"`{rec['method']}` (it builds the instance the MWIS policy would solve), cylinder "
         f"separation with V = {_f(rec['vertical_separation_m'], 0)} m, "
         f"{_f(rec['slot_s'], 0)} s departure slots, demand seed {rec['seed']}, routes searched "
         "when a pair is first requested. One row per run and phase: its epochs (t from / to), "
         "the instances' sizes, the requests decided per epoch and the share of them approved "
         "(the contention the instances carry), the flights airborne (median and at the last "
         "epoch), and the CPU per epoch of building and deciding it (the process's CPU time, "
         f"solver-free). Phase: `{WARMUP}` = planned before the run's `record_from_s` to fill "
         "the sky, its instances neither kept nor sampled; "
         f"`{STEADY}` = from `record_from_s` on; `{START}` = a run recorded from t = 0.", ""]
    rows = []
    inst = inst.assign(phase=phases(inst))
    for (run, phase), x in inst.groupby(["run", "phase"], sort=False):
        rows.append([run, _f(int(x["rate_per_hour"].iloc[0])), phase, len(x),
                     f"{_f(x['t_s'].min(), 0)} / {_f(x['t_s'].max(), 0)}",
                     f"{_f(int(x['vertices'].min()))} / {_f(int(x['vertices'].median()))} / "
                     f"{_f(int(x['vertices'].max()))}", _f(int(x["edges"].max())),
                     _f(x["eligible"].mean(), 1),
                     _f(100.0 * x["approved"].sum() / max(int(x["eligible"].sum()), 1), 1),
                     f"{_f(int(x['airborne'].median()))} / {_f(int(x['airborne'].iloc[-1]))}",
                     int(_true(x["sampled"]).sum()),
                     f"{_f(x['cpu_s'].median(), 1)} / {_f(x['cpu_s'].max(), 1)}"])
    L += _table(rows, ["run", "requests/h", "phase", "epochs", "t [s]",
                       "vertices min / median / max", "edges max", "requests decided per epoch",
                       "approved [%]", "airborne median / at the end", "sampled",
                       "CPU per epoch median / max [s]"])
    return L + [""]


def _solves_lines(cfg: dict, g: pd.DataFrame, rows: list) -> list:
    sol = cfg["solve"]
    n_inst = g[["run", "epoch"]].drop_duplicates().shape[0]
    ref = g[g["solver"] == "reference"]
    L = ["## Matched shadow solves", "",
         f"{n_inst} instances (a seeded sample of up to {sol['per_bin']} per size bin of each "
         f"run, bins {', '.join(_f(b) for b in sol['bins'])}; of a steady-state window "
         + ("every kept instance" if sol.get("steady_per_bin", sol["per_bin"]) is None else
            f"up to {sol.get('steady_per_bin', sol['per_bin'])} per bin")
         + "), each solved by "
         f"{', '.join(sol['backends'])} at {_f(sol['time_limit_s'], 1)} s and by the reference "
         f"({sol['reference']['backend']}, {_f(sol['reference']['time_limit_s'], 0)} s), one "
         "after the other on one worker (uam_sim.studies.decision_study.e0_solve_rows, as E0). "
         "Best known = the largest objective any of them reached on the instance; gap = (best "
         "known - objective) / best known; time to target = the wall time of the solver's answer "
         f"when its gap is at most {_f(TARGET_GAP_PCT, 1)} %, else not reached; gain = the "
         "objective over first-fit's [%] and the approvals minus first-fit's (count). A "
         "fallback is an answer the solver service gave in the backend's place (it overran its "
         "limit + 0.4 s: the greedy answer computed before the solve).", "",
         f"The reference proved its answer optimal on {int(_true(ref['proven_optimal']).sum())} "
         f"of {len(ref)} instances (largest proven: "
         f"{_f(int(ref[_true(ref['proven_optimal'])]['vertices'].max())) if _true(ref['proven_optimal']).any() else 'none'} "
         f"vertices) and fell back on {int(_true(ref['fallback']).sum())}; above that the best "
         "known is a bound from below, not the optimum.", ""]
    head = ["solver", "vertices", "instances", "largest", "gap mean [%]", "gap max [%]",
            "target reached [%]", "time to target median [s]", "gain over first-fit [%]",
            "approvals over first-fit", "proven [%]", "fallbacks", "wall median [s]",
            "wall max [s]"]
    for subset in ("all", STEADY):
        sel = [r for r in rows if r["subset"] == subset]
        if subset == STEADY and sel:
            L += ["", "The same of the steady-state instances alone (best known and gaps as "
                  "above):", ""]
        L += _table([[r["solver"], r["bin"], r["instances"], _f(r["vertices_max"]),
                      _f(r["gap_mean_pct"], 3), _f(r["gap_max_pct"], 3),
                      _f(100 * r["reached_share"], 0), _f(r["time_to_target_median_s"], 2),
                      _f(r["gain_mean_pct"], 3, True), _f(r["count_gain_mean"], 2, True),
                      _f(100 * r["proven_share"], 0), r["fallbacks"], _f(r["wall_median_s"], 2),
                      _f(r["wall_max_s"], 2)] for r in sel], head) if sel else []
    L += ["", "Per instance, the gap [%] of each solver (`-`: not run):", ""]
    solvers = [s for s in ORDER if s in set(g["solver"])]
    inst_rows = []
    for (run, epoch), x in g.groupby(["run", "epoch"], sort=False):
        by = x.set_index("solver")
        inst_rows.append([run, int(epoch), _f(int(x["vertices"].iloc[0])),
                          _f(int(x["edges"].iloc[0])), _f(float(x["best_known"].iloc[0]), 3)]
                         + [_f(by.loc[s, "gap_pct"], 3)
                            + ("*" if _true(by.loc[[s], "fallback"]).iloc[0] else "")
                            if s in by.index else "-" for s in solvers])
    L += _table(inst_rows, ["run", "epoch", "vertices", "edges", "best known"] + solvers)
    return L + ["", "`*`: a fallback answer.", ""]


def _replanning_lines(rp: pd.DataFrame | None, args: dict | None) -> tuple[list, dict]:
    if rp is None or rp.empty:
        return ["## Re-planning after a restriction", "", "No re-planning rows yet.", ""], {}
    L = ["## Re-planning after a restriction", "",
         "`scripts/measure_replanning.py " + " ".join(args["args"] if args else []) + "`, one "
         "process per seed: the layered synthetic city; at the announcement a circle is put "
         "over the busiest area (the corridor node with the most airborne aircraft within its "
         "radius), in force after the lead time; each seed runs twice from the same demand, "
         "re-plan policy `mwis` and `firstfit` (the epochs are MWIS in both). Reach = affected "
         "flights still reaching their destination (kept, re-routed, re-timed); saved = reach "
         "plus diverted; added delay = mean over those reaching their destination.", ""]
    L += _table([[r["seed"], r["policy"], _f(int(r["intents"])), _f(int(r["affected"])),
                  _f(int(r["reach"])), _f(int(r["saved"])), _f(r["reach_delay_mean_s"], 1),
                  _f(int(r["diverted"])), _f(int(r["cancelled"])), _f(int(r["contingency"])),
                  _f(int(r["vertices"])), _f(r["decision_cpu_s"], 2), r["losses"],
                  r["incursions"]] for r in rp.to_dict("records")],
                ["seed", "policy", "intents", "affected", "reach", "saved", "added delay [s]",
                 "diverted", "cancelled", "contingency", "vertices", "decision CPU [s]",
                 "losses", "incursions"])
    L.append("")
    res = {}
    a = rp[rp["policy"] == "mwis"].set_index("seed")
    b = rp[rp["policy"] == "firstfit"].set_index("seed")
    for metric, unit in (("reach", "flights"), ("saved", "flights"), ("reach_delay_mean_s", "s")):
        pr = paired(a[metric].to_dict(), b[metric].to_dict())
        res[metric] = pr
        L.append(f"- MWIS - first-fit, {metric}: {_f(pr.mean, 2, True)} {unit} "
                 f"[{_f(pr.lo, 2, True)}, {_f(pr.hi, 2, True)}] over {pr.n} seeds "
                 f"({pr.positive} positive / {pr.negative} negative).")
    return L + [""], res


def _interval_word(lo: float, hi: float, above: str, below: str, neither: str) -> str:
    if not (math.isfinite(lo) and math.isfinite(hi)):
        return neither
    return above if lo > 0 else below if hi < 0 else neither


def _gain_by_bin(g: pd.DataFrame, solver: str) -> list:
    """[(bin label, lower edge, n, objective gain mean/lo/hi [%], count gain mean/lo/hi)]."""
    out = []
    x = g[g["solver"] == solver]
    for lo, y in x.groupby("bin_lo", sort=True):
        m, a, b = mean_interval(y["gain_pct"].to_numpy(dtype=float))
        c, ca, cb = mean_interval(y["count_gain"].to_numpy(dtype=float))
        out.append((y["bin"].iloc[0], int(lo), len(y), m, a, b, c, ca, cb))
    return out


PREDICTION = "The paper predicts that the optimiser matters once capacity grows."


def _prediction_lines(g: pd.DataFrame, inst: pd.DataFrame, rp_res: dict,
                      lead: bool = True) -> list:
    """One paragraph answering the paper's prediction by instance size; every number and word
    from the rows. ``lead``: it opens the section (no steady-state paragraph before it)."""
    gains = _gain_by_bin(g, OPTIMISER)
    if not gains:
        return []
    small, large = gains[0], gains[-1]
    big = g[(g["bin_lo"] == large[1]) & ~g["solver"].isin([BASELINE, "reference"])]
    fb = int(_true(big["fallback"]).sum())
    top = g[(g["bin_lo"] == large[1]) & (g["solver"] != BASELINE)]
    at_best = top[np.isclose(top["objective"], top["best_known"])]
    own = int(at_best.groupby(["run", "epoch"])["fallback"].apply(lambda c: _true(c).all()).sum())
    reached = g[(g["bin_lo"] == large[1]) & (g["solver"] == OPTIMISER)]["reached"].mean()
    runs = list(dict.fromkeys(g[g["bin_lo"] == large[1]]["run"]))
    inst = inst[inst["run"].isin(runs)]
    approved, decided = int(inst["approved"].sum()), int(inst["eligible"].sum())
    contention = ("every request" if approved == decided else
                  f"{_f(100.0 * approved / max(decided, 1), 1)} % of the requests")
    per_request = float((inst["vertices"] / inst["eligible"].clip(lower=1)).median())
    trend = ("grows" if large[3] > small[3] else "shrinks" if large[3] < small[3] else "stays")
    count_word = _interval_word(large[7], large[8], "more", "fewer", "no more and no fewer")
    obj_word = _interval_word(large[4], large[5], "above", "below", "not distinguishable from")
    pays = ("in approvals" if count_word == "more" else
            "in the objective only" if obj_word == "above" else "in neither approvals nor objective")
    why = ("each request brings many candidates and the requests barely compete, so there is "
           "little for the optimiser to win in approvals" if approved == decided else
           "some requests compete for the same airspace")
    txt = ((f"{PREDICTION} On the largest " if lead else "By size: on the largest ")
           + f"instances recorded here it pays {pays}: {OPTIMISER} at the 1 s limit is "
           f"{_f(small[3], 3, True)} % [{_f(small[4], 3, True)}, {_f(small[5], 3, True)}] above "
           f"first-fit in the objective in the smallest bin ({small[0]} vertices, {small[2]} "
           f"instances) and {_f(large[3], 3, True)} % [{_f(large[4], 3, True)}, "
           f"{_f(large[5], 3, True)}] in the largest ({large[0]}, {large[2]} instances), so its "
           f"gain {trend} with the instance's size and is {obj_word} first-fit's in the largest "
           f"bin, where it approves {count_word} flights than first-fit "
           f"({_f(large[6], 2, True)} [{_f(large[7], 2, True)}, {_f(large[8], 2, True)}] per "
           f"instance). Under first-fit the recorded epochs of the runs these instances come "
           f"from ({', '.join(runs)}) approved {contention} they decided, "
           f"with a median of {_f(per_request, 0)} vertices per request decided (levels x "
           f"departure slots x routes): {why}. At this size the 1 s limit "
           f"{'binds' if fb else 'holds'}: {fb} of the "
           f"{len(big)} answers of the 1 s optimisers in the largest bin were fallbacks (the "
           f"greedy answer computed before the solve), their wall time median "
           f"{_f(big['wall_s'].median(), 1)} s and max {_f(big['wall_s'].max(), 1)} s against the "
           f"limit, and the best known there came from a fallback on {own} of its "
           f"{large[2]} instances ({_f(100 * reached, 0)} % of {OPTIMISER}'s answers there within "
           f"{_f(TARGET_GAP_PCT, 1)} % of it)"
           + (": what the optimisers gain over first-fit at this size is the greedy fallback's "
              "gain." if own == large[2] else "."))
    if rp_res:
        r, d, v = rp_res["reach"], rp_res["reach_delay_mean_s"], rp_res["saved"]
        word = _interval_word(r.lo, r.hi, "keeps more flights reaching their destination than",
                              "keeps fewer flights reaching their destination than",
                              "is not distinguishable, in flights still reaching their "
                              "destination, from")
        txt += (f" After a restriction over the busiest area, MWIS re-planning {word} "
                f"first-fit over {r.n} seeds ({_f(r.mean, 2, True)} flights [{_f(r.lo, 2, True)}, "
                f"{_f(r.hi, 2, True)}]), with {_f(d.mean, 1, True)} s [{_f(d.lo, 1, True)}, "
                f"{_f(d.hi, 1, True)}] of added delay per flight reaching its destination; it "
                + _interval_word(v.lo, v.hi, "saves more", "saves fewer", "saves no more and no fewer")
                + f" flights from a contingency ({_f(v.mean, 2, True)} [{_f(v.lo, 2, True)}, "
                f"{_f(v.hi, 2, True)}], {v.positive} of {v.n} seeds up).")
    return (["## The paper's prediction", ""] if lead else []) + [txt, ""]


def _epoch_s(x: pd.DataFrame) -> float:
    """A run's epoch length [s]: the median step of its epochs' times."""
    return float(np.median(np.diff(np.sort(x["t_s"].to_numpy(dtype=float)))))


def _steady_lines(g: pd.DataFrame, inst: pd.DataFrame) -> list:
    """The paper's prediction answered from the steady-state rows alone (the section's first
    paragraph: the prediction is about contention, which only these rows carry): their
    contention (instances.csv) and the optimiser's gain over first-fit on their sampled
    instances."""
    ph = phases(inst)
    st, warm = inst[ph == STEADY], inst[ph == WARMUP]
    if st.empty:
        return []
    sg = of_epochs(g, steady_keys(inst))
    runs = ", ".join(f"{run} from t = {_f(float(x['record_from_s'].iloc[0]), 0)} s"
                     for run, x in st.groupby("run", sort=False))
    approved, decided = int(st["approved"].sum()), int(st["eligible"].sum())
    share = 100.0 * approved / max(decided, 1)
    offered = sum(float(x["rate_per_hour"].iloc[0]) * len(x) * _epoch_s(inst[inst["run"] == run])
                  / 3600.0 for run, x in st.groupby("run", sort=False))
    txt = (f"{PREDICTION} At steady state ({runs}: {len(st)} epochs, after {len(warm)} warm-up epochs planned "
           f"to fill the sky but neither kept nor sampled), first-fit approved {_f(share, 1)} % of "
           f"the {_f(decided)} requests it decided ({_f(st['eligible'].mean(), 1)} per epoch; a "
           f"request refused in an epoch is decided again while its departure window lasts): "
           f"{_f(approved / len(st), 1)} approvals per epoch, {_f(100.0 * approved / offered, 1)} % "
           f"of the {_f(offered / len(st), 1)} requests the rate offers per epoch, with "
           f"{_f(int(st['airborne'].median()))} flights airborne (median; "
           f"{_f(int(st['airborne'].min()))} to {_f(int(st['airborne'].max()))}) and instances of "
           f"{_f(int(st['vertices'].min()))} to {_f(int(st['vertices'].max()))} vertices"
           + (f" (the warm-up's up to {_f(int(warm['vertices'].max()))}: the airborne flights "
              "discard most candidates)" if len(warm) else "") + ": "
           + ("the requests compete there." if approved < decided else
              "every request is approved even there, so the requests do not compete."))
    opt = sg[sg["solver"] == OPTIMISER]
    if opt.empty:
        return ["## The paper's prediction", "", txt + " None of its instances was solved.", ""]
    m, lo, hi = mean_interval(opt["gain_pct"].to_numpy(dtype=float))
    c, clo, chi = mean_interval(opt["count_gain"].to_numpy(dtype=float))
    ff = sg[sg["solver"] == BASELINE]
    count_word = _interval_word(clo, chi, "more", "fewer", "no more and no fewer"
                                if clo == chi == 0 else "not distinguishably more or fewer")
    obj_word = _interval_word(lo, hi, "above", "below", "not distinguishable from")
    verdict = ("holds here: the optimiser approves more flights than first-fit" if count_word == "more"
               else "holds in the objective only: the optimiser's selection weighs more than "
               "first-fit's without approving distinguishably more flights" if obj_word == "above"
               else "is not borne out here: the optimiser is not above first-fit")
    opts = sg[~sg["solver"].isin([BASELINE, "reference"])]
    fb = int(_true(opts["fallback"]).sum())
    ref = sg[sg["solver"] == "reference"]
    txt += (f" On its {len(opt)} sampled instances (each solved by first-fit and by {OPTIMISER} "
            f"from the same epoch's instance: per epoch, the run does not take the optimiser's "
            f"answer; consecutive epochs share most of their flights, so the 95 % intervals, "
            f"which treat the instances as independent, are if anything narrow), {OPTIMISER} "
            f"at the 1 s limit gains {_f(m, 3, True)} % [{_f(lo, 3, True)}, "
            f"{_f(hi, 3, True)}] over first-fit in the objective (it is {obj_word} first-fit "
            f"there) and {_f(c, 2, True)} [{_f(clo, 2, True)}, {_f(chi, 2, True)}] approvals per "
            f"instance, against first-fit's {_f(ff['count'].mean(), 1)} (it approves {count_word} "
            f"flights than first-fit): the paper's prediction {verdict}. {fb} of the {len(opts)} answers of the "
            f"1 s optimisers there were fallbacks (the greedy answer computed before the solve; "
            f"wall time median {_f(opts['wall_s'].median(), 1)} s, max "
            f"{_f(opts['wall_s'].max(), 1)} s), and the reference proved "
            f"{int(_true(ref['proven_optimal']).sum())} of its {len(ref)} answers optimal.")
    return ["## The paper's prediction", "", txt, ""]


def _read(d: Path, name: str):
    p = d / name
    return pd.read_csv(p) if p.exists() and p.stat().st_size > 0 else None


def report_text(d: Path, shown: str | None = None) -> tuple[str, list]:
    """The report's text and the summary rows; ``shown``: the directory as the report names it."""
    cfg = json.loads((d / "config.json").read_text(encoding="utf-8"))
    inst, solves, rp = _read(d, "instances.csv"), _read(d, "solves.csv.gz"), _read(d, "replanning.csv")
    args = json.loads((d / "replanning_args.json").read_text()) if (d / "replanning_args.json").exists() else None
    bins = list(cfg["solve"]["bins"])
    L = ["# Where optimisation pays on large instances", "",
         "Written by `uam_sim.reports.large_instances_report` from the tables in this directory "
         "alone (`config.json`, `instances.csv`, `solves.csv.gz`, `replanning.csv`, "
         f"`replanning_args.json`): `python -m uam_sim.large_instances_report "
         f"{shown or d.as_posix()}` writes it again, byte for byte "
         "(src/uam_sim/test/test_large_instances.py checks). The tables are computed by "
         "`nice -n 10 python -m uam_sim.large_instances --config config/large-instances.yaml` "
         "(README.md beside this file).", ""]
    rows = []
    if inst is not None and solves is not None:
        check_window(inst, solves)
        g = gaps(solves, bins)
        rows = summary_rows(g, bins) + summary_rows(g, bins, steady_keys(inst))
        loads = solves["load"]
        L += [f"Recorded: {len(inst)} epochs in {inst['run'].nunique()} runs "
              f"({int((phases(inst) == WARMUP).sum())} of them warm-up), "
              f"{_f(inst['cpu_s'].sum(), 0)} CPU-s of planning; solved: "
              f"{solves[['run', 'epoch']].drop_duplicates().shape[0]} instances by "
              f"{solves['solver'].nunique()} solvers, {_f(solves['wall_s'].sum(), 0)} s of wall "
              "time in all.", ""]
        L += [f"Solves ran at commit {', '.join(c[:7] for c in sorted(set(solves['commit'].astype(str))))}, "
              f"machine load (1-min average at each answer) {_f(loads.min(), 1)} to "
              f"{_f(loads.max(), 1)} on 2 cores: the 1 s limits are wall time, so load can decide "
              "a fallback.", ""]
        rp_lines, rp_res = _replanning_lines(rp, args)
        steady = _steady_lines(g, inst)
        L += steady
        L += _prediction_lines(g, inst[phases(inst) != WARMUP], rp_res, lead=not steady)
        L += _instances_lines(cfg, inst)
        L += _solves_lines(cfg, g, rows)
        L += rp_lines
    else:
        rp_lines, _res = _replanning_lines(rp, args)
        L += ["No shadow solves yet.", ""] + rp_lines
    return "\n".join(L).rstrip() + "\n", rows


def write_report(d, shown: str | None = None) -> str:
    d = Path(d)
    text, rows = report_text(d, shown)
    (d / "REPORT.md").write_text(text, encoding="utf-8")
    write_csv(d / "summary.csv", rows)
    return str(d / "REPORT.md")


def main(argv=None) -> int:
    ap = argparse.ArgumentParser(prog="large_instances_report", description=__doc__.split("\n\n")[0])
    ap.add_argument("dir", nargs="?", default="docs/large-instances")
    args = ap.parse_args(argv)
    d = Path(args.dir)
    if not (d / "config.json").exists():
        print(f"large_instances_report: {d / 'config.json'}: not found (run uam_sim.large_instances "
              "first)", file=sys.stderr)
        return 2
    print(write_report(d))
    return 0


if __name__ == "__main__":
    sys.exit(main())
