"""Plans as F3548 operational intents (issue 25, item 1; docs/f3548.md): hand-computed volumes,
ids, times and states; what a volume set proves and what it does not (a loss of separation always
intersects; separated flights may intersect; the stated bound makes them disjoint); schema
validation of every intent and constraint of short runs."""

import math
import re

import numpy as np
import pytest
from shapely.geometry import Point

from uam_planner.constraints import Constraint
from uam_planner.f3548 import (PRECISION_M, F3548Error, IntentContext, VolumeSpec, as_json,
                               published_intersections,
                               f3548_constraint, first_intersection, intent_id, intent_version, operational_intent,
                               ovn, rfc3339, trajectory_volumes, volumes_for_limit)
from uam_planner.f3548_schema import errors, validate, validate_implicit
from uam_planner.planning import Flight
from uam_planner.trajectory import Trajectory

ORIGIN = (1.29, 103.85, 0.0)
UUID4 = re.compile(r"^[0-9a-f]{8}-[0-9a-f]{4}-4[0-9a-f]{3}-[89ab][0-9a-f]{3}-[0-9a-f]{12}$")


def flight(times, points, request_id="r1", operator_id="op1", **kw):
    traj = Trajectory(np.asarray(times, float), np.asarray(points, float))
    return Flight(request_id, "A", "B", ("A", "B"), traj, traj.departure_s, traj.arrival_s,
                  0.0, 1.0, 0, "mwis", "greedy", 0, operator_id=operator_id, **kw)


def test_a_hand_built_plan_gives_the_expected_volumes():
    # 10 m/s east for 10 s (two 5 s pieces), then a 3 s climb of 30 m straight up
    traj = Trajectory(np.array([0.0, 10.0, 13.0]),
                      np.array([[0.0, 0.0, 100.0], [100.0, 0.0, 100.0], [100.0, 0.0, 130.0]]))
    vols = trajectory_volumes(traj, VolumeSpec(50.0, 50.0))
    assert len(vols) == 3
    # piece 1: x 0 -> 50, widened 50 m each side, 50 m beyond each end; band 100 -/+ 50
    np.testing.assert_allclose(vols[0].corners_m, [[-50, -50], [100, -50], [100, 50], [-50, 50]])
    assert (vols[0].lower_m, vols[0].upper_m, vols[0].t0_s, vols[0].t1_s) == (50.0, 150.0, 0.0, 5.0)
    np.testing.assert_allclose(vols[1].corners_m, [[0, -50], [150, -50], [150, 50], [0, 50]])
    assert (vols[1].t0_s, vols[1].t1_s) == (5.0, 10.0)
    # the climb (no horizontal motion): a 100 m square about (100, 0), band 100-50 .. 130+50
    np.testing.assert_allclose(vols[2].corners_m, [[50, -50], [150, -50], [150, 50], [50, 50]])
    assert (vols[2].lower_m, vols[2].upper_m, vols[2].t0_s, vols[2].t1_s) == (50.0, 180.0, 10.0, 13.0)
    # a separation gives half of it less F3548's 1 cm (the cylinder V / 2 vertically), so flights
    # exactly at the separation get volumes 2 cm apart; longer pieces cut fewer volumes
    from uam_planner.separation import SeparationModel
    assert VolumeSpec.for_separation(100.0) == VolumeSpec(49.99, 49.99)
    spec = VolumeSpec.for_separation(SeparationModel("cylinder", 100.0, 30.0), max_piece_s=10.0)
    assert (spec.horizontal_buffer_m, spec.vertical_buffer_m) == (49.99, 14.99)
    assert len(trajectory_volumes(traj, spec)) == 2
    # from_s keeps the piece flying at from_s whole and drops the ones that ended
    assert [v.t0_s for v in trajectory_volumes(traj, VolumeSpec.for_separation(100.0), 7.0)] == [5.0, 10.0]


def test_the_intent_reference_details_and_times():
    ctx = IntentContext(ORIGIN, VolumeSpec.for_separation(100.0),
                        scenario_start_utc="2025-01-06T08:00:00+08:00")
    f = flight([30.0, 40.0], [[0, 0, 120], [100, 0, 120]], priority=3, version=2)
    oi = operational_intent(f, 0.0, ctx)
    ref, det = oi.reference, oi.details
    assert UUID4.match(ref.id) and ref.id == intent_id("op1", "r1")
    assert intent_id("op1", "r1") != intent_id("op2", "r1")  # operators are told apart
    # plan version 2, Accepted: F3548 version 4 (1-3 were version 1's states)
    assert (ref.version, ref.state, ref.manager, ref.uss_availability) == (4, "Accepted",
                                                                            "uam-fleet", "Unknown")
    assert ref.ovn == ovn(ref.id, 4) and len(ref.ovn) == 32 and ref.ovn != ovn(ref.id, 1)
    # airborne: a new version, the same details (every volume, whenever asked)
    air = operational_intent(f, 35.0, ctx)
    assert (air.reference.version, air.reference.state) == (5, "Activated")
    assert as_json(air.details) == as_json(det) and as_json(operational_intent(f, 39.0, ctx)) == as_json(air)
    # 08:00+08:00 is 00:00Z; the plan flies from 30 s to 40 s
    assert ref.time_start.value == "2025-01-06T00:00:30.000000Z"
    assert ref.time_end.value == "2025-01-06T00:00:40.000000Z"
    assert det.priority == 3 and len(det.volumes) == 2 and det.off_nominal_volumes == []
    v = det.volumes[0].volume
    # corners 50 m south and north of the origin's parallel: a degree of latitude at 1.29 deg is
    # M pi / 180 = 110,575 m (WGS84 meridian radius M = 6,335,471 m there), so 0.00045218 deg
    lats = [p.lat for p in v.outline_polygon.vertices]
    assert min(lats) == pytest.approx(1.29 - 50 / 110575.0, abs=2e-7)  # 2e-7 deg: 2 cm
    assert max(lats) == pytest.approx(1.29 + 50 / 110575.0, abs=2e-7)
    assert abs(v.altitude_lower.value - 70.01) < 0.01 and abs(v.altitude_upper.value - 169.99) < 0.01
    # rounding to the microsecond: start down, end up
    start = ctx.start_ns
    assert rfc3339(0.0000015, start) == "2025-01-06T00:00:00.000001Z"
    assert rfc3339(0.0000015, start, up=True) == "2025-01-06T00:00:00.000002Z"
    # airborne: Activated; contingency: Contingent, no volumes, the plan off-nominal; Ended: None
    assert operational_intent(f, 35.0, ctx).reference.state == "Activated"
    assert len(operational_intent(f, 35.0, ctx).details.volumes) == 2  # every piece: details stay
    c = operational_intent(flight([30.0, 40.0], [[0, 0, 120], [100, 0, 120]], contingent=True), 35.0, ctx)
    assert c.reference.state == "Contingent" and c.details.volumes == [] \
        and len(c.details.off_nominal_volumes) == 2
    assert operational_intent(f, 41.0, ctx) is None
    with pytest.raises(F3548Error, match="state: 'Flying' is not an F3548"):
        operational_intent(f, 0.0, ctx, state="Flying")
    with pytest.raises(F3548Error, match="scenario_start_utc: 'sim'"):
        IntentContext(ORIGIN, ctx.spec, scenario_start_utc="sim")
    with pytest.raises(F3548Error, match="uss_base_url: 'http://x/' must be a URL without"):
        IntentContext(ORIGIN, ctx.spec, uss_base_url="http://x/")
    with pytest.raises(F3548Error, match="VolumeSpec.max_piece_s: 0 is not a positive"):
        VolumeSpec(50.0, 50.0, 0)


def test_a_long_plan_is_cut_into_at_most_oi_max_vertices():
    f = flight([0.0, 30000.0], [[0, 0, 100], [300000, 0, 100]])  # 6,000 pieces of 5 s
    vols, spec = volumes_for_limit(f.trajectory, VolumeSpec.for_separation(100.0))
    assert 4 * len(vols) <= 10000 and spec.max_piece_s > 5.0
    assert len(vols) == math.ceil(30000.0 / spec.max_piece_s - 1e-9)


def test_a_loss_of_separation_always_intersects_and_separation_may_not_be_disjoint():
    spec = VolumeSpec.for_separation(100.0)  # r = 50 m, 5 s pieces
    a = flight([0.0, 100.0], [[0, 0, 100], [1000, 0, 100]], "a")
    # b crosses a's path 60 m from it at t = 50 (a loss: 60 < 100)
    b = flight([0.0, 100.0], [[500, -500, 160], [500, 500, 160]], "b")
    va, vb = trajectory_volumes(a.trajectory, spec), trajectory_volumes(b.trajectory, spec)
    assert first_intersection(va, vb) is not None
    # in trail 150 m behind (15 s later, same path): separated, but the volumes intersect; the
    # piece of b at [15, 20] s spans x in [-50, 100] and a's [10, 15] s piece x in [50, 200]
    trail = flight([15.0, 115.0], [[0, 0, 100], [1000, 0, 100]], "t")
    assert first_intersection(va, trajectory_volumes(trail.trajectory, spec)) is not None
    # 230 m behind (23 s) is beyond D_h = 2 hypot(10 * 5 + 49.99, 49.99) = 223.58 m: disjoint
    d_h, d_v = spec.bounds_m(10.0, 0.0)
    assert d_h == pytest.approx(2 * math.hypot(99.99, 49.99)) and d_v == pytest.approx(99.98)
    far = flight([23.0, 123.0], [[0, 0, 100], [1000, 0, 100]], "f")
    assert first_intersection(va, trajectory_volumes(far.trajectory, spec)) is None
    # 1 cm precision: side by side 99.985 m apart (a loss of 1.5 cm) the boxes are 0.5 cm apart
    # and intersect; exactly at the separation, 100 m, they are 2 cm apart and do not
    side = lambda dy: flight([0.0, 100.0], [[0, dy, 100], [1000, dy, 100]], "s")  # noqa: E731
    assert first_intersection(va, trajectory_volumes(side(99.985).trajectory, spec)) is not None
    assert first_intersection(va, trajectory_volumes(side(100.0).trajectory, spec)) is None


def _holds_the_half_separation_box(f, vols, spec, times):
    for t in times:
        p = f.trajectory.position_at(t)
        inside = [v for v in vols if v.t0_s <= t <= v.t1_s and v.lower_m <= p[2] - spec.vertical_buffer_m + 1e-9
                  and p[2] + spec.vertical_buffer_m <= v.upper_m + 1e-9
                  and v.polygon().contains(Point(p[:2]))
                  and v.polygon().exterior.distance(Point(p[:2])) >= spec.horizontal_buffer_m - 1e-6]
        assert inside, (f.request_id, t)


def _run(tmp_path, separation_m, storm=True):
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.network_spec import load_network_spec
    from uam_sim.runner.scenario import run_scenario
    net = load_network_spec("config/networks/tiny.yaml")
    cfg = make_config({"network": "config/networks/tiny.yaml", "audit": False,
                       "separation_m": separation_m})
    decided = []  # (flight, decision time)

    def before(planner, t, k):
        if storm and k == 6:  # a storm over W7 from 240 s: re-plans (new versions) for what it affects
            planner.update_constraint("add", Constraint("storm", 1, "storm", 240.0, 900.0,
                                                        center_m=(0.0, 0.0), radius_m=150.0,
                                                        lower_m=0.0, upper_m=500.0), t)

    def keep(t, k, submitted, rejected, result):
        decided.extend((f, t) for f in result.approved)
        decided.extend((u.flight, t) for u in result.plan_updates if u.flight is not None)

    run_scenario(net, "greedy", 4.0, 3, 420.0, cfg, observer=keep, before_epoch=before)
    return net, decided


@pytest.mark.slow  # not in `make test-fast`: a short run in process, ~8 s
@pytest.mark.parametrize("separation_m", [100.0])
def test_every_intent_of_a_short_run_is_valid_and_holds_its_flight(tmp_path, separation_m):
    net, decided = _run(tmp_path, separation_m)
    spec = VolumeSpec.for_separation(100.0)
    ctx = IntentContext(net.origin_lat_lon_alt, spec)
    versions = [f.version for f, _ in decided]
    assert len(decided) >= 10 and max(versions) >= 2, versions  # approvals and re-plans
    for f, t in decided:
        oi = operational_intent(f, t, ctx)
        doc = {"operational_intent": as_json(oi)}
        assert errors(doc, "GetOperationalIntentDetailsResponse") == [], f.request_id
        validate_implicit(doc, "GetOperationalIntentDetailsResponse")
        assert oi.reference.version == intent_version(f.version, oi.reference.state)
        vols = trajectory_volumes(f.trajectory, spec, t)
        _holds_the_half_separation_box(f, vols, spec, np.linspace(max(t, f.departure_s), f.arrival_s, 23))
    c = f3548_constraint(Constraint("storm", 1, "storm", 240.0, 900.0, center_m=(0.0, 0.0),
                                    radius_m=150.0, lower_m=0.0, upper_m=500.0), ctx)
    validate({"constraint": as_json(c)}, "GetConstraintDetailsResponse")
    poly = f3548_constraint(Constraint("p", 0, "", 0.0, math.inf, rings_m=(np.array([[0, 0], [10, 0], [0, 10]]),)), ctx)
    doc = as_json(poly)
    assert "time_end" not in doc["details"]["volumes"][0] and "altitude_lower" not in doc["details"]["volumes"][0]["volume"]
    validate({"constraint": doc}, "GetConstraintDetailsResponse")
    assert f3548_constraint(Constraint("x", 0, "", 0.0, 10.0, vertiport_id="A"), ctx) is None
    # the validator sees a broken document
    bad = {"operational_intent": as_json(operational_intent(*decided[0], ctx))}
    bad["operational_intent"]["reference"]["ovn"] = "short"
    bad["operational_intent"]["details"]["volumes"][0]["volume"]["altitude_lower"]["reference"] = "SFC"
    assert [e.split(":")[0] for e in errors(bad, "GetOperationalIntentDetailsResponse")] == [
        "operational_intent/details/volumes/0/volume/altitude_lower",  # under anyOf
        "operational_intent/reference/ovn"]


def _speeds(flights):
    vh = vz = 0.0
    for f in flights:
        d = np.diff(f.trajectory.points_m, axis=0) / np.diff(f.trajectory.times_s)[:, None]
        vh = max(vh, float(np.hypot(d[:, 0], d[:, 1]).max()))
        vz = max(vz, float(np.abs(d[:, 2]).max()))
    return vh, vz


@pytest.mark.slow  # not in `make test-fast`: two short runs in process, ~15 s
def test_volumes_of_approved_plans_meet_only_within_the_bound_and_never_beyond_it(tmp_path):
    """At the paper's 100 m, approved (separated) flights may have intersecting volumes; every
    intersection lies within the bound (D_h, D_v) at its instant. Planned with a separation
    above sqrt(D_h^2 + D_v^2) + 1 cm, no two approved plans' volume sets intersect."""
    spec = VolumeSpec.for_separation(100.0)
    for separation_m, expect_disjoint in ((100.0, False), (None, True)):
        if separation_m is None:
            d_h, d_v = spec.bounds_m(10.0, 10.0)
            separation_m = math.hypot(d_h, d_v) + PRECISION_M + 1.0
        net, decided = _run(tmp_path, separation_m, storm=False)
        flights = [f for f, _ in decided]
        assert all(f.version == 1 for f in flights) and len(flights) >= 5
        vh, vz = _speeds(flights)
        assert vh <= 10.0 + 1e-9 and vz <= 10.0 + 1e-9
        d_h, d_v = spec.bounds_m(vh, vz)
        vols = {f.request_id: trajectory_volumes(f.trajectory, spec) for f in flights}
        met = 0
        for i, a in enumerate(flights):
            for b in flights[i + 1:]:
                if a.arrival_s < b.departure_s or b.arrival_s < a.departure_s:
                    continue
                hit = first_intersection(vols[a.request_id], vols[b.request_id])
                if hit is None:
                    continue
                met += 1
                va, vb = vols[a.request_id][hit[0]], vols[b.request_id][hit[1]]
                t = (max(va.t0_s, vb.t0_s) + min(va.t1_s, vb.t1_s)) / 2
                pa, pb = a.trajectory.position_at(t, clamp=True), b.trajectory.position_at(t, clamp=True)
                assert math.hypot(*(pa - pb)[:2]) <= d_h + 1e-6 and abs(pa[2] - pb[2]) <= d_v + 1e-6
        if expect_disjoint:
            assert met == 0
        else:
            assert met > 0  # the paper's separation alone does not give disjoint volume sets


def test_another_usss_intents_and_constraints_come_in_as_constraints(tmp_path):
    """Intents in (item 4): a foreign intent's volume becomes a prism widened by half our
    separation; an F3548 constraint a prism as it is; the planner then keeps out of both."""
    import json

    from uam_planner.airspace_files import load_airspace as load_constraints
    from uam_planner.f3548 import constraints_from_f3548
    from uam_planner.network import load_network

    net = load_network("config/networks/tiny.yaml")
    ctx = IntentContext(net.origin_lat_lon_alt, VolumeSpec(10.0, 5.0, 60.0), manager="uss2")
    other = flight([100.0, 160.0], [[-300, 0, 120], [300, 0, 120]], "theirs", "uss2-op", priority=5)
    doc = {"operational_intent": as_json(operational_intent(other, 0.0, ctx))}
    cons = constraints_from_f3548(doc, net, spec=VolumeSpec.for_separation(100.0))
    assert len(cons) == 1 and cons[0].constraint_id.startswith("oi:")
    assert "priority 5" in cons[0].reason and "uss2" in cons[0].reason
    # their rectangle [-310, 310] x [-10, 10], widened by 49.99 m (mitre: still a rectangle)
    xy = cons[0].rings_m[0]
    assert np.allclose(sorted({round(v, 2) for v in xy[:, 0]}), [-359.99, 359.99], atol=0.01)
    assert np.allclose(sorted({round(v, 2) for v in xy[:, 1]}), [-59.99, 59.99], atol=0.01)
    assert cons[0].lower_m == pytest.approx(120 - 5 - 49.99, abs=0.01)
    assert cons[0].upper_m == pytest.approx(120 + 5 + 49.99, abs=0.01)
    assert (cons[0].start_s, cons[0].end_s) == (100.0, 160.0)
    storm = f3548_constraint(Constraint("s", 3, "", 0.0, 500.0, center_m=(800.0, 0.0), radius_m=100.0,
                                        lower_m=0.0, upper_m=300.0), ctx)
    both = {"operational_intents": [doc["operational_intent"]], "constraints": [as_json(storm)]}
    path = tmp_path / "f3548.json"
    path.write_text(json.dumps(both))
    cset = load_constraints(path, net)  # --constraints FILE takes F3548 documents too
    ids = sorted(c.constraint_id for c in cset)
    assert ids[0].startswith("cst:") and ids[1].startswith("oi:")
    circle = next(c for c in cset if c.constraint_id.startswith("cst:"))
    assert circle.center_m == pytest.approx((800.0, 0.0), abs=0.01) and circle.radius_m == 100.0
    # a flight through their volume while it holds is refused; after its window it is allowed
    through = Trajectory(np.array([120.0, 150.0]), np.array([[0.0, -200, 120], [0.0, 200, 120]]))
    later = through.shifted(100.0)
    which, _ = cset.violations([through, later], [0, 0], [1, 1])
    assert which[0] >= 0 and which[1] < 0
    bad = dict(doc)
    bad["operational_intent"] = {"reference": {"id": "x"}}
    path.write_text(json.dumps(bad))
    from uam_planner.constraints import ConstraintError
    with pytest.raises(ConstraintError, match="not an F3548 OperationalIntent"):
        load_constraints(path, net)


LAYERED = "config/networks/singapore-layered.yaml"


def test_adjacent_flight_levels_publish_bands_2_cm_apart_everywhere():
    """On a layered network z is the height above the ellipsoid: a level's band is exactly the
    level -/+ (V / 2 - 1 cm), so two flights on adjacent levels crossing 8 km from the origin
    publish volumes 2 cm apart (reading z as ENU up made bands 30.1 m wide there, overlapping)."""
    from uam_planner.f3548 import first_published_intersection, volume4d
    from uam_planner.network import load_network
    from uam_planner.separation import SeparationModel

    net = load_network(LAYERED)
    spec = VolumeSpec.for_separation(SeparationModel("cylinder", 100.0, 30.0))
    ctx = IntentContext.for_network(net, spec)
    assert ctx.altitude_is_height and not IntentContext.for_network(load_network("config/networks/tiny.yaml"),
                                                                    spec).altitude_is_height
    east = flight([0.0, 100.0], [[7500, 6000, 60.0], [8500, 6000, 60.0]], "east")
    north = flight([0.0, 100.0], [[8000, 5500, 90.0], [8000, 6500, 90.0]], "north")
    docs = {f.request_id: [as_json(volume4d(v, ctx)) for v in trajectory_volumes(f.trajectory, spec)]
            for f in (east, north)}
    for rid, level in (("east", 60.0), ("north", 90.0)):
        bands = {(v["volume"]["altitude_lower"]["value"], v["volume"]["altitude_upper"]["value"])
                 for v in docs[rid]}
        assert bands == {(level - 14.99, level + 14.99)}
    assert first_published_intersection(docs["east"], docs["north"], net.origin_lat_lon_alt) is None
    # the same flights 1.5 cm closer than the levels (a loss of separation) do intersect
    low = flight([0.0, 100.0], [[8000, 5500, 89.985], [8000, 6500, 89.985]], "low")
    low_docs = [as_json(volume4d(v, ctx)) for v in trajectory_volumes(low.trajectory, spec)]
    assert first_published_intersection(docs["east"], low_docs, net.origin_lat_lon_alt) is not None
    # the horizontal map is one for every height: a point keeps its latitude and longitude
    hi = volume4d(trajectory_volumes(flight([0.0, 5.0], [[8000, 6000, 150.0], [8000, 6000, 150.0]]).trajectory,
                                     spec)[0], ctx)
    lo = volume4d(trajectory_volumes(flight([0.0, 5.0], [[8000, 6000, 60.0], [8000, 6000, 60.0]]).trajectory,
                                     spec)[0], ctx)
    assert as_json(hi.volume.outline_polygon) == as_json(lo.volume.outline_polygon)


def _layered_run(separation_m, intent_volume_piece_s=0.0):
    """A layered run (cylinder H = separation_m, V = 30 m, 5 s slots) with storms announced where
    flights are going (re-plans): every (flight, plan version, decision time)."""
    from uam_planner.network import load_network
    from uam_sim.runner.experiment_config import make_config
    from uam_sim.runner.scenario import run_scenario

    net = load_network(LAYERED)
    cfg = make_config(network=LAYERED, separation_model="cylinder", separation_m=separation_m,
                      vertical_separation_m=30.0, departure_slot_s=5.0, audit=False, time_limit_s=5.0,
                      intent_volume_piece_s=intent_volume_piece_s)
    decided = []

    def before(planner, t, k):
        if 3 <= k <= 7:  # a storm 60 s ahead of a flight still in the air in 2 min
            f = sorted((fl for fl, _ in decided if fl.arrival_s > t + 120.0), key=lambda fl: fl.request_id)[0]
            p = f.trajectory.position_at(t + 60.0, clamp=True)
            planner.update_constraint("add", Constraint(f"storm{k}", 1, "storm", t + 30.0, 900.0,
                                                        center_m=(float(p[0]), float(p[1])), radius_m=700.0,
                                                        lower_m=0.0, upper_m=500.0), t)

    def keep(t, k, submitted, rejected, result):
        decided.extend((f, t) for f in result.approved)
        decided.extend((u.flight, t) for u in result.plan_updates if u.flight is not None)

    run_scenario(net, "greedy", 6.0, 4, 240.0, cfg, observer=keep, before_epoch=before)
    return net, decided


@pytest.mark.slow  # not in `make test-fast`: two layered runs in process, ~30 s
def test_no_two_published_intents_of_a_layered_run_with_replans_intersect():
    """The published documents of a layered run with re-plans, as a peer checks them (1 cm):
    at the plain 100 m separation only same-level pairs meet (in trail or crossing within the
    bound D_h); none of adjacent levels. In F3548 mode (the planner checks the published
    volumes too, ``intent_volume_piece_s``) at the same 100 m, no two intents intersect."""
    from uam_planner.separation import SeparationModel

    spec = VolumeSpec.for_separation(SeparationModel("cylinder", 100.0, 30.0))
    for piece_s in (0.0, spec.max_piece_s):
        net, decided = _layered_run(100.0, piece_s)
        assert max(f.version for f, _ in decided) >= 2 and len(decided) >= 30  # re-plans
        ctx = IntentContext.for_network(net, spec)
        pairs, hits = published_intersections(decided, ctx, net.origin_lat_lon_alt)
        assert pairs > 500
        if not piece_s:
            assert hits and all(overlap > 1.0 for _, _, overlap in hits), hits  # the same band only
            assert all(a.trajectory.points_m[1, 2] == b.trajectory.points_m[1, 2] for a, b, _ in hits)
        else:
            assert hits == [], [(a.request_id, b.request_id, o) for a, b, o in hits]


def test_published_times_read_by_the_fast_parser_equal_implicitdicts():
    """published_prisms reads the form rfc3339 writes with the standard library's parser and
    every other form with implicitdict's: the same instants to the last bit."""
    import random

    from implicitdict import StringBasedDateTime

    from uam_planner.f3548 import _timestamp, rfc3339

    rng = random.Random(7)
    start = 1_790_000_000_123_456_789
    for _ in range(2000):
        t = rng.uniform(-1e5, 1e6)
        for up in (False, True):
            s = rfc3339(t, start, up)
            assert _timestamp(s) == StringBasedDateTime(s).datetime.timestamp(), s
    # peers' forms: no fraction, nanoseconds, an offset, one digit
    for s in ("2026-12-07T20:10:08Z", "2026-12-07T20:10:08.123456789Z",
              "2026-12-07T21:10:08.5+01:00", "2026-12-07T20:10:08.1Z"):
        assert _timestamp(s) == StringBasedDateTime(s).datetime.timestamp(), s
