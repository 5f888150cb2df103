"""Independent safety audits of flown flights: the exact closest approach of every pair.

Two implementations, both independent of the planner's separation code:

- :func:`audit_trajectories` / :func:`audit_plans`: ``uam_planner.audit.pair_min_distance`` (a
  brute-force kernel) on the pairs whose bounding boxes come close (used on recordings by
  :mod:`uam_sim.audit.analysis`);
- :func:`sweep_audit`: a vectorised time sweep over straight segments (used on in-process runs
  by :mod:`uam_sim.runner.scenario`, where runs have hundreds of long flights).

Tests hold both equal to the brute force ``uam_planner.audit.audit_flights``.

Both audit in the run's separation model: ``separation_m`` is a number (the paper's sphere of
that radius) or a ``uam_planner.separation.SeparationModel`` (the cylinder: horizontal distance
below H while the vertical distance is below V; distances reported are then horizontal). A
distance within 1e-9 of the minimum below it is an exact tie rounded (e.g. two departures two
5 s slots apart on one route trail each other by exactly 100 m), not a loss, as in
``uam_planner.audit``.
"""

from __future__ import annotations

import math
from dataclasses import dataclass
from typing import Any, Sequence

import numpy as np

from uam_contract.defaults import SEPARATION_M
from uam_contract.stamps import stamp_s

# as uam_planner.audit: a distance this close (relative) below the minimum is a rounded exact tie
TIE_RELATIVE = 1e-9


def _model(separation):
    from uam_planner.separation import as_separation_model
    return as_separation_model(separation)


#: the MCAP metadata record that says which airspace a run was planned in (the recorder writes
#: it from its parameters, run_fleet.sh giving it the planner's values); the analysis audits in it
AIRSPACE_METADATA = "uam_airspace"


def airspace_metadata(separation_model: str = "sphere", separation_m: float = SEPARATION_M,
                      vertical_separation_m: float = 30.0, departure_slot_s: float = 0.0) -> dict:
    """The ``uam_airspace`` metadata of a run (strings, as MCAP metadata holds them); the
    values are checked as the planner checks them (ValueError naming the field)."""
    from uam_planner.separation import SeparationModel

    SeparationModel(separation_model, float(separation_m), float(vertical_separation_m))
    if not math.isfinite(float(departure_slot_s)) or float(departure_slot_s) < 0:
        raise ValueError(f"departure_slot_s must be finite and >= 0, got {departure_slot_s!r}")
    return {"separation_model": str(separation_model), "separation_m": repr(float(separation_m)),
            "vertical_separation_m": repr(float(vertical_separation_m)),
            "departure_slot_s": repr(float(departure_slot_s))}


def separation_from_metadata(meta: dict, default=SEPARATION_M):
    """The SeparationModel recorded in a ``uam_airspace`` metadata record, or ``default`` (a
    number = the sphere, or a model) when the record is absent (recordings made before it).
    A malformed record raises ValueError naming the field."""
    from uam_planner.separation import SeparationModel

    if not meta:
        return _model(default)
    try:
        kind = meta["separation_model"]
        h = float(meta["separation_m"])
        v = float(meta.get("vertical_separation_m", "30.0"))
    except (KeyError, ValueError) as exc:
        raise ValueError(f"recording metadata {AIRSPACE_METADATA}: {exc!r} in {meta!r}") from None
    return SeparationModel(kind, h, v)


@dataclass
class SafetyAudit:
    """Closest approach between every pair of approved flights, as flown."""

    separation_m: float
    min_separation_m: float          # inf when no two flights are ever airborne together
    closest_pair: list | None        # [request_id, request_id] at the minimum
    losses: list                     # [request_id, request_id, distance_m, t_s] below separation_m, by time
    pairs_checked: int               # pairs whose closest approach was computed exactly (cylinder:
                                     # plus pairs proven V or more apart vertically by their boxes)
    separation_model: str = "sphere"  # 'sphere' (3D distances) or 'cylinder' (horizontal distances)
    vertical_separation_m: float = 0.0  # the cylinder's V [m]; 0 for the sphere

    def describe_minimum(self) -> str:
        """The required minimum in words, e.g. '100 m' or '100 m horizontal within 30 m vertical'."""
        if self.separation_model == "cylinder":
            return (f"{self.separation_m:.0f} m horizontal within {self.vertical_separation_m:.0f} m "
                    "vertical (cylinder)")
        return f"{self.separation_m:.0f} m"

    @property
    def ok(self) -> bool:
        return not self.losses


def trajectory_of(plan: Any) -> tuple[np.ndarray, np.ndarray]:
    """(times_s (p,), points_m (p, 3)) of a FlightPlan's waypoints."""
    times = np.array([stamp_s(w.time) for w in plan.waypoints], dtype=np.float64)
    points = np.array([(w.position.x, w.position.y, w.position.z) for w in plan.waypoints],
                      dtype=np.float64).reshape(-1, 3)
    return times, points


def _bounded_pairs(flights: list[tuple[np.ndarray, np.ndarray]], labels: list[str], groups,
                   only_pairs_with, vertical_m) -> tuple[np.ndarray, np.ndarray, np.ndarray, int]:
    """The pairs (i < j) airborne together, of different groups (and with a flagged flight when
    ``only_pairs_with``), with the gap between their bounding boxes [m] as a lower bound on their
    distance; with a cylinder (``vertical_m`` not None) the pairs whose boxes are ``vertical_m``
    or more apart vertically are left out, counted as checked, and the bound is horizontal.
    Returns (i, j, bound, pairs checked by the vertical bound alone)."""
    n = len(flights)
    t0 = np.array([f[0][0] for f in flights])
    t1 = np.array([f[0][-1] for f in flights])
    lo = np.array([f[1].min(axis=0) for f in flights])
    hi = np.array([f[1].max(axis=0) for f in flights])
    iu, ju = np.triu_indices(n, k=1)
    # airborne together, and not two parts of one flight (one group: its versions in force)
    grp = np.array([str(x) for x in (labels if groups is None else groups)], dtype=object)
    together = (t0[iu] <= t1[ju]) & (t0[ju] <= t1[iu]) & (grp[iu] != grp[ju])
    if only_pairs_with is not None:
        flag = np.asarray(only_pairs_with, dtype=bool)
        together &= flag[iu] | flag[ju]
    iu, ju = iu[together], ju[together]
    gap = np.maximum(0.0, np.maximum(lo[iu] - hi[ju], lo[ju] - hi[iu]))  # per axis, (k, 3)
    checked = 0
    if vertical_m is not None:
        # boxes V or more apart vertically: never vertically within V, so no distance counts;
        # such a pair is checked by that bound alone (counted as checked)
        close = gap[:, 2] < vertical_m
        checked = int((~close).sum())
        iu, ju, gap = iu[close], ju[close], gap[close, :2]
    return iu, ju, np.sqrt((gap * gap).sum(axis=1)), checked


class _PairSearch:
    """The exact closest approach of pairs taken in order of their lower bound [m]: the smallest
    distance found [m] and its pair, every loss of separation [label a, label b, m, s] and the
    pairs checked."""

    def __init__(self, flights, labels, iu, ju, bound, separation_m: float, vertical_m, checked: int):
        self.flights, self.labels = flights, labels
        self.iu, self.ju, self.bound = iu, ju, bound
        self.separation_m, self.vertical_m = separation_m, vertical_m
        self.checked = checked
        self.best, self.best_pair, self.losses = math.inf, None, []
        # plain Python floats for the pure-Python kernel (converting numpy scalars per pair is slow)
        self.plain: dict = {}

    def flight(self, i):
        if i not in self.plain:
            times, points = self.flights[i]
            self.plain[i] = ([float(t) for t in times], [tuple(map(float, p)) for p in points])
        return self.plain[i]

    def walk(self, ks) -> None:
        """The pairs ``ks`` (indices into the pairs, in bound order) until the bound reaches both
        the separation minimum and the smallest distance found."""
        from uam_planner.audit import pair_min_distance

        for k in ks:
            if self.bound[k] >= self.separation_m and self.bound[k] >= self.best:
                return
            i, j = int(self.iu[k]), int(self.ju[k])
            d, t = pair_min_distance(self.flight(i), self.flight(j), self.vertical_m)
            self.checked += 1
            if d < self.best:
                self.best, self.best_pair = d, [self.labels[i], self.labels[j]]
            if d < self.separation_m * (1.0 - TIE_RELATIVE):
                self.losses.append([self.labels[i], self.labels[j], float(d), float(t)])


def audit_trajectories(flights: list[tuple[np.ndarray, np.ndarray]], labels: list[str],
                       separation_m=SEPARATION_M, groups: Sequence | None = None,
                       only_pairs_with: Sequence[bool] | None = None) -> SafetyAudit:
    """Exact minimum separation and every loss of separation among piecewise-linear 4D flights.

    ``flights``: (times_s (p,), points_m (p, 3)) per flight, times increasing; flights of one
    group (``groups``, default the labels: the parts of one flight, each version while in force)
    are never a pair; with ``only_pairs_with`` (a flag per flight) only pairs with at least one
    flagged flight are audited. The exact closest
    approach of a pair is ``uam_planner.audit.pair_min_distance`` (brute force over the pair's
    time-overlapping segment pairs). Pairs are taken in increasing order of a lower bound on
    their distance (the gap between the two flights' bounding boxes; pairs never airborne
    together are skipped) and the search stops once the bound reaches both the separation
    minimum and the smallest distance found: every loss and the true minimum are still found,
    because no skipped pair can be closer than its bound. A finer bound first (a grid hash over
    the flights' straight pieces, ``uam_planner.audit._near_pairs``) leaves out every pair that
    stays twice the minimum apart on some horizontal axis at every common instant; those count
    as checked once a closer pair is found. Complexity O(F^2) for the box bounds (numpy), the
    grid's O(S log S) in the pieces, plus O(s_a + s_b) per evaluated pair.

    ``separation_m``: a number (sphere) or a SeparationModel. For the cylinder the bound is the
    horizontal gap of the boxes, pairs whose boxes are V or more apart vertically are never
    vertically close (checked by that bound alone: counted in ``pairs_checked``, no distance),
    and distances are horizontal while vertically closer than V.
    """
    model = _model(separation_m)
    separation_m = model.separation_m
    cylinder = model.kind == "cylinder"
    vertical_m = model.vertical_separation_m if cylinder else None
    kind = dict(separation_model=model.kind,
                vertical_separation_m=float(model.vertical_separation_m) if cylinder else 0.0)
    n = len(flights)
    if n < 2:
        return SafetyAudit(float(separation_m), math.inf, None, [], 0, **kind)
    iu, ju, bound, checked = _bounded_pairs(flights, labels, groups, only_pairs_with, vertical_m)
    order = np.argsort(bound, kind="stable")
    # A second, finer bound (on the 2,000-flight city recording nearly every
    # pair's boxes overlap, and the loop below ran for tens of CPU-minutes): the pairs that come
    # within `reach` on each horizontal axis at some common instant, by uam_planner.audit's grid
    # hash over straight pieces. A pair it leaves out is at least `reach` apart at every common
    # instant: no loss, and not the minimum once a pair closer than `reach` is found. So the
    # kernel runs on those pairs only, in the same order; the others count as checked (by that
    # bound, like the vertically apart ones). If the minimum is not below `reach`, the others are
    # searched as before.
    reach = 2.0 * separation_m
    near = _near_flight_pairs(flights, reach)
    codes = iu.astype(np.int64) * n + ju.astype(np.int64)
    is_near = np.isin(codes, near)
    search = _PairSearch(flights, labels, iu, ju, bound, separation_m, vertical_m, checked)
    search.walk(order[is_near[order]])
    far = order[~is_near[order]]
    if search.best < reach:
        search.checked += int(far.size)
    else:
        search.walk(far)
    losses = search.losses
    losses.sort(key=lambda x: (x[3], x[0], x[1]))
    return SafetyAudit(separation_m=float(separation_m), min_separation_m=float(search.best),
                       closest_pair=search.best_pair, losses=losses, pairs_checked=search.checked, **kind)


def _near_flight_pairs(flights: list[tuple[np.ndarray, np.ndarray]], reach_m: float) -> np.ndarray:
    """Sorted codes i * n + j (i < j) of the flight pairs that may come within ``reach_m`` on
    each horizontal axis at a common instant (``uam_planner.audit._near_pairs`` on their pieces)."""
    from uam_planner.audit import _near_pairs

    n = len(flights)
    t0 = np.concatenate([t[:-1] for t, _x in flights])
    t1 = np.concatenate([t[1:] for t, _x in flights])
    p0 = np.concatenate([x[:-1] for _t, x in flights]).reshape(-1, 3).astype(np.float64)
    p1 = np.concatenate([x[1:] for _t, x in flights]).reshape(-1, 3).astype(np.float64)
    f = np.concatenate([np.full(len(t) - 1, k, dtype=np.int64) for k, (t, _x) in enumerate(flights)])
    order = np.argsort(t0, kind="stable")
    seg = (t0[order], t1[order], p0[order], p1[order], f[order])
    i, j = _near_pairs(seg, reach_m)
    if i.size == 0:
        return np.zeros(0, np.int64)
    fa, fb = seg[4][i], seg[4][j]
    return np.unique(np.minimum(fa, fb) * n + np.maximum(fa, fb))


def audit_plans(plans: list[Any], separation_m=SEPARATION_M,
                labels: Sequence[str] | None = None) -> SafetyAudit:
    """Exact minimum separation between every pair of approved plans (see :func:`audit_trajectories`).

    ``labels`` name the plans in the result (default: their request ids; give distinct labels
    when two plans share an id). ``separation_m``: a number (sphere) or a SeparationModel.
    """
    names = [str(p.request_id) for p in plans] if labels is None else list(labels)
    flights, kept = [], []
    for p, name in zip(plans, names):
        times, points = trajectory_of(p)
        if len(times) < 2:
            continue
        if np.any(np.diff(times) <= 0):
            raise ValueError(f"flight plan {p.request_id!r}: waypoint times are not increasing: {times}")
        flights.append((times, points))
        kept.append(name)
    return audit_trajectories(flights, kept, separation_m)


def sweep_audit(trajectories: Sequence, separation_m, labels: Sequence | None = None,
                chunk_pairs: int = 4_000_000, max_listed: int = 20, prune: bool = True,
                groups: Sequence | None = None) -> dict:
    """Exact minimum separation over every pair of flights, by a time sweep over segments, as the
    study's tables want it (a dict).

    The sweep is ``uam_planner.audit.sweep_audit`` (every pair of straight segments of different
    flights whose time intervals overlap, closest approach clamped to the overlap, in numpy,
    chunked; ``prune`` (default) checks only the pairs its own grid hash finds near each other,
    with the same result, so nothing depends on the planner's broad phase; its tests hold it
    equal to the full sweep and to the brute-force ``uam_planner.audit.audit_flights``). One
    implementation for the sphere and the cylinder; this function only converts its result.

    Args:
        trajectories: objects with ``times_s`` (p,) and ``points_m`` (p, 3).
        separation_m: a number (the sphere: a loss is a 3D distance strictly below it, ties
            within 1e-9 excepted) or a SeparationModel (the cylinder: horizontal distances while
            vertically closer than V).
        labels: names for the pairs (default: indices).
        chunk_pairs: segment pairs per numpy chunk (memory bound).
        prune: False checks every time-overlapping segment pair (the slow reference).
        groups: a name per trajectory: the parts of one flight (each version while in force)
            share it, are never a pair, and the pairs are named by it.
    Returns: {"min_separation_m" (None if no two flights share time), "pair_of_min",
    "min_time_s", "losses" (count of flight pairs with a loss), "loss_pairs" (up to max_listed,
    closest first: label, label, distance_m, t_s), "pairs_checked" (flight pairs with a common
    time), "separation_model"} (+ "vertical_separation_m" for the cylinder).
    Complexity: O(S log S + P) for S segments and P time-overlapping segment pairs.
    """
    return sweep_audits(trajectories, [separation_m], labels, chunk_pairs, max_listed, prune, groups)[0]


def sweep_audits(trajectories: Sequence, models: Sequence, labels: Sequence | None = None,
                 chunk_pairs: int = 4_000_000, max_listed: int = 20, prune: bool = True,
                 groups: Sequence | None = None) -> list[dict]:
    """:func:`sweep_audit` in several separation models with one candidate search
    (``uam_planner.audit.sweep_audits``), one dict per model."""
    from uam_planner.audit import sweep_audits as planner_sweeps

    labels = list(labels) if labels is not None else list(range(len(trajectories)))
    models = [_model(m) for m in models]
    results = planner_sweeps(list(trajectories), models, labels=labels, chunk_pairs=chunk_pairs, prune=prune,
                             groups=groups)
    return [_as_dict(res, model, max_listed) for res, model in zip(results, models)]


def _as_dict(res, model, max_listed: int) -> dict:
    extra = {"separation_model": model.kind}
    if model.kind == "cylinder":
        extra["vertical_separation_m"] = float(model.vertical_separation_m)
    if res.pairs_checked == 0:
        return {"min_separation_m": None, "pair_of_min": None, "losses": 0, "loss_pairs": [],
                "pairs_checked": 0, **extra}
    loss_pairs = sorted(([a, b, float(d), float(t)] for a, b, d, t in res.losses), key=lambda x: x[2])
    best = res.min_separation_m
    return {"min_separation_m": float(best) if math.isfinite(best) else None,
            "pair_of_min": list(res.pair_of_min) if res.pair_of_min else None,
            "min_time_s": float(res.min_time_s),
            "losses": len(res.losses), "loss_pairs": loss_pairs[:max_listed],
            "pairs_checked": res.pairs_checked, **extra}
