"""The audit of what flew when plans change (issue 22 item 5), on hand-built plan versions:
chaining, the flown trajectory, and incursions into constraints in force, hand-computed."""

from __future__ import annotations

import math
from types import SimpleNamespace as NS

import numpy as np
import pytest

from uam_planner.constraints import Constraint
from uam_sim.audit.flown_audit import chain_problems, constraint_intervals, flown_trajectory, incursions
from uam_sim.audit.record import RunRecord


def t(sec: float) -> NS:
    return NS(sec=int(math.floor(sec)), nanosec=int(round((sec - math.floor(sec)) * 1e9)))


def plan(wps, version=1, effective=0.0, ids=(), kind="", origin="A", destination="B"):
    """A FlightPlan-like object; ``wps``: (t, x, y, z)."""
    return NS(request_id="r1", operator_id="op", version=version, effective_time=t(effective),
              constraint_ids=list(ids), update_kind=kind, origin_id=origin, destination_id=destination,
              waypoints=[NS(time=t(ts), position=NS(x=float(x), y=float(y), z=float(z))) for ts, x, y, z in wps])


def square(cid="sq", version=1, lo=(-100.0, -100.0), hi=(100.0, 100.0), band=(0.0, 300.0), window=(0.0, 1000.0)):
    ring = np.array([[lo[0], lo[1]], [hi[0], lo[1]], [hi[0], hi[1]], [lo[0], hi[1]]])
    return Constraint(cid, version, "test", window[0], window[1], rings_m=(ring,), lower_m=band[0], upper_m=band[1])


# r1 flies east at 10 m/s, z = 100: x = -500 + 10 t for t in [0, 100]
EAST = [(0, -500, 0, 100), (100, 500, 0, 100)]


def test_a_reroute_in_the_air_is_flown_from_its_effective_instant():
    # at t = 50 the flight is at x = 0; version 1 turns north from there: (0, 10 (t - 50), 100)
    v0 = plan(EAST)
    v1 = plan([(50, 0, 0, 100), (80, 0, 300, 100)], version=2, effective=50.0, ids=["sq"], kind="rerouted")
    f, problems = flown_trajectory("op/r1", [v0, v1])
    assert problems == []
    np.testing.assert_allclose(f.times_s, [0, 50, 80])
    np.testing.assert_allclose(f.points_m, [[-500, 0, 100], [0, 0, 100], [0, 300, 100]])
    assert f.pieces == [(1, 0.0, 50.0), (2, 50.0, 80.0)]
    # a takeover that does not start where the flight was: 3 m off at t = 50
    jump = plan([(50, 0, 3, 100), (80, 0, 300, 100)], version=2, effective=50.0, ids=["sq"])
    _, problems = flown_trajectory("op/r1", [v0, jump])
    assert problems == ["op/r1: version 2 starts 3.000 m from where version 1 had the flight at 50 s"]
    # a cancellation before departure: nothing flown; a retime: only the new version
    cancel = plan([], version=2, effective=-10.0, ids=["sq"], kind="cancelled")
    f, _ = flown_trajectory("op/r1", [plan([(10, -500, 0, 100), (110, 500, 0, 100)]), cancel])
    assert len(f.times_s) == 0
    retimed = plan([(40, -500, 0, 100), (140, 500, 0, 100)], version=2, effective=5.0, ids=["sq"], kind="retimed")
    f, problems = flown_trajectory("op/r1", [plan([(10, -500, 0, 100), (110, 500, 0, 100)]), retimed])
    assert problems == [] and f.times_s.tolist() == [40.0, 140.0]


def test_versions_that_do_not_chain_are_named():
    announced = {"sq": 30.0}
    v0 = plan(EAST)
    v1 = plan(EAST, version=2, effective=50.0, ids=["sq"])
    v2 = plan(EAST, version=3, effective=40.0, ids=["sq"])
    v3 = plan(EAST, version=4, effective=60.0, ids=["other"])
    assert chain_problems("k", [v0, v1], announced) == []
    assert chain_problems("k", [v0, v2], announced) == ["k: version 3 follows version 1 (version 2 missing)"]
    assert chain_problems("k", [v1], announced) == ["k: version 2 without version 1 (the approval)"]
    assert chain_problems("k", [v0, v1, v2], announced) == [
        "k: version 3 takes effect at 40 s, before version 2 (at 50 s)"]
    assert chain_problems("k", [v0, v1, v2.__class__(**{**v2.__dict__, "version": 3, "effective_time": t(55)}), v3],
                          announced) == ["k: version 4 names constraint 'other', never announced on the constraint topic"]
    early = plan(EAST, version=2, effective=20.0, ids=["sq"])
    assert chain_problems("k", [v0, early], announced) == [
        "k: version 2 takes effect at 20 s, before constraint 'sq' was announced (30 s)"]
    nameless = plan(EAST, version=2, effective=50.0, kind="retimed")
    assert chain_problems("k", [v0, nameless], announced) == ["k: version 2 (retimed) names no constraint"]
    # issue 23: the reaction to nonconformance updates a flight for what it flew, not for a
    # constraint: it names none, and that is no problem (a constraint it does name is checked)
    reacted = plan(EAST, version=2, effective=50.0, kind="nonconforming")
    assert chain_problems("k", [v0, reacted], announced) == []
    contingent = plan(EAST, version=2, effective=50.0, kind="contingency")
    assert chain_problems("k", [v0, contingent], announced) == ["k: version 2 (contingency) names no constraint"]
    contingent.reason = "re-timed from the observed progress rate 0.91; no conflict-free plan"
    assert chain_problems("k", [v0, contingent], announced) == []
    reacted_named = plan(EAST, version=2, effective=50.0, kind="nonconforming", ids=["other"])
    assert chain_problems("k", [v0, reacted_named], announced) == [
        "k: version 2 names constraint 'other', never announced on the constraint topic"]


def test_the_record_flags_updates_without_an_approval():
    sets = [(30.0, [(square(), 30.0)])]
    record = RunRecord.from_plans([], {"op/r1": {2: plan(EAST, version=2, effective=50.0, ids=["sq"])}}, sets)
    assert record.flights == [] and record.problems == [
        "op/r1: 1 plan update(s) for a request with no approval in the recording"]


def test_incursions_hand_computed():
    flight = flown_trajectory("op/r1", [plan(EAST)])[0]
    # in force from 0, window [0, 1000): entered at x = -100, t = 40
    (hit,) = incursions([flight], [(square(), 0.0, math.inf)])
    assert (hit.constraint_id, hit.t_s, hit.what) == ("sq", pytest.approx(40.0), "volume")
    # the window closes at 40: entering exactly then is allowed (half-open); at 40.5 it is not
    assert incursions([flight], [(square(window=(0.0, 40.0)), 0.0, math.inf)]) == []
    assert len(incursions([flight], [(square(window=(0.0, 40.5)), 0.0, math.inf)])) == 1
    # the band: level at 100 m under a band from 120 m: nothing
    assert incursions([flight], [(square(band=(120.0, 300.0)), 0.0, math.inf)]) == []
    # in force only from t = 60 (the flight is then at x = 100, on the closed boundary): t = 60
    (late,) = incursions([flight], [(square(), 60.0, math.inf)])
    assert late.t_s == pytest.approx(60.0)
    # ... so it was inside when the version came into force (airborne since 0): no plan could
    # have avoided it, said so and reported all the same; the entry at 40 above could have been
    assert late.inside_at_start and "already inside when it came into force: unavoidable" in late.describe()
    assert not hit.inside_at_start
    # withdrawn at t = 30, before the flight reaches it: nothing
    assert incursions([flight], [(square(), 0.0, 30.0)]) == []
    # climbing: z = 2 t, x = -500 + 10 t; band from 150 m is reached at t = 75 (x = 250), inside
    # a square over x in [0, 400]: entry at t = 75
    climb = flown_trajectory("op/r1", [plan([(0, -500, 0, 0), (100, 500, 0, 200)])])[0]
    (up,) = incursions([climb], [(square(lo=(0.0, -100.0), hi=(400.0, 100.0), band=(150.0, 300.0)), 0.0, math.inf)])
    assert up.t_s == pytest.approx(75.0)
    # a circle of 100 m around (200, 0): the level flight enters at x = 100, t = 60
    circle = Constraint("c", 1, "", 0.0, 1000.0, center_m=(200.0, 0.0), radius_m=100.0, lower_m=0.0, upper_m=300.0)
    (round_,) = incursions([flight], [(circle, 0.0, math.inf)])
    assert round_.t_s == pytest.approx(60.0)
    # a closure of the origin A over [0, 100): the departure at t = 0 enters it
    closed = Constraint("A-closed", 1, "", 0.0, 100.0, vertiport_id="A")
    (dep,) = incursions([flight], [(closed, 0.0, math.inf)])
    assert (dep.what, dep.t_s) == ("departure", 0.0)
    assert incursions([flight], [(Constraint("B-closed", 1, "", 0.0, 100.0, vertiport_id="B"), 0.0, math.inf)]) == []


def test_a_reroute_that_leaves_the_constraint_in_time_has_no_incursion():
    """Version 1 would enter the square at t = 40; version 2, effective at 30 (x = -200), turns
    north before it: the flown trajectory never enters. Audited on version 1 alone it would."""
    v0 = plan(EAST)
    v1 = plan([(30, -200, 0, 100), (60, -200, 300, 100)], version=2, effective=30.0, ids=["sq"], kind="rerouted")
    sets = [(30.0, [(square(), 30.0)])]
    record = RunRecord.from_plans([("op/r1", v0)], {"op/r1": {1: v1}}, sets)
    assert record.problems == [] and len(record.applied) == 1
    assert record.incursions() == ([], [])
    found, _ = RunRecord.from_plans([("op/r1", v0)], {}, sets).incursions()
    assert [i.t_s for i in found] == [pytest.approx(40.0)]


def test_constraint_intervals_follow_the_recorded_sets():
    v1, v2 = square(version=1), square(version=2)
    sets = [(0.0, [(v1, 0.0)]), (60.0, [(v2, 60.0)]), (120.0, [])]
    got = [(c.version, a, b) for c, a, b in constraint_intervals(sets)]
    assert got == [(1, 0.0, 60.0), (2, 60.0, 120.0)]


# A reaction update (kind nonconforming) takes over at 50 s from where the aircraft was, 60 m
# north of where version 1 had it: (0, 60) at 50 s, east to (100, 60) at 60 s, then north.
# Joining the versions into one path (dropping that first waypoint) drew (0, 0) at 50 s ->
# (100, 60) at 60 s, a path in no plan.
def _reacted():
    v1 = plan(EAST)
    v2 = plan([(45, -50, 60, 100), (60, 100, 60, 100), (100, 100, 460, 100)], version=2, effective=50.0,
              kind="nonconforming")
    return v1, v2


def _in_force_audit(other):
    v1, v2 = _reacted()
    record = RunRecord.from_plans([("op/r1", v1), ("op/r2", other)], {"op/r1": {2: v2}})
    assert record.problems == []
    got = record.in_force()
    audit, conflicts = record.audit_plans(100.0)
    assert conflicts == []
    return audit, got.parts, got.labels


def test_a_reaction_update_is_in_force_from_its_first_waypoint_and_no_phantom_path_is_audited():
    v1, v2 = _reacted()
    f, problems = flown_trajectory("op/r1", [v1, v2])
    assert problems == []
    # two parts: version 1 to 50 s; version 2 from where the aircraft was at 50 s
    (t1, x1), (t2, x2) = f.trajectories()
    assert t1.tolist() == [0.0, 50.0] and x1[-1].tolist() == [0.0, 0.0, 100.0]
    assert t2.tolist() == [50.0, 60.0, 100.0] and x2[0].tolist() == [0.0, 60.0, 100.0]
    # r2 from (50, -60) at 51 s, south: 77 m from the joined path at 51 s, 126 m from version 2
    # (version 1 is no longer in force): no loss between the plans in force
    r2 = plan([(51, 50, -60, 100), (100, 50, -550, 100)])
    audit, parts, labels = _in_force_audit(r2)
    assert labels == ["op/r1", "op/r1", "op/r2"]
    assert audit.ok and audit.min_separation_m == pytest.approx(math.hypot(40.0, 120.0))


def test_a_loss_on_a_reaction_updates_first_leg_is_found():
    # r2 from (10, 140) at 51 s, north at 10 m/s: version 2's first leg passes 80 m from it at 51 s
    # (the joined path was 134 m away and saw nothing)
    r2 = plan([(51, 10, 140, 100), (100, 10, 630, 100)])
    audit, _parts, _labels = _in_force_audit(r2)
    assert not audit.ok
    a, b, d, when = audit.losses[0]
    assert (a, b) == ("op/r1", "op/r2") and d == pytest.approx(80.0) and when == pytest.approx(51.0)


def test_a_cancellation_effective_at_the_departure_flew_nothing():
    from uam_sim.audit.analysis import _departure_flown

    v1 = plan([(10, -500, 0, 100), (110, 500, 0, 100)])
    cancel = plan([], version=2, effective=10.0, ids=["sq"], kind="cancelled")
    f, problems = flown_trajectory("op/r1", [v1, cancel])
    assert problems == [] and len(f.times_s) == 0 and f.trajectories() == []
    # so the analysis never expects it in the fleet states ("never flew" made the run NOT VERIFIED)
    record = RunRecord.from_plans([("op/r1", v1)], {"op/r1": {2: cancel}}, [(10.0, [(square(), 10.0)])])
    assert record.problems == [] and record.flights[0].flown.trajectories() == []
    assert _departure_flown("op/r1", v1, record.by_key()) == math.inf
    # a cancellation one second later: it flew that second
    f, _ = flown_trajectory("op/r1", [v1, plan([], version=2, effective=11.0, ids=["sq"], kind="cancelled")])
    assert f.times_s.tolist() == [10.0, 11.0]


def test_a_contingency_versions_conflicts_are_a_class_of_their_own():
    from uam_sim.audit.separation import audit_trajectories

    # r1's version 2, a contingency from 50 s, turns north through r2's path; r2 flies east 300 m
    # north of r1, so only the contingency comes within the minimum (at (0, 300) at 80 s)
    v1 = plan(EAST)
    v2 = plan([(50, 0, 0, 100), (80, 0, 300, 100), (110, 0, 600, 100)], version=2, effective=50.0, kind="contingency")
    r2 = plan([(0, -800, 300, 100), (100, 200, 300, 100)])
    record = RunRecord.from_plans([("op/r1", v1), ("op/r2", r2)], {"op/r1": {2: v2}})
    got = record.in_force()
    assert got.labels == ["op/r1", "op/r1 v2 (contingency)", "op/r2"] and got.groups == ["op/r1", "op/r1", "op/r2"]
    assert got.contingent == [False, True, False]
    deconflicted = got.select([not c for c in got.contingent])
    assert audit_trajectories(deconflicted.parts, deconflicted.labels, 100.0, groups=deconflicted.groups).ok
    conflicts = audit_trajectories(got.parts, got.labels, 100.0, groups=got.groups,
                                   only_pairs_with=got.contingent).losses
    assert [c[:2] for c in conflicts] == [["op/r1 v2 (contingency)", "op/r2"]]
    assert conflicts[0][2] == pytest.approx(0.0) and conflicts[0][3] == pytest.approx(80.0)
    audit, found = record.audit_plans(100.0)
    assert audit.ok and found == conflicts


def test_entries_between_the_announcement_and_the_planners_epoch_are_reported_apart():
    from uam_planner.live_constraints import constraints_from_text, set_geojson

    # the authority announces the square at 30 s; the planner applies it at its next epoch, 70 s.
    # r1 flies east through it from x = -100 at 40 s: inside the authority's constraint before
    # the planner's (it has left by 70 s, x = 200: no incursion as applied)
    text = set_geojson([square()], 70.0, {"sq": 70.0}, {"sq": 30.0})
    sets = [constraints_from_text(text)]
    assert sets[0][1][0][0].announce_s == 30.0 and sets[0][1][0][1] == 70.0
    v0 = plan(EAST)
    record = RunRecord.from_plans([("op/r1", v0)], {}, sets)
    found, gap = record.incursions()
    assert (found, len(record.applied)) == ([], 1)
    assert [(i.key, i.constraint_id, i.t_s) for i in gap] == [("op/r1", "sq", pytest.approx(40.0))]
    # without the announcement recorded (or announced at the epoch itself) there is no gap
    unannounced = [constraints_from_text(set_geojson([square()], 70.0, {"sq": 70.0}))]
    assert RunRecord.from_plans([("op/r1", v0)], {}, unannounced).incursions()[1] == []


def test_a_pad_closure_is_entered_only_from_that_pad():
    from uam_planner.synthetic import generate_network

    net = generate_network(60, 6, seed=1, levels_m=(60.0, 90.0), pads_per_vertiport=2)
    a = net.enu_m[net.node_index("A000")]
    pads = a[:2] + net.pads_of(net.node_index("A000"))
    # r1 departs from A000's pad 1 at t = 0 and climbs away; pad 0 is closed, then pad 1
    v0 = plan([(0, pads[1][0], pads[1][1], 0), (20, pads[1][0], pads[1][1], 60), (100, 0, 0, 60)],
              origin="A000", destination="A001")
    flight = flown_trajectory("op/r1", [v0])[0]
    closed = [(Constraint("pad0", 1, "", 0.0, 100.0, vertiport_id="A000", pad_index=0), 0.0, math.inf)]
    assert incursions([flight], closed, net) == []
    (unknown,) = incursions([flight], closed)       # no network: the pad cannot be told
    assert unknown.what == "departure (pad not known)"
    closed1 = [(Constraint("pad1", 1, "", 0.0, 100.0, vertiport_id="A000", pad_index=1), 0.0, math.inf)]
    (dep,) = incursions([flight], closed1, net)
    assert (dep.what, dep.t_s) == ("departure", 0.0)
