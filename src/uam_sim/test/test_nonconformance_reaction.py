"""The reaction to a nonconforming flight (issue 23 item 3; uam_planner.nonconformance,
docs/disturbances.md). Every expected value is computed by hand in the comments: the paper's
sphere of 100 m, speed 10 m/s, epochs of 30 s, the conformance bounds 30 m, 15 m, 10 s."""

import functools
import math

import numpy as np
import pytest

from uam_planner.audit import audit_flights
from uam_planner.network import network_from_enu
from uam_planner.nonconformance import KIND, MAX_OVERRUN_SHARE, ConformanceBounds, rejoin_trajectory
from uam_planner.planning import Flight, FlightRequest, Planner, PlanningConfig
from uam_planner.trajectory import Trajectory
from uam_sim.world.conformance import track_conformance
from uam_sim.world.disturbance import DisturbanceConfig, FlightDraws, fly


def cross():
    """W (0, 0) - m (3000, 0) - E (6000, 0) and S (3000, -3000) - m - N (3000, 3000)."""
    ids = ["W", "m", "E", "S", "N"]
    enu = [(0, 0, 0), (3000, 0, 0), (6000, 0, 0), (3000, -3000, 0), (3000, 3000, 0)]
    return network_from_enu("cross", ids, enu, [True, False, True, True, True],
                            [("W", "m"), ("m", "E"), ("S", "m"), ("m", "N")])


def flight(rid, route, points, t0):
    pts = np.array(points, dtype=np.float64)
    legs = np.sqrt(np.square(np.diff(pts, axis=0)).sum(axis=1))
    times = t0 + np.concatenate(([0.0], np.cumsum(legs / 10.0)))
    tr = Trajectory(times, pts)
    return Flight(rid, route[0], route[-1], tuple(route), tr, float(times[0]), float(times[-1]),
                  float(legs.sum()), 1.0, 0, "greedy", "greedy", 0)


#: P: W at 0 s, m at 300 s, E at 600 s. Q: S at 33.33 s, m at 333.33 s, N at 633.33 s
P = flight("P", ["W", "m", "E"], [(0, 0, 0), (3000, 0, 0), (6000, 0, 0)], 0.0)
Q = flight("Q", ["S", "m", "N"], [(3000, -3000, 0), (3000, 0, 0), (3000, 3000, 0)], 100.0 / 3.0)
#: a head wind of 1 m/s (from the east): P holds its airspeed of 10 m/s, 9 m/s over the ground
HEAD_WIND = DisturbanceConfig(wind_speed_mps=1.0, wind_from_deg=90.0)


def planner(reaction=True):
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds() if reaction else None),
                "mwis", solve_mwis=None)
    p.restore([P, Q])
    return p


def test_a_flight_slowed_by_a_head_wind_is_flagged_at_the_right_step():
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    # at step n it has flown 9 n m, planned at 0.9 n s: late by 0.1 n s, over 10 s from n = 101
    assert flown.position_at(100.0)[0] == pytest.approx(900.0)
    tc = track_conformance("P", P.trajectory, flown, ConformanceBounds())
    assert tc.first_nonconforming_s == pytest.approx(101.0)
    assert tc.time_err_s[100] == pytest.approx(10.0) and tc.time_err_s[101] == pytest.approx(10.1)


def _observe(p, flown, times):
    for t in times:
        assert p.observe("P", t, flown.position_at(t)) is None


def test_its_updated_plan_keeps_separation_with_a_hand_placed_neighbour():
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    p = planner()
    _observe(p, flown, (100.0, 110.0, 120.0))
    assert p.report_nonconforming("P", 101.0, "monitor") is None
    res = p.plan(120.0, 4)
    # the progress rate: planned 90 -> 108 s in 100 -> 120 s = 0.9. From (1080, 0) at 120 s the
    # rejoin at 0.9 reaches m at 120 + 1920 / 9 = 333.33 s, with Q: a loss (both at m then).
    naive = rejoin_trajectory(P.trajectory, 120.0, (1080.0, 0.0, 0.0), 0.9)
    assert naive.position_at(1000.0 / 3.0) == pytest.approx([3000.0, 0.0, 0.0])
    assert len(audit_flights([naive, Q.trajectory], separation_m=100.0).losses) == 1
    # the alternatives keep 0.99 (10 % faster), 0.81, 0.72, 0.63 of the planned speed. Two paths
    # crossing at right angles at speeds vp, vq with a time gap dt at the crossing come closest at
    # dt vp vq / sqrt(vp^2 + vq^2): at 0.99 P reaches m at 120 + 1920 / 9.9 = 313.94 s, 19.39 s
    # before Q: 136.4 m; 0.81: 23.70 s after, 149.2 m. The faster one weighs as much as the
    # rejoin (no delay: weight 3), the slower ones less: the MWIS takes 0.99
    (u,) = res.plan_updates
    assert (u.request_id, u.kind, u.version, u.effective_s) == ("P", KIND, 2, 120.0)
    assert u.observed_rate == pytest.approx(0.9)   # what the simulator flies it on at (the wire field)
    assert u.flight.contingent is False and "time +12.0 s" in u.reason
    new = u.flight.trajectory
    assert new.departure_s == 120.0 and new.points_m[0] == pytest.approx([1080.0, 0.0, 0.0])
    assert new.position_at(120.0 + 1920.0 / 9.9) == pytest.approx([3000.0, 0.0, 0.0])
    assert new.arrival_s == pytest.approx(120.0 + 4920.0 / 9.9)
    gap = 1000.0 / 3.0 - (120.0 + 1920.0 / 9.9)
    a = audit_flights([new, Q.trajectory], separation_m=100.0)
    assert a.losses == [] and a.min_separation_m == pytest.approx(gap * 99.0 / math.hypot(9.9, 10.0), abs=0.01)
    # the planner's traffic picture: both flights, P's newest version
    assert sorted((f.request_id, f.version) for f in p.active) == [("P", 2), ("Q", 1)]
    assert res.report.nonconformance["kinds"] == {KIND: 1}


def test_without_a_neighbour_it_rejoins_at_its_observed_speed_and_conforms_again():
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds()), "mwis", solve_mwis=None)
    p.restore([P])
    _observe(p, flown, (100.0, 110.0, 120.0))
    assert p.report_nonconforming("P", 101.0) is None
    (u,) = p.plan(120.0, 4).plan_updates
    new = u.flight.trajectory
    assert new.arrival_s == pytest.approx(120.0 + 4920.0 / 9.0)   # the rejoin at 0.9
    # flown on from (1080, 0) at its airspeed (speed error (1 + 0) / 0.9 - 1 against the new
    # plan): 10 m/s air, 9 over the ground, the new plan's speed: conforming to the end
    cont = fly(new, FlightDraws((1.0 / 0.9) - 1.0), HEAD_WIND)
    tc = track_conformance("P", new, cont, ConformanceBounds())
    assert tc.first_nonconforming_s is None
    assert cont.arrival_s == pytest.approx(new.arrival_s, abs=1.0)


def test_a_report_the_planner_cannot_confirm_changes_nothing():
    p = planner()
    # P on its plan at 120 s (1200, 0): the planner's own view conforms
    assert p.observe("P", 120.0, (1200.0, 0.0, 0.0)) is None
    assert p.report_nonconforming("P", 119.0, "forged") is None
    res = p.plan(120.0, 4)
    assert res.plan_updates == []
    (rid, why), = res.report.nonconformance["refused"]
    assert rid == "P" and "conforms in the planner's own view" in why
    assert sorted((f.request_id, f.version) for f in p.active) == [("P", 1), ("Q", 1)]
    # no fleet state of Q seen: refused, Q kept
    assert p.report_nonconforming("Q", 140.0) is None
    res = p.plan(150.0, 5)
    assert res.plan_updates == [] and "no fleet state" in res.report.nonconformance["refused"][0][1]
    assert {f.request_id for f in p.active} == {"P", "Q"}
    # an unknown flight, a bad time, the reaction off: refused at once, naming the field
    assert p.report_nonconforming("Z", 150.0).startswith("request_id: 'Z'")
    assert p.report_nonconforming("P", math.nan).startswith("t_s: nan")
    assert planner(reaction=False).report_nonconforming("P", 150.0).startswith("conformance:")
    assert p.observe("P", 150.0, (math.inf, 0.0, 0.0)).startswith("position_m:")


def test_with_no_deconflicted_update_it_stays_in_the_picture_as_a_contingency():
    # Q' crosses P's position at the epoch itself: every update starts there, none keeps
    # separation (each with one flight), so P flies the one that lands soonest (0.99 of the plan's
    # speed), contingent, and stays active
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    q2 = flight("Q2", ["S", "m", "N"], [(1080, -3000, 0), (1080, 0, 0), (1080, 3000, 0)], -180.0)
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds()), "mwis", solve_mwis=None)
    p.restore([P, q2])
    _observe(p, flown, (100.0, 110.0, 120.0))
    assert p.report_nonconforming("P", 101.0) is None
    (u,) = p.plan(120.0, 4).plan_updates
    assert u.kind == "contingency" and u.flight.contingent
    assert u.flight.arrival_s == pytest.approx(120.0 + 4920.0 / 9.9)
    assert {f.request_id for f in p.active} == {"P", "Q2"}


#: the settings of the runner's disturbed runs on the tiny network below
TINY_RUN = dict(epoch_s=30.0, time_limit_s=5.0, corpus_max_vertices=0,
                disturbance={"speed_error": 0.3, "gust_std_mps": 0.5})


@functools.lru_cache(maxsize=None)
def tiny_run(**settings):
    """The in-process runner on the tiny network (greedy, rate 3, seed 4, 300 s) with TINY_RUN and
    ``settings``; each set of settings runs once per test process (the reaction at the epochs is
    in two tests), and the tests only read the result."""
    from uam_planner.network import load_network
    from uam_sim.runner.experiment_config import REPO_ROOT, make_config
    from uam_sim.runner.scenario import run_scenario
    net = load_network(REPO_ROOT / "config" / "networks" / "tiny.yaml")
    return run_scenario(net, "greedy", 3.0, 4, 300.0, make_config(dict(TINY_RUN, **settings)))


def test_the_runner_reacts_and_off_is_todays_run():
    """The in-process runner with --reaction: its monitor reports, the planner confirms and
    updates, the aircraft fly on; conformance improves and every update is recorded. Reaction
    off is the run without the option, field for field (timings aside)."""
    from uam_sim.runner.sweep import TIMING_FIELDS
    off = tiny_run()
    off2 = tiny_run(reaction=False)
    on = tiny_run(reaction=True)
    import json
    strip = lambda s: json.dumps({k: v for k, v in s.items() if k not in TIMING_FIELDS},  # noqa: E731
                                 sort_keys=True, default=str)
    assert strip(off.summary) == strip(off2.summary) and off.flights == off2.flights
    kinds = [r["kind"] for r in on.replans]
    # (a neighbour re-timed so that a nonconforming flight keeps separation: "yielded")
    assert kinds and set(kinds) <= {KIND, "contingency", "yielded"} and on.summary["nonconforming_updates"] > 0
    assert on.summary["conf_conformance_percent"] > off.summary["conf_conformance_percent"]
    assert on.summary["conf_longest_excursion_s"] < off.summary["conf_longest_excursion_s"]
    # every update is a new version of a flight the run approved, decided at an epoch
    ids = {f["request_id"] for f in on.flights}
    assert all(r["request_id"] in ids and r["version"] >= 2 and r["t_s"] % 30.0 == 0 for r in on.replans)
    # the plans (every version while in force) lose separation only where a contingency (flown,
    # not deconflicted) is one of the pair
    contingent = {r["request_id"] for r in on.replans if r["kind"] == "contingency"}
    pairs = on.audit["loss_pairs"]
    assert len(pairs) == min(on.summary["losses"], 20)
    assert all(a in contingent or b in contingent for a, b, _d, _t in pairs)


# ---- flights that fly past their plan (issue 23, the safety gap; uam_planner.nonconformance
# .overruns, docs/disturbances.md 6): held in the planner's traffic picture, by hand ---------
#: P (W at 0 s, E at 600 s) in a 1 m/s head wind: 9 m/s over the ground, x = 9 t, lands at
#: 6000 / 9 = 666.67 s, 66.7 s after its planned arrival
LATE = fly(P.trajectory, FlightDraws(), HEAD_WIND)
LANDS = 6000.0 / 9.0
#: R leaves E for W (the only route: E - m - W, against P's last leg) as soon as it can
R = FlightRequest("R", "E", "W", 630.0, 630.0, 700.0)


def seen_planner(observe_until=None, flown=LATE, reaction=False):
    """A planner holding P (by default no reaction: the default configuration), that has seen P
    in the fleet state every 10 s up to ``observe_until`` (None: never)."""
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds() if reaction else None),
                "mwis", solve_mwis=None)
    p.restore([P])
    if observe_until is not None:
        observe_every_10_s(p, 10.0, observe_until, flown)
    return p


def observe_every_10_s(p, t0, t1, flown=LATE):
    t = t0
    while t <= t1 + 1e-9:
        if flown.departure_s <= t < flown.arrival_s:      # the fleet state holds airborne vehicles
            assert p.observe("P", t, flown.position_at(t)) is None
        t += 10.0


def test_a_late_flight_is_held_past_its_planned_arrival_and_nothing_is_approved_into_it():
    assert LATE.arrival_s == pytest.approx(LANDS, abs=1.0)
    # the gap: a planner that does not see the fleet forgets P at its planned arrival (600 s)
    # and sends R head-on into it (P at 5670 m, R from 6000 m at 630 s: they meet at 19 t =
    # 12300, t = 647.4 s)
    blind = seen_planner()
    blind.submit(R)
    (r,) = blind.plan(630.0, 21).approved
    assert len(audit_flights([r.trajectory, LATE], separation_m=100.0).losses) == 1

    p = seen_planner(observe_until=630.0)
    p.submit(R)
    res = p.plan(630.0, 21)
    # seen at 630 s at 5670 m, planned there at 567 s: 63 s late; the rest of the plan shifted by
    # that lands at 663 s, and R leaving E at 630 s meets that projection head-on
    assert res.approved == [] and res.waiting == [R]
    assert res.report.overruns == {"P": pytest.approx(663.0)}
    assert res.report.active_flights == 1 and [f.request_id for f in p.active] == []
    # 660 s: seen at 5940 m (planned at 594 s: 66 s late), held until 666 s; R would leave E with
    # P 60 m away: it waits (the shift follows the growing lateness one sighting behind: the
    # aircraft lands at 666.67 s)
    observe_every_10_s(p, 640.0, 660.0)
    res = p.plan(660.0, 22)
    assert res.approved == [] and res.report.overruns == {"P": pytest.approx(666.0)}
    # 690 s: P landed at 666.67 s (no fleet state shows it any more); R goes, clear of it
    observe_every_10_s(p, 670.0, 690.0)
    res = p.plan(690.0, 23)
    (r,) = res.approved
    assert r.departure_s == 690.0 and res.report.overruns == {} and p.overruns == {}
    assert audit_flights([r.trajectory, LATE], separation_m=100.0).losses == []


def test_a_flight_seen_on_its_plan_holds_nothing_and_changes_nothing():
    # P flown exactly (no wind), seen every 10 s: it projects onto its own plan, nothing is
    # held, and R is approved at 630 s as by the planner that sees nothing (bit for bit)
    exact = fly(P.trajectory, FlightDraws(), type(HEAD_WIND)())
    seen, blind = seen_planner(observe_until=630.0, flown=exact), seen_planner()
    out = []
    for p in (seen, blind):
        p.submit(R)
        res = p.plan(630.0, 21)
        assert res.report.overruns == {} and p.overruns == {}
        (r,) = res.approved
        out.append((r.departure_s, r.trajectory.times_s.tobytes(), r.trajectory.points_m.tobytes()))
    assert out[0] == out[1]


def test_a_vehicle_that_vanishes_is_held_only_until_its_last_sighting_lands():
    # seen up to 630 s (5670 m, 63 s late), then never again (it vanished from the fleet state):
    # held until the projection from its last sighting lands, 663 s, then let go; the bound
    # MAX_OVERRUN_SHARE x 600 s after the planned arrival is never reached
    p = seen_planner(observe_until=630.0)
    assert p.plan(630.0, 21).report.overruns == {"P": pytest.approx(663.0)}
    assert p.plan(660.0, 22).report.overruns == {"P": pytest.approx(663.0)}
    assert p.plan(690.0, 23).report.overruns == {}
    assert 600.0 + MAX_OVERRUN_SHARE * 600.0 > LANDS


def test_a_flight_still_flying_after_its_planned_arrival_is_updated_between_epochs():
    # P (x = 9 t) reported late only at 605 s, after its planned arrival at 600 s; seen every
    # 10 s up to 610 s. Progress over the window 490 -> 610 s: planned 441 -> 549 s, 0.9. From
    # (5490, 0) at 610 s the rejoin at 0.9 (9 m/s) lands at 610 + 510 / 9 = 666.67 s, as it flies.
    # Before the sixteenth stop the claim was refused ("not airborne on its plan") and P flew the
    # end of its plan nonconforming until it landed (F3548: an excursion of at most 10 s)
    p = seen_planner(610.0, reaction=True)
    assert p.report_nonconforming("P", 605.0, "monitor") is None
    (u,) = p.react_between(610.0, 20)
    assert (u.request_id, u.kind, u.version, u.effective_s) == ("P", KIND, 2, 610.0)
    assert u.observed_rate == pytest.approx(0.9) and "time +61.0 s" in u.reason
    new = u.flight.trajectory
    assert new.points_m[0] == pytest.approx([5490.0, 0.0, 0.0]) and new.departure_s == 610.0
    assert new.arrival_s == pytest.approx(LANDS)
    # what flies from there conforms to the new version to the end
    tail = Trajectory(LATE.times_s[LATE.times_s >= 610.0], LATE.points_m[LATE.times_s >= 610.0])
    assert track_conformance("P", new, tail, ConformanceBounds()).first_nonconforming_s is None
    # and the planner's picture holds it: R, asked to leave E at 630 s head-on, waits
    p.submit(R)
    assert p.plan(630.0, 21).approved == [] and [(f.request_id, f.version) for f in p.active] == [("P", 2)]


def test_a_flight_held_past_its_plan_is_updated_at_the_epoch_that_dropped_its_plan():
    # P is seen every 10 s up to 630 s and reported at 625 s; at the epoch at 630 s its plan
    # (arrival 600 s) leaves the active flights and P is held (overruns). The claim holds: its
    # plan is updated from where it is, (5670, 0) at 630 s, at 0.9: landing at 630 + 330 / 9 =
    # 666.67 s; the hold ends (the new version is active). Before the sixteenth stop the claim was
    # refused ("no longer active") and P stayed nonconforming to its landing
    p = seen_planner(630.0, reaction=True)
    assert p.report_nonconforming("P", 625.0, "monitor") is None
    p.submit(R)
    res = p.plan(630.0, 21)
    (u,) = res.plan_updates
    assert (u.request_id, u.kind, u.version, u.effective_s) == ("P", KIND, 2, 630.0)
    assert u.flight.trajectory.points_m[0] == pytest.approx([5670.0, 0.0, 0.0])
    assert u.flight.trajectory.arrival_s == pytest.approx(LANDS)
    assert [(f.request_id, f.version) for f in p.active] == [("P", 2)] and p.overruns == {}
    assert res.report.nonconformance["refused"] == []
    # R (E -> W at 630 s) is kept out of it, then leaves once P has landed, clear of what flew
    assert res.approved == []
    observe_every_10_s(p, 640.0, 660.0)
    assert p.plan(660.0, 22).approved == []
    observe_every_10_s(p, 670.0, 690.0)
    (r,) = p.plan(690.0, 23).approved
    assert r.departure_s == 690.0 and p.overruns == {}
    assert audit_flights([r.trajectory, LATE], separation_m=100.0).losses == []


def test_a_claim_about_a_flight_neither_active_nor_held_is_refused_by_name():
    p = seen_planner(630.0, reaction=True)
    assert p.report_nonconforming("X", 625.0) == \
        "request_id: 'X' is neither an active flight of this planner nor held past its plan"


# ---- the reaction between epochs (issue 23 item 3: F3548's 5 s update; reaction_period_s) ----

def test_between_epochs_the_update_comes_at_once_and_keeps_separation_with_the_neighbour():
    # as test_its_updated_plan_keeps_separation_with_a_hand_placed_neighbour, but the planner
    # reacts at 110 s, between the epochs at 90 and 120 s: seen at 100 and 110 s (planned 90 and
    # 99 s: progress 0.9), from (990, 0) at 110 s the rejoin at 0.9 reaches m at 110 + 2010 / 9 =
    # 333.33 s, with Q: a loss; 10 % faster (9.9 m/s) reaches m at 110 + 2010 / 9.9 = 313.03 s,
    # 20.30 s before Q: 20.30 x 9.9 x 10 / sqrt(9.9^2 + 10^2) = 142.8 m
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    p = planner()
    _observe(p, flown, (100.0, 110.0))
    assert p.report_nonconforming("P", 101.0, "monitor") is None
    (u,) = p.react_between(110.0, 3)
    assert (u.request_id, u.kind, u.version, u.effective_s) == ("P", KIND, 2, 110.0)
    assert u.observed_rate == pytest.approx(0.9)
    new = u.flight.trajectory
    assert new.departure_s == 110.0 and new.points_m[0] == pytest.approx([990.0, 0.0, 0.0])
    assert new.position_at(110.0 + 2010.0 / 9.9) == pytest.approx([3000.0, 0.0, 0.0])
    gap = 1000.0 / 3.0 - (110.0 + 2010.0 / 9.9)
    a = audit_flights([new, Q.trajectory], separation_m=100.0)
    assert a.losses == [] and a.min_separation_m == pytest.approx(gap * 99.0 / math.hypot(9.9, 10.0), abs=0.01)
    assert sorted((f.request_id, f.version) for f in p.active) == [("P", 2), ("Q", 1)]
    # nothing is left for the epoch at 120 s: the claim was acted on, P conforms to its update
    assert p.react_between(115.0, 3) == [] and p.plan(120.0, 4).plan_updates == []
    # between epochs nothing else happens: no claim, no update; not while an epoch is prepared
    prep = p.prepare(150.0, 5)
    with pytest.raises(RuntimeError):
        p.react_between(155.0, 5)
    p.commit(prep)


def test_a_second_update_is_timed_from_the_sightings_of_the_version_in_force_only():
    # issue 23 fourth stop (the root cause of the planned losses with reaction_period_s = 5): as
    # above, P is updated at 110 s to v2, from (990, 0) at 9 m/s (rate 0.9; v2 reaches (1080, 0)
    # at 120 s). It flies v2 exactly to 120 s, then a gust puts it 40 m north: seen at (1170, 40)
    # at 130 s. Its nearest point on v2 is (1170, 0), planned at 110 + 180 / 9 = 130 s: on time.
    # The rate against v2 from its own sightings (110 -> 130 s, planned 110 -> 130 s) is 1.0,
    # so v3 is timed at 9 m/s. The sighting at 100 s (900, 0), made against v1, projects onto
    # v2's first point (planned 110 s): counted, it reads (130 - 110) / (130 - 100) = 2 / 3, and
    # v3 is timed at 6 m/s while the aircraft flies 9 m/s over the ground: 3 m/s ahead, 0.5 s of
    # plan per second, out of the 10 s bound 20 s later (and updated again, at 2 / 3 of that...)
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds()), "mwis", solve_mwis=None)
    p.restore([P])
    _observe(p, flown, (100.0, 110.0))
    assert p.report_nonconforming("P", 101.0, "monitor") is None
    (u2,) = p.react_between(110.0, 3)
    v2 = u2.flight.trajectory
    assert u2.observed_rate == pytest.approx(0.9) and v2.position_at(120.0) == pytest.approx([1080.0, 0.0, 0.0])
    assert p.observe("P", 120.0, (1080.0, 0.0, 0.0)) is None
    assert p.observe("P", 130.0, (1170.0, 40.0, 0.0)) is None
    assert p.positions.progress_rate("P", v2, until=130.0) == pytest.approx(1.0)
    assert p.report_nonconforming("P", 130.0, "monitor") is None
    (u3,) = p.react_between(130.0, 3)
    assert (u3.version, u3.kind, u3.effective_s) == (3, KIND, 130.0)
    assert u3.observed_rate == pytest.approx(1.0)
    v3 = u3.flight.trajectory
    # from (1170, 40) straight to m (3000, 0): 1830.44 m at 9 m/s, then 3000 m at 9 m/s
    first = math.hypot(1830.0, 40.0)
    assert v3.points_m[1] == pytest.approx([3000.0, 0.0, 0.0])
    assert v3.times_s[1] == pytest.approx(130.0 + first / 9.0)
    assert v3.arrival_s == pytest.approx(130.0 + first / 9.0 + 3000.0 / 9.0)
    # flown on at its airspeed (10 m/s, 9 over the ground against the head wind): the
    # speed error against v3 is (1 + (1 / 0.9 - 1)) / 1.0 - 1, and it conforms to its end
    cont = fly(v3, FlightDraws(1.0 / 0.9 - 1.0), HEAD_WIND)
    assert track_conformance("P", v3, cont, ConformanceBounds()).first_nonconforming_s is None


def test_the_reaction_graph_is_handed_to_the_caller_and_its_answer_taken():
    # Planner.prepare_steps / react_between_steps yield the reaction's MWIS graph, as the
    # constraint re-plan's, so the planner node solves it through the solver service. Same case
    # as test_its_updated_plan_keeps_separation_with_a_hand_placed_neighbour: the alternatives
    # are the rates 0.9 (a loss with Q: not a vertex), 0.81, 0.99, 0.72, 0.63. A caller answering
    # with the 0.81 one gets it (P at m at 120 + 1920 / 8.1 = 357.04 s, 23.70 s after Q: 149.2 m)
    from uam_planner.replanning import SOLVE_HERE
    from types import SimpleNamespace
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    for between in (False, True):
        p = planner()
        _observe(p, flown, (100.0, 110.0, 120.0))
        assert p.report_nonconforming("P", 101.0, "monitor") is None
        steps = p.react_between_steps(120.0, 4) if between else p.prepare_steps(120.0, 4)
        graph = next(steps)
        assert graph.n_vertices == 4   # the rejoin at 0.9 loses separation with Q
        v = int(np.flatnonzero(graph.vertex_source == 1)[0])   # the alternative at 0.81
        try:
            steps.send(SimpleNamespace(selected=[v], backend="by-caller"))
            raise AssertionError("one graph only")
        except StopIteration as done:
            out = done.value
        (u,) = out if between else p.commit(out).plan_updates
        assert u.kind == KIND and u.flight.backend == "by-caller"
        assert u.flight.trajectory.position_at(120.0 + 1920.0 / 8.1) == pytest.approx([3000.0, 0.0, 0.0])
        gap = 120.0 + 1920.0 / 8.1 - 1000.0 / 3.0
        a = audit_flights([u.flight.trajectory, Q.trajectory], separation_m=100.0)
        assert a.losses == [] and a.min_separation_m == pytest.approx(gap * 81.0 / math.hypot(8.1, 10.0), abs=0.01)
        # solved here (SOLVE_HERE: the planner's own solver) it is the 0.99 one, as before
        p = planner()
        _observe(p, flown, (100.0, 110.0, 120.0))
        p.report_nonconforming("P", 101.0, "monitor")
        steps = p.react_between_steps(120.0, 4) if between else p.prepare_steps(120.0, 4)
        next(steps)
        try:
            steps.send(SOLVE_HERE)
        except StopIteration as done:
            out = done.value
        (u,) = out if between else p.commit(out).plan_updates
        assert u.flight.trajectory.position_at(120.0 + 1920.0 / 9.9) == pytest.approx([3000.0, 0.0, 0.0])


def test_the_runner_reacts_between_epochs():
    """reaction_period_s = 5 s in the runner: updates take effect between epochs, and the
    longest excursion is shorter than with the reaction at the epochs only (same seed)."""
    from uam_sim.runner.experiment_config import ExperimentError, make_config
    at_epochs = tiny_run(reaction=True)
    often = tiny_run(reaction=True, reaction_period_s=5.0)
    assert any(r["t_s"] % 30.0 != 0 for r in often.replans)
    assert all(r["t_s"] % 5.0 == 0 for r in often.replans)
    assert often.summary["conf_longest_excursion_s"] < at_epochs.summary["conf_longest_excursion_s"]
    # the plans the planner deconflicted keep separation (the reaction's contingencies apart)
    assert at_epochs.summary["losses_deconflicted"] == 0 and often.summary["losses_deconflicted"] == 0
    for r in (at_epochs, often):
        assert 0 <= r.summary["flown_losses_with_contingency"] <= r.summary["flown_losses"]
    with pytest.raises(ExperimentError, match="reaction_period_s: 45"):
        make_config(dict(TINY_RUN, reaction=True, reaction_period_s=45.0))


def test_the_runners_record_keeps_each_version_in_force_by_its_kind():
    # a flight planned W -> E from 0 s, updated at 100 s as a contingency: the plan until 100 s,
    # then the contingency, one flight (never a pair with itself); the audit leaves the
    # contingency out of the losses of the deconflicted plans (scenario.run_scenario's summary
    # "losses_deconflicted")
    from uam_sim.audit.record import PlanVersion
    from uam_planner.nonconformance import RATE_WORD
    from uam_sim.runner.scenario import run_record
    a = P.trajectory
    b = rejoin_trajectory(a, 100.0, (900.0, 0.0, 0.0), 0.9)
    row = {"request_id": "r1", "_versions": [PlanVersion.of(1, -math.inf, a),
                                             PlanVersion.of(2, 100.0, b, update_kind="contingency",
                                                            reason=f"re-timed from the {RATE_WORD} 0.9")]}
    record = run_record([row])
    assert record.problems == []
    got = record.in_force()
    assert got.labels == ["r1", "r1 v2 (contingency)"] and got.groups == ["r1", "r1"]
    assert got.contingent == [False, True]
    (ta, _xa), (tb, _xb) = got.parts
    assert ta[-1] == 100.0 and tb[0] == 100.0 and tb[-1] == b.arrival_s


def test_on_a_path_that_comes_back_over_itself_a_late_flight_is_held_from_its_first_pass():
    # A -> B -> A at 10 m/s. Seen at 170 s at x = 500: on the way out 120 s late, or on the way
    # back 20 s late; one sighting cannot tell. The hold takes the first pass (lands at
    # 170 + 150 = 320 s), never the shorter one (220 s); the reaction's rejoin, which re-times a
    # flight known to be on its version, takes the pass nearest in planned time (on the way back).
    from uam_planner.nonconformance import Observation, overrun_trajectory
    back = Trajectory(np.array([0.0, 100.0, 200.0]),
                      np.array([[0.0, 0.0, 50.0], [1000.0, 0.0, 50.0], [0.0, 0.0, 50.0]]))
    held = overrun_trajectory(back, Observation(170.0, (500.0, 0.0, 50.0)), cap_s=1e9)
    assert held.arrival_s == pytest.approx(320.0)
    rejoin = rejoin_trajectory(back, 170.0, (500.0, 0.0, 50.0), 1.0)
    assert rejoin.arrival_s == pytest.approx(220.0)


def test_a_neighbour_yields_so_that_a_nonconforming_flight_keeps_separation():
    """Seventh stop (uam_planner.nonconformance.YIELD_SHARES): each of P's five updates meets
    one crossing flight at m, so alone P would be a contingency (flown, not deconflicted). Its
    least-conflicting update (0.99 of the planned speed, the soonest to land) meets only Q3;
    Q3, airborne and conforming, yields: 10 % faster from where its plan is at the epoch, it is
    at m 17.6 s before P, 129.5 m at their closest; P's update is deconflicted, nobody loses
    separation."""
    from uam_planner.nonconformance import KIND_YIELD
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    # P's updates from (1080, 0) at 120 s reach m at 120 + 1920 / v, v = 9 x (1, 1.1, 0.9, 0.8, 0.7)
    at_m = [120.0 + 1920.0 / (9.0 * s) for s in (1.1, 1.0, 0.9, 0.8, 0.7)]
    # one northbound flight on S - m - N at m at each of those instants (Q's own is the second)
    qs = [flight(f"Q{k}", ["S", "m", "N"], [(3000, -3000, 0), (3000, 0, 0), (3000, 3000, 0)], t - 300.0)
          for k, t in enumerate(at_m)]
    p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds()), "mwis", solve_mwis=None)
    p.restore([P, *qs])
    _observe(p, flown, (100.0, 110.0, 120.0))
    assert p.report_nonconforming("P", 101.0) is None
    res = p.plan(120.0, 4)
    by = {u.request_id: u for u in res.plan_updates}
    assert set(by) == {"P", "Q0"}
    assert by["P"].kind == KIND and not by["P"].flight.contingent
    assert by["P"].flight.trajectory.position_at(at_m[0]) == pytest.approx([3000.0, 0.0, 0.0])
    q0 = by["Q0"]
    assert q0.kind == KIND_YIELD and q0.version == 2 and q0.effective_s == 120.0
    assert q0.observed_rate == 0.0 and "speed x1.1" in q0.reason and "P" in q0.reason
    # re-timed from where its plan is at 120 s (3000, -1939.4), 11 m/s: its plan up to then
    # (the same departure), the rest 10 % faster
    new_q = q0.flight.trajectory
    assert q0.flight.departure_s == qs[0].departure_s == new_q.departure_s
    assert new_q.position_at(120.0) == pytest.approx(qs[0].trajectory.position_at(120.0))
    assert new_q.position_at(60.0) == pytest.approx(qs[0].trajectory.position_at(60.0))
    t_q = 120.0 + (3000.0 - (120.0 - (at_m[0] - 300.0)) * 10.0) / 11.0
    assert new_q.position_at(t_q) == pytest.approx([3000.0, 0.0, 0.0])
    newest = [f.trajectory for f in p.active]
    assert sorted((f.request_id, f.version) for f in p.active) == \
        [("P", 2), ("Q0", 2), ("Q1", 1), ("Q2", 1), ("Q3", 1), ("Q4", 1)]
    a = audit_flights(newest, separation_m=100.0)
    dt = at_m[0] - t_q
    assert a.losses == [] and a.min_separation_m == pytest.approx(dt * 9.9 * 11.0 / math.hypot(9.9, 11.0), abs=0.5)
    assert res.report.nonconformance["kinds"] == {KIND: 1, KIND_YIELD: 1}


# ---- the conflict probe (PlanningConfig.conflict_probe_s) ---------------------------------------

#: Q2: S at 20 s, m at 320 s, N at 620 s: 20 s after P at m, 20 x 10 x 10 / sqrt(200) = 141.4 m
Q2 = flight("Q2", ["S", "m", "N"], [(3000, -3000, 0), (3000, 0, 0), (3000, 3000, 0)], 20.0)


def probe_planner(probe_s):
    from uam_planner.nonconformance import ConformanceBounds as CB
    p = Planner(cross(), PlanningConfig(conformance=CB(), conflict_probe_s=probe_s), "mwis",
                solve_mwis=None)
    p.restore([P, Q2])
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)  # 9 m/s over the ground
    for t in (50.0, 60.0):
        assert p.observe("P", t, flown.position_at(t)) is None
        assert p.observe("Q2", t, Q2.trajectory.position_at(t)) is None
    return p


def test_the_probe_predicts_a_loss_between_two_conforming_flights_from_their_observed_speeds():
    from uam_planner.nonconformance import predicted_conflicts
    # P at 60 s: x = 540 m, planned 54 s: 6 s late, it conforms (10 s bound); progress 0.9. Flown
    # from there at 9 m/s it reaches m at 60 + 2460 / 9 = 333.33 s, Q2 (on its plan) at 320 s:
    # 81 (t - 333.33) + 100 (t - 320) = 0 at t = 325.97 s, dx = -66.3 m, dy = 59.7 m: 89.2 m
    p = probe_planner(300.0)
    got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, 100.0)
    assert {p.active[i].request_id: ids for i, (_o, ids) in got.items()} == {"P": ["Q2"], "Q2": ["P"]}
    # the meeting is 266 s ahead: a look-ahead of 200 s does not see it; the plans keep 141 m
    assert predicted_conflicts(p.active, p.positions, 60.0, 200.0, 100.0) == {}
    assert audit_flights([P.trajectory, Q2.trajectory], separation_m=100.0).losses == []


def test_the_probe_updates_both_before_either_is_nonconforming_and_the_new_plans_keep_separation():
    p = probe_planner(300.0)
    ups = p.react_between(60.0, 2)
    assert sorted(u.request_id for u in ups) == ["P", "Q2"]
    assert all(u.kind == KIND and "conflict probe" in u.reason and u.effective_s == 60.0 for u in ups)
    new = {u.request_id: u.flight.trajectory for u in ups}
    assert new["P"].points_m[0] == pytest.approx([540.0, 0.0, 0.0])
    assert audit_flights(list(new.values()), separation_m=100.0).losses == []
    # what P really flies (9 m/s from 540 m at 60 s) keeps separation with Q2's new plan too
    flown_p = Trajectory(np.array([60.0, 60.0 + 5460.0 / 9.0]), np.array([[540.0, 0, 0], [6000.0, 0, 0]]))
    assert audit_flights([flown_p, new["Q2"]], separation_m=100.0).losses == []
    # off (the default): no report, nothing happens
    assert probe_planner(0.0).react_between(60.0, 2) == []


def test_the_probe_sees_a_flight_due_to_depart_and_updates_the_airborne_one_against_its_plan():
    # thirteenth stop: flights due to depart within the look-ahead are projected on their plan.
    # A vertiport V at (3000, -1500) on the south leg; R leaves it at 183.33 s, at m at 333.33 s:
    # its plan keeps 33.33 s x 10 m/s / sqrt(2) = 235.7 m from P's plan (P at m at 300 s). P,
    # 6 s late at 60 s and flown on at 0.9 of its speed, reaches m at 333.33 s too: the
    # projection of P meets R's plan there (0 m) while R is still on the ground at 60 s
    from uam_planner.nonconformance import ConformanceBounds as CB, predicted_conflicts

    net = network_from_enu("cross-v", ["W", "m", "E", "V", "N"],
                           [(0, 0, 0), (3000, 0, 0), (6000, 0, 0), (3000, -1500, 0), (3000, 3000, 0)],
                           [True, False, True, True, True],
                           [("W", "m"), ("m", "E"), ("V", "m"), ("m", "N")])
    R = flight("R", ["V", "m", "N"], [(3000, -1500, 0), (3000, 0, 0), (3000, 3000, 0)], 550.0 / 3.0)
    assert audit_flights([P.trajectory, R.trajectory], separation_m=100.0).min_separation_m == \
        pytest.approx(1000.0 / 3.0 / math.sqrt(2.0), rel=1e-4)
    p = Planner(net, PlanningConfig(conformance=CB(), conflict_probe_s=300.0), "mwis", solve_mwis=None)
    p.restore([P, R])
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)  # 9 m/s over the ground
    for t in (50.0, 60.0):
        assert p.observe("P", t, flown.position_at(t)) is None
    got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, 100.0)
    # only P is probed: R has not been seen (nothing to update it from), it is met as planned
    assert {p.active[i].request_id: ids for i, (_o, ids) in got.items()} == {"P": ["R"]}
    # R departs after the look-ahead's end: not projected, nothing predicted
    assert predicted_conflicts(p.active, p.positions, 60.0, 120.0, 100.0) == {}
    ups = p.react_between(60.0, 2)
    assert [u.request_id for u in ups] == ["P"] and "conflict probe" in ups[0].reason
    new_p = ups[0].flight.trajectory
    assert new_p.points_m[0] == pytest.approx([540.0, 0.0, 0.0])
    # P's new plan keeps the minimum from R's plan, which R keeps (version 1, not updated)
    assert audit_flights([new_p, R.trajectory], separation_m=100.0).losses == []
    assert {f.request_id: f.version for f in p.active}["R"] == 1


def test_a_flight_due_to_depart_is_held_on_the_pad_when_the_airborne_one_cannot_move():
    # thirteenth stop. P (6 s late at 60 s, 9 m/s) and R (due to leave V at 183.33 s) as above:
    # P's projection and R's plan meet at m at 333.33 s. A vehicle hovers on P's route at
    # (1500, 0) from 60 s to 700 s: every alternative of P passes it (its plan too), so P is
    # released (keeps its plan); R is held on the pad instead. Held d s, R is at m d s after P's
    # projection: 10 x 9 / sqrt(181) d = 6.69 d m apart at closest, so 10 s (66.9 m) is too little
    # and 20 s (133.8 m) the least hold that keeps 100 m
    from uam_planner.nonconformance import (KIND_YIELD, ConformanceBounds as CB, deviations,
                                            predicted_conflicts, react_steps)
    from uam_planner.planning import replan_selector
    from uam_planner.replanning import SOLVE_HERE, run_steps

    net = network_from_enu("cross-v", ["W", "m", "E", "V", "N"],
                           [(0, 0, 0), (3000, 0, 0), (6000, 0, 0), (3000, -1500, 0), (3000, 3000, 0)],
                           [True, False, True, True, True],
                           [("W", "m"), ("m", "E"), ("V", "m"), ("m", "N")])
    R = flight("R", ["V", "m", "N"], [(3000, -1500, 0), (3000, 0, 0), (3000, 3000, 0)], 550.0 / 3.0)
    p = Planner(net, PlanningConfig(conformance=CB(), conflict_probe_s=300.0), "mwis", solve_mwis=None)
    p.restore([P, R])
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    for t in (50.0, 60.0):
        assert p.observe("P", t, flown.position_at(t)) is None
    got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, 100.0)
    found = {i: (obs, tuple(float(x[0]) for x in deviations(p.active[i].trajectory, [obs.t_s],
                                                             [obs.position_m])))
             for i, (obs, _ids) in got.items()}
    hover = Trajectory(np.array([60.0, 700.0]), np.array([[1500.0, 0.0, 0.0]] * 2))
    r_index = [f.request_id for f in p.active].index("R")
    steps = react_steps(60.0, 2, p.active, found, p.positions, p.config,
                        replan_selector(None, p.config, 2, 60.0), "mwis", p.network,
                        fixed=[hover], fixed_ids=["H"],
                        probed={i: ids for i, (_o, ids) in got.items()}, held=[r_index])
    active, ups, rep = run_steps(steps, lambda _graph: SOLVE_HERE)
    assert [(u.request_id, u.kind) for u in ups] == [("R", KIND_YIELD)]
    assert rep["probe_released"] == 1 and rep["probe_held"] == 1
    new_r = ups[0].flight
    assert new_r.departure_s == pytest.approx(550.0 / 3.0 + 20.0) and new_r.version == 2
    assert "held on the pad 20 s" in ups[0].reason and "P" in ups[0].reason
    assert new_r.trajectory.points_m == pytest.approx(R.trajectory.points_m)
    # what P really flies (9 m/s from 540 m at 60 s) keeps the minimum from R's new plan
    flown_p = Trajectory(np.array([60.0, 60.0 + 5460.0 / 9.0]), np.array([[540.0, 0, 0], [6000.0, 0, 0]]))
    a = audit_flights([flown_p, new_r.trajectory], separation_m=100.0)
    assert a.losses == [] and a.min_separation_m == pytest.approx(20.0 * 90.0 / math.sqrt(181.0), rel=1e-3)
    # P keeps its plan (released), R has its second version
    assert {f.request_id: f.version for f in active} == {"P": 1, "R": 2}


def test_with_the_probe_a_new_request_keeps_the_minimum_from_where_a_flight_is_seen():
    # thirteenth stop: with the probe on, new requests are deconflicted against the airborne
    # flights' projections too. P flies 10.3 m/s over the ground (0.3 m/s tail wind): at 180 s
    # at 1854 m, 5.2 s early (it conforms; a late flight is held by its overrun already), its
    # projection reaches m at 180 + 1146 / 10.3 = 291.26 s. T may leave V (3000, -1050) at 180 s
    # only: at m at 285 s, 15 s before P's plan (106.1 m apart at closest) but 6.26 s before P's
    # projection (6.26 x 103 / sqrt(206.09) = 44.9 m)
    from uam_planner.nonconformance import ConformanceBounds as CB

    net = network_from_enu("cross-v", ["W", "m", "E", "V", "N"],
                           [(0, 0, 0), (3000, 0, 0), (6000, 0, 0), (3000, -1050, 0), (3000, 3000, 0)],
                           [True, False, True, True, True],
                           [("W", "m"), ("m", "E"), ("V", "m"), ("m", "N")])
    flown = fly(P.trajectory, FlightDraws(), DisturbanceConfig(wind_speed_mps=0.3, wind_from_deg=270.0))
    assert flown.position_at(180.0)[0] == pytest.approx(1854.0)
    T = FlightRequest("T", "V", "N", 180.0, 180.0, 180.0)
    got = {}
    for probe_s in (0.0, 300.0):
        p = Planner(net, PlanningConfig(conformance=CB(), conflict_probe_s=probe_s), "mwis",
                    solve_mwis=None)
        p.restore([P])
        for t in np.arange(10.0, 181.0, 10.0):
            assert p.observe("P", float(t), flown.position_at(float(t))) is None
        p.submit(T)
        got[probe_s] = p.plan(180.0, 6)
    # without the probe T is approved against P's plan, and meets P as it flies
    (t_plan,) = got[0.0].approved
    assert audit_flights([t_plan.trajectory, P.trajectory], separation_m=100.0).min_separation_m == \
        pytest.approx(150.0 / math.sqrt(2.0), rel=1e-3)
    a = audit_flights([t_plan.trajectory, flown], separation_m=100.0)
    assert len(a.losses) == 1 and a.min_separation_m == pytest.approx(44.9, abs=0.5)
    # with it, T's one candidate is not approved into P's projection (it is discarded: it
    # expires with its window),
    # and P's plan is not changed (nothing is predicted to meet it)
    res = got[300.0]
    assert res.approved == [] and (res.report.candidates, res.report.vertices) == (1, 0), res.report
    assert res.plan_updates == []


def test_a_flight_no_re_timing_saves_is_diverted_before_it_flies_a_contingency():
    # thirteenth stop: P 12 s late at 120 s (nonconforming) and a vehicle hovering on its route
    # at (4500, 0) from 60 s to 2000 s: every re-join of P to E passes it, and nothing can yield
    # (a fixed projection). Before, P flew a contingency through it; now it is diverted at m to
    # the nearest other vertiport that keeps separation: W, S and N are 3 km from m (ties by
    # index: W first), flown at its observed rate (0.9: 9 m/s), clear of the hovering vehicle
    from uam_planner.nonconformance import (KIND, KIND_CONTINGENCY, deviations, react_steps)
    from uam_planner.planning import replan_selector
    from uam_planner.replanning import SOLVE_HERE, _Router, run_steps

    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    hover = Trajectory(np.array([60.0, 2000.0]), np.array([[4500.0, 0.0, 0.0]] * 2))
    out = {}
    for divert in (False, True):
        p = Planner(cross(), PlanningConfig(conformance=ConformanceBounds()), "mwis", solve_mwis=None)
        p.restore([P])
        _observe(p, flown, (100.0, 110.0, 120.0))
        obs = p.positions.latest("P", until=120.0)
        errs = tuple(float(x[0]) for x in deviations(P.trajectory, [obs.t_s], [obs.position_m]))
        assert errs[2] == pytest.approx(12.0, abs=0.01)        # 12 s late: nonconforming
        steps = react_steps(120.0, 4, p.active, {0: (obs, errs)}, p.positions, p.config,
                            replan_selector(None, p.config, 4, 120.0), "mwis", p.network,
                            fixed=[hover], fixed_ids=["H"],
                            router=_Router(p.network, p.cache, (), 120.0) if divert else None)
        _active, ups, rep = run_steps(steps, lambda _graph: SOLVE_HERE)
        (out[divert],) = ups
    before, after = out[False], out[True]
    assert before.kind == KIND_CONTINGENCY and before.flight.contingent
    assert len(audit_flights([before.flight.trajectory, hover], separation_m=100.0).losses) == 1
    assert after.kind == KIND and not after.flight.contingent
    assert "diverted to 'W'" in after.reason and after.flight.destination_id == "W"
    assert after.flight.route_node_ids == ("W", "m", "W") and after.previous is P
    new = after.flight.trajectory
    # from where P is (1080, 0) at 120 s to m at 9 m/s (333.33 s), then back to W at 9 m/s
    assert new.points_m[0] == pytest.approx([1080.0, 0.0, 0.0])
    assert new.position_at(1000.0 / 3.0) == pytest.approx([3000.0, 0.0, 0.0])
    assert new.arrival_s == pytest.approx(1000.0 / 3.0 + 3000.0 / 9.0)
    assert audit_flights([new, hover], separation_m=100.0).losses == []


def test_the_probe_margin_widens_what_it_predicts_and_what_its_updates_keep():
    # thirteenth stop: PlanningConfig.conflict_probe_margin_m
    from uam_planner.nonconformance import ConformanceBounds as CB, predicted_conflicts, probe_batch_separation

    cfg = PlanningConfig(conformance=CB(), conflict_probe_s=300.0, conflict_probe_margin_m=30.0,
                         spatial_buffer_m=10.0)
    assert cfg.probe_separation.separation_m == 130.0 and cfg.separation.separation_m == 110.0
    assert probe_batch_separation(cfg).separation_m == 130.0
    assert probe_batch_separation(PlanningConfig(spatial_buffer_m=50.0, conflict_probe_margin_m=30.0)) \
        .separation_m == 150.0
    assert PlanningConfig().probe_separation == PlanningConfig().minimum_separation
    with pytest.raises(ValueError, match="conflict_probe_margin_m"):
        PlanningConfig(conflict_probe_margin_m=-1.0)
    # P, 6 s late at 60 s, flown on at 0.9 (9 m/s) reaches m at 333.33 s; Q6 (due to depart S at
    # 80 s: projected on its plan) reaches m at 380 s, 46.67 s later: the projections' closest
    # approach is 46.67 x 10 x 9 / sqrt(181) = 312.2 m: no loss of 100 m, nor of 100 + 200 m,
    # one of 100 + 250 m
    p = Planner(cross(), cfg, "mwis", solve_mwis=None)
    q6 = flight("Q6", ["S", "m", "N"], [(3000, -3000, 0), (3000, 0, 0), (3000, 3000, 0)], 80.0)
    p.restore([P, q6])
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    for t in (50.0, 60.0):
        assert p.observe("P", t, flown.position_at(t)) is None
    d = 140.0 / 3.0 * 90.0 / math.sqrt(181.0)
    assert d == pytest.approx(312.2, abs=0.1)
    for margin, hit in ((0.0, False), (200.0, False), (250.0, True)):
        sep = PlanningConfig(conflict_probe_margin_m=margin).probe_separation
        got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, sep)
        assert bool(got) == hit, (margin, got)
    # with a margin of 250 m the probe updates P (Q6 is on the ground), and P's new plan keeps
    # 350 m from Q6's
    p2 = Planner(cross(), PlanningConfig(conformance=CB(), conflict_probe_s=300.0,
                                         conflict_probe_margin_m=250.0), "mwis", solve_mwis=None)
    p2.restore([P, q6])
    for t in (50.0, 60.0):
        assert p2.observe("P", t, flown.position_at(t)) is None
    ups = p2.react_between(60.0, 2)
    assert [u.request_id for u in ups] == ["P"] and "conflict probe" in ups[0].reason
    new = {f.request_id: f.trajectory for f in p2.active}
    assert audit_flights([new["P"], new["Q6"]], separation_m=350.0).losses == []


def test_a_time_shift_reaches_its_delay_within_the_window_on_the_same_path():
    from uam_planner.nonconformance import shifted_trajectory
    # 0 -> 6000 m at 10 m/s from 0 s; +10 s within 60 s: the first 600 m take 70 s (8.57 m/s),
    # then the same speed as before, 10 s later: at 600 m at 70 s, at the end at 610 s
    base = Trajectory(np.array([0.0, 600.0]), np.array([[0.0, 0, 0], [6000.0, 0, 0]]))
    late = shifted_trajectory(base, 0.0, 10.0, 60.0)
    assert late.arrival_s == pytest.approx(610.0)
    assert late.position_at(70.0) == pytest.approx([600.0, 0, 0])
    assert late.position_at(35.0) == pytest.approx([300.0, 0, 0])
    early = shifted_trajectory(base, 0.0, -5.0, 60.0)   # 600 m in 55 s (10.9 m/s)
    assert early.arrival_s == pytest.approx(595.0) and early.position_at(55.0) == pytest.approx([600.0, 0, 0])
    assert shifted_trajectory(base, 0.0, -60.0, 60.0) is None   # would stop the clock


def test_a_probed_flight_the_batch_cannot_save_keeps_its_plan_and_the_other_is_still_updated():
    from uam_planner.nonconformance import deviations, predicted_conflicts, react_steps
    from uam_planner.planning import replan_selector
    from uam_planner.replanning import SOLVE_HERE, run_steps
    p = probe_planner(300.0)                 # P 6 s late at 60 s, predicted to meet Q2 (89.2 m)
    got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, 100.0)
    found = {i: (obs, tuple(float(x[0]) for x in deviations(p.active[i].trajectory, [obs.t_s],
                                                             [obs.position_m])))
             for i, (obs, _ids) in got.items()}
    # a vehicle hovering on Q2's route 600 m ahead of it, (3000, -2000), from 60 s to 700 s:
    # every alternative of Q2 passes it (its own plan too, at 120 s); P's route is 2 km away
    hover = Trajectory(np.array([60.0, 700.0]), np.array([[3000.0, -2000.0, 0.0]] * 2))
    steps = react_steps(60.0, 2, p.active, found, p.positions, p.config,
                        replan_selector(None, p.config, 2, 60.0), "mwis", p.network,
                        fixed=[hover], fixed_ids=["H"],
                        probed={i: ids for i, (_o, ids) in got.items()})
    _active, ups, rep = run_steps(steps, lambda _graph: SOLVE_HERE)
    # Q2 has no alternative: it keeps its plan; P is solved again against Q2's plan and
    # projection and updated (before the tenth stop the whole batch was dropped: no update)
    assert [u.request_id for u in ups] == ["P"]
    assert ups[0].kind == KIND and "conflict probe" in ups[0].reason
    assert rep["probe_released"] == 1 and rep["probe_kept"] == 1 and rep["probe_updates"] == 1
    new_p = ups[0].flight.trajectory
    assert new_p.points_m[0] == pytest.approx([540.0, 0.0, 0.0])
    assert audit_flights([new_p, Q2.trajectory], separation_m=100.0).losses == []


def test_a_rate_read_from_a_short_time_on_the_version_is_drawn_towards_one():
    # twelfth stop (RATE_FULL_SPAN_S = 60 s): a plan of 10 m/s along x from t = 0, flown at
    # 7 m/s. Seen at 10 and 20 s (70, 140 m; planned at 7 and 14 s) the raw rate is 0.7, but 20 s
    # on the version is little evidence (gusts, a climb): 1 - 0.3 x 20 / 60 = 0.9. From 60 s on
    # it is read as it is: 0.7. A version that began at 100 s (a reaction's update, from where
    # the aircraft was) starts afresh: 30 s on it give half the correction.
    from uam_planner.nonconformance import RATE_FULL_SPAN_S, PositionBook

    assert RATE_FULL_SPAN_S == 60.0
    plan = Trajectory(np.array([0.0, 300.0]), np.array([[0.0, 0.0, 0.0], [3000.0, 0.0, 0.0]]))
    book = PositionBook()
    for t in range(10, 131, 10):
        assert book.observe("P", float(t), (7.0 * t, 0.0, 0.0)) is None
    assert book.progress_rate("P", plan, until=20.0) == pytest.approx(0.9)
    assert book.progress_rate("P", plan, until=40.0) == pytest.approx(1.0 - 0.3 * 40.0 / 60.0)
    assert book.progress_rate("P", plan, until=60.0) == pytest.approx(0.7)
    assert book.progress_rate("P", plan, until=130.0) == pytest.approx(0.7)
    # v2 from (700, 0) at 100 s at 8 m/s; the aircraft flies on at 7 m/s (rate 7 / 8 on v2)
    v2 = Trajectory(np.array([100.0, 100.0 + 2300.0 / 8.0]),
                    np.array([[700.0, 0.0, 0.0], [3000.0, 0.0, 0.0]]))
    raw = 7.0 / 8.0
    assert book.progress_rate("P", v2, until=130.0) == pytest.approx(1.0 + (raw - 1.0) * 30.0 / 60.0)


def test_a_contingency_keeps_the_true_minimum_before_the_buffer():
    # twelfth stop: with a 25 m buffer (125 m kept), alternative A passes 50 m from O1 (a loss
    # of the true minimum, one flight inside the buffer) and B 110 m from O1 and from O2 (inside
    # the buffer of two flights, the true minimum kept). By buffered conflicts alone A (1) beat
    # B (2); a contingency's choice now counts losses of the true minimum first: B
    from uam_planner.nonconformance import _least_conflicting

    cfg = PlanningConfig(spatial_buffer_m=25.0)
    assert cfg.separation.separation_m == 125.0 and cfg.minimum_separation.separation_m == 100.0

    def line(y, t1=100.0):
        return Trajectory(np.array([0.0, t1]), np.array([[0.0, y, 0.0], [1000.0, y, 0.0]]))

    a, b = (line(0.0), 3.0), (line(-60.0, 110.0), 2.0)
    others = [line(50.0), line(-170.0, 110.0)]
    assert _least_conflicting([a, b], others, cfg, 0.0) is a
    assert _least_conflicting([a, b], others, cfg, 0.0, true_first=True) is b
    assert _least_conflicting([b, a], others, cfg, 0.0, true_first=True) is b
    # without a buffer the two orders are one: fewest losses, then the soonest arrival
    cfg0 = PlanningConfig()
    assert _least_conflicting([a, b], others, cfg0, 0.0, true_first=True) is \
        _least_conflicting([a, b], others, cfg0, 0.0)


def test_the_probe_re_routes_a_flight_no_re_timing_saves_from_a_head_on_meeting():
    # fourteenth stop. W (0, 0) - m (3000, 0) - E (6000, 0), m - N (3000, 3000) - E. P flies W ->
    # m -> E from 0 s (m at 300 s, E at 600 s) and conforms (seen on its plan at 40 and 50 s);
    # R leaves E at 60 s for W over m (the plan of a flight flown as a contingency, say): head-on,
    # 10 t = 6000 - 10 (t - 60) at t = 330 s, 300 m past m. No re-timing of P and no hold of R
    # parts them (head-on on one corridor they meet whatever the times). Before, the probe kept
    # both plans at every look; now P is re-routed from m over N to E: at m at 300 s, R is 600 m
    # east of m coming west; P goes north, both at 10 m/s: (600 - 10 s)^2 + (10 s)^2 is least at
    # s = 30 s, 300 sqrt(2) = 424.3 m
    from uam_planner.nonconformance import (ConformanceBounds as CB, deviations, predicted_conflicts,
                                            react_steps)
    from uam_planner.planning import replan_selector
    from uam_planner.replanning import SOLVE_HERE, _Router, run_steps

    net = network_from_enu("cross-ne", ["W", "m", "E", "N"],
                           [(0, 0, 0), (3000, 0, 0), (6000, 0, 0), (3000, 3000, 0)],
                           [True, False, True, True],
                           [("W", "m"), ("m", "E"), ("m", "N"), ("N", "E")])
    R = flight("R", ["E", "m", "W"], [(6000, 0, 0), (3000, 0, 0), (0, 0, 0)], 60.0)
    assert len(audit_flights([P.trajectory, R.trajectory], separation_m=100.0).losses) == 1
    out = {}
    for reroute in (False, True):
        p = Planner(net, PlanningConfig(conformance=CB(), conflict_probe_s=300.0), "mwis",
                    solve_mwis=None)
        p.restore([P, R])
        for t in (40.0, 50.0):
            assert p.observe("P", t, P.trajectory.position_at(t)) is None
        got = predicted_conflicts(p.active, p.positions, 50.0, 300.0, 100.0)
        assert {p.active[i].request_id: ids for i, (_o, ids) in got.items()} == {"P": ["R"]}
        found = {i: (obs, tuple(float(x[0]) for x in deviations(p.active[i].trajectory, [obs.t_s],
                                                                 [obs.position_m])))
                 for i, (obs, _ids) in got.items()}
        steps = react_steps(50.0, 2, p.active, found, p.positions, p.config,
                            replan_selector(None, p.config, 2, 50.0), "mwis", p.network,
                            probed={i: ids for i, (_o, ids) in got.items()},
                            held=[[f.request_id for f in p.active].index("R")],
                            router=_Router(p.network, p.cache, (), 50.0) if reroute else None)
        out[reroute] = run_steps(steps, lambda _graph: SOLVE_HERE)
    _a, ups, rep = out[False]
    assert ups == [] and rep["probe_kept"] == 1
    _a, ups, rep = out[True]
    (u,) = ups
    assert u.request_id == "P" and u.kind == KIND and not u.flight.contingent
    assert "conflict probe" in u.reason and "rerouted to 'E'" in u.reason
    assert u.flight.route_node_ids == ("W", "m", "N", "E") and u.flight.destination_id == "E"
    assert rep["probe_rerouted"] == 1 and rep["probe_updates"] == 1
    new = u.flight.trajectory
    assert new.position_at(300.0) == pytest.approx([3000.0, 0.0, 0.0])
    assert new.position_at(600.0) == pytest.approx([3000.0, 3000.0, 0.0])
    assert new.arrival_s == pytest.approx(600.0 + 3000.0 * math.sqrt(2.0) / 10.0)
    a = audit_flights([new, R.trajectory], separation_m=100.0)
    assert a.losses == [] and a.min_separation_m == pytest.approx(300.0 * math.sqrt(2.0), rel=1e-3)
    # the planner's own path (its probe between epochs) re-routes it the same way
    p = Planner(net, PlanningConfig(conformance=CB(), conflict_probe_s=300.0), "mwis", solve_mwis=None)
    p.restore([P, R])
    for t in (40.0, 50.0):
        assert p.observe("P", t, P.trajectory.position_at(t)) is None
    (u2,) = p.react_between(50.0, 2)
    assert u2.flight.route_node_ids == ("W", "m", "N", "E")
    assert u2.flight.trajectory.arrival_s == pytest.approx(new.arrival_s)


def probe_batch_at_60(margin_m, fixed=(), fixed_ids=()):
    """P (6 s late at 60 s, 9 m/s) and Q2 as in probe_planner, a probe of 300 s with a margin of
    ``margin_m``: the batch of what it predicts at 60 s, solved here (``fixed``: traffic outside
    the planner's book). Returns (planner, active after, updates, report)."""
    from uam_planner.nonconformance import (ConformanceBounds as CB, deviations,
                                            predicted_conflicts, react_steps)
    from uam_planner.planning import replan_selector
    from uam_planner.replanning import SOLVE_HERE, run_steps

    cfg = PlanningConfig(conformance=CB(), conflict_probe_s=300.0, conflict_probe_margin_m=margin_m)
    p = Planner(cross(), cfg, "mwis", solve_mwis=None)
    p.restore([P, Q2])
    flown = fly(P.trajectory, FlightDraws(), HEAD_WIND)
    for t in (50.0, 60.0):
        assert p.observe("P", t, flown.position_at(t)) is None
        assert p.observe("Q2", t, Q2.trajectory.position_at(t)) is None
    got = predicted_conflicts(p.active, p.positions, 60.0, 300.0, cfg.probe_separation)
    found = {i: (obs, tuple(float(x[0]) for x in deviations(p.active[i].trajectory, [obs.t_s],
                                                             [obs.position_m])))
             for i, (obs, _ids) in got.items()}
    steps = react_steps(60.0, 2, p.active, found, p.positions, p.config,
                        replan_selector(None, p.config, 2, 60.0), "mwis", p.network,
                        fixed=list(fixed), fixed_ids=list(fixed_ids),
                        probed={i: ids for i, (_o, ids) in got.items()})
    active, ups, rep = run_steps(steps, lambda _graph: SOLVE_HERE)
    return p, active, ups, rep


def test_the_probes_margin_is_kept_from_the_batchs_flights_and_the_buffer_from_the_others():
    # fourteenth stop. P (6 s late at 60 s, 9 m/s) and Q2 as in probe_planner, a 50 m margin
    # (the batch's separation 150 m). T flies beside P's route, 120 m north of it, W -> E at
    # 10 m/s from 0 s (a held projection, fixed traffic): every alternative of P passes within
    # 150 m of T (at 60 s P is at x = 540, T at 600: 134.2 m; P's own plan keeps 120 m), none
    # within 100 m at first. Before, the batch kept every update 150 m from T as well: P had no
    # alternative and kept its plan. Now T, outside the batch, is kept at the planner's
    # separation (100 m, no buffer) and P is updated, 150 m clear of Q2
    T = Trajectory(np.array([0.0, 600.0]), np.array([[0.0, 120.0, 0.0], [6000.0, 120.0, 0.0]]))
    assert math.hypot(600.0 - 540.0, 120.0) == pytest.approx(134.16, abs=0.01)
    _p, active, ups, rep = probe_batch_at_60(50.0, fixed=[T], fixed_ids=["T"])
    new = {f.request_id: f.trajectory for f in active}
    assert "P" in [u.request_id for u in ups]
    assert new["P"].points_m[0] == pytest.approx([540.0, 0.0, 0.0])
    a = audit_flights([new["P"], T], separation_m=100.0)
    assert a.losses == [] and a.min_separation_m < 150.0
    assert audit_flights([new["P"], new["Q2"]], separation_m=150.0).losses == []


def test_a_probed_pair_nothing_parts_by_the_margin_takes_the_widest_berth_that_keeps_the_minimum():
    # fifteenth stop. P (6 s late at 60 s, 9 m/s) and Q2 as in probe_planner, projected 89.2 m
    # apart at m; a margin of 800 m: no re-timing of either keeps 900 m from the other, so the
    # solve leaves both keeping their plans (before: nothing else happened, and the pair flew
    # as projected, inside the true minimum; seed 14 of the Monte-Carlo did so at 86.5 m). Now
    # P takes, of its re-timings, the one whose closest approach to Q2's plan and projection is
    # the widest (its slowest re-join, 0.9 x 0.7 of its planned speed: 5460 m at 6.3 m/s, in at
    # 926.7 s), Q2 then keeps its plan, and the reason says how close it passes
    from uam_planner.nonconformance import SHARES, rejoin_trajectory
    from uam_planner.separation import min_separation_m

    p, _active, ups, rep = probe_batch_at_60(800.0)
    assert rep["probe_released"] == 2 and rep["probe_widest"] == 1
    (u,) = ups
    assert u.request_id == "P" and u.kind == KIND and not u.flight.contingent
    new = u.flight.trajectory
    assert new.points_m[0] == pytest.approx([540.0, 0.0, 0.0])
    assert new.arrival_s == pytest.approx(60.0 + 5460.0 / 6.3)
    gap = min_separation_m(new, Q2.trajectory)
    assert 100.0 < gap < 900.0
    assert f"the widest berth left: {gap:.1f} m" in u.reason and "nothing kept 900 m" in u.reason
    # every other re-join of P passes Q2 closer
    obs = p.positions.latest("P")
    for share in (1.0,) + SHARES[:-1]:
        other = rejoin_trajectory(P.trajectory, obs.t_s, obs.position_m, 0.9 * share)
        assert min_separation_m(other, Q2.trajectory) < gap
