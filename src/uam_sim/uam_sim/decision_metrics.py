"""What operators value, measured per run (issue 21): delay, detour, priorities and fairness.

One implementation for the in-process runner's summary (``uam_sim.scenario``) and for
recordings (``uam_sim.analysis``): plain functions over plain rows, no ROS.

- delay [s] of an approved flight: departure - the request's earliest departure (so the time a
  request waited counts), mean and p95 (numpy's linear percentile);
- detour: flown length - the request's shortest candidate route length [m], mean;
- per priority class: the p95 delay of its flights (``delay_p95_s_prio<class>``);
- per operator: approval share = approved / requested (``share_<operator>``), and Jain's index
  J = (sum x)^2 / (n sum x^2) over the operators' shares (Jain, Chiu and Hawe 1984): 1 when every
  operator gets the same share, 1/n when one gets everything; NaN with no operator or all shares 0.

Warm-up: with ``warmup_s``, requests whose earliest departure is before it are left out of every
metric. End: with ``end_s``, requests whose latest departure is after it (not through their
window when the run ended: filed ahead, still waiting) are left out too.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Iterable, Mapping, Sequence

import numpy as np


def jain_index(values: Sequence[float]) -> float:
    """Jain's fairness index of non-negative values: (sum x)^2 / (n sum x^2); NaN when empty or
    all zero. O(n)."""
    x = np.asarray(list(values), dtype=np.float64)
    if x.size == 0 or not np.any(x > 0):
        return float("nan")
    return float(x.sum() ** 2 / (x.size * np.sum(x * x)))


def _p95(x: np.ndarray) -> float:
    return float(np.percentile(x, 95)) if x.size else float("nan")


def decision_metrics(flights: Iterable[Mapping], requests: Iterable[Mapping],
                     warmup_s: float | None = None, end_s: float | None = None) -> dict:
    """Delay, detour, per-priority p95 delay, per-operator approval share and Jain index.

    Args:
        flights: approved flights, each with ``earliest_departure_s``, ``departure_s``,
            ``length_m``, ``shortest_length_m`` (may be None: no detour then), ``priority``,
            ``operator``.
        requests: every request submitted (accepted or refused), each with
            ``earliest_departure_s``, ``operator`` and ``priority``.
        warmup_s: requests (and their flights) with an earliest departure before it are left out
            (None: none is).
        end_s: requests (and their flights) with a latest departure after it are left out
            (None: none is); rows without ``latest_departure_s`` are kept.
    Returns: a flat dict (a tidy summary row): ``delay_mean_s``, ``delay_p95_s``,
    ``detour_mean_m``, ``jain_index``, ``delay_p95_s_prio<c>`` per class present and
    ``share_<op>`` per named operator (when any request names one). O(n log n).
    """
    lo = -math.inf if warmup_s is None else float(warmup_s)
    hi = math.inf if end_s is None else float(end_s)

    def inside(row) -> bool:
        return float(row["earliest_departure_s"]) >= lo and \
            float(row.get("latest_departure_s", -math.inf)) <= hi
    fl = [f for f in flights if inside(f)]
    rq = [r for r in requests if inside(r)]
    delay = np.array([float(f["departure_s"]) - float(f["earliest_departure_s"]) for f in fl])
    det = np.array([float(f["length_m"]) - float(f["shortest_length_m"]) for f in fl
                    if f.get("shortest_length_m") is not None])
    out = {"delay_mean_s": float(delay.mean()) if delay.size else float("nan"),
           "delay_p95_s": _p95(delay),
           "detour_mean_m": float(det.mean()) if det.size else float("nan")}
    classes = sorted({int(r.get("priority", 0)) for r in rq} | {int(f.get("priority", 0)) for f in fl})
    if len(classes) > 1:
        for c in classes:
            out[f"delay_p95_s_prio{c}"] = _p95(np.array(
                [d for d, f in zip(delay.tolist(), fl) if int(f.get("priority", 0)) == c]))
    asked = Counter(str(r.get("operator", "")) for r in rq)
    got = Counter(str(f.get("operator", "")) for f in fl)
    named = sorted(o for o in asked if o)
    shares = {o: got[o] / asked[o] for o in named}
    for o in named:
        out[f"share_{o}"] = shares[o]
    out["jain_index"] = jain_index(list(shares.values())) if named else float("nan")
    return out

