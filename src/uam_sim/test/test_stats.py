"""Paired per-seed statistics: hand-computed intervals, pairing by seed, bad input named."""

import math

import numpy as np
import pytest

from uam_sim.reports.stats import StatsError, compare, mean_interval, paired


def test_t_interval_by_hand():
    # d = 1, 2, 3, 4, 5: mean 3, sd sqrt(2.5), t_{0.975,4} = 2.776445 -> half 1.963243
    m, lo, hi = mean_interval([1, 2, 3, 4, 5])
    assert m == 3.0
    assert lo == pytest.approx(3 - 1.963243, abs=1e-6) and hi == pytest.approx(3 + 1.963243, abs=1e-6)


def test_paired_pairs_by_seed_not_position():
    a = {0: 110.0, 1: 100.0, 2: 130.0}
    b = {2: 120.0, 0: 100.0, 1: 100.0, 7: 5.0}  # seed 7 has no partner and is left out
    p = paired(a, b)
    assert p.seeds == (0, 1, 2) and p.diffs == (10.0, 0.0, 10.0)
    assert p.n == 3 and p.positive == 2 and p.negative == 0
    # mean 20/3, sd 5.7735, t_{0.975,2} = 4.302653 -> half 14.342
    assert p.mean == pytest.approx(20 / 3)
    assert p.hi - p.mean == pytest.approx(4.302653 * 5.773503 / math.sqrt(3), rel=1e-5)
    assert not p.supported and p.sign == 0
    rel = paired(a, b, relative=True)
    assert rel.diffs == pytest.approx((10.0, 0.0, 100 * 10 / 120))


def test_one_seed_carrying_the_mean_is_not_supported():
    # The case: greedy vs exact +12 on average, driven by one seed.
    a = {0: 300, 1: 300, 2: 300, 3: 300, 4: 360}
    b = {0: 300, 1: 300, 2: 300, 3: 300, 4: 300}
    p = paired(a, b)
    assert p.mean == 12 and p.lo < 0 < p.hi and not p.supported and p.positive == 1


def test_consistent_difference_is_supported():
    p = paired({s: 100 + s + 5 for s in range(5)}, {s: 100 + s for s in range(5)})
    assert (p.mean, p.lo, p.hi, p.supported, p.sign) == (5, 5, 5, True, 1)
    q = paired({s: 10.0 - s * 0.1 for s in range(5)}, {s: 12.0 for s in range(5)})
    assert q.supported and q.sign == -1


def test_bootstrap_interval_contains_mean_and_is_seeded():
    x = np.random.default_rng(3).normal(2.0, 1.0, size=30)
    m, lo, hi = mean_interval(x, method="bootstrap")
    assert lo < m < hi
    assert mean_interval(x, method="bootstrap") == (m, lo, hi)


def test_bad_input_names_the_argument():
    with pytest.raises(StatsError, match="paired: no common seed"):
        paired({0: 1.0}, {1: 1.0})
    with pytest.raises(StatsError, match="level: 1.5"):
        mean_interval([1, 2], level=1.5)
    with pytest.raises(StatsError, match="method: 'z'"):
        mean_interval([1, 2], method="z")


def _cell(method, rate, seed, approved):
    return {"summary": {"method": method, "rate": rate, "seed": seed, "approved": approved}}


def test_compare_rows_per_rate():
    cells = [_cell("exact", 2, s, 150 + s) for s in range(3)] + \
            [_cell("fifo", 2, s, 100 + s) for s in range(3)] + [_cell("exact", 4, 0, 1)]
    rows = compare(cells, "exact", "fifo")
    assert len(rows) == 1  # rate 4 has no FIFO run
    r = rows[0]
    assert (r["rate"], r["mean_a"], r["mean_b"], r["diff"], r["seeds"]) == (2, 151, 101, 50, 3)
    assert r["rel_pct"] == pytest.approx(np.mean([50 / 100, 50 / 101, 50 / 102]) * 100)
    assert r["supported"]
