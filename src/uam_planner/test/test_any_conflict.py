"""The check that decides (``separation.any_conflict``) against the pair list it replaces.

Deconfliction against the active flights needs one answer per candidate: does it lose
separation with any of them. ``any_conflict`` gives it without distances or pairs and stops
checking a candidate at its first loss; these tests hold it to the mask that the first column
of ``conflicting_pairs`` gives (the path the planner took before), bit for bit, on seeded random
cases with exact ties (a flight trailing another by exactly the separation, levels exactly V
apart and a rounding step off), with and without departure shifts, in both models, with the
planner's stages in time, finer ones and a single stage.
"""

import numpy as np
import pytest

from uam_planner import separation
from uam_planner.conflict_graph import ShiftedCandidates, build_conflict_graph
from uam_planner.separation import SegmentSet, SeparationModel, any_conflict, conflicting_pairs
from uam_planner.trajectory import Trajectory

SPHERE = SeparationModel("sphere", 100.0)
CYL = SeparationModel("cylinder", 100.0, 30.0)
LEVELS = [60.0, 90.0, 120.0, 150.0, 5.0]


def _flight(rng, t0):
    p = rng.uniform(-1500, 1500, 2)
    q = rng.uniform(-1500, 1500, 2)
    z0, z1 = rng.choice(LEVELS), rng.choice(LEVELS)
    dur = np.linalg.norm(q - p) / 10 + 5
    mid = (p + q) / 2
    return Trajectory(np.array([t0, t0 + dur / 2, t0 + dur]),
                      np.array([(*p, z0), (*mid, z1), (*q, z1)], float))


def _case(seed, n_a, n_b):
    """Random trajectories a and b; some of b fly a's path 10 s (= 100 m at 10 m/s, the
    separation exactly) ahead or behind, some a's path one level (V) up, some nudged by one
    rounding step off a level: the ties where a decision could flip on the last bit."""
    rng = np.random.default_rng(seed)
    a = [_flight(rng, rng.uniform(0, 60)) for _ in range(n_a)]
    b = [_flight(rng, rng.uniform(-200, 100)) for _ in range(n_b)]
    for k in range(0, n_a, 3):
        tr = a[k]
        lag = 10.0 * rng.choice([-1.0, 1.0, 2.0])
        pts = tr.points_m.copy()
        if k % 2:
            pts[:, 2] = pts[:, 2] + 30.0
        if k % 5 == 0:
            pts[1:, 2] = np.nextafter(pts[1:, 2], np.inf if k % 10 else -np.inf)
        b.append(Trajectory(tr.times_s + lag, pts))
    return a, b


def _mask(pairs, n):
    m = np.zeros(n, dtype=bool)
    m[pairs[:, 0]] = True
    return m


STAGES = [separation._DECIDE_STAGES_S, (5.0, 20.0, 60.0, 150.0), ()]

#: the pair lists' masks by case and setting, computed once for the three stage settings of a
#: case: conflicting_pairs does not read the deciding stages or chunks the tests vary
_WANT: dict = {}


def _want(key, a, b, model, n, **kw):
    """The mask of the pair list of case ``key`` (which fixes a, b and any shifts) in ``model``
    with the cell settings ``kw``."""
    full_key = (key, repr(model), repr(sorted((k, v) for k, v in kw.items() if k != "shifts_a")))
    if full_key not in _WANT:
        _WANT[full_key] = _mask(conflicting_pairs(a, b, model, **kw), n)
    return _WANT[full_key]


@pytest.mark.parametrize("stages", STAGES)
@pytest.mark.parametrize("model", [SPHERE, CYL])
@pytest.mark.parametrize("seed", range(6))
def test_any_conflict_matches_conflicting_pairs(model, seed, stages, monkeypatch):
    # small chunks: many candidates are decided in one chunk and skipped in the next ones; the
    # planner's stages, finer ones (most segments in a later stage than their trajectory's
    # first) and one stage
    monkeypatch.setattr(separation, "_DECIDE_PAIRS_PER_CHUNK", 64)
    monkeypatch.setattr(separation, "_DECIDE_STAGES_S", stages)
    a, b = _case(seed, 80, 120)
    want = _want(("plain", seed), a, b, model, len(a))
    assert 10 < want.sum() < len(a)
    assert any_conflict(a, b, model).tolist() == want.tolist()
    # other cells cut other pieces: at a tie the exact kernel may then round the other way, so
    # each setting is compared with the pair list of the same setting
    for kw in (dict(cell_m=150.0, bucket_s=15.0), dict(z_cell_m=model.vertical_reach_m)):
        want_kw = _want(("plain", seed), a, b, model, len(a), **kw)
        assert any_conflict(a, b, model, **kw).tolist() == want_kw.tolist()


@pytest.mark.parametrize("stages", STAGES)
@pytest.mark.parametrize("model", [SPHERE, CYL])
@pytest.mark.parametrize("seed", range(4))
def test_any_conflict_with_shifts_matches_conflicting_pairs(model, seed, stages, monkeypatch):
    monkeypatch.setattr(separation, "_DECIDE_PAIRS_PER_CHUNK", 64)
    monkeypatch.setattr(separation, "_DECIDE_STAGES_S", stages)
    base, active = _case(100 + seed, 40, 80)
    rng = np.random.default_rng(seed)
    counts = rng.integers(0, 8, len(base))               # 0..7 slots per template
    first = np.concatenate(([0], np.cumsum(counts)))
    shift = np.concatenate([5.0 * np.arange(c) for c in counts])
    st = {}
    want = _want(("shifted", seed), base, active, model, shift.size, shifts_a=(first, shift))
    got = any_conflict(base, active, model, shifts_a=(first, shift), stats=st)
    assert got.tolist() == want.tolist() and 10 < want.sum() < shift.size
    assert st["exact_checks"] > 0
    keyed = any_conflict(base, active, model, shifts_a=(first, shift),
                         z_cell_m=model.vertical_reach_m)
    assert keyed.tolist() == want.tolist()


def test_any_conflict_of_empty_or_disjoint_sets_is_all_false():
    a, b = _case(0, 5, 5)
    assert any_conflict(a, [], SPHERE).tolist() == [False] * 5
    assert any_conflict([], b, SPHERE).shape == (0,)
    later = [Trajectory(t.times_s + 1e5, t.points_m) for t in b]
    assert not any_conflict(a, later, SPHERE).any()
    with pytest.raises(ValueError, match="shifts_a"):
        any_conflict(a, b, SPHERE, shifts_a=(np.array([0, 1]), np.zeros(1)))


def test_conflict_graph_is_the_one_built_from_the_pair_list(monkeypatch):
    """The planner's graph with the deciding check equals the graph with the old discard (the
    first column of the pair list), shifted candidates included."""
    base, active = _case(7, 30, 60)
    counts = np.full(len(base), 7)
    first = np.concatenate(([0], np.cumsum(counts)))
    shift = np.tile(5.0 * np.arange(7), len(base))
    cands = ShiftedCandidates(base, first, shift)
    n = len(cands)
    req = np.arange(n) // 14
    args = (cands, req, np.arange(n) % 14, np.linspace(1.0, 0.5, n), int(req.max()) + 1,
            active, CYL)
    new = build_conflict_graph(*args)

    def old_path(a, b, sep, **kw):
        pairs = conflicting_pairs(a, b, sep, **kw)
        n_out = len(kw["shifts_a"][1]) if kw.get("shifts_a") is not None else len(a)
        return _mask(pairs, n_out)

    monkeypatch.setattr("uam_planner.conflict_graph.any_conflict", old_path)
    old = build_conflict_graph(*args)
    assert new.discarded.tolist() == old.discarded.tolist()
    assert 0 < old.n_discarded < n
    assert new.edges.tolist() == old.edges.tolist()
    assert new.weights.tolist() == old.weights.tolist()


def test_survivors_segments_are_those_of_their_trajectories():
    """``ShiftedCandidates.segments_of``: the survivors' segments without a trajectory each,
    the same floats as flattening their trajectories (a shift of 0 is the base itself)."""
    base, _ = _case(11, 12, 0)
    counts = np.array([0, 3, 1, 5, 2, 0, 4, 1, 3, 2, 6, 1])
    first = np.concatenate(([0], np.cumsum(counts)))
    shift = np.concatenate([np.array([0.0, 5.0, 7.5, 10.0, 12.5, 15.0])[:c] for c in counts])
    cands = ShiftedCandidates(base, first, shift)
    keep = np.array([0, 2, 3, 4, 9, 10, 11, 17, 20, len(cands) - 1])
    got = cands.segments_of(keep)
    want = SegmentSet.from_trajectories([cands[i] for i in keep])
    assert got.n_trajectories == want.n_trajectories == keep.size
    for name in ("traj", "t0_s", "t1_s", "p0_m", "v_mps"):
        assert getattr(got, name).tobytes() == getattr(want, name).tobytes(), name
    assert len(cands.segments_of(np.zeros(0, np.int64))) == 0


def _city_run(per_epoch: int = 50, epochs: int = 15) -> tuple:
    """The layered city (2,000 nodes, 100 vertiports, 4 levels, 4 pads), cylinder 100/30 m,
    5 s slots, ``per_epoch`` requests every 30 s between random distinct vertiports (window
    60 s), greedy MWIS: approvals, and every epoch's graph, as one digest."""
    import hashlib

    from uam_planner.planning import AirspaceConfig, FlightRequest, Planner, PlanningConfig
    from uam_planner.synthetic import generate_network
    from uam_solvers.greedy import greedy_mwis

    class _Answer:
        backend = "greedy"

        def __init__(self, selected):
            self.selected = selected

    net = generate_network(2000, 100, seed=0, levels_m=[60.0, 90.0, 120.0, 150.0],
                           pads_per_vertiport=4)
    planner = Planner(net, PlanningConfig(airspace=AirspaceConfig("cylinder", 30.0, 5.0)), "mwis",
                      solve_mwis=lambda w, e, g: _Answer(greedy_mwis(w, e)))
    rng = np.random.default_rng(3)
    h = hashlib.sha256()
    approved = discarded = 0
    for e in range(epochs):
        t = 30.0 * e
        for k in range(per_epoch):
            o, d = rng.choice(len(net.aerodrome_ids), 2, replace=False)
            planner.submit(FlightRequest(f"r{e:03d}-{k:03d}", net.aerodrome_ids[o],
                                         net.aerodrome_ids[d], t, t, t + 60.0))
        res = planner.plan(t, e)
        rep = res.report
        discarded += rep.discarded
        for f in res.approved:
            approved += 1
            h.update(f"{f.request_id}:{e}:{f.candidate_index}:{f.departure_s!r}:{f.level_m}:"
                     f"{' '.join(f.route_node_ids)}\n".encode())
        h.update(rep.weights.tobytes() + rep.edges_array.tobytes())
    return approved, discarded, h.hexdigest()[:16]


@pytest.mark.slow
def test_layered_city_decisions_are_those_of_the_pair_list_path():
    """Pinned on the commit before the deciding check (the pair list's first column): the same
    approvals and the same graph, weights and edges, epoch by epoch."""
    assert _city_run() == PINNED_CITY


PINNED_CITY = (748, 20509, "3aaf8e453522a914")  # computed at f58ce4d
