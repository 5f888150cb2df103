"""uam_sim.world.demand: the seeded request stream and demand files."""

from collections import Counter
from pathlib import Path

import pytest

from uam_sim.world.demand import (DemandError, DemandSchedule, RequestGenerator, load_demand,
                            parse_demand, request_id)

REPO = Path(__file__).resolve().parents[3]
AERO = ["A", "B", "C", "D"]


def test_interval_requests_follow_the_paper_setup():
    gen = RequestGenerator(AERO, 5, interval_s=30.0, window_s=60.0, seed=3)
    reqs = gen.requests_at(90.0, 3)
    assert len(reqs) == 5
    assert [r.request_id for r in reqs] == [f"r00003_{i:03d}" for i in range(5)]
    for r in reqs:
        assert r.origin_id in AERO and r.destination_id in AERO
        assert r.origin_id != r.destination_id
        assert r.request_time_s == r.earliest_departure_s == 90.0
        assert r.latest_departure_s == 150.0
    assert request_id(12, 3) == "r00012_003"


def test_stream_is_a_function_of_seed_and_interval_only():
    a = RequestGenerator(AERO, 4, seed=11)
    in_order = [a.requests_for_epoch(i) for i in range(8)]
    b = RequestGenerator(AERO, 4, seed=11)
    assert b.requests_for_epoch(7) == in_order[7]      # no call history needed
    assert b.requests_for_epoch(7) == in_order[7]      # asking twice changes nothing
    assert [b.requests_for_epoch(i) for i in reversed(range(8))] == in_order[::-1]
    c = RequestGenerator(AERO, 4, seed=12)
    assert [c.requests_for_epoch(i) for i in range(8)] != in_order


def test_destinations_cover_every_other_aerodrome_evenly():
    gen = RequestGenerator(["A", "B", "C"], 10, seed=0)
    pairs = Counter((r.origin_id, r.destination_id) for i in range(300)
                    for r in gen.requests_for_epoch(i))
    assert set(pairs) == {(o, d) for o in "ABC" for d in "ABC" if o != d}
    # 3000 draws over 6 ordered pairs: each near 500
    assert all(400 < n < 600 for n in pairs.values())


def test_fractional_rate_has_the_right_mean():
    gen = RequestGenerator(AERO, 0.5, seed=1)
    counts = [len(gen.requests_for_epoch(i)) for i in range(2000)]
    assert set(counts) == {0, 1}
    assert 0.45 < sum(counts) / len(counts) < 0.55
    gen = RequestGenerator(AERO, 2.25, seed=1)
    counts = [len(gen.requests_for_epoch(i)) for i in range(2000)]
    assert set(counts) == {2, 3}
    assert 2.2 < sum(counts) / len(counts) < 2.3
    assert RequestGenerator(AERO, 0, seed=1).requests_for_epoch(5) == []


@pytest.mark.parametrize("kwargs, field", [
    (dict(aerodrome_ids=["A"], rate_per_interval=1), "aerodrome_ids"),
    (dict(aerodrome_ids=["A", "A"], rate_per_interval=1), "aerodrome_ids"),
    (dict(aerodrome_ids=AERO, rate_per_interval=-1), "rate_per_interval"),
    (dict(aerodrome_ids=AERO, rate_per_interval=float("nan")), "rate_per_interval"),
    (dict(aerodrome_ids=AERO, rate_per_interval=1, interval_s=0), "interval_s"),
    (dict(aerodrome_ids=AERO, rate_per_interval=1, window_s=-3), "window_s"),
    (dict(aerodrome_ids=AERO, rate_per_interval=1, seed=-1), "seed"),
])
def test_bad_generator_arguments_name_the_field(kwargs, field):
    with pytest.raises(DemandError, match=field):
        RequestGenerator(**kwargs)


def test_demand_file_parsing_sorts_and_fills_windows():
    entries = parse_demand([
        {"t_s": 30, "origin": "B", "destination": "A", "id": "late"},
        {"t_s": 0, "origin": "A", "destination": "B", "window_s": 120},
        {"t_s": 0, "origin": "C", "destination": "A", "latest_s": 10},
    ], AERO)
    assert [e.request_id for e in entries] == ["d00001", "d00002", "late"]
    assert [e.latest_s for e in entries] == [120.0, 10.0, 90.0]
    req = entries[2].to_request()
    assert (req.request_time_s, req.earliest_departure_s, req.latest_departure_s) == (30.0, 30.0, 90.0)
    assert parse_demand({"requests": []}) == []


@pytest.mark.parametrize("item, match", [
    ({"origin": "A", "destination": "B"}, r"\[0\]\.t_s: missing"),
    ({"t_s": 0, "origin": "A"}, r"\[0\]\.destination: missing"),
    ({"t_s": -5, "origin": "A", "destination": "B"}, r"\[0\]\.t_s: -5"),
    ({"t_s": "soon", "origin": "A", "destination": "B"}, r"\[0\]\.t_s: 'soon'"),
    ({"t_s": 0, "origin": "A", "destination": "A"}, r"\[0\]\.destination: 'A'"),
    ({"t_s": 0, "origin": "A", "destination": "Z"}, r"\[0\]\.destination: 'Z' is not an aerodrome"),
    ({"t_s": 0, "origin": "A", "destination": "B", "window_s": -1}, r"\[0\]\.window_s: -1"),
    ({"t_s": 9, "origin": "A", "destination": "B", "latest_s": 5}, r"\[0\]\.latest_s: 5"),
    ({"t_s": 0, "origin": "A", "destination": "B", "latest_s": 5, "window_s": 5}, r"latest_s"),
    ({"t_s": 0, "origin": "A", "destination": "B", "speed": 5}, r"\[0\]\.speed: unknown field \(value 5; known: "),
])
def test_demand_file_errors_name_the_field_and_value(item, match):
    with pytest.raises(DemandError, match=match):
        parse_demand([item], AERO)


def test_duplicate_ids_and_non_list_are_rejected(tmp_path):
    with pytest.raises(DemandError, match=r"\[1\]\.id: 'x'"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "id": "x"},
                      {"t_s": 1, "origin": "B", "destination": "A", "id": "x"}])
    p = tmp_path / "bad.yaml"
    p.write_text("just: text\n")
    with pytest.raises(DemandError, match="bad.yaml"):
        load_demand(p)


def test_schedule_hands_requests_to_the_first_instant_at_or_after_them():
    entries = parse_demand([{"t_s": t, "origin": "A", "destination": "B", "id": f"q{t}"}
                            for t in (0, 15, 30, 31, 95)])
    s = DemandSchedule(entries, interval_s=30.0)
    got = {i: [r.request_id for r in s.requests_at(30.0 * i, i)] for i in range(5)}
    assert got == {0: ["q0"], 1: ["q15", "q30"], 2: ["q31"], 3: [], 4: ["q95"]}
    assert s.requests_at(30.0, 1)[0].request_time_s == 15.0


def test_example_demand_file_matches_the_singapore_network():
    from uam_planner.network import load_network
    net = load_network(REPO / "config/networks/singapore.yaml")
    entries = load_demand(REPO / "config/demand_example.yaml", net.aerodrome_ids)
    assert len(entries) >= 10
    assert all(e.origin in net.aerodrome_ids and e.destination in net.aerodrome_ids for e in entries)


def test_priority_and_operator_mix_is_seeded_and_leaves_the_paper_stream_unchanged():
    plain = RequestGenerator(AERO, 10, seed=4)
    mixed = RequestGenerator(AERO, 10, seed=4, priority_share=0.05, priority_class=3,
                             operators=["op1", "op2", "op3"])
    a = [r for e in range(200) for r in plain.requests_for_epoch(e)]
    b = [r for e in range(200) for r in mixed.requests_for_epoch(e)]
    # same requests, only the class and the operator added
    assert [(r.request_id, r.origin_id, r.destination_id, r.latest_departure_s) for r in a] == \
        [(r.request_id, r.origin_id, r.destination_id, r.latest_departure_s) for r in b]
    assert {r.priority for r in a} == {0} and {r.operator_id for r in a} == {""}
    n_prio = sum(r.priority == 3 for r in b)
    assert {r.priority for r in b} == {0, 3}
    # 2,000 requests at 5 %: 100 expected, sd 9.7; seeded, so the count is fixed
    assert 70 < n_prio < 130
    assert n_prio == sum(r.priority == 3 for e in range(200)
                         for r in RequestGenerator(AERO, 10, seed=4, priority_share=0.05,
                                                   priority_class=3,
                                                   operators=["op1", "op2", "op3"]
                                                   ).requests_for_epoch(e))
    assert {r.operator_id for r in b} == {"op1", "op2", "op3"}


@pytest.mark.parametrize("kwargs, message", [
    ({"priority_share": 1.5}, r"priority_share: 1.5 must be a number in \[0, 1\]"),
    ({"priority_class": 0}, r"priority_class: 0 must be an integer in \[1, 255\]"),
    ({"priority_class": 256}, r"priority_class: 256 must be an integer in \[1, 255\]"),
    ({"operators": "abc"}, r"operators: 'abc' must be a list of operator ids"),
    ({"operators": ["a b"]}, r"operators: 'a b' must be 1 to 64 characters"),
])
def test_bad_mix_options_are_named(kwargs, message):
    with pytest.raises(DemandError, match=message):
        RequestGenerator(AERO, 1, seed=0, **kwargs)


def test_demand_file_priority_and_operator():
    entries = parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "priority": 5,
                             "operator": "medic"},
                            {"t_s": 10, "origin": "B", "destination": "A"}], AERO)
    r = [e.to_request() for e in entries]
    assert [(x.priority, x.operator_id) for x in r] == [(5, "medic"), (0, "")]
    with pytest.raises(DemandError, match=r"demand\[0\]\.priority: 300 is not an integer in \[0, 255\]"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "priority": 300}], AERO)
    with pytest.raises(DemandError, match=r"demand\[0\]\.priority: True is not an integer"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "priority": True}], AERO)
    with pytest.raises(DemandError, match=r"demand\[0\]\.operator: 'x/y' must be 1 to 64"):
        parse_demand([{"t_s": 0, "origin": "A", "destination": "B", "operator": "x/y"}], AERO)


def test_lead_time_files_requests_ahead_with_the_same_stream():
    plain = RequestGenerator(AERO, 3, seed=2).requests_for_epoch(4)
    ahead = RequestGenerator(AERO, 3, seed=2, lead_time_s=600.0).requests_for_epoch(4)
    assert [(r.origin_id, r.destination_id, r.request_time_s) for r in plain] == \
        [(r.origin_id, r.destination_id, r.request_time_s) for r in ahead]
    assert [(r.earliest_departure_s, r.latest_departure_s) for r in ahead] == [(720.0, 780.0)] * 3
    with pytest.raises(DemandError, match=r"lead_time_s: -1 must be a finite number >= 0"):
        RequestGenerator(AERO, 3, lead_time_s=-1)


def test_operators_with_their_own_filing_habits():
    gen = RequestGenerator(AERO, 10, seed=5, operators=["early", "late"], lead_time_s=30.0,
                           operator_lead_times_s=[600.0, 0.0])
    reqs = [r for e in range(5) for r in gen.requests_for_epoch(e)]
    for r in reqs:
        lead = r.earliest_departure_s - r.request_time_s
        assert lead == (630.0 if r.operator_id == "early" else 30.0)
        assert r.latest_departure_s - r.earliest_departure_s == 60.0
    assert {r.operator_id for r in reqs} == {"early", "late"}
    with pytest.raises(DemandError, match=r"operator_lead_times_s: 1 values for 2 operators"):
        RequestGenerator(AERO, 1, operators=["a", "b"], operator_lead_times_s=[5.0])
    with pytest.raises(DemandError, match=r"operator_lead_times_s: -5.0 must be a finite number >= 0"):
        RequestGenerator(AERO, 1, operators=["a"], operator_lead_times_s=[-5.0])
