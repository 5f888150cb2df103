"""The committed corpus of the planner's rolling-horizon graphs (issue 20): `auto` proves them
through CP-SAT on the whole graph (KaMIS branch-and-reduce does not finish them), by their
structure, and the change leaves the synthetic paper-shaped graphs' route as it was. No timing
assertions: the limits are generous and the verdicts are the solvers' own."""

import numpy as np
import pytest

from uam_solvers import solve
from uam_solvers.auto import AutoBackend, triangle_ratio
from uam_solvers.base import MwisProblem
from uam_solvers.instances import (HORIZON_CORPUS, grouped_random_instance, load_corpus,
                                   real_corpus_path)
from uam_solvers.options import parse_options


@pytest.fixture(scope="module")
def corpus():
    return load_corpus(real_corpus_path(HORIZON_CORPUS))


def test_the_horizon_corpus_is_small_and_holds_both_horizons(corpus):
    assert real_corpus_path(HORIZON_CORPUS).stat().st_size < 1_100_000
    names = [e.name for e in corpus]
    assert {n.split("-r")[0] for n in names} == {"horizon-h5", "horizon-h10"}
    assert max(e.problem.n for e in corpus) > 2000
    for e in corpus:
        assert e.problem.groups and "horizon" in e.source and "epoch" in e.source


def _smallest_clique_structured(corpus):
    a = AutoBackend()
    opts = a.validate_options({})
    for e in sorted(corpus, key=lambda e: e.problem.n):
        p = e.problem
        if p.n > 600 and a._cpsat_suits(p, None, int(p.all_edges().shape[0]), opts):
            return p
    raise AssertionError("no clique-structured horizon graph above 600 vertices")


def test_auto_proves_a_horizon_graph_by_cpsat_with_or_without_a_kamis_proof(corpus):
    p = _smallest_clique_structured(corpus)
    # 120 s: CP-SAT proves it in 0.1-0.5 s CPU (1.3-2.3 s wall at load 15) and the solve
    # returns when proven, so the limit costs nothing and the proof does not depend on the load
    r = solve(p.weights, p.edges, list(p.groups), backend="auto", time_limit_s=120.0)
    assert p.is_independent(r.selected) and not r.fallback
    assert r.proven_optimal, r.stats
    ex = solve(p.weights, p.edges, list(p.groups), backend="exact", time_limit_s=30.0)
    if ex.proven_optimal:
        assert r.objective == pytest.approx(ex.objective, rel=1e-12)
    if r.stats["auto_method"] != "kamis":
        assert r.stats["auto_method"] == "cpsat (whole graph)"
    # the same graph without CP-SAT's route: not proven through the old route, or proven the same
    off = solve(p.weights, p.edges, list(p.groups), backend="auto", time_limit_s=1.0,
                options={"cpsat_fraction": 0.0})
    assert p.is_independent(off.selected)
    assert "cpsat (whole graph)" not in str(off.stats.get("auto_method"))


def test_the_cpsat_route_is_chosen_by_structure_not_by_size():
    a = AutoBackend()
    opts = a.validate_options({})
    # paper-shaped graphs (requests of 5 candidates): the clique cover is 5 per clique, below 8
    p = grouped_random_instance(500, 0)
    assert not a._cpsat_suits(p, None, int(p.all_edges().shape[0]), opts)
    # a random graph of large groups: G(n, p) triangles are at the edge density, refused
    rng = np.random.default_rng(1)
    n = 400
    iu, ju = np.triu_indices(n, 1)
    keep = rng.random(iu.size) < 0.3
    groups = [list(range(i, i + 20)) for i in range(0, n, 20)]
    g = MwisProblem.from_arrays(rng.random(n) + 0.5, np.stack([iu[keep], ju[keep]], 1), groups)
    assert triangle_ratio(g) < 2 * 2 * g.all_edges().shape[0] / (n * (n - 1))
    assert not a._cpsat_suits(g, None, int(g.all_edges().shape[0]), opts)
    # off by option
    assert not a._cpsat_suits(g, None, 0, {**opts, "cpsat_fraction": 0.0})


def test_cached_options_never_take_a_bool_for_a_number_or_skip_a_check():
    from uam_solvers.chszla import KamisBackend
    from uam_solvers.errors import MwisInputError

    spec = KamisBackend.options_spec
    assert parse_options("kamis", spec, {"finish_fraction": 1})["finish_fraction"] == 1
    with pytest.raises(MwisInputError, match="finish_fraction"):
        parse_options("kamis", spec, {"finish_fraction": 2})
    with pytest.raises(MwisInputError, match="finish_fraction"):
        parse_options("kamis", spec, {"finish_fraction": 2})  # again: refused, not cached
    a = parse_options("kamis", spec, {"finish_fraction": 0.5})
    a["finish_fraction"] = 0.7  # a caller's copy: the cache is not changed through it
    assert parse_options("kamis", spec, {"finish_fraction": 0.5})["finish_fraction"] == 0.5
    with pytest.raises(MwisInputError, match="unknown option"):
        parse_options("kamis", spec, {"nope": 1})


def test_a_cached_number_does_not_let_true_through():
    from uam_solvers.chszla import KamisBackend
    from uam_solvers.errors import MwisInputError

    spec = KamisBackend.options_spec
    parse_options("kamis", spec, {"finish_fraction": 1})  # cached: 1 == True and hash(1) == hash(True)
    with pytest.raises(MwisInputError, match="finish_fraction"):
        parse_options("kamis", spec, {"finish_fraction": True})


def _kamis_calls(monkeypatch, finishes_at_s=None, answer=None):
    """Record the limits auto gives KaMIS on the whole graph; with ``finishes_at_s`` KaMIS is a
    stand-in that returns ``answer`` (an optimum found beforehand), proven only when given at
    least that long, as a search stopped by its limit would otherwise."""
    from uam_solvers.base import make_result
    from uam_solvers.chszla import KamisBackend

    calls = []
    real = KamisBackend.solve

    def recording(self, problem, *, time_limit_s=10.0, seed=0, options=None):
        calls.append(float(time_limit_s))
        if finishes_at_s is None:
            return real(self, problem, time_limit_s=time_limit_s, seed=seed, options=options)
        return make_result(problem, answer, proven_optimal=time_limit_s >= finishes_at_s,
                           solve_time_s=min(time_limit_s, finishes_at_s), backend="kamis")

    monkeypatch.setattr(KamisBackend, "solve", recording)
    return calls


def _kamis_then_cpsat(corpus):
    """The horizon graph of 910 vertices: clustered (KaMIS gets it first) and clique-structured
    (CP-SAT follows), so KaMIS gets only its probe."""
    [e] = [e for e in corpus if e.name.endswith("-v910")]
    a = AutoBackend()
    p = e.problem
    assert a._cpsat_suits(p, None, int(p.all_edges().shape[0]), a.validate_options({}))
    return p


def _auto_here(p, time_limit_s, options=None):
    """auto's pipeline solved in this process (``solve`` runs auto above 64 vertices in a child
    process, where the recording stand-ins below would record out of sight)."""
    from uam_solvers import build_pipeline

    return build_pipeline("auto").solve(p, time_limit_s=time_limit_s, seed=0,
                                        options=options or {})


def test_the_kamis_probe_before_cpsat_gets_the_tie_break_budget_once(corpus, monkeypatch):
    # twelfth stop: on a graph that goes to CP-SAT, KaMIS's probe (0.01 of the limit, at least
    # 0.05 s) is given the tie-break's budget (3 x that: 0.15 s at 1 s) at once, and no re-run
    # follows a CP-SAT proof: one KaMIS call, not a probe and a re-run
    import uam_solvers.auto as auto_mod

    p = _kamis_then_cpsat(corpus)
    calls = _kamis_calls(monkeypatch)
    r = _auto_here(p, 1.0)
    assert p.is_independent(r.selected)
    assert calls == [pytest.approx(0.15)], r.stats
    if r.proven_optimal and r.stats["auto_method"] != "kamis":
        assert r.stats["tie_break"] == "kamis unfinished"
    # at most a quarter of the limit: at 0.4 s the probe is 0.1 s
    calls.clear()
    _auto_here(p, 0.4)
    assert calls[0] == pytest.approx(0.1)
    # with the tie-break off the probe stays the probe
    calls.clear()
    _auto_here(p, 1.0, {"tie_break": False})
    assert calls == [pytest.approx(0.05)]
    assert auto_mod.KAMIS_PROBE_MAX_SHARE == 0.25


def test_a_graph_kamis_proves_past_the_old_probe_is_answered_by_kamis_alone(corpus, monkeypatch):
    # KaMIS (a stand-in) finishes in 0.1 s: past the old 0.05 s probe, within the 0.15 s budget.
    # Before, CP-SAT proved first and the tie-break's re-run returned KaMIS's set; now KaMIS
    # answers at once: the same set, one KaMIS call and no CP-SAT
    import uam_solvers.auto as auto_mod
    from uam_solvers.cpsat import CpSatBackend

    p = _kamis_then_cpsat(corpus)
    ex = solve(p.weights, p.edges, list(p.groups), backend="exact", time_limit_s=60.0)
    assert ex.proven_optimal
    calls = _kamis_calls(monkeypatch, finishes_at_s=0.1, answer=ex.selected)
    now = _auto_here(p, 1.0)
    assert now.proven_optimal and now.stats["auto_method"] == "kamis"
    assert "tie_break" not in now.stats and calls == [pytest.approx(0.15)]
    assert now.selected.tolist() == sorted(ex.selected.tolist())
    calls.clear()
    monkeypatch.setattr(auto_mod, "KAMIS_PROBE_MAX_SHARE", 0.0)  # the probe as it was
    cpsat = []
    real = CpSatBackend.solve
    monkeypatch.setattr(CpSatBackend, "solve",
                        lambda self, *a, **k: cpsat.append(1) or real(self, *a, **k))
    before = _auto_here(p, 1.0)
    assert calls[0] == pytest.approx(0.05) and cpsat  # the probe ran out, CP-SAT followed
    if before.stats.get("tie_break") == "kamis":     # CP-SAT proved, the re-run finished
        assert calls == [pytest.approx(0.05), pytest.approx(0.15)]
        assert before.selected.tolist() == now.selected.tolist()
