"""Batch re-planning on constraint updates, plan versions and the audit of what flew (issue 22,
uam_planner.replanning, docs/replanning.md). Every expected value is computed by hand in the
comments: speed 10 m/s, the paper's sphere of 100 m, epochs of 30 s."""

import itertools
import json
import math
from dataclasses import replace
from typing import Sequence

import numpy as np
import pytest

from uam_planner.constraints import Constraint, ConstraintSet, load_constraints
from uam_planner.network import network_from_enu
from uam_planner.planning import AirspaceConfig, FlightRequest, Planner, PlanningConfig
from uam_planner.replanning import DELAY_SCALE_S, pad_of_point, constraint_timeline, flight_state, spliced
from uam_planner.trajectory import Trajectory


# The planner's own view of what flew and of its incursions (its closed-form prism test), for the
# tests of its re-plans; the audit of a run reads uam_sim.audit.record (one implementation).
def spliced_versions(versions: Sequence) -> Trajectory | None:
    """The trajectory flown by one flight given its versions in order (Flight objects with
    ``trajectory`` and ``effective_s``, or None for a cancellation): each version from the
    instant it took effect. None if nothing flew (cancelled before departure)."""
    flown = None
    for v in versions:
        if v is None:  # cancelled: only a flight that had not departed is ever cancelled
            return None
        flown = v.trajectory if flown is None else spliced(flown, v.trajectory, v.effective_s)
    return flown


def planner_violations_as_flown(flown: dict, timeline: Sequence, network, ends: dict) -> list:
    """Constraint incursions of what flew: (request_id, constraint label, t_s) for each flight
    whose flown trajectory enters a constraint version while it was in force (its window cut
    to [from_s, until_s)), by the same exact test the planner uses.

    Args:
        flown: request_id -> flown Trajectory.
        timeline: from :func:`constraint_timeline`.
        network: the Network.
        ends: request_id -> (origin_id, destination_id) (the destination it landed at).
    """
    cs = []
    for k, (c, since, until) in enumerate(timeline):
        lo, hi = max(c.start_s, since), min(c.end_s, until)
        if not hi > lo:
            continue
        cs.append(replace(c, constraint_id=f"{c.constraint_id}#{k}", start_s=lo, end_s=hi,
                          announce_s=-math.inf))
    if not cs or not flown:
        return []
    labels = {f"{c.constraint_id}#{k}": c.label() for k, (c, _a, _b) in enumerate(timeline)}
    cset = ConstraintSet(cs, network)
    ids = list(flown)
    trs = [flown[i] for i in ids]
    o = np.array([network.node_index(ends[i][0]) for i in ids], dtype=np.int64)
    d = np.array([network.node_index(ends[i][1]) for i in ids], dtype=np.int64)
    po = np.array([pad_of_point(network, oi, tr.points_m[0]) for oi, tr in zip(o.tolist(), trs)])
    pd = np.array([pad_of_point(network, di, tr.points_m[-1]) for di, tr in zip(d.tolist(), trs)])
    which, when = cset.violations(trs, o, d, po, pd)
    return [(ids[i], labels[cset.constraints[int(which[i])].constraint_id], float(when[i]))
            for i in np.flatnonzero(which >= 0).tolist()]


def lanes():
    """Two east-west lanes 1 km apart and a vertiport C between them.

    P's lane: Wp (-1000, 0) - mp (0, 0) - Ep (1000, 0); Q's lane: Wq (-1000, 1000) - mq (0, 1000)
    - Eq (1000, 1000); C (0, 480) joined to mp (480 m) and mq (520 m). Aerodromes: the W, E and C."""
    ids = ["Wp", "mp", "Ep", "Wq", "mq", "Eq", "C"]
    enu = [(-1000, 0, 0), (0, 0, 0), (1000, 0, 0), (-1000, 1000, 0), (0, 1000, 0), (1000, 1000, 0),
           (0, 480, 0)]
    aer = [True, False, True, True, False, True, True]
    edges = [("Wp", "mp"), ("mp", "Ep"), ("Wq", "mq"), ("mq", "Eq"), ("mp", "C"), ("mq", "C")]
    return network_from_enu("lanes", ids, enu, aer, edges)


#: x in [400, 600] over both lanes, 0-500 m, from t = 60 s
EAST = Constraint("east", 1, "storm cell", 60.0, 1000.0, lower_m=-10.0, upper_m=500.0,
                  rings_m=(np.array([(400.0, -100.0), (600.0, -100.0), (600.0, 1100.0), (400.0, 1100.0)]),))


def req(rid, o, d, t=0.0, latest=None, earliest=None):
    e = t if earliest is None else earliest
    return FlightRequest(rid, o, d, t, e, e + 20.0 if latest is None else latest)


def exact_mwis(weights, edges, groups):
    """Brute force over every independent set (a handful of vertices)."""
    from types import SimpleNamespace
    n = len(weights)
    adj = {(int(a), int(b)) for a, b in np.asarray(edges).reshape(-1, 2)}
    best, best_set = -1.0, ()
    for r in range(n + 1):
        for s in itertools.combinations(range(n), r):
            if any((a, b) in adj for a, b in itertools.combinations(s, 2)):
                continue
            w = float(sum(weights[i] for i in s))
            if w > best + 1e-12:
                best, best_set = w, s
    return SimpleNamespace(selected=np.array(best_set, dtype=np.int64), backend="brute-force")


def planner(policy="mwis", **kw):
    return Planner(lanes(), PlanningConfig(k=2, **kw), policy, solve_mwis=exact_mwis)


def fly(p, *requests):
    for r in requests:
        assert p.submit(r) is None
    res = p.plan(0.0, 0)
    assert sorted(f.request_id for f in res.approved) == sorted(r.request_id for r in requests)
    return res


def divert_weight(t_land_s):
    return 1.0 + 1.0 / (1.0 + t_land_s / DELAY_SCALE_S)


def test_airborne_flight_is_diverted_to_the_nearest_free_vertiport():
    p = planner()
    fly(p, req("P", "Wp", "Ep"))
    # P: Wp at 0, mp at 100, Ep at 200; it would enter x = 400 at t = 140
    assert p.update_constraint("add", EAST, 80.0) is None
    assert p.plan(60.0, 2).plan_updates == []            # announced at 80: not yet
    res = p.plan(90.0, 3)
    (u,) = res.plan_updates
    # branch point mp (the first waypoint at or after t = 90); no route east avoids the cell;
    # the nearest vertiports from mp: C (480 m, lands at 148: 58 s after t_eff), Wp (1000 m, 110 s
    # after), Wq (1414 m; its route through C and mq lands at 300); turning back now from
    # (-100, 0) lands at Wp at 90 + 90 = 180 (90 s after)
    assert (u.kind, u.version, u.effective_s, u.constraint_ids) == ("diverted", 2, 90.0, ("east",))
    assert "constraint 'east' v1 (storm cell)" in u.reason and "'C'" in u.reason
    f = u.flight
    assert (f.destination_id, f.route_node_ids, f.version, f.effective_s) == ("C", ("Wp", "mp", "C"), 2, 90.0)
    np.testing.assert_allclose(f.trajectory.times_s, [0.0, 100.0, 148.0])
    np.testing.assert_allclose(f.trajectory.points_m, [(-1000, 0, 0), (0, 0, 0), (0, 480, 0)])
    assert f.weight == pytest.approx(divert_weight(58.0))   # lands 148 - 90 = 58 s after t_eff
    assert u.added_delay_s == pytest.approx(148.0 - 200.0)
    assert [g.request_id for g in p.active] == ["P"] and p.active[0] is f
    assert res.report.replan.kinds == {"diverted": 1} and res.report.replan.affected_airborne == 1
    # the chain: what flew is the old plan up to t_eff and the new one after
    flown = spliced_versions([u.previous, f])
    np.testing.assert_allclose(flown.points_m[-1], (0, 480, 0))
    assert flight_state(f, 120.0) == "Activated" and flight_state(f, 149.0) == "Ended"


def test_an_airborne_flight_turns_back_at_once_when_that_lands_soonest():
    # at t_eff = 60 P is at (-400, 0): turning back now lands at Wp at 60 + 600 / 10 = 120 (60 s
    # after t_eff, w = 1 + 300/360) beats C from mp (148: 88 s after) and Wp from mp (200)
    p = planner()
    fly(p, req("P", "Wp", "Ep"))
    p.update_constraint("add", EAST, 60.0)
    (u,) = p.plan(60.0, 2).plan_updates
    f = u.flight
    assert (u.kind, f.destination_id, f.route_node_ids) == ("diverted", "Wp", ("Wp",))
    np.testing.assert_allclose(f.trajectory.times_s, [0.0, 60.0, 120.0])
    np.testing.assert_allclose(f.trajectory.points_m, [(-1000, 0, 0), (-400, 0, 0), (-1000, 0, 0)])
    assert f.weight == pytest.approx(divert_weight(60.0))
    np.testing.assert_allclose(spliced_versions([u.previous, f]).points_m[-1], (-1000, 0, 0))


def test_a_stream_that_must_turn_back_keeps_its_spacing():
    # P1 and P2 leave Wp 20 s apart (200 m) towards Ep; at t_eff = 60 the cell closes the way
    # east and every other vertiport is behind them. Turning back at once (P1 from (-400, 0)
    # lands at 120, P2 from (-600, 0) at 100) keeps their 200 m; P1 turning at mp (100) instead
    # would meet P2 (then at (-200, 0), heading east) head-on.
    p = planner()
    fly(p, req("P1", "Wp", "Ep"))
    assert p.submit(FlightRequest("P2", "Wp", "Ep", 0.0, 20.0, 40.0)) is None
    (p2,) = p.plan(30.0, 1).approved
    assert p2.departure_s == 30.0
    for c in (EAST, Constraint("C-closed", 1, "", 60.0, 1000.0, vertiport_id="C")):
        p.update_constraint("add", c, 60.0)
    res = p.plan(60.0, 2)
    got = {u.request_id: (u.kind, u.flight.destination_id, u.flight.arrival_s) for u in res.plan_updates}
    # P2 departed at 30: at 60 it is at (-700, 0), back at Wp at 90
    assert got == {"P1": ("diverted", "Wp", pytest.approx(120.0)), "P2": ("diverted", "Wp", pytest.approx(90.0))}
    assert min_flown_separation(res.plan_updates) >= 100.0


def test_an_occupied_alternate_sends_the_diversion_to_the_next_vertiport():
    p = planner()
    # R: Wq -> mq -> C, lands at C at t = 152 (1,520 m); it never meets the cell: unaffected
    fly(p, req("P", "Wp", "Ep"), req("R", "Wq", "C"))
    p.update_constraint("add", EAST, 60.0)
    res = p.plan(60.0, 2)
    (u,) = res.plan_updates
    # P -> C would land at 148 while R is 40 m away (at (0, 520)): a loss, so P turns back to Wp
    # (at once, from (-400, 0) at t_eff = 60: lands at 120)
    assert (u.request_id, u.kind, u.flight.destination_id) == ("P", "diverted", "Wp")
    np.testing.assert_allclose(u.flight.trajectory.times_s, [0.0, 60.0, 120.0])
    assert [f.request_id for f in p.active] == ["R", "P"]


@pytest.mark.parametrize("policy", ["mwis", "firstfit"])
def test_two_replanned_flights_that_would_conflict_get_compatible_alternatives(policy):
    p = planner(replan_policy=policy)
    fly(p, req("P", "Wp", "Ep"), req("Q", "Wq", "Eq"))
    wq_closed = Constraint("Wq-closed", 1, "fire", 60.0, 1000.0, vertiport_id="Wq")
    assert p.update_constraint("add", EAST, 90.0) is None
    assert p.update_constraint("add", wq_closed, 90.0) is None
    res = p.plan(90.0, 3)
    got = {u.request_id: (u.kind, u.flight.destination_id if u.flight else None) for u in res.plan_updates}
    # Alternatives at t_eff = 90 (branch at mp / mq at t = 100; Wq closed; the east lanes blocked):
    #   P -> C lands 148 (w = 1 + 300/358), P turning back now from (-100, 0) lands at Wp at 180
    #   (w = 1 + 300/390), P -> Wp from mp lands 200 (w = 1 + 300/410)
    #   Q -> C lands 152 (w = 1 + 300/362), Q -> Wp via C, mp lands 300 (w = 1 + 300/510)
    # P -> C conflicts with both of Q's (Q is 40 m from C when P lands there at 148).
    # MWIS: {P -> Wp now, Q -> C} = 3.598 beats {P -> C} alone = 1.838.
    # First-fit in approval order: P takes C, Q has nothing left: a contingency, deconflicted
    # with every other flight: holding 30 s at mq (100 -> 130) it reaches C at 130 + 52 = 182,
    # when P has landed (148; at 148 Q is at (0, 820), 340 m from P), so P keeps C.
    if policy == "mwis":
        assert got == {"P": ("diverted", "Wp"), "Q": ("diverted", "C")}
    else:
        assert got == {"P": ("diverted", "C"), "Q": ("contingency", "C")}
        q = next(u for u in res.plan_updates if u.request_id == "Q")
        assert q.flight.contingent and "deconflicted with every other flight" in q.reason
        assert "holding 30 s" in q.reason
        np.testing.assert_allclose(q.flight.trajectory.times_s, [0.0, 100.0, 130.0, 182.0])
        assert flight_state(q.flight, 120.0) == "Contingent"
        assert res.report.replan.contingencies_fixed == 1 and res.report.replan.unresolved == 0
    assert res.report.replan.affected == 2 and res.report.replan.policy == policy
    assert min_flown_separation(res.plan_updates) >= 100.0


def min_flown_separation(updates, others=()):
    """The exact minimum distance between what flies (each update's chained versions and the
    flights ``others``), over every pair."""
    from uam_planner.separation import min_separation_m
    trs = [spliced_versions([u.previous, u.flight]) for u in updates if u.flight is not None]
    trs += [f.trajectory for f in others]
    return min((min_separation_m(a, b) for a, b in itertools.combinations(trs, 2)), default=math.inf)


#: over lane q only, east of mq: x in [400, 600], y in [900, 1100], 0-500 m, from t = 60 s
QEAST = Constraint("qeast", 1, "storm cell", 60.0, 1000.0, lower_m=-10.0, upper_m=500.0,
                   rings_m=(np.array([(400.0, 900.0), (600.0, 900.0), (600.0, 1100.0), (400.0, 1100.0)]),))
WQ_CLOSED = Constraint("Wq-closed", 1, "fire", 60.0, 1000.0, vertiport_id="Wq")


def contingency_case(monkeypatch=None, holds=None):
    """Q (Wq -> Eq, mq at 100) meets QEAST at x = 400 at t = 140; Wq is closed. From its branch
    point mq (t = 100) every alternative passes C: C itself (lands 100 + 52 = 152) and Wp through
    C and mp (lands 300); Wq, the other of the 3 nearest vertiports, is closed, so is turning
    back; Eq only through the cell. R (Wp -> mp -> C, unaffected) lands at C at 148, when Q is
    at (0, 520) on any of them: 40 m, a loss. So Q has no vertex: a contingency."""
    if holds is not None:
        import uam_planner.replanning as rp
        monkeypatch.setattr(rp, "HOLD_S", holds)
    p = planner()
    res = fly(p, req("Q", "Wq", "Eq"), req("R", "Wp", "C"))
    r = next(f for f in res.approved if f.request_id == "R")
    np.testing.assert_allclose(r.trajectory.times_s, [0.0, 100.0, 148.0])
    assert p.update_constraint("add", QEAST, 60.0) is None
    assert p.update_constraint("add", WQ_CLOSED, 60.0) is None
    return p, r, p.plan(60.0, 2)


def test_a_contingency_that_would_meet_a_neighbour_holds_and_keeps_separation():
    # Before: Q's contingency flew its least-conflicting alternative (C, landing at 152) NOT
    # deconflicted: 40 m from R at t = 148. Now it is a fixed flight: holding 30 s at mq (to 130)
    # then C at 182 loses separation with nobody (at 148 Q is still at (0, 820), 340 m from R),
    # so R is not touched.
    p, r, res = contingency_case()
    (u,) = res.plan_updates
    assert (u.request_id, u.kind, u.flight.destination_id) == ("Q", "contingency", "C")
    np.testing.assert_allclose(u.flight.trajectory.times_s, [0.0, 100.0, 130.0, 182.0])
    np.testing.assert_allclose(u.flight.trajectory.points_m[1:3], [(0, 1000, 0), (0, 1000, 0)])
    assert "holding 30 s at its branch point, deconflicted with every other flight" in u.reason
    assert "constraint 'qeast' v1 (storm cell)" in u.reason
    rep = res.report.replan
    assert (rep.contingencies_fixed, rep.pulled_in, rep.unresolved, rep.cascade_rounds) == (1, 0, 0, 1)
    assert [f.request_id for f in p.active] == ["R", "Q"]
    assert min_flown_separation(res.plan_updates, [r]) >= 100.0


def test_without_holds_the_neighbour_is_pulled_in_and_replanned_around_the_contingency(monkeypatch):
    # No holds: every alternative of Q meets R (one airborne flight each); the soonest landing,
    # C at 152, is fixed. R (unaffected) is pulled into the re-plan: its plan (C at 148) meets Q;
    # turning back at once from (-400, 0) it lands at Wp at 120 (before Wp or Ep from mp, both
    # at 200), never near Q (x = 0, y >= 480).
    p, r, res = contingency_case(monkeypatch, holds=())
    got = {u.request_id: u for u in res.plan_updates}
    q, rr = got["Q"], got["R"]
    assert (q.kind, q.flight.destination_id, q.flight.arrival_s) == ("contingency", "C", pytest.approx(152.0))
    assert (rr.kind, rr.flight.destination_id, rr.version) == ("diverted", "Wp", 2)
    np.testing.assert_allclose(rr.flight.trajectory.times_s, [0.0, 60.0, 120.0])
    assert "contingency flight 'Q'" in rr.reason and "'qeast'" in rr.reason
    assert rr.constraint_ids == ("qeast",)
    rep = res.report.replan
    assert (rep.affected, rep.pulled_in, rep.contingencies_fixed, rep.unresolved) == (1, 1, 1, 0)
    assert sorted(f.request_id for f in p.active) == ["Q", "R"]
    assert min_flown_separation(res.plan_updates) >= 100.0


def test_a_flight_that_would_enter_only_after_the_window_closes_is_not_replanned():
    # P reaches x = 400 at t = 140: a window closing at 140 is never entered ([start, end))
    for end, n_updates in ((140.0, 0), (140.5, 1)):
        p = planner()
        fly(p, req("P", "Wp", "Ep"))
        c = Constraint("east", 1, "", 60.0, end, lower_m=-10.0, upper_m=500.0, rings_m=EAST.rings_m)
        p.update_constraint("add", c, 60.0)
        res = p.plan(60.0, 2)
        assert len(res.plan_updates) == n_updates
        assert res.report.replan.affected == n_updates


def two_route_network():
    """A -> B directly through m (1 km) or around through n (2 x 707 m)."""
    return network_from_enu("two", ["A", "m", "n", "B"],
                            [(0, 0, 0), (500, 0, 0), (500, 500, 0), (1000, 0, 0)],
                            [True, False, False, True],
                            [("A", "m"), ("m", "B"), ("A", "n"), ("n", "B")])


OVER_M = (np.array([(400.0, -100.0), (600.0, -100.0), (600.0, 100.0), (400.0, 100.0)]),)


def slotted(k=2):
    return Planner(two_route_network(), PlanningConfig(k=k, airspace=AirspaceConfig(departure_slot_s=10.0)),
                   "mwis", solve_mwis=exact_mwis)


def test_a_flight_not_departed_is_retimed_rerouted_or_cancelled():
    # r1 asks to depart in [30, 50]: approved at epoch 0 for t = 30 (its only slot then), direct
    # (arrives 130). The cell over m opens at 30 and closes at 75: departing at 30 it would be at
    # x = 400 at 70 (inside), at 40 it gets there at 80 (after): re-timed to 40,
    # w = 2 + 1/(1 + 10/300) = 2.968 beats the detour at 30 (arrives 171.4: 2 + 1/(1 + 41.4/300)).
    c = Constraint("cell", 2, "", 30.0, 75.0, lower_m=-10.0, upper_m=500.0, rings_m=OVER_M)
    p = slotted()
    assert p.submit(req("r1", "A", "B", 0.0, earliest=30.0, latest=50.0)) is None
    (f,) = p.plan(0.0, 0).approved
    assert (f.departure_s, f.route_node_ids) == (30.0, ("A", "m", "B"))
    p.update_constraint("add", c, 10.0)
    res = p.plan(30.0, 1)
    (u,) = res.plan_updates
    assert (u.kind, u.flight.departure_s, u.flight.route_node_ids) == ("retimed", 40.0, ("A", "m", "B"))
    assert u.flight.weight == pytest.approx(2.0 + 1.0 / (1.0 + 10.0 / 300.0))
    assert flight_state(u.flight, 35.0) == "Accepted"
    # closed until 1000 instead: no slot of the direct route gets out, the detour at 30 does
    p = slotted()
    p.submit(req("r1", "A", "B", 0.0, earliest=30.0, latest=50.0))
    p.plan(0.0, 0)
    p.update_constraint("add", Constraint("cell", 2, "", 30.0, 1000.0, lower_m=-10.0, upper_m=500.0,
                                          rings_m=OVER_M), 10.0)
    (u,) = p.plan(30.0, 1).plan_updates
    assert (u.kind, u.flight.departure_s, u.flight.route_node_ids) == ("rerouted", 30.0, ("A", "n", "B"))
    # and with k = 1 (no detour) it is cancelled, naming the constraint
    p = slotted(k=1)
    p.submit(req("r1", "A", "B", 0.0, earliest=30.0, latest=50.0))
    p.plan(0.0, 0)
    p.update_constraint("add", Constraint("cell", 2, "hail", 30.0, 1000.0, lower_m=-10.0, upper_m=500.0,
                                          rings_m=OVER_M), 10.0)
    res = p.plan(30.0, 1)
    (u,) = res.plan_updates
    assert (u.kind, u.flight, u.version) == ("cancelled", None, 2)
    assert "constraint 'cell' v2 (hail)" in u.reason
    assert p.active == [] and res.approved == []


def test_bad_updates_are_refused_naming_the_field_and_nothing_is_lost():
    p = planner()
    assert p.update_constraint("add", EAST, 10.0) is None
    before = list(p.queued_updates)
    assert "action: 'move'" in p.update_constraint("move", EAST, 10.0)
    assert "constraint_id: 'east' is already a constraint" in p.update_constraint("add", EAST, 10.0)
    lower = Constraint("east", 0, "", 60.0, 1000.0, center_m=(0.0, 0.0), radius_m=50.0)
    assert "version: 0 of 'east' is not above the current version 1" in p.update_constraint("change", lower, 10.0)
    unknown = Constraint("nope", 5, "", 60.0, 1000.0, center_m=(0.0, 0.0), radius_m=50.0)
    assert "constraint_id: 'nope' is not a known constraint" in p.update_constraint("change", unknown, 10.0)
    assert "constraint_id: 'nope'" in p.update_constraint("withdraw", "nope", 10.0)
    past = Constraint("old", 1, "", 0.0, 5.0, center_m=(0.0, 0.0), radius_m=50.0)
    assert "end_s: 5.0 is in the past (now is 10.0 s)" in p.update_constraint("add", past, 10.0)
    closed = Constraint("z", 1, "", 0.0, 50.0, vertiport_id="mp")
    assert "vertiport_id: 'mp' is not a vertiport" in p.update_constraint("add", closed, 10.0)
    assert "t_s: nan" in p.update_constraint("add", unknown, float("nan"))
    assert p.queued_updates == before
    # a change with a higher version and a withdrawal are accepted, applied in order
    bigger = Constraint("east", 2, "", 60.0, 1000.0, center_m=(500.0, 0.0), radius_m=50.0)
    assert p.update_constraint("change", bigger, 20.0) is None
    assert p.update_constraint("withdraw", "east", 25.0) is None
    p.plan(30.0, 1)
    assert [(u.action, u.constraint.version, u.applied_s) for u in p.constraint_log] == \
        [("add", 1, 30.0), ("change", 2, 30.0), ("withdraw", 2, 30.0)]
    assert len(p.config.constraints) == 0


def test_announced_constraint_from_geojson_applies_at_its_first_epoch(tmp_path):
    net = lanes()
    doc = {"type": "FeatureCollection", "frame": "enu", "features": [{
        "type": "Feature", "geometry": {"type": "Point", "coordinates": [500.0, 0.0]},
        "properties": {"id": "tfr", "version": 1, "reason": "VIP", "start_s": 60.0, "end_s": 900.0,
                       "announce_s": 45.0, "radius_m": 50.0, "lower_m": -10.0, "upper_m": 300.0}}]}
    path = tmp_path / "c.geojson"
    path.write_text(json.dumps(doc))
    cs = load_constraints(path, net)
    assert cs.constraints[0].announce_s == 45.0
    p = Planner(net, PlanningConfig(k=2), "mwis", solve_mwis=exact_mwis)
    p.set_constraints(cs)
    assert len(p.config.constraints) == 0 and len(p.queued_updates) == 1
    fly(p, req("P", "Wp", "Ep"))
    # at t = 30 it is not announced yet: a request planned then flies through (no detour asked)
    assert p.submit(req("P2", "Wq", "Eq", 30.0)) is None
    r30 = p.plan(30.0, 1)
    assert [f.request_id for f in r30.approved] == ["P2"] and r30.plan_updates == []
    r60 = p.plan(60.0, 2)   # announced at 45: applied at the first epoch >= 45
    assert [u.request_id for u in r60.plan_updates] == ["P"]    # P2's lane is 1 km north
    assert [c.constraint_id for c in p.config.constraints] == ["tfr"]


def test_announce_after_the_end_is_refused():
    from uam_planner.constraints import ConstraintError
    with pytest.raises(ConstraintError, match=r"announce_s: 950.0 is not before end_s 900.0"):
        Constraint("x", 1, "", 60.0, 900.0, center_m=(0.0, 0.0), radius_m=5.0, announce_s=950.0)


def test_spliced_versions_chain_and_a_gap_is_refused():
    old = Trajectory(np.array([0.0, 100.0, 200.0]), np.array([(0, 0, 0), (1000, 0, 0), (2000, 0, 0)], float))
    new = Trajectory(np.array([0.0, 100.0, 150.0]), np.array([(0, 0, 0), (1000, 0, 0), (1000, 500, 0)], float))
    s = spliced(old, new, 60.0)
    np.testing.assert_allclose(s.times_s, [0.0, 60.0, 100.0, 150.0])
    np.testing.assert_allclose(s.points_m[1], (600, 0, 0))
    bad = Trajectory(np.array([0.0, 150.0]), np.array([(0, 10, 0), (1000, 500, 0)], float))
    with pytest.raises(ValueError, match="versions do not chain"):
        spliced(old, bad, 60.0)
    # a version replacing one that had not departed is simply the new one
    later = old.shifted(100.0)
    assert spliced(later, new, 60.0) is new


def test_audit_of_what_flew_finds_no_incursion_where_the_old_plans_had_one():
    """C and Wq closed too: both turn back to Wp (P lands at 200, Q, through C and mp, at 300);
    what flew stays out, the old plans would not have."""
    p = planner(replan_policy="firstfit")
    fly(p, req("P", "Wp", "Ep"), req("Q", "Wq", "Eq"))
    for c in (EAST, Constraint("Wq-closed", 1, "", 60.0, 1000.0, vertiport_id="Wq"),
              Constraint("C-closed", 1, "", 60.0, 1000.0, vertiport_id="C")):
        assert p.update_constraint("add", c, 60.0) is None
    res = p.plan(60.0, 2)
    kinds = {u.request_id: u.kind for u in res.plan_updates}
    # P: back to Wp (lands 200). Q: Wp through C and mp (the closure of C forbids only landing
    # there), arriving 300 - P has landed at 200, so it is free: no contingency after all
    assert kinds == {"P": "diverted", "Q": "diverted"}
    flown = {u.request_id: spliced_versions([u.previous, u.flight]) for u in res.plan_updates}
    ends = {u.request_id: (u.flight.origin_id, u.flight.destination_id) for u in res.plan_updates}
    tl = constraint_timeline(p.initial_constraints, p.constraint_log)
    assert planner_violations_as_flown(flown, tl, p.network, ends) == []
    # the old plans would have entered the cell (x = 400 at t = 140) had they been flown
    old = {u.request_id: u.previous.trajectory for u in res.plan_updates}
    old_ends = {u.request_id: (u.previous.origin_id, u.previous.destination_id) for u in res.plan_updates}
    got = sorted(planner_violations_as_flown(old, tl, p.network, old_ends))
    assert got == [("P", "'east' v1 (storm cell)", pytest.approx(140.0)),
                   ("Q", "'east' v1 (storm cell)", pytest.approx(140.0))]


def test_paper_mode_flights_default_to_version_one():
    p = planner()
    (f,) = fly(p, req("P", "Wp", "Ep")).approved
    assert (f.version, f.effective_s, f.contingent) == (1, 0.0, False)
    assert p.replan_policy() == "mwis" and Planner(lanes(), policy="fifo").replan_policy() == "firstfit"
    with pytest.raises(ValueError, match="replan_policy"):
        PlanningConfig(replan_policy="best")


def layered_lanes():
    """The lanes at one level (60 m, no direction rule); C has two pads, (0, 480) and (150, 480)."""
    base = lanes()
    return network_from_enu("lanes-layered", list(base.node_ids), base.enu_m, base.is_aerodrome,
                            [(base.node_ids[a], base.node_ids[b]) for a, b in base.edges],
                            airspace={"levels_m": [60.0], "direction_rule": "none"},
                            pads_m={"C": [[0.0, 0.0], [150.0, 0.0]]})


def test_airborne_flight_diverted_to_the_free_pad_of_the_alternate():
    """Climb 5 m/s, descent 3 m/s. P: Wp -> mp -> Ep at 60 m: top of climb at 12 s, mp at 112,
    Ep at 212. R: Wq -> mq -> C pad 0 (the only level's pad), over pad 0 at 164, down at 184."""
    net = layered_lanes()
    p = Planner(net, PlanningConfig(k=2), "mwis", solve_mwis=exact_mwis)
    fly(p, req("P", "Wp", "Ep"), req("R", "Wq", "C"))
    np.testing.assert_allclose(p.active[1].trajectory.times_s, [0.0, 12.0, 112.0, 164.0, 184.0], atol=0.05)
    p.update_constraint("add", EAST, 90.0)
    (u,) = p.plan(90.0, 3).plan_updates
    # At t_eff = 90 P is at (-220, 0, 60); turning back lands at 90 + 78 + 20 = 188 (98 s after).
    # Branch at mp (112 s). C pad 0: over it at 160, descending until 180 while R descends there
    # from 164: 12 m apart at 164, a loss. C pad 1 (150, 480): 502.9 m -> over it at 162.3, down at
    # 182.3, never within 100 m of R: chosen (lands 92.3 s after t_eff: w = 1 + 300/392.3, above
    # turning back's 1 + 300/398 and Wp's from mp 1 + 300/442).
    assert (u.kind, u.flight.destination_id) == ("diverted", "C")
    tr = u.flight.trajectory
    np.testing.assert_allclose(tr.points_m[-2:], [(150, 480, 60), (150, 480, tr.points_m[-1, 2])])
    assert tr.points_m[-1, 2] < 0.1                      # the pad (ground, about 0 m)
    np.testing.assert_allclose(tr.times_s[-2:], [112.0 + math.hypot(150, 480) / 10.0,
                                                 112.0 + math.hypot(150, 480) / 10.0 + 20.0], atol=0.05)
    np.testing.assert_allclose(tr.times_s[:3], [0.0, 12.0, 112.0], atol=0.05)   # the old plan up to mp
    assert u.flight.weight == pytest.approx(divert_weight(tr.arrival_s - 90.0))


def test_clipped_from_cuts_at_any_instant():
    from uam_planner.replanning import clipped_from
    tr = Trajectory(np.array([0.0, 100.0, 200.0]), np.array([(0, 0, 0), (1000, 0, 0), (1000, 1000, 0)], float))
    c = clipped_from(tr, 150.0)
    np.testing.assert_allclose(c.times_s, [150.0, 200.0])
    np.testing.assert_allclose(c.points_m, [(1000, 500, 0), (1000, 1000, 0)])
    assert clipped_from(tr, -5.0) is tr and clipped_from(tr, 200.0) is None
    c = clipped_from(tr, 200.0 - 1e-12)         # within rounding of the arrival
    assert c.times_s[-1] == 200.0 and c.times_s[0] < 200.0
    np.testing.assert_allclose(clipped_from(tr, 100.0).points_m[0], (1000, 0, 0))


def held_at(x_m, t0=60.0, t1=300.0, rid="H"):
    """A flight the planner holds past its plan (issue 23): its projection hovers at (x, 0, 0)."""
    return rid, Trajectory(np.array([t0, t1]), np.array([(x_m, 0.0, 0.0), (x_m, 0.0, 0.0)]))


@pytest.mark.parametrize("policy", ["mwis", "firstfit"])
def test_the_replan_avoids_a_flight_held_past_its_plan(policy):
    # P (Wp 0 -> mp 100 -> Ep 200) meets the cell at t_eff = 60 at (-400, 0): alone it turns back
    # to Wp (lands at 120, test above). A late flight H is held hovering at (-700, 0) from 60 to
    # 300 s (its projection): turning back passes it at t = 90, 0 m away. So P must take the next
    # alternative, C from mp (lands at 148), which stays >= 400 m from H ((-400,0)->(0,0)->(0,480)).
    from uam_planner.planning import departure_slots_s, replan_selector
    from uam_planner.replanning import replan
    from uam_planner.separation import SegmentSet, conflicting_pairs

    def run(held):
        p = planner()
        fly(p, req("P", "Wp", "Ep"))
        from uam_planner.replanning import ConstraintUpdate, apply_updates
        cfg = p.config
        cset = apply_updates(cfg.constraints, [ConstraintUpdate("add", EAST, 60.0, 0)], p.network)
        from dataclasses import replace as dc_replace
        cfg = dc_replace(cfg, constraints=cset)
        _active, updates, _rep = replan(60.0, 2, p.active, p._requests, p.network, cfg, p.cache, cset,
                                        replan_selector(p.solve_mwis, cfg, 2, 60.0),
                                        lambda t, r: departure_slots_s(t, r, cfg), policy, held=held)
        (u,) = updates
        return u

    alone = run([])
    assert (alone.kind, alone.flight.destination_id, alone.flight.route_node_ids) == ("diverted", "Wp", ("Wp",))
    h = held_at(-700.0)
    u = run([h])
    assert (u.kind, u.flight.destination_id, u.flight.route_node_ids) == ("diverted", "C", ("Wp", "mp", "C"))
    np.testing.assert_allclose(u.flight.trajectory.times_s, [0.0, 100.0, 148.0])
    a, b = SegmentSet.from_trajectories([u.flight.trajectory]), SegmentSet.from_trajectories([h[1]])
    sep = planner().config.separation
    assert len(conflicting_pairs(a, b, sep)) == 0
    assert len(conflicting_pairs(SegmentSet.from_trajectories([alone.flight.trajectory]), b, sep)) > 0
    # a flight's own projection does not block its own re-plan
    assert run([("P", h[1])]).flight.destination_id == "Wp"


def test_the_planner_passes_its_held_flights_to_the_replan(monkeypatch):
    # the same case through Planner.plan: the planner's overruns (issue 23) reach the re-plan
    from dataclasses import replace as dc_replace
    from types import SimpleNamespace
    p = planner()
    fly(p, req("P", "Wp", "Ep"))
    rid, tr = held_at(-700.0)
    ghost = dc_replace(p.active[0], request_id=rid, trajectory=tr, departure_s=60.0, arrival_s=300.0)
    monkeypatch.setattr(Planner, "_hold_overruns", lambda self, t: None)
    p.overruns = {rid: SimpleNamespace(flights=[ghost], until_s=300.0)}
    p.update_constraint("add", EAST, 60.0)
    (u,) = p.plan(60.0, 2).plan_updates
    assert (u.kind, u.flight.destination_id) == ("diverted", "C")


# ---- issue 22, fourth stop: the decision's speed-ups decide exactly what the old code did ---------

def test_pad_of_a_point_is_the_one_the_norm_and_argmin_pick():
    """``pad_of_point`` in scalars against the former numpy formula (the reference here), to the
    index, on random points and on points exactly as near to two pads (the first wins)."""
    from uam_planner.replanning import pad_of_point
    net = network_from_enu("pads", ["A", "B", "m"], [(0, 0, 0), (1000, 0, 0), (500, 300, 0)],
                           [True, True, False], [("A", "m"), ("m", "B")],
                           airspace={"levels_m": [60.0], "direction_rule": "none"},
                           pads_m={"A": [[0.0, 0.0], [30.0, 0.0], [0.0, 30.0], [30.0, 30.0]]})
    centre = net.enu_m[0, :2]
    pads = net.pads_of(0)

    def reference(xy):
        return int(np.argmin(np.linalg.norm(centre + np.asarray(pads) - np.asarray(xy)[:2], axis=1)))

    rng = np.random.default_rng(22)
    pts = [rng.uniform(-60.0, 90.0, 2) for _ in range(2000)]
    pts += [(15.0, 0.0), (15.0, 15.0), (0.0, 15.0), (30.0, 15.0), (15.0, 30.0)]  # exact ties
    pts += [(x, y, 60.0) for x, y in rng.uniform(-5.0, 35.0, (200, 2))]        # with a height
    got = [pad_of_point(net, 0, p) for p in pts]
    assert got == [reference(p) for p in pts]
    assert got[2000:2005] == [0, 0, 0, 1, 2]
    assert pad_of_point(net, 1, (999.0, 5.0)) == 0          # one pad: always 0


def test_constraint_free_in_one_call_is_one_call_per_flight():
    """The batched constraint test of the re-plan (every affected flight's alternatives in one
    ``ConstraintSet.violations`` call) keeps exactly the alternatives a call per flight keeps,
    in their order, with closures at the origin of the flights not departed only."""
    from uam_planner.constraints import ConstraintSet
    from uam_planner.replanning import _Alt, _constraint_free, _constraint_free_many
    net = lanes()
    closed = Constraint("shut", 1, "Ep closed", 0.0, 1000.0, vertiport_id="Ep")
    cset = ConstraintSet([EAST, closed], net)
    wp, ep, c, eq = (net.node_index(x) for x in ("Wp", "Ep", "C", "Eq"))

    def alt(xs, dest, t0=0.0):
        pts = np.array([(x, y, 0.0) for x, y in xs])
        legs = np.linalg.norm(np.diff(pts, axis=0), axis=1)
        return _Alt(Trajectory(t0 + np.concatenate(([0.0], np.cumsum(legs / 10.0))), pts), "rerouted",
                    1.5, dest, (), float(legs.sum()))

    through = alt([(-1000, 0), (0, 0), (1000, 0)], ep)              # enters EAST, lands at the closure
    to_c = alt([(-1000, 0), (0, 0), (0, 480)], c)                   # stays out
    north = alt([(-1000, 1000), (0, 1000), (1000, 1000)], eq)       # enters EAST
    late = alt([(-1000, 1000), (0, 1000), (0, 480)], c, 2000.0)    # after both windows
    from_ep = alt([(1000, 0), (1000, 480), (700, 480)], c, 10.0)    # leaves the closed Ep, east of EAST
    groups = [([through, to_c], None), ([north, late, to_c], wp), ([], None), ([from_ep], ep),
              ([from_ep, to_c], None)]
    batch = _constraint_free_many(groups, cset, 5.0, net)
    assert batch == [_constraint_free(a, cset, 5.0, net, o) for a, o in groups]
    assert [[id(a) for a in g] for g in batch] == [[id(to_c)], [id(late), id(to_c)], [], [],
                                                   [id(from_ep), id(to_c)]]


def test_nearest_vertiports_in_the_order_of_the_sort_by_distance_then_index():
    """The diversion targets (``_nearest``) against the former sort by (hypot, index), on random
    points and on a ring of nodes all exactly as far from the point (ties: lowest index first)."""
    from uam_planner.replanning import _nearest
    rng = np.random.default_rng(7)
    xy = np.concatenate((rng.uniform(-5000.0, 5000.0, (300, 2)),
                         [(100.0, 0.0), (-100.0, 0.0), (0.0, 100.0), (0.0, -100.0)]))
    nodes = np.array([i for i in range(xy.shape[0]) if i % 7 or i >= 300], dtype=np.int64)

    def reference(at, n):
        return sorted(nodes.tolist(), key=lambda a: (float(np.hypot(*(xy[a] - at))), a))[:n]

    for at in [rng.uniform(-5000.0, 5000.0, 2) for _ in range(200)] + [np.zeros(2)]:
        for n in (1, 3, 10):
            assert _nearest(xy, nodes, at, n) == reference(at, n)
    assert _nearest(xy, nodes, np.zeros(2), 4) == [300, 301, 302, 303]  # the tied ring, by index
