"""The load sweep's knee, per-class approvals and operators' spread, on hand-made run summaries."""

from uam_sim.reports.knee import class_rows, knee_rows, knee_section, operator_rows, priority_classes


def _cell(method, rate, seed, approval_rate, **extra):
    return {"summary": {"method": method, "rate": rate, "seed": seed, "approval_rate": approval_rate,
                        **extra}}


def test_the_knee_is_the_first_rate_whose_mean_falls_below_95_percent():
    cells = [_cell("a", 2, 0, 1.0), _cell("a", 2, 1, 0.98),     # mean 0.99
             _cell("a", 5, 0, 0.96), _cell("a", 5, 1, 0.92),    # mean 0.94: the knee
             _cell("a", 10, 0, 0.97),                           # above again: not the knee
             _cell("b", 2, 0, 0.5), _cell("b", 5, 0, 0.4),      # below from the start
             _cell("c", 2, 0, 1.0), _cell("c", 5, 0, 0.99)]     # never below: no knee
    rows = {r["method"]: r for r in knee_rows(cells, ["a", "b", "c"], [2, 5, 10])}
    assert rows["a"]["last_above"] == 2 and rows["a"]["knee"] == 5
    assert abs(rows["a"]["rate_knee"] - 0.94) < 1e-12 and rows["a"]["top"] == 10
    assert rows["b"]["last_above"] is None and rows["b"]["knee"] == 2
    assert rows["c"]["knee"] is None and rows["c"]["last_above"] == 5


def test_class_approvals_are_pooled_over_the_seeds():
    # class 1: 1 of 2 requests in seed 0, 3 of 3 in seed 1 -> 4 / 5 pooled (not the mean 0.75)
    cells = [_cell("a", 2, 0, 0.9, requests_prio0=18, approved_prio0=17, requests_prio1=2, approved_prio1=1,
                   delay_mean_s_prio0=4.0, delay_mean_s_prio1=2.0, operator_share_ratio="nan"),
             _cell("a", 2, 1, 0.9, requests_prio0=17, approved_prio0=15, requests_prio1=3, approved_prio1=3,
                   delay_mean_s_prio0=6.0, delay_mean_s_prio1="", operator_share_ratio="")]
    assert priority_classes(cells) == [0, 1]
    (row,) = class_rows(cells, ["a"], [2], [0, 1])
    assert row["requests1"] == 5 and row["approved1"] == 4 and abs(row["rate1"] - 0.8) < 1e-12
    assert row["rate0"] == 32 / 35 and row["delay0"] == 5.0 and row["delay1"] == 2.0
    assert operator_rows(cells, ["a"], [2]) == []   # no operator named: nothing to show
    text = "\n".join(knee_section(cells, ["a"], [2], 30.0))
    assert "| a | 2 | 2 | 35 | 91.4 | 5.0 | 5 | 80.0 | 2.0 |" in text
    assert "the demand names none" in text


def test_operators_spread_is_the_mean_over_the_seeds():
    cells = [_cell("a", 2, s, 0.9, operator_share_min=lo, operator_share_max=0.9, operator_share_ratio=lo / 0.9)
             for s, lo in ((0, 0.6), (1, 0.72))]
    (row,) = operator_rows(cells, ["a"], [2])
    assert row["seeds"] == 2 and abs(row["min"] - 0.66) < 1e-12 and abs(row["ratio"] - 0.66 / 0.9) < 1e-12


def test_the_committed_load_sweeps_print_their_knee_and_classes_from_runs_csv():
    """Each committed load sweep's REPORT.md holds the section its runs.csv gives (the whole
    report byte for byte is the slow test's, for docs/load-sweep)."""
    from pathlib import Path

    from uam_sim.reports.report import STUDY_COMMANDS, _methods, _rates, _read_csv
    docs = Path(__file__).resolve().parents[3] / "docs"
    for name in ("load-sweep", "load-sweep-paper", "load-sweep-city"):
        d = docs / name
        cells = [{"summary": row} for row in _read_csv(d, "runs.csv")]
        text = (d / "REPORT.md").read_text(encoding="utf-8")
        section = "\n".join(knee_section(cells, _methods(cells), _rates(cells), 30.0))
        assert section in text, name
        assert STUDY_COMMANDS[f"results/{name}"] in text, name   # its own command


def test_a_rate_the_tables_decimals_would_round_is_written_in_full():
    """0.25 requests per 30 s at one decimal would read 0.2, as the rate 0.2 does: written in
    full, and the whole rates keep the table's decimals."""
    from uam_sim.reports.report import _table
    text = _table([{"rate": 0.2, "x": 1.0}, {"rate": 0.25, "x": 2.0}, {"rate": 10.0, "x": 3.0}],
                  ["rate", "x"], nd=1)
    assert [line.split(" | ")[0] for line in text.splitlines()[2:]] == ["| 0.2", "| 0.25", "| 10.0"]
