"""Re-planning through the node graph (issue 22 items 4 and 6): a constraint announced during the
run (``announce_s`` in the planner's ``constraints_file``) re-plans the flights it affects at
the epoch it is announced at, exactly as the in-process runner does; the new versions reach the
operator as FlightPlan messages naming the constraint, the simulator flies them from the instant
they take effect, and the recording's independent audit of what flew finds no incursion."""

from __future__ import annotations

import json

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from graph_harness import build_graph, decisions, in_process, run_to_end, shutdown  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402

from uam_planner.nodes import conversions as m  # noqa: E402

pytestmark = pytest.mark.ros


def announced(tmp_path, announce_s=120.0):
    """A 500 m square over the tiny network's hub W7, 0-300 m, from announce_s + 60 s on,
    announced at announce_s (docs/constraints.md)."""
    doc = {"type": "FeatureCollection", "frame": "enu", "features": [
        {"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [
            [[-250, -250], [250, -250], [250, 250], [-250, 250], [-250, -250]]]},
         "properties": {"id": "hub", "version": 1, "reason": "event", "lower_m": 0, "upper_m": 300.0,
                        "start_s": announce_s + 60.0, "end_s": 10000, "announce_s": announce_s}}]}
    path = tmp_path / "announced.geojson"
    path.write_text(json.dumps(doc))
    return path


def test_graph_replans_as_the_runner_does_and_the_recording_audits_what_flew(ros_context, spin_until, tmp_path):
    path = announced(tmp_path)
    rate, seed, duration = 3.0, 4, 300.0
    out = tmp_path / "replan.mcap"
    executor, nodes, obs = build_graph(ros_context, rate=rate, seed=seed, duration_s=duration, record_to=out,
                                       planner_extra={"constraints_file": str(path)})
    try:
        run_to_end(executor, nodes, obs, spin_until)
    finally:
        shutdown(executor, nodes)
    ref = in_process(rate, seed, duration, "exact", constraints_file=str(path))
    assert decisions(obs.plans) == ref.decisions() and ref.decisions()
    # the same plan updates: request, new version, kind, effective instant (the epoch at 120 s)
    graph_updates = sorted((p.request_id, int(p.version), p.update_kind, m.from_time(p.effective_time))
                           for p in obs.plans if p.version > 1)
    runner_updates = sorted((r["request_id"], int(r["version"]), r["kind"], float(r["t_s"])) for r in ref.replans)
    assert graph_updates == runner_updates and graph_updates, (graph_updates, runner_updates)
    assert {t for *_x, t in graph_updates} == {120.0}
    for p in obs.plans:
        if p.version > 1:
            assert list(p.constraint_ids) == ["hub"] and "'hub' v1 (event)" in p.reason
            airborne = p.waypoints and m.from_time(p.departure_time) <= 120.0
            assert p.state == (FlightPlan.STATE_ENDED if p.update_kind == "cancelled" else
                               FlightPlan.STATE_CONTINGENT if p.update_kind == "contingency" else
                               FlightPlan.STATE_ACTIVATED if airborne else FlightPlan.STATE_ACCEPTED), p
        elif p.outcome == FlightPlan.OUTCOME_APPROVED:
            # F3548: Accepted before its departure, Activated from it (the paper's rule departs at once)
            departs_later = m.from_time(p.departure_time) > m.from_time(p.header.stamp)
            assert p.version == 1 and p.state == (FlightPlan.STATE_ACCEPTED if departs_later
                                                  else FlightPlan.STATE_ACTIVATED)
    assert nodes["simulator"].fly_errors == 0
    assert nodes["simulator"].versions_received == len(graph_updates)
    # the recording: the set published when it took effect, every version, audited as flown
    from uam_sim.analysis import summarize
    s = summarize(out)
    assert s.verified, s.problems
    assert s.audit.ok and s.incursions == [] and s.constraints_in_force == 1
    assert sum(s.plan_updates.values()) == len(graph_updates)
    assert s.approved == len(ref.decisions())
    assert ref.summary["replans"] == len(graph_updates)
