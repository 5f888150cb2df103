"""The report's observations beyond the paper are computed from the runs, not written in."""

from __future__ import annotations

from uam_sim.report import beyond_paper


def _cells(approved: dict) -> list:
    return [{"summary": {"method": m, "rate": r, "seed": s, "approved": a}}
            for (m, r), per_seed in approved.items() for s, a in enumerate(per_seed)]


def test_greedy_ahead_of_exact_and_tie_divergence_are_reported_with_numbers():
    cells = _cells({("fifo", 4): [10, 10], ("greedy", 4): [14, 16], ("exact", 4): [12, 12],
                    ("sa", 4): [13, 13], ("fifo", 8): [20, 20], ("greedy", 8): [21, 21],
                    ("exact", 8): [25, 25], ("sa", 8): [25, 25]})
    text = beyond_paper(cells)
    assert len(text) == 2
    assert "rates 4 (15.0 vs 12.0)" in text[0] and "8 (" not in text[0]
    assert "exact, sa" in text[1] and "rates 4 (12.0 to 13.0)" in text[1] and "8 (" not in text[1]


def test_nothing_to_say_when_exact_leads_and_solvers_agree():
    cells = _cells({("fifo", 4): [10], ("greedy", 4): [11], ("exact", 4): [12], ("sa", 4): [12]})
    text = beyond_paper(cells)
    assert text == ["Exact approves at least as many flights as greedy at every rate: 4 (12.0 vs 11.0)."]
