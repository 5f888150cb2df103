"""The report's comparisons are computed from the runs with paired CIs, not written in."""

from __future__ import annotations

from uam_sim.reports.report import alternatives_vs_optimisation, beyond_paper, paper_checks


def _cells(approved: dict) -> list:
    return [{"summary": {"method": m, "rate": r, "seed": s, "approved": a}}
            for (m, r), per_seed in approved.items() for s, a in enumerate(per_seed)]


def test_greedy_ahead_only_where_the_paired_interval_excludes_zero():
    # rate 4: greedy +2, +4, +3 on every seed -> supported; rate 8: +0, +0, +36 (one seed) -> not
    cells = _cells({("greedy", 4): [14, 16, 15], ("exact", 4): [12, 12, 12],
                    ("sa", 4): [13, 12, 12], ("greedy", 8): [25, 25, 61],
                    ("exact", 8): [25, 25, 25], ("sa", 8): [25, 25, 25]})
    text = beyond_paper(cells)
    assert len(text) == 2
    assert "rate 4: +3.0 [" in text[0] and "(3+ / 0-)" in text[0]
    assert "rate 8: +12.0 [" in text[0] and "(1+ / 0-)" in text[0]
    assert "supported (CI excludes 0) at rates 4 (greedy higher)" in text[0]
    assert "greedy is ahead at rates 4." in text[0]
    assert "rates 4 (12.0 to 12.3)" in text[1] and "8 (" not in text[1]


def test_one_seed_driving_the_mean_is_not_a_finding():
    cells = _cells({("greedy", 8): [300, 300, 300, 300, 360], ("exact", 8): [300] * 5})
    text = beyond_paper(cells)
    assert "No interval excludes 0" in text[0] and "no rate where greedy is ahead" in text[0]


def test_gap_shrinking_is_judged_in_counts_and_relative_terms():
    # FIFO 100 / 200 / 400; exact +50 at every rate (same count) -> relative shrinks, count not
    fifo = {1: [100, 102, 98], 4: [200, 204, 196], 8: [400, 404, 396]}
    exact = {r: [v + 50 + d for v, d in zip(vals, (0, 1, -1))] for r, vals in fifo.items()}
    cells = _cells({**{("fifo", r): v for r, v in fifo.items()},
                    **{("exact", r): v for r, v in exact.items()}})
    checks = {t: (txt, v) for t, txt, v in paper_checks(cells, {}, {})}
    txt, verdict = checks["The gap to FIFO shrinks at high rates"]
    assert verdict == "agrees in relative terms only"
    assert "1: +50.0 [" in txt and "the count does not shrink" in txt


def test_first_fit_share_of_the_mwis_gain():
    cells = _cells({("fifo", 2): [100, 100], ("firstfit", 2): [130, 132],
                    ("exact", 2): [140, 140]})
    (row,) = alternatives_vs_optimisation(cells)
    # exact - fifo = 40, first-fit - fifo = 31 -> 77.5 %; exact - first-fit = +9 [..]
    assert row["share_pct"] == 77.5 and row["mwis_vs_firstfit"].startswith("+9.0 [")
