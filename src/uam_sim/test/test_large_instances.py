"""The large-instance study's report: hand-checked gaps and time to target, and the committed
report rebuilt byte for byte from the committed tables (fast: small tables, no solver)."""

import json
import re
import shutil
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import yaml

from uam_sim.reports.large_instances_report import TABLES, gaps, report_text, summary_rows, write_report
from uam_sim.studies.large_instances import kept_problem, load_config, record_city, replan_row

COMMITTED = Path(__file__).resolve().parents[3] / "docs" / "large-instances"
CONFIG = Path(__file__).resolve().parents[3] / "config" / "large-instances.yaml"


def _row(epoch, solver, objective, count, wall, vertices=2000, fallback=False, proven=False):
    return {"run": "r", "epoch": epoch, "vertices": vertices, "edges": 10, "solver": solver,
            "objective": objective, "count": count, "wall_s": wall, "fallback": fallback,
            "proven_optimal": proven}


def test_gaps_time_to_target_and_gain_over_first_fit_by_hand():
    solves = pd.DataFrame([_row(0, "firstfit", 8.0, 8, 0.1), _row(0, "auto", 9.995, 9, 0.7),
                           _row(0, "reference", 10.0, 9, 4.0, proven=True),
                           _row(1, "firstfit", 5.0, 5, 0.1, vertices=20000),
                           _row(1, "auto", 5.0, 5, 1.4, vertices=20000, fallback=True),
                           _row(1, "reference", 5.5, 6, 10.0, vertices=20000)])
    g = gaps(solves, [1, 10000, 100000]).set_index(["epoch", "solver"])
    assert g.loc[(0, "firstfit"), "gap_pct"] == pytest.approx(20.0)
    assert g.loc[(0, "auto"), "gap_pct"] == pytest.approx(0.05)  # within 0.1 %: target reached
    assert g.loc[(0, "auto"), "time_to_target_s"] == pytest.approx(0.7)
    assert np.isnan(g.loc[(1, "auto"), "time_to_target_s"])  # 9.09 % short: not reached
    assert g.loc[(0, "auto"), "gain_pct"] == pytest.approx(100 * 1.995 / 8.0)
    assert g.loc[(1, "reference"), "count_gain"] == 1
    assert g.loc[(1, "auto"), "bin"] == "[10,000, 100,000)"
    rows = {(r["solver"], r["bin"]): r for r in summary_rows(gaps(solves, [1, 10000, 100000]),
                                                              [1, 10000, 100000])}
    assert rows[("auto", "[10,000, 100,000)")]["fallbacks"] == 1
    assert rows[("auto", "[1, 10,000)")]["reached_share"] == 1.0
    assert rows[("reference", "[1, 10,000)")]["proven_share"] == 1.0


def test_a_replanning_run_becomes_one_flat_row():
    run = {"seed": 2, "policy": "mwis", "affected": 80, "reach": 60, "saved": 79,
           "kinds": {"kept": 0, "rerouted": 60, "retimed": 0, "diverted": 19, "cancelled": 0,
                     "contingency": 1}, "reach_delay_mean_s": 170.5, "ignored": [1]}
    row = replan_row(run)
    assert row["diverted"] == 19 and row["contingency"] == 1 and row["seed"] == 2
    assert "ignored" not in row and row["losses"] is None


@pytest.mark.skipif(not (COMMITTED / "REPORT.md").exists(), reason="no committed study yet")
def test_the_committed_report_rebuilds_byte_for_byte_from_the_committed_tables(tmp_path):
    d = tmp_path / "large-instances"
    d.mkdir()
    for name in TABLES + ("replanning_args.json",):
        if (COMMITTED / name).exists():
            shutil.copy(COMMITTED / name, d / name)
    text, _rows = report_text(d, "docs/large-instances")  # named as the committed one
    assert text == (COMMITTED / "REPORT.md").read_text(encoding="utf-8")
    write_report(d, "docs/large-instances")
    assert (d / "summary.csv").read_bytes() == (COMMITTED / "summary.csv").read_bytes()
    json.loads((d / "config.json").read_text())


# -- the recorded window: steady state, warm-up --------------------------------------------------

def _window_tables(d: Path, sampled_warmup: bool = False) -> None:
    """Run A: epochs 0-1 warm-up (every request approved, large), 2-4 at steady state (80 % of
    the requests approved), 2 and 4 sampled; run B recorded from the start, epoch 1 sampled."""
    cfg = {"record": {"city": "c", "city_seed": 0, "method": "firstfit", "seed": 0,
                      "slot_s": 5.0, "vertical_separation_m": 30.0},
           "solve": {"backends": ["firstfit", "auto"], "time_limit_s": 1.0, "per_bin": 3,
                     "reference": {"backend": "exact", "time_limit_s": 10.0},
                     "bins": [1, 10000, 1000000]}}
    (d / "config.json").write_text(json.dumps(cfg))
    inst = []
    for e, (elig, appr, air, v) in enumerate([(10, 10, 0, 9000), (10, 10, 10, 9500),
                                               (10, 8, 100, 3000), (10, 7, 120, 2500),
                                               (10, 9, 110, 2800)]):
        inst.append({"run": "A", "rate_per_hour": 1200, "record_from_s": 60.0, "epoch": e,
                     "t_s": 30.0 * e, "warmup": e < 2, "eligible": elig, "vertices": v,
                     "edges": 10, "approved": appr, "airborne": air,
                     "sampled": e in (2, 4) or (sampled_warmup and e == 0), "cpu_s": 1.0,
                     "load": 1.0})
    for e in range(2):
        inst.append({"run": "B", "rate_per_hour": 100, "record_from_s": 0.0, "epoch": e,
                     "t_s": 30.0 * e, "warmup": False, "eligible": 2, "vertices": 500,
                     "edges": 5, "approved": 2, "airborne": 0, "sampled": e == 1, "cpu_s": 0.1,
                     "load": 1.0})
    pd.DataFrame(inst).to_csv(d / "instances.csv", index=False)
    solves = []
    picked = [("A", 2, 3000, 8, 9), ("A", 4, 2800, 9, 11), ("B", 1, 500, 2, 2)]
    if sampled_warmup:
        picked.append(("A", 0, 9000, 10, 10))
    for run, e, v, ff, opt in picked:
        for solver, count in (("firstfit", ff), ("auto", opt), ("reference", opt)):
            solves.append({**_row(e, solver, float(count), count, 0.5, vertices=v), "run": run,
                           "load": 1.0, "commit": "abcdef0"})
    pd.DataFrame(solves).to_csv(d / "solves.csv.gz", index=False)


def test_the_steady_state_is_read_from_its_rows_alone(tmp_path):
    _window_tables(tmp_path)
    text, rows = report_text(tmp_path)
    # the contention of epochs 2-4 of A alone: 24 of 30 requests, airborne 100-120
    assert ("At steady state (A from t = 60 s: 3 epochs, after 2 warm-up epochs planned to fill "
            "the sky but neither kept nor sampled), first-fit approved 80.0 % of the 30 requests"
            in text)
    assert "with 110 flights airborne (median; 100 to 120) and instances of 2,500 to 3,000" in text
    # the gain of A's two sampled epochs alone (B's epoch 1 is from the start): +1 and +2
    assert "and +1.50 [-4.85, +7.85] approvals per instance, against first-fit's 8.5" in text
    steady = [r for r in rows if r["subset"] == "steady state"]
    assert {r["instances"] for r in steady} == {2}
    assert [r["count_gain_mean"] for r in steady if r["solver"] == "auto"] == [1.5]
    assert [r["instances"] for r in rows if r["subset"] == "all" and r["solver"] == "auto"] == [3]


def test_a_warm_up_epoch_sampled_or_an_unsampled_epoch_solved_is_refused(tmp_path):
    _window_tables(tmp_path, sampled_warmup=True)
    with pytest.raises(ValueError, match="run A epoch 0 .* sampled but in its warm-up"):
        report_text(tmp_path)
    _window_tables(tmp_path)
    inst = pd.read_csv(tmp_path / "instances.csv")
    inst.loc[(inst["run"] == "A") & (inst["epoch"] == 4), "sampled"] = False
    inst.to_csv(tmp_path / "instances.csv", index=False)
    with pytest.raises(ValueError, match="run A epoch 4 is solved but not a sampled epoch"):
        report_text(tmp_path)


def test_record_city_keeps_no_warm_up_instance():
    from uam_sim.studies.decision_study import e0_sample
    found, epochs = record_city("layered-city", 0, 600.0, 90.0, 0, record_from_s=60.0)
    assert [(e["epoch"], e["warmup"]) for e in epochs] == [(0, True), (1, True), (2, False)]
    assert all(e["vertices"] > 0 for e in epochs)
    assert [e for e, _t, _k in found] == [2]
    sample = e0_sample(found, [1, 1000000], None, 0)
    problem = kept_problem(sample[0][2])
    assert problem.n == epochs[2]["vertices"] and len(problem.edges) == epochs[2]["edges"]


@pytest.mark.parametrize("value, words", [([0.0], "one start [s] per rate (2), got [0.0]"),
                                          ([0.0, 600.0], "record_from_s = 600.0 for 3000"),
                                          ([-1, 0.0], "record_from_s = -1 for 1000"),
                                          ([0.0, "x"], "record_from_s = 'x' for 3000")])
def test_a_bad_recorded_window_names_the_field_and_the_value(tmp_path, value, words):
    cfg = yaml.safe_load(CONFIG.read_text())
    cfg["record"].update(rates_per_hour=[1000, 3000], duration_s=[300.0, 600.0],
                         record_from_s=value)
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ValueError, match=re.escape(words)):
        load_config(path)


@pytest.mark.parametrize("value", [0, 2.5, "all", True])
def test_a_bad_steady_sample_size_names_the_field_and_the_value(tmp_path, value):
    cfg = yaml.safe_load(CONFIG.read_text())
    cfg["solve"]["steady_per_bin"] = value
    path = tmp_path / "c.yaml"
    path.write_text(yaml.safe_dump(cfg))
    with pytest.raises(ValueError, match=re.escape(f"solve.steady_per_bin = {value!r}")):
        load_config(path)
