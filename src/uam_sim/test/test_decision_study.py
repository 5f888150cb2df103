"""The decision study (issue 24): config validation, the statistics it decides with (Holm, seeds
from power, MSER-5), comparisons and verdicts computed from rows, E0 and the report rebuilt from
its tables."""

import json
import math
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml
from scipy.stats import t as student_t

from uam_sim.runner import sweep
from uam_sim.reports.decision_report import comparison_rows, power_rows, write_decision_report
from uam_sim.studies.decision_study import load_decision_config, run_stage
from uam_sim.runner.experiment_config import ExperimentError
from uam_sim.reports.stats import StatsError, holm, mser_truncation, seeds_needed

REPO = Path(__file__).resolve().parents[3]
COMMITTED = REPO / "docs" / "decision-study"


def small(tmp_path, **over) -> Path:
    data = {"out": str(tmp_path / "out"), "cells": str(tmp_path / "cells"), "workers": 1,
            "base": {"duration_s": 240.0, "time_limit_s": 0.5, "corpus_max_vertices": 0,
                     "include_qpu": False, "baseline_order": "priority", "priority_share": 0.05,
                     "priority_class": 1, "operators": ["a", "b"],
                     "operator_lead_times_s": [60.0, 0.0]},
            "power": {"pilot_seeds": 2, "half_width_pct": 1.0, "max_seeds": 3},
            "e0": {"duration_s": 240.0, "backends": ["firstfit", "greedy", "exact"],
                   "time_limit_s": 0.5, "reference": {"backend": "exact", "time_limit_s": 2.0},
                   "per_bin": 1,
                   "runs": [{"name": "sg", "network": "config/networks/singapore.yaml",
                             "mode": "both", "objective": "count", "rate": 4, "seed": 0}]},
            "experiments": [{
                "name": "E1", "question": "q", "methods": ["firstfit", "greedy"],
                "vary": {"objective": ["paper", "count"]},
                "cells": [{"name": "sg", "network": "config/networks/singapore.yaml",
                           "mode": "both", "rates": [4]}],
                "primary": [{"name": "p", "metric": "approved_ss", "terms": [
                    {"sign": 1, "method": "greedy", "where": {"objective": "count"}},
                    {"sign": -1, "method": "firstfit", "where": {"objective": "count"}}]}],
                "secondary": [{"name": "s", "metric": "delay_mean_s", "terms": [
                    {"sign": 1, "method": "greedy"}, {"sign": -1, "method": "firstfit"}]}]}]}
    data.update(over)
    p = tmp_path / f"study{len(list(tmp_path.glob('study*.yaml')))}.yaml"
    p.write_text(yaml.safe_dump(data))
    return p


def test_the_committed_config_loads_and_declares_a_primary_per_experiment():
    cfg = load_decision_config(REPO / "config" / "decision-study.yaml")
    assert [e["name"] for e in cfg["experiments"]] == ["E1", "E2", "E3"]
    assert all(e["primary"] for e in cfg["experiments"])
    assert set(cfg["e0"]["backends"]) == {"firstfit", "greedy", "auto", "exact", "sa", "tabu",
                                          "qpu-emulator"}


def test_bad_study_files_are_refused_naming_the_field(tmp_path):
    good = yaml.safe_load(small(tmp_path).read_text())
    exp = good["experiments"][0]

    def with_exp(**kw):
        return small(tmp_path, experiments=[{**exp, **kw}])
    prim = exp["primary"][0]
    cases = [
        (with_exp(primary=[]), r"experiments\[0\].primary: \[\] must have at least 1 item"),
        (with_exp(primary=[{**prim, "metric": "happiness"}]), r"primary\[0\].metric: 'happiness'"),
        (with_exp(primary=[{**prim, "terms": [prim["terms"][0], prim["terms"][0]]}]),
         r"primary\[0\].terms: signs must sum to 0"),
        (with_exp(primary=[{**prim, "terms": [{**prim["terms"][0], "where": {"colour": 1}},
                                              prim["terms"][1]]}]),
         r"terms\[0\].where.colour: not a varied key"),
        (with_exp(primary=[{**prim, "terms": [{**prim["terms"][0], "where": {"objective": "joy"}},
                                              prim["terms"][1]]}]),
         r"terms\[0\].where.objective: 'joy' is not one of"),
        (with_exp(cells=[{**exp["cells"][0], "mode": "wide"}]), r"cells\[0\].mode: 'wide'"),
        (small(tmp_path, power={"pilot_seeds": 1}), r"power.pilot_seeds: 1 is below the minimum 2"),
        (small(tmp_path, power={"pilot_seeds": "3"}), r"power.pilot_seeds: '3' is not an integer"),
        (small(tmp_path, power={"level": 1.5}), r"power.level: 1.5 must be < 1"),
        (small(tmp_path, power={"colour": 1}), r"power.colour: unknown field"),
        (small(tmp_path, e0={"per_bin": 0}), r"e0.per_bin: 0 is below the minimum 1"),
        (small(tmp_path, e0={"runs": [{"name": "x", "network": "n.yaml", "mode": "both",
                                       "rate": "fast", "seed": 0}]}),
         r"e0.runs\[0\].rate: 'fast' is not an integer or a finite number"),
        (with_exp(primary=[{**prim, "terms": [{**prim["terms"][0], "sign": 2},
                                              prim["terms"][1]]}]),
         r"primary\[0\].terms\[0\].sign: 2 is not one of"),
        (with_exp(primary=[{**prim, "terms": [{**prim["terms"][0], "method": "exactt"},
                                              prim["terms"][1]]}]),
         r"primary\[0\].terms\[0\].method: 'exactt' is not one of the experiment's methods"),
        (small(tmp_path, share_firstfit_across=["E9"]), r"share_firstfit_across\[0\]: 'E9' is not"),
        (small(tmp_path, base={"seeds": 4}), r"base.seeds: 4 is set per cell"),
    ]
    for path, msg in cases:
        with pytest.raises(ExperimentError, match=msg):
            load_decision_config(path)


def test_holm_matches_its_definition_on_a_hand_computed_case():
    # sorted 0.005, 0.01, 0.03, 0.04 -> 4 x 0.005 = 0.02, 3 x 0.01 = 0.03, 2 x 0.03 = 0.06,
    # max(0.06, 1 x 0.04) = 0.06; back in input order
    assert holm([0.01, 0.04, 0.03, 0.005]) == pytest.approx([0.03, 0.06, 0.06, 0.02])
    assert holm([0.5, 0.9]) == pytest.approx([1.0, 1.0])  # capped at 1
    assert holm([]) == []


def test_seeds_needed_is_the_smallest_n_whose_t_interval_reaches_the_target():
    # t_{0.975,16} 10 / sqrt 17 = 5.14 > 5, t_{0.975,17} 10 / sqrt 18 = 4.97 <= 5
    assert seeds_needed(10.0, 5.0) == 18
    half = lambda n: student_t.ppf(0.975, n - 1) * 10.0 / math.sqrt(n)  # noqa: E731
    assert half(18) <= 5.0 < half(17)
    assert seeds_needed(0.0, 1.0) == 2
    assert seeds_needed(1000.0, 0.001, cap=50) == 51  # unreachable: says so
    with pytest.raises(StatsError, match="sd -1"):
        seeds_needed(-1.0, 1.0)


def test_mser5_truncates_a_ramp_and_keeps_a_stationary_series():
    ramp = list(np.linspace(0, 9, 10)) + [10 + (1 if i % 2 else -1) for i in range(40)]
    assert mser_truncation(ramp) == 10
    flat = [10 + (1 if i % 2 else -1) * 0.1 * (i % 5) for i in range(50)]
    assert mser_truncation(flat) == 0
    assert mser_truncation([1, 2, 3]) == 0  # too short to batch


def test_every_variant_of_a_cell_and_rate_is_measured_in_one_window():
    """The window is the latest of the variants' MSER-5 truncations, per experiment cell and
    rate: a comparison across variants (E2's horizons) counts the same requests in both arms
    (a window per variant gave E2's pilot 8 % more requests in its H = 5 arm)."""
    from uam_sim.studies.decision_study import windows

    def cell(ramp, rate=20, method="firstfit"):
        series = list(np.linspace(0, 9, ramp)) + [10 + (1 if i % 2 else -1) for i in range(60)]
        return {"summary": {"rate": rate, "method": method},
                "epochs": [{"active": x, "t_s": 30.0 * k} for k, x in enumerate(series)]}
    e, c = {"name": "E2"}, {"name": "sg"}
    h1, h5 = {"horizon_epochs": 1}, {"horizon_epochs": 5}
    records = [(e, c, h1, cell(10)), (e, c, h5, cell(25)), (e, c, h1, cell(5, rate=40))]
    ss = {"method": "mser5", "series": "active", "reference_method": "firstfit"}
    w = windows(records, ss, 30.0)
    own = {k: mser_truncation([ep["active"] for ep in r[3]["epochs"]])
           for k, r in zip(("h1", "h5", "h1r40"), records)}
    assert own["h1"] < own["h5"]  # the variants' own truncations differ
    assert w[("E2", "sg", "horizon_epochs=1", 20)] == (own["h5"], 30.0 * own["h5"], "firstfit",
                                                       own["h1"])
    assert w[("E2", "sg", "horizon_epochs=5", 20)] == (own["h5"], 30.0 * own["h5"], "firstfit",
                                                       own["h5"])
    # another rate keeps its own window
    assert w[("E2", "sg", "horizon_epochs=1", 40)][0] == own["h1r40"]
    # the same windows from the per-epoch rows as a reader of epochs.csv.gz has them (text)
    from uam_sim.studies.decision_study import epoch_rows, windows_from_epoch_rows
    for k, r in enumerate(records):
        r[3]["summary"]["seed"] = k
    text = [{k: str(v) for k, v in row.items()} for row in epoch_rows(records)]
    again = windows_from_epoch_rows(text, ss)
    assert {(k[0], k[1], k[2], int(k[3])): v for k, v in again.items()} == w


def _runs(diffs, base=100.0):
    rows = []
    for s, d in enumerate(diffs):
        for m, v in (("firstfit", base + s), ("greedy", base + s + d)):
            rows.append({"experiment": "E1", "cell": "sg", "variant": "objective=count",
                         "objective": "count", "method": m, "rate": 4, "seed": s,
                         "approved_ss": v, "delay_mean_s": 5.0 + (d if m == "greedy" else 0)})
    return pd.DataFrame(rows)


def test_comparisons_and_verdicts_are_computed_from_the_rows(tmp_path):
    study = load_decision_config(small(tmp_path))
    study["experiments"][0]["vary"] = {"objective": ["count"]}
    # greedy - firstfit = 2, 3, 4 flights: mean 3, t interval 3 +- 4.303 * 1 / sqrt 3
    rows = comparison_rows(_runs([2, 3, 4]), study)
    p = next(r for r in rows if r["kind"] == "primary")
    assert p["diff"] == pytest.approx(3.0) and p["seeds"] == 3
    assert p["diff_hi"] - 3.0 == pytest.approx(student_t.ppf(0.975, 2) / math.sqrt(3))
    assert p["positive"] == 3
    # its power row: sd 1, target 1 % of the firstfit mean (101) -> seeds for half-width 1.01
    pw = power_rows(_runs([2, 3, 4]), study)[0]
    assert pw["paired_sd"] == pytest.approx(1.0) and pw["target_half"] == pytest.approx(1.01)
    assert pw["seeds_needed"] == seeds_needed(1.0, 1.01)
    # the minimal detectable effect at 80 % power: (t_0.975 + t_0.8, 2 df) * sd / sqrt(3)
    assert pw["mde_now"] == pytest.approx((student_t.ppf(0.975, 2) + student_t.ppf(0.8, 2))
                                          / math.sqrt(3))
    assert pw["decides"] and pw["max_seeds"] == 3 and pw["mde_at_cap"] == pytest.approx(pw["mde_now"])
    # the sentence follows the interval: excludes 0 here, includes 0 for -1, +1, +3
    from uam_sim.reports.decision_report import _verdict
    assert "excludes 0, a difference above 0" in _verdict(p, "flights")
    q = next(r for r in comparison_rows(_runs([-1, 1, 3]), study) if r["kind"] == "primary")
    text = _verdict(q, "flights")
    assert "includes 0" in text and "not resolved at this power" in text
    assert "no effect" not in text and "no difference" not in text
    # declared per: pooled (the same question at two rates), the pooled row sets the seeds: the
    # stacked relative differences [%] over both groups, seeds per group = total / 2, rounded up
    two = pd.concat([_runs([2, 3, 4]), _runs([1, 5, 3]).assign(rate=8)], ignore_index=True)
    study["experiments"][0]["primary"][0]["per"] = "pooled"
    prow = power_rows(two, study)
    assert [r["decides"] for r in prow] == [False, False, True]
    rel = np.array([100.0 * d / (100.0 + s) for s, d in enumerate([2, 3, 4])]
                   + [100.0 * d / (100.0 + s) for s, d in enumerate([1, 5, 3])])
    assert prow[2]["paired_sd"] == pytest.approx(rel.std(ddof=1)) and prow[2]["seeds_run"] == 6
    assert prow[2]["seeds_needed"] == math.ceil(seeds_needed(rel.std(ddof=1), 1.0) / 2)
    study["experiments"][0]["primary"][0]["per"] = "cell"
    # a varied integer read back as float (blanks in its column) still selects its rows
    study["experiments"][0]["vary"] = {"horizon_epochs": [1, 5]}
    runs = _runs([2, 3, 4]).assign(horizon_epochs=5.0)
    study["experiments"][0]["primary"][0]["terms"] = [
        {"sign": 1, "method": "greedy", "where": {"horizon_epochs": 5}},
        {"sign": -1, "method": "firstfit", "where": {"horizon_epochs": 5}}]
    h = next(r for r in comparison_rows(runs, study) if r["kind"] == "primary")
    assert h["seeds"] == 3 and h["diff"] == pytest.approx(3.0)


def test_first_fit_flies_the_same_flights_under_every_objective():
    """The assumption behind share_firstfit_across (E1 runs first-fit once, not once per
    objective): first-fit's decisions do not depend on the weights. Here with priority classes,
    operators with filing habits, slots and levels ("both"), so every objective's weights differ."""
    from uam_planner.objectives import OBJECTIVES
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario
    flown, weights = {}, {}
    for objective in OBJECTIVES:
        cfg = make_config({"network": str(REPO / "config/networks/singapore.yaml"),
                           "airspace_mode": "both", "methods": ["firstfit"], "rates": [6],
                           "duration_s": 420.0, "baseline_order": "priority",
                           "priority_share": 0.3, "priority_class": 1,
                           "operators": ["a", "b", "c"], "operator_lead_times_s": [300.0, 60.0, 0.0],
                           "objective": objective, "fair_window_s": 300.0 if objective == "fair" else 0.0,
                           "include_qpu": False, "tts": {"enabled": False}})
        res = run_scenario(load_network_spec(cfg.network), "firstfit", 6, 0, cfg.duration_s, cfg)
        flown[objective] = [{k: v for k, v in f.items() if k != "weight"} for f in res.flights]
        weights[objective] = [f["weight"] for f in res.flights]
    assert len(flown["paper"]) > 20
    for objective in OBJECTIVES:
        assert flown[objective] == flown["paper"], objective
    assert len({tuple(w) for w in weights.values()}) > 1  # the objectives did weigh differently


@pytest.mark.slow  # a tiny E0 (3 solvers + reference) and pilot: worker start-up dominates
def test_the_study_runs_resumes_and_its_report_rebuilds_from_the_tables(tmp_path):
    cfg = load_decision_config(small(tmp_path, share_firstfit_across=["E1"]))
    out = Path(cfg["out"])
    run_stage(cfg, "e0", out, progress=False)
    info = run_stage(cfg, "pilot", out, progress=False)
    assert info["runs"] == 2 * 2 * 2  # 2 variants x 2 methods x 2 pilot seeds
    # first-fit ran once per seed (under the first objective) and stands for both variants
    assert len(list((Path(cfg["cells"]) / "cells").glob("firstfit_*.json"))) == 2
    runs = pd.read_csv(out / "runs.csv")
    ff = runs[runs["method"] == "firstfit"]
    assert sorted(ff["objective"]) == ["count", "count", "paper", "paper"]
    assert (ff["ran_under"] == "paper").all()
    assert ff[ff["objective"] == "count"]["weight_sum_ss"].isna().all()
    assert ff[ff["objective"] == "paper"]["weight_sum_ss"].notna().all()
    assert (runs["losses"] == 0).all() and (runs["overruns"] == 0).all()
    assert runs["commit"].str.len().min() >= 40  # every cell says which commit ran it
    # and the machine it ran on: wall-clock limits make fallbacks depend on load
    assert runs["load_before"].notna().all() and (runs["cpu_s"] > 0).all()
    e0 = pd.read_csv(out / "e0.csv.gz")
    assert set(e0["solver"]) == {"firstfit", "greedy", "exact", "reference"}
    best = e0.groupby(["run", "epoch"])["objective"].transform("max")
    proven = e0[e0["proven_optimal"]]
    # a proven optimum is the best any solver found on that instance
    assert np.allclose(proven["objective"], best[proven.index])
    # the per-epoch series are committed beside the windows, and the windows re-derive from them
    import csv
    import gzip

    from uam_sim.studies.decision_study import windows_from_epoch_rows
    with gzip.open(out / "epochs.csv.gz", "rt", newline="") as f:
        erows = list(csv.DictReader(f))
    assert len({(r["method"], r["seed"], r["variant"]) for r in erows}) == info["runs"]
    rederived = windows_from_epoch_rows(erows, cfg["steady_state"])
    with open(out / "windows.csv", newline="") as f:
        committed = {(r["experiment"], r["cell"], r["variant"], r["rate"]):
                     (int(r["truncation_epoch"]), float(r["warmup_s"]), r["reference_method"],
                      int(r["variant_truncation_epoch"])) for r in csv.DictReader(f)}
    assert {k: (int(w[0]), float(w[1]), w[2], int(w[3])) for k, w in rederived.items()} == committed
    # resumes: the finished cells are reused (the pilot again computes nothing)
    again = run_stage(cfg, "pilot", out, progress=False)
    assert again["runs"] == info["runs"]
    first = (out / "REPORT.md").read_text()
    write_decision_report(out)
    assert (out / "REPORT.md").read_text() == first
    assert "## E0: matched shadow solves" in first and "| E1 | p |" in first
    # answered: pooled where heterogeneity allows a pooled claim, else per group (this pilot
    # has one group)
    assert "- E1 primary `p` (approved_ss, cell sg, rate 4): " in first
    assert "Machine load (1-min average, the larger of before and after each run) median" in first
    # the tables rebuilt where no cell of this code version is (a later version, another cells
    # folder): the finished tables are kept, not replaced by empty ones
    before = {n: (out / n).read_bytes() for n in ("runs.csv", "windows.csv", "e0.csv.gz",
                                                  "epochs.csv.gz")}
    run_stage(dict(cfg, cells=str(tmp_path / "no-cells")), "tables", out, progress=False)
    assert {n: (out / n).read_bytes() for n in before} == before
    assert (out / "REPORT.md").read_text() == first
    # seventh stop: cells live where they ran (not committed). The rows of an experiment (an E0
    # run) with no cell here are kept as committed, not dropped, when the tables are rebuilt
    # from the cells of others; the experiments with cells are recomputed from them
    runs_before = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    other = runs_before.assign(experiment="E9")
    pd.concat([runs_before, other]).to_csv(out / "runs.csv", index=False)
    win = pd.read_csv(out / "windows.csv", dtype=str, keep_default_na=False)
    pd.concat([win, win.assign(experiment="E9")]).to_csv(out / "windows.csv", index=False)
    e0_before = pd.read_csv(out / "e0.csv.gz", dtype=str, keep_default_na=False)
    pd.concat([e0_before, e0_before.assign(run="zz")]).to_csv(out / "e0.csv.gz", index=False)
    run_stage(cfg, "tables", out, progress=False)
    runs_after = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    assert runs_after[runs_after["experiment"] == "E9"].reset_index(drop=True).equals(
        other.reset_index(drop=True))
    assert runs_after[runs_after["experiment"] != "E9"].reset_index(drop=True).equals(runs_before)
    assert (pd.read_csv(out / "windows.csv", dtype=str)["experiment"] == "E9").sum() == len(win)
    e0_after = pd.read_csv(out / "e0.csv.gz", dtype=str, keep_default_na=False)
    assert len(e0_after) == 2 * len(e0_before) and (e0_after["run"] == "zz").sum() == len(e0_before)
    # cells computed by other run code (a worktree at a study's frozen code) are collected with
    # the code version pinned, and give the same rows as at their own code
    runs_own = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    frozen = tmp_path / "frozen-cells"
    own = sweep.code_version()
    for f in Path(cfg["cells"]).rglob("*.json"):
        dest = frozen / f.relative_to(cfg["cells"]).parent / f.name.replace(own, "0123456789ab")
        dest.parent.mkdir(parents=True, exist_ok=True)
        dest.write_text(f.read_text().replace(own, "0123456789ab"))
    try:
        sweep.pin_code_version("0123456789ab")
        run_stage(dict(cfg, cells=str(frozen)), "tables", out, progress=False)
    finally:
        sweep._CODE[:] = [own]
    runs_pinned = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    assert (runs_pinned[runs_pinned["experiment"] != "E9"]["code_version"] == "0123456789ab").all()
    assert runs_pinned.drop(columns="code_version").equals(runs_own.drop(columns="code_version"))
    # the tables stage with experiments named collects only those: E1 has cells here, but asked
    # for E9 alone it keeps E1's rows as they are (tenth stop: cells computed for one experiment
    # that another shares replaced the other's whole table)
    marked = runs_pinned.assign(cpu_s=lambda d: d["cpu_s"].where(d["experiment"] != "E1", "-1"))
    marked.to_csv(out / "runs.csv", index=False)
    run_stage(cfg, "tables", out, progress=False, experiments=["E9"])
    again = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    assert (again[again["experiment"] == "E1"]["cpu_s"] == "-1").all()
    run_stage(cfg, "tables", out, progress=False)          # all of them: E1 from its cells again
    again = pd.read_csv(out / "runs.csv", dtype=str, keep_default_na=False)
    assert (again[again["experiment"] == "E1"]["cpu_s"] != "-1").all()


def test_a_pinned_code_version_is_only_for_collecting_tables(tmp_path, capsys):
    from uam_sim.studies.decision_study import main

    assert main(["--stage", "full", "--code-version", "d3795b835634", "--out", str(tmp_path)]) == 2
    assert "--code-version d3795b835634: only with --stage tables" in capsys.readouterr().err
    assert main(["--stage", "tables", "--code-version", "D3795B", "--out", str(tmp_path)]) == 2
    assert "--code-version: code version: 'D3795B' is not 12 lowercase hex digits" in capsys.readouterr().err
    with pytest.raises(ValueError, match="code version: 12 is not"):
        sweep.pin_code_version(12)


@pytest.mark.slow  # several seconds of KaMIS / reports: make test runs it, test-fast does not
@pytest.mark.skipif(not (COMMITTED / "REPORT.md").exists(), reason="no committed study yet")
def test_the_committed_report_rebuilds_byte_for_byte_from_the_committed_tables(tmp_path):
    d = tmp_path / "decision-study"
    d.mkdir()
    for name in ("study.json", "runs.csv", "windows.csv", "e0.csv.gz", "amendments.csv",
                 "superseded_runs.csv"):
        if (COMMITTED / name).exists():
            shutil.copy(COMMITTED / name, d / name)
    # one computation (write_decision_report writes report_text's text and tables)
    write_decision_report(d, "docs/decision-study")  # named as the committed one
    assert (d / "REPORT.md").read_text(encoding="utf-8") == \
        (COMMITTED / "REPORT.md").read_text(encoding="utf-8")
    for name in ("comparisons.csv", "power.csv", "e0_summary.csv"):
        if (COMMITTED / name).exists():
            assert (d / name).read_bytes() == (COMMITTED / name).read_bytes(), name
    json.loads((d / "study.json").read_text())
