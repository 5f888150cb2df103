"""Constraints (issue 22): the exact segment-prism test on hand-computed cases, its ties, bad
input named by field and value, files, and the planner never approving a flight into one."""

import json
import math
from pathlib import Path

import numpy as np
import pytest

from uam_planner import constraints as constraints_module
from uam_planner.constraints import (MAX_VERTICES, Constraint, ConstraintError, ConstraintSet,
                                     constraints_from_geojson, load_constraints,
                                     prism_entry_times)
from uam_planner.network import load_network, network_from_enu
from uam_planner.planning import FlightRequest, Planner, PlanningConfig
from uam_planner.trajectory import Trajectory

REPO = Path(__file__).resolve().parents[3]
SQUARE = ((0.0, 0.0), (100.0, 0.0), (100.0, 100.0), (0.0, 100.0))


def box(cid="box", lower=0.0, upper=200.0, start=0.0, end=1000.0, ring=SQUARE, **kw):
    return Constraint(cid, 1, "test", start, end, rings_m=(ring,), lower_m=lower, upper_m=upper, **kw)


def entry(c, p_start, p_end, t0, t1):
    """Entry time of the one segment from p_start at t0 to p_end at t1."""
    a, b = np.array(p_start, float), np.array(p_end, float)
    v = (b - a) / (t1 - t0)
    return float(prism_entry_times([t0], [t1], a[None], v[None], c)[0])


# ---- the segment-prism test, by hand ----------------------------------------------------------

@pytest.fixture(params=["dense", "indexed"])
def polygon_path(request, monkeypatch):
    """Run a polygon test through both implementations: every segment x every edge, and the
    STR-tree of edges used for outlines of many vertices."""
    monkeypatch.setattr(constraints_module, "INDEXED_MIN_VERTICES", 10**9 if request.param == "dense" else 3)
    return request.param


def test_segment_cutting_a_corner_enters_where_it_meets_the_first_edge(polygon_path):
    # line x + y = 10 from (-50, 60) to (60, -50) over t in [0, 110]: x = -50 + t meets the
    # edge x = 0 at (0, 10), t = 50, and leaves through y = 0 at (10, 0), t = 60
    assert entry(box(), (-50, 60, 100), (60, -50, 100), 0.0, 110.0) == pytest.approx(50.0, abs=1e-9)


def test_segment_through_the_corner_point_only_counts_as_entering(polygon_path):
    # x + y = 0 touches the square at its corner (0, 0) alone, at t = 50: touching is entering
    assert entry(box(), (-50, 50, 100), (50, -50, 100), 0.0, 100.0) == 50.0
    # the parallel line x + y = -10 misses it
    assert entry(box(), (-50, 40, 100), (40, -50, 100), 0.0, 90.0) == math.inf


def test_segment_over_the_prism_above_its_band_is_clear(polygon_path):
    assert entry(box(upper=200.0), (-100, 50, 250), (200, 50, 250), 0.0, 300.0) == math.inf
    # level exactly at upper_m: the band is closed, so it enters at x = 0, t = 100
    assert entry(box(upper=200.0), (-100, 50, 200), (200, 50, 200), 0.0, 300.0) == 100.0


def test_climbing_segment_is_clipped_by_the_band(polygon_path):
    # x = -100 + t, z = 100 + t: over the square (t in [100, 200]) z runs 200 -> 300, so it is in
    # the band [0, 200] only at t = 100, on the square's edge: a touch, refused at t = 100
    assert entry(box(upper=200.0), (-100, 50, 100), (200, 50, 400), 0.0, 300.0) == 100.0
    # a band ending 0.1 m lower is left (t <= 99.9) before the square is reached (t >= 100)
    assert entry(box(upper=199.9), (-100, 50, 100), (200, 50, 400), 0.0, 300.0) == math.inf
    # descending through the band over the square: z = 400 - t is <= 200 from t = 200 on, at
    # x = 100 (the far edge): enters at t = 200
    assert entry(box(upper=200.0), (-100, 50, 400), (200, 50, 100), 0.0, 300.0) == 200.0


def test_time_window_is_half_open(polygon_path):
    # x = -100 + t: in the square for t in [100, 200]
    path = ((-100, 50, 100), (200, 50, 100), 0.0, 300.0)
    assert entry(box(end=100.0), *path) == 100.0       # entry time, not yet compared to end_s
    s = ConstraintSet([box(end=100.0)], network_from_enu(
        "n", ["A", "B"], [(0, 0, 0), (1, 0, 0)], [True, True], [("A", "B")]))
    tr = Trajectory(np.array([0.0, 300.0]), np.array([[-100, 50, 100], [200, 50, 100]], float))
    which, _ = s.violations([tr], [0], [1])
    assert which.tolist() == [-1]                       # there exactly at end_s: allowed
    assert entry(box(end=100.5), *path) == 100.0        # window still open at t = 100
    assert entry(box(end=50.0), *path) == math.inf      # closes before the flight gets there
    assert entry(box(start=150.0), *path) == 150.0      # inside when the window opens
    assert entry(box(start=200.0), *path) == 200.0      # on the far edge as it opens: a touch
    assert entry(box(start=200.5), *path) == math.inf   # gone before it opens


def test_circle_tangent_secant_and_miss():
    c = Constraint("disk", 1, "", 0.0, 1000.0, center_m=(0.0, 0.0), radius_m=100.0,
                   lower_m=0.0, upper_m=500.0)
    # y = 100 is tangent at (0, 100), reached at t = 200 (disc = 0 exactly)
    assert entry(c, (-200, 100, 50), (200, 100, 50), 0.0, 400.0) == 200.0
    assert entry(c, (-200, 100.001, 50), (200, 100.001, 50), 0.0, 400.0) == math.inf
    # through the centre: enters at x = -100, t = 100
    assert entry(c, (-200, 0, 50), (200, 0, 50), 0.0, 400.0) == 100.0
    # starting inside: at once
    assert entry(c, (10, 10, 50), (300, 10, 50), 5.0, 300.0) == 5.0


def test_vertical_segment_inside_on_edge_and_outside(polygon_path):
    # a pad climb (no horizontal motion): inside, on the boundary (touch), outside
    assert entry(box(lower=50.0), (50, 50, 0), (50, 50, 100), 0.0, 10.0) == 5.0   # z = 50 at t = 5
    assert entry(box(lower=50.0), (100, 50, 0), (100, 50, 100), 0.0, 10.0) == 5.0
    assert entry(box(lower=50.0), (101, 50, 0), (101, 50, 100), 0.0, 10.0) == math.inf


def test_polygon_with_a_hole_and_concave_notch(polygon_path):
    hole = ((40.0, 40.0), (60.0, 40.0), (60.0, 60.0), (40.0, 60.0))
    c = Constraint("ring", 1, "", 0.0, 1e3, rings_m=(SQUARE, hole), lower_m=0.0, upper_m=1e3)
    assert entry(c, (45, 45, 10), (55, 55, 10), 0.0, 10.0) == math.inf   # inside the hole
    assert entry(c, (50, 50, 10), (50, 80, 10), 0.0, 30.0) == 10.0      # leaves the hole at y=60
    # a U shape: the notch (40..60 x 30..100) is outside
    u = ((0, 0), (100, 0), (100, 100), (60, 100), (60, 30), (40, 30), (40, 100), (0, 100))
    cu = Constraint("u", 1, "", 0.0, 1e3, rings_m=(u,), lower_m=0.0, upper_m=1e3)
    assert entry(cu, (50, 200, 10), (50, 40, 10), 0.0, 160.0) == math.inf
    assert entry(cu, (50, 200, 10), (50, 0, 10), 0.0, 200.0) == 170.0   # y = 30 at t = 170


def test_random_segments_agree_with_shapely(polygon_path):
    """The closed-form test against an independent one (GEOS) on random segments of a concave
    polygon, band and window unbounded: entering <=> the closed segment meets the polygon."""
    import shapely
    rng = np.random.default_rng(7)
    star = [(math.cos(a) * r, math.sin(a) * r) for a, r in
            zip(np.linspace(0, 2 * np.pi, 14, endpoint=False), [300, 120] * 7)]
    c = Constraint("star", 1, "", 0.0, math.inf, rings_m=(star,))
    a = rng.uniform(-500, 500, (4000, 2))
    b = a + rng.uniform(-300, 300, (4000, 2))
    b[:300] = a[:300]          # point segments (a vertical climb seen from above)
    b[300:400, 1] = a[300:400, 1]  # horizontal ones, parallel to some edges
    p0 = np.column_stack([a, np.zeros(4000)])
    v = np.column_stack([b - a, np.zeros(4000)])
    ours = np.isfinite(prism_entry_times(np.zeros(4000), np.ones(4000), p0, v, c))
    poly = shapely.Polygon(star)
    ref = shapely.intersects(poly, shapely.linestrings(np.stack([a, b], axis=1)))
    assert ours.sum() > 500 and (~ours).sum() > 500
    assert (ours == ref).all()


def test_many_vertex_outline_dense_and_indexed_agree(monkeypatch):
    """A 600-vertex wavy outline: the STR-tree path and the all-pairs path give the same entry
    times (not just the same yes/no) on random segments, and GEOS agrees on yes/no."""
    import shapely
    rng = np.random.default_rng(11)
    ang = np.linspace(0, 2 * np.pi, 600, endpoint=False)
    rad = 400 + 80 * np.sin(9 * ang)
    c = Constraint("wavy", 1, "", 0.0, math.inf, rings_m=(np.column_stack([rad * np.cos(ang), rad * np.sin(ang)]),))
    a = rng.uniform(-600, 600, (3000, 2))
    b = a + rng.uniform(-200, 200, (3000, 2))
    b[:200] = a[:200]
    p0 = np.column_stack([a, np.zeros(3000)])
    v = np.column_stack([(b - a) / 10.0, np.zeros(3000)])  # from a at t = 0 to b at t = 10
    res = {}
    for name, limit in (("dense", 10**9), ("indexed", 3)):
        monkeypatch.setattr(constraints_module, "INDEXED_MIN_VERTICES", limit)
        res[name] = prism_entry_times(np.zeros(3000), np.full(3000, 10.0), p0, v, c)
    assert np.array_equal(res["dense"], res["indexed"])
    ref = shapely.intersects(shapely.Polygon(c.rings_m[0]), shapely.linestrings(np.stack([a, b], axis=1)))
    assert (np.isfinite(res["dense"]) == ref).all() and 300 < ref.sum() < 2700


# ---- bad input ----------------------------------------------------------------------------------

def tiny():
    return load_network(REPO / "config/networks/tiny.yaml")


@pytest.mark.parametrize("make, says", [
    (lambda: box(ring=((0, 0), (100, 100), (100, 0), (0, 100))), "invalid polygon: Self-intersection"),
    (lambda: box(lower=100.0, upper=50.0), "upper_m: 50.0 is not above lower_m 100.0"),
    (lambda: box(start=10.0, end=5.0), "end_s: 5.0 is not after start_s 10.0"),
    (lambda: box(ring=tuple((math.cos(a), math.sin(a)) for a in
                            np.linspace(0, 2 * np.pi, MAX_VERTICES + 1, endpoint=False))),
     f"{MAX_VERTICES + 1} vertices, more than the {MAX_VERTICES}"),
    (lambda: Constraint("c", 1, "", 0.0, 10.0, center_m=(0.0, 0.0), radius_m=-5.0), "radius_m: -5.0"),
    (lambda: Constraint("c", -1, "", 0.0, 10.0, vertiport_id="A"), "version: -1"),
    (lambda: Constraint("", 1, "", 0.0, 10.0, vertiport_id="A"), "id: ''"),
    (lambda: Constraint("c", 1, "", 0.0, 10.0), "geometry: exactly one"),
    (lambda: Constraint("c", 1, "", float("nan"), 10.0, vertiport_id="A"), "start_s: nan"),
])
def test_bad_constraints_are_refused_naming_field_and_value(make, says):
    with pytest.raises(ConstraintError, match=None) as err:
        make()
    assert says in str(err.value)


def test_set_level_refusals_name_field_and_value():
    net = tiny()
    with pytest.raises(ConstraintError, match="vertiport_id: 'Z' is not a vertiport"):
        ConstraintSet([Constraint("c", 1, "", 0.0, 10.0, vertiport_id="Z")], net)
    with pytest.raises(ConstraintError, match="vertiport_id: 'W1' is not a vertiport"):
        ConstraintSet([Constraint("c", 1, "", 0.0, 10.0, vertiport_id="W1")], net)
    with pytest.raises(ConstraintError, match=r"pad: 1 is not a pad of 'A' \(it has 1: 0..0\)"):
        ConstraintSet([Constraint("c", 1, "", 0.0, 10.0, vertiport_id="A", pad_index=1)], net)
    with pytest.raises(ConstraintError, match=r"end_s: 10.0 is in the past \(now is 20.0 s\)"):
        ConstraintSet([box(end=10.0)], net, now_s=20.0)
    with pytest.raises(ConstraintError, match="id: 'box' appears twice"):
        ConstraintSet([box(), box()], net)
    ConstraintSet([box(end=10.0)], net, now_s=5.0)  # still on: accepted


def feature(props, geometry):
    return {"type": "Feature", "properties": props, "geometry": geometry}


def test_geojson_in_lon_lat_and_enu(tmp_path):
    net = tiny()  # origin lat 1.29, lon 103.85
    d = 0.001
    ring = [[103.85 - d, 1.29 - d], [103.85 + d, 1.29 - d], [103.85 + d, 1.29 + d],
            [103.85 - d, 1.29 + d], [103.85 - d, 1.29 - d]]
    doc = {"type": "FeatureCollection", "features": [
        feature({"id": "p", "version": 2, "reason": "fire", "lower_m": 0, "upper_m": 300,
                 "start_s": 0, "end_s": 600}, {"type": "Polygon", "coordinates": [ring]}),
        feature({"id": "c", "version": 1, "reason": "", "lower_m": 0, "upper_m": 300,
                 "start_s": 0, "end_s": 600, "radius_m": 50}, {"type": "Point", "coordinates": [103.85, 1.29]}),
        feature({"id": "x", "version": 1, "reason": "pad works", "vertiport_id": "B",
                 "start_s": 0, "end_s": 600}, None)]}
    path = tmp_path / "c.geojson"
    path.write_text(json.dumps(doc))
    s = load_constraints(path, net)
    p, c, x = s.constraints
    assert (p.kind, p.version, p.reason, c.kind, x.kind, x.vertiport_id) == \
        ("polygon", 2, "fire", "circle", "closure", "B")
    # 0.001 deg of latitude is 110.6 m at 1.29 deg N, of longitude 111.3 m x cos(1.29 deg)
    east, north = p.rings_m[0][2]
    assert east == pytest.approx(111.3, abs=0.3) and north == pytest.approx(110.6, abs=0.3)
    assert c.center_m == pytest.approx((0.0, 0.0), abs=1e-6)
    enu = {"type": "FeatureCollection", "frame": "enu", "features": [
        feature({"id": "p", "version": 0, "lower_m": 0, "upper_m": 1, "start_s": 0, "end_s": 1},
                {"type": "Polygon", "coordinates": [[[0, 0], [10, 0], [10, 10], [0, 0]]]})]}
    assert constraints_from_geojson(enu)[0].rings_m[0].tolist() == [[0, 0], [10, 0], [10, 10]]


def test_geojson_errors_name_the_feature_and_field():
    net = tiny()
    good = {"id": "p", "version": 1, "lower_m": 0, "upper_m": 100, "start_s": 0, "end_s": 60}
    sq = {"type": "Polygon", "coordinates": [[[0, 0], [1, 0], [1, 1], [0, 1]]]}
    cases = [
        ({**good, "upper_m": -5}, sq, "features[0] (id 'p'): constraint 'p': upper_m: -5 is not above"),
        ({k: v for k, v in good.items() if k != "start_s"}, sq, "features[0] (id 'p').properties.start_s: missing"),
        (good, {"type": "LineString", "coordinates": [[0, 0], [1, 1]]}, "geometry.type: 'LineString'"),
        (good, {"type": "Polygon", "coordinates": [[[0, 0], [1, 1], [1, 0], [0, 1]]]}, "Self-intersection"),
        (good, {"type": "Polygon", "coordinates": [[[i, i * i] for i in range(10_001)]]},
         "10001 positions, more than the"),
    ]
    for props, geom, says in cases:
        doc = {"type": "FeatureCollection", "frame": "enu", "features": [feature(props, geom)]}
        with pytest.raises(ConstraintError) as err:
            constraints_from_geojson(doc, net)
        assert says in str(err.value), str(err.value)
    bad_lonlat = {"type": "FeatureCollection", "features": [feature(good, {
        "type": "Polygon", "coordinates": [[[1.29, 200.0], [1.3, 1.0], [1.3, 1.1]]]})]}
    with pytest.raises(ConstraintError, match=r"are not \[lon, lat\] degrees"):
        constraints_from_geojson(bad_lonlat, net)


# ---- the planner: never into a constraint ---------------------------------------------------------

def two_route_network():
    """A -> B directly through m (1 km) or around through n (2 x 707 m)."""
    return network_from_enu("two", ["A", "m", "n", "B"],
                            [(0, 0, 0), (500, 0, 0), (500, 500, 0), (1000, 0, 0)],
                            [True, False, False, True],
                            [("A", "m"), ("m", "B"), ("A", "n"), ("n", "B")])


def req(rid, o, d, t, latest=None):
    return FlightRequest(rid, o, d, t, t, t + 20.0 if latest is None else latest)


OVER_M = ((400.0, -100.0), (600.0, -100.0), (600.0, 100.0), (400.0, 100.0))


@pytest.mark.parametrize("policy", ["mwis", "firstfit"])
def test_planner_refuses_the_direct_route_and_approves_the_detour(policy):
    net = two_route_network()
    p = Planner(net, PlanningConfig(k=2), policy)
    p.set_constraints([box("tfr", lower=-10.0, upper=500.0, end=1000.0, ring=OVER_M)])
    assert p.submit(req("r1", "A", "B", 0.0)) is None
    res = p.plan(0.0, 0)
    assert [f.route_node_ids for f in res.approved] == [("A", "n", "B")]
    # the detour keeps its weight against the unconstrained best: d*/d = 1000 / (2 x 707.1)
    assert res.approved[0].weight == pytest.approx(1000.0 / (2 * math.hypot(500, 500)))
    assert res.report.candidates == 1 and res.report.constraint_refusals == {}
    # without the constraint the direct route wins
    p2 = Planner(net, PlanningConfig(k=2), policy)
    p2.submit(req("r1", "A", "B", 0.0))
    assert [f.route_node_ids for f in p2.plan(0.0, 0).approved] == [("A", "m", "B")]


def test_fifo_waits_and_expires_naming_the_constraint():
    # the shortest-route baseline has no detour: its one candidate is refused every epoch
    net = two_route_network()
    p = Planner(net, PlanningConfig(k=2), "fifo")
    p.set_constraints([box("tfr", lower=-10.0, upper=500.0, end=1000.0, ring=OVER_M)])
    p.submit(req("r1", "A", "B", 0.0, latest=45.0))
    r0 = p.plan(0.0, 0)
    assert (r0.approved, [r.request_id for r in r0.waiting]) == ([], ["r1"])
    r1 = p.plan(30.0, 1)
    assert [r.request_id for r in r1.expired] == ["r1"]
    reason = r1.report.constraint_refusals["r1"]
    assert "constraint 'tfr' v1 (test)" in reason and "t = 70 s" in reason  # x = 400 at 40 s after departing at 30


def test_flight_entering_only_after_the_window_closes_is_approved():
    net = two_route_network()
    # the direct flight departing at 0 reaches x = 400 at t = 40 s; the window closes at 40
    p = Planner(net, PlanningConfig(k=1), "mwis")
    p.set_constraints([box("early", lower=-10.0, upper=500.0, start=0.0, end=40.0, ring=OVER_M)])
    p.submit(req("r1", "A", "B", 0.0))
    assert [f.route_node_ids for f in p.plan(0.0, 0).approved] == [("A", "m", "B")]
    # open 0.5 s longer, it would be entered: refused, and with k = 1 nothing else to offer
    p = Planner(net, PlanningConfig(k=1), "mwis")
    p.set_constraints([box("early", lower=-10.0, upper=500.0, start=0.0, end=40.5, ring=OVER_M)])
    p.submit(req("r1", "A", "B", 0.0))
    res = p.plan(0.0, 0)
    assert res.approved == [] and [r.request_id for r in res.expired] == ["r1"]
    assert "constraint 'early' v1" in res.report.constraint_refusals["r1"]


def test_closure_of_the_destination_vertiport():
    net = two_route_network()   # A -> B is 100 s at 10 m/s (the direct route)
    closed = Constraint("B-closed", 3, "pad repair", 50.0, 200.0, vertiport_id="B")
    for policy in ("mwis", "fifo", "firstfit"):
        p = Planner(net, PlanningConfig(k=2), policy)
        p.set_constraints([closed])
        for rid, o, d in (("to-B", "A", "B"), ("from-B", "B", "A")):
            p.submit(req(rid, o, d, 0.0))
        res = p.plan(0.0, 0)
        # from B at t = 0 is before the closure: approved; every arrival at B falls in [50, 200)
        assert [f.request_id for f in res.approved] == ["from-B"], policy
        assert [r.request_id for r in res.expired] == ["to-B"]
        assert "constraint 'B-closed' v3 (pad repair)" in res.report.constraint_refusals["to-B"]
    # an arrival at exactly end_s is allowed: window [0, 100) and the direct arrival at 100
    p = Planner(net, PlanningConfig(k=1), "mwis")
    p.set_constraints([Constraint("B-closed", 1, "", 0.0, 100.0, vertiport_id="B")])
    p.submit(req("to-B", "A", "B", 0.0))
    assert len(p.plan(0.0, 0).approved) == 1


def test_pad_closure_refuses_only_that_pad():
    net = network_from_enu("n", ["A", "B"], [(0, 0, 0), (1000, 0, 0)], [True, True], [("A", "B")])
    s = ConstraintSet([Constraint("pad", 1, "", 0.0, 100.0, vertiport_id="A", pad_index=0)], net)
    tr = Trajectory(np.array([10.0, 110.0]), np.array([[0, 0, 0], [1000, 0, 0]], float))
    which, when = s.violations([tr, tr], [0, 0], [1, 1], origin_pad=[0, 1], destination_pad=[0, 0])
    assert which.tolist() == [0, -1] and when[0] == 10.0


def test_empty_constraint_set_changes_nothing():
    from uam_planner.synthetic import generate_network
    net = generate_network(40, 6, seed=3)
    ids = [net.node_ids[i] for i in np.flatnonzero(net.is_aerodrome)]
    out = []
    for cs in (None, []):
        p = Planner(net, PlanningConfig(k=3), "mwis")
        if cs is not None:
            p.set_constraints(cs)
        for j in range(12):
            p.submit(req(f"r{j}", ids[j % len(ids)], ids[(j + 1 + j // len(ids)) % len(ids)], 0.0))
        out.append([(f.request_id, f.route_node_ids) for f in p.plan(0.0, 0).approved])
    assert out[0] == out[1] and len(out[0]) > 0


def ed269_zone(identifier="TFR01", restriction="PROHIBITED", **changes):
    d = 0.001
    ring = [[103.85 - d, 1.29 - d], [103.85 + d, 1.29 - d], [103.85 + d, 1.29 + d],
            [103.85 - d, 1.29 + d], [103.85 - d, 1.29 - d]]
    zone = {"identifier": identifier, "country": "SGP", "name": "test", "type": "COMMON",
            "restriction": restriction, "reason": ["EMERGENCY"], "message": "fire",
            "zoneAuthority": [{"name": "CAAS", "purpose": "AUTHORIZATION"}],
            "applicability": [{"permanent": "NO", "startDateTime": "2025-01-06T00:10:00Z",
                               "endDateTime": "2025-01-06T01:00:00.000Z"}],
            "geometry": [{"uomDimensions": "FT", "lowerLimit": 0, "lowerVerticalReference": "AGL",
                          "upperLimit": 400, "upperVerticalReference": "AGL",
                          "horizontalProjection": {"type": "Polygon", "coordinates": [ring]}}]}
    zone.update(changes)
    return zone


def test_ed269_zones_through_uas_standards(tmp_path):
    net = tiny()
    circle = ed269_zone("CIR01", geometry=[{
        "uomDimensions": "M", "lowerLimit": 50, "lowerVerticalReference": "AMSL",
        "upperVerticalReference": "AMSL",
        "horizontalProjection": {"type": "Circle", "center": [103.85, 1.29], "radius": 300}}],
        applicability=[{"permanent": "YES"}])
    doc = {"title": "t", "description": "", "features": [
        ed269_zone(), circle, ed269_zone("FREE01", restriction="NO_RESTRICTION")]}
    path = tmp_path / "zones.json"
    path.write_text(json.dumps(doc))
    s = load_constraints(path, net, scenario_start_utc="2025-01-06T00:00:00Z")
    poly, circ = s.constraints  # the NO_RESTRICTION zone constrains nothing
    assert (poly.constraint_id, poly.version, poly.reason) == ("TFR01", 0, "PROHIBITED: EMERGENCY / fire")
    assert (poly.start_s, poly.end_s) == (600.0, 3600.0)
    assert (poly.lower_m, poly.upper_m) == (0.0, pytest.approx(121.92))   # 400 ft
    assert (circ.kind, circ.radius_m, circ.start_s, circ.end_s) == ("circle", 300.0, -math.inf, math.inf)
    assert circ.lower_m == 50.0 and circ.upper_m == math.inf  # origin at 0 m: AMSL = up
    with pytest.raises(ConstraintError, match="ED-269"):
        load_constraints_doc(tmp_path, {"features": [{"identifier": "X"}]}, net)


def test_ed269_daily_schedules_become_time_windows(tmp_path):
    # The scenario starts Monday 2025-01-06 00:00Z; the period runs to Tuesday 14th 08:30Z.
    # MON, SAT 08:00Z-09:00Z: Monday 6th [28,800, 32,400) s, Saturday 11th from 5 x 86,400 +
    # 28,800 = 460,800 s, Monday 13th from 7 x 86,400 + 28,800 = 633,600 s (each 3,600 s).
    # TUE 22:00+0800-02:00+0800 (crosses midnight, Singapore time): Tuesday 7th 22:00 SGT = 7th
    # 14:00Z = 86,400 + 50,400 = 136,800 s, to 151,200 s; Tuesday 14th 22:00 SGT = 14:00Z is
    # after the period's end (08:30Z): left out.
    sched = ed269_zone(applicability=[{"permanent": "NO", "startDateTime": "2025-01-06T00:00:00Z",
                                       "endDateTime": "2025-01-14T08:30:00Z", "schedule": [
        {"day": ["MON", "SAT"], "startTime": "08:00Z", "endTime": "09:00Z"},
        {"day": ["TUE"], "startTime": "22:00+0800", "endTime": "02:00+0800"}]}])
    s = load_constraints_doc(tmp_path, {"features": [sched]}, net := tiny())
    got = [(c.constraint_id, c.start_s, c.end_s) for c in s.constraints]
    assert got == [("TFR01.0.0", 28800.0, 32400.0), ("TFR01.0.1", 136800.0, 151200.0),
                   ("TFR01.0.2", 460800.0, 464400.0), ("TFR01.0.3", 633600.0, 637200.0)], got
    # every day (ANY) 23:30Z-00:30Z, cut to the period [00:10Z on the 6th, 01:00Z on the 8th)
    # = [600, 176,400) s: the 5th's window (to 00:30Z on the 6th = 1,800 s) cut to [600, 1,800);
    # the 6th's [84,600, 88,200); the 7th's [171,000, 174,600) whole.
    every = ed269_zone(applicability=[{"permanent": "NO", "startDateTime": "2025-01-06T00:10:00Z",
                                       "endDateTime": "2025-01-08T01:00:00Z", "schedule": [
        {"day": ["ANY"], "startTime": "23:30Z", "endTime": "00:30Z"}]}])
    s = load_constraints_doc(tmp_path, {"features": [every]}, net)
    assert [(c.start_s, c.end_s) for c in s.constraints] == [(600.0, 1800.0), (84600.0, 88200.0),
                                                             (171000.0, 174600.0)]
    # a schedule with no period end runs SCHEDULE_HORIZON_DAYS from the scenario's start
    from uam_planner.constraints import SCHEDULE_HORIZON_DAYS
    open_ended = ed269_zone(applicability=[{"permanent": "NO", "schedule": [
        {"day": ["ANY"], "startTime": "08:00Z", "endTime": "09:00Z"}]}])
    s = load_constraints_doc(tmp_path, {"features": [open_ended]}, net)
    assert len(s.constraints) == SCHEDULE_HORIZON_DAYS
    assert s.constraints[-1].start_s == (SCHEDULE_HORIZON_DAYS - 1) * 86400.0 + 28800.0
    with pytest.raises(ConstraintError, match="ED-269"):
        load_constraints_doc(tmp_path, {"features": [{"identifier": "X"}]}, net)


def load_constraints_doc(tmp_path, doc, net):
    path = tmp_path / "doc.json"
    path.write_text(json.dumps(doc))
    return load_constraints(path, net)


def test_pad_closure_in_the_planner_sends_arrivals_to_the_other_pad():
    """A layered network with 2 pads per vertiport and 2 levels: a candidate at level index i
    uses pad i mod 2 at each end. With pad 0 of every vertiport but one closed, the approved
    flights touching those vertiports fly level index 1 only (pad 1); without it both levels fly."""
    from uam_planner.planning import AirspaceConfig
    from uam_planner.synthetic import generate_network
    net = generate_network(30, 4, seed=2, levels_m=[60.0, 90.0], pads_per_vertiport=2)
    ids = list(net.aerodrome_ids)
    closed = [Constraint(f"pad0-{v}", 1, "", 0.0, 1e6, vertiport_id=v, pad_index=0) for v in ids]
    levels = {}
    for name, cs in (("free", None), ("pad 0 closed", closed)):
        p = Planner(net, PlanningConfig(k=3, airspace=AirspaceConfig("cylinder", 30.0, 0.0)), "mwis")
        if cs is not None:
            p.set_constraints(cs)
        for t in range(0, 300, 30):
            for j, o in enumerate(ids):
                p.submit(req(f"r{t}-{j}", o, ids[(j + 1 + t // 30) % len(ids)], float(t)))
            p.plan(float(t), t // 30)
        levels[name] = sorted({net.levels_m.index(f.level_m) for f in p.active})
    assert levels["free"] == [0, 1]
    assert levels["pad 0 closed"] == [1]


def test_bad_constraints_leave_the_planner_as_it_was():
    net = two_route_network()
    p = Planner(net, PlanningConfig(k=2), "mwis")
    p.set_constraints([box("tfr", lower=-10.0, upper=500.0, ring=OVER_M)])
    before = p.config.constraints
    with pytest.raises(ConstraintError, match="vertiport_id: 'Z'"):
        p.set_constraints([box("ok", ring=OVER_M), Constraint("bad", 1, "", 0.0, 9.0, vertiport_id="Z")])
    assert p.config.constraints is before
    p.set_constraints(None)
    assert p.config.constraints is None
