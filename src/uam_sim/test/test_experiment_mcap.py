"""uam_sim.studies.experiment --from-mcap: a recording of a run gives the same metrics as the run itself."""

from __future__ import annotations

import math

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from uam_msgs.msg import FlightPlan, FlightRequest, PlanningReport  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402

from uam_sim.studies.experiment import main, make_config, run_scenario, study_from_mcaps  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402
from uam_sim.runner.network_spec import load_network_spec  # noqa: E402

NET = {"synthetic": {"n_nodes": 30, "n_aerodromes": 5, "seed": 2}}
NS = 1_000_000_000


def record(path, method, cfg):
    """Run a scenario in process and record it with the node graph's topics and messages."""
    net = load_network_spec(NET)
    with McapRecorder(path) as rec:
        rec.add_topic("/uam/requests", FlightRequest)
        rec.add_topic("/uam/flight_plans", FlightPlan)
        rec.add_topic("/uam/planning_reports", PlanningReport)
        policy = "fifo" if method == "fifo" else "mwis"

        def observer(t_s, epoch, submitted, refused, res):
            ns = int(t_s * NS)
            for r in submitted:
                rec.write("/uam/requests", m.request_to_msg(r), ns)
            for f in res.approved:
                rec.write("/uam/flight_plans", m.approved_plan(f, t_s, policy), ns)
            for r in res.expired:
                rec.write("/uam/flight_plans", m.unapproved_plan(
                    r.request_id, r.origin_id, r.destination_id, FlightPlan.OUTCOME_EXPIRED,
                    "expired", t_s, epoch, policy), ns)
            rec.write("/uam/planning_reports", m.report_to_msg(res.report), ns)
        return run_scenario(net, method, 6, 0, 300.0, cfg, observer=observer)


@pytest.mark.slow  # not in `make test-fast`: two runs, recordings and a report, 3 s
def test_recordings_give_the_runs_metrics(tmp_path):
    cfg = make_config({"network": NET, "out": str(tmp_path / "res"), "include_qpu": False,
                       "tts": {"enabled": False}})
    runs = {meth: record(tmp_path / f"{meth}.mcap", meth, cfg) for meth in ("fifo", "greedy")}
    out = study_from_mcaps([str(tmp_path / "fifo.mcap"), str(tmp_path / "greedy.mcap")], cfg)
    cells = out["sweep"].cells
    assert [c["summary"]["method"] for c in cells] == ["fifo", "greedy"]
    for c, run in zip(cells, runs.values()):
        got, want = c["summary"], run.summary
        for k in ("requests", "approved", "expired", "epochs", "max_vertices", "losses"):
            assert got[k] == want[k], k
        assert got["rate"] == 6
        assert got["min_separation_m"] == pytest.approx(want["min_separation_m"], abs=1e-6)
        assert [e["approved_cum"] for e in c["epochs"]] == [e["approved_cum"] for e in run.epochs]
    assert len(cells[1]["instances"]) == len(runs["greedy"].instances)
    assert (tmp_path / "res" / "REPORT.md").exists()
    assert (tmp_path / "res" / "figures" / "cumulative_approved.png").exists()
    rc = main(["--from-mcap", str(tmp_path / "greedy.mcap"), "--out", str(tmp_path / "cli"),
               "--no-tts"])
    assert rc == 0 and (tmp_path / "cli" / "runs.csv").exists()


def test_a_recording_gives_the_runs_decision_metrics(tmp_path):
    """Issue 21: uam_sim.audit.analysis computes the runner's delay, per-class p95, operator shares and,
    given the network, the detour in metres from a recording with the same implementation
    (uam_sim.world.flights.run_metrics)."""
    from uam_sim.audit.analysis import format_summary, summarize

    cfg = make_config({"network": NET, "objective": "priority", "priority_share": 0.3,
                       "priority_class": 4, "operators": ["a", "b"], "audit": False})
    net = load_network_spec(NET)
    path = tmp_path / "run.mcap"
    with McapRecorder(path) as rec:
        rec.add_topic("/uam/requests", FlightRequest)
        rec.add_topic("/uam/flight_plans", FlightPlan)
        rec.add_topic("/uam/planning_reports", PlanningReport)

        def observer(t_s, epoch, submitted, refused, res):
            ns = int(t_s * NS)
            for r in submitted:
                rec.write("/uam/requests", m.request_to_msg(r, operator_id=r.operator_id), ns)
            for f in res.approved:
                plan = m.approved_plan(f, t_s, "mwis")
                plan.operator_id = f.operator_id
                rec.write("/uam/flight_plans", plan, ns)
            rec.write("/uam/planning_reports", m.report_to_msg(res.report), ns)
        run = run_scenario(net, "greedy", 6, 0, 300.0, cfg, observer=observer)
    dm = summarize(path, network=net).decision_metrics
    want = run.summary
    for k in ("delay_mean_s", "delay_p95_s", "delay_p95_s_prio0", "delay_p95_s_prio4",
              "share_a", "share_b", "jain_index", "detour_mean_m", "delayed_share"):
        assert dm[k] == pytest.approx(want[k], abs=1e-6), k
    assert want["detour_mean_m"] > 0  # some flight took a longer candidate: the check can fail
    assert math.isnan(summarize(path).flight_stats["detour_mean_m"])  # no network, no metres
    text = format_summary(summarize(path), epochs=False)
    assert "p95 class 4" in text and "Jain index" in text
