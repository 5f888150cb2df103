"""Objectives (issue 21): hand-computed weights and selections for every objective, the bounded
integer scheme, the baselines' priority order and the planner's plumbing."""

from collections import Counter

import numpy as np
import pytest

import uam_solvers
from uam_solvers.base import MwisProblem, brute_force_mwis
from uam_planner.network import network_from_enu
from uam_planner.objectives import (FLOAT_EXACT, ObjectiveRangeError, OperatorShares,
                                    epoch_weights, lexicographic_weights, order_requests,
                                    priority_values)
from uam_planner.planning import AirspaceConfig, FlightRequest, Planner, PlanningConfig


def req(rid, t=0.0, earliest=None, latest=None, priority=0, operator=""):
    e = t if earliest is None else earliest
    return FlightRequest(rid, "A", "B", e, e, e + 60.0 if latest is None else latest,
                         priority=priority, operator_id=operator)


def best(weights, edges, groups):
    sel, _ = brute_force_mwis(MwisProblem.from_arrays(weights, edges, groups))
    return sel.tolist()


# ---- count vs paper ------------------------------------------------------------------------------

# Two requests, each with a direct candidate (T = 100 s) and a detour (T = 300 s), departing at
# t = 0. Vertices 0, 1 = request 0 direct, detour; 2, 3 = request 1 direct, detour. Only the two
# detours are compatible: 0-2, 0-3 and 1-2 conflict (plus the request cliques 0-1, 2-3).
TWO_REQ_EDGES = [[0, 1], [2, 3], [0, 2], [0, 3], [1, 2]]
TWO_REQ = dict(req_of=[0, 0, 1, 1], departure_s=[0.0] * 4, duration_s=[100.0, 300.0, 100.0, 300.0],
               paper_weights=[1.0, 1 / 3, 1.0, 1 / 3])


def test_count_approves_two_detours_where_paper_takes_one_direct_flight():
    requests = [req("r0"), req("r1")]
    groups = [[0, 1], [2, 3]]
    paper = epoch_weights("paper", 0.0, 30.0, requests, **TWO_REQ).weights
    # paper: {direct} = 1 > {detour, detour} = 2/3
    assert best(paper, TWO_REQ_EDGES, groups) == [0]
    count = epoch_weights("count", 0.0, 30.0, requests, **TWO_REQ)
    # added cost c = 0, 200 s for each request; Q = 201; B = 2 * 201 + 1 = 403;
    # w = B + (Q - c) = 604 (direct), 404 (detour)
    assert count.weights.tolist() == [604.0, 404.0, 604.0, 404.0]
    assert count.step_s == 1 and count.exact_for_integer_backends
    assert best(count.weights, TWO_REQ_EDGES, groups) == [1, 3]  # 808 > 604
    # the exact backend (CP-SAT: integer weights) finds the same optimum and proves it
    res = uam_solvers.solve(count.weights, TWO_REQ_EDGES, groups=groups, backend="exact")
    assert res.selected.tolist() == [1, 3] and res.proven_optimal


def test_count_prefers_less_delay_among_sets_of_equal_size():
    # one request, two departures 0 s and 20 s later, same flight time: c = 0, 20; Q = 21,
    # B = 22: w = 43, 23
    w = epoch_weights("count", 0.0, 30.0, [req("r0")], [0, 0], [0.0, 20.0], [100.0, 100.0],
                      [1.0, 100 / 120]).weights
    assert w.tolist() == [43.0, 23.0]


# ---- the bounded scheme --------------------------------------------------------------------------

def test_lexicographic_weights_coarsen_only_the_secondary_term_to_stay_within_w_max():
    # m = 4, w_max = 100: Q may be at most (100 - 1) // (4 + 1) = 19 levels; costs up to 95 s
    # need steps of ceil(95 / 18) = 6 s: c = 0, 1, 2, 16; Q = 17; q = 17, 16, 15, 1;
    # B = 4 * 17 + 1 = 69: w = 86, 85, 84, 70 (<= 100)
    out = lexicographic_weights(np.ones(4, dtype=int), [0.0, 5.0, 10.0, 95.0], 4, w_max=100)
    assert out.weights.tolist() == [86.0, 85.0, 84.0, 70.0]
    assert out.step_s == 6 and out.exact_for_integer_backends
    # four approvals always beat three, whatever their costs: 4 * 70 > 3 * 86 + 69
    assert 4 * 70 > 3 * 86
    # w_max too small for even two levels: the primary term alone (w = 1), never rounded
    out = lexicographic_weights(np.ones(4, dtype=int), [0.0, 5.0, 10.0, 95.0], 4, w_max=5)
    assert out.weights.tolist() == [1.0] * 4 and out.step_s == 0


def test_priority_values_outweigh_every_lower_class_combined_and_overflow_is_an_error():
    # classes 0 (x3), 2 (x2), 7 (x1): P = 1; 1 + 3 = 4; 1 + 3 + 2 * 4 = 12
    assert priority_values([0, 2, 0, 7, 2, 0]).tolist() == [1, 4, 1, 12, 4, 1]
    # 40 classes of 2 requests: P_r = 3^r, past 2^53 at r = 34
    many = [r for r in range(40) for _ in range(2)]
    assert int(max(priority_values(many))) == 3**39 > FLOAT_EXACT
    n = len(many)
    with pytest.raises(ObjectiveRangeError, match=r"priority: 40 classes over 80 requests"):
        epoch_weights("priority", 0.0, 30.0, [req(f"r{i}", priority=p) for i, p in enumerate(many)],
                      list(range(n)), [0.0] * n, [100.0] * n, [1.0] * n)
    # 14 classes of 2: 3^13 = 1,594,323 > w_max = 10^6 but exact in float64: flagged, still
    # exact whole numbers (q dropped: step 0)
    few = [r for r in range(14) for _ in range(2)]
    out = epoch_weights("priority", 0.0, 30.0, [req(f"r{i}", priority=p) for i, p in enumerate(few)],
                        list(range(28)), [0.0] * 28, [100.0] * 28, [1.0] * 28)
    assert not out.exact_for_integer_backends
    assert out.weights.max() == 3**13 and out.step_s == 0


def test_one_high_priority_flight_beats_three_low_ones():
    # h (class 1) conflicts with l1, l2, l3 (class 0); the low ones are compatible.
    requests = [req("l1"), req("l2"), req("l3"), req("h", priority=1)]
    edges = [[0, 3], [1, 3], [2, 3]]
    kw = dict(req_of=[0, 1, 2, 3], departure_s=[0.0] * 4, duration_s=[100.0] * 4,
              paper_weights=[1.0] * 4)
    count = epoch_weights("count", 0.0, 30.0, requests, **kw).weights
    assert best(count, edges, None) == [0, 1, 2]
    # P = 1 (x3), 4; costs 0: Q = 1, B = 4 * 1 + 1 = 5; w = 1 * 5 + 1 = 6 (low), 4 * 5 + 1 = 21
    prio = epoch_weights("priority", 0.0, 30.0, requests, **kw).weights
    assert prio.tolist() == [6.0, 6.0, 6.0, 21.0]
    assert best(prio, edges, None) == [3]  # 21 > 18
    res = uam_solvers.solve(prio, edges, backend="exact")
    assert res.selected.tolist() == [3] and res.proven_optimal


# ---- delay -----------------------------------------------------------------------------------------

def test_delay_counts_from_the_earliest_departure_and_gives_a_last_chance_urgency():
    # t = 0, epoch 30 s. u: earliest -30 (waited 30 s), latest 10 (< next epoch 30: urgent);
    # n: earliest 0, latest 60. Each: direct (T = 100 s) and detour (T = 120 s).
    # u: D_not = 10 + 30 + 2 * 30 = 100 (refused); D = 30 + 0 (direct), 30 + 20 (detour):
    #    w = 70, 50.  n: D_not = 30 (next epoch); D = 0, 20: w = 30, 10.
    requests = [req("u", earliest=-30.0, latest=10.0), req("n")]
    w = epoch_weights("delay", 0.0, 30.0, requests, [0, 0, 1, 1], [0.0] * 4,
                      [100.0, 120.0, 100.0, 120.0], [1.0, 100 / 120, 1.0, 100 / 120]).weights
    assert w.tolist() == [70.0, 50.0, 30.0, 10.0]
    # the directs conflict, and u's direct with n's detour: {u detour, n direct} 80 >
    # {u direct} 70 ... but u direct + n detour is out; so 80 wins and u still flies
    edges = [[0, 1], [2, 3], [0, 2], [0, 3]]
    assert best(w, edges, [[0, 1], [2, 3]]) == [1, 2]
    # a candidate worse than waiting keeps weight 1 (taking it is still better than nothing now)
    w = epoch_weights("delay", 0.0, 30.0, [req("n")], [0], [0.0], [200.0], [1.0]).weights
    assert w.tolist() == [30.0]  # the best candidate has no detour: 30 - 0
    w = epoch_weights("delay", 0.0, 30.0, [req("n")], [0, 0], [0.0, 0.0], [100.0, 200.0],
                      [1.0, 0.5]).weights
    assert w.tolist() == [30.0, 1.0]  # 30 - 100 -> 1


# ---- fair ------------------------------------------------------------------------------------------

def test_fair_serves_the_operator_behind_where_count_sees_a_tie():
    # a: 10 requests decided so far, 10 approved; b: 10 decided, 2 approved.
    # phi_a = round(10 * 11 / 11) = 10; phi_b = round(10 * 11 / 3) = round(36.67) = 37
    shares = OperatorShares(Counter(a=10, b=10), Counter(a=10, b=2))
    # an operator not seen yet: round(10 * 1 / 1) = 10
    assert (shares.factor("a"), shares.factor("b"), shares.factor("new")) == (10, 37, 10)
    requests = [req("a1", operator="a"), req("b1", operator="b")]
    # one candidate each, in conflict (a request's only candidate adds no cost: c = 0):
    # Q = 1, B = 2 * 1 + 1 = 3
    kw = dict(req_of=[0, 1], departure_s=[0.0, 0.0], duration_s=[100.0, 110.0],
              paper_weights=[1.0, 1.0])
    count = epoch_weights("count", 0.0, 30.0, requests, **kw).weights
    assert count.tolist() == [4.0, 4.0]  # count: a tie
    fair = epoch_weights("fair", 0.0, 30.0, requests, shares=shares, **kw).weights
    assert fair.tolist() == [10 * 3 + 1.0, 37 * 3 + 1.0]  # 31 < 112: b
    assert best(fair, [[0, 1]], None) == [1]
    # an operator far behind counts at most FAIR_MAX_RATIO times: (10 * 1001 / 1) -> 100
    assert OperatorShares(Counter(c=1000), Counter()).factor("c") == 100


def one_route_network():
    """C and D 1 km apart with one route C-m-D: two requests at the same time always conflict."""
    return network_from_enu("one-route", ["C", "D", "m"], [(0, 0, 0), (1000, 0, 0), (500, 0, 0)],
                            [True, True, False], [("C", "m"), ("m", "D")])


def run_two_operators(objective, epochs=4):
    """Each epoch, operators a and b (in that order) ask C -> D to depart now (window 0 s): only
    one can fly; the other expires."""
    p = Planner(one_route_network(), PlanningConfig(objective=objective, backend="exact"), "mwis")
    won = []
    for e in range(epochs):
        t = 30.0 * e
        for op in ("a", "b"):
            assert p.submit(FlightRequest(f"{op}{e}", "C", "D", t, t, t, operator_id=op)) is None
        res = p.plan(t, e)
        won += [f.operator_id for f in res.approved]
    return won, p


def test_fair_balances_two_operators_over_epochs_where_count_serves_one():
    won, p = run_two_operators("count")
    assert len(won) == 4 and len(set(won)) == 1  # a tie every epoch, broken the same way
    won, p = run_two_operators("fair")
    # counts of decided requests: epoch 0: nothing decided, phi = 10 each (tie); epoch 1: the
    # winner's phi is round(10 * 2 / 2) = 10, the other's round(10 * 2 / 1) = 20: the other
    # flies; epoch 2: a tie again; epoch 3: 13 against 20. 2 each
    assert sorted(Counter(won).values()) == [2, 2]
    assert p.shares.approved == Counter(a=2, b=2) and p.shares.requested == Counter(a=4, b=4)


# ---- the baselines' order --------------------------------------------------------------------------

def two_route_network():
    """As in test_first_fit: A-B straight via m1 or detour via m2; C-m1-D crosses the straight
    A-B route at m1 at the same time."""
    return network_from_enu(
        "two-route", ["A", "B", "m1", "m2", "C", "D"],
        [(0, 0, 0), (1000, 0, 0), (500, 0, 0), (500, -800, 0), (500, 500, 0), (500, -500, 0)],
        [True, True, False, False, True, True],
        [("A", "m1"), ("m1", "B"), ("A", "m2"), ("m2", "B"), ("C", "m1"), ("m1", "D")])


@pytest.mark.parametrize("policy", ["firstfit", "fifo"])
def test_baselines_serve_priority_first_with_baseline_order_priority(policy):
    # r1 A->B arrives first (class 0), r2 C->D second (class 1); their direct routes cross.
    requests = [FlightRequest("r1", "A", "B", 0, 0, 60), FlightRequest("r2", "C", "D", 0, 0, 60, priority=1)]
    out = {}
    for order in ("arrival", "priority"):
        p = Planner(two_route_network(), PlanningConfig(baseline_order=order), policy)
        for r in requests:
            assert p.submit(r) is None
        out[order] = [(f.request_id, f.candidate_index) for f in p.plan(0.0, 0).approved]
    # arrival: r1 takes its straight route first and blocks r2
    assert out["arrival"] == [("r1", 0)]
    # priority: r2 first; first-fit then gives r1 its detour (candidate 1), FIFO makes r1 wait
    assert out["priority"] == ([("r2", 0), ("r1", 1)] if policy == "firstfit" else [("r2", 0)])


def test_order_requests_priority_then_deadline_then_arrival():
    rs = [req("a", latest=60), req("b", latest=20), req("c", latest=60, priority=2),
          req("d", latest=20)]
    assert [r.request_id for r in order_requests(rs, "priority")] == ["c", "b", "d", "a"]
    assert [r.request_id for r in order_requests(rs, "arrival")] == ["a", "b", "c", "d"]
    with pytest.raises(ValueError, match=r"baseline_order must be one of .* got 'fast'"):
        order_requests(rs, "fast")


# ---- plumbing and validation -----------------------------------------------------------------------

def test_planner_weights_follow_the_objective():
    # r1 A->B: straight 1,000 m (T = 100 s), detour 1,886.8 m (T = 188.68 s, c = ceil 88.68 = 89);
    # r2 C->D: one route, c = 0. count: Q = 90, B = 2 * 90 + 1 = 181: 271, 182, 271;
    # the MWIS takes r1's detour and r2 (453 > 271)
    p = Planner(two_route_network(), PlanningConfig(objective="count", backend="exact"), "mwis")
    for r in (FlightRequest("r1", "A", "B", 0, 0, 60), FlightRequest("r2", "C", "D", 0, 0, 60)):
        assert p.submit(r) is None
    res = p.plan(0.0, 0)
    assert res.report.weights.tolist() == [271.0, 182.0, 271.0]
    assert sorted((f.request_id, f.candidate_index, f.weight) for f in res.approved) == [
        ("r1", 1, 182.0), ("r2", 0, 271.0)]


def test_bad_objective_priority_and_order_are_named():
    with pytest.raises(ValueError, match=r"PlanningConfig.objective: 'speed' is not an objective; known: paper, count"):
        PlanningConfig(objective="speed")
    with pytest.raises(ValueError, match=r"PlanningConfig.baseline_order must be one of .* got 1"):
        PlanningConfig(baseline_order=1)
    p = Planner(two_route_network())
    assert p.submit(FlightRequest("r1", "A", "B", 0, 0, 60, priority=256)) == \
        "priority: 256 is not an integer in [0, 255]"
    assert p.submit(FlightRequest("r2", "A", "B", 0, 0, 60, priority=1.5)) == \
        "priority: 1.5 is not an integer in [0, 255]"
    assert p.submit(FlightRequest("r3", "A", "B", 0, 0, 60, priority=255)) is None


def test_count_selects_a_maximum_cardinality_set_in_every_epoch_of_a_busy_run():
    """On the Singapore network at 20 requests per 30 s, each epoch's count-objective optimum
    (CP-SAT, proven) has as many flights as the largest independent set of the same graph (CP-SAT
    on unit weights, proven): the lexicographic weights survive the integer backend exactly."""
    from pathlib import Path

    from uam_planner.network import load_network

    net = load_network(Path(__file__).resolve().parents[3] / "config" / "networks" / "singapore.yaml")
    p = Planner(net, PlanningConfig(objective="count", backend="exact"))
    rng = np.random.default_rng(1)
    checked = 0
    for e in range(8):
        t = 30.0 * e
        for j in range(20):
            o, d = rng.choice(len(net.aerodrome_ids), 2, replace=False)
            p.submit(FlightRequest(f"r{e}_{j}", net.aerodrome_ids[o], net.aerodrome_ids[d], t, t, t + 60.0))
        prep = p.prepare(t, e)
        g = prep.graph
        ans = None
        if prep.needs_solver:
            ans = uam_solvers.solve(g.weights, g.edges, groups=g.groups, backend="exact", time_limit_s=20)
            card = uam_solvers.solve(np.ones(g.n_vertices), g.edges, groups=g.groups, backend="exact",
                                     time_limit_s=20)
            assert ans.proven_optimal and card.proven_optimal
            assert len(ans.selected) == len(card.selected), e
            assert np.all(g.weights == np.floor(g.weights)) and g.weights.max() <= 10**6
            checked += 1
        p.commit(prep, ans)
    assert checked >= 6


# ---- the planning horizon --------------------------------------------------------------------------

def run_horizon(h, slot_s=0.0):
    """One route C-m-D (100 s): r1 (class 1) may depart at 0 or 30 s, r2 (class 0) only at 0;
    two departures at the same time conflict, 30 s apart (300 m in trail) they do not."""
    p = Planner(one_route_network(), PlanningConfig(objective="priority", backend="exact", horizon_epochs=h,
                                                    airspace=AirspaceConfig(departure_slot_s=slot_s)))
    assert p.submit(FlightRequest("r1", "C", "D", 0, 0, 30, priority=1)) is None
    assert p.submit(FlightRequest("r2", "C", "D", 0, 0, 0)) is None
    out = []
    for e in range(2):
        res = p.plan(30.0 * e, e)
        out.append(([(f.request_id, f.departure_s) for f in res.approved],
                    sorted(r.request_id for r in res.expired), sorted(r.request_id for r in res.waiting)))
    return out


def test_planning_two_epochs_jointly_approves_more_than_two_myopic_epochs():
    # H = 1 at t = 0: r1 and r2 both depart at 0 and conflict; priority takes r1 (class 1),
    # r2's window closes: it expires. Epoch 1: nothing left. 1 flight.
    assert run_horizon(1) == [([("r1", 0.0)], ["r2"], []), ([], [], [])]
    # H = 2 at t = 0: r1 may take 30 s; one graph over both epochs (P = 1, 2 for r2, r1) takes
    # r2 at 0 and r1 at 30. Only r2 departs in this epoch: committed; r1 waits, and at t = 30
    # is planned again and flies. 2 flights.
    assert run_horizon(2) == [([("r2", 0.0)], [], ["r1"]), ([("r1", 30.0)], [], [])]
    # with 10 s slots the epoch's window is [t, t + 30] (H = 1): r1 simply takes a later slot
    assert sorted(run_horizon(1, slot_s=10.0)[0][0]) == [("r1", 10.0), ("r2", 0.0)]


def test_horizon_commits_only_what_departs_in_this_epoch_and_replans_the_rest():
    # r1 may depart at 0, 30 or 60 (class 1), r2 only at 0, r3 only at 30; H = 3 at t = 0:
    # r2 at 0, r3 at 30, r1 at 60 (no two at one time). Only r2 is committed; r1 and r3 wait and
    # are planned again at t = 30 (r3 at 30 committed, r1 at 60 waits) and at t = 60 (r1).
    p = Planner(one_route_network(), PlanningConfig(objective="priority", backend="exact", horizon_epochs=3))
    for r in (FlightRequest("r1", "C", "D", 0, 0, 60, priority=1), FlightRequest("r2", "C", "D", 0, 0, 0),
              FlightRequest("r3", "C", "D", 0, 30, 30)):
        assert p.submit(r) is None
    res = p.plan(0.0, 0)
    assert [(f.request_id, f.departure_s) for f in res.approved] == [("r2", 0.0)]
    assert [r.request_id for r in res.waiting] == ["r1", "r3"]
    assert res.report.approved == 1 and len(res.report.selected) == 1  # committed vertices only
    res = p.plan(30.0, 1)
    assert [(f.request_id, f.departure_s) for f in res.approved] == [("r3", 30.0)]
    res = p.plan(60.0, 2)
    assert [(f.request_id, f.departure_s) for f in res.approved] == [("r1", 60.0)]


def run_reservations(commit_ahead):
    """H = 2 on route C-m-D (priority): at t = 0, r1 (class 1) may depart at 0 or 30, r2 (class 0)
    only at 0; at t = 30 arrives r3 (class 2) that may depart only at 30. Two departures at one
    time conflict."""
    p = Planner(one_route_network(), PlanningConfig(objective="priority", backend="exact", horizon_epochs=2,
                                                    commit_ahead=commit_ahead))
    assert p.submit(FlightRequest("r1", "C", "D", 0, 0, 30, priority=1)) is None
    assert p.submit(FlightRequest("r2", "C", "D", 0, 0, 0)) is None
    out = [p.plan(0.0, 0)]
    assert p.submit(FlightRequest("r3", "C", "D", 30, 30, 30, priority=2)) is None
    out.append(p.plan(30.0, 1))
    return [([(f.request_id, f.departure_s) for f in r.approved], [x.request_id for x in r.expired],
             [x.request_id for x in r.waiting], r.report.discarded) for r in out], p


def test_commit_ahead_turns_the_horizons_later_departures_into_reservations_that_are_not_replanned():
    # rolling horizon (default): t = 0 commits r2 at 0, r1 waits; at t = 30 r1 (class 1) and r3
    # (class 2) both want 30: priority takes r3, r1 expires.
    plain, _ = run_reservations(False)
    assert plain == [([("r2", 0.0)], [], ["r1"], 0), ([("r3", 30.0)], ["r1"], [], 0)]
    # commit_ahead: t = 0 commits r2 at 0 and r1 at 30 (a reservation: an approved flight now);
    # at t = 30 r3's only candidate conflicts with the reserved r1, so it is discarded against
    # it (discarded = 1) and r3 expires: the reservation is not revoked for a higher class.
    ahead, p = run_reservations(True)
    assert ahead == [([("r1", 30.0), ("r2", 0.0)], [], [], 0), ([], ["r3"], [], 1)]  # arrival order
    assert sorted(f.request_id for f in p.active) == ["r1", "r2"]
    with pytest.raises(ValueError, match=r"PlanningConfig.commit_ahead must be a bool, got 'yes'"):
        PlanningConfig(commit_ahead="yes")


def test_horizon_epochs_is_validated():
    with pytest.raises(ValueError, match=r"PlanningConfig.horizon_epochs must be an integer in \[1, 100\], got 0"):
        PlanningConfig(horizon_epochs=0)
    with pytest.raises(ValueError, match=r"horizon_epochs .* got 2.0"):
        PlanningConfig(horizon_epochs=2.0)


def test_horizon_departures_every_slot_now_and_the_first_of_each_later_epoch():
    from uam_planner.planning import departure_slots_s

    cfg = PlanningConfig(horizon_epochs=3, airspace=AirspaceConfig(departure_slot_s=10.0))
    r = FlightRequest("r", "C", "D", 0, 0, 200)
    assert departure_slots_s(0.0, r, cfg, 3).tolist() == [0, 10, 20, 30, 40, 70]
    assert departure_slots_s(0.0, r, cfg, 1).tolist() == [0, 10, 20, 30]
    late = FlightRequest("l", "C", "D", 0, 45, 200)  # grid 45, 55, 65, 75, 85: epochs 2, 2, 3, 3, 3
    assert departure_slots_s(0.0, late, cfg, 3).tolist() == [45, 65]
    # the paper's rule: the epoch times inside the window
    paper = PlanningConfig(horizon_epochs=3)
    assert departure_slots_s(0.0, FlightRequest("p", "C", "D", 0, 20, 70), paper, 3).tolist() == [30, 60]


def test_fair_shares_over_a_sliding_window_forget_the_older_epochs():
    from uam_planner.objectives import OperatorShares

    whole, window = OperatorShares(), OperatorShares(window_s=60.0)
    for s in (whole, window):
        s.record(0.0, ["a"], ["b"])     # epoch at 0: a approved, b expired
        s.record(30.0, ["b"], ["a"])    # epoch at 30: b approved, a expired
        s.advance(90.0)                 # the window keeps tau >= 90 - 60 = 30
    # whole run: a 1 of 2, b 1 of 2: phi = round(10 x 3 / 2) = 15 each
    assert (whole.factor("a"), whole.factor("b")) == (15, 15)
    # window: only the epoch at 30: a 0 of 1 -> round(10 x 2 / 1) = 20; b 1 of 1 -> 10
    assert (window.requested["a"], window.approved["a"]) == (1, 0)
    assert (window.factor("a"), window.factor("b")) == (20, 10)
    window.advance(120.0)  # nothing left: back to the neutral F = 10
    assert (window.factor("a"), window.factor("b")) == (10, 10)


def run_fair_window(window_s):
    """Route C-m-D, objective fair: b's two requests expire at t = 0 (windows [5, 10] s fall
    between epochs), a's one at t = 30 ([35, 40]); at t = 90 a and b ask for the same departure."""
    p = Planner(one_route_network(), PlanningConfig(objective="fair", backend="exact", fair_window_s=window_s))
    for e, rids in enumerate((("b0", "b1"), ("a1",))):
        t = 30.0 * e
        for rid in rids:
            assert p.submit(FlightRequest(rid, "C", "D", t, t + 5, t + 10, operator_id=rid[0])) is None
        res = p.plan(t, e)
        assert res.approved == [] and sorted(r.request_id for r in res.expired) == list(rids)
    p.plan(60.0, 2)
    for op in ("a", "b"):
        assert p.submit(FlightRequest(f"{op}3", "C", "D", 90, 90, 90, operator_id=op)) is None
    return [f.request_id for f in p.plan(90.0, 3).approved], p


def test_fair_window_forgets_the_early_losses_in_the_planner():
    # whole run at t = 90: a 0 of 1 -> phi 20, b 0 of 2 -> round(10 x 3 / 1) = 30: b flies
    won, p = run_fair_window(0.0)
    assert won == ["b3"]
    # after it: a 0 of 2 -> round(10 x 3 / 1) = 30, b 1 of 3 -> round(10 x 4 / 2) = 20
    assert (p.shares.factor("a"), p.shares.factor("b")) == (30, 20)
    # window 60 s at t = 90: only decisions at tau >= 30 count: a 0 of 1 -> 20, b none -> 10: a
    won, p = run_fair_window(60.0)
    assert won == ["a3"] and p.shares.window_s == 60.0
    # after it (window still at t = 90): a 1 of 2 -> 15, b 0 of 1 (b3) -> 20
    assert (p.shares.factor("a"), p.shares.factor("b")) == (15, 20)
    with pytest.raises(ValueError, match=r"PlanningConfig.fair_window_s must be finite and >= 0, got -1"):
        PlanningConfig(fair_window_s=-1)
