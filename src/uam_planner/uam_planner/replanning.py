"""Batch re-planning when constraints change, plan versions and F3548 states (items 3
and 4; docs/replanning.md). Free of ROS; no wall clock inside a decision.

When the ``Planner`` applies a constraint update at an epoch time ``t_eff`` (an announced
constraint reaching its ``announce_s``, or a live ``Planner.update_constraint``), before the
epoch's new requests are planned, :func:`replan` decides for every **affected** flight (one whose
plan, from ``t_eff`` on, enters a constraint of the updated set during its window):

- **not departed** (departure >= t_eff): its alternatives are its request's candidates (every
  route and level, every departure slot in [max(t_eff, earliest), min(latest, t_eff + epoch)],
  as the planner builds them) that stay out of every constraint; none chosen -> **cancelled**,
  with a reason naming the constraint;
- **airborne** (departure < t_eff): it flies on to its *branch point*, the first waypoint at or
  after t_eff (a corridor node, or its origin pad at the top of the climb), and from there gets,
  at its level, up to ``k`` routes to its destination's pad (**rerouted**) and the shortest
  route to each of the ``DIVERT_VERTIPORTS`` nearest other vertiports, every pad (**diverted**),
  and turning back at once from where it is at t_eff to the pad it left (``_turn_back``);
  a flight left with fewer than ``STAGE2_BELOW`` of them that keep separation with the
  unaffected flights also gets the re-routes to its destination's other pads and all of these
  from its next waypoint (``BRANCH_WAYPOINTS``). Routes: penalised Dijkstra with the corridors
  that cross an updated volume avoided (each 10,000 km dearer, so taken only where there is no
  other way, e.g. to leave the zone before it opens; vertiports terminals on a layered
  network), then checked exactly. None chosen -> **contingency**: it flies the constraint-free
  alternative that loses separation with the fewest flights, then lands soonest (a contingency
  landing, flown but *not deconflicted*, ``Flight.contingent``, F3548 Contingent), or its
  current plan if none stays out (an incursion that cannot be avoided: reported, never hidden);
- a flight whose plan still stays out keeps it (**kept**; a flight is affected only if it does
  not, so kept appears when the caller names flights explicitly).

ONE conflict graph over every affected flight's alternatives (one vertex per alternative, one
clique per flight), each alternative deconflicted exactly (``conflict_graph``, the run's
separation model) against every unaffected active flight and joined by an edge to the
alternatives of other affected flights it loses separation with. Weights (tiers, so the MWIS
prefers keep > re-route or re-time with the least added delay > divert to the nearest pad >
nothing): ``W_KEEP`` = 4; re-route / re-time 2 + 1 / (1 + delay / ``DELAY_SCALE_S``) in (2, 3],
delay = new arrival - old arrival clamped at 0; divert 1 + 1 / (1 + T / ``DELAY_SCALE_S``) in
(1, 2], T = landing time - t_eff.
Policy "mwis" solves it with the planner's solve function (answer checked, greedy fallback);
"firstfit" (the baseline) walks the flights in approval order and takes each one's first
alternative in preference order (weight, descending) that keeps separation with what is taken.
"""

from __future__ import annotations

import math
import time
from dataclasses import dataclass, field, replace
from typing import Callable, Sequence

import numpy as np

from .constraints import Constraint, ConstraintError, ConstraintSet, check_against
from .intent_volumes import graph_for_config
from .trajectory import Trajectory

ACTIONS = ("add", "change", "withdraw")
KINDS = ("kept", "rerouted", "retimed", "diverted", "cancelled", "contingency")
#: the kind of a new version an operator asked for (``Planner.modify``): not a re-plan, so not
#: one of KINDS (the re-plan counts); it names no constraint
KIND_MODIFIED = "modified"
STATES = ("Accepted", "Activated", "Contingent", "Ended")  # ASTM F3548-21 (Nonconforming: uam_planner.nonconformance)
W_KEEP = 4.0
DELAY_SCALE_S = 300.0
DIVERT_VERTIPORTS = 3
BRANCH_WAYPOINTS = 2
STAGE2_BELOW = 4
#: contingency rounds after the first graph: each unsaved airborne flight becomes a FIXED
#: contingency and the graph is solved again around it (docs/replanning.md, "Contingencies")
CASCADE_ROUNDS = 8
#: unaffected flights pulled into one re-plan at most (those a contingency would meet)
CASCADE_MAX_PULLED = 200
#: holds [s] a contingency may take at its branch point before flying on or landing
HOLD_S = (30.0, 60.0, 120.0)
_EPS_T = 1e-9


@dataclass(frozen=True)
class ConstraintUpdate:
    """One queued or applied constraint update.

    Attributes:
        action: 'add', 'change' or 'withdraw'.
        constraint: the new Constraint (add, change) or the one withdrawn (withdraw).
        t_s: when it was announced [s]; it is applied at the first epoch at a time >= t_s.
        seq: submission order (ties of t_s are applied in this order).
        applied_s: the epoch time it was applied at (nan while queued).
    """

    action: str
    constraint: Constraint
    t_s: float
    seq: int
    applied_s: float = float("nan")


@dataclass(frozen=True, eq=False)
class PlanUpdate:
    """What happened to one affected flight, for the operator and the recording.

    Attributes:
        request_id, operator_id: the flight.
        version: the new version (old version + 1; a cancellation has one too).
        kind: one of KINDS.
        constraint_ids: the constraint(s) the old plan entered.
        reason: a sentence naming the constraint(s) and what was done.
        effective_s: when the new version takes effect (the epoch time t_eff).
        flight: the new Flight (None when cancelled).
        previous: the replaced Flight.
        added_delay_s: new arrival - old arrival [s] (nan when cancelled).
    """

    request_id: str
    operator_id: str
    version: int
    kind: str
    constraint_ids: tuple
    reason: str
    effective_s: float
    flight: object
    previous: object
    added_delay_s: float = float("nan")


@dataclass
class ReplanReport:
    """Counts and times of one batch re-plan (``EpochReport.replan``)."""

    t_s: float
    policy: str
    updates: list = field(default_factory=list)      # labels of the updates applied
    affected: int = 0
    affected_airborne: int = 0
    affected_not_departed: int = 0
    alternatives: int = 0       # constraint-free alternatives generated
    stage2: int = 0             # flights that got stage-2 alternatives
    vertices: int = 0
    edges: int = 0
    kinds: dict = field(default_factory=dict)        # kind -> count
    decision_time_s: float = 0.0                     # wall, for reports only
    decision_cpu_s: float = 0.0                      # process CPU time, for reports only
    graphs_solved: int = 0                           # MWIS / first-fit selections (1 + cascade rounds)
    solve_time_s: float = 0.0
    backend_used: str = ""
    fallback: bool = False
    fallback_reason: str = ""
    cascade_rounds: int = 0     # contingency rounds after the first graph
    pulled_in: int = 0          # unaffected flights re-planned around a contingency
    contingencies_fixed: int = 0  # contingencies deconflicted (chosen in the graph, or fixed)
    unresolved: int = 0         # contingencies flown NOT deconflicted (bound, or unavoidable clash)
    unavoidable: int = 0        # no constraint-free alternative at all (already inside): plan flown


# ---- states and versions ----------------------------------------------------------------------

def flight_state(flight, t_s: float) -> str:
    """The ASTM F3548-21 state of ``flight`` (its newest version) at ``t_s`` [s]: 'Accepted'
    before departure, 'Activated' airborne, 'Contingent' airborne on a contingency plan,
    'Ended' after arrival. (A cancelled flight is Ended from its cancellation; a PlanUpdate of
    kind 'cancelled' says so. Nonconforming needs a conformance monitor: uam_planner.nonconformance.)"""
    if t_s > flight.arrival_s:
        return "Ended"
    if t_s < flight.departure_s:
        return "Accepted"
    return "Contingent" if getattr(flight, "contingent", False) else "Activated"


def spliced(old: Trajectory, new: Trajectory, effective_s: float, tol_m: float = 1e-6) -> Trajectory:
    """What flies when ``new`` replaces ``old`` at ``effective_s``: old before, new after.

    If ``old`` has not departed by ``effective_s`` the answer is ``new``. Otherwise the two
    must chain: ``new`` airborne at ``effective_s`` at the position of ``old`` there (within
    ``tol_m``); else ValueError naming the gap ("versions do not chain")."""
    t = float(effective_s)
    if old.departure_s >= t:
        return new
    if not new.departure_s <= t <= new.arrival_s:
        raise ValueError(f"versions do not chain: the new version is not airborne at t = {t:g} s "
                         f"(it flies [{new.departure_s:g}, {new.arrival_s:g}] s)")
    a = old.position_at(min(t, old.arrival_s), clamp=True)
    b = new.position_at(t)
    gap = float(np.linalg.norm(a - b))
    if gap > tol_m:
        raise ValueError(f"versions do not chain: at t = {t:g} s the new version is {gap:.3f} m "
                         f"from the old one")
    keep = old.times_s < t - _EPS_T
    after = new.times_s > t + _EPS_T
    times = np.concatenate((old.times_s[keep], [t], new.times_s[after]))
    points = np.concatenate((old.points_m[keep], [b], new.points_m[after]))
    return Trajectory(times, points)



def clipped_from(tr: Trajectory, t_s: float) -> Trajectory | None:
    """The part of ``tr`` at or after ``t_s`` (None if it has landed by then)."""
    t = float(t_s)
    if t >= tr.arrival_s:
        return None
    if t <= tr.departure_s:
        return tr
    ts, ps = tr.times_s, tr.points_m
    j = min(int(np.searchsorted(ts, t + _EPS_T, side="right")), ts.shape[0] - 1)  # next waypoint
    w = (t - ts[j - 1]) / (ts[j] - ts[j - 1])
    here = ps[j - 1] + w * (ps[j] - ps[j - 1])
    times = np.concatenate(([t], ts[j:]))
    points = np.concatenate(([here], ps[j:]))
    return Trajectory._trusted(times, points, None)  # a cut of a valid trajectory


def clipped_until(tr: Trajectory, t_s: float) -> Trajectory | None:
    """The part of ``tr`` before ``t_s``, ending at its position then (None if it departs at or
    after ``t_s``)."""
    t = float(t_s)
    if tr.departure_s >= t:
        return None
    if tr.arrival_s <= t:
        return tr
    keep = tr.times_s < t
    return Trajectory._trusted(np.append(tr.times_s[keep], t),     # a cut of a valid trajectory
                               np.vstack((tr.points_m[keep], tr.position_at(t))), None)


# ---- the constraint state ----------------------------------------------------------------------

def check_update(action: str, constraint, t_s, current: dict, network) -> str | None:
    """Why the update cannot be accepted (naming the field and value), or None.

    ``current``: constraint id -> Constraint as it will be once every update queued before is
    applied."""
    if action not in ACTIONS:
        return f"action: {action!r} is not one of {ACTIONS}"
    if isinstance(t_s, bool) or not isinstance(t_s, (int, float, np.integer, np.floating)) \
            or not math.isfinite(t_s):
        return f"t_s: {t_s!r} is not a finite time"
    if action == "withdraw":
        cid = constraint if isinstance(constraint, str) else getattr(constraint, "constraint_id", None)
        if cid not in current:
            return f"constraint_id: {cid!r} is not a known constraint (nothing to withdraw)"
        return None
    if not isinstance(constraint, Constraint):
        return f"constraint: {constraint!r} is not a Constraint"
    cid = constraint.constraint_id
    if action == "add" and cid in current:
        return (f"constraint_id: {cid!r} is already a constraint (v{current[cid].version}); "
                f"use 'change' with a higher version")
    if action == "change":
        if cid not in current:
            return f"constraint_id: {cid!r} is not a known constraint (nothing to change)"
        if constraint.version <= current[cid].version:
            return (f"version: {constraint.version!r} of {cid!r} is not above the current "
                    f"version {current[cid].version}")
    try:
        check_against(constraint, network, float(t_s))
    except ConstraintError as exc:
        return str(exc)
    return None


def apply_updates(cset: ConstraintSet | None, updates: Sequence[ConstraintUpdate], network) -> ConstraintSet:
    """The ConstraintSet after ``updates`` (in order) on ``cset`` (None = empty)."""
    cur = {c.constraint_id: c for c in (cset or ())}
    for u in updates:
        cid = u.constraint.constraint_id
        if u.action == "withdraw":
            cur.pop(cid, None)
        else:
            cur[cid] = u.constraint
    return ConstraintSet(list(cur.values()), network)


def constraint_timeline(initial: Sequence[Constraint], applied: Sequence[ConstraintUpdate]) -> list:
    """(Constraint, from_s, until_s) of every constraint version while it was in force: from
    the epoch it was applied at (-inf for the initial ones) until it was changed or withdrawn
    (inf if never). What the audit of what flew checks incursions against."""
    open_: dict = {c.constraint_id: (c, -math.inf) for c in initial}
    out = []
    for u in applied:
        cid = u.constraint.constraint_id
        if cid in open_:
            c, since = open_.pop(cid)
            out.append((c, since, u.applied_s))
        if u.action != "withdraw":
            open_[cid] = (u.constraint, u.applied_s)
    out.extend((c, since, math.inf) for c, since in open_.values())
    return out


def pad_of_point(network, node: int, xy) -> int:
    """Index of the pad of ``node`` nearest to ``xy`` (the first of equally near ones)."""
    pads = network.pads_of(node)
    if len(pads) <= 1:
        return 0
    # in scalars, the same operations as ``argmin(norm(centre + pads - xy, axis=1))`` (each
    # distance is sqrt(dx * dx + dy * dy), correctly rounded either way): the same pad, without
    # five numpy calls per flight end (~4,000 calls per re-plan)
    c = network.enu_m[node]
    cx, cy = float(c[0]), float(c[1])
    x, y = float(xy[0]), float(xy[1])
    best, k = math.inf, 0
    for i, (px, py) in enumerate(pads.tolist()):
        dx, dy = (cx + px) - x, (cy + py) - y
        d = math.sqrt(dx * dx + dy * dy)
        if d < best:
            best, k = d, i
    return k



# ---- affected flights and their alternatives ---------------------------------------------------

def affected_flights(active: Sequence, cset: ConstraintSet, t_eff: float, network) -> dict:
    """index in ``active`` -> (constraint index, entry time) of each flight whose plan from
    ``t_eff`` on enters a constraint of ``cset`` during its window (an airborne flight's
    departure is not re-checked against closures)."""
    if cset is None or not len(cset) or not active:
        return {}
    rows, trs, o, d, po, pd = [], [], [], [], [], []
    for i, f in enumerate(active):
        tr = clipped_from(f.trajectory, t_eff)
        if tr is None:
            continue
        rows.append(i)
        trs.append(tr)
        oi = network.node_index(f.origin_id)
        di = network.node_index(f.destination_id)
        o.append(oi if f.departure_s >= t_eff else -1)
        d.append(di)
        po.append(pad_of_point(network, oi, f.trajectory.points_m[0]))
        pd.append(pad_of_point(network, di, f.trajectory.points_m[-1]))
    if not rows:
        return {}
    which, when = cset.violations(trs, np.array(o), np.array(d), np.array(po), np.array(pd))
    return {rows[k]: (int(which[k]), float(when[k])) for k in np.flatnonzero(which >= 0).tolist()}


@dataclass
class _Alt:
    trajectory: Trajectory
    kind: str
    weight: float
    destination: int
    route_node_ids: tuple
    length_m: float
    route_index: int = 0
    candidate_index: int = 0
    hold_s: float = 0.0         # hover at the branch point before flying on (a contingency's)


def _tier(kind: str, delay_s: float) -> float:
    d = max(0.0, float(delay_s))
    if kind == "kept":
        return W_KEEP
    base = 1.0 if kind == "diverted" else 2.0
    return base + 1.0 / (1.0 + d / DELAY_SCALE_S)


class _Router:
    """Routes from any node at one level around the updated volumes (penalised Dijkstra on the
    corridors that do not cross a volume whose band holds the level, vertiports terminals on a
    layered network)."""

    def __init__(self, network, cache, cset: ConstraintSet, t_eff: float):
        self.net = network
        self.cache = cache
        self.vols = [c for c in cset if c.kind != "closure" and c.end_s > t_eff]
        self._blocked: dict = {}
        self._lines = None
        self._memo: dict = {}

    def blocked(self, level_z: float | None) -> np.ndarray:
        key = None if level_z is None else round(float(level_z), 6)
        got = self._blocked.get(key)
        if got is not None:
            return got
        import shapely
        net = self.net
        e = np.asarray(net.edges, dtype=np.int64)
        mask = np.zeros(e.shape[0], dtype=bool)
        if self.vols and e.shape[0]:
            if self._lines is None:
                xy = net.enu_m[:, :2]
                self._lines = shapely.STRtree(shapely.linestrings(np.stack((xy[e[:, 0]], xy[e[:, 1]]), axis=1)))
            z = net.enu_m[:, 2]
            zlo = np.minimum(z[e[:, 0]], z[e[:, 1]])
            zhi = np.maximum(z[e[:, 0]], z[e[:, 1]])
            for c in self.vols:
                if c.center_m is not None:
                    # the disk grown by 1 m: the search is a pre-filter, the exact test decides
                    geom = shapely.Point(c.center_m).buffer(c.radius_m + 1.0, quad_segs=32)
                else:
                    geom = shapely.Polygon(c.rings_m[0], c.rings_m[1:]).buffer(1.0)
                hit = self._lines.query(geom, predicate="intersects")
                if level_z is None:
                    band = (zhi[hit] >= c.lower_m) & (zlo[hit] <= c.upper_m)
                else:
                    band = np.full(hit.shape[0], c.lower_m <= level_z <= c.upper_m)
                mask[hit[band]] = True
        self._blocked[key] = mask
        return mask

    def routes(self, u: int, target: int, k: int, level_z: float | None):
        from .candidates import _routes
        if u == target:
            return []
        key = (u, target, k, None if level_z is None else round(float(level_z), 6))
        got = self._memo.get(key)
        if got is None:
            try:
                got = _routes(self.cache._graph, self.net, u, target, k, self.cache.penalty_factor,
                              terminals=self.net.layered, blocked=self.blocked(level_z))
            except ValueError:
                got = []
            self._memo[key] = got
        return got


def _turn_back(f, t_eff: float, network, config) -> _Alt | None:
    """Airborne flight ``f`` turning back at once, from where it is at ``t_eff``, along the
    waypoints it has flown to the pad it left (a diversion to its origin): the one option that
    keeps the spacing of a stream of flights on one corridor that must all turn back (each
    turning at its own next waypoint would meet its followers head-on). None if it has not
    left the ground's vertical leg or has landed."""
    tr = f.trajectory
    times, pts = tr.times_s, tr.points_m
    if not times[0] < t_eff < times[-1]:
        return None
    j = int(np.searchsorted(times, t_eff, side="right"))        # waypoints before t_eff: [0, j)
    here = tr.position_at(t_eff)
    back = pts[:j][::-1]
    layered = network.layered
    if layered and j <= 1:
        return None  # still climbing from its pad
    new = _extend(np.concatenate((times[:j], [t_eff])) if times[j - 1] < t_eff else times[:j],
                  np.concatenate((pts[:j], [here])) if times[j - 1] < t_eff else pts[:j],
                  back[1:] if times[j - 1] >= t_eff else back, float(config.speed_mps),
                  float(config.airspace.descent_rate_mps), vertical_last=layered)
    if new is None:
        return None
    o = network.node_index(f.origin_id)
    route = list(f.route_node_ids)
    k = max(0, min(len(route), j - (1 if layered else 0)))
    node_ids = tuple(route[:k]) + tuple(reversed(route[:k]))[1:] if k > 1 else (f.origin_id,)
    length = float(np.sqrt(np.square(np.diff(new.points_m, axis=0)).sum(axis=1)).sum())
    return _Alt(new, "diverted", _tier("diverted", new.arrival_s - t_eff), o, node_ids, length,
                f.route_index, f.candidate_index)


def _airborne_alternatives(f, t_eff: float, network, config, router: _Router, stage: int = 1) -> list:
    """Re-routes to the destination and diversions of airborne flight ``f`` (see the module
    docstring); may be empty. Stage 1: from its branch point, re-routes to its own pad and
    diversions to every pad; stage 2 (the rest, for a flight with too few stage-1 survivors):
    re-routes to its destination's other pads, then everything from the next
    ``BRANCH_WAYPOINTS - 1`` waypoints."""
    tr = f.trajectory
    times, pts = tr.times_s, tr.points_m
    k0 = int(np.searchsorted(times, t_eff - _EPS_T, side="left"))  # first waypoint >= t_eff
    route = [network.node_index(x) for x in f.route_node_ids]
    layered = network.layered
    dest = network.node_index(f.destination_id)
    speed = float(config.speed_mps)
    descent = float(config.airspace.descent_rate_mps)
    xy = network.enu_m[:, :2]
    dest_pad = pad_of_point(network, dest, pts[-1])
    alts = []
    others = np.array([int(a) for a in network.aerodrome_indices if int(a) != dest], dtype=np.int64)
    for k in range(k0, k0 + (1 if stage == 1 else BRANCH_WAYPOINTS)):
        node_at = k - 1 if layered else k  # route node of waypoint k
        if not 0 <= node_at < len(route) or (layered and k == 0):
            break  # descending to its pad: nothing to branch from
        u = route[node_at]
        level = float(pts[k, 2]) if layered else None
        targets = [(dest, "rerouted", int(config.k))]
        targets += [(a, "diverted", 1) for a in _nearest(xy, others, pts[k, :2], DIVERT_VERTIPORTS)]
        for target, kind, n_routes in targets:
            for r in router.routes(u, target, n_routes, level):
                mid = np.asarray(r.node_indices[1:-1], dtype=np.int64)
                node_ids = tuple(f.route_node_ids[:node_at + 1]) + \
                    tuple(network.node_ids[i] for i in r.node_indices[1:])
                news = []
                if layered:
                    alt_z = float(network.lat_lon_alt[target, 2])
                    pads = network.pads_of(target)
                    order = list(range(len(pads)))
                    if kind == "rerouted":  # its own pad first
                        order.remove(dest_pad)
                        order.insert(0, dest_pad)
                    for pi in order:
                        first = k == k0 and (kind == "diverted" or pi == dest_pad)
                        if first != (stage == 1):
                            continue
                        pad = xy[target] + pads[pi]
                        horiz = np.concatenate((xy[mid].reshape(-1, 2), [pad]))
                        new = np.column_stack((horiz, np.full(horiz.shape[0], level)))
                        news.append(np.concatenate((new, [(pad[0], pad[1], alt_z)])))
                elif (k == k0) == (stage == 1):
                    news.append(network.enu_m[np.asarray(r.node_indices[1:], dtype=np.int64)])
                for new in news:
                    traj = _extend(times[:k + 1], pts[:k + 1], new, speed, descent, vertical_last=layered)
                    if traj is None:
                        continue
                    length = float(np.sqrt(np.square(np.diff(traj.points_m, axis=0)).sum(axis=1)).sum())
                    # a re-route costs its added delay; a diversion its time to land
                    cost = traj.arrival_s - (tr.arrival_s if kind == "rerouted" else t_eff)
                    alts.append(_Alt(traj, kind, _tier(kind, cost), target, node_ids, length,
                                     int(r.candidate_index)))
    return alts


def _nearest(xy, nodes: np.ndarray, at, n: int) -> list:
    """The ``n`` of ``nodes`` (int64 indices into ``xy``) nearest to ``at`` horizontally, nearest
    first, ties by index: the order of sorting by ``(hypot(*(xy[a] - at)), a)`` (the hypot taken
    elementwise, the same values as one at a time), in two numpy calls instead of one lambda per
    node."""
    dist = np.hypot(xy[nodes, 0] - at[0], xy[nodes, 1] - at[1])
    return nodes[np.lexsort((nodes, dist))[:n]].tolist()


def _extend(times, pts, new_pts, speed, descent, vertical_last: bool) -> Trajectory | None:
    """Prefix (times, pts) continued through ``new_pts`` at ``speed`` (the last leg vertical at
    ``descent`` when ``vertical_last``); zero-length legs dropped; None if nothing is left."""
    seq = np.concatenate((pts[-1:], np.asarray(new_pts, dtype=np.float64).reshape(-1, 3)))
    legs = np.sqrt(np.square(np.diff(seq, axis=0)).sum(axis=1))
    keep = np.concatenate(([True], legs > 1e-9))   # drop zero-length legs
    if not keep.all():
        seq = seq[keep]
        legs = legs[legs > 1e-9]
    if seq.shape[0] < 2:
        return None
    dt = legs / speed
    if vertical_last and seq[-1, 0] == seq[-2, 0] and seq[-1, 1] == seq[-2, 1]:
        dt[-1] = legs[-1] / descent
    t = times[-1] + np.concatenate(([0.0], np.cumsum(dt)))
    out_t = np.concatenate((times[:-1], t))
    out_p = np.concatenate((pts[:-1], seq))
    return Trajectory._trusted(out_t, out_p, None)  # increasing: positive legs at positive speeds


def _ground_alternatives(f, req, t_eff: float, network, cache, departures: Callable) -> list:
    """Candidates of a flight that has not departed: every template and departure slot in its
    request's window from t_eff (see the module docstring)."""
    o, d = network.node_index(f.origin_id), network.node_index(f.destination_id)
    if req is not None:
        slots = np.asarray(departures(t_eff, req), dtype=np.float64)
        slots = slots[(slots >= req.earliest_departure_s - _EPS_T) & (slots <= req.latest_departure_s + _EPS_T)]
    else:  # restored without its request: only its own departure time
        slots = np.array([f.departure_s]) if f.departure_s >= t_eff else np.zeros(0)
    alts = []
    c = 0
    for tp in cache.templates(o, d):
        for dep in slots.tolist():
            traj = tp.trajectory(dep)
            same = tp.node_ids == tuple(f.route_node_ids) and \
                (math.isnan(tp.level_m) and math.isnan(f.level_m) or tp.level_m == f.level_m)
            kind = "retimed" if same else "rerouted"
            alts.append(_Alt(traj, kind, _tier(kind, traj.arrival_s - f.arrival_s), d, tp.node_ids,
                             float(tp.route.length_m), int(tp.route.candidate_index), c))
            c += 1
    return alts


def _constraint_free(alts: list, cset: ConstraintSet, t_eff: float, network, origin: int | None) -> list:
    """The alternatives that, from t_eff on, stay out of every constraint (closures at the end
    they land at; at the origin too for a flight that has not departed)."""
    return _constraint_free_many([(alts, origin)], cset, t_eff, network)[0]


def _constraint_free_many(groups: list, cset: ConstraintSet, t_eff: float, network) -> list:
    """:func:`_constraint_free` of each ``(alts, origin)`` of ``groups``, in one
    ``ConstraintSet.violations`` call (each trajectory's answer is its own: the same lists as
    one call per group, for one call's overhead)."""
    flat = [(a, origin) for alts, origin in groups for a in alts]
    if not flat:
        return [list(alts) for alts, _o in groups]
    trs = [clipped_from(a.trajectory, t_eff) for a, _o in flat]
    o = np.array([origin if origin is not None else -1 for _a, origin in flat], dtype=np.int64)
    d = np.array([a.destination for a, _o in flat], dtype=np.int64)
    po = np.array([pad_of_point(network, max(origin, 0), a.trajectory.points_m[0]) if origin is not None
                   else 0 for a, origin in flat])
    pd = np.array([pad_of_point(network, a.destination, a.trajectory.points_m[-1]) for a, _o in flat])
    which, _ = cset.violations(trs, o, d, po, pd)
    ok = (which < 0).tolist()
    out, pos = [], 0
    for alts, _o in groups:
        out.append([a for a, w in zip(alts, ok[pos:pos + len(alts)]) if w])
        pos += len(alts)
    return out


def _keep_alt(f, network) -> _Alt:
    return _Alt(f.trajectory, "kept", W_KEEP, network.node_index(f.destination_id),
                tuple(f.route_node_ids), f.length_m, f.route_index, f.candidate_index)


def _held(a: _Alt, t_eff: float, hold_s: float) -> _Alt | None:
    """``a`` with a hover of ``hold_s`` at its first waypoint at or after ``t_eff`` (the branch
    point: the prefix before it is the old plan's, so it still chains); None if that waypoint is
    its landing."""
    times, pts = a.trajectory.times_s, a.trajectory.points_m
    k = int(np.searchsorted(times, t_eff - _EPS_T, side="left"))
    if k >= times.shape[0] - 1:
        return None
    t = np.concatenate((times[:k + 1], [times[k] + hold_s], times[k + 1:] + hold_s))
    p = np.concatenate((pts[:k + 1], pts[k:k + 1], pts[k + 1:]))
    return replace(a, trajectory=Trajectory._trusted(t, p, None), hold_s=float(hold_s))  # a hover


def _contingency_weight(a: _Alt, t_eff: float) -> float:
    """A contingency option's weight in the graph: in (0, 1), below every diversion's, the
    soonest landing heaviest."""
    return 0.999 / (1.0 + max(0.0, a.trajectory.arrival_s - t_eff) / DELAY_SCALE_S)


def _contingency_candidates(alts: list, f, t_eff: float, cset: ConstraintSet, network,
                            config) -> tuple[list, list]:
    """A contingency's options: its constraint-free alternatives (turning back at once among
    them), and each held ``HOLD_S`` at its branch point (for the turn-back: where it is at
    t_eff), kept only if it still stays out. Returns (options, hold of each [s])."""
    cands, holds = list(alts), [0.0] * len(alts)
    for h in HOLD_S:
        more = [x for x in (_held(a, t_eff, h) for a in alts) if x is not None]
        more = _constraint_free(more, cset, t_eff, network, None)
        cands += more
        holds += [h] * len(more)
    return cands, holds


def _contingency_choice(options: tuple, active: Sequence, in_replan: set, fixed: dict, chosen: dict,
                        config, t_eff: float, pending: Sequence = (), held: Sequence = ()):
    """A contingency's plan: of its ``options`` (from :func:`_contingency_candidates`), the one
    that loses separation with the fewest FIXED flights (other contingencies, flights with no
    way out: ideally none), then leaves the fewest of the flights still to be decided
    (``pending``: each one's options) with no option that avoids it, then meets
    the fewest airborne unaffected flights, then the fewest not departed (airborne flights
    outrank them), then the fewest flights the graph chose (re-decided in the next round), then
    lands soonest. ``held``: trajectories of flights held past their plans, counted as fixed
    flights. Returns (option, hold [s], indices in ``active`` of the unaffected flights it
    loses separation with, airborne first, whether it meets a fixed flight)."""
    from .separation import SegmentSet, conflicting_pairs
    cands, holds = options
    fx = [a.trajectory for a in fixed.values()] + list(held)
    un = [j for j in range(len(active)) if j not in in_replan]
    ch = [a.trajectory for a in chosen.values()]
    others = fx + [active[j].trajectory for j in un] + ch
    n = len(cands)
    n_fx, n_air, n_gnd, n_ch, n_block = (np.zeros(n, dtype=np.int64) for _ in range(5))
    hits: list = [set() for _ in range(n)]
    cset_ = SegmentSet.from_trajectories([x.trajectory for x in cands])
    if others:
        oset = SegmentSet.from_trajectories(others)
        oset = oset.take(oset.t1_s >= t_eff) if len(oset) else oset
        if len(oset):
            pairs = np.unique(conflicting_pairs(cset_, oset, config.separation)[:, :2], axis=0)
            for c_, o_ in pairs.tolist():
                if o_ < len(fx):
                    n_fx[c_] += 1
                elif o_ < len(fx) + len(un):
                    j = un[o_ - len(fx)]
                    hits[c_].add(j)
                    if active[j].departure_s < t_eff:
                        n_air[c_] += 1
                    else:
                        n_gnd[c_] += 1
                else:
                    n_ch[c_] += 1
    pend = [list(p_cands) for p_cands, _h in pending if p_cands]
    if pend and fx:  # their options left: those that keep separation with the fixed flights
        from .conflict_graph import discard_against_active
        flat = [x for xs in pend for x in xs]
        fset = SegmentSet.from_trajectories(fx)
        gone = discard_against_active([x.trajectory for x in flat], fset.take(fset.t1_s >= t_eff),
                                      config.separation)
        live, pos = [], 0
        for xs in pend:
            live.append([x for x, g in zip(xs, gone[pos:pos + len(xs)].tolist()) if not g])
            pos += len(xs)
        pend = [xs for xs in live if xs]  # one with none left cannot be helped here
    if pend:  # an option that would leave another flight no option that avoids it
        owner = np.repeat(np.arange(len(pend)), [len(x) for x in pend])
        size = np.array([len(x) for x in pend], dtype=np.int64)
        pset = SegmentSet.from_trajectories([x.trajectory for xs in pend for x in xs])
        pset = pset.take(pset.t1_s >= t_eff) if len(pset) else pset
        if len(pset):
            pairs = np.unique(conflicting_pairs(cset_, pset, config.separation)[:, :2], axis=0)
            if len(pairs):
                co = np.unique(np.stack((pairs[:, 0], owner[pairs[:, 1]]), axis=1), axis=0, return_counts=True)
                (cc, oo), cnt = co[0].T, co[1]
                full = cnt >= size[oo]
                np.add.at(n_block, cc[full], 1)
    k = min(range(n), key=lambda i: (int(n_fx[i]), int(n_block[i]), int(n_air[i]), int(n_gnd[i]),
                                     int(n_ch[i]), cands[i].trajectory.arrival_s, -cands[i].weight))
    got = sorted(hits[k], key=lambda j: (active[j].departure_s >= t_eff, j))
    return cands[k], holds[k], got, bool(n_fx[k])


#: sent back for a graph :func:`replan_steps` yielded: "solve it here", with ``select``'s own
#: solver (what :func:`replan` and the in-process runner do; the planner node sends the solver
#: service's answer instead)
SOLVE_HERE = object()


def run_steps(steps, answer_for: Callable):
    """Drive a generator that yields MWIS graphs (:func:`replan_steps`,
    ``Planner.prepare_steps``): each yielded graph gets ``answer_for(graph)`` sent back; returns
    the generator's return value."""
    try:
        graph = next(steps)
        while True:
            graph = steps.send(answer_for(graph))
    except StopIteration as done:
        return done.value


def replan(t_eff: float, epoch_index: int, active: Sequence, requests: dict, network, config,
           cache, cset: ConstraintSet, select: Callable, departures: Callable, policy: str = "mwis",
           affected: dict | None = None, labels: Sequence[str] = (),
           held: Sequence = ()) -> tuple[list, list, ReplanReport]:
    """Re-plan the flights of ``active`` that the constraints ``cset`` affect, at ``t_eff``:
    :func:`replan_steps` with every graph solved by ``select`` itself (see there)."""
    return run_steps(replan_steps(t_eff, epoch_index, active, requests, network, config, cache, cset,
                                  select, departures, policy, affected, labels, held),
                     lambda _graph: SOLVE_HERE)


class _Replan:
    """One batch re-plan of :func:`replan_steps`: the state its rounds build up, and its steps."""

    def __init__(self, t_eff: float, epoch_index: int, active: Sequence, requests: dict, network, config, cache,
                 cset: ConstraintSet, select: Callable, departures: Callable, policy: str, held: Sequence,
                 affected: dict, rep: ReplanReport):
        self.t_eff, self.epoch_index, self.active, self.requests = t_eff, epoch_index, active, requests
        self.network, self.config, self.cache, self.cset = network, config, cache, cset
        self.select, self.departures, self.policy, self.held, self.rep = select, departures, policy, held, rep
        idx = sorted(affected)
        self.router = _Router(network, cache, cset, t_eff)
        self.why = dict(affected)        # index in active -> (constraint index, entry time)
        self.pulled_by: dict = {}        # index -> request_id of the contingency it was pulled in for
        self.clean: dict = {}            # index -> its constraint-free alternatives, preference order
        self.fixed: dict = {}            # index -> _Alt flown as a FIXED flight (contingency or no way out)
        self.unavoidable: set = set()    # no constraint-free alternative at all: it flies its plan
        self.unresolved: dict = {}       # contingencies flown not deconflicted -> why
        self.hold_of: dict = {}          # index -> seconds held at the branch point by its contingency
        self.work = list(idx)            # flights being decided by the graph
        self.in_replan = set(idx)
        for i in idx:
            rep.affected_airborne += int(active[i].departure_s < t_eff)
            rep.affected_not_departed += int(active[i].departure_s >= t_eff)
        self.act_memo: dict = {}
        self.chosen: dict = {}           # index -> _Alt chosen by the graph
        self.held_opts: dict = {}        # index -> its contingency options in the graph (unsaved before)
        self.rounds = 0

    def held_now(self):
        """The held projections of flights not being re-planned (fixed for every decision)."""
        mine = {self.active[j].request_id for j in self.in_replan}
        return [tr for rid, tr in self.held if rid not in mine]

    def act_set(self, extra=()):
        """The flights every alternative keeps separation with (from t_eff on): not re-planned, fixed, held."""
        from .separation import SegmentSet
        # the same flights in the same order give the same set: built again only when the
        # flights re-planned or the fixed ones changed (the cascade's
        # rounds rebuilt it from ~1,200 trajectories each time)
        fixed, t_eff = self.fixed, self.t_eff
        key = (frozenset(self.in_replan), tuple((i, id(a)) for i, a in fixed.items())) if not extra else None
        got = self.act_memo.get(key) if key is not None else None
        if got is not None:
            return got[0]
        s_ = SegmentSet.from_trajectories(self.in_force(extra))
        s_ = s_.take(s_.t1_s >= t_eff) if len(s_) else s_
        if key is not None:
            self.act_memo.clear()
            self.act_memo[key] = (s_, list(fixed.values()))  # holds them: their ids stay theirs
        return s_

    def in_force(self, extra=()) -> list:
        """The trajectories of the flights every alternative avoids: not re-planned, fixed, held."""
        return [f.trajectory for j, f in enumerate(self.active) if j not in self.in_replan] + \
            [a.trajectory for a in self.fixed.values()] + self.held_now() + list(extra)

    def generate(self, todo, act):
        """Alternatives of the flights ``todo`` (stage 2 for those with too few survivors)."""
        from .conflict_graph import discard_against_active
        active, t_eff, network, config, router = self.active, self.t_eff, self.network, self.config, self.router
        groups = []
        for i in todo:
            f = active[i]
            airborne = f.departure_s < t_eff
            origin = None if airborne else network.node_index(f.origin_id)
            alts = _airborne_alternatives(f, t_eff, network, config, router) + \
                [x for x in (_turn_back(f, t_eff, network, config),) if x is not None] if airborne else \
                _ground_alternatives(f, self.requests.get(f.request_id), t_eff, network, self.cache,
                                     self.departures)
            groups += [([_keep_alt(f, network)], origin), (alts, origin)]
        # every flight's alternatives tested against the constraints in one call
        # (one call per flight and kind was ~15 % of the decision)
        free = _constraint_free_many(groups, self.cset, t_eff, network)
        lists = [free[2 * r] + free[2 * r + 1] for r in range(len(todo))]
        flat1 = [a.trajectory for alts in lists for a in alts]
        gone = discard_against_active(flat1, act, config.separation) if flat1 and len(act) \
            else np.zeros(len(flat1), dtype=bool)
        pos = 0
        for r, i in enumerate(todo):
            n = len(lists[r])
            left = n - int(gone[pos:pos + n].sum())
            pos += n
            f = active[i]
            if left < STAGE2_BELOW and f.departure_s < t_eff:
                lists[r] += _constraint_free(_airborne_alternatives(f, t_eff, network, config, router, stage=2),
                                             self.cset, t_eff, network, None)
                self.rep.stage2 += 1
            lists[r].sort(key=lambda a: -a.weight)  # stable: preference order within the flight
            self.clean[i] = lists[r]
            self.rep.alternatives += len(lists[r])

    def generate_new(self):
        """Alternatives of the flights new to the graph; an airborne one with none at all flies its plan, fixed."""
        todo = [i for i in self.work if i not in self.clean]
        if todo:
            self.generate(todo, self.act_set())
            # an airborne flight with no constraint-free alternative at all (already inside, or
            # entering before its branch point) flies its plan: fixed before the graph
            for i in todo:
                if not self.clean[i] and self.active[i].departure_s < self.t_eff:
                    self.fixed[i] = _keep_alt(self.active[i], self.network)
                    self.unavoidable.add(i)
            self.work = [i for i in self.work if i not in self.fixed]

    def round_graph(self):
        """This round's graph of the flights in ``work``, against the fixed traffic: (alternatives, rows, graph)."""
        from .conflict_graph import build_conflict_graph
        act = self.act_set()
        per_flight = [self.clean[i] + self.held_opts.get(i, []) for i in self.work]
        flat = [a for alts in per_flight for a in alts]
        req_of = np.repeat(np.arange(len(self.work)), [len(a) for a in per_flight]).astype(np.int64)
        cand_idx = np.concatenate([np.arange(len(a)) for a in per_flight]).astype(np.int64) \
            if flat else np.zeros(0, np.int64)
        graph = build_conflict_graph([a.trajectory for a in flat], req_of, cand_idx,
                                     np.array([a.weight for a in flat], dtype=np.float64), len(self.work),
                                     act, self.config.separation)
        # F3548 mode: the new versions' volumes too (in force: the flights the graph avoids)
        graph = graph_for_config(graph, [a.trajectory for a in flat], self.in_force(), self.config,
                                 self.t_eff - 1.0)
        return flat, req_of, graph

    def solve_steps(self, graph):
        """Generator: the vertices selected in ``graph`` (with "mwis" from the answer sent back), into the report."""
        rep = self.rep
        ts = time.perf_counter()
        if graph.n_vertices == 0:
            selected = np.zeros(0, dtype=np.int64)
        else:
            answer = (yield graph) if self.policy == "mwis" else SOLVE_HERE
            selected, er = self.select(graph, self.policy) if answer is SOLVE_HERE else \
                self.select(graph, self.policy, answer)
            rep.graphs_solved += 1
            rep.backend_used = er.backend_used
            if er.fallback:  # any round's fallback is reported
                rep.fallback, rep.fallback_reason = True, er.fallback_reason
        rep.solve_time_s += time.perf_counter() - ts
        return selected

    def rounds_steps(self):
        """Generator: the graph, then cascade rounds around unsaved airborne flights until none is left or the bound."""
        while True:
            self.generate_new()
            flat, req_of, graph = self.round_graph()
            if self.rounds == 0:
                self.rep.vertices, self.rep.edges = graph.n_vertices, graph.n_edges
            selected = yield from self.solve_steps(graph)
            self.chosen = {}
            for v in selected.tolist():
                src = int(graph.vertex_source[v])
                self.chosen[self.work[int(req_of[src])]] = flat[src]
            unsaved = [i for i in self.work if i not in self.chosen and self.active[i].departure_s < self.t_eff]
            if not unsaved or self.rounds >= CASCADE_ROUNDS:
                break
            self.rounds += 1
            fresh = [i for i in unsaved if i not in self.held_opts]
            if fresh:
                self.add_contingency_options(fresh)
                continue
            self.fix_contingencies(unsaved)
            self.work = [i for i in self.work if i not in self.fixed]
        self.rep.cascade_rounds, self.rep.pulled_in = self.rounds, len(self.pulled_by)

    def add_contingency_options(self, fresh):
        """The contingency options of the flights ``fresh`` join the next graph, to be decided jointly."""
        # first, the unsaved flights' contingency options join the graph (holds at the branch
        # point, then each alternative; weights below every diversion): decided jointly
        t_eff = self.t_eff
        for i in fresh:
            cands, _holds = _contingency_candidates(self.clean[i], self.active[i], t_eff, self.cset, self.network,
                                                    self.config)
            mine = {id(a) for a in self.clean[i]}
            self.held_opts[i] = [replace(c, kind="contingency", weight=_contingency_weight(c, t_eff))
                                 for c in cands if id(c) not in mine]

    def fix_contingencies(self, unsaved):
        """Each of ``unsaved`` flies a FIXED contingency; the flights it would meet are re-planned around it."""
        # each unsaved airborne flight becomes a contingency, deconflicted as a FIXED flight
        # (airborne flights outrank flights not departed); the flights it would lose separation
        # with are re-planned around it: chosen ones in the next graph, unaffected ones pulled in
        active, clean, fixed, chosen = self.active, self.clean, self.fixed, self.chosen
        options = {i: _contingency_candidates(clean[i], active[i], self.t_eff, self.cset, self.network, self.config)
                   for i in unsaved}
        for n_i, i in enumerate(unsaved):
            # the others still to be decided: the round's later contingencies (every option, holds
            # too) and the flights the graph saved (their alternatives: the next graph's choice)
            pending = [options[u] for u in unsaved[n_i + 1:]] + \
                [(clean[u], None) for u in self.work if u in chosen and u not in fixed]
            a, hold, hits, clash = _contingency_choice(options[i], active, self.in_replan, fixed, chosen,
                                                       self.config, self.t_eff, pending, self.held_now())
            fixed[i], self.hold_of[i] = a, hold
            if clash:  # it cannot avoid another fixed flight: flown, the loss reported
                self.unresolved[i] = "it cannot avoid another contingency (or a flight held past its plan)"
            chosen.pop(i, None)
            for j in hits:
                if len(self.pulled_by) >= CASCADE_MAX_PULLED:
                    self.unresolved.setdefault(i, f"the cascade's bound of {CASCADE_MAX_PULLED} flights pulled in")
                    break
                self.pulled_by[j] = active[i].request_id
                self.why[j] = self.why[i]
                self.in_replan.add(j)
                self.work.append(j)

    def past_bound(self):
        """The airborne flights unsaved after the last round fly their least-conflicting option; the counts."""
        # past the bound: the last unsaved airborne flights fly their least-conflicting alternative,
        # NOT deconflicted (reported: ReplanReport.unresolved, the reason, the audit of what flew)
        active, t_eff = self.active, self.t_eff
        for i in [i for i in self.work if i not in self.chosen and active[i].departure_s < t_eff]:
            options_i = _contingency_candidates(self.clean[i], active[i], t_eff, self.cset, self.network, self.config)
            a, hold, _hits, _clash = _contingency_choice(options_i, active, self.in_replan, self.fixed, self.chosen,
                                                         self.config, t_eff, held=self.held_now())
            self.fixed[i], self.hold_of[i] = a, hold
            self.unresolved[i] = f"the cascade's bound of {CASCADE_ROUNDS} rounds"
        rep = self.rep
        rep.unavoidable, rep.unresolved = len(self.unavoidable), len(self.unresolved)
        rep.contingencies_fixed = len(self.fixed) - len(self.unavoidable) - len(self.unresolved) + \
            sum(1 for a in self.chosen.values() if a.kind == "contingency")

    def contingency_what(self, i: int, a: _Alt) -> str:
        """What flight ``i`` flying the contingency ``a`` does, and whether it is deconflicted (for its reason)."""
        land = self.network.node_ids[a.destination]
        hold_note = f" after holding {self.hold_of[i]:g} s at its branch point" if self.hold_of.get(i) else ""
        if i in self.unavoidable:
            return "no route avoids it: it flies its current plan (an incursion that cannot be avoided)"
        if i not in self.fixed:
            return (f"no alternative that stays out keeps separation with the others; contingency "
                    f"landing at {land!r}{hold_note}, deconflicted with every other flight (chosen in "
                    f"the graph)")
        if i in self.unresolved:
            return (f"each of its {len(self.clean[i])} alternatives that stay out loses separation with "
                    f"another flight; contingency landing at {land!r}{hold_note}, flown but not "
                    f"deconflicted ({self.unresolved[i]})")
        return (f"no alternative that stays out keeps separation with the others; contingency "
                f"landing at {land!r}{hold_note}, deconflicted with every other flight (fixed: the "
                f"flights it would meet are re-planned around it)")

    def update_of(self, i: int):
        """(PlanUpdate, new version or None when cancelled) of the re-planned flight ``i``, with its reason."""
        f, t_eff, network = self.active[i], self.t_eff, self.network
        k_c, when = self.why[i]
        c = self.cset.constraints[k_c]
        cids = (c.constraint_id,)
        a = self.fixed.get(i, self.chosen.get(i))
        contingent = i in self.fixed or (a is not None and a.kind == "contingency")
        if a is not None and a.kind == "contingency":
            self.hold_of[i] = a.hold_s
        by = self.pulled_by.get(i)
        cause = (f"its plan enters constraint {c.label()} at t = {when:g} s" if by is None else
                 f"its plan loses separation with contingency flight {by!r} (constraint {c.label()})")
        if a is None:
            reason = (f"cancelled: {cause} and no route, level or departure in its window avoids it "
                      f"and keeps separation")
            return PlanUpdate(f.request_id, f.operator_id, f.version + 1, "cancelled", cids,
                              reason, float(t_eff), None, f), None
        if contingent:
            kind = "contingency"
            reason = f"contingency: {cause}; {self.contingency_what(i, a)}"
        else:
            kind = a.kind
            reason = (f"{kind}: {cause}".replace("enters", "entered", 1) if kind != "kept"
                      else f"kept: its plan stays out of constraint {c.label()}")
            if kind == "diverted":
                reason += f"; diverted to {network.node_ids[a.destination]!r}"
        nf = replace(f, destination_id=network.node_ids[a.destination], route_node_ids=a.route_node_ids,
                     trajectory=a.trajectory, departure_s=a.trajectory.departure_s,
                     arrival_s=a.trajectory.arrival_s, length_m=a.length_m, weight=a.weight,
                     candidate_index=a.candidate_index, method=f"replan-{self.policy}",
                     backend=self.rep.backend_used or self.policy, epoch_index=int(self.epoch_index),
                     route_index=a.route_index, version=f.version + 1, effective_s=float(t_eff),
                     contingent=contingent)
        return PlanUpdate(f.request_id, f.operator_id, nf.version, kind, cids, reason,
                          float(t_eff), nf, f, nf.arrival_s - f.arrival_s), nf


def replan_steps(t_eff: float, epoch_index: int, active: Sequence, requests: dict, network, config,
                 cache, cset: ConstraintSet, select: Callable, departures: Callable, policy: str = "mwis",
                 affected: dict | None = None, labels: Sequence[str] = (), held: Sequence = ()):
    """Re-plan the flights of ``active`` that the constraints ``cset`` affect, at ``t_eff``.

    A generator: with policy "mwis" it yields each round's ConflictGraph (the first graph and
    each cascade round's) and takes back the solver's answer for it (``send``: an answer with
    ``selected``, a reason string or an exception, as ``planning.checked_selection`` takes them;
    or :data:`SOLVE_HERE`), so the planner node awaits the solver service for the re-plan as it
    does for an epoch (docs/replanning.md); first-fit yields nothing. The decisions do not
    depend on who solved: the answer is checked (greedy if invalid) and the rounds follow it.

    Args:
        t_eff: the epoch time the update takes effect [s].
        epoch_index: the epoch, copied to the new versions.
        active: the planner's active flights (newest versions; landed ones already dropped).
        requests: request_id -> FlightRequest of the active flights (their windows; a flight
            missing here keeps only its own departure time as a re-time option).
        network, config, cache: the planner's Network, PlanningConfig and CandidateCache.
        cset: the ConstraintSet after the update.
        select: callable(graph, policy[, answer]) -> (selected vertex indices, an object with
            ``backend_used``, ``fallback``, ``fallback_reason``): the checked MWIS or first-fit
            answer, solved by its own solver or from ``answer`` when given (the Planner's:
            ``uam_planner.planning.replan_selector``).
        departures: callable(t_s, request) -> departure times a request may take at an epoch at
            t_s (the Planner's ``departure_slots_s`` with its config).
        policy: "mwis" or "firstfit".
        affected: optional {index in active: (constraint index, entry time)} (default:
            :func:`affected_flights`).
        labels: the updates' labels, for the report.
        held: ``(request_id, Trajectory)`` of the flights the planner holds past their plans
            (``uam_planner.nonconformance.overruns``: each a projection of where a
            late flight may still be): every alternative and every contingency is deconflicted
            against them as against fixed flights (they are in the air: nothing re-plans them
            here). A flight's own projections are left out while that flight is re-planned.
    Returns (as the generator's return value): (new active list: unaffected flights in their
        order, then the new versions; PlanUpdate per affected flight in ``active`` order;
        ReplanReport).
    """
    t0, c0 = time.perf_counter(), time.process_time()
    rep = ReplanReport(t_s=float(t_eff), policy=policy, updates=list(labels))
    if affected is None:
        affected = affected_flights(active, cset, t_eff, network)
    idx = sorted(affected)
    rep.affected = len(idx)
    if not idx:
        rep.decision_time_s = time.perf_counter() - t0
        rep.decision_cpu_s = time.process_time() - c0
        return list(active), [], rep
    rp = _Replan(t_eff, epoch_index, active, requests, network, config, cache, cset, select, departures,
                 policy, held, affected, rep)
    yield from rp.rounds_steps()
    rp.past_bound()
    updates, new_versions = [], []
    for i in [i for i in range(len(active)) if i in rp.in_replan]:
        up, nf = rp.update_of(i)
        updates.append(up)
        if nf is not None:
            new_versions.append(nf)
    for u in updates:
        rep.kinds[u.kind] = rep.kinds.get(u.kind, 0) + 1
    rep.decision_time_s = time.perf_counter() - t0
    rep.decision_cpu_s = time.process_time() - c0
    kept_order = [f for j, f in enumerate(active) if j not in rp.in_replan]
    return kept_order + new_versions, updates, rep
