"""The analysis audits a recording in the run's separation model (the recorder's uam_airspace
metadata), not always in the paper's sphere."""

from __future__ import annotations

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from uam_msgs.msg import FleetState, FlightPlan, FlightRequest, PlanningReport, VehicleState, Waypoint  # noqa: E402

from uam_sim.audit.analysis import format_summary, main, summarize  # noqa: E402
from uam_sim.audit.separation import AIRSPACE_METADATA, airspace_metadata  # noqa: E402
from run_frame import complete_run  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402

NS = 1_000_000_000


def _plan(rid: str, start, end, z: float) -> FlightPlan:
    wps = [Waypoint(position=Point(x=start[0], y=start[1], z=z), time=Time(sec=0)),
           Waypoint(position=Point(x=end[0], y=end[1], z=z), time=Time(sec=100))]
    return FlightPlan(request_id=rid, outcome=FlightPlan.OUTCOME_APPROVED, waypoints=wps)


def _recording(path, z_b: float, metadata: dict | None):
    """Flight a east at 60 m and flight b north at ``z_b``, crossing over the origin at t = 50 s."""
    rec = McapRecorder(path)
    if metadata is not None:
        rec.add_metadata(AIRSPACE_METADATA, metadata)
    for topic, cls in (("/uam/requests", FlightRequest), ("/uam/flight_plans", FlightPlan),
                       ("/uam/planning_reports", PlanningReport), ("/uam/fleet_state", FleetState)):
        rec.add_topic(topic, cls)
    with rec:
        for rid in ("a", "b"):
            rec.write("/uam/requests", FlightRequest(request_id=rid), 0)
        rec.write("/uam/flight_plans", _plan("a", (-500.0, 0.0), (500.0, 0.0), 60.0), 0)
        rec.write("/uam/flight_plans", _plan("b", (0.0, -500.0), (0.0, 500.0), z_b), 0)
        rec.write("/uam/planning_reports", PlanningReport(epoch_index=0, approved=2), 0)
        for k in range(5):
            fs = FleetState(step_index=k, vehicles=[
                VehicleState(vehicle_id="a", position=Point(x=-500.0 + 10.0 * k, y=0.0, z=60.0)),
                VehicleState(vehicle_id="b", position=Point(x=0.0, y=-500.0 + 10.0 * k, z=z_b))])
            fs.header.stamp = Time(sec=k)
            rec.write("/uam/fleet_state", fs, k * NS)
        complete_run(rec, airspace_record=False)  # the airspace record is the test's own
    return path


def test_one_level_apart_is_safe_in_a_cylinder_run_and_a_loss_in_a_paper_run(tmp_path):
    cyl = _recording(tmp_path / "cyl.mcap", 90.0, airspace_metadata("cylinder", 100.0, 30.0, 5.0))
    s = summarize(cyl)
    assert s.audit.separation_model == "cylinder" and s.audit.ok and s.verified
    assert "100 m horizontal within 30 m vertical" in format_summary(s)
    assert main([str(cyl), "--no-epochs"]) == 0
    # the same flights in a recording without the record (paper mode): 30 m apart, a loss
    paper = _recording(tmp_path / "paper.mcap", 90.0, None)
    s = summarize(paper)
    assert s.audit.separation_model == "sphere" and len(s.audit.losses) == 1
    assert s.audit.losses[0][2] == pytest.approx(30.0)
    assert main([str(paper), "--no-epochs"]) == 2
    # flags override the recorded model
    assert main([str(cyl), "--separation", "sphere", "--no-epochs"]) == 2


def test_cylinder_run_audit_finds_a_crossing_at_one_level(tmp_path):
    path = _recording(tmp_path / "x.mcap", 70.0, airspace_metadata("cylinder", 100.0, 30.0, 5.0))
    s = summarize(path)
    (a, b, d, t), = s.audit.losses
    assert {a, b} == {"a", "b"} and d == pytest.approx(0.0, abs=1e-9) and t == pytest.approx(50.0)
    # V given on the command line: below the 10 m between them, no loss
    assert main([str(path), "--vertical-separation-m", "5", "--no-epochs"]) == 0
