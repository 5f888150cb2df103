"""Planning cycle: submit validation, expiry, solver checking and fallback, safety, determinism."""

import numpy as np
import pytest

from uam_planner.audit import audit_flights
from uam_planner.network import network_from_enu
from uam_planner.planning import FlightRequest, Planner, PlanningConfig
from uam_planner.synthetic import generate_network


def corridor_network():
    """Two aerodromes joined by a single 1 km corridor (one route each way)."""
    return network_from_enu("line", ["A", "m", "B"], [(0, 0, 0), (500, 0, 0), (1000, 0, 0)],
                            [True, False, True], [("A", "m"), ("m", "B")])


def req(rid, o, d, t, latest=None, earliest=None):
    return FlightRequest(rid, o, d, t, t if earliest is None else earliest,
                         t + 60.0 if latest is None else latest)


@pytest.mark.parametrize("request_, field", [
    (req("r1", "X", "B", 0.0), "origin_id: 'X'"),
    (req("r1", "A", "m", 0.0), "destination_id: 'm' is not an aerodrome"),
    (req("r1", "A", "A", 0.0), "destination_id: 'A' is the same as origin_id"),
    (req("r1", "A", "B", 0.0, latest=-5.0), "latest_departure_s: -5.0"),
    (req("r1", "A", "B", float("nan")), "request_time_s: nan"),
    (req("r1", "A", "B", 0.0, latest=float("inf")), "latest_departure_s: inf"),
    (req("", "A", "B", 0.0), "request_id: ''"),
])
def test_submit_rejections_name_the_field(request_, field):
    p = Planner(corridor_network(), policy="fifo")
    reason = p.submit(request_)
    assert reason is not None and field in reason
    assert p.pending == []
    assert p.plan(0.0, 0).report.rejected == 1


def test_duplicate_request_id_is_rejected_even_after_approval():
    p = Planner(corridor_network(), policy="mwis")
    assert p.submit(req("r1", "A", "B", 0.0)) is None
    assert p.plan(0.0, 0).report.approved == 1
    assert "request_id: 'r1'" in p.submit(req("r1", "B", "A", 30.0))


@pytest.mark.parametrize("policy", ["mwis", "fifo"])
def test_conflicting_requests_wait_then_expire(policy):
    p = Planner(corridor_network(), PlanningConfig(epoch_s=30.0), policy)
    # Head-on on the single corridor: only one may fly.
    assert p.submit(req("r1", "A", "B", 0.0)) is None
    assert p.submit(req("r2", "B", "A", 0.0, latest=40.0)) is None
    # Window entirely between two epochs: expires at the first epoch without being eligible.
    assert p.submit(req("r3", "A", "B", 0.0, earliest=5.0, latest=20.0)) is None
    r0 = p.plan(0.0, 0)
    assert [f.request_id for f in r0.approved] == ["r1"]
    assert [r.request_id for r in r0.expired] == ["r3"]
    assert [r.request_id for r in r0.waiting] == ["r2"]
    rep = r0.report
    assert (rep.pending, rep.eligible, rep.approved, rep.expired, rep.active_flights) == (3, 2, 1, 1, 1)
    # At t=30 r1 is mid-corridor heading to B: r2 (B->A) still conflicts; latest 40 < 60: expires.
    r1 = p.plan(30.0, 1)
    assert r1.approved == [] and [r.request_id for r in r1.expired] == ["r2"]
    assert p.pending == [] and len(p.active) == 1
    # After r1 lands (t = 100 s) it is dropped from the active flights.
    p.plan(120.0, 2)
    assert p.active == []


def test_latest_departure_exactly_at_next_epoch_waits():
    p = Planner(corridor_network(), PlanningConfig(epoch_s=30.0), "fifo")
    p.submit(req("r1", "A", "B", 0.0))
    p.submit(req("r2", "B", "A", 0.0, latest=30.0))
    res = p.plan(0.0, 0)
    assert [r.request_id for r in res.waiting] == ["r2"] and res.expired == []


class Answer:
    def __init__(self, selected, backend="stub"):
        self.selected = selected
        self.backend = backend


@pytest.mark.parametrize("solver, reason", [
    # the reasons of the one answer checker, uam_solvers.check_selection
    (lambda w, e, g: Answer(np.arange(len(w))), "conflict"),
    (lambda w, e, g: Answer(np.array([len(w) + 3])), "out of range"),
    (lambda w, e, g: Answer(np.array([0, 0])), "duplicate"),
    (lambda w, e, g: Answer(np.array([0.5])), "integer"),
    (lambda w, e, g: 1 / 0, "ZeroDivisionError"),
    (lambda w, e, g: object(), "no 'selected'"),
])
def test_bad_solver_answers_fall_back_to_greedy(solver, reason):
    net = generate_network(40, 5, seed=2)
    p = Planner(net, policy="mwis", solve_mwis=solver)
    rng = np.random.default_rng(0)
    for i in range(8):
        o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
        p.submit(req(f"r{i}", o, d, 0.0))
    res = p.plan(0.0, 0)
    rep = res.report
    assert rep.fallback and reason in rep.fallback_reason and rep.backend_used == "greedy"
    assert rep.approved >= 1
    assert audit_flights(res.approved, 100.0).ok


def test_valid_injected_answer_is_used_and_reported():
    net = generate_network(40, 5, seed=2)
    calls = []

    def first_vertex(w, e, g):
        calls.append((len(w), e.shape))
        return Answer(np.array([0], dtype=np.int32), backend="mine")

    p = Planner(net, policy="mwis", solve_mwis=first_vertex)
    p.submit(req("r0", net.aerodrome_ids[0], net.aerodrome_ids[1], 0.0))
    p.submit(req("r1", net.aerodrome_ids[2], net.aerodrome_ids[3], 0.0))
    res = p.plan(0.0, 0)
    rep = res.report
    assert len(calls) == 1 and not rep.fallback and rep.backend_used == "mine"
    assert rep.selected.tolist() == [0] and [f.request_id for f in res.approved] == ["r0"]
    assert res.approved[0].candidate_index == rep.vertex_candidate_index[0]
    assert rep.vertex_request_ids[0] == "r0"
    assert rep.objective == pytest.approx(rep.weights[0])
    assert rep.vertices == len(rep.weights) and rep.edges == rep.edges_array.shape[0]


def run_scenario(net, policy, seed, epochs=25, per_epoch=8, solve_mwis=None):
    rng = np.random.default_rng(seed)
    p = Planner(net, PlanningConfig(), policy, solve_mwis=solve_mwis)
    flights, expired, reports, n = [], [], [], 0
    for e in range(epochs):
        t = 30.0 * e
        for _ in range(per_epoch):
            o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
            assert p.submit(req(f"r{n:04d}", o, d, t)) is None
            n += 1
        res = p.plan(t, e)
        flights += res.approved
        expired += res.expired
        reports.append(res.report)
    return p, flights, expired, reports, n


@pytest.mark.parametrize("policy", ["mwis", "fifo"])
@pytest.mark.parametrize("seed", range(5))
def test_no_two_approved_flights_ever_lose_separation(policy, seed):
    net = generate_network(45, 6, seed=100 + seed)
    p, flights, expired, reports, n = run_scenario(net, policy, seed)
    audit = audit_flights(flights, 100.0)
    assert audit.losses == [], audit.losses[:3]
    assert audit.pairs_checked > 0
    # Every accepted request is decided once or still pending.
    ids = [f.request_id for f in flights] + [r.request_id for r in expired] + \
        [r.request_id for r in p.pending]
    assert sorted(ids) == [f"r{i:04d}" for i in range(n)]
    # The scenarios are busy enough to exercise the deconfliction.
    assert sum(r.discarded for r in reports) > 0
    assert sum(r.expired for r in reports) > 0
    for f in flights:
        assert f.method == policy and f.departure_s == 30.0 * f.epoch_index
        assert f.route_node_ids[0] == f.origin_id and f.route_node_ids[-1] == f.destination_id


def test_mwis_with_solver_package_backend_is_safe():
    net = generate_network(45, 6, seed=7)
    _, flights, _, reports, _ = run_scenario(net, "mwis", 7, epochs=12)
    assert audit_flights(flights, 100.0).ok
    assert not any(r.fallback for r in reports)
    assert any(r.conflict_edges > 0 for r in reports)


@pytest.mark.parametrize("policy", ["mwis", "fifo"])
def test_same_inputs_give_the_same_approvals(policy):
    net = generate_network(45, 6, seed=3)
    runs = [run_scenario(net, policy, 42, epochs=15) for _ in range(2)]
    keys = [[(f.request_id, f.route_node_ids, f.departure_s, f.candidate_index) for f in r[1]]
            for r in runs]
    assert keys[0] == keys[1]
    for a, b in zip(runs[0][3], runs[1][3]):
        assert a.weights.tolist() == b.weights.tolist()
        assert a.edges_array.tolist() == b.edges_array.tolist()
        assert a.selected.tolist() == b.selected.tolist()


def test_config_validation_names_the_field():
    with pytest.raises(ValueError, match="epoch_s"):
        PlanningConfig(epoch_s=0.0)
    with pytest.raises(ValueError, match="k must"):
        PlanningConfig(k=0)
    with pytest.raises(ValueError, match="policy"):
        Planner(corridor_network(), policy="best")


def test_precomputed_routes_fill_the_cache_and_change_nothing():
    net = generate_network(45, 6, seed=3)
    p = Planner(net, PlanningConfig(precompute_routes=True), "mwis")
    assert len(p.cache) == 6 * 5
    before = p.cache.misses
    rng = np.random.default_rng(1)
    for i in range(5):
        o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
        p.submit(req(f"r{i}", o, d, 0.0))
    with_pre = [(f.request_id, f.route_node_ids) for f in p.plan(0.0, 0).approved]
    assert p.cache.misses == before
    q = Planner(net, PlanningConfig(), "mwis")
    rng = np.random.default_rng(1)
    for i in range(5):
        o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
        q.submit(req(f"r{i}", o, d, 0.0))
    assert [(f.request_id, f.route_node_ids) for f in q.plan(0.0, 0).approved] == with_pre


def test_new_config_rebuilds_the_route_cache_only_when_routes_change():
    net = generate_network(45, 6, seed=3)
    p = Planner(net, PlanningConfig(), "mwis")
    cache = p.cache
    p.config = PlanningConfig(backend="greedy", seed=5)
    assert p.cache is cache
    p.config = PlanningConfig(k=3)
    assert p.cache is not cache and p.cache.k == 3
    p.record_rejection()
    assert p.plan(0.0, 0).report.rejected == 1
    with pytest.raises(TypeError, match="PlanningConfig"):
        p.config = {"k": 3}


def test_solver_own_fallback_is_reported():
    net = generate_network(40, 5, seed=2)

    class Late(Answer):
        fallback = True
        message = "time limit reached; greedy answer"
        proven_optimal = False

    p = Planner(net, policy="mwis", solve_mwis=lambda w, e, g: Late(np.array([0]), backend="greedy"))
    p.submit(req("r0", net.aerodrome_ids[0], net.aerodrome_ids[1], 0.0))
    rep = p.plan(0.0, 0).report
    assert rep.fallback and rep.fallback_reason == "time limit reached; greedy answer"
    assert rep.backend_used == "greedy" and rep.approved == 1


def _requests(net, n, t, seed=0):
    rng = np.random.default_rng(seed)
    out = []
    for i in range(n):
        o, d = rng.choice(net.aerodrome_ids, 2, replace=False)
        out.append(req(f"r{t:g}_{i}", str(o), str(d), t))
    return out


@pytest.mark.parametrize("policy", ["mwis", "fifo"])
def test_prepare_then_commit_gives_what_plan_gives(policy):
    """The node prepares an epoch, awaits the solver, then commits: the same flights as plan()."""
    import uam_solvers
    from uam_planner.planning import call_solver

    net = generate_network(40, 5, seed=2)
    cfg = PlanningConfig(backend="exact")
    a, b = Planner(net, cfg, policy), Planner(net, cfg, policy)
    for k in range(4):
        for r in _requests(net, 6, 30.0 * k, seed=k):
            assert a.submit(r) is None and b.submit(r) is None
        ra = a.plan(30.0 * k, k)
        prep = b.prepare(30.0 * k, k)
        other = _requests(net, 1, 30.0 * k, seed=99 + k)[0]
        late = req(f"late{k}", other.origin_id, other.destination_id, 30.0 * k)
        assert b.submit(late) is None  # arrives while the solver works: waits for the next epoch
        assert a.submit(late) is None
        answer = None
        if prep.needs_solver:
            answer = call_solver(lambda w, e, g: uam_solvers.solve(w, e, groups=g, backend="exact"), prep.graph)
        rb = b.commit(prep, answer)
        assert [(f.request_id, f.route_node_ids) for f in ra.approved] == \
            [(f.request_id, f.route_node_ids) for f in rb.approved]
        assert [r.request_id for r in a.pending] == [r.request_id for r in b.pending]
        assert f"late{k}" in {r.request_id for r in b.pending}


def test_commit_checks_the_answer_in_one_place_and_falls_back():
    net = generate_network(40, 5, seed=2)
    p = Planner(net, PlanningConfig(backend="exact"), "mwis")
    for r in _requests(net, 8, 0.0):
        p.submit(r)
    prep = p.prepare(0.0, 0)
    assert prep.needs_solver
    with pytest.raises(RuntimeError):
        p.prepare(0.0, 0)  # one prepared epoch at a time
    res = p.commit(prep, "solver service uam/solve_mwis did not answer within 1.0 s")
    assert res.report.fallback and res.report.backend_used == "greedy"
    assert "did not answer" in res.report.fallback_reason
    assert res.approved and audit_flights(res.approved, 100.0).ok
