"""What a run's approved flights measure, in one implementation: for the in-process
runner's summary (``uam_sim.runner.scenario``), the analysis of a recording (``uam_sim.audit.analysis``) and
the experiment report (``uam_sim.reports.report``, ``uam_sim.reports.figures``). Plain functions over plain rows,
numpy only (no ROS, no plotting library).

:func:`run_metrics` over the approved flights (and, for shares, every request);
:func:`flight_metrics` is the same for a report's cell (its ``"flights"``):

- delay [s] of a flight: departure - the request's earliest departure (the time a request waited
  counts): mean, p95 (numpy's linear percentile), the share of flights delayed, and the p95 per
  priority class (``delay_p95_s_prio<class>``, when more than one class is present);
- detour: flown length - the request's shortest route length [m] (``detour_mean_m``, rows with
  ``shortest_length_m``), and from the paper's weight d*/d (``detour_mean_pct``: d/d* - 1, rows
  with a weight in (0, 1]);
- route length mean, flown km, the share on the best candidate, and with a network and a mask
  of its central corridors the share of flown distance on them (``central_share``);
- per operator: approval share = approved / requested (``share_<operator>``), and Jain's index
  J = (sum x)^2 / (n sum x^2) over the operators' shares (Jain, Chiu and Hawe 1984): 1 when every
  operator gets the same share, 1/n when one gets everything; NaN with no operator or all shares 0.

Warm-up: with ``warmup_s``, requests whose earliest departure is before it are left out of every
metric. End: with ``end_s``, requests whose latest departure is after it (not through their
window when the run ended: filed ahead, still waiting) are left out too. The same filtered
flights give every number, so a delay mean and a p95 always describe one set of flights.
"""

from __future__ import annotations

import math
from collections import Counter
from typing import Iterable, Mapping, Sequence

import numpy as np


def corridor_use_m(network, flights) -> np.ndarray:
    """Flown distance per corridor [m] of a run's flights (each flight's route node ids).
    Every leg of every route at once (``Network.edge_indices``); ``np.bincount`` adds each
    corridor's lengths one by one in the flights' order, as a loop over the legs would."""
    L = np.asarray(network.edge_length_m, dtype=float)
    starts, ends = [], []
    for f in flights:
        idx = [network.node_index(x) for x in f["route"].split()]
        starts += idx[:-1]
        ends += idx[1:]
    if not starts:
        return np.zeros(network.n_edges, dtype=float)
    e = network.edge_indices(starts, ends)
    return np.bincount(e, weights=L[e], minlength=network.n_edges)


def jain_index(values: Sequence[float]) -> float:
    """Jain's fairness index of non-negative values: (sum x)^2 / (n sum x^2); NaN when empty or
    all zero. O(n)."""
    x = np.asarray(list(values), dtype=np.float64)
    if x.size == 0 or not np.any(x > 0):
        return float("nan")
    return float(x.sum() ** 2 / (x.size * np.sum(x * x)))


def _p95(x: np.ndarray) -> float:
    return float(np.percentile(x, 95)) if x.size else float("nan")


def _mean(x: np.ndarray) -> float:
    return float(x.mean()) if x.size else float("nan")


def _known(v) -> bool:
    return v is not None and v != ""


def _in_window(warmup_s: float | None, end_s: float | None):
    """The filter of requests and flights: earliest departure at or after ``warmup_s`` and latest
    departure (where known) at or before ``end_s`` [s]; a row without an earliest departure is
    kept only when neither is given."""
    lo = -math.inf if warmup_s is None else float(warmup_s)
    hi = math.inf if end_s is None else float(end_s)
    filtered = warmup_s is not None or end_s is not None

    def inside(row) -> bool:
        e = row.get("earliest_departure_s")
        if not _known(e):
            return not filtered
        last = row.get("latest_departure_s")
        return float(e) >= lo and (not _known(last) or float(last) <= hi)
    return inside


def _route_and_delay(fl: list) -> dict:
    """The flights' count, route length [m] and distance flown [km], detour [% and m], share on
    their shortest candidate, and departure delay (mean, p95 [s] and share delayed)."""
    delay = np.array([float(f["departure_s"]) - float(f["earliest_departure_s"]) for f in fl
                      if _known(f.get("earliest_departure_s"))], dtype=float)
    length = np.array([float(f["length_m"]) for f in fl], dtype=float)
    weight = np.array([float(f["weight"]) for f in fl if _known(f.get("weight"))], dtype=float)
    # a weight outside (0, 1] is not the paper's d*/d (another objective's, or a plan written by
    # hand): no detour from it
    paper_w = weight[(weight > 0) & (weight <= 1)]
    det_m = np.array([float(f["length_m"]) - float(f["shortest_length_m"]) for f in fl
                      if _known(f.get("shortest_length_m"))], dtype=float)
    return {"flights": len(fl),
            "route_length_mean_m": _mean(length),
            "flown_km": float(length.sum() / 1000.0),
            "detour_mean_pct": _mean(100.0 * (1.0 / paper_w - 1.0)),
            "detour_mean_m": _mean(det_m),
            "shortest_share": float(np.mean([int(f["candidate_index"]) == 0 for f in fl]))
            if fl and all(_known(f.get("candidate_index")) for f in fl) else float("nan"),
            "delay_mean_s": _mean(delay),
            "delay_p95_s": _p95(delay),
            "delayed_share": float((delay > 1e-6).mean()) if delay.size else float("nan")}


def _class_delays(fl: list, rq: list) -> dict:
    """Per priority class, when more than one class is present: the p95 and mean departure delay
    [s] and, with the requests, the requests, approvals and approval rate of the class (what a
    priority objective moves; the totals hide a class of a few per cent)."""
    out = {}
    classes = sorted({int(r.get("priority", 0)) for r in rq} | {int(f.get("priority", 0)) for f in fl})
    if len(classes) > 1:
        for c in classes:
            delays = np.array([float(f["departure_s"]) - float(f["earliest_departure_s"]) for f in fl
                               if int(f.get("priority", 0)) == c and _known(f.get("earliest_departure_s"))])
            out[f"delay_p95_s_prio{c}"] = _p95(delays)
            out[f"delay_mean_s_prio{c}"] = float(delays.mean()) if delays.size else float("nan")
            if rq:
                asked = sum(1 for r in rq if int(r.get("priority", 0)) == c)
                got = sum(1 for f in fl if int(f.get("priority", 0)) == c)
                out[f"requests_prio{c}"] = asked
                out[f"approved_prio{c}"] = got
                out[f"approval_rate_prio{c}"] = got / asked if asked else float("nan")
    return out


def _operator_shares(fl: list, rq: list) -> dict:
    """Per named operator its share of requests approved, then Jain's index over the shares."""
    def operator(row) -> str:
        return str(row.get("operator", row.get("operator_id", "")) or "")
    asked = Counter(operator(r) for r in rq)
    got = Counter(operator(f) for f in fl)
    named = sorted(o for o in asked if o)
    shares = {o: got[o] / asked[o] for o in named}
    out = {f"share_{o}": shares[o] for o in named}
    out["jain_index"] = jain_index(list(shares.values())) if named else float("nan")
    # the least and greatest operator's approval rate and their ratio: it moves where Jain's
    # index sits at its ceiling (>= 0.997 for rates within a few per cent of each other)
    lo, hi = (min(shares.values()), max(shares.values())) if named else (float("nan"), float("nan"))
    out["operator_share_min"], out["operator_share_max"] = lo, hi
    out["operator_share_ratio"] = lo / hi if named and hi > 0 else float("nan")
    return out


def run_metrics(flights: Iterable[Mapping] | Mapping, requests: Iterable[Mapping] | None = None,
                warmup_s: float | None = None, end_s: float | None = None,
                network=None, top=None) -> dict:
    """Every per-run number of the module docstring, from one filtered set of flights.

    Args:
        flights: approved flights (or a cell with ``"flights"``, as the report has them), each
            with ``departure_s``, ``length_m`` and where known ``earliest_departure_s``,
            ``latest_departure_s``, ``shortest_length_m``, ``weight``, ``candidate_index``,
            ``priority``, ``operator`` (or ``operator_id``), ``route``.
        requests: every request submitted (accepted or refused), each with
            ``earliest_departure_s`` and where known ``latest_departure_s``, ``operator`` and
            ``priority``; None: no shares (and the classes come from the flights alone).
        warmup_s, end_s: leave out requests (and their flights) with an earliest departure before
            ``warmup_s`` or a latest departure after ``end_s`` (None: none); a flight without an
            earliest departure is kept only when neither is given.
        network, top: the network and a boolean mask of its central corridors, for
            ``central_share``.
    Returns: a flat dict (a tidy summary row), {} when there is neither a flight nor a request:
    ``flights``, ``route_length_mean_m``, ``flown_km``, ``detour_mean_pct``, ``detour_mean_m``,
    ``shortest_share``, ``delay_mean_s``, ``delay_p95_s``, ``delayed_share``, ``jain_index``,
    per class (more than one present) ``delay_p95_s_prio<c>``, ``delay_mean_s_prio<c>`` and with
    the requests ``requests_prio<c>``, ``approved_prio<c>``, ``approval_rate_prio<c>``;
    ``share_<op>`` per named operator and ``operator_share_min`` / ``_max`` / ``_ratio``;
    ``central_share`` with a network. O(n log n).
    """
    if isinstance(flights, Mapping):
        flights = flights.get("flights") or []
    flights = list(flights)
    requests = None if requests is None else list(requests)
    if not flights and not requests:
        return {}
    inside = _in_window(warmup_s, end_s)
    fl = [f for f in flights if inside(f)]
    out = _route_and_delay(fl)
    rq = [r for r in requests if inside(r)] if requests is not None else []
    out.update(_class_delays(fl, rq))
    out.update(_operator_shares(fl, rq))
    if network is not None and top is not None:
        use = corridor_use_m(network, fl)
        out["central_share"] = float(use[top].sum() / use.sum()) if use.sum() > 0 else float("nan")
    return out


def flight_metrics(cell: Mapping, network=None, top=None) -> dict:
    """:func:`run_metrics` of a report's cell (``cell["flights"]``, no requests, no filter)."""
    return run_metrics(cell, network=network, top=top)


def shortest_route_lengths_m(network, pairs) -> dict:
    """(origin id, destination id) -> the length [m] of a shortest route between them (the first
    of the planner's candidate routes, which is a shortest one; through no other vertiport on a
    layered network): what the runner's ``shortest_length_m`` holds, for a recording's flights.
    A pair without a route (or with an unknown node) is left out."""
    from uam_planner.candidates import candidate_routes
    out = {}
    for o, d in set(pairs):
        try:
            out[(o, d)] = float(candidate_routes(network, o, d, k=1)[0].length_m)
        except (KeyError, ValueError, IndexError):
            continue
    return out
