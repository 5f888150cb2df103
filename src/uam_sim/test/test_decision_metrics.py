"""uam_sim.world.flights.flight_metrics, the decision metrics (issue 21): hand-computed delay,
detour, priority and fairness metrics, and the runner's summary carrying them."""

import math

import pytest

from uam_sim.world.flights import jain_index, run_metrics as decision_metrics


def test_jain_index_hand_computed():
    assert jain_index([0.5, 0.5]) == 1.0
    assert jain_index([1.0, 0.0]) == 0.5  # (1)^2 / (2 * 1)
    # (0.2 + 0.6)^2 / (2 * (0.04 + 0.36)) = 0.64 / 0.8 = 0.8
    assert jain_index([0.2, 0.6]) == pytest.approx(0.8)
    assert math.isnan(jain_index([])) and math.isnan(jain_index([0.0, 0.0]))


def test_decision_metrics_hand_computed():
    flights = [
        # delay 0, 30, 60 s from the earliest departure; detours 0, 500, 200 m
        {"earliest_departure_s": 0.0, "departure_s": 0.0, "length_m": 1000.0,
         "shortest_length_m": 1000.0, "priority": 0, "operator": "a"},
        {"earliest_departure_s": 30.0, "departure_s": 60.0, "length_m": 1500.0,
         "shortest_length_m": 1000.0, "priority": 0, "operator": "a"},
        {"earliest_departure_s": 30.0, "departure_s": 90.0, "length_m": 1200.0,
         "shortest_length_m": 1000.0, "priority": 1, "operator": "b"},
        # warm-up: left out with warmup_s = 10 (earliest -30 < 10)... kept otherwise
        {"earliest_departure_s": -30.0, "departure_s": 0.0, "length_m": 1000.0,
         "shortest_length_m": 1000.0, "priority": 0, "operator": "b"},
    ]
    requests = [{"earliest_departure_s": f["earliest_departure_s"], "operator": f["operator"],
                 "priority": f["priority"]} for f in flights] + \
        [{"earliest_departure_s": 30.0, "operator": "b", "priority": 0},
         {"earliest_departure_s": 30.0, "operator": "b", "priority": 0}]
    m = decision_metrics(flights, requests, warmup_s=-1.0)
    # delays 0, 30, 60: mean 30; p95 (linear) = 30 + 0.9 * 30 = 57
    assert m["delay_mean_s"] == 30.0 and m["delay_p95_s"] == pytest.approx(57.0)
    assert m["detour_mean_m"] == pytest.approx(700.0 / 3)
    assert m["delay_p95_s_prio0"] == pytest.approx(28.5) and m["delay_p95_s_prio1"] == 60.0
    # a: 2 of 2; b: 1 of 3 (the warm-up request excluded): J = (1 + 1/3)^2 / (2 (1 + 1/9)) = 0.8
    assert (m["share_a"], m["share_b"]) == (1.0, pytest.approx(1 / 3))
    assert m["jain_index"] == pytest.approx(0.8)
    m = decision_metrics(flights, requests)
    assert m["share_b"] == pytest.approx(2 / 4) and m["delay_mean_s"] == pytest.approx(30.0)
    # end_s: a request whose window is still open at the end is left out (b: 1 of 2 left)
    rows = [{"earliest_departure_s": 0.0, "latest_departure_s": 60.0, "operator": "b"},
            {"earliest_departure_s": 600.0, "latest_departure_s": 660.0, "operator": "b"}]
    assert decision_metrics([], rows)["share_b"] == 0.0
    m = decision_metrics([{**rows[1], "departure_s": 600.0, "length_m": 1.0,
                           "shortest_length_m": 1.0}], rows, end_s=300.0)
    assert m["share_b"] == 0.0 and math.isnan(m["delay_mean_s"])
    m = decision_metrics([{**rows[1], "departure_s": 600.0, "length_m": 1.0,
                           "shortest_length_m": 1.0}], rows)
    assert m["share_b"] == 0.5
    # no operator named, one class: no share or class keys
    m = decision_metrics([{"earliest_departure_s": 0.0, "departure_s": 5.0, "length_m": 1.0,
                           "shortest_length_m": None}],
                         [{"earliest_departure_s": 0.0}])
    assert not [k for k in m if k.startswith(("share_", "delay_p95_s_prio"))]
    assert math.isnan(m["detour_mean_m"]) and math.isnan(m["jain_index"])
    # the report's flight statistics come from the same rows: one delay set
    assert (m["flights"], m["delay_mean_s"], m["delayed_share"], m["route_length_mean_m"]) == (1, 5.0, 1.0, 1.0)


def test_runner_summary_carries_the_objective_and_metrics():
    from uam_sim.studies.experiment import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario

    net = load_network_spec({"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}})
    base = dict(priority_share=0.2, priority_class=2, operators=["a", "b"], audit=False)
    runs = {obj: run_scenario(net, "greedy", 6, 0, 300.0, make_config(objective=obj, **base))
            for obj in ("paper", "priority")}
    for obj, r in runs.items():
        s = r.summary
        assert s["objective"] == obj
        assert {"share_a", "share_b", "jain_index", "delay_p95_s_prio0", "delay_p95_s_prio2",
                "delay_mean_s", "delay_p95_s", "detour_mean_m"} <= set(s)
        assert 0.0 <= s["share_a"] <= 1.0 and 0.5 <= s["jain_index"] <= 1.0
        # flights of requests still within their window at the end (300 s) are left out
        delays = [f["departure_s"] - f["earliest_departure_s"] for f in r.flights
                  if f["latest_departure_s"] <= 300.0]
        assert len(delays) < len(r.flights)
        assert s["delay_mean_s"] == pytest.approx(sum(delays) / len(delays))
        assert all(f["length_m"] >= f["shortest_length_m"] - 1e-6 for f in r.flights)
    # the mix leaves the paper objective's decisions as they are without it
    plain = run_scenario(net, "greedy", 6, 0, 300.0, make_config(audit=False))
    assert plain.decisions() == runs["paper"].decisions()
    assert "share_a" not in plain.summary and math.isnan(plain.summary["jain_index"])


@pytest.mark.parametrize("horizon", [1, 2])
def test_every_objective_is_deterministic_given_a_seed(horizon):
    """Issue 21's "every objective is deterministic given a seed": the same seed twice gives the
    same decisions (request -> epoch, candidate) for each objective, with priority classes and
    operators in the demand and with a horizon; and the objectives do decide differently (the
    check is not vacuous)."""
    from uam_planner.objectives import OBJECTIVES
    from uam_sim.studies.experiment import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario

    net = load_network_spec({"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}})
    base = dict(priority_share=0.2, priority_class=2, operators=["a", "b"], audit=False,
                horizon_epochs=horizon)
    seen = {}
    for obj in OBJECTIVES:
        cfg = make_config(objective=obj, **base)
        first = run_scenario(net, "greedy", 8, 3, 300.0, cfg).decisions()
        assert run_scenario(net, "greedy", 8, 3, 300.0, cfg).decisions() == first and first, obj
        seen[obj] = first
    assert len({tuple(sorted(d.items())) for d in seen.values()}) > 1


def test_per_class_approvals_and_the_operators_spread_move_where_totals_and_jain_do_not():
    """Two runs with the same total approvals: the class-1 approvals and the operators' min/max
    ratio tell them apart; Jain's index barely does."""
    req = ([{"earliest_departure_s": 0.0, "priority": 1, "operator": "a"}] * 2
           + [{"earliest_departure_s": 0.0, "priority": 0, "operator": "a"}] * 48
           + [{"earliest_departure_s": 0.0, "priority": 0, "operator": "b"}] * 50)

    def flight(prio, op, delay):
        return {"departure_s": delay, "earliest_departure_s": 0.0, "length_m": 1000.0, "priority": prio,
                "operator": op}

    # run x approves both class-1 requests, run y neither; both approve 90 of 100
    x = [flight(1, "a", 0.0)] * 2 + [flight(0, "a", 10.0)] * 44 + [flight(0, "b", 20.0)] * 44
    y = [flight(0, "a", 10.0)] * 45 + [flight(0, "b", 20.0)] * 45
    mx, my = decision_metrics(x, req), decision_metrics(y, req)
    assert mx["flights"] == my["flights"] == 90
    assert (mx["requests_prio1"], mx["approved_prio1"], mx["approval_rate_prio1"]) == (2, 2, 1.0)
    assert (my["approved_prio1"], my["approval_rate_prio1"]) == (0, 0.0)
    assert my["approval_rate_prio0"] == pytest.approx(90 / 98)
    assert mx["delay_mean_s_prio1"] == 0.0 and mx["delay_mean_s_prio0"] == pytest.approx(15.0)
    assert math.isnan(my["delay_mean_s_prio1"])
    # shares: x 46/50 and 44/50 (ratio 0.9565), y 45/50 and 45/50 (1.0); Jain 0.9995 and 1.0
    assert mx["operator_share_ratio"] == pytest.approx(44 / 46) and my["operator_share_ratio"] == 1.0
    assert (mx["operator_share_min"], mx["operator_share_max"]) == (0.88, 0.92)
    assert mx["jain_index"] > 0.999
