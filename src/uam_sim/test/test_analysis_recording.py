"""Analysis of a synthetic recording: hand-counted outcomes, a hand-computed closest approach."""

from __future__ import annotations

import json
import math

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from rclpy.qos import DurabilityPolicy, QoSProfile  # noqa: E402
from uam_msgs.msg import (FleetState, FlightPlan, FlightRequest, MwisInstance,  # noqa: E402
                          PlanningReport, VehicleState, Waypoint)

from uam_sim.audit.analysis import format_summary, main, summarize  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402
from run_frame import complete_run  # noqa: E402
from uam_sim.recording.recorded_instances import instances_from_mcap, recorded_instances  # noqa: E402

NS = 1_000_000_000


def t(sec: float) -> Time:
    return Time(sec=int(sec), nanosec=int(round((sec - int(sec)) * 1e9)))


def plan(rid: str, outcome: int, wps=(), reason: str = "", stamp: float = 0.0) -> FlightPlan:
    p = FlightPlan(request_id=rid, outcome=outcome, reason=reason,
                   waypoints=[Waypoint(position=Point(x=float(x), y=float(y), z=float(z)), time=t(ts))
                              for ts, x, y, z in wps])
    p.header.stamp = t(stamp)
    return p


# Flights (time s, east m, north m, up m):
#   r1 flies east at 10 m/s, z = 100: (10 t, 0, 100)
#   r2 flies north at 10 m/s, z = 150, in two segments: (500, -500 + 10 t, 150)
#   r3 flies east 5 km north of r1
# r1 - r2: |d|^2 = 2 (10 t - 500)^2 + 50^2, so the closest approach is 50 m at t = 50 s.
FLIGHTS = {
    "r1": [(0, 0, 0, 100), (100, 1000, 0, 100)],
    "r2": [(0, 500, -500, 150), (50, 500, 0, 150), (100, 500, 500, 150)],
    "r3": [(0, 0, 5000, 100), (100, 1000, 5000, 100)],
}


def _on_plan(rid, t_s):
    """Where ``rid``'s plan has it at ``t_s`` (the fleet flies its plans)."""
    import numpy as np
    from geometry_msgs.msg import Point

    times = [w[0] for w in FLIGHTS[rid]]
    x, y, z = (float(np.interp(t_s, times, [w[k] for w in FLIGHTS[rid]])) for k in (1, 2, 3))
    return Point(x=x, y=y, z=z)


@pytest.fixture(scope="module")
def recording(tmp_path_factory):
    path = tmp_path_factory.mktemp("an") / "synthetic.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/uam/requests", FlightRequest)
        rec.add_topic("/uam/flight_plans", FlightPlan,
                      QoSProfile(depth=1000, durability=DurabilityPolicy.TRANSIENT_LOCAL))
        rec.add_topic("/uam/planning_reports", PlanningReport)
        rec.add_topic("/uam/fleet_state", FleetState)
        for i in range(1, 7):  # r1..r6
            rec.write("/uam/requests", FlightRequest(request_id=f"r{i}", request_time=t(0)), 0)
        for rid, wps in FLIGHTS.items():
            rec.write("/uam/flight_plans", plan(rid, FlightPlan.OUTCOME_APPROVED, wps), 0)
        rec.write("/uam/flight_plans", plan("r4", FlightPlan.OUTCOME_REJECTED, reason="unknown aerodrome 'Z'"), 0)
        rec.write("/uam/flight_plans", plan("r5", FlightPlan.OUTCOME_EXPIRED, reason="no slot"), 0)
        rec.write("/uam/flight_plans", plan("r1", FlightPlan.OUTCOME_APPROVED, FLIGHTS["r1"]), 1)  # a repeat
        # r6 has no plan: undecided
        report = PlanningReport(epoch_index=0, vertices=4, edges=4, approved=3, solve_time_s=0.004,
                                backend_used="exact",
                                instance=MwisInstance(weights=[1.0, 0.8, 0.5, 1.0], edges_u=[0, 0, 1, 2],
                                                      edges_v=[1, 2, 2, 3],
                                                      vertex_request_ids=["r1", "r1", "r1", "r2"],
                                                      vertex_candidate_index=[0, 1, 2, 0], selected=[0, 3]))
        rec.write("/uam/planning_reports", report, 0)
        empty = PlanningReport(epoch_index=1, solve_time_s=0.0, fallback=True, backend_used="greedy")
        empty.header.stamp = t(30)
        rec.write("/uam/planning_reports", empty, 30 * NS)
        # fleet states at t = 0..4 s with 3, 3, 2, 2, 0 vehicles: time-average over [0, 4] = 2.5
        for k, n in enumerate([3, 3, 2, 2, 0]):
            fs = FleetState(step_index=k, vehicles=[VehicleState(vehicle_id=f"r{j + 1}", position=_on_plan(f"r{j + 1}", k))
                                                    for j in range(n)])
            fs.header.stamp = t(k)
            rec.write("/uam/fleet_state", fs, k * NS)
        complete_run(rec, epochs=2)
    return path


def test_counts_and_average_active_aircraft(recording):
    s = summarize(recording)
    assert (s.requests, s.approved, s.rejected, s.expired, s.undecided) == (6, 3, 1, 1, 1)
    assert s.duplicate_decisions == 1 and s.plans_without_request == 0
    assert s.average_active_aircraft == pytest.approx(2.5)
    assert s.max_active_aircraft == 3 and s.fleet_steps == 5
    assert [e.epoch_index for e in s.epochs] == [0, 1]
    assert s.epochs[0].selected == 2 and s.epochs[1].fallback
    assert s.mwis_vertices["count"] == 1 and s.mwis_vertices["max"] == 4  # empty epochs left out
    assert s.solve_time_s["median"] == pytest.approx(0.004)
    assert s.fallbacks == 1
    assert s.rejection_reasons == {"unknown aerodrome 'Z'": 1, "no slot": 1}


def test_safety_audit_finds_the_hand_computed_closest_approach(recording):
    s = summarize(recording, separation_m=100.0)
    assert s.audit.min_separation_m == pytest.approx(50.0, abs=1e-9)
    assert sorted(s.audit.closest_pair) == ["r1", "r2"]
    assert len(s.audit.losses) == 1
    a, b, d, when = s.audit.losses[0]
    assert sorted([a, b]) == ["r1", "r2"] and d == pytest.approx(50.0) and when == pytest.approx(50.0)
    assert 1 <= s.audit.pairs_checked <= 3  # far pairs may be skipped by the distance bound
    relaxed = summarize(recording, separation_m=40.0)
    assert relaxed.audit.ok and relaxed.audit.min_separation_m == pytest.approx(50.0)


def test_rosbags_decoder_gives_the_same_summary(recording):
    a = summarize(recording, reader="rclpy").to_dict()
    b = summarize(recording, reader="rosbags").to_dict()
    a.pop("reader"), b.pop("reader")
    assert a == b


def test_summary_is_json_serialisable(recording):
    d = json.loads(summarize(recording).to_json())
    assert d["approved"] == 3 and d["audit"]["ok"] is False
    assert math.isclose(d["audit"]["min_separation_m"], 50.0)


def test_instances_come_back_as_mwis_problems(recording):
    problems = instances_from_mcap(recording)
    assert len(problems) == 1
    p = problems[0]
    assert list(p.weights) == [1.0, 0.8, 0.5, 1.0]
    assert [tuple(e) for e in p.edges] == [(0, 1), (0, 2), (1, 2), (2, 3)]
    inst = recorded_instances(recording)[0]
    assert inst.vertex_request_ids == ["r1", "r1", "r1", "r2"] and inst.selected == [0, 3]


def test_command_line_prints_summary_and_exit_code_flags_a_loss(recording, capsys):
    assert main([str(recording)]) == 2  # the 50 m approach is a loss at 100 m
    out = capsys.readouterr().out
    assert "approved       3" in out and "50.0 m" in out and "LOSS OF SEPARATION" in out
    assert main([str(recording), "--separation-m", "40", "--json"]) == 0
    assert json.loads(capsys.readouterr().out)["audit"]["ok"] is True
    assert main([str(recording) + ".missing"]) == 1


def test_files_that_are_not_mcap_are_refused_naming_them(tmp_path, capsys):
    # the README was read as an INCOMPLETE recording of 0 requests whose audit was "OK", exit 0
    text = tmp_path / "README.md"
    text.write_text("# not a recording\n")
    empty = tmp_path / "empty.mcap"
    empty.write_bytes(b"")
    for path in (text, empty):
        assert main([str(path)]) == 2
        captured = capsys.readouterr()
        assert f"{str(path)!r} is not an MCAP file" in captured.err
        assert "Safety audit" not in captured.out and "OK" not in captured.out
    with pytest.raises(ValueError, match="not an MCAP file"):
        summarize(text)
    # an MCAP file of something else: none of a run's topics, so nothing to judge
    other = tmp_path / "other.mcap"
    with McapRecorder(other) as rec:
        rec.add_topic("/camera/info", Time)
        rec.write("/camera/info", t(1), NS)
    assert main([str(other)]) == 2
    captured = capsys.readouterr()
    assert "holds none of the topics /uam/requests" in captured.err and "Safety audit" not in captured.out


def test_misspelled_options_are_errors_not_file_names(recording, capsys):
    # `--seperation cylinder x.mcap` said "no file at cylinder"
    with pytest.raises(SystemExit) as stop:
        main(["--seperation", "cylinder", str(recording)])
    assert stop.value.code == 2 and "--seperation" in capsys.readouterr().err
    with pytest.raises(SystemExit) as stop:  # an abbreviation is not taken for the option
        main(["--separation-", "40", str(recording)])
    assert stop.value.code == 2
    # what ros2 run appends is still ignored
    assert main([str(recording), "--separation-m", "40", "--ros-args", "-r", "__node:=x"]) == 0


def test_fleet_state_digest_reads_stamp_and_count_from_the_cdr():
    from uam_sim.recording.cdr import fleet_state_digest as _fleet_state_digest
    from uam_sim.recording.cdr import serialize_exact

    for frame in ("", "e", "enu", "a-longer-frame"):
        for n in (0, 1, 7):
            fs = FleetState(step_index=123456789012, vehicles=[VehicleState(vehicle_id=str(j)) for j in range(n)])
            fs.header.stamp = Time(sec=42, nanosec=5)
            fs.header.frame_id = frame
            d = _fleet_state_digest(serialize_exact(fs))
            assert (d.header.stamp.sec, d.header.stamp.nanosec, d.step_index, len(d.vehicles)) == \
                (42, 5, 123456789012, n)


def test_pruned_audit_equals_brute_force_on_random_flights():
    """The bound-ordered search finds the same minimum and the same losses as checking all pairs."""
    import numpy as np
    from uam_planner.audit import audit_flights

    from uam_sim.audit.separation import audit_trajectories

    rng = np.random.default_rng(7)
    for trial in range(20):
        flights = []
        for _ in range(int(rng.integers(2, 25))):
            p = int(rng.integers(2, 6))
            times = np.cumsum(rng.uniform(5, 60, size=p)) + rng.uniform(0, 200)
            points = rng.uniform(0, 3000, size=(p, 3)) * np.array([1, 1, 0.05])
            flights.append((times, points))
        labels = [f"f{i}" for i in range(len(flights))]
        for sep in (50.0, 400.0):
            ours = audit_trajectories(flights, labels, sep)
            ref = audit_flights(flights, separation_m=sep, labels=labels)
            assert ours.min_separation_m == pytest.approx(ref.min_separation_m, abs=1e-9), trial
            assert {tuple(sorted(x[:2])) for x in ours.losses} == {tuple(sorted(x[:2])) for x in ref.losses}
            assert ours.pairs_checked <= ref.pairs_checked


def test_the_solver_librarys_corpus_reader_reads_recordings_through_the_entry_point(recording):
    """uam_solvers.instances reads .mcap corpora without importing uam_sim (no upward import):
    uam_sim declares the reader as an entry point."""
    from uam_solvers.instances import read_instances

    entries = read_instances(recording)
    assert [e.name for e in entries] == ["synthetic-epoch0"]
    assert list(entries[0].problem.weights) == list(instances_from_mcap(recording)[0].weights)


@pytest.fixture(scope="module")
def fifo_two_operators(tmp_path_factory):
    """A FIFO run of two operators: A's flight departs 30 s after its earliest departure on a
    route 25 % longer than the shortest (weight d*/d = 0.8), B's at once on the shortest; two
    requests expire by different latest departures."""
    path = tmp_path_factory.mktemp("fifo") / "fifo.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/uam/requests", FlightRequest)
        rec.add_topic("/uam/flight_plans", FlightPlan)
        rec.add_topic("/uam/planning_reports", PlanningReport)
        for op, rid in [("opA", "a1"), ("opB", "b1"), ("opA", "a2"), ("opB", "b2")]:
            rec.write("/uam/requests", FlightRequest(operator_id=op, request_id=rid, request_time=t(0),
                                                     earliest_departure=t(0)), 0)
        for op, rid, dep, w, k in [("opA", "a1", 30.0, 0.8, 1), ("opB", "b1", 0.0, 1.0, 0)]:
            p = plan(rid, FlightPlan.OUTCOME_APPROVED, [(dep, 0, 0, 100), (dep + 100, 1000, 0, 100)])
            p.operator_id, p.weight, p.length_m, p.candidate_index = op, w, 1000.0 / w, k
            p.departure_time, p.arrival_time = t(dep), t(dep + 100)
            rec.write("/uam/flight_plans", p, 0)
        for op, rid, latest in [("opA", "a2", 60), ("opB", "b2", 90)]:
            p = plan(rid, FlightPlan.OUTCOME_EXPIRED,
                     reason=f"no conflict-free departure found by latest_departure {latest} s")
            p.operator_id = op
            rec.write("/uam/flight_plans", p, 0)
        for k in range(2):  # FIFO reports its graph's size but solves no MWIS
            r = PlanningReport(epoch_index=k, policy="fifo", vertices=2, edges=1, approved=1 - k)
            r.header.stamp = t(30 * k)
            rec.write("/uam/planning_reports", r, 30 * k * NS)
    return path


def test_delay_and_detour_per_run_and_per_operator(fifo_two_operators):
    s = summarize(fifo_two_operators)
    assert s.flight_stats["flights"] == 2
    assert s.flight_stats["delay_mean_s"] == pytest.approx(15.0)  # (30 + 0) / 2
    assert s.flight_stats["delayed_share"] == pytest.approx(0.5)
    assert s.flight_stats["detour_mean_pct"] == pytest.approx(12.5)  # (25 + 0) / 2
    assert s.flight_stats["shortest_share"] == pytest.approx(0.5)
    assert s.flight_stats_by_operator["opA"]["delay_mean_s"] == pytest.approx(30.0)
    assert s.flight_stats_by_operator["opA"]["detour_mean_pct"] == pytest.approx(25.0)
    assert s.flight_stats_by_operator["opB"]["detour_mean_pct"] == pytest.approx(0.0)
    text = format_summary(s)
    # one delay row: mean, p95 (linear: 0 + 0.95 x 30 = 28.5) and the delayed share of one set
    assert "Departure delay  mean 15.0 s after the earliest departure, p95 28.5 s, 50 % of 2 flights delayed" in text
    assert text.count("p95") == 3  # the run's row and one per operator; no second delay row
    assert "Route detour     mean 12.5 % over the shortest route" in text
    assert "Departure delay of opA  mean 30.0 s" in text


def test_fifo_prints_no_mwis_rows_and_reasons_show_their_numbers(fifo_two_operators):
    s = summarize(fifo_two_operators)
    assert s.mwis_vertices["count"] == 0 and s.mwis_selected["count"] == 0
    text = format_summary(s)
    # FIFO printed "MWIS selected min 0, median 0, max 0" and "... by latest_departure N s"
    assert "MWIS             none solved (policy fifo)" in text and "MWIS selected" not in text
    assert "2 x no conflict-free departure found by latest_departure 60..90 s" in text
    assert "latest_departure N" not in text


def test_log_times_on_the_scenario_clock_give_the_same_analysis(recording, tmp_path):
    """Issue 22: the recorder puts log times on the scenario's UTC clock (2025-01-06T00:00:00Z =
    1,736,121,600 s after the Unix epoch, + simulation time) and says so in the ``uam_clock``
    record; the readers subtract it, so the analysis, its times and its verdict are unchanged."""
    from uam_sim.recording.mcap_reader import CLOCK_METADATA, iter_decoded, log_time_zero_ns, read_messages, read_metadata
    from uam_sim.recording import parse_offered_qos

    zero = 1_736_121_600 * NS
    utc = tmp_path / "utc.mcap"
    with McapRecorder(utc) as rec:
        rec.add_metadata(CLOCK_METADATA, {"log_time_zero_ns": zero, "log_time_start_utc": "2025-01-06T00:00:00Z"})
        for m in read_messages(recording):
            if not rec.has_topic(m.topic):
                rec.add_topic(m.topic, m.type_name, offered_qos_profiles=parse_offered_qos(m.qos_yaml) or None)
            rec.write(m.topic, m.data, m.log_time_ns + zero)
        for name in ("uam_airspace", "uam_recorder_check"):
            if read_metadata(recording, name):
                rec.add_metadata(name, read_metadata(recording, name))
    assert log_time_zero_ns(recording) == 0 and log_time_zero_ns(utc) == zero
    assert min(m.log_time_ns for m in read_messages(utc)) == zero          # the file: 2025-01-06
    assert [t for _, t, _ in iter_decoded(utc)] == [t for _, t, _ in iter_decoded(recording)]
    a, b = summarize(recording).to_dict(), summarize(utc).to_dict()
    a.pop("path", None), b.pop("path", None)
    assert a == b and a["fleet_steps"] == 5
    assert main([str(utc)]) == main([str(recording)]) == 2                # the same loss, found the same way


def test_a_bad_clock_record_is_refused_naming_it(tmp_path):
    from uam_sim.recording.mcap_reader import CLOCK_METADATA, log_time_zero_ns

    bad = tmp_path / "bad.mcap"
    with McapRecorder(bad) as rec:
        rec.add_metadata(CLOCK_METADATA, {"log_time_zero_ns": "soon"})
    with pytest.raises(ValueError, match=r"uam_clock.log_time_zero_ns: 'soon' is not an integer"):
        log_time_zero_ns(bad)
