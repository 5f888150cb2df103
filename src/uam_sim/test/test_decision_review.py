"""The decision report's reviewer-facing statistics (uam_sim.reports.decision_review and the
helpers in uam_sim.reports.stats): pooling with heterogeneity, the Answers' Holm family, E0's
clustered intervals, CUPED, Jain's bound, the amendments, and the report's bugs fixed (pilot
runs counted per arm, the model of E3 read from the config)."""

import json
import math
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from uam_sim.reports import decision_review as review
from uam_sim.reports.decision_report import paper_figures_text, report_text
from uam_sim.reports.stats import (StatsError, binomial_upper, cluster_bootstrap_mean, cuped,
                                   jain_min_max_bound, random_effects)
from uam_sim.studies.decision_study import load_decision_config

sys.path.insert(0, str(Path(__file__).parent))
from test_decision_study import small  # noqa: E402  (the study's small config, one home)

REPO = Path(__file__).resolve().parents[3]
COMMITTED = REPO / "docs" / "decision-study"


def test_random_effects_on_a_hand_computed_pair():
    # effects 0 and 3, SE 1 each: FE 1.5, Q = 4.5 (df 1), I^2 = 1 - 1/4.5, C = 2 - 2/2 = 1,
    # tau^2 = 3.5, RE weights 1/4.5 each: RE 1.5 with SE sqrt(4.5 / 2) = 1.5
    r = random_effects([0.0, 3.0], [1.0, 1.0])
    assert r["fe"] == pytest.approx(1.5) and r["q"] == pytest.approx(4.5) and r["q_df"] == 1
    assert r["i2_pct"] == pytest.approx(100 * (1 - 1 / 4.5))
    assert r["tau2"] == pytest.approx(3.5)
    assert r["re_hi"] - r["re"] == pytest.approx(1.959964 * 1.5, rel=1e-5)
    assert r["fe_hi"] - r["fe"] == pytest.approx(1.959964 / math.sqrt(2), rel=1e-5)
    # agreeing groups: Q below its df, I^2 0, random = fixed
    h = random_effects([1.0, 1.1, 0.9], [0.5, 0.5, 0.5])
    assert h["i2_pct"] == 0.0 and h["tau2"] == 0.0 and h["re"] == pytest.approx(h["fe"])
    with pytest.raises(StatsError, match="SE must be positive"):
        random_effects([1.0, 2.0], [0.0, 1.0])


def _study(per_group_diffs: dict, tmp_path) -> tuple:
    """A one-comparison study whose primary has one group per rate, with the given paired
    differences (flights) against a base of 1,000 + seed."""
    study = load_decision_config(small(tmp_path))
    exp = study["experiments"][0]
    exp["vary"] = {"objective": ["count"]}
    exp["cells"][0]["rates"] = sorted(per_group_diffs)
    exp["secondary"] = [{"name": "again", "metric": "approved_ss", "terms": [
        {"sign": 1, "method": "greedy", "where": {"objective": "count"}},
        {"sign": -1, "method": "firstfit", "where": {"objective": "count"}}]}]
    rows = []
    for rate, diffs in per_group_diffs.items():
        for s, dd in enumerate(diffs):
            for m, v in (("firstfit", 1000.0 + s), ("greedy", 1000.0 + s + dd)):
                rows.append({"experiment": "E1", "cell": "sg", "variant": "objective=count",
                             "objective": "count", "method": m, "rate": rate, "seed": s,
                             "approved_ss": v, "requests_ss": 2000 + 3 * s})
    return study, pd.DataFrame(rows)


def test_a_pooled_claim_only_where_the_groups_agree(tmp_path):
    agree, runs = _study({4: [9, 10, 11, 10], 8: [10, 11, 9, 10]}, tmp_path)
    claims = review.answer_claims(runs, agree)
    prim = [c for c in claims if c["kind"] == "primary"]
    assert [c["group"] for c in prim] == ["pooled"] and prim[0]["pool"]["allowed"]
    differ, runs = _study({4: [0, 1, -1, 0], 8: [30, 31, 29, 30]}, tmp_path)
    prim = [c for c in review.answer_claims(runs, differ) if c["kind"] == "primary"]
    assert [c["group"] for c in prim] == ["cell sg, rate 4", "cell sg, rate 8"]
    assert not prim[0]["pool"]["allowed"] and prim[0]["pool"]["i2_pct"] >= 50
    text = "\n".join(review.answer_lines(prim, [], {"approved_ss": "flights"}))
    assert "the pooled estimate is not claimed (heterogeneity: Q =" in text


def test_holm_covers_each_distinct_claim_once(tmp_path):
    # the secondary compares the very runs of the primary: one claim in the family, not two
    study, runs = _study({4: [0, 1, -1, 0], 8: [30, 31, 29, 30]}, tmp_path)
    claims = review.answer_claims(runs, study)
    dup = [c for c in claims if "same_as" in c]
    fam = [c for c in claims if "p_holm" in c]
    assert len(claims) == 4 and len(dup) == 2 and len(fam) == 2
    from uam_sim.reports.stats import holm
    assert [c["p_holm"] for c in fam] == pytest.approx(holm([c["p"] for c in fam]))
    assert "2 distinct claims" in review.holm_family_text(claims)


def test_cluster_bootstrap_widens_the_interval_of_clustered_values():
    # two runs, every instance of one at 0 and of the other at 10: 200 instances look precise,
    # but there are two independent draws; resampling runs gives means 0, 5 or 10
    v = [0.0] * 100 + [10.0] * 100
    m, lo, hi = cluster_bootstrap_mean(v, ["a"] * 100 + ["b"] * 100, resamples=2000)
    assert m == 5.0 and lo == 0.0 and hi == 10.0
    # one observation per cluster: about the ordinary bootstrap of the mean
    x = np.arange(20.0)
    _, lo1, hi1 = cluster_bootstrap_mean(x, range(20))
    assert lo1 < 9.5 < hi1 and hi1 - lo1 < 10


def test_cuped_removes_the_variance_the_covariate_explains():
    x = np.array([0.0, 1.0, 2.0, 3.0, 4.0])
    d = 2.0 * x + np.array([0.1, -0.1, 0.0, 0.1, -0.1])
    c = cuped(d, x)
    assert c["theta"] == pytest.approx(2.0, abs=0.05) and c["variance_reduction"] > 0.99
    assert c["adjusted"].mean() == pytest.approx(d.mean())
    flat = cuped(d, np.full(5, 7.0))
    assert flat["theta"] == 0.0 and flat["variance_reduction"] == 0.0


def test_the_cuped_section_reads_whether_the_requests_vary(tmp_path):
    study, runs = _study({4: [1, 3, 2, 6, 4]}, tmp_path)
    lines, s = review.cuped_lines(review.cuped_rows(runs, study), {}, study)
    assert "vary between seeds in 1 of 1" in s and "premise of zero variance is false" in s
    lines, s = review.cuped_lines(review.cuped_rows(runs.assign(requests_ss=2000), study), {}, study)
    assert "do not vary between seeds" in s


def test_jain_bounds_the_min_max_ratio():
    # two shares: the index fixes the ratio, (1 + r)^2 / (2 (1 + r^2)); r = 0.5 -> 0.9
    assert jain_min_max_bound(0.9, 2) == pytest.approx(0.5, abs=1e-6)
    # three shares: the bound is below the ratio of any configuration with that index
    shares = np.array([0.8, 0.9, 1.0])
    j = shares.sum() ** 2 / (3 * (shares ** 2).sum())
    assert jain_min_max_bound(j, 3) <= 0.8 + 1e-9
    assert jain_min_max_bound(1.0, 3) == pytest.approx(1.0, abs=1e-6)


def test_the_exact_binomial_bound_is_the_rule_of_three_with_no_event():
    assert binomial_upper(0, 10_000) == pytest.approx(1 - 0.05 ** (1 / 10_000))
    assert binomial_upper(0, 10_000) == pytest.approx(3 / 10_000, rel=0.01)
    assert binomial_upper(0, 58) == pytest.approx(0.0504, abs=1e-4)
    assert binomial_upper(1, 100) > binomial_upper(0, 100)


def test_the_paper_figures_sentence_names_the_model_from_the_config():
    study = {"experiments": [{"name": "E3", "cells": [
        {"name": "sg-both", "network": "config/networks/singapore.yaml", "mode": "both", "rates": [20]}]}]}
    text = paper_figures_text(study)
    assert "airspace mode `both`, not the paper's model" in text
    study["experiments"][0]["cells"][0]["mode"] = "paper"
    assert "config/networks/singapore.yaml, the paper's model" in paper_figures_text(study)


def _report_dir(tmp_path, per_arm_seeds: dict) -> Path:
    """A study directory with study.json and runs.csv: ``per_arm_seeds`` {(method, rate): seeds}."""
    study = load_decision_config(small(tmp_path))
    exp = study["experiments"][0]
    exp["vary"] = {"objective": ["count"]}
    exp["cells"][0]["rates"] = [4, 8]
    exp["secondary"] = []
    rows = []
    for (m, rate), seeds in per_arm_seeds.items():
        for s in seeds:
            rows.append({"experiment": "E1", "cell": "sg", "variant": "objective=count",
                         "objective": "count", "mode": "both", "method": m, "rate": rate, "seed": s,
                         "approved_ss": 100.0 + s + (m == "greedy") * (1 + s % 2),
                         "expired_ss": 1.0, "requests_ss": 200, "delay_mean_s": 1.0,
                         "delay_p95_s": 2.0, "detour_mean_m": 0.0, "jain_index": 1.0,
                         "solve_time_median_s": 0.0, "solve_time_max_s": 0.0, "overruns": 0,
                         "fallbacks": 0})
    d = tmp_path / "study"
    d.mkdir()
    (d / "study.json").write_text(json.dumps(study))
    pd.DataFrame(rows).to_csv(d / "runs.csv", index=False)
    return d


def test_pilot_runs_missing_counts_seeds_per_arm_not_runs(tmp_path):
    # pilot 2 seeds x 4 arms = 8 runs; here 8 runs, but greedy at rate 8 has 1 seed and
    # firstfit at rate 4 has 3: one pilot run is missing
    d = _report_dir(tmp_path, {("firstfit", 4): [0, 1, 2], ("greedy", 4): [0, 1],
                               ("firstfit", 8): [0, 1], ("greedy", 8): [0]})
    text, _ = report_text(d)
    row = next(line for line in text.splitlines() if line.startswith("| E1 |"))
    cells = [c.strip() for c in row.strip("|").split("|")]
    assert cells[2] == "8" and cells[4] == "1"


def test_the_committed_amendments_name_real_commits_at_their_dates():
    am = pd.read_csv(COMMITTED / "amendments.csv", dtype=str).fillna("")
    try:
        for a in am.to_dict("records"):
            for c, date in ((a["commit"], a["date"]), (a["after_look_commit"], a["after_look_date"])):
                out = subprocess.run(["git", "-C", str(REPO), "show", "-s", "--format=%cI", c],
                                     capture_output=True, text=True, timeout=10)
                if out.returncode != 0:
                    pytest.skip("no git history here")
                assert out.stdout.strip() == date, (c, date)
                # the look at the data came before the change
            assert a["after_look_date"] < a["date"], a["commit"]
    except FileNotFoundError:
        pytest.skip("git not installed")


def test_a_rerun_amendment_reports_the_primary_before_and_after(tmp_path):
    study, runs = _study({4: [1, 3, 2, 6, 4]}, tmp_path)
    runs = runs.assign(cell="sg", variant="objective=count")
    old = runs[(runs["method"] == "greedy") & (runs["seed"] == 3)].assign(approved_ss=1003.0)
    a = {"experiment": "E1", "comparison": "p"}
    text = review._rerun_effect(runs, old, study, a)
    assert text.startswith("1 runs re-run (1 in the primary's treatment arm, 0 in its control arm")
    assert "rose in 1 of 1" in text and "with the earlier rows and is" in text
