"""First-fit baseline: hand-computed selections, arrival order, safety, planner and runner wiring."""

import numpy as np
import pytest

from uam_planner.audit import audit_flights
from uam_planner.first_fit import first_fit_select
from uam_planner.network import network_from_enu
from uam_planner.planning import POLICIES, FlightRequest, Planner, PlanningConfig
from uam_planner.synthetic import generate_network


def two_route_network():
    """A and B 1 km apart: a straight route via m1 (1,000 m) and a detour via m2
    (2 x sqrt(500^2 + 800^2) = 1,886.8 m). C and D sit on a north-south line through m1, so the
    only route C -> D (C-m1-D, 1,000 m) crosses the straight A-B route at m1."""
    return network_from_enu(
        "two-route", ["A", "B", "m1", "m2", "C", "D"],
        [(0, 0, 0), (1000, 0, 0), (500, 0, 0), (500, -800, 0), (500, 500, 0), (500, -500, 0)],
        [True, True, False, False, True, True],
        [("A", "m1"), ("m1", "B"), ("A", "m2"), ("m2", "B"), ("C", "m1"), ("m1", "D")])


def req(rid, o, d, t=0.0):
    return FlightRequest(rid, o, d, t, t, t + 60.0)


def plan_once(policy, requests):
    p = Planner(two_route_network(), PlanningConfig(epoch_s=30.0), policy)
    for r in requests:
        assert p.submit(r) is None
    return p.plan(0.0, 0)


def test_select_takes_first_vertex_free_of_taken_neighbours():
    # Request 0: vertices 0, 1; request 1: vertices 2, 3 (clique edges 0-1, 2-3).
    # Conflicts 0-2 and 1-3. Walk: 0 taken; 1 blocked by 0; 2 blocked by 0; 3 free -> {0, 3}.
    edges = np.array([[0, 1], [2, 3], [0, 2], [1, 3]])
    assert first_fit_select(np.ones(4), edges).selected.tolist() == [0, 3]
    # Weights are ignored: a heavier later vertex does not displace an earlier one.
    # Path 0-1-2 with weights 1, 5, 1: first-fit {0, 2} (weight 2), MWIS {1} (weight 5).
    assert first_fit_select([1.0, 5.0, 1.0], [[0, 1], [1, 2]]).selected.tolist() == [0, 2]
    assert first_fit_select(np.ones(3), np.zeros((0, 2))).selected.tolist() == [0, 1, 2]


def test_select_names_out_of_range_edges():
    with pytest.raises(ValueError, match=r"edges: vertex indices must lie in \[0, 1\]"):
        first_fit_select(np.ones(2), [[0, 2]])


def test_head_on_pair_second_request_takes_its_detour():
    # r1 A->B and r2 B->A at t = 0: the straight routes meet head-on at m1 (t = 50 s).
    # FIFO: r1 straight, r2 waits. First-fit: r1 straight (candidate 0), r2's candidate 0 conflicts,
    # its candidate 1 (the detour via m2) is free -> both fly.
    requests = [req("r1", "A", "B"), req("r2", "B", "A")]
    ff = plan_once("firstfit", requests)
    assert [(f.request_id, f.route_node_ids, f.candidate_index) for f in ff.approved] == [
        ("r1", ("A", "m1", "B"), 0), ("r2", ("B", "m2", "A"), 1)]
    assert ff.approved[1].length_m == pytest.approx(2 * np.hypot(500, 800))
    assert all(f.method == "firstfit" and f.backend == "firstfit" for f in ff.approved)
    assert ff.report.policy == "firstfit" and ff.report.backend_used == "firstfit"
    # Vertices: 2 candidates per request, none discarded; edges: 2 clique + 2 head-on conflicts.
    assert (ff.report.vertices, ff.report.edges, ff.report.conflict_edges) == (4, 4, 2)
    fifo = plan_once("fifo", requests)
    assert [f.request_id for f in fifo.approved] == ["r1"]


def test_arrival_order_decides_not_weight():
    # r1 A->B arrives first, r2 C->D second; r2's only route crosses r1's straight route at m1
    # at the same time (both reach m1 at t = 50 s). First-fit gives r1 its first free candidate,
    # the straight route, which blocks r2: 1 flight. MWIS takes r1's detour (weight
    # 1000 / 1886.8 = 0.53) plus r2 (weight 1): 1.53 > 1.0, 2 flights.
    requests = [req("r1", "A", "B"), req("r2", "C", "D")]
    ff = plan_once("firstfit", requests)
    assert [(f.request_id, f.candidate_index) for f in ff.approved] == [("r1", 0)]
    assert [r.request_id for r in ff.waiting] == ["r2"]
    mwis = plan_once("mwis", requests)
    assert sorted((f.request_id, f.candidate_index) for f in mwis.approved) == [("r1", 1), ("r2", 0)]
    # Reversed arrival order: r2 first takes its only route, r1 then falls back to its detour.
    ff2 = plan_once("firstfit", requests[::-1])
    assert [(f.request_id, f.candidate_index) for f in ff2.approved] == [("r2", 0), ("r1", 1)]


def test_candidates_blocked_by_active_flights_are_skipped():
    p = Planner(two_route_network(), PlanningConfig(epoch_s=30.0), "firstfit")
    p.submit(req("r1", "A", "B"))
    assert [f.candidate_index for f in p.plan(0.0, 0).approved] == [0]
    # At t = 30 r1 is 300 m along the straight route; r2 B->A straight would meet it head-on,
    # so first-fit skips candidate 0 (discarded against the active flight) and takes the detour.
    p.submit(req("r2", "B", "A", 30.0))
    res = p.plan(30.0, 1)
    assert [(f.request_id, f.candidate_index) for f in res.approved] == [("r2", 1)]
    assert res.report.discarded == 1


@pytest.mark.parametrize("seed", range(3))
def test_firstfit_never_approves_flights_that_lose_separation(seed):
    net = generate_network(45, 6, seed=200 + seed)
    p = Planner(net, PlanningConfig(epoch_s=30.0, seed=seed), "firstfit")
    rng = np.random.default_rng(seed)
    aero = list(net.aerodrome_ids)
    flights, n = [], 0
    for e in range(20):
        t = 30.0 * e
        for _ in range(8):
            o, d = rng.choice(len(aero), size=2, replace=False)
            p.submit(req(f"r{n:04d}", aero[o], aero[d], t))
            n += 1
        res = p.plan(t, e)
        flights.extend(res.approved)
    audit = audit_flights(flights, 100.0)
    assert audit.losses == [] and audit.pairs_checked > 0
    # busy enough that first-fit used candidates beyond the shortest
    assert any(f.candidate_index > 0 for f in flights)


def test_firstfit_is_a_planner_policy():
    assert "firstfit" in POLICIES
    with pytest.raises(ValueError, match="policy must be one of"):
        Planner(two_route_network(), policy="first-fit")
