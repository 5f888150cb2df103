"""The disturbance study's flown-loss bound: held-out seeds only, missing seeds found, rows
against a baseline at another commit named; the committed report equals its generator's output."""

import json
import shutil
from pathlib import Path

import pandas as pd

from uam_sim.reports.safety_report import parse_seeds, report_text

COMMITTED = Path(__file__).resolve().parents[3] / "docs" / "disturbance-study"
POINT = {"speed_error": 0.1, "spatial_buffer_m": 10.0, "temporal_buffer_s": 0.0}


def _table(d: Path, name: str, flights: int, losses: int, runs: int = 10):
    pd.DataFrame([{**POINT, "runs": runs, "flights": flights, "flown_losses": losses,
                   "probe_updates": 5}]).to_csv(d / name, index=False)


def test_the_bound_reads_the_held_out_seeds_alone(tmp_path):
    _table(tmp_path, "tune.csv", 20_000, 0)
    _table(tmp_path, "held.csv", 1_000, 0)
    (tmp_path / "tables.json").write_text(json.dumps({"point": POINT, "tables": {
        "tune.csv": {"seeds": "0-3,6-9", "code": "aaa", "role": "tuning", "what": "t"},
        "held.csv": {"seeds": "10-19", "code": "bbb", "role": "held-out", "what": "h",
                     "baseline": "tune.csv"}}}))
    text = report_text(tmp_path)
    # 1 - 0.05^(1/1000) = 2.99e-3 from the 1,000 held-out flights, not 1.4e-4 from 21,000
    assert "0 flown losses in 1,000 held-out flights (10 runs, seeds 10-19)" in text
    assert "below 2.99e-03 per flight" in text and "at most 25.9% of runs have a loss" in text
    assert "Seeds 4-5 are in no table" in text
    assert "`held.csv` (h) ran at `bbb`, its baseline `tune.csv` at `aaa`" in text


def test_held_out_sets_are_bound_together_and_each_alone_and_a_gap_carries_its_note(tmp_path):
    _table(tmp_path, "held.csv", 1_000, 0)
    _table(tmp_path, "held2.csv", 2_000, 0)
    (tmp_path / "tables.json").write_text(json.dumps({"point": POINT, "tables": {
        "held.csv": {"seeds": "0-9", "code": "aaa", "role": "held-out", "what": "h"},
        "held2.csv": {"seeds": "14-23", "code": "bbb", "role": "held-out", "what": "h2"}},
        "gaps": {"10-11": {"explained": False, "note": "left out by the first sweep."}}}))
    text = report_text(tmp_path)
    # 1 - 0.05^(1/3000) = 9.98e-4 from all 3,000 held-out flights together
    assert "0 flown losses in 3,000 held-out flights (20 runs, seeds 0-9, 14-23)" in text
    assert "below 9.98e-04 per flight" in text and "ran at `aaa`, `bbb`" in text
    assert "- `held.csv` (`aaa`): 0 flown losses in 1,000 flights (10 runs, seeds 0-9)" in text
    assert "- `held2.csv` (`bbb`): 0 flown losses in 2,000 flights" in text
    assert "Seeds 10-11: left out by the first sweep. Why they were left out is not recorded" in text
    assert "Seeds 12-13: neither the tables nor the history" in text


def test_parse_seeds():
    assert parse_seeds("0-2,5,7-8") == [0, 1, 2, 5, 7, 8]


def test_the_committed_safety_report_is_its_generators_output(tmp_path):
    d = tmp_path / "disturbance-study"
    shutil.copytree(COMMITTED, d)
    text = report_text(d).replace(d.as_posix(), "docs/disturbance-study")
    assert text == (COMMITTED / "REPORT.md").read_text(encoding="utf-8")
