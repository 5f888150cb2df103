"""The reaction to a nonconforming flight (docs/disturbances.md), free of ROS.

Whether a flight conforms, and what the planner itself observes of it, is
:mod:`uam_planner.conformance` (its names are re-exported here).

**A report is a claim, not a fact.** The planner learns of a nonconforming flight from outside
(the ``conformance_monitor`` node's ``/uam/conformance``; in process the runner's monitor), but
it acts only on what it knows itself:

- the flight must be one of its active flights, or held past its plan (:func:`overruns`: a
  late flight still in the air after its planned arrival), seen after its departure;
- the position used is the planner's own latest observation of the vehicle (the fleet state,
  :class:`PositionBook`), never a number from the report; it must be at most ``MAX_AGE_S`` old;
- the planner recomputes the errors of that position against its own newest plan version: if
  they are within the bounds the report is refused (nothing changes);
- the observed speed is the planner's own estimate (:meth:`PositionBook.progress_rate`).

What a report can cause is therefore at worst one re-plan of a flight that the planner itself sees
outside its plan, and that re-plan is deconflicted like any other: a flight is never removed from
the planner's traffic picture by a report (there is no cancellation here; a flight for which no
deconflicted alternative exists keeps flying its updated intent as a *contingency*, still
active, so later requests are deconflicted against it).

**The update** (at the epoch after the report, ``Planner.prepare`` step 2, right after the
constraint re-plan; t_eff = the epoch time): the flight's intent is re-drawn *from where it is*
at its *observed progress rate* f (planned seconds flown per second, so 0.9 = 10 % slow):
from the observed position q at the observation time t0, straight to the first waypoint of its
plan beyond the point of the path nearest to q, then the plan's remaining waypoints, every leg
timed at f times the plan's speed (:func:`rejoin_trajectory`). Alternatives: that rejoin at
``f``, and at ``SHARES`` x f (the aircraft asked to fly slower, which delays it, or 10 % faster,
either of which can clear a neighbour). One conflict graph over every nonconforming flight's alternatives (one clique per
flight), each alternative deconflicted exactly against every other active flight (the run's
separation model, from t_eff on), solved by the planner's selector (the same as the
batch re-planning of ``uam_planner.replanning``: MWIS with the answer checked and greedy as fallback, or first-fit). Weights
2 + 1 / (1 + delay / 300 s), delay = arrival - the arrival of the rejoin at f (the tier of a
re-route in ``uam_planner.replanning``; a faster one weighs as the rejoin at f). The chosen one
becomes version + 1 (``PlanUpdate`` of kind ``nonconforming``, ``effective_s`` = t_eff); with none
chosen the alternative that loses separation with the fewest flights (then lands soonest) is
taken as a ``contingency`` (``Flight.contingent``, F3548 Contingent). The F3548 state at the decision is
Nonconforming (``FlightPlan.STATE_NONCONFORMING`` on the wire): the flight was outside its intent
from the report until its new version took effect, and conforms to the new one.

The new version's trajectory starts at the observation (t0, q): it does not chain with the old
plan (the aircraft is not where the old plan is; that is why it is updated). What flew before
t_eff is what flew; the simulator flies the new version from the aircraft's state.
"""

from __future__ import annotations

from dataclasses import dataclass, replace
from typing import Callable, Sequence

import numpy as np

from .conformance import (  # noqa: F401
    _DEFAULTS,
    _EPS_T,
    MATCH_M,
    MATCH_S,
    MAX_AGE_S,
    MAX_OBSERVATIONS,
    MIN_SPEED_SPAN_S,
    RATE_FULL_SPAN_S,
    RATE_RANGE,
    SPEED_WINDOW_S,
    Claim,
    ConformanceBounds,
    Observation,
    PositionBook,
    conforming,
    deviations,
    nearest,
    verify,
)
from .intent_volumes import graph_for_config
from .replanning import PlanUpdate
from .trajectory import Trajectory

#: the update kinds of this module (``PlanUpdate.kind``; ``FlightPlan.update_kind``)
KIND = "nonconforming"
KIND_CONTINGENCY = "contingency"
#: a conforming flight re-timed so that a nonconforming one keeps separation (:func:`_yield_steps`)
KIND_YIELD = "yielded"
STATE = "Nonconforming"
#: the other alternatives, as shares of the observed rate: slower (a delay), and 10 % faster (the
#: speed margin an aircraft keeps; 4D guidance asks for as much)
SHARES = (0.9, 1.1, 0.8, 0.7)
DELAY_SCALE_S = 300.0


# ---- the conflict probe ------------------------------------------------------------------------
#
# Conformance alone misses what a speed error does to two flights that both conform: each may be
# up to the time bound (10 s, 100 m at 10 m/s) off its schedule, so two plans separated by the
# minimum can meet (BENCHMARKS.md: most flown losses at 10 % speed error were between two
# conforming flights). The probe looks ahead from the planner's own observations: every airborne
# flight's rest of plan flown from where it was last seen at its observed progress rate (the
# same projection a nonconforming update starts from, :func:`rejoin_trajectory`), cut at
# ``lookahead_s``; a pair of projections closer than the true minimum (exact, continuous time)
# is a predicted loss of separation, and both flights are updated from where they are exactly
# as nonconforming ones are, in the same batch (deconflicted against each other and every other
# flight; a flight the batch cannot save keeps its plan: it conforms, it is not a contingency).
# What it rests on is the planner's own fleet state, never a report.

def projections(active: Sequence, book: PositionBook, t_s: float, lookahead_s: float,
                exclude=()) -> list:
    """(index in ``active``, its newest observation, its projection) of every flight of
    ``active`` airborne on its plan at ``t_s`` with an observation at most ``MAX_AGE_S`` old (not
    in ``exclude``): the rest of its plan flown from that sighting at its observed progress rate
    (:func:`rejoin_trajectory`), from ``t_s`` to ``t_s + lookahead_s``."""
    from .replanning import clipped_until

    out = []
    skip = set(exclude)
    for i, f in enumerate(active):
        tr = f.trajectory
        if i in skip or not tr.departure_s < t_s < f.arrival_s:
            continue
        obs = book.latest(f.request_id, until=t_s)
        if obs is None or obs.t_s < t_s - MAX_AGE_S or not tr.departure_s < obs.t_s < f.arrival_s:
            continue
        rate = book.progress_rate(f.request_id, tr, until=t_s)
        pred = rejoin_trajectory(tr, obs.t_s, obs.position_m, rate)
        # from now (a sighting may be a step old: what it predicts before now is past) on
        pred = _clipped(pred, t_s) if pred is not None else None
        pred = clipped_until(pred, t_s + lookahead_s) if pred is not None else None
        if pred is None or pred.times_s.shape[0] < 2:
            continue
        out.append((i, obs, pred))
    return out


def predicted_conflicts(active: Sequence, book: PositionBook, t_s: float, lookahead_s: float,
                        separation, exclude=()) -> dict:
    """The flights of ``active`` predicted to lose ``separation`` (the true minimum) within
    ``lookahead_s`` of ``t_s`` when each flies the rest of its plan from its newest observation
    (at most ``MAX_AGE_S`` old) at its observed progress rate. Returns index in ``active`` ->
    (observation, the request ids it is predicted to meet). Flights due to depart within the
    look-ahead fly their plan in the projection: an airborne flight predicted to meet one is
    probed (they are not: nothing seen to update them from). Flights without a recent
    observation, otherwise not airborne on their plan at ``t_s``, or in ``exclude`` (indices)
    are not probed. O(F log F) broad phase (``separation.conflicting_pairs``)."""
    from .replanning import clipped_until
    from .separation import conflicting_pairs

    idx, obs_of, preds = [], {}, []
    skip = set(exclude)
    airborne = {i: (obs, pred) for i, obs, pred in projections(active, book, t_s, lookahead_s, skip)}
    for i, f in enumerate(active):
        tr = f.trajectory
        if i in skip:
            continue
        if i in airborne:
            obs_of[i], pred = airborne[i]
            idx.append(i)
            preds.append(pred)
            continue
        if t_s <= tr.departure_s < t_s + lookahead_s:
            # due to depart within the look-ahead: not seen yet, so flown as planned (thirteenth
            # stop: two flown losses at 25 m were a departure or an arrival the probe saw only
            # 0.3 s and 13.5 s ahead, once the flight was airborne). It is never updated itself
            # (nothing observed to update it from); an airborne flight whose projection meets
            # its plan is, against that plan.
            pred = clipped_until(tr, t_s + lookahead_s)
            if pred is not None and pred.times_s.shape[0] >= 2:
                idx.append(i)
                preds.append(pred)
    out: dict = {}
    if len(preds) < 2:
        return out
    for a, b in np.asarray(conflicting_pairs(preds, separation_m=separation)).reshape(-1, 2).tolist():
        ia, ib = idx[a], idx[b]
        if ia in obs_of:
            out.setdefault(ia, (obs_of[ia], []))[1].append(active[ib].request_id)
        if ib in obs_of:
            out.setdefault(ib, (obs_of[ib], []))[1].append(active[ia].request_id)
    return out


# ---- the update -------------------------------------------------------------------------------

def rejoin_trajectory(plan: Trajectory, t0_s: float, q, rate: float,
                      first_pass: bool = False) -> Trajectory | None:
    """From ``q`` at ``t0_s`` straight to the first waypoint of ``plan`` beyond the point of
    its path nearest to ``q``, then the plan's remaining waypoints; every leg at ``rate`` times
    the plan's speed (the first at the speed of the segment it rejoins). None if nothing is
    left (it is at the plan's end). Where the path comes back over itself, the pass nearest in
    planned time to ``t0_s`` (:func:`nearest`), or with ``first_pass`` the first one (the most
    of the plan left: the held projection of a late flight, never a shorter hold)."""
    q = np.asarray(q, dtype=np.float64).reshape(3)
    j, lam, _p, _tau = nearest(plan, q[None], None if first_pass else [t0_s])
    j = int(j[0])
    nxt = j + 1
    pts = plan.points_m
    ts = plan.times_s
    seg_len = float(np.linalg.norm(pts[j + 1] - pts[j]))
    v_seg = seg_len / float(ts[j + 1] - ts[j]) if seg_len > 0 else 1.0
    first = float(np.linalg.norm(pts[nxt] - q))
    times = [float(t0_s)]
    points = [q]
    if first > 1e-6:
        times.append(times[-1] + first / (rate * v_seg))
        points.append(pts[nxt])
    for k in range(nxt + 1, pts.shape[0]):
        times.append(times[-1] + float(ts[k] - ts[k - 1]) / rate)
        points.append(pts[k])
    if len(times) < 2:
        return None
    return Trajectory(np.array(times), np.array(points))


#: the reason of a nonconforming update names the observed progress rate after these words (for
#: a reader; the simulator reads ``ReactionUpdate.observed_rate``, on the wire
#: ``FlightPlan.observed_progress_rate``)
RATE_WORD = "observed progress rate"
#: the weight of a probed flight's keep-its-plan alternative: below every update's (2-3)
KEEP_WEIGHT = 1.0


@dataclass(frozen=True, eq=False)
class ReactionUpdate(PlanUpdate):
    """A ``replanning.PlanUpdate`` of the reaction, with the observed progress rate it was
    re-timed from (``observed_rate``; on the wire ``FlightPlan.observed_progress_rate``, which
    the simulator flies it on at)."""

    observed_rate: float = 0.0


def _clipped(tr: Trajectory, t_s: float) -> Trajectory | None:
    from .replanning import clipped_from
    return clipped_from(tr, t_s)


def _least_conflicting(alts: list, others: list, config, t_eff: float, true_first: bool = False):
    """Of (trajectory, weight) alternatives, the one that loses separation (from t_eff on) with
    the fewest of ``others``, then the one that lands soonest. With ``true_first`` (a
    contingency's choice) the fewest losses of the true minimum
    (``config.minimum_separation``) come first, then of the buffered separation: with a buffer,
    an alternative that only cuts into the buffer of one flight had ranked below one that keeps
    the buffer from none of two others but crosses a third at a few metres."""
    trs = [a[0] for a in alts]
    n_conf = _conflict_counts(trs, others, config.separation, t_eff)
    n_true = _conflict_counts(trs, others, config.minimum_separation, t_eff) \
        if true_first and config.minimum_separation != config.separation else np.zeros_like(n_conf)
    k = min(range(len(alts)), key=lambda i: (int(n_true[i]), int(n_conf[i]), alts[i][0].arrival_s))
    return alts[k]


def _segment_sets(trajectories: list, others: list, t_eff: float):
    """(``trajectories`` from ``t_eff`` on, the segments of ``others`` still flown at
    ``t_eff``) as SegmentSets for ``conflicting_pairs``, or None when either is empty."""
    from .separation import SegmentSet

    oset = SegmentSet.from_trajectories(others) if others else None
    if oset is not None and len(oset):
        oset = oset.take(oset.t1_s >= t_eff)
    if oset is None or not len(oset) or not trajectories:
        return None
    return SegmentSet.from_trajectories([_clipped(tr, t_eff) or tr for tr in trajectories]), oset


def _conflict_counts(trajectories: list, others: list, separation, t_eff: float) -> np.ndarray:
    """For each of ``trajectories`` (from ``t_eff`` on), how many of ``others`` it loses
    ``separation`` with (exact, continuous time)."""
    from .separation import conflicting_pairs

    n_conf = np.zeros(len(trajectories), dtype=np.int64)
    sets = _segment_sets(trajectories, others, t_eff)
    if sets is None:
        return n_conf
    pairs = conflicting_pairs(*sets, separation)
    for i in np.unique(pairs[:, 0]).tolist():
        n_conf[i] = np.unique(pairs[pairs[:, 0] == i, 1]).size
    return n_conf


#: **Neighbours yield** ("re-deconflicted against its
#: neighbours"): a nonconforming flight none of whose own alternatives is conflict-free would be
#: flown as a contingency, not deconflicted (in the Monte-Carlo at 10 % speed error and a 50 m
#: buffer, 8 of the 9 flown losses of 11 runs had one). Before that, the flights its
#: least-conflicting alternative loses separation with may yield: an airborne one flies the
#: rest of its plan at YIELD_SHARES of its planned speed (re-timed from where its plan is at
#: the update; the aircraft, which conforms, follows it), one not yet departed waits
#: YIELD_DELAYS_S at its origin; each keeps its plan unless moving it saves the flight.
YIELD_SHARES = (0.9, 1.1, 0.8)
YIELD_DELAYS_S = (30.0, 60.0, 120.0)
#: weights of the yield graph: a neighbour's own plan, a neighbour moved (2 + 1 / (1 + delay /
#: 300 s): always below its plan), a saved flight's alternative (YIELD_SAVE + its weight: saving
#: one outweighs moving all of its neighbours)
YIELD_KEEP = 3.0
YIELD_SAVE = 1000.0
#: rounds of the yield graph: a neighbour left without a vertex keeps its plan, which is then
#: fixed for the next round; after the last round with one still left the stage changes nothing
YIELD_ROUNDS = 3


def _constraint_free(alts: list, f, config, network, t_eff: float, airborne: bool) -> list:
    """The (trajectory, weight, ...) alternatives of flight ``f`` that enter no constraint in
    force (``config.constraints``) from ``t_eff`` on; ``airborne``: its origin is behind it."""
    cset = config.constraints
    if not alts or cset is None or not len(cset):
        return alts
    from .replanning import pad_of_point
    d = network.node_index(f.destination_id)
    o = -1 if airborne else network.node_index(f.origin_id)
    trs = [_clipped(a[0], t_eff) or a[0] for a in alts]
    which, _ = cset.violations(trs, np.full(len(alts), o, dtype=np.int64),
                               np.full(len(alts), d, dtype=np.int64), np.zeros(len(alts), dtype=np.int64),
                               np.array([pad_of_point(network, d, a[0].points_m[-1]) for a in alts]))
    return [a for a, w in zip(alts, which.tolist()) if w < 0]


def _neighbour_alternatives(f, t_eff: float, config, network) -> list:
    """(trajectory, weight, how) ways for flight ``f`` to yield at ``t_eff``: its plan first."""
    tr0 = f.trajectory
    out = [(tr0, YIELD_KEEP, "")]
    if tr0.departure_s > t_eff:                      # not departed: wait at the origin
        for d in YIELD_DELAYS_S:
            out.append((Trajectory(tr0.times_s + d, tr0.points_m.copy()),
                        2.0 + 1.0 / (1.0 + d / DELAY_SCALE_S), f"departure {d:+g} s"))
        airborne = False
    else:                                            # in the air: the rest of its plan re-timed
        from .replanning import spliced
        q = tr0.position_at(t_eff)
        for share in YIELD_SHARES:
            rest = rejoin_trajectory(tr0, t_eff, q, share)
            if rest is None or rest.arrival_s <= t_eff:
                continue
            tr = spliced(tr0, rest, t_eff)           # its plan up to t_eff, then the rest re-timed
            # (so the version keeps its departure, as a constraint re-plan's does)
            delay = max(0.0, tr.arrival_s - tr0.arrival_s)
            out.append((tr, 2.0 + 1.0 / (1.0 + delay / DELAY_SCALE_S), f"speed x{share:g} from t = {t_eff:g} s"))
        airborne = True
    return out[:1] + _constraint_free(out[1:], f, config, network, t_eff, airborne)


def _selection_steps(graph, select: Callable, policy: str):
    """Generator: ``select``'s (selected, report) for ``graph``; with "mwis" from the answer sent back for it."""
    from .replanning import SOLVE_HERE
    answer = (yield graph) if policy == "mwis" else SOLVE_HERE
    return select(graph, policy) if answer is SOLVE_HERE else select(graph, policy, answer)


def _segments_from(trs: list, t_eff: float):
    """``trs`` from ``t_eff`` on as one SegmentSet: what flew before ``t_eff`` is past, it cannot meet anything."""
    from .separation import SegmentSet
    s_ = SegmentSet.from_trajectories([_clipped(t, t_eff) or t for t in trs])
    return s_.take(s_.t1_s >= t_eff) if len(s_) else s_


def _meets(trs: list, obstacles: list, t_eff: float, separation) -> bool:
    """Whether any of ``trs`` loses ``separation`` with any of ``obstacles`` from ``t_eff`` on (a refused yield)."""
    from .separation import conflicting_pairs
    if not trs or not obstacles:
        return False
    return bool(len(conflicting_pairs(_segments_from(trs, t_eff), _segments_from(obstacles, t_eff), separation)))


def _yield_neighbours(unsaved: dict, cand_of: dict, config, t_eff: float) -> set:
    """The flights of ``cand_of`` that an unsaved flight's least-conflicting alternative meets: those that may yield."""
    from .separation import conflicting_pairs
    keys = sorted(cand_of)
    oset = _segments_from([cand_of[j].trajectory for j in keys], t_eff)
    neighbours = set()
    for alts in unsaved.values():
        a = _least_conflicting(alts, [cand_of[j].trajectory for j in keys], config, t_eff)
        pairs = conflicting_pairs(_segments_from([a[0]], t_eff), oset, config.separation)
        neighbours.update(keys[k] for k in np.unique(pairs[:, 1]).tolist())
    return neighbours


def _yield_graph(unsaved: dict, moves: dict, cand_of: dict, others: list, held: list, chosen_trs: list,
                 config, t_eff: float):
    """One round's graph of the yield stage: (its vertices' (owner, trajectory, weight, move), owners, the graph)."""
    from .conflict_graph import build_conflict_graph
    rs, js = sorted(unsaved), sorted(moves)
    moving_ids = {cand_of[j].request_id for j in js}
    flat = [(("r", r), a[0], YIELD_SAVE + a[1], None) for r in rs for a in unsaved[r]] + \
        [(("n", j), a[0], a[1], a) for j in js for a in moves[j]]
    owners = [o for o, *_ in flat]
    req = {o: i for i, o in enumerate(dict.fromkeys(owners))}
    req_of = np.array([req[o] for o in owners], dtype=np.int64)
    cand = np.zeros(len(flat), dtype=np.int64)
    for i in range(1, len(flat)):
        cand[i] = cand[i - 1] + 1 if owners[i] == owners[i - 1] else 0
    fixed = [f.trajectory for j, f in others if j not in moves] + \
        [tr for rid, tr in held if rid not in moving_ids] + list(chosen_trs)
    act = _segments_from(fixed, t_eff) if fixed else ()
    trs = [_clipped(x[1], t_eff) or x[1] for x in flat]
    graph = build_conflict_graph(trs, req_of, cand, np.array([x[2] for x in flat], dtype=np.float64), len(req),
                                 act, config.separation)
    graph = graph_for_config(graph, trs, fixed, config, t_eff - 1.0)   # F3548 mode: volumes too
    return flat, owners, graph


def _yield_steps(t_eff: float, unsaved: dict, others: list, held: list, chosen_trs: list, config,
                 select: Callable, policy: str, network, report: dict):
    """The yield stage (see YIELD_SHARES): ``unsaved`` {r: its alternatives}, ``others``
    [(index in active, Flight)] the flights not being updated, ``held`` [(request id,
    Trajectory)] the projections of the flights held past their plans, ``chosen_trs`` the
    updates already chosen. A generator like :func:`react_steps` (one graph a round). Returns
    ({r: chosen alternative}, {index in active: (trajectory, weight, how)} of the neighbours
    that move); both empty when it saves nothing. A neighbour's own projections do not block
    its own alternatives, but they stay where they are while it keeps its plan: a choice that
    meets them is refused and that neighbour fixed for the next round."""
    cand_of = {j: f for j, f in others if not f.contingent and f.trajectory.arrival_s > t_eff}
    if not cand_of:
        return {}, {}
    neighbours = _yield_neighbours(unsaved, cand_of, config, t_eff)
    if not neighbours:
        return {}, {}
    moves = {j: _neighbour_alternatives(cand_of[j], t_eff, config, network) for j in sorted(neighbours)}
    proj = {}
    for rid, tr in held:
        proj.setdefault(rid, []).append(tr)
    for _round in range(YIELD_ROUNDS):
        rs, js = sorted(unsaved), sorted(moves)
        flat, owners, graph = _yield_graph(unsaved, moves, cand_of, others, held, chosen_trs, config, t_eff)
        report["yield_vertices"] = report.get("yield_vertices", 0) + graph.n_vertices
        if not graph.n_vertices:
            return {}, {}
        selected, _er = yield from _selection_steps(graph, select, policy)
        got = {}
        for v in np.asarray(selected).tolist():
            src = int(graph.vertex_source[v])
            got[owners[src]] = flat[src]
        # a neighbour without a vertex keeps its plan; one that keeps it keeps its projections:
        # a choice that meets them is refused, that neighbour fixed for the next round
        left = [j for j in js if ("n", j) not in got]
        chosen_now = [x[1] for o, x in got.items() if o[0] == "r" or x[3][2]]
        left += [j for j in js if ("n", j) in got and not got[("n", j)][3][2]
                 and _meets(chosen_now, proj.get(cand_of[j].request_id, []), t_eff, config.separation)]
        if not left:
            saved = {r: next(a for a in unsaved[r] if a[0] is got[("r", r)][1])
                     for r in rs if ("r", r) in got}
            if not saved:
                return {}, {}
            return saved, {j: got[("n", j)][3] for j in js if got[("n", j)][3][2]}
        for j in sorted(set(left)):
            del moves[j]
        if not moves:
            return {}, {}
    return {}, {}


def _delay_weight(tr: Trajectory, base_arrival_s: float) -> float:
    """An update's weight: 2 + 1 / (1 + its delay past the earliest update's / DELAY_SCALE_S)."""
    return 2.0 + 1.0 / (1.0 + max(0.0, tr.arrival_s - base_arrival_s) / DELAY_SCALE_S)


def _observed_updates(idx: list, active: Sequence, found: dict, book: PositionBook, t_eff: float,
                      report: dict) -> tuple[list, list]:
    """For each flight ``active[i]``, i in ``idx``: its observed progress rate (also into
    ``report["rates"]``) and :func:`_rejoin_alternatives` from its sighting in ``found``."""
    rates, rejoins = [], []
    for i in idx:
        f = active[i]
        rate = book.progress_rate(f.request_id, f.trajectory, until=t_eff)
        rates.append(rate)
        report["rates"][f.request_id] = rate
        rejoins.append(_rejoin_alternatives(f, found[i][0], rate, t_eff))
    return rates, rejoins


def _rejoin_alternatives(f, obs, rate: float, t_eff: float) -> tuple[list, float | None, Trajectory | None]:
    """The updates of ``f`` from its sighting ``obs``: its plan re-joined at the observed rate
    x (1, SHARES), those still flying after ``t_eff``, with their weights; the first one's
    arrival (None when none is left); and the re-join at the observed rate itself (its
    projection, also when it lands before ``t_eff``; None when there is none)."""
    alts, base, own = [], None, None
    for share in (1.0,) + tuple(SHARES):
        tr = rejoin_trajectory(f.trajectory, obs.t_s, obs.position_m, rate * share)
        if share == 1.0:
            own = tr
        if tr is None or tr.arrival_s <= t_eff:
            continue
        if base is None:
            base = tr.arrival_s
        alts.append((tr, _delay_weight(tr, base)))
    return alts, base, own


def _probe_reason(ids, obs, lat: float, terr: float, rate: float) -> str:
    """Why the conflict probe updates a flight (the text of its ReactionUpdate)."""
    return (f"predicted to lose separation with {', '.join(ids)} at the observed speeds (conflict "
            f"probe, seen at t = {obs.t_s:g} s: lateral {lat:.1f} m, time {terr:+.1f} s); intent "
            f"updated from where it is, {RATE_WORD} {rate:.12g}")


def _reaction_update(f, alt, kind: str, reason: str, policy: str, backend: str, epoch_index: int,
                     t_eff: float, rate: float, contingent: bool, **changes):
    """The new version of ``f`` flying ``alt`` (trajectory, weight) from ``t_eff`` (with
    ``changes`` to its other fields: a diversion's destination and route), and its
    ReactionUpdate."""
    tr = alt[0]
    nf = replace(f, trajectory=tr, arrival_s=float(tr.arrival_s), weight=float(alt[1]),
                 method=f"nonconforming-{policy}", backend=backend, epoch_index=int(epoch_index),
                 version=f.version + 1, effective_s=float(t_eff), contingent=contingent, **changes)
    return nf, ReactionUpdate(f.request_id, f.operator_id, nf.version, kind, (), reason,
                              float(t_eff), nf, f, nf.arrival_s - f.arrival_s, float(rate))


def _divert_alternatives(f, obs, rate: float, t_eff: float, network, config, router) -> list:
    """Re-routes of ``f`` to its destination and diversions to the nearest vertiports
    (``replanning._airborne_alternatives``: stage 1, from the next waypoint) flown from its
    sighting ``obs``: straight to its plan's next waypoint, then the new route, every leg at
    ``rate`` times the planned speeds (as the re-joins: the aircraft keeps its airspeed). Each a
    ``replanning._Alt`` whose route is the flight's whole route (the part flown, then the new
    one), best first (re-routes by added delay, then diversions by time to land)."""
    from .replanning import _airborne_alternatives

    plan = f.trajectory
    q = np.asarray(obs.position_m, dtype=np.float64).reshape(3)
    j, _lam, _p, _tau = nearest(plan, q[None], [float(obs.t_s)])
    nxt = int(j[0]) + 1
    own = rejoin_trajectory(plan, float(obs.t_s), q, rate)
    route = tuple(f.route_node_ids)
    if own is None or own.times_s.shape[0] < 2 or nxt < 1 or nxt > len(route):
        return []
    # the re-join's waypoint i >= 1 is the plan's waypoint nxt + i - 1: its route from the node
    # before that one on (on a layered network waypoint w is over route node w - 1, else w)
    pseudo = replace(f, trajectory=own, departure_s=float(own.departure_s),
                     arrival_s=float(own.arrival_s), route_node_ids=route[nxt - 1:])
    a = config.airspace
    cfg = replace(config, speed_mps=float(config.speed_mps) * rate,
                  airspace=replace(a, descent_rate_mps=float(a.descent_rate_mps) * rate))
    # branch at the re-join's first waypoint after the sighting (the plan's next one)
    alts = _airborne_alternatives(pseudo, float(own.times_s[0]) + 1e-3, network, cfg, router)
    out = []
    for al in alts:
        tr = al.trajectory
        if tr.arrival_s <= t_eff:
            continue
        out.append(replace(al, route_node_ids=route[:nxt - 1] + tuple(al.route_node_ids),
                           length_m=float(f.length_m) if al.kind == "rerouted" and
                           tuple(al.route_node_ids) == route[nxt - 1:] else float(al.length_m)))
    out.sort(key=lambda al: -al.weight)
    return out


def _route_changes(alt, network) -> dict:
    """The fields of a flight that a re-route or diversion (``_Alt`` of
    :func:`_divert_alternatives`) changes besides its trajectory (:func:`_reaction_update`)."""
    return {"destination_id": network.node_ids[alt.destination],
            "route_node_ids": tuple(alt.route_node_ids), "length_m": float(alt.length_m)}


def _first_clear(alts: list, others: list, config, t_eff: float, separation=None):
    """The first of ``alts`` (``_Alt``) that keeps ``separation`` (default
    ``config.separation``) from every trajectory of ``others`` from ``t_eff`` on (exact,
    continuous time), or None."""
    sep = config.separation if separation is None else separation
    n_conf = _conflict_counts([a.trajectory for a in alts], others, sep, t_eff)
    return next((a for a, n in zip(alts, n_conf.tolist()) if n == 0), None)


def react(t_eff: float, epoch_index: int, active: Sequence, found: dict, book: PositionBook,
          config, select: Callable, policy: str, network=None, fixed: Sequence = (),
          fixed_ids: Sequence = ()) -> tuple[list, list, dict]:
    """:func:`react_steps` with its MWIS graph solved by ``select`` here (no caller's answer)."""
    from .replanning import SOLVE_HERE, run_steps
    return run_steps(react_steps(t_eff, epoch_index, active, found, book, config, select, policy,
                                 network, fixed, fixed_ids), lambda _graph: SOLVE_HERE)


@dataclass(frozen=True, eq=False)
class _Batch:
    """What the steps of one reaction batch share (:func:`react_steps`, :func:`_probe_batch_steps`), and its report."""

    t_eff: float
    epoch_index: int
    active: Sequence
    found: dict
    config: object
    select: Callable
    policy: str
    network: object
    report: dict


def _react_alternatives(b: _Batch, idx: list, book: PositionBook, probed: dict | None):
    """(rates, alternatives per row, {row: keep-its-plan alternative}) of the flights ``idx`` (their re-joins)."""
    per = []
    keep: dict = {}   # row -> the keep-its-plan alternative of a probed flight
    rates, rejoins = _observed_updates(idx, b.active, b.found, book, b.t_eff, b.report)
    for r, i in enumerate(idx):
        f = b.active[i]
        alts, _base, _own = rejoins[r]
        alts = _constraint_free(alts, f, b.config, b.network, b.t_eff, True) or alts[:1]
        if probed and i in probed:
            # it conforms: keeping its plan is an alternative too (the least preferred), so the
            # batch never leaves it with a plan the others' updates were not deconflicted from
            keep[len(per)] = (f.trajectory, KEEP_WEIGHT)
            alts = alts + [keep[len(per)]]
        per.append(alts)
    return rates, per, keep


def _react_solve_steps(b: _Batch, idx: list, per: list, fixed: list):
    """Generator: the one graph of every row's alternatives, against the others and ``fixed``: ({row: alt}, backend)."""
    from .conflict_graph import build_conflict_graph
    from .separation import SegmentSet

    others = [f for j, f in enumerate(b.active) if j not in b.found]
    act = SegmentSet.from_trajectories([f.trajectory for f in others] + fixed)
    act = act.take(act.t1_s >= b.t_eff) if len(act) else act
    flat = [a for alts in per for a in alts]
    b.report["alternatives"] = len(flat)
    req_of = np.repeat(np.arange(len(idx)), [len(a) for a in per]).astype(np.int64)
    cand = np.concatenate([np.arange(len(a)) for a in per]).astype(np.int64) if flat else np.zeros(0, np.int64)
    # deconflicted from t_eff on (what flew before is past)
    trs = [_clipped(a[0], b.t_eff) or a[0] for a in flat]
    graph = build_conflict_graph(trs, req_of, cand, np.array([a[1] for a in flat], dtype=np.float64),
                                 len(idx), act, b.config.separation)
    # F3548 mode: the new versions' volumes too
    graph = graph_for_config(graph, trs, [f.trajectory for f in others] + fixed, b.config, b.t_eff - 1.0)
    b.report["vertices"], b.report["edges"] = graph.n_vertices, graph.n_edges
    chosen = {}
    backend = b.policy
    if graph.n_vertices:
        selected, er = yield from _selection_steps(graph, b.select, b.policy)
        backend = er.backend_used or b.policy
        for v in np.asarray(selected).tolist():
            src = int(graph.vertex_source[v])
            chosen[int(req_of[src])] = flat[src]
    return chosen, backend


def _react_yield_steps(b: _Batch, unsaved: dict, chosen: dict, fixed: list, fixed_ids: Sequence):
    """Generator: the neighbours' yield for the rows ``unsaved`` (saved ones into ``chosen``): (saved, moved)."""
    saved: dict = {}
    moved: dict = {}
    if unsaved:
        held = list(zip(fixed_ids, fixed)) if len(fixed_ids) == len(fixed) else \
            [("", tr) for tr in fixed]
        saved, moved = yield from _yield_steps(
            b.t_eff, unsaved, [(j, f) for j, f in enumerate(b.active) if j not in b.found], held,
            [chosen[r][0] for r in sorted(chosen)], b.config, b.select, b.policy, b.network, b.report)
        chosen.update(saved)
        b.report["yield_saved"], b.report["yield_moved"] = len(saved), len(moved)
    return saved, moved


def _react_diversions(b: _Batch, idx: list, left: list, rates: list, chosen: dict, others: list,
                      fixed: list, router) -> dict:
    """{row: _Alt} of the rows ``left`` re-routed or diverted, each clear of all else (into ``chosen``)."""
    diverted: dict = {}       # row -> the _Alt flown (its destination and route change)
    if left and router is not None and b.network is not None:
        taken = [chosen[r][0] for r in sorted(chosen)]
        for r in left:
            f = b.active[idx[r]]
            alt = _first_clear(_divert_alternatives(f, b.found[idx[r]][0], rates[r], b.t_eff, b.network,
                                                    b.config, router),
                               [g.trajectory for g in others] + list(fixed) + taken, b.config, b.t_eff)
            if alt is not None:
                diverted[r] = alt
                chosen[r] = (alt.trajectory, alt.weight)
                taken.append(alt.trajectory)
        b.report["diverted"] = sum(1 for a in diverted.values() if a.kind == "diverted")
        b.report["rerouted"] = sum(1 for a in diverted.values() if a.kind == "rerouted")
    return diverted


def _react_updates(b: _Batch, idx: list, rates: list, per: list, keep: dict, chosen: dict, diverted: dict,
                   others: list, fixed: list, probed: dict | None, backend: str) -> tuple[list, list]:
    """(updates, new versions) of the rows: the chosen update, else a contingency; a probed one may keep its plan."""
    t_eff, report = b.t_eff, b.report
    updates, new_versions = [], []
    for r, i in enumerate(idx):
        f = b.active[i]
        obs, (lat, ver, terr) = b.found[i]
        what = (f"nonconforming at t = {obs.t_s:g} s (lateral {lat:.1f} m, vertical {ver:.1f} m, "
                f"time {terr:+.1f} s); intent updated from where it is, {RATE_WORD} {rates[r]:.12g}")
        a = chosen.get(r)
        if r in keep:
            what = _probe_reason(probed[i], obs, lat, terr, rates[r])
            if a is None or a is keep[r]:
                report["probe_kept"] = report.get("probe_kept", 0) + 1
                continue  # it conforms: it keeps its plan rather than fly a contingency
            report["probe_updates"] = report.get("probe_updates", 0) + 1
        contingent = a is None
        if a is None:
            if not per[r]:
                continue  # nothing left to fly: it is at its plan's end (it keeps its plan)
            a = _least_conflicting(per[r], [f.trajectory for f in others] + fixed +
                                   [x.trajectory for x in new_versions], b.config, t_eff,
                                   true_first=True)
            kind = KIND_CONTINGENCY
            reason = (f"contingency: {what}; each of its {len(per[r])} updated intents loses "
                      f"separation with another flight: flown but not deconflicted")
        else:
            kind = KIND
            reason = f"{KIND}: {what}"
        changes = {}
        if r in diverted:
            d = diverted[r]
            changes = _route_changes(d, b.network)
            reason += f"; {d.kind} to {changes['destination_id']!r} (no re-timing kept separation)"
        nf, up = _reaction_update(f, a, kind, reason, b.policy, backend, b.epoch_index, t_eff,
                                  rates[r], contingent, **changes)
        updates.append(up)
        new_versions.append(nf)
        report["kinds"][kind] = report["kinds"].get(kind, 0) + 1
    return updates, new_versions


def _neighbour_updates(b: _Batch, idx: list, saved: dict, moved: dict, yielded: dict, updates: list,
                       new_versions: list) -> None:
    """The updates and new versions (appended) of the neighbours that yield so that the rows ``saved`` keep it."""
    for j in sorted(moved):
        f, nf, how = b.active[j], yielded[j], moved[j][2]
        saved_ids = ", ".join(b.active[idx[r]].request_id for r in sorted(saved))
        updates.append(_yield_update(f, nf, f"{KIND_YIELD}: {how} so that the nonconforming "
                                            f"{saved_ids} keep(s) separation", b.t_eff))
        new_versions.append(nf)
        b.report["kinds"][KIND_YIELD] = b.report["kinds"].get(KIND_YIELD, 0) + 1


def react_steps(t_eff: float, epoch_index: int, active: Sequence, found: dict, book: PositionBook,
                config, select: Callable, policy: str, network=None, fixed: Sequence = (),
                fixed_ids: Sequence = (), probed: dict | None = None, held: Sequence = (),
                router=None):
    """Update the intents of the nonconforming flights ``found`` at the epoch ``t_eff``.

    A generator, as ``replanning.replan_steps``: with policy "mwis" it yields the one conflict
    graph of the alternatives and takes back the solver's answer for it (``send``: an answer,
    a reason string, or ``replanning.SOLVE_HERE`` to solve it with ``select``'s own solver), so
    the planner node awaits the solver service for it (``Planner.prepare_steps``,
    ``Planner.react_between_steps``); the answer is checked (greedy if invalid) by ``select``.
    The decisions are those of :func:`react` given the same answer.

    Args:
        t_eff: the epoch time [s] (the update takes effect then).
        epoch_index: copied to the new versions.
        active: the planner's active flights (newest versions).
        found: index in ``active`` -> (observation, (lateral, vertical, time) errors), the
            verified claims (:func:`verify`).
        book: the planner's PositionBook (the progress rates).
        config: the PlanningConfig (its ``separation``: the buffered one the planner keeps;
            ``constraints``: alternatives that enter one are dropped).
        select: callable(graph, policy) -> (selected, report), ``planning.replan_selector``.
        policy: "mwis" or "firstfit".
        fixed: more trajectories every update is deconflicted against (the overruns of other
            flights, :func:`overruns`).
        fixed_ids: the request id of each of ``fixed`` (a flight held past its plan may yield:
            its own projections do not block its moves, but stay while it keeps its plan).
        probed: index in ``active`` -> the request ids it is predicted to meet, for the flights
            of ``found`` the conflict probe found (:func:`predicted_conflicts`; they conform):
            one the batch cannot save keeps its plan (no contingency).
        held: indices in ``active`` of flights due to depart that the probed flights are
            predicted to meet (a batch of the probe alone: they may be held on the pad,
            :func:`_probe_batch_steps`).
        router: a ``replanning._Router`` of the planner's network: a flight
            that no re-timing saves (nor its neighbours' yields) is re-routed to its destination
            or diverted to one of the nearest vertiports from where it is
            (:func:`_divert_alternatives`) before it is flown as a contingency; None = not tried.
    Returns: (new active list: the others in their order, then the new versions; PlanUpdate per
    flight in ``active`` order; a report dict: flights, alternatives, vertices, edges, kinds).
    """
    idx = sorted(found)
    report = {"t_s": float(t_eff), "flights": len(idx), "alternatives": 0, "vertices": 0,
              "edges": 0, "kinds": {}, "rates": {}}
    if not idx:
        return list(active), [], report
    if probed and set(probed) == set(found):
        # a batch of the conflict probe alone (every flight conforms): its own solve
        return (yield from _probe_batch_steps(t_eff, epoch_index, active, found, book, config,
                                              select, policy, network, fixed, probed, report,
                                              held, router))
    b = _Batch(t_eff, epoch_index, active, found, config, select, policy, network, report)
    fixed = list(fixed)
    rates, per, keep = _react_alternatives(b, idx, book, probed)
    chosen, backend = yield from _react_solve_steps(b, idx, per, fixed)
    if keep and any(r not in chosen for r in keep):
        # a probed flight whose own plan conflicts with the batch's fixed traffic (a held
        # projection): no probe update of this batch is taken, every probed flight keeps its plan
        chosen = {r: a for r, a in chosen.items() if r not in keep}
        report["probe_dropped"] = len(keep)
    # the flights no alternative of their own saves: their neighbours may yield (YIELD_SHARES)
    unsaved = {r: per[r] for r in range(len(idx)) if r not in chosen and per[r] and r not in keep}
    saved, moved = yield from _react_yield_steps(b, unsaved, chosen, fixed, fixed_ids)
    yielded = {j: moved_flight(active[j], moved[j], t_eff, epoch_index, policy, backend) for j in moved}
    others = [yielded.get(j, f) for j, f in enumerate(active) if j not in found]
    # the flights still unsaved: re-routed or diverted from where they are, one at a time in
    # index order, each clear of every other flight, the held projections and what is chosen
    left = [r for r in range(len(idx)) if r not in chosen and per[r] and r not in keep]
    diverted = _react_diversions(b, idx, left, rates, chosen, others, fixed, router)
    updates, new_versions = _react_updates(b, idx, rates, per, keep, chosen, diverted, others, fixed,
                                           probed, backend)
    _neighbour_updates(b, idx, saved, moved, yielded, updates, new_versions)
    replaced = {u.request_id for u in updates}
    keep = [f for j, f in enumerate(active) if active[j].request_id not in replaced]
    return keep + new_versions, updates, report


#: the conflict probe's time shifts [s]: a probed flight may reach this much later (earlier when
#: negative) than its projection within PROBE_SHIFT_WINDOW_S, then fly the projection shifted
#: by it (speed x 0.67 to 1.09 for that minute: the re-timings by SHARES hold the
#: new speed for the rest of the flight, 100-400 s of delay, and met some other flight far
#: ahead in most batches)
PROBE_SHIFTS_S = (-5.0, 5.0, 10.0, 20.0, 30.0)
PROBE_SHIFT_WINDOW_S = 60.0
#: added to every alternative of a probed flight (its own plan included), so that the solve
#: covers every probed flight first (with keep 1 and updates 2-3 leaving one out could score
#: more than keeping both plans)
PROBE_COVER = 100.0
#: the conflict probe's holds on the pad [s]: a flight due to depart that a
#: probed flight is predicted to meet may leave this much later (its whole plan shifted)
HOLD_SHIFTS_S = (10.0, 20.0, 30.0, 60.0)
#: the weight of a flight due to depart keeping its plan: above every hold's (2 + 1 / (1 + hold /
#: DELAY_SCALE_S) < 3), so the batch holds one only when the airborne flights cannot move instead
HOLD_KEEP_WEIGHT = 3.0


def shifted_trajectory(base: Trajectory, t0_s: float, delta_s: float,
                       window_s: float = PROBE_SHIFT_WINDOW_S) -> Trajectory | None:
    """``base`` (the same path) ``delta_s`` later (earlier when negative) by ``t0_s + window_s``:
    its times after ``t0_s`` stretched by (1 + delta / window) up to then, shifted by delta from
    there on. None when the times would not increase (delta <= -window)."""
    ts, ps = base.times_s, base.points_m
    tb = float(t0_s) + float(window_s)
    if tb < ts[-1] and not np.any(np.isclose(ts, tb)):
        k = int(np.searchsorted(ts, tb))
        ts = np.insert(ts, k, tb)
        ps = np.insert(ps, k, base.position_at(tb), axis=0)
    rel = ts - float(t0_s)
    new = np.where(rel <= window_s, float(t0_s) + rel * (1.0 + delta_s / window_s), ts + delta_s)
    if np.any(np.diff(new) <= 0):
        return None
    return Trajectory(new, ps)


def probe_batch_separation(config):
    """The separation a batch of the conflict probe alone deconflicts with: the wider of the
    planner's (``config.separation``, with the buffers) and the probe's
    (``config.probe_separation``, the true minimum + ``conflict_probe_margin_m``)."""
    from .separation import SeparationModel
    a, b = config.separation, config.probe_separation
    if b.separation_m <= a.separation_m and b.vertical_separation_m <= a.vertical_separation_m:
        return a
    return SeparationModel(a.kind, max(a.separation_m, b.separation_m),
                           max(a.vertical_separation_m, b.vertical_separation_m))


def _probe_alternatives(b: _Batch, idx: list, rejoins: list) -> tuple[list, list]:
    """(alternatives, projection up to the look-ahead) per probed row: re-joins, shifts, then keeping its plan."""
    from .replanning import clipped_until

    look = float(b.config.conflict_probe_s)
    per, proj = [], []
    for r, i in enumerate(idx):
        f = b.active[i]
        obs = b.found[i][0]
        alts, base, own = rejoins[r]
        if own is not None and alts:
            for delta in PROBE_SHIFTS_S:
                tr = shifted_trajectory(own, float(obs.t_s), delta)
                if tr is None or tr.arrival_s <= b.t_eff:
                    continue
                alts.append((tr, _delay_weight(tr, base)))
        alts = _constraint_free(alts, f, b.config, b.network, b.t_eff, True) or alts[:1]
        per.append(alts + [(f.trajectory, KEEP_WEIGHT)])   # the last one: keep its plan
        pr = _clipped(own, b.t_eff) if own is not None else None
        pr = clipped_until(pr, b.t_eff + look) if pr is not None else None
        proj.append(pr if pr is not None and pr.times_s.shape[0] >= 2 else None)
    return per, proj


def _hold_alternatives(b: _Batch, f) -> list:
    """The alternatives of ``f``, due to depart: its plan held on the pad by each of HOLD_SHIFTS_S, keeping it last."""
    tr = f.trajectory
    shifted = [Trajectory(tr.times_s + d, tr.points_m) for d in HOLD_SHIFTS_S]
    alts = [(s, _delay_weight(s, tr.arrival_s)) for s in shifted]
    alts = _constraint_free(alts, f, b.config, b.network, b.t_eff, False)
    return alts + [(tr, HOLD_KEEP_WEIGHT)]        # the last one: keep its plan


def _projection_edges(graph, flat: list, src: list, trs: list, per: list, proj: list, sep):
    """``graph`` with an edge from each row's keep vertex to the others' vertices its projection meets (flown so)."""
    from .conflict_graph import _unique_pairs
    from .separation import conflicting_pairs

    add = []
    for v, s_v in enumerate(src):
        r, c, _a = flat[s_v]
        if c != len(per[r]) - 1 or proj[r] is None:
            continue                                # not a keep vertex, or nothing projected
        us = [u for u, s_u in enumerate(src) if flat[s_u][0] != r]
        if us:
            pairs = np.asarray(conflicting_pairs([proj[r]], [trs[src[u]] for u in us],
                                                 sep)).reshape(-1, 2)
            add += [(min(v, us[y]), max(v, us[y])) for y in pairs[:, 1].tolist()]
    if not add:
        return graph
    edges = _unique_pairs(np.concatenate((np.asarray(graph.edges, np.int64).reshape(-1, 2),
                                          np.array(add, np.int64))), graph.n_vertices)
    return replace(graph, edges=edges.astype(np.int32),
                   n_conflict_edges=graph.n_conflict_edges + len(add))


def _probe_round_graph(b: _Batch, rows: list, per: list, proj: list, others: list, extra: list, sep):
    """One solve round's graph of the rows still in: ((row, index, alternative) list, vertex sources, graph)."""
    from .conflict_graph import build_conflict_graph

    t_eff = b.t_eff
    flat = [(r, c, a) for r in rows for c, a in enumerate(per[r])]
    trs = [_clipped(a[0], t_eff) or a[0] for _r, _c, a in flat]
    # the margin is kept from the batch's own flights (the rows, the released ones' plans and
    # projections: those predicted to come close); every other flight at the planner's
    # buffered separation, as every plan keeps it (against all traffic at
    # minimum + margin, an update that parted the pair could be refused for a third flight
    # planned at the buffer)
    ok = ~((_conflict_counts(trs, others, b.config.separation, t_eff) > 0) |
           (_conflict_counts(trs, extra, sep, t_eff) > 0))
    flat = [x for x, k in zip(flat, ok.tolist()) if k]
    trs = [x for x, k in zip(trs, ok.tolist()) if k]
    at = {r: q for q, r in enumerate(rows)}
    req_of = np.array([at[r] for r, _c, _a in flat], dtype=np.int64)
    cand = np.array([c for _r, c, _a in flat], dtype=np.int64)
    graph = build_conflict_graph(trs, req_of, cand,
                                 np.array([a[1] + PROBE_COVER for _r, _c, a in flat]),
                                 len(rows), (), sep)
    src = np.asarray(graph.vertex_source).tolist()
    return flat, src, _projection_edges(graph, flat, src, trs, per, proj, sep)


def _probe_solve_steps(b: _Batch, rows_i: list, per: list, proj: list, others: list, sep):
    """Generator: solve rounds until every row left has a vertex (one left out keeps its plan): (chosen, backend)."""
    rows, extra, chosen, backend = list(range(len(rows_i))), [], {}, b.policy
    while rows:
        flat, src, graph = _probe_round_graph(b, rows, per, proj, others, extra, sep)
        b.report["vertices"] += graph.n_vertices
        b.report["edges"] += graph.n_edges
        got = {}
        if graph.n_vertices:
            selected, er = yield from _selection_steps(graph, b.select, b.policy)
            backend = er.backend_used or b.policy
            for v in np.asarray(selected).tolist():
                r, c, a = flat[src[v]]
                got[r] = (c, a)
        left = [r for r in rows if r not in got]
        if not left:
            chosen.update(got)
            break
        for r in left:                                  # it keeps its plan, flown as projected
            rows.remove(r)
            extra += [b.active[rows_i[r]].trajectory] + ([proj[r]] if proj[r] is not None else [])
            b.report["probe_released"] = b.report.get("probe_released", 0) + 1
    return chosen, backend


def _probe_updates(b: _Batch, idx: list, rates: list, per: list, chosen: dict, diverted: dict, widest: dict,
                   probed: dict, sep, backend: str) -> tuple[list, list]:
    """(updates, new versions) of the probed rows the batch moves (re-timed, re-routed or diverted); the others keep."""
    report = b.report
    updates, new_versions = [], []
    for r, i in enumerate(idx):
        f = b.active[i]
        obs, (lat, _ver, terr) = b.found[i]
        ch = chosen.get(r)
        d = diverted.get(r)
        if d is not None:
            ch = (-1, (d.trajectory, d.weight))
        if ch is None or ch[0] == len(per[r]) - 1:
            report["probe_kept"] = report.get("probe_kept", 0) + 1
            continue
        report["probe_updates"] = report.get("probe_updates", 0) + 1
        what = _probe_reason(probed[i], obs, lat, terr, rates[r])
        changes = {}
        if d is not None:
            changes = _route_changes(d, b.network)
            what += (f"; {d.kind} to {changes['destination_id']!r} from where it is (no "
                     f"re-timing kept separation)")
        if r in widest:
            what += (f"; the widest berth left: {widest[r]:.1f} m at the closest (nothing kept "
                     f"{sep.separation_m:g} m)")
        nf, up = _reaction_update(f, ch[1], KIND, f"{KIND}: {what}", b.policy, backend, b.epoch_index,
                                  b.t_eff, rates[r], False, **changes)
        updates.append(up)
        new_versions.append(nf)
        report["kinds"][KIND] = report["kinds"].get(KIND, 0) + 1
    return updates, new_versions


def _hold_updates(b: _Batch, idx: list, rows_i: list, per: list, chosen: dict, probed: dict, backend: str,
                  updates: list, new_versions: list) -> None:
    """The updates and new versions (appended) of the rows on the ground the batch holds on the pad."""
    report = b.report
    for r in range(len(idx), len(rows_i)):                # on the ground: held, or keeps its plan
        f = b.active[rows_i[r]]
        ch = chosen.get(r)
        if ch is None or ch[0] == len(per[r]) - 1:
            continue
        tr = ch[1][0]
        delay = float(tr.departure_s - f.departure_s)
        met = sorted(b.active[idx[q]].request_id for q in range(len(idx))
                     if f.request_id in probed.get(idx[q], ()))
        nf = moved_flight(f, (tr, ch[1][1], ""), b.t_eff, b.epoch_index, b.policy, backend)
        updates.append(_yield_update(
            f, nf, f"{KIND_YIELD}: held on the pad {delay:g} s (departs at {tr.departure_s:g} s) so "
            f"that {', '.join(met) or 'the probed flights'} keep(s) separation (conflict probe)",
            b.t_eff))
        new_versions.append(nf)
        report["probe_held"] = report.get("probe_held", 0) + 1
        report["kinds"][KIND_YIELD] = report["kinds"].get(KIND_YIELD, 0) + 1


def _probe_batch_steps(t_eff: float, epoch_index: int, active: Sequence, found: dict,
                       book: PositionBook, config, select: Callable, policy: str, network,
                       fixed: Sequence, probed: dict, report: dict, held: Sequence = (),
                       router=None):
    """:func:`react_steps` for a batch of the conflict probe alone (every flight conforms).

    Each probed flight's alternatives: re-joins of its plan from where it is at its observed
    rate x (1, SHARES), its projection shifted by PROBE_SHIFTS_S within PROBE_SHIFT_WINDOW_S,
    and keeping its plan (weight KEEP_WEIGHT), each + PROBE_COVER. Keeping its plan conflicts
    with what its plan meets and with what its projection (from its newest sighting at its
    observed rate, up to the look-ahead) meets: it flies as projected, not as planned. The
    solve is repeated: a flight the answer leaves without an alternative keeps its plan, its
    plan and projection become fixed traffic, and the others are solved again (until every
    flight left has one). When one flight left out dropped every update of the
    batch, 14 of 20 flown losses at 25 m in 41 seeds were such batches (BENCHMARKS.md).
    ``held``: flights due to depart that a probed flight is predicted to meet
    join the batch too, with their plan (weight HOLD_KEEP_WEIGHT) and their plan shifted later by
    each of HOLD_SHIFTS_S (held on the pad; weight by the delay, below keeping it), each +
    PROBE_COVER; a hold is a plan update of kind ``yielded`` (the flight is not airborne: no
    observation to update it from, its new plan is the old one later).
    ``router`` (as in :func:`react_steps`): a probed flight the solve leaves
    keeping its plan while that plan or its projection still loses the true minimum with another
    flight (no re-timing and no hold cleared it: a head-on pair on one corridor, say) is
    re-routed to its destination or diverted from where it is (:func:`_divert_alternatives`),
    one flight at a time in index order, clear of everything else at the batch's separation
    (minimum + margin, also from flights outside the batch): minutes ahead, where the
    reaction's diversion comes only once a flight is reported nonconforming. Without it the probe saw such pairs
    at every look for 120-150 s and kept both plans.
    Where nothing keeps the batch's separation, such a flight takes the widest berth that keeps
    the true minimum (see :func:`_probe_diversions`).
    A generator as :func:`react_steps`: it yields each round's graph."""
    idx = sorted(found)
    hold = sorted({int(i) for i in held if i not in found and active[i].departure_s > t_eff})
    rows_i = idx + hold          # the batch's rows: the probed flights, then those on the ground
    sep = probe_batch_separation(config)
    b = _Batch(t_eff, epoch_index, active, found, config, select, policy, network, report)
    rates, rejoins = _observed_updates(idx, active, found, book, t_eff, report)
    per, proj = _probe_alternatives(b, idx, rejoins)
    for i in hold:
        per.append(_hold_alternatives(b, active[i]))
        proj.append(None)
    ground = set(hold)
    others = [f.trajectory for j, f in enumerate(active) if j not in found and j not in ground] + \
        list(fixed)
    report["alternatives"] = sum(len(a) for a in per)
    chosen, backend = yield from _probe_solve_steps(b, rows_i, per, proj, others, sep)
    diverted, widest = _probe_diversions(t_eff, idx, rows_i, active, found, rates, per, proj,
                                         chosen, others, sep, config, network, router, report)
    updates, new_versions = _probe_updates(b, idx, rates, per, chosen, diverted, widest, probed, sep,
                                           backend)
    _hold_updates(b, idx, rows_i, per, chosen, probed, backend, updates, new_versions)
    replaced = {u.request_id for u in updates}
    return [f for f in active if f.request_id not in replaced] + new_versions, updates, report


def _probe_diversions(t_eff: float, idx: list, rows_i: list, active: Sequence, found: dict,
                      rates: list, per: list, proj: list, chosen: dict, others: list,
                      sep, config, network, router, report: dict) -> tuple[dict, dict]:
    """The re-routes and diversions of :func:`_probe_batch_steps` (see there): {row: _Alt} for
    the probed (airborne) rows the solve left keeping their plan whose plan or projection still
    loses the true minimum (``config.minimum_separation``) with the rest of the traffic as the
    batch leaves it (``others``: the plans outside the batch and the fixed traffic; each other
    row's update, or its plan and projection). One row at a time in index order, each clear at
    ``sep`` (the batch's separation) of all of that and of the re-routes taken before it; a row
    whose conflict an earlier re-route removed keeps its plan. A row with no re-route or
    diversion clear at ``sep`` (or no ``router``) takes, of its re-timings ``per[r]``, the one
    whose closest approach to all of that is the widest, if it keeps the true minimum (into
    ``chosen``, as if the solve had picked it), else the widest such re-route or diversion
    (``report["probe_widest"]`` counts both; the second dict: {row: its closest approach [m]})."""

    def flies(r):          # what row r flies as the batch leaves it (its update, or plan + projection)
        if r in out:
            return [out[r].trajectory]
        ch = chosen.get(r)
        if ch is not None and ch[0] != len(per[r]) - 1:
            return [ch[1][0]]
        f = active[rows_i[r]]
        return [f.trajectory] + ([proj[r]] if proj[r] is not None else [])

    out: dict = {}
    widest: dict = {}
    for r in range(len(idx)):
        ch = chosen.get(r)
        if ch is not None and ch[0] != len(per[r]) - 1:
            continue                                    # it is updated already
        rest = list(others) + [t for q in range(len(rows_i)) if q != r for t in flies(q)]
        if not _conflict_counts(flies(r), rest, config.minimum_separation, t_eff).any():
            # no loss of the true minimum is left to avoid (the margin alone is the re-timings'
            # business: re-routing for it diverted ~2 conforming flights a run),
            # or what it meets has moved: it keeps its plan
            continue
        f = active[idx[r]]
        diverts = [] if router is None or network is None else _divert_alternatives(
            f, found[idx[r]][0], rates[r], t_eff, network, config, router)
        alt = _first_clear(diverts, rest, config, t_eff, sep)
        if alt is None:
            # nothing keeps the batch's separation: the widest berth that still keeps the true
            # minimum, a re-timing before a re-route or diversion (seed 14: the
            # early flight's every re-timing met a third flight at the buffer, the other's
            # every one came within 150 m of its projection; both kept their plans, projected
            # 81-91 m apart, and flew 86.5 m apart; with this the early flight is re-timed at
            # the first such look and the run has no flown loss, closest pair 104.5 m)
            minimum = config.minimum_separation
            retimed = per[r][:-1]
            got = _widest([a[0] for a in retimed], rest, sep, minimum, t_eff)
            if got is not None:
                chosen[r] = (got[0], retimed[got[0]])
            else:
                got = _widest([a.trajectory for a in diverts], rest, sep, minimum, t_eff)
                alt = diverts[got[0]] if got is not None else None
            if got is not None:
                widest[r] = got[1]
                report["probe_widest"] = report.get("probe_widest", 0) + 1
        if alt is not None:
            out[r] = alt
            key = "probe_" + alt.kind
            report[key] = report.get(key, 0) + 1
    return out, widest


def _widest(trajectories: list, others: list, separation, minimum,
            t_eff: float) -> tuple[int, float] | None:
    """(index, closest approach [m]) of the one of ``trajectories`` (from ``t_eff`` on) whose
    closest approach to ``others`` is the widest (exact, continuous time; ``separation`` or more
    counts as ``separation``; the first of equals), or None when none keeps ``minimum`` from all
    of them."""
    from .separation import as_separation_model, conflicting_pairs

    if not trajectories:
        return None
    sep = as_separation_model(separation)
    near = np.full(len(trajectories), float(sep.separation_m))
    sets = _segment_sets(trajectories, others, t_eff)
    if sets is not None:
        pairs, dist = conflicting_pairs(*sets, sep, return_distances=True)
        np.minimum.at(near, np.asarray(pairs[:, 0], dtype=np.int64), np.asarray(dist))
    k = int(np.argmax(near))
    if _conflict_counts([trajectories[k]], others, minimum, t_eff)[0]:
        return None
    return k, float(near[k])


def _yield_update(f, nf, reason: str, t_eff: float):
    """The ReactionUpdate of ``f`` moved to ``nf`` so that others keep separation (a neighbour
    that yields, a flight held on the pad): kind ``yielded``, no observed rate."""
    return ReactionUpdate(f.request_id, f.operator_id, nf.version, KIND_YIELD, (), reason,
                          float(t_eff), nf, f, nf.arrival_s - f.arrival_s, 0.0)


def moved_flight(f, alt, t_eff: float, epoch_index: int, policy: str, backend: str):
    """The new version of a neighbour that yields (``alt``: trajectory, weight, how)."""
    tr = alt[0]
    return replace(f, trajectory=tr, departure_s=float(tr.departure_s), arrival_s=float(tr.arrival_s),
                   method=f"yield-{policy}", backend=backend, epoch_index=int(epoch_index),
                   version=f.version + 1, effective_s=float(t_eff))


# ---- flights that fly past their plan (the safety gap) -----------------------------
#
# A plan ends at its planned arrival; an aircraft that is late is still in the air then. The
# planner used to drop a flight from its traffic picture at the planned arrival whatever it saw,
# so new approvals could be planned into a late aircraft still flying. Now every epoch the
# planner projects, from its own observations of a flight (the fleet state; never a report),
# where the rest of the flight goes: the rest of its plan from the observed position at the
# plan's speed, i.e. the remaining plan shifted by the observed lateness
# (:func:`overrun_trajectory`). When a projection lands later than the plan, the flight is
# *held* (an :class:`Overrun`): two projections are deconflicted against like active flights,
# beside the plan itself, until they have landed, even after the plan's arrival:
#
# - the *newest* sighting's (the best estimate of where the aircraft is: it follows a flight that
#   recovers part of its lateness, which the plan and an older, later projection both miss);
# - the *latest-landing* one of every sighting of this plan version (never shortened: a forged
#   "on time" or "landed" fleet state cannot cancel a real late one).
#
# The absence of a vehicle from the fleet state (it landed, or it vanished) changes nothing: the
# projections from its last sightings stand, and land. What bounds it: projections are cut at
# the plan's arrival plus MAX_OVERRUN_SHARE of its planned flight time, so forged sightings cannot
# hold a flight for ever. Without observations (the paper's mode in process), or for a flight
# flying its plan exactly, nothing is held: the results are the same bit for bit.

#: a projection that lands at most this much after the plan's arrival holds nothing [s]
#: (rounding: an aircraft flying its plan exactly projects onto its own plan)
OVERRUN_TOLERANCE_S = 1e-3
#: an overrun is cut at the plan's arrival plus this share of its planned flight time (the
#: slowest progress rate the planner believes, RATE_RANGE[0], doubles a flight's time)
MAX_OVERRUN_SHARE = 1.0 / RATE_RANGE[0] - 1.0


@dataclass(frozen=True, eq=False)
class Overrun:
    """A flight held past its plan: ``plan`` (its newest version, the one projected from),
    ``latest`` (that plan's Flight with the latest-landing projection of its sightings as
    trajectory), ``newest`` (the same with the newest sighting's projection, or None when that
    one lands on time), ``observed_s`` (the sighting ``latest`` starts from) and ``cap_s`` (the
    latest it may be held to). ``until_s``: when it is let go."""

    request_id: str
    plan: object
    latest: object
    newest: object
    observed_s: float
    cap_s: float

    @property
    def until_s(self) -> float:
        return float(self.latest.arrival_s)

    @property
    def flights(self) -> list:
        """The projections deconflicted against (Flights)."""
        return [self.latest] + ([self.newest] if self.newest is not None else [])


def overrun_trajectory(plan: Trajectory, obs: Observation, cap_s: float) -> Trajectory | None:
    """Where a flight seen at ``obs`` goes if it flies the rest of ``plan`` at its planned speed
    from there (:func:`rejoin_trajectory` at rate 1: the remaining plan shifted by the observed
    lateness), cut at ``cap_s``. None if nothing is left."""
    tr = rejoin_trajectory(plan, obs.t_s, obs.position_m, 1.0, first_pass=True)
    if tr is None or tr.arrival_s <= cap_s:
        return tr
    ts, ps = tr.times_s, tr.points_m
    if cap_s <= ts[0]:
        return None
    keep = ts < cap_s
    return Trajectory(np.append(ts[keep], cap_s), np.vstack((ps[keep], tr.position_at(cap_s))))


def _planned_times(rid: str, plan, obs: list, cache: dict | None) -> np.ndarray:
    """The planned time of each sighting's nearest path point (:func:`nearest` without the
    sightings' times), per sighting. ``cache`` (request id -> (plan, {sighting time: planned
    time})) keeps the answers for a plan version from one epoch to the next: a sighting's is a
    function of the plan and its position alone (``nearest`` answers each point on its own), and
    a sighting never changes once taken, so only the new ones are computed (the planner node
    sees every vehicle every second: ~120 sightings a flight in the window, ~30 of them new)."""
    if cache is None:
        return nearest(plan, np.array([o.position_m for o in obs]))[3]
    ent = cache.get(rid)
    if ent is None or ent[0] is not plan:
        ent = cache[rid] = (plan, {})
    known = ent[1]
    new = [o for o in obs if o.t_s not in known]
    if new:
        tau_new = nearest(plan, np.array([o.position_m for o in new]))[3]
        known.update(zip((o.t_s for o in new), tau_new.tolist()))
    lo = obs[0].t_s
    for t in [t for t in known if t < lo]:   # pruned from the book: never asked for again
        del known[t]
    return np.array([known[o.t_s] for o in obs], dtype=np.float64)


def overruns(t_s: float, plans: dict, book: PositionBook, previous: dict,
             cache: dict | None = None) -> dict:
    """The flights held past their plans at the epoch ``t_s``: request id -> :class:`Overrun`.

    Args:
        plans: request id -> the newest Flight of every flight the planner still holds (the
            active ones and those already held).
        book: the planner's own observations; those stamped in [plan departure, ``t_s``] count.
        previous: the result of the last epoch (the latest-landing projection of a plan version
            is only ever replaced by one that lands later).
        cache: optional dict kept by the caller from one epoch to the next: the sightings'
            planned times already computed (:func:`_planned_times`; the same answers); the
            flights not in ``plans`` are dropped from it.
    Held flights whose projections have landed by ``t_s`` are left out.
    """
    if cache is not None:
        for rid in [r for r in cache if r not in plans]:
            del cache[rid]
    out = {}
    for rid, f in plans.items():
        prev = previous.get(rid)
        if prev is not None and prev.plan is not f:
            prev = None  # a new version (a re-plan from where it is): projected afresh
        plan = f.trajectory
        arrival = float(f.arrival_s)
        obs = book.observations(rid, plan.departure_s, t_s)
        latest, observed_s, newest = (prev.latest, prev.observed_s, None) if prev is not None else (None, 0.0, None)
        cap = float(f.arrival_s) + MAX_OVERRUN_SHARE * max(0.0, arrival - float(f.departure_s))

        def held(tr):
            return replace(f, trajectory=tr, departure_s=float(tr.departure_s), arrival_s=float(tr.arrival_s))

        if obs:
            # the landing each sighting projects (the rest of the plan from its nearest point at
            # the plan's speed; the rejoin's first leg is built for the ones kept). Without the
            # sightings' times on purpose: where the path comes back over itself the first pass
            # is taken, the earliest planned time, so the latest landing (never a shorter hold)
            tau = _planned_times(rid, plan, obs, cache)
            land = np.array([o.t_s for o in obs]) + (float(plan.arrival_s) - tau)
            k = int(np.argmax(land))
            if land[k] > arrival + OVERRUN_TOLERANCE_S and \
                    (latest is None or land[k] > latest.arrival_s + OVERRUN_TOLERANCE_S):
                tr = overrun_trajectory(plan, obs[k], cap)
                if tr is not None and tr.arrival_s > arrival + OVERRUN_TOLERANCE_S and \
                        (latest is None or tr.arrival_s > latest.arrival_s):
                    latest, observed_s = held(tr), float(obs[k].t_s)
            if latest is not None and land[-1] > arrival + OVERRUN_TOLERANCE_S and obs[-1].t_s > observed_s:
                tr = overrun_trajectory(plan, obs[-1], cap)
                if tr is not None and tr.arrival_s > arrival + OVERRUN_TOLERANCE_S and tr.arrival_s >= t_s:
                    newest = held(tr)
        if latest is not None and latest.arrival_s >= t_s:
            out[rid] = Overrun(rid, f, latest, newest, observed_s, cap)
    return out
