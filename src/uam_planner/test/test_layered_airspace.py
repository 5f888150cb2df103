"""Vertiports as terminals with pads, flight levels with a direction rule, vertical climb and
descent, departure slots: hand-computed answers on small networks."""

import math

import numpy as np
import pytest

from uam_planner.audit import audit_flights
from uam_planner.candidates import CandidateCache, candidate_routes
from uam_planner.network import NetworkError, network_from_enu
from uam_planner.planning import (AirspaceConfig, FlightRequest, Planner, PlanningConfig,
                                  departure_slots_s)
from uam_planner.separation import SeparationModel

LEVELS = {"levels_m": [60.0, 90.0, 120.0, 150.0], "direction_rule": "semicircular"}
CYL = AirspaceConfig(separation_model="cylinder", vertical_separation_m=30.0)


def net(airspace=LEVELS, pads=None):
    """A (0, 0) and B (3000, 0) at 5 m; aerodrome C (1500, 0) sits in line between m1 (500, 0)
    and m2 (2500, 0); a detour m1 - n (1500, 800) - m2 avoids it."""
    ids = ["A", "B", "C", "m1", "m2", "n"]
    enu = [(0, 0, 5), (3000, 0, 5), (1500, 0, 5), (500, 0, 120), (2500, 0, 120), (1500, 800, 120)]
    edges = [("A", "m1"), ("m1", "C"), ("C", "m2"), ("m2", "B"), ("m1", "n"), ("n", "m2")]
    return network_from_enu("line3", ids, enu, [True, True, True, False, False, False], edges,
                            airspace=airspace, pads_m=pads)


def req(rid, o, d, t=0.0, earliest=None, latest=None):
    return FlightRequest(rid, o, d, t, t if earliest is None else earliest,
                         t + 60.0 if latest is None else latest)


def test_no_route_passes_through_a_vertiport_it_does_not_use():
    paper = net(airspace=None)
    assert candidate_routes(paper, "A", "B", k=1)[0].node_indices == (0, 3, 2, 4, 1)  # via C
    layered = net()
    routes = candidate_routes(layered, "A", "B", k=5)
    assert [r.node_indices for r in routes] == [(0, 3, 5, 4, 1)]   # the only way round C
    # C itself is still an origin and destination
    assert candidate_routes(layered, "C", "A", k=1)[0].node_indices == (2, 3, 0)


def test_semicircular_rule_gives_eastbound_even_and_westbound_odd_levels():
    cache = CandidateCache(net(), k=1)
    assert [t.level_m for t in cache.templates(0, 1)] == [60.0, 120.0]     # track 90 deg
    assert [t.level_m for t in cache.templates(1, 0)] == [90.0, 150.0]     # track 270 deg
    none = CandidateCache(net({"levels_m": [60.0, 90.0], "direction_rule": "none"}), k=1)
    assert [t.level_m for t in none.templates(1, 0)] == [60.0, 90.0]


def test_climb_cruise_and_descent_times_by_hand():
    cache = CandidateCache(net(), k=1, speed_mps=10.0, climb_rate_mps=5.0, descent_rate_mps=3.0)
    tp = cache.templates(0, 1)[0]                       # level 60 m
    diag = math.hypot(1000.0, 800.0)
    # z is altitude: B, 5 m up in the ENU frame 3 km from its origin, is 5.7 m above the ellipsoid
    z_b = cache.network.lat_lon_alt[1, 2]
    assert z_b == pytest.approx(5.0 + 3000.0 ** 2 / (2 * 6.378e6), abs=0.01)
    # climb 55 m at 5 m/s = 11 s; cruise 500 + 2 x 1280.6 + 500 m at 10 m/s; descend at 3 m/s
    want_t = np.cumsum([0.0, 11.0, 50.0, diag / 10, diag / 10, 50.0, (60.0 - z_b) / 3.0])
    np.testing.assert_allclose(tp.rel_times_s, want_t)
    np.testing.assert_allclose(tp.points_m, [(0, 0, 5), (0, 0, 60), (500, 0, 60), (1500, 800, 60),
                                             (2500, 0, 60), (3000, 0, 60), (3000, 0, z_b)])
    traj = tp.trajectory(100.0)
    # 5 s into the descent the aircraft is 15 m lower, over the pad
    np.testing.assert_allclose(traj.position_at(100.0 + want_t[-2] + 5.0), (3000.0, 0.0, 45.0))
    assert traj.arrival_s == pytest.approx(100.0 + want_t[-1])


def test_descents_at_one_pad_conflict_and_at_two_pads_do_not():
    # Two arrivals at B from A at levels 60 and 120 with the same departure: the 120 m flight
    # descends through 60 m over the same pad while the other is still descending below it.
    one_pad = CandidateCache(net(), k=1)
    a, b = (t.trajectory(0.0) for t in one_pad.templates(0, 1))
    sep = SeparationModel("cylinder", 100.0, 30.0)
    assert not audit_flights([a, b], sep).ok
    # four pads at each end, one per level (level index i uses pad i mod 4): the 60 m flight
    # lands 150 m south of B, the 120 m flight 150 m north
    pads = {"A": [[0, 0], [0, 300], [0, 600], [0, 900]],
            "B": [[0, -150], [0, 450], [0, 150], [0, 750]]}
    four = CandidateCache(net(pads=pads), k=1)
    t60, t120 = four.templates(0, 1)
    np.testing.assert_allclose(t60.points_m[-1, :2], (3000, -150))
    np.testing.assert_allclose(t120.points_m[-1, :2], (3000, 150))
    np.testing.assert_allclose(t120.points_m[0], (0, 600, 5))
    assert audit_flights([t60.trajectory(0.0), t120.trajectory(0.0)], sep).ok


def test_two_pads_of_one_vertiport_let_two_flights_leave_in_the_same_instant():
    cfg = PlanningConfig(k=1, airspace=CYL)
    rule_none = {"levels_m": [60.0, 90.0], "direction_rule": "none"}
    # one pad: both candidates of both requests climb from (0, 0) at t = 0: only one flies now
    p1 = Planner(net(rule_none), cfg, "mwis")
    p1.submit(req("r1", "A", "B"))
    p1.submit(req("r2", "A", "B"))
    assert len(p1.plan(0.0, 0).approved) == 1
    # two pads 150 m apart across the track (level 60 from pad 0, level 90 from pad 1)
    p2 = Planner(net(rule_none, pads={"A": [[0, 0], [0, 150]]}), cfg, "mwis")
    p2.submit(req("r1", "A", "B"))
    p2.submit(req("r2", "A", "B"))
    got = p2.plan(0.0, 0).approved
    assert sorted(f.level_m for f in got) == [60.0, 90.0]
    assert [f.departure_s for f in got] == [0.0, 0.0]
    assert audit_flights(got, cfg.separation).ok


def test_departure_slots_by_hand():
    cfg = PlanningConfig(epoch_s=30.0, airspace=AirspaceConfig(departure_slot_s=5.0))
    assert departure_slots_s(0.0, req("r", "A", "B"), cfg).tolist() == [0, 5, 10, 15, 20, 25, 30]
    assert departure_slots_s(0.0, req("r", "A", "B", earliest=12.0, latest=20.0),
                             cfg).tolist() == [12.0, 17.0]
    late = req("r", "A", "B", earliest=40.0, latest=100.0)
    assert departure_slots_s(0.0, late, cfg).tolist() == []
    assert departure_slots_s(30.0, late, cfg).tolist() == [40, 45, 50, 55, 60]
    paper = PlanningConfig()
    assert departure_slots_s(30.0, late, paper).tolist() == [30.0]


def test_slot_candidates_and_their_weights():
    cfg = PlanningConfig(k=1, airspace=AirspaceConfig("cylinder", departure_slot_s=10.0))
    p = Planner(net(), cfg, "mwis")
    p.submit(req("r1", "A", "B", latest=25.0))
    rep = p.plan(0.0, 0).report
    # 1 route x 2 levels (60, 120 m) x 3 slots (0, 10, 20 s) = 6 candidates, one clique
    assert (rep.candidates, rep.vertices, rep.edges) == (6, 6, 15)
    cache = p.cache
    t60, t120 = (t.duration_s for t in cache.templates(0, 1))
    assert t120 - t60 == pytest.approx(60.0 / 5.0 + 60.0 / 3.0)      # 60 m more climb and descent
    want = [t60 / (t60 + 0), t60 / (t60 + 10), t60 / (t60 + 20),
            t60 / (t120 + 0), t60 / (t120 + 10), t60 / (t120 + 20)]
    np.testing.assert_allclose(rep.weights, want)
    assert rep.selected.tolist() == [0]           # the weight-1 candidate: level 60, slot 0


def test_slots_let_two_flights_leave_one_pad_in_one_epoch():
    one = PlanningConfig(k=1, airspace=CYL)
    p = Planner(net(), one, "mwis")
    for rid in ("r1", "r2"):
        p.submit(req(rid, "A", "B"))
    assert len(p.plan(0.0, 0).approved) == 1          # paper rule: both would leave at t = 0
    slots = PlanningConfig(k=1, airspace=AirspaceConfig("cylinder", departure_slot_s=5.0))
    p = Planner(net(), slots, "mwis")
    for rid in ("r1", "r2"):
        p.submit(req(rid, "A", "B"))
    got = p.plan(0.0, 0).approved
    assert len(got) == 2 and got[0].departure_s == 0.0 and got[1].departure_s > 0.0
    assert audit_flights(got, slots.separation).ok


def test_slots_make_requests_with_a_later_window_eligible_within_the_epoch():
    cfg = PlanningConfig(k=1, airspace=AirspaceConfig("cylinder", departure_slot_s=5.0))
    p = Planner(net(), cfg, "fifo")
    p.submit(req("r1", "A", "B", earliest=17.0, latest=40.0))
    got = p.plan(0.0, 0).approved
    assert [f.departure_s for f in got] == [17.0]
    assert got[0].trajectory.departure_s == 17.0


@pytest.mark.parametrize("airspace, pads, field", [
    ({"levels_m": [90.0, 60.0]}, None, "levels_m[1]"),
    ({"levels_m": [3.0, 60.0]}, None, "levels_m[0]"),
    ({"levels_m": [60.0, 90.0], "direction_rule": "lanes"}, None, "direction_rule"),
    ({"levels_m": [60.0], "direction_rule": "semicircular"}, None, "direction_rule"),
    (LEVELS, {"m1": [[0, 0]]}, "not an aerodrome"),
    (LEVELS, {"A": [[0, 0], [0, 0]]}, "duplicates pad 0"),
    (LEVELS, {"A": [[0, "x"]]}, "pads_m[0][1]"),
    (None, {"A": [[0, 0]]}, "layered"),
])
def test_bad_airspace_names_the_field(airspace, pads, field):
    with pytest.raises(NetworkError, match=field.replace("[", r"\[").replace("]", r"\]")):
        net(airspace, pads)


def test_bad_airspace_config_names_the_field():
    for kw, field in ((dict(separation_model="box"), "separation_model"),
                      (dict(departure_slot_s=-5.0), "departure_slot_s"),
                      (dict(climb_rate_mps=0.0), "climb_rate_mps")):
        with pytest.raises(ValueError, match=field):
            AirspaceConfig(**kw)


def test_layered_yaml_round_trip_and_singapore_layered_file(tmp_path):
    from pathlib import Path

    import scipy.sparse
    from scipy.sparse.csgraph import connected_components

    from uam_planner.network import load_network, save_network_yaml
    n = net(pads={"A": [[0, 0], [0, 150]]})
    save_network_yaml(n, tmp_path / "n.yaml")
    again = load_network(tmp_path / "n.yaml")
    assert again.levels_m == (60.0, 90.0, 120.0, 150.0) and again.direction_rule == "semicircular"
    assert again.pads_m == {"A": ((0.0, 0.0), (0.0, 150.0))}
    np.testing.assert_allclose(again.pads_of(again.node_index("B")), [[0.0, 0.0]])
    from uam_planner.network import save_network_geojson
    with pytest.raises(NetworkError, match="layered"):
        save_network_geojson(n, tmp_path / "n.geojson")

    root = Path(__file__).resolve().parents[3] / "config" / "networks"
    paper = load_network(root / "singapore.yaml")
    sg = load_network(root / "singapore-layered.yaml")
    assert not paper.layered and sg.layered
    assert sg.node_ids == paper.node_ids and np.array_equal(sg.edges, paper.edges)
    assert sg.levels_m == (60.0, 90.0, 120.0, 150.0)
    assert set(sg.pads_m) == set(sg.aerodrome_ids)
    assert all(len(p) == 4 for p in sg.pads_m.values())
    # with vertiports as terminals every vertiport still reaches every other: the corridors
    # without the aerodromes form one component holding every aerodrome's access nodes
    corridor = ~sg.is_aerodrome[sg.edges].any(axis=1)
    e = sg.edges[corridor]
    adj = scipy.sparse.coo_array((np.ones(len(e)), (e[:, 0], e[:, 1])), shape=(sg.n_nodes,) * 2)
    _, label = connected_components(adj, directed=False)
    access = sg.edges[~corridor]
    ends = np.where(sg.is_aerodrome[access[:, 0]], access[:, 1], access[:, 0])
    assert len(set(label[ends].tolist())) == 1


def test_generate_network_with_levels_and_pads():
    from uam_planner.synthetic import generate_network
    g = generate_network(300, 20, seed=1, levels_m=[60, 90, 120, 150], pads_per_vertiport=4)
    assert g.layered and g.name.endswith("-layered") and len(g.pads_m) == 20
    pads = g.pads_of(0)
    d = np.linalg.norm(pads[:, None] - pads[None], axis=2)
    assert d[d > 0].min() == pytest.approx(150.0)            # a 150 m square
    assert not generate_network(300, 20, seed=1).layered     # default unchanged
    with pytest.raises(NetworkError, match="pads_per_vertiport"):
        generate_network(300, 20, seed=1, pads_per_vertiport=2)
    # a layered city plans without losses of separation in the cylinder model
    cfg = PlanningConfig(airspace=AirspaceConfig("cylinder", departure_slot_s=10.0))
    p = Planner(g, cfg, "mwis")
    rng = np.random.default_rng(0)
    for i in range(30):
        o, dd = rng.choice(20, 2, replace=False)
        p.submit(req(f"r{i}", g.aerodrome_ids[o], g.aerodrome_ids[dd]))
    flights = p.plan(0.0, 0).approved + p.plan(30.0, 1).approved
    assert len(flights) >= 25 and audit_flights(flights, cfg.separation).ok


def test_a_request_with_no_route_avoiding_other_vertiports_is_rejected_at_submit():
    # D is reachable only through C: fine in the paper's model, not with vertiports as terminals
    ids = ["A", "C", "D", "m"]
    enu = [(0, 0, 5), (1000, 0, 5), (2000, 0, 5), (500, 0, 120)]
    edges = [("A", "m"), ("m", "C"), ("C", "D")]
    layered = network_from_enu("dead-end", ids, enu, [True, True, True, False], edges,
                               airspace=LEVELS)
    p = Planner(layered, PlanningConfig(k=1), "mwis")
    reason = p.submit(req("r1", "A", "D"))
    assert reason is not None and "without passing through another vertiport" in reason
    assert p.submit(req("r2", "A", "C")) is None
    assert [f.request_id for f in p.plan(0.0, 0).approved] == ["r2"]


@pytest.mark.parametrize("policy", ["mwis", "fifo"])
def test_route_searches_run_by_submit_count_in_the_next_epochs_planning_time(policy):
    """A new origin-destination pair of a layered network is searched when ``submit``
    validates it; that time is part of the next epoch's figures (phase "routes_s"), and a
    planner whose routes were precomputed spends none there."""
    from uam_planner.synthetic import generate_network
    city = generate_network(60, 6, seed=1, levels_m=[60.0, 90.0], pads_per_vertiport=2)
    cfg = AirspaceConfig("cylinder", 30.0, 5.0)
    lazy = Planner(city, PlanningConfig(airspace=cfg), policy, solve_mwis=_first_each)
    warm = Planner(city, PlanningConfig(airspace=cfg, precompute_routes=True), policy,
                   solve_mwis=_first_each)
    for p in (lazy, warm):
        assert p.submit(FlightRequest("r1", "A000", "A001", 0.0, 0.0, 60.0)) is None
    lazy_rep, warm_rep = lazy.plan(0.0, 0).report, warm.plan(0.0, 0).report
    assert lazy_rep.phase_times_s["routes_s"] > 0.0
    assert lazy_rep.planning_time_s >= lazy_rep.phase_times_s["routes_s"]
    assert warm_rep.phase_times_s["routes_s"] == 0.0
    assert lazy_rep.approved == warm_rep.approved == 1
    assert lazy.plan(30.0, 1).report.phase_times_s["routes_s"] == 0.0   # counted once


def _first_each(weights, edges, groups):
    from uam_solvers import solve
    return solve(weights, edges, groups=groups, backend="greedy")
