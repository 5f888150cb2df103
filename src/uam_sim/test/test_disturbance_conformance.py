"""Disturbances, conformance monitoring, planning buffers and the audit of what flew (issue 23).

Every expected value is computed by hand in the comments."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uam_planner.planning import AirspaceConfig, PlanningConfig
from uam_planner.separation import SeparationModel
from uam_planner.trajectory import Trajectory
from uam_sim.world.conformance import (MAX_EXCURSION_S, MAX_EXCURSIONS_PER_FLIGHT_HOUR,
                                 MIN_CONFORMANCE_PERCENT, ConformanceBounds, ConformanceMonitor,
                                 deviations, f3548_statistics, track_conformance)
from uam_sim.world.disturbance import (DisturbanceConfig, FlightDraws, fly, fly_plans, flight_draws)
from uam_sim.runner.experiment_config import REPO_ROOT, ExperimentError, make_config
from uam_sim.audit.flown import flown_audit, tracks_from_samples

# east along y = 0 at z = 50 m, 1,000 m in 100 s (10 m/s)
PLAN = Trajectory(np.array([0.0, 100.0]), np.array([[0.0, 0.0, 50.0], [1000.0, 0.0, 50.0]]))


# ---- disturbance model ----------------------------------------------------------------------

def test_no_disturbance_flies_the_plan_itself():
    cfg = DisturbanceConfig()
    assert not cfg.enabled
    assert fly(PLAN, FlightDraws(), cfg) is PLAN
    assert fly_plans([PLAN], ["a"], DisturbanceConfig(seed=7, track_gain_per_s=0.5))[0] is PLAN


def test_tail_wind_makes_the_flight_early_and_nonconforming_at_the_right_step():
    # 2.5 m/s from the west (a tail wind), steady, compensated crab 0: ground speed 12.5 m/s, so
    # at t the aircraft is at x = 12.5 t, which the plan reaches at 1.25 t: time error -0.25 t.
    # |error| <= 10 s (inclusive) up to t = 40 s; the first nonconforming sample is t = 41 s.
    # It lands when x = 1000: t = 80 s exactly.
    cfg = DisturbanceConfig(wind_speed_mps=2.5, wind_from_deg=270.0)
    flown = fly(PLAN, FlightDraws(), cfg)
    assert flown.arrival_s == pytest.approx(80.0)
    assert flown.position_at(40.0) == pytest.approx([500.0, 0.0, 50.0])
    tc = track_conformance("a", PLAN, flown, ConformanceBounds(lateral_m=30, vertical_m=15, time_s=10))
    assert tc.time_err_s[40] == pytest.approx(-10.0) and tc.conforming[40]
    assert tc.first_nonconforming_s == 41.0
    ex = tc.excursions
    # nonconforming from 41 s to the landing sample at 80 s, errors up to 0.25 * 80 = 20 s
    assert len(ex) == 1 and ex[0].start_s == 41.0 and ex[0].end_s == pytest.approx(80.0)
    assert ex[0].max_time_s == pytest.approx(20.0) and ex[0].max_lateral_m == pytest.approx(0.0)


def test_cross_wind_drifts_within_the_guidance_and_is_flagged_at_the_right_step():
    # 3 m/s from the south, not compensated, gain k = 0.1/s: the offset north obeys d' = 3 - 0.1 d,
    # held over 1 s steps: d(n) = 30 (1 - exp(-0.1 n)) exactly. It passes 20 m when
    # exp(-0.1 n) < 1/3, n > 10 ln 3 = 10.99: first nonconforming sample at t = 11 s.
    cfg = DisturbanceConfig(wind_speed_mps=3.0, wind_from_deg=180.0, compensate_steady_wind=False)
    flown = fly(PLAN, FlightDraws(), cfg)
    n = np.arange(0, 12)
    assert flown.points_m[:12, 1] == pytest.approx(30.0 * (1.0 - np.exp(-0.1 * n)))
    assert flown.points_m[:12, 0] == pytest.approx(10.0 * n)    # a pure cross wind: on time
    tc = track_conformance("a", PLAN, flown, ConformanceBounds(lateral_m=20.0))
    assert tc.first_nonconforming_s == 11.0
    assert tc.conforming[:11].all() and not tc.conforming[11:].any()
    # the guidance bound: with max_lateral_m = 25 the offset never exceeds 25 m
    clipped = fly(PLAN, FlightDraws(), DisturbanceConfig(wind_speed_mps=3.0, wind_from_deg=180.0,
                                                         compensate_steady_wind=False, max_lateral_m=25.0))
    assert clipped.points_m[:, 1].max() == pytest.approx(25.0)


def test_speed_error_and_delay():
    # +10 % airspeed, no wind: 11 m/s, lands after 1000 / 11 s; 7 s late departure
    flown = fly(PLAN, FlightDraws(speed_error=0.1, delay_s=7.0), DisturbanceConfig(speed_error=0.1))
    assert flown.departure_s == 7.0
    assert flown.arrival_s == pytest.approx(7.0 + 1000.0 / 11.0)
    lat, ver, terr = deviations(PLAN, [7.0], [[0.0, 0.0, 50.0]])
    assert terr[0] == pytest.approx(7.0) and lat[0] == 0.0 and ver[0] == 0.0


def test_a_turn_back_flown_on_time_conforms_on_the_way_back():
    # A -> B -> A at 10 m/s (a turn-back diversion flies back the way it came): at 150 s the
    # aircraft is at x = 500 on the way back, exactly on plan. Both passes are 0 m away; the one
    # meant is the return (planned 150 s), not the outbound (planned 50 s: "100 s late").
    back = Trajectory(np.array([0.0, 100.0, 200.0]),
                      np.array([[0.0, 0.0, 50.0], [1000.0, 0.0, 50.0], [0.0, 0.0, 50.0]]))
    lat, ver, terr = deviations(back, [50.0, 150.0, 160.0], [[500.0, 0.0, 50.0], [500.0, 0.0, 50.0],
                                                             [400.0, 5.0, 50.0]])
    assert list(terr) == pytest.approx([0.0, 0.0, 0.0]) and list(lat) == pytest.approx([0.0, 0.0, 5.0])
    # a late aircraft on the outbound leg is still read as late, not as early on the return
    _lat, _ver, late = deviations(back, [70.0], [[500.0, 0.0, 50.0]])
    assert late[0] == pytest.approx(20.0)
    t = np.arange(0.0, 201.0)
    pts = np.stack([np.where(t <= 100.0, 10.0 * t, 2000.0 - 10.0 * t), np.zeros_like(t),
                    np.full_like(t, 50.0)], axis=1)
    tc = track_conformance("a", back, Trajectory(t, pts), ConformanceBounds())
    assert tc.conforming.all() and tc.first_nonconforming_s is None


def test_a_turn_back_whose_passes_lie_metres_apart_is_matched_to_the_pass_at_the_right_time():
    # fifteenth stop (seed 12 of the Monte-Carlo at 15 m): a diversion along the way it came
    # starts where the aircraft was, a few metres off the corridor, so the outbound pass runs
    # (0, 4) -> (1000, 0) and the return (1000, 0) -> (0, 0) at 10 m/s (planned at x = 500:
    # 50.0 s out, 150.0 s back). At 150 s the aircraft flies the return on time, 1.8 m to the
    # side of it: (500, 1.8). The outbound pass is nearer (0.2 m: it is at y = 2 there) but
    # 100 s off; before, a pass was considered only within 1 m of the nearest, so it was read
    # 100 s late
    back = Trajectory(np.array([0.0, 100.0, 200.0]),
                      np.array([[0.0, 4.0, 50.0], [1000.0, 0.0, 50.0], [0.0, 0.0, 50.0]]))
    lat, _ver, terr = deviations(back, [150.0, 50.0], [[500.0, 1.8, 50.0], [500.0, 2.0, 50.0]])
    assert terr[0] == pytest.approx(0.0, abs=1e-9) and lat[0] == pytest.approx(1.8)
    # on the way out at 50 s, on the outbound pass: matched to it (0 s, 0 m), not to the return
    assert terr[1] == pytest.approx(0.0, abs=1e-6) and lat[1] == pytest.approx(0.0, abs=1e-3)
    # late on the way out by 20 s (at 70 s at x = 500), it is read as 20 s late on the outbound
    # pass (max(0 / 30, 20 / 10) = 2), not 80 s early on the return (max(2 / 30, 80 / 10) = 8)
    _lat, _ver, late = deviations(back, [70.0], [[500.0, 2.0, 50.0]])
    assert late[0] == pytest.approx(20.0, abs=1e-6)
    tc = track_conformance("a", back, Trajectory(np.array([100.0, 150.0, 200.0]),
                                                 np.array([[1000.0, 0.0, 50.0], [500.0, 1.8, 50.0],
                                                           [0.0, 0.0, 50.0]])), ConformanceBounds())
    assert tc.conforming.all()


def test_draws_are_seeded_per_flight_and_within_bounds():
    cfg = DisturbanceConfig(speed_error=0.1, delay_mean_s=20.0, delay_max_s=30.0, seed=3)
    a = [flight_draws(cfg, f"r{i}") for i in range(200)]
    assert a == [flight_draws(cfg, f"r{i}") for i in range(200)]      # deterministic
    assert flight_draws(cfg, "r5") == a[5]                             # not order dependent
    assert all(-0.1 <= d.speed_error <= 0.1 and 0.0 <= d.delay_s <= 30.0 for d in a)
    assert len({d.speed_error for d in a}) == 200
    other = DisturbanceConfig(speed_error=0.1, delay_mean_s=20.0, delay_max_s=30.0, seed=4)
    assert flight_draws(other, "r5") != a[5]


def test_every_effect_draws_in_registration_order_from_one_generator():
    # the speed error's uniform u, the delay's exponential x, the altitude error's uniform z, in
    # that order from the flight's generator, whatever the levels
    import zlib
    cfg = DisturbanceConfig(speed_error=0.1, delay_mean_s=20.0, delay_max_s=30.0, altitude_error_m=5.0, seed=3)
    rng = np.random.default_rng([3, zlib.crc32(b"r7")])
    u, x, z = rng.uniform(-1.0, 1.0), rng.exponential(1.0), rng.uniform(-1.0, 1.0)
    assert flight_draws(cfg, "r7") == FlightDraws(float(u * 0.1), float(min(x * 20.0, 30.0)), float(z * 5.0))
    assert flight_draws(DisturbanceConfig(altitude_error_m=5.0, seed=3), "r7") == FlightDraws(0.0, 0.0, float(z * 5.0))


def test_the_launchers_rule_is_the_registry_of_the_built_in_effects():
    # uam_contract.disturbances (run_fleet.sh and the launch file read it) does not import the
    # simulator: its levels are the built-in effects' levels, in their registration order
    from uam_contract.disturbances import LEVELS, disturbances_on
    from uam_sim.world.disturbance import BUILTIN_EFFECTS, effects

    built_in = [e for e in effects() if e.name in BUILTIN_EFFECTS]
    assert [e.name for e in built_in] == list(BUILTIN_EFFECTS)
    assert tuple(level for e in built_in for level in e.levels) == LEVELS
    assert not DisturbanceConfig().enabled and not disturbances_on(*[0] * len(LEVELS))
    for i, level in enumerate(LEVELS):
        levels = [0.0] * len(LEVELS)
        levels[i] = 0.05
        assert disturbances_on(*levels) and DisturbanceConfig(**{level: 0.05}).enabled, level
    # the along-track guidance has no level: alone it flies the plan exactly
    assert not DisturbanceConfig(time_gain_per_s=0.1).enabled


def test_gusts_are_seeded_and_have_the_stated_spread():
    from uam_sim.world.disturbance import WindField
    cfg = DisturbanceConfig(gust_std_mps=2.0, seed=1)
    w = WindField(cfg)
    xy = np.random.default_rng(0).uniform(-20000, 20000, size=(20000, 2))
    g = w.gust(xy, np.random.default_rng(1).uniform(0, 3600, 20000))
    assert np.allclose(g, WindField(cfg).gust(xy, 0.0 * 0 + np.random.default_rng(1).uniform(0, 3600, 20000)))
    # each component: 8 cosines of amplitude 2 sqrt(2/8) = 1 with random phases: std 2
    assert g.std(axis=0) == pytest.approx([2.0, 2.0], rel=0.1)


def test_bad_disturbance_names_the_field():
    with pytest.raises(ValueError, match=r"speed_error: -0.1 must be >= 0"):
        DisturbanceConfig(speed_error=-0.1)
    # the simulator node's bound, in the node's words (uam_contract.defaults.SPEED_ERROR_MAX)
    with pytest.raises(ValueError, match=r"speed_error: 0.795 is above the maximum 0.79"):
        DisturbanceConfig(speed_error=0.795)
    with pytest.raises(ValueError, match=r"step_s: 0 must be > 0"):
        DisturbanceConfig(step_s=0)
    with pytest.raises(ValueError, match=r"unknown field 'wind'"):
        DisturbanceConfig.from_mapping({"wind": 3})
    with pytest.raises(ExperimentError, match=r"disturbance.gust_std_mps: nan"):
        make_config({"disturbance": {"gust_std_mps": float("nan")}})
    with pytest.raises(ExperimentError, match=r"spatial_buffer_m must be finite and >= 0, got -1"):
        make_config({"spatial_buffer_m": -1.0})


# ---- conformance ----------------------------------------------------------------------------

def test_deviations_by_hand():
    # at t = 30 s at (250, 40, 45): nearest plan point (250, 0, 50), planned at 25 s
    lat, ver, terr = deviations(PLAN, [30.0], [[250.0, 40.0, 45.0]])
    assert lat[0] == pytest.approx(40.0) and ver[0] == pytest.approx(-5.0) and terr[0] == pytest.approx(5.0)
    # a corner: plan climbs 0 -> 60 m at (0, 0) in 12 s, then east; point (-3, 4, 30) at t = 6
    climb = Trajectory(np.array([0.0, 12.0, 112.0]),
                       np.array([[0.0, 0.0, 0.0], [0.0, 0.0, 60.0], [1000.0, 0.0, 60.0]]))
    lat, ver, terr = deviations(climb, [6.0], [[-3.0, 4.0, 30.0]])
    assert lat[0] == pytest.approx(5.0) and ver[0] == pytest.approx(0.0) and terr[0] == pytest.approx(0.0)


def test_f3548_statistics_by_hand():
    # flight a: 0..100 s, nonconforming at samples 20..24 (5 s) and 60..74 (15 s): 80 % in
    # conformance, 2 excursions; flight b: 0..100 s, always conforming.
    t = np.arange(0.0, 101.0)
    pts = PLAN.position_at(t).copy()
    bad = ((t >= 20) & (t < 25)) | ((t >= 60) & (t < 75))
    pts[bad, 1] = 100.0
    flown_a = Trajectory(t, pts)
    ta = track_conformance("a", PLAN, flown_a, ConformanceBounds())
    tb = track_conformance("b", PLAN, PLAN, ConformanceBounds(), step_s=1.0)
    assert [(e.start_s, e.end_s) for e in ta.excursions] == [(20.0, 25.0), (60.0, 75.0)]
    st = f3548_statistics([ta, tb])
    # 200 s of flight, 180 s conforming (the 20 nonconforming samples count 1 s each)
    assert st.flight_hours == pytest.approx(200.0 / 3600.0)
    assert st.conformance_percent == pytest.approx(90.0)
    assert st.excursions == 2 and st.excursions_per_flight_hour == pytest.approx(2 * 18.0)
    assert st.longest_excursion_s == 15.0 and st.nonconforming_flights == 1
    assert not st.meets_time and not st.meets_rate and not st.meets_duration
    assert (MIN_CONFORMANCE_PERCENT, MAX_EXCURSIONS_PER_FLIGHT_HOUR, MAX_EXCURSION_S) == (95.0, 18.0, 10.0)
    # the streaming monitor sees the same
    mon = ConformanceMonitor(ConformanceBounds())
    mon.set_plan("a", PLAN)
    states = [mon.update(float(ti), ["a", "x"], [p, p])[0] for ti, p in zip(t, pts)]
    assert [s.conforming for s in states] == list(~bad)
    assert states[22].excursion_start_s == 20.0
    assert [(e.start_s, e.end_s) for e in mon.excursions] == [(20.0, 25.0), (60.0, 75.0)]
    assert mon.statistics().conformance_percent == pytest.approx(80.0)


# ---- planning buffers -----------------------------------------------------------------------

def test_buffer_zero_is_the_minimum_and_the_widened_separation_by_hand():
    cfg = PlanningConfig()
    assert cfg.separation == cfg.minimum_separation == SeparationModel("sphere", 100.0, 30.0)
    b = PlanningConfig(spatial_buffer_m=10.0, temporal_buffer_s=5.0)
    # sphere: 100 + 10 + max(10, 5, 3) m/s x 5 s = 160 m; the minimum stays 100 m
    assert b.separation.separation_m == 160.0 and b.minimum_separation.separation_m == 100.0
    cyl = PlanningConfig(spatial_buffer_m=10.0, temporal_buffer_s=5.0,
                         airspace=AirspaceConfig(separation_model="cylinder"))
    # cylinder: H = 100 + 10 + 10 x 5 = 160 m, V = 30 + max(5, 3) x 5 = 55 m
    assert cyl.separation == SeparationModel("cylinder", 160.0, 55.0)


def test_the_temporal_buffer_bound_holds():
    # two plans that keep S' = S + b + v tau at every common time keep S + b between any two of
    # their times tau apart (inside the common interval): checked on a dense grid of time pairs
    S, b, tau, v = 100.0, 10.0, 5.0, 10.0
    rng = np.random.default_rng(0)
    checked = 0
    for _ in range(40):
        pa = np.cumsum(rng.uniform(-1, 1, (6, 3)) * [400, 400, 0], axis=0) + [0, 0, 50]
        pb = np.cumsum(rng.uniform(-1, 1, (6, 3)) * [400, 400, 0], axis=0) + [0, 0, 50]
        from uam_planner.trajectory import trajectory_from_points
        a, bb = trajectory_from_points(pa, 0.0, v), trajectory_from_points(pb, 0.0, v)
        end = min(a.arrival_s, bb.arrival_s)
        ts = np.arange(0.0, end, 0.25)
        if ts.size < 10:
            continue
        same = np.linalg.norm(a.position_at(ts) - bb.position_at(ts), axis=1)
        if same.min() < S + b + v * tau:
            continue  # the planner would not approve this pair
        for dt in np.arange(-tau, tau + 1e-9, 0.25):
            t2 = np.clip(ts + dt, 0.0, end)
            d = np.linalg.norm(a.position_at(ts) - bb.position_at(t2), axis=1)
            assert d.min() >= S + b - 1e-9
            checked += 1
    assert checked > 100


# ---- the audit of what flew -----------------------------------------------------------------

def test_flown_closest_approach_on_hand_tracks():
    # A east along y = 0 at 10 m/s from x = 0 at t = 0, sampled at 0, 5, 20 s;
    # B west along y = 30 at 10 m/s from x = 200 at t = 0, sampled at 0, 10, 20 s.
    # Closest at t = 10 s (both at x = 100): 30 m, between A's samples 5 and 20.
    a = (np.array([0.0, 5.0, 20.0]), np.array([[0, 0, 50], [50, 0, 50], [200, 0, 50.0]]))
    b = (np.array([0.0, 10.0, 20.0]), np.array([[200, 30, 50], [100, 30, 50], [0, 30, 50.0]]))
    samples = sorted([(t, ["a"], [p]) for t, p in zip(*a)] + [(t, ["b"], [p]) for t, p in zip(*b)],
                     key=lambda s: s[0])
    tracks = tracks_from_samples(samples)
    res = flown_audit(tracks, 100.0, sample_step_s=15.0)
    assert res["what"] == "flown" and res["losses"] == 1
    assert res["min_separation_m"] == pytest.approx(30.0) and res["min_time_s"] == pytest.approx(10.0)
    # sampling bound: largest speed 10 m/s x the 15 s step = 150 m
    assert res["sampling_bound_m"] == pytest.approx(150.0) and res["possible_losses"] == 1
    # B 130 m away instead: no loss by interpolation, but a possible loss within the bound
    far = {"a": tracks["a"], "b": Trajectory(b[0], b[1] + [0, 100, 0])}
    res = flown_audit(far, 100.0, sample_step_s=15.0)
    assert res["losses"] == 0 and res["possible_losses"] == 1
    assert res["min_separation_m"] == pytest.approx(130.0)
    # per piece and axis (no plans: the ball of the largest speed): A's 15 s piece 10 x 15 / 2 =
    # 75 m, B's 10 s pieces 50 m, so the pair's bound is 125 m: 230 m away is cleared
    farther = {"a": tracks["a"], "b": Trajectory(b[0], b[1] + [0, 200, 0])}
    assert flown_audit(farther, 100.0, sample_step_s=15.0)["possible_losses"] == 0
    assert flown_audit(far, 100.0, sample_step_s=15.0)["possible_loss_pairs"][0][:2] == ["a", "b"]


def test_a_flown_loss_is_placed_near_a_shared_vertiport_or_en_route():
    from uam_sim.runner.scenario import VERTIPORT_AREA_M, near_shared_vertiport
    # A lands at the vertiport V = (0, 0): from (1000, 0) at t = 0 to V at t = 100 (10 m/s),
    # its flown track ending 15 m off V (drift). B departs V at t = 90 northwards at 10 m/s:
    # at t = 95 A is at x = 50 (about), B at y = 50, both within 200 m of V, which both plans
    # use: near the vertiport.
    a = Trajectory(np.array([0.0, 100.0]), np.array([[1000.0, 0, 0], [0.0, 15, 0]]))
    b = Trajectory(np.array([90.0, 190.0]), np.array([[0.0, 0, 0], [0.0, 1000, 0]]))
    ends_a, ends_b = [(1000.0, 0.0), (0.0, 0.0)], [(0.0, 0.0), (0.0, 1000.0)]
    assert VERTIPORT_AREA_M == 200.0
    assert near_shared_vertiport(a, b, 95.0, VERTIPORT_AREA_M, ends_a, ends_b)
    # the flown end points alone (15 m apart) would not tell: the plans' ends are what count
    assert not near_shared_vertiport(a, b, 95.0, VERTIPORT_AREA_M, [(0.0, 15.0)], ends_b)
    # at t = 60 A is 400 m out (B not yet flying: clamped at V): not near
    assert not near_shared_vertiport(a, b, 60.0, VERTIPORT_AREA_M, ends_a, ends_b)
    # C flies past V's area between vertiports of its own: en route
    c = Trajectory(np.array([0.0, 100.0]), np.array([[-500.0, 50, 0], [500.0, 50, 0]]))
    assert not near_shared_vertiport(a, c, 95.0, VERTIPORT_AREA_M, ends_a,
                                     [(-500.0, 50.0), (500.0, 50.0)])


def test_a_kinked_flown_track_is_interpolated_linearly():
    # A hovers at the origin; B flies (300, -300) -> (40, 0) -> (300, 300) in 20 s (samples 0,
    # 10, 20): its linear pieces pass closest to A at the kink, 40 m at t = 10 s.
    a = Trajectory(np.array([0.0, 20.0]), np.array([[0, 0, 50], [0, 0, 50.0]]))
    b = Trajectory(np.array([0.0, 10.0, 20.0]), np.array([[300, -300, 50], [40, 0, 50], [300, 300, 50.0]]))
    res = flown_audit({"a": a, "b": b}, 100.0)
    assert res["min_separation_m"] == pytest.approx(40.0) and res["min_time_s"] == pytest.approx(10.0)
    assert res["sampling_bound_m"] == 0.0


# ---- through the in-process runner ---------------------------------------------------------

TINY = str(REPO_ROOT / "config" / "networks" / "tiny.yaml")


def test_zero_disturbance_and_zero_buffers_give_todays_results_bit_for_bit():
    from uam_sim.runner.scenario import run_scenario
    from uam_planner.network import load_network
    net = load_network(TINY)
    # first-fit: the same planner, no solver worker processes (this test stays in make test-fast)
    base = make_config({"network": TINY, "methods": ["firstfit"], "duration_s": 300.0})
    zero = make_config({"network": TINY, "methods": ["firstfit"], "duration_s": 300.0,
                        "disturbance": {"track_gain_per_s": 0.3}, "spatial_buffer_m": 0.0,
                        "temporal_buffer_s": 0.0})
    r0 = run_scenario(net, "firstfit", 4, 1, 300.0, base)
    r1 = run_scenario(net, "firstfit", 4, 1, 300.0, zero)
    assert r0.flights == r1.flights and r0.audit == r1.audit and r0.decisions() == r1.decisions()
    assert len(r0.flights) > 3
    # what flew is the plan: the flown audit equals the plans' audit, every flight conforming
    assert r1.summary["flown_losses"] == 0 == r0.summary["losses"]
    assert r1.summary["flown_min_separation_m"] == r0.summary["min_separation_m"]
    assert r1.summary["conf_conformance_percent"] == 100.0 and r1.summary["conf_excursions"] == 0
    assert "flown_losses" not in r0.summary


def test_disturbed_run_is_seeded_and_reports_what_flew():
    from uam_sim.runner.scenario import run_scenario
    from uam_planner.network import load_network
    net = load_network(TINY)
    cfg = make_config({"network": TINY, "methods": ["firstfit"], "duration_s": 300.0,
                       "disturbance": {"speed_error": 0.1, "gust_std_mps": 1.5, "delay_mean_s": 5.0}})
    r1 = run_scenario(net, "firstfit", 4, 1, 300.0, cfg)
    r2 = run_scenario(net, "firstfit", 4, 1, 300.0, cfg)
    keys = [k for k in r1.summary if k.startswith(("conf_", "flown_"))]
    assert keys and {k: r1.summary[k] for k in keys} == {k: r2.summary[k] for k in keys}
    assert r1.summary["conf_conformance_percent"] < 100.0


def test_time_control_holds_a_slow_aircraft_near_its_plan():
    # -10 % airspeed, time gain 0.05/s, correction up to 20 %: the steady lag L solves
    # 0.9 (10 + 0.05 L) = 10, L = 10 / 0.9 / 0.05 - 200 = 22.2 m (2.2 s): conforming throughout,
    # whereas without time control it is at 9 t, which the plan reached at 0.9 t: 0.1 t late,
    # 10 s at t = 100 s (still conforming, inclusive), first nonconforming sample t = 101 s
    long = Trajectory(np.array([0.0, 1000.0]), np.array([[0.0, 0.0, 50.0], [10000.0, 0.0, 50.0]]))
    cfg = DisturbanceConfig(speed_error=0.1, time_gain_per_s=0.05, max_speed_adjust=0.2)
    flown = fly(long, FlightDraws(speed_error=-0.1), cfg)
    tc = track_conformance("a", long, flown, ConformanceBounds())
    assert tc.conforming.all()
    assert tc.time_err_s[500] == pytest.approx((10.0 / 0.9 / 0.05 - 200.0) / 10.0, abs=0.01)
    free = fly(long, FlightDraws(speed_error=-0.1), DisturbanceConfig(speed_error=0.1))
    assert track_conformance("a", long, free, ConformanceBounds()).first_nonconforming_s == pytest.approx(101.0)


def test_montecarlo_aggregates_a_point_by_hand():
    from uam_sim.studies.experiment import key_values
    from uam_sim.studies.montecarlo import aggregate
    assert key_values("speed_error=0.1, compensate_steady_wind=false") == {
        "speed_error": 0.1, "compensate_steady_wind": False}
    # two runs: 10 + 30 flight hours at 90 % and 100 %: flight-time weighted 97.5 %;
    # 2 + 6 excursions over 40 h: 0.2 per hour; approvals 30 of 40 + 50 of 60 = 80 %
    a = {"requests": 40, "approved": 30, "conf_flight_hours": 10.0, "conf_conformance_percent": 90.0,
         "conf_excursions": 2, "conf_longest_excursion_s": 12.0, "conf_nonconforming_flights": 2,
         "replans": 0, "flown_losses": 1, "flown_min_separation_m": 80.0, "losses": 0}
    b = {"requests": 60, "approved": 50, "conf_flight_hours": 30.0, "conf_conformance_percent": 100.0,
         "conf_excursions": 6, "conf_longest_excursion_s": 4.0, "conf_nonconforming_flights": 3,
         "replans": 0, "flown_losses": 0, "flown_min_separation_m": 120.0, "losses": 0}
    row = aggregate((0.1, 25.0, 5.0), [{"summary": a}, {"summary": b}])
    assert row["approval_rate"] == pytest.approx(0.8) and row["conformance_percent"] == pytest.approx(97.5)
    assert row["excursions_per_flight_hour"] == pytest.approx(0.2) and row["longest_excursion_s"] == 12.0
    assert row["flown_losses"] == 1 and row["flown_min_separation_m"] == 80.0 and row["flights"] == 80
    # the approval rate over two runs, 0.75 and 0.8333: Student's t with 1 degree of freedom
    # (12.706) would give 26.2-132.1 %, no interval to speak of: none below 3 runs
    assert math.isnan(row["approval_ci95_low"]) and math.isnan(row["approval_ci95_high"])
    # three runs, 0.75, 0.8333 and 1.0: mean 0.8611, sd 0.1273, t(2) = 4.303: 0.8611 -+ 0.3162,
    # the upper end within the share's bound 1
    c = dict(b, requests=20, approved=20)
    row3 = aggregate((0.1, 25.0, 5.0), [{"summary": a}, {"summary": b}, {"summary": c}])
    assert row3["approval_ci95_low"] == pytest.approx(0.8611 - 0.3162, abs=1e-3)
    assert row3["approval_ci95_high"] == 1.0
    # 1 flown loss in 80 flights: the exact Poisson bound chi2(0.95, 4) / 2 / 80 = 9.4877 / 160
    assert row["flown_losses_per_flight_upper95"] == pytest.approx(9.4877 / 160.0, rel=1e-4)
    from uam_sim.studies.montecarlo import format_table, poisson_upper95, spread_ci95
    assert poisson_upper95(0, 1000) == pytest.approx(2.9957 / 1000.0, rel=1e-4)   # the rule of three
    assert all(math.isnan(x) for x in spread_ci95([0.5]))
    assert "54.5-100.0 %" in format_table([row3]) and "| - |" in format_table([row])
    assert "0.0593" in format_table([row])


def test_the_planner_keeps_the_buffered_separation_and_the_audit_the_minimum():
    from uam_planner.network import load_network
    from uam_sim.audit.separation import sweep_audit
    from uam_sim.runner.scenario import run_scenario
    net = load_network(TINY)
    got = {}
    for b in (0.0, 60.0):
        trajs = []
        cfg = make_config({"network": TINY, "methods": ["firstfit"], "duration_s": 600.0,
                           "spatial_buffer_m": b})
        assert cfg.separation().separation_m == 100.0          # the audit's minimum, never buffered
        res = run_scenario(net, "firstfit", 6, 2, 600.0, cfg,
                           observer=lambda t, e, s, r, out: trajs.extend(f.trajectory for f in out.approved))
        got[b] = (len(trajs), sweep_audit(trajs, 160.0))
        assert res.summary["losses"] == 0
    # with the buffer no two plans come within 100 + 60 m; without it some do (the count of
    # approvals need not fall: first-fit's later choices change too)
    assert got[60.0][1]["losses"] == 0 and got[0.0][1]["losses"] > 0
    assert got[60.0][0] > 0


# ---- vertical disturbances --------------------------------------------------------------------

def test_an_altitude_hold_error_is_flagged_by_the_vertical_bound_at_the_right_step():
    # a flight that holds 20 m above its plan (altitude-hold gain 0.1 /s, from 0 at departure):
    # h(t) = 20 (1 - exp(-0.1 t)) exactly at the samples (the exact integration); over the
    # vertical bound of 15 m from t = 10 ln 4 = 13.86 s, so the first nonconforming sample is
    # t = 14 s (h = 15.07 m; h(13) = 14.55 m); lateral and time errors stay 0
    cfg = DisturbanceConfig(altitude_error_m=20.0, altitude_gain_per_s=0.1)
    assert cfg.enabled and cfg.vertical
    flown = fly(PLAN, FlightDraws(altitude_offset_m=20.0), cfg)
    t = flown.times_s
    assert flown.points_m[:, 2] - 50.0 == pytest.approx(20.0 * (1.0 - np.exp(-0.1 * t)), abs=1e-9)
    tc = track_conformance("a", PLAN, flown, ConformanceBounds(lateral_m=30, vertical_m=15, time_s=10))
    assert tc.first_nonconforming_s == pytest.approx(14.0)
    assert np.abs(tc.lateral_m).max() < 1e-9 and np.abs(tc.time_err_s).max() < 1e-9
    (ex,) = tc.excursions
    assert ex.max_vertical_m == pytest.approx(20.0 * (1.0 - math.exp(-0.1 * 100.0)), abs=1e-6)
    # below: the same, 20 m under the plan; clipped at max_vertical_m
    low = fly(PLAN, FlightDraws(altitude_offset_m=-40.0), cfg)
    assert low.points_m[:, 2].min() == pytest.approx(50.0 - 30.0)


def test_vertical_disturbances_leave_the_horizontal_track_and_draws_unchanged():
    # the vertical field and the altitude error have their own streams: with them on, the
    # horizontal track and the speed error and delay of every flight are those without them,
    # bit for bit, and without them the height is the plan's exactly
    base = DisturbanceConfig(speed_error=0.1, gust_std_mps=1.5, delay_mean_s=10.0, seed=3)
    vert = DisturbanceConfig(speed_error=0.1, gust_std_mps=1.5, delay_mean_s=10.0, seed=3,
                             vertical_gust_std_mps=1.0, altitude_error_m=10.0)
    ids = [f"r{i}" for i in range(20)]
    for i in ids:
        a, b = flight_draws(base, i), flight_draws(vert, i)
        assert (a.speed_error, a.delay_s) == (b.speed_error, b.delay_s)
        assert a.altitude_offset_m == 0.0 and -10.0 <= b.altitude_offset_m <= 10.0
    plans = [PLAN] * len(ids)
    fa, fb = fly_plans(plans, ids, base), fly_plans(plans, ids, vert)
    for x, y in zip(fa, fb):
        assert np.array_equal(x.times_s, y.times_s)
        assert np.array_equal(x.points_m[:, :2], y.points_m[:, :2])
        assert np.array_equal(x.points_m[:, 2], np.full(x.times_s.shape, 50.0))
    assert max(np.abs(y.points_m[:, 2] - 50.0).max() for y in fb) > 1.0


def test_vertical_gusts_are_seeded_and_have_the_stated_spread():
    from uam_sim.world.disturbance import WindField
    cfg = DisturbanceConfig(vertical_gust_std_mps=0.5, seed=2)
    xy = np.random.default_rng(0).uniform(-20000, 20000, size=(20000, 2))
    t = np.random.default_rng(1).uniform(0, 3600, 20000)
    w = WindField(cfg).vertical(xy, t)
    assert np.array_equal(w, WindField(cfg).vertical(xy, t))
    # 8 cosines of amplitude 0.5 sqrt(2/8) = 0.25: std 0.5
    assert w.std() == pytest.approx(0.5, rel=0.1)
    # the horizontal gusts are the same with or without the vertical ones
    h = DisturbanceConfig(gust_std_mps=1.0, seed=2)
    hv = DisturbanceConfig(gust_std_mps=1.0, seed=2, vertical_gust_std_mps=0.5)
    assert np.array_equal(WindField(h).gust(xy, t), WindField(hv).gust(xy, t))


def test_montecarlo_existing_only_runs_nothing(tmp_path, capsys):
    # --existing-only: the table of the cells already in --out; with none there, no row and no run
    from uam_sim.studies.montecarlo import main
    assert main(["--speed-errors", "0.1", "--spatial-buffers", "0,10", "--temporal-buffers", "0",
                 "--seeds", "3", "--out", str(tmp_path), "--existing-only"]) == 0
    assert list((tmp_path / "cells").iterdir()) == []
    assert (tmp_path / "montecarlo.csv").read_text().count("\n") == 1   # the header only
    assert "0 points" in capsys.readouterr().out
