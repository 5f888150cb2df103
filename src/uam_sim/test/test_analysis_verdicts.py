"""Verdicts that mean something (issue 18): the analysis calls a recording OK only when the run
ended as planned and everything that proves it is in the file; otherwise NOT VERIFIED (exit 3)
with the reason, and forged plans are listed, not audited as flown."""

from __future__ import annotations

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from run_frame import complete_run  # noqa: E402
from uam_msgs.msg import EpochSync, FleetState, FlightPlan, FlightRequest, PlanningReport, VehicleState, Waypoint  # noqa: E402

from uam_sim.audit.analysis import main, summarize  # noqa: E402
from uam_sim.audit.separation import AIRSPACE_METADATA, airspace_metadata  # noqa: E402
from uam_sim.recording.mcap_reader import read_metadata  # noqa: E402
from uam_sim.recording.mcap_recover import recover  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402

NS = 1_000_000_000
APPROVED = FlightPlan.OUTCOME_APPROVED


def _plan(rid, epoch, north_m=0.0, t0=0):
    return FlightPlan(request_id=rid, outcome=APPROVED, epoch_index=epoch, waypoints=[
        Waypoint(position=Point(x=0.0, y=north_m, z=100.0), time=Time(sec=t0)),
        Waypoint(position=Point(x=1000.0, y=north_m, z=100.0), time=Time(sec=t0 + 100))])


def _write(path, *, frame=True, extra=None, epochs=2, **frame_kw):
    """A clean run of two epochs: r1 in epoch 0, r2 in epoch 1 (1 km apart), both flown."""
    rec = McapRecorder(path)
    for topic, cls in (("/uam/requests", FlightRequest), ("/uam/flight_plans", FlightPlan),
                       ("/uam/planning_reports", PlanningReport), ("/uam/fleet_state", FleetState)):
        rec.add_topic(topic, cls)
    with rec:
        for rid, epoch, north in (("r1", 0, 0.0), ("r2", 1, 1000.0)):
            rec.write("/uam/requests", FlightRequest(request_id=rid), 0)
            rec.write("/uam/flight_plans", _plan(rid, epoch, north, t0=30 * epoch), 30 * epoch * NS)
            rec.write("/uam/planning_reports", PlanningReport(epoch_index=epoch, approved=1), 30 * epoch * NS)
        for k in range(60):
            ids = ["r1"] + (["r2"] if k >= 30 else [])
            # each where its plan has it (east at 10 m/s, r2 1 km north of r1)
            fs = FleetState(step_index=k, vehicles=[VehicleState(
                vehicle_id=v, position=Point(x=10.0 * (k - 30 * (v == "r2")), y=1000.0 * (v == "r2"), z=100.0))
                for v in ids])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * NS)
        if extra is not None:
            extra(rec)
        if frame:
            complete_run(rec, epochs=epochs, **frame_kw)
    return path


def test_a_clean_run_is_ok(tmp_path):
    s = summarize(_write(tmp_path / "ok.mcap"))
    assert s.verified and s.audit.ok and s.approved == 2, s.problems
    assert main([str(tmp_path / "ok.mcap"), "--no-epochs"]) == 0


def test_a_run_cut_short_or_ended_on_an_error_is_not_verified(tmp_path):
    def ended_early(rec):
        rec.add_topic("/uam/epoch_sync", EpochSync)
        for k in (0, 1):
            rec.write("/uam/epoch_sync", EpochSync(sender="simulator", epoch_index=k, session="s", duration_s=600.0,
                                                   epoch_s=30.0, epoch_time=Time(sec=30 * k)), 30 * k * NS)
    # no end announced at all (the planner was killed and the recorder stopped with the script)
    cut = _write(tmp_path / "cut.mcap", frame=False, extra=ended_early)
    s = summarize(cut)
    assert not s.verified and any("never announced the end" in p for p in s.problems), s.problems
    assert main([str(cut), "--no-epochs"]) == 3
    # an end announced with an error (a skipped epoch, a second simulator, a planner that died)
    def on_error(rec):
        ended_early(rec)
        rec.write("/uam/epoch_sync", EpochSync(sender="simulator", epoch_index=2, session="s", finished=True,
                                               epoch_time=Time(sec=60), duration_s=600.0, epoch_s=30.0,
                                               error="no answer for epoch 2 within 120 s"), 60 * NS)
    s = summarize(_write(tmp_path / "err.mcap", frame=False, extra=on_error))
    assert not s.verified and any("ended early on an error: no answer for epoch 2" in p for p in s.problems)
    # an end before the duration without an error (a forged end)
    s = summarize(_write(tmp_path / "short.mcap", duration_s=600.0, end_s=60.0))
    assert not s.verified and any("before its duration 600 s" in p for p in s.problems), s.problems


def test_a_forged_plan_with_a_forged_report_is_listed_and_not_audited(tmp_path):
    """Finding: a forged plan plus a forged PlanningReport (epoch 9999) passed both checks."""
    def forge(rec):
        rec.write("/uam/flight_plans", _plan("x9", 9999, north_m=5.0), 0)  # 5 m from r1
        rec.write("/uam/planning_reports", PlanningReport(epoch_index=9999, approved=1), 0)
    path = _write(tmp_path / "forged.mcap", extra=forge)
    s = summarize(path)
    assert s.forged_plans == ["x9"] and s.audit.ok, (s.forged_plans, s.audit.losses)
    assert not s.verified and any("forged" in p for p in s.problems), s.problems
    assert main([str(path), "--no-epochs"]) == 3

def test_the_view_of_a_recording_draws_what_the_record_holds(tmp_path, monkeypatch):
    """The Rerun view of a recording (log_recording) reads the run's record: r1's and r2's
    routes are drawn, the forged x9's is not."""
    pytest.importorskip("rerun")
    from uam_sim.views import rerun_log

    def forge(rec):
        rec.write("/uam/flight_plans", _plan("x9", 9999, north_m=5.0), 0)
        rec.write("/uam/planning_reports", PlanningReport(epoch_index=9999, approved=1), 0)
    drawn = []
    original = rerun_log.RerunLogger.log_route
    monkeypatch.setattr(rerun_log.RerunLogger, "log_route",
                        lambda self, t, rid, pts: (drawn.append(rid), original(self, t, rid, pts)))
    rerun_log.log_recording(_write(tmp_path / "forged.mcap", extra=forge), tmp_path / "forged.rrd")
    assert sorted(drawn) == ["r1", "r2"]


def test_an_approval_that_never_flew_is_flagged(tmp_path):
    """Finding: 5 counted approvals never flew and the analysis said OK."""
    def never_flown(rec):
        rec.write("/uam/flight_plans", _plan("r3", 1, north_m=3000.0, t0=30), 30 * NS)
        rec.write("/uam/planning_reports", PlanningReport(epoch_index=1, approved=2), 30 * NS)  # a second report
    s = summarize(_write(tmp_path / "nf.mcap", extra=never_flown))
    assert not s.verified
    assert any("never flew" in p and "'r3'" in p for p in s.problems), s.problems
    assert any("two different planning reports" in p for p in s.problems), s.problems


def test_two_simulators_or_a_missing_epoch_report_are_not_verified(tmp_path):
    def second(rec):
        rec.add_topic("/uam/epoch_sync", EpochSync)
        rec.write("/uam/epoch_sync", EpochSync(sender="simulator", epoch_index=0, session="other",
                                               duration_s=60.0, epoch_s=30.0), 0)
    s = summarize(_write(tmp_path / "two.mcap", extra=second))
    assert not s.verified and any("2 simulators announced" in p for p in s.problems), s.problems
    s = summarize(_write(tmp_path / "gap.mcap", epochs=3))
    assert not s.verified and any("no planning report (epochs 2)" in p for p in s.problems), s.problems


def test_missing_records_make_a_recording_not_verified(tmp_path):
    path = tmp_path / "bare.mcap"
    _write(path, airspace_record=False)
    s = summarize(path)
    assert not s.verified and any("uam_airspace" in p for p in s.problems)


def test_a_recovered_recording_keeps_its_airspace_and_is_never_complete(tmp_path):
    """Finding: a recording recovered after a recorder SIGKILL lost uam_airspace and the
    INCOMPLETE mark, so a cylinder run cut at 70 % was audited as a 100 m sphere."""
    torn = tmp_path / "torn.mcap"
    rec = McapRecorder(torn, flush_period_s=None)
    rec.add_metadata(AIRSPACE_METADATA, airspace_metadata("cylinder", 100.0, 30.0, 5.0))  # as the recorder does
    rec.add_topic("/uam/flight_plans", FlightPlan)
    rec.write("/uam/flight_plans", _plan("r1", 0), 0)
    rec.flush()
    data = torn.read_bytes()  # what is on disk when the recorder is killed: no summary, no footer
    rec.close()
    torn.write_bytes(data)
    assert read_metadata(torn, AIRSPACE_METADATA)["separation_model"] == "cylinder"
    fixed = tmp_path / "fixed.mcap"
    assert recover(torn, fixed) == 1
    assert read_metadata(fixed, AIRSPACE_METADATA)["separation_model"] == "cylinder"
    s = summarize(fixed)
    assert s.audit.separation_model == "cylinder"
    assert not s.complete_file and not s.verified
    assert any("rebuilt from a recording cut short" in p for p in s.problems), s.problems


def test_the_runs_choices_are_in_the_header(tmp_path):
    from uam_contract.params import RECORDER
    from uam_sim.audit.analysis import RUN_METADATA, format_summary

    rule = next(p for p in RECORDER if p.name == "run_choices")
    for bad, why in (("{objective", "is not JSON"), ("[1, 2]", "must be a JSON object"), ('{"a": [1]}', "must be a JSON object")):
        with pytest.raises(ValueError, match=f"parameter run_choices: {why}"):
            rule.validate(bad)
    assert rule.validate('{"objective": "count"}') == '{"objective": "count"}'

    def extra(rec):
        rec.add_metadata(RUN_METADATA, {"objective": '"priority"', "priority_share": "0.05", "horizon": "5",
                                        "lead_time_s": "300", "spatial_buffer_m": "10", "reaction": "true"})
    s = summarize(_write(tmp_path / "choices.mcap", extra=extra))
    assert s.run_choices == {"objective": "priority", "priority_share": 0.05, "horizon": 5, "lead_time_s": 300,
                             "spatial_buffer_m": 10, "reaction": True}
    assert ("Run choices      objective priority, priority share 0.05, horizon 5, lead time 300 s, "
            "spatial buffer 10 m, reaction true (as launched)") in format_summary(s)
    assert "Run choices      not recorded" in format_summary(summarize(_write(tmp_path / "none.mcap")))


def test_both_launchers_state_the_runs_choices_with_one_function():
    import json
    from pathlib import Path

    from uam_contract.run_choices import NAMES, as_json, main

    got = json.loads(as_json(objective="priority", seed="7", reaction="true", probe_s="120", backend="exact"))
    assert got == {"backend": "exact", "seed": 7, "objective": "priority", "reaction": True, "probe_s": 120}
    with pytest.raises(ValueError, match="horizon_epochs not among"):
        as_json(horizon_epochs="5")
    assert main(["seed"]) == 2
    # run_fleet.sh and the launch file call it with every name
    for launcher in ("scripts/run_fleet.sh", "src/uam_bringup/launch/uam.launch.py"):
        text = Path(launcher).read_text()
        assert "uam_contract.run_choices" in text, launcher
        assert all(f"{n}=" in text or f'"{n}"' in text for n in NAMES), launcher


def test_approvals_are_stated_per_priority_class(tmp_path):
    from uam_sim.audit.analysis import format_summary

    def urgent(rec):
        rec.write("/uam/requests", FlightRequest(request_id="r3", priority=1), 0)
    s = summarize(_write(tmp_path / "classes.mcap", extra=urgent))
    assert s.approvals_by_class == {0: (2, 2), 1: (0, 1)}
    text = format_summary(s)
    assert "Classes          class 0: 2 of 2 approved (100.0 %); class 1: 0 of 1 approved (0.0 %)" in text
    # one class: no line
    assert "Classes" not in format_summary(summarize(_write(tmp_path / "one.mcap")))
