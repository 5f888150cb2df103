"""Paired per-seed statistics for the study's comparisons.

Every method at one (rate, seed) plans the *same* requests (the demand is a function of the seed
alone), so two methods are compared seed by seed: d_s = x_A(s) - x_B(s), and the report gives
the mean paired difference with a 95 % confidence interval over seeds. Pairing removes the
between-seed variation of the demand (at rate 20 the approvals of one method vary by about
+-40 flights between seeds, while the paired difference of two methods varies far less), which
is why unpaired CIs that overlap can still hide a clear difference, and why overlapping CIs of
two means are no evidence of "no difference" either.

Interval: Student t on the differences, ``mean(d) +- t_{0.975, n-1} sd(d) / sqrt(n)``
(``scipy.stats.t``). With the study's 5 seeds it assumes roughly normal differences; it is the
usual choice for so few pairs, since a bootstrap interval from 5 values is too narrow (the
percentile bootstrap's coverage is well below 95 % at n = 5). ``method="bootstrap"`` gives the
BCa bootstrap of the mean instead (``scipy.stats.bootstrap``, seeded, 9,999 resamples) for
larger seed counts. A difference is called *supported* only when its interval excludes 0; the
count of seeds with a positive difference is reported beside it, so one seed carrying the mean
is visible.

Relative differences are computed per seed too: 100 (x_A - x_B) / x_B [%].
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Iterable, Sequence

import numpy as np

LEVEL = 0.95
BOOTSTRAP_RESAMPLES = 9_999


class StatsError(ValueError):
    """Bad input to a statistic; the message names the argument and the value."""


@dataclass(frozen=True)
class Paired:
    """A paired comparison over seeds.

    Attributes:
        mean: mean of the per-seed differences (units of the metric, or % when relative).
        lo, hi: the confidence interval of the mean difference (nan when n < 2).
        n: number of paired seeds.
        positive, negative: seeds with a difference > 0 / < 0.
        level: confidence level; method: "t" or "bootstrap".
        diffs: the per-seed differences, in seed order.
        seeds: the seeds, in the same order.
    """

    mean: float
    lo: float
    hi: float
    n: int
    positive: int
    negative: int
    level: float = LEVEL
    method: str = "t"
    diffs: tuple = field(default=(), repr=False)
    seeds: tuple = field(default=(), repr=False)

    @property
    def supported(self) -> bool:
        """True when the interval excludes 0 (a difference in a definite direction)."""
        return self.n >= 2 and (self.lo > 0 or self.hi < 0)

    @property
    def sign(self) -> int:
        """+1 / -1 when the interval lies above / below 0, else 0."""
        if not self.supported:
            return 0
        return 1 if self.lo > 0 else -1

    def text(self, nd: int = 1, unit: str = "") -> str:
        """'+12.0 [-24.0, +48.0]' (with a unit appended to each number when given)."""
        u = f" {unit}" if unit and unit != "%" else unit
        if self.n < 2:
            return f"{self.mean:+.{nd}f}{u} (n = {self.n}, no interval)"
        return f"{self.mean:+.{nd}f}{u} [{self.lo:+.{nd}f}, {self.hi:+.{nd}f}]{u if u else ''}"


def _clean(name: str, values) -> np.ndarray:
    x = np.asarray(list(values), dtype=np.float64)
    if x.ndim != 1:
        raise StatsError(f"{name}: expected a 1-D sequence, got shape {x.shape}")
    return x


def mean_interval(values: Sequence[float], level: float = LEVEL, method: str = "t",
                  seed: int = 0) -> tuple[float, float, float]:
    """(mean, low, high) of a sample: Student t (default) or BCa bootstrap interval.

    NaN entries are dropped; fewer than 2 values give (mean, nan, nan); identical values give a
    zero-width interval.
    """
    if not 0 < level < 1:
        raise StatsError(f"level: {level!r} must lie in (0, 1)")
    if method not in ("t", "bootstrap"):
        raise StatsError(f"method: {method!r} must be 't' or 'bootstrap'")
    x = _clean("values", values)
    x = x[~np.isnan(x)]
    if x.size == 0:
        return math.nan, math.nan, math.nan
    m = float(x.mean())
    if x.size < 2:
        return m, math.nan, math.nan
    if np.all(x == x[0]):
        return m, m, m
    if method == "t":
        from scipy.stats import t as student_t
        half = float(student_t.ppf(0.5 + level / 2, x.size - 1) * x.std(ddof=1) / math.sqrt(x.size))
        return m, m - half, m + half
    from scipy.stats import bootstrap
    res = bootstrap((x,), np.mean, confidence_level=level, n_resamples=BOOTSTRAP_RESAMPLES,
                    method="BCa", random_state=np.random.default_rng(seed))
    return m, float(res.confidence_interval.low), float(res.confidence_interval.high)


def paired(a: dict, b: dict, relative: bool = False, level: float = LEVEL,
           method: str = "t") -> Paired:
    """Paired comparison of two per-seed results ``{seed: value}`` on their common seeds.

    ``relative``: per-seed 100 (a - b) / b [%] (seeds with b == 0 are left out).
    Raises StatsError when no seed is common to both.
    """
    seeds = sorted(set(a) & set(b))
    if not seeds:
        raise StatsError(f"paired: no common seed (a has {sorted(a)}, b has {sorted(b)})")
    if relative:
        seeds = [s for s in seeds if b[s]]
        d = np.array([100.0 * (a[s] - b[s]) / b[s] for s in seeds], dtype=np.float64)
    else:
        d = np.array([a[s] - b[s] for s in seeds], dtype=np.float64)
    m, lo, hi = mean_interval(d, level, method)
    return Paired(mean=m, lo=lo, hi=hi, n=len(seeds), positive=int((d > 0).sum()),
                  negative=int((d < 0).sum()), level=level, method=method,
                  diffs=tuple(d.tolist()), seeds=tuple(seeds))


def per_seed(cells: Iterable[dict], method: str, rate, metric) -> dict:
    """``{seed: value}`` of one method at one rate; ``metric`` is a summary key or a function
    of the cell."""
    out = {}
    for c in cells:
        s = c["summary"]
        if s["method"] == method and s["rate"] == rate:
            out[int(s["seed"])] = float(metric(c) if callable(metric) else s[metric])
    return out


def compare(cells: Sequence[dict], a: str, b: str, metric="approved", rates=None,
            level: float = LEVEL, method: str = "t") -> list:
    """Rows of method ``a`` against method ``b`` per rate: means of both, the paired difference
    (count) and the paired relative difference [%], each with its interval.

    Rates where either method has no run are skipped.
    """
    rates = sorted({c["summary"]["rate"] for c in cells}) if rates is None else rates
    rows = []
    for r in rates:
        xa, xb = per_seed(cells, a, r, metric), per_seed(cells, b, r, metric)
        if not (set(xa) & set(xb)):
            continue
        d = paired(xa, xb, level=level, method=method)
        rel = paired(xa, xb, relative=True, level=level, method=method)
        common = d.seeds
        rows.append({"a": a, "b": b, "rate": r, "mean_a": float(np.mean([xa[s] for s in common])),
                     "mean_b": float(np.mean([xb[s] for s in common])),
                     "diff": d.mean, "diff_lo": d.lo, "diff_hi": d.hi,
                     "rel_pct": rel.mean, "rel_lo": rel.lo, "rel_hi": rel.hi,
                     "seeds": d.n, "positive": d.positive, "negative": d.negative,
                     "supported": d.supported, "paired": d, "paired_rel": rel})
    return rows


# -- the decision study's --------------------------------------------------------------

def seeds_needed(sd: float, target_half: float, level: float = 0.95, cap: int = 10_000) -> int:
    """Smallest n >= 2 with t_{(1+level)/2, n-1} sd / sqrt(n) <= target_half (paired differences
    of SD ``sd``); ``cap`` + 1 when even ``cap`` seeds do not reach it. sd 0 needs 2."""
    from scipy.stats import t as student_t
    if not (sd >= 0 and target_half > 0):
        raise StatsError(f"seeds_needed: sd {sd!r} must be >= 0 and target {target_half!r} > 0")
    n = 2
    while n <= cap:
        if student_t.ppf(0.5 + level / 2, n - 1) * sd / math.sqrt(n) <= target_half:
            return n
        n += 1 if n < 100 else max(1, n // 20)
    return cap + 1


def holm(pvalues) -> list:
    """Holm's step-down adjusted p-values, in the input order.

    Hand-written (10 lines) because statsmodels (whose ``multipletests(method="holm")`` is the
    reference) is not pinned in requirements.txt and would add it, patsy and their wheels for this
    one function; test_decision_study checks it against Holm's definition on hand-computed cases.
    """
    p = np.asarray(list(pvalues), dtype=float)
    m = p.size
    order = np.argsort(p, kind="stable")
    adj = np.empty(m)
    running = 0.0
    for rank, i in enumerate(order):
        running = max(running, min(1.0, (m - rank) * p[i]))
        adj[i] = running
    return adj.tolist()


def mser_truncation(series, batch: int = 5) -> int:
    """MSER-b (White 1997): the index d (a multiple of ``batch``) minimising the squared standard
    error of the mean of the batch means after d, over d in the first half of the series."""
    x = np.asarray(series, dtype=float)
    nb = x.size // batch
    if nb < 4:
        return 0
    z = x[: nb * batch].reshape(nb, batch).mean(axis=1)
    best, best_k = math.inf, 0
    for k in range(nb // 2 + 1):
        rest = z[k:]
        val = float(((rest - rest.mean()) ** 2).sum()) / rest.size ** 2
        if val < best - 1e-12:
            best, best_k = val, k
    return best_k * batch


def random_effects(effects, ses, level: float = LEVEL) -> dict:
    """Fixed-effect (inverse variance) and DerSimonian-Laird random-effects pooling of ``k``
    estimates ``effects`` with standard errors ``ses`` (same units), with Cochran's Q, its
    chi-square p-value (df k - 1) and I^2 = max(0, (Q - df) / Q) [%].

    Returns a dict: ``k``, ``fe``, ``fe_lo``, ``fe_hi``, ``fe_p`` (two-sided z test), ``re``,
    ``re_lo``, ``re_hi``, ``re_p``, ``hk_lo``, ``hk_hi`` (the random-effects interval with the
    Hartung-Knapp-Sidik-Jonkman SE and a t quantile), ``tau2``, ``q``, ``q_df``, ``q_p``, ``i2_pct``. Normal
    quantiles, as ``statsmodels.stats.meta_analysis.combine_effects(method_re="dl")`` (the
    reference; statsmodels is not pinned in requirements.txt, which is part of the run code's
    version, and the 12 lines below are its formulas). Raises StatsError when fewer than 2
    estimates or a standard error is not positive (its weight would be infinite).
    """
    from scipy.stats import chi2, norm
    y = np.asarray(list(effects), dtype=float)
    s = np.asarray(list(ses), dtype=float)
    if y.size < 2 or y.size != s.size:
        raise StatsError(f"random_effects: need >= 2 estimates with one SE each, got {y.size} and {s.size}")
    if not np.all(np.isfinite(s)) or np.any(s <= 0):
        raise StatsError(f"random_effects: every SE must be positive and finite, got {s.tolist()}")
    w = 1.0 / s ** 2
    fe = float(np.sum(w * y) / np.sum(w))
    fe_se = float(math.sqrt(1.0 / np.sum(w)))
    q = float(np.sum(w * (y - fe) ** 2))
    df = y.size - 1
    c = float(np.sum(w) - np.sum(w ** 2) / np.sum(w))
    tau2 = max(0.0, (q - df) / c) if c > 0 else 0.0
    wr = 1.0 / (s ** 2 + tau2)
    re = float(np.sum(wr * y) / np.sum(wr))
    re_se = float(math.sqrt(1.0 / np.sum(wr)))
    z = float(norm.ppf(0.5 + level / 2))
    # Hartung-Knapp-Sidik-Jonkman: the random-effects SE from the weighted residuals with a t
    # quantile on k - 1 df (DL's normal interval is too narrow with few groups)
    from scipy.stats import t as student_t
    hk_se = float(math.sqrt(np.sum(wr * (y - re) ** 2) / (df * np.sum(wr))))
    tq = float(student_t.ppf(0.5 + level / 2, df))
    return {"k": int(y.size), "hk_lo": re - tq * hk_se, "hk_hi": re + tq * hk_se,
            "fe": fe, "fe_lo": fe - z * fe_se, "fe_hi": fe + z * fe_se,
            "fe_p": float(2 * norm.sf(abs(fe) / fe_se)),
            "re": re, "re_lo": re - z * re_se, "re_hi": re + z * re_se,
            "re_p": float(2 * norm.sf(abs(re) / re_se)), "tau2": tau2,
            "q": q, "q_df": df, "q_p": float(chi2.sf(q, df)),
            "i2_pct": max(0.0, 100.0 * (q - df) / q) if q > 0 else 0.0}


def cluster_bootstrap_mean(values, clusters, level: float = LEVEL, resamples: int = 4_000,
                           seed: int = 0) -> tuple:
    """(mean, low, high): the mean of ``values`` with a percentile interval from resampling whole
    clusters with replacement (the observations of one cluster are not independent: instances of
    one run share its traffic). Each resample draws as many clusters as there are and takes the
    mean over all their observations. Seeded, vectorised: O(resamples x clusters)."""
    v = np.asarray(list(values), dtype=float)
    c = np.asarray(list(clusters))
    if v.size == 0 or v.size != c.size:
        raise StatsError(f"cluster_bootstrap_mean: {v.size} values and {c.size} cluster labels")
    labels, idx = np.unique(c, return_inverse=True)
    sums = np.bincount(idx, weights=v, minlength=labels.size)
    counts = np.bincount(idx, minlength=labels.size).astype(float)
    rng = np.random.default_rng(seed)
    draw = rng.integers(0, labels.size, size=(resamples, labels.size))
    means = sums[draw].sum(axis=1) / counts[draw].sum(axis=1)
    a = (1.0 - level) / 2
    return float(v.mean()), float(np.quantile(means, a)), float(np.quantile(means, 1 - a))


def binomial_upper(events: int, trials: int, level: float = LEVEL) -> float:
    """The exact (Clopper-Pearson) one-sided upper confidence bound of a binomial proportion at
    ``level``; with 0 events it is 1 - (1 - level)^(1/n), about 3 / n (the rule of three)."""
    from scipy.stats import beta
    if trials <= 0 or not 0 <= events <= trials:
        raise StatsError(f"binomial_upper: events {events} of trials {trials}")
    if events == trials:
        return 1.0
    return float(beta.ppf(level, events + 1, trials - events))


def cuped(diffs, covariate) -> dict:
    """CUPED (regression adjustment on a pre-treatment covariate shared by both arms of a pair):
    d_adj = d - theta (x - mean x), theta = cov(d, x) / var(x). Returns ``theta``, the adjusted
    differences ``adjusted`` and ``variance_reduction`` = 1 - var(d_adj) / var(d) (= corr^2);
    theta 0 and no reduction when the covariate does not vary."""
    d = np.asarray(list(diffs), dtype=float)
    x = np.asarray(list(covariate), dtype=float)
    if d.size != x.size or d.size < 3:
        raise StatsError(f"cuped: need >= 3 pairs with a covariate each, got {d.size} and {x.size}")
    vx = float(np.var(x, ddof=1))
    theta = float(np.cov(d, x, ddof=1)[0, 1] / vx) if vx > 0 else 0.0
    adj = d - theta * (x - x.mean())
    vd = float(np.var(d, ddof=1))
    return {"theta": theta, "adjusted": adj,
            "variance_reduction": 1.0 - float(np.var(adj, ddof=1)) / vd if vd > 0 else 0.0}


def jain_min_max_bound(jain: float, n: int = 3) -> float:
    """The smallest min/max ratio n shares can have at Jain's index ``jain`` (a lower bound on
    the ratio; Jain alone does not give the ratio itself for n > 2). With the largest share 1
    and the smallest r, the others at the value that maximises the index, the index rises with
    r; found by bisection on r."""
    if not 0 < jain <= 1 or n < 2:
        raise StatsError(f"jain_min_max_bound: jain {jain}, n {n}")

    def best_index(r: float) -> float:
        # the n - 2 middle shares all at m: the index's maximum over m in [r, 1]
        m = np.linspace(r, 1.0, 201)
        s = 1.0 + r + (n - 2) * m
        ss = 1.0 + r * r + (n - 2) * m * m
        return float(np.max(s * s / (n * ss)))

    lo, hi = 0.0, 1.0
    for _ in range(50):
        mid = (lo + hi) / 2
        if best_index(mid) >= jain:
            hi = mid
        else:
            lo = mid
    return hi
