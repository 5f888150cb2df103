"""The analysis can be trusted: a duplicate id never hides a decision from the audit, and a
recording that lacks plans it should hold is never reported "OK"."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from builtin_interfaces.msg import Time  # noqa: E402
from geometry_msgs.msg import Point  # noqa: E402
from uam_msgs.msg import FleetState, FlightPlan, FlightRequest, PlanningReport, VehicleState, Waypoint  # noqa: E402

from uam_sim.audit.analysis import format_summary, main, summarize  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402
from run_frame import complete_run  # noqa: E402

NS = 1_000_000_000
APPROVED, REJECTED = FlightPlan.OUTCOME_APPROVED, FlightPlan.OUTCOME_REJECTED


def _plan(rid: str, outcome: int, north_m: float = 0.0, reason: str = "", stamp_s: int = 0) -> FlightPlan:
    """Approved plans fly east at 10 m/s for 100 s, z = 100 m, ``north_m`` north of the origin."""
    wps = [] if outcome != APPROVED else [
        Waypoint(position=Point(x=0.0, y=north_m, z=100.0), time=Time(sec=0)),
        Waypoint(position=Point(x=1000.0, y=north_m, z=100.0), time=Time(sec=100))]
    p = FlightPlan(request_id=rid, outcome=outcome, reason=reason, waypoints=wps)
    p.header.stamp = Time(sec=stamp_s)
    return p


def _fleet(rec: McapRecorder, ids: list[str], steps: int = 5, skip=()) -> None:
    for k in range(steps):
        if k in skip:
            continue
        # 1 km apart, east at 10 m/s: what flew keeps separation (the tests judge the record)
        fs = FleetState(step_index=k, vehicles=[VehicleState(vehicle_id=v, position=Point(x=10.0 * k, y=1000.0 * n, z=100.0))
                                                for n, v in enumerate(ids)])
        fs.header.stamp = Time(sec=k)
        rec.write("/uam/fleet_state", fs, k * NS)


def _report(rec: McapRecorder, epoch: int, approved: int) -> None:
    r = PlanningReport(epoch_index=epoch, approved=approved)
    r.header.stamp = Time(sec=30 * epoch)
    rec.write("/uam/planning_reports", r, 30 * epoch * NS)


def _open(path) -> McapRecorder:
    rec = McapRecorder(path)
    for topic, cls in (("/uam/requests", FlightRequest), ("/uam/flight_plans", FlightPlan),
                       ("/uam/planning_reports", PlanningReport), ("/uam/fleet_state", FleetState)):
        rec.add_topic(topic, cls)
    complete_run(rec)  # a run of one epoch that ended as planned: only what each test adds is wrong
    return rec


@pytest.fixture()
def forged(tmp_path):
    """The issue's attack: r1 is re-sent while pending, so a REJECTED plan is published under r1;
    r1 is then approved, and a forged approved plan 'x9' flies 5 m from it."""
    path = tmp_path / "forged.mcap"
    with _open(path) as rec:
        rec.write("/uam/requests", FlightRequest(request_id="r1"), 0)
        rec.write("/uam/requests", FlightRequest(request_id="r1"), 0)  # the re-sent copy
        rec.write("/uam/flight_plans", _plan("r1", REJECTED, reason="duplicate request id"), 0)
        rec.write("/uam/flight_plans", _plan("r1", APPROVED, north_m=0.0), 1)
        rec.write("/uam/flight_plans", _plan("x9", APPROVED, north_m=5.0), 2)
        _report(rec, 0, approved=1)
        _fleet(rec, ["r1", "x9"])
    return path


def test_a_duplicate_id_never_hides_an_approved_plan_from_the_audit(forged):
    s = summarize(forged)
    assert not s.audit.ok, "the approved r1 and the forged x9 flew 5 m apart"
    (a, b, d, _t), = s.audit.losses
    assert {a, b} == {"r1", "x9"} and d == pytest.approx(5.0)
    assert s.approved == 2 and s.conflicting_decisions == {"r1": ["rejected", "approved"]}
    assert any("r1" in p and "conflicting" in p for p in s.problems)
    assert any("x9" in p for p in s.problems), "a plan beyond what the reports announce is flagged"
    assert main([str(forged)]) == 2


def test_identical_repeats_of_a_plan_are_not_conflicts(tmp_path):
    """A late-joining subscriber may get a latched plan twice: same decision, counted once."""
    path = tmp_path / "repeat.mcap"
    with _open(path) as rec:
        rec.write("/uam/requests", FlightRequest(request_id="r1"), 0)
        rec.write("/uam/flight_plans", _plan("r1", APPROVED), 0)
        rec.write("/uam/flight_plans", _plan("r1", APPROVED), 1)
        _report(rec, 0, approved=1)
        _fleet(rec, ["r1"])
    s = summarize(path)
    assert s.approved == 1 and s.duplicate_decisions == 1 and s.conflicting_decisions == {}
    assert s.problems == [] and "Safety audit     OK" in format_summary(s)
    assert main([str(path)]) == 0


def test_a_recording_without_the_plans_it_should_hold_is_never_ok(tmp_path, capsys):
    """The fault of the issue: reports and fleet states say flights flew, no plan was recorded."""
    path = tmp_path / "no-plans.mcap"
    with _open(path) as rec:
        for rid in ("r1", "r2"):
            rec.write("/uam/requests", FlightRequest(request_id=rid), 0)
        _report(rec, 0, approved=2)
        _fleet(rec, ["r1", "r2"])
    s = summarize(path)
    assert s.audit.ok and s.audit.pairs_checked == 0  # nothing to audit: that must not read as OK
    text = " ".join(s.problems)
    assert "announce 2 approvals" in text and "0 approved plans" in text
    assert "r1" in text and "no approved plan" in text
    out = format_summary(s)
    assert "Safety audit     OK" not in out and "NOT VERIFIED" in out
    assert main([str(path)]) == 3
    assert "NOT VERIFIED" in capsys.readouterr().out
    assert json.loads(s.to_json())["verified"] is False


def test_fleet_states_lost_on_the_way_make_the_recording_unverified(tmp_path):
    """Fleet states are published at every step: a gap between the first and the last held
    (the transport dropped them for a lagging recorder) is flagged; a recording that starts
    late or ends early is not."""
    def recorded(name, skip=(), steps=8):
        path = tmp_path / name
        with _open(path) as rec:
            rec.write("/uam/requests", FlightRequest(request_id="r1"), 0)
            rec.write("/uam/flight_plans", _plan("r1", APPROVED), 0)
            _report(rec, 0, approved=1)
            _fleet(rec, ["r1"], steps=steps, skip=skip)
        return summarize(path)

    assert recorded("whole.mcap").problems == []
    assert recorded("late.mcap", skip=(0, 1)).problems == []
    s = recorded("gaps.mcap", skip=(3, 4, 6))
    assert s.fleet_steps == 5
    assert any("3 fleet state(s) are missing" in p and "3, 4, 6" in p for p in s.problems), s.problems
    assert main([str(tmp_path / "gaps.mcap")]) == 3


def test_missing_steps_are_counted_and_only_the_first_listed_even_for_a_forged_step_index():
    """A forged fleet state with step_index 2**64 - 1 (uint64 on the wire) is counted as a gap,
    not listed step by step (which would never end) nor an overflow."""
    from uam_sim.audit.analysis import missing_steps

    assert missing_steps([0, 1, 2]) == (0, [])
    assert missing_steps([5, 0, 3, 1]) == (2, [2, 4])
    count, listed = missing_steps([0, 1, 2**64 - 1])
    assert count == 2**64 - 3 and listed == list(range(2, 12))


def test_flights_that_flew_together_with_no_pair_checked_are_flagged(tmp_path):
    """Fleet states show two vehicles airborne at once, but only one plan is in the file."""
    path = tmp_path / "one-plan.mcap"
    with _open(path) as rec:
        rec.write("/uam/flight_plans", _plan("r1", APPROVED), 0)
        _fleet(rec, ["r1", "r2"])
    s = summarize(path)
    assert s.audit.pairs_checked == 0 and s.max_active_aircraft == 2
    assert any("0 pairs" in p for p in s.problems) and any("r2" in p for p in s.problems)


def test_requests_are_keyed_by_operator_and_a_refused_duplicate_is_not_a_decision(tmp_path):
    """Two operators may use the same request_id; the vehicles fly under the scoped key; an
    OUTCOME_DUPLICATE answer (a reused id refused) neither hides nor changes the decision."""
    path = tmp_path / "operators.mcap"
    with _open(path) as rec:
        for op in ("generator", "console"):
            rec.write("/uam/requests", FlightRequest(operator_id=op, request_id="r1"), 0)
        a = _plan("r1", APPROVED, north_m=0.0)
        a.operator_id = "generator"
        b = _plan("r1", APPROVED, north_m=500.0)
        b.operator_id = "console"
        dup = _plan("r1", FlightPlan.OUTCOME_DUPLICATE, reason="request id already taken")
        dup.operator_id = "generator"
        for p in (a, b, dup):
            rec.write("/uam/flight_plans", p, 0)
        _report(rec, 0, approved=2)
        _fleet(rec, ["console/r1", "generator/r1"])
    s = summarize(path)
    assert (s.requests, s.approved, s.conflicting_decisions, s.duplicate_requests_refused) == (2, 2, {}, 1)
    assert s.problems == [] and s.audit.pairs_checked == 1 and s.audit.ok
    assert sorted(s.audit.closest_pair) == ["console/r1", "generator/r1"]


def test_the_key_separator_is_the_contracts():
    wire = pytest.importorskip("uam_contract.wire")
    from uam_sim.audit.analysis import SCOPE_SEPARATOR
    assert wire.scoped_id("op", "r1") == f"op{SCOPE_SEPARATOR}r1"
