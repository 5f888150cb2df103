"""python -m uam_sim.export_f3548 (issue 25, item 2): a recording of a short run with a storm
announced mid-run gives one schema-valid F3548 document per approved plan version (the
re-plans as version 2), the constraint as an F3548 constraint, and an index."""

from __future__ import annotations

import json

import pytest

pytest.importorskip("uam_msgs.msg", reason="needs the built workspace (source scripts/env.sh)")

from std_msgs.msg import String  # noqa: E402
from uam_msgs.msg import FlightPlan, FlightRequest  # noqa: E402
from uam_planner.constraints import Constraint  # noqa: E402
from uam_planner.f3548 import constraint_entity_id, intent_id  # noqa: E402
from uam_planner.f3548_schema import errors, validate_implicit  # noqa: E402
from uam_planner.live_constraints import set_geojson  # noqa: E402
from uam_planner.f3548 import intent_version  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402

from uam_sim.audit.separation import AIRSPACE_METADATA, airspace_metadata  # noqa: E402
from uam_sim.runner.experiment_config import make_config  # noqa: E402
from uam_sim.f3548.export_f3548 import main  # noqa: E402
from uam_sim.recording.mcap_writer import McapRecorder  # noqa: E402
from uam_sim.runner.network_spec import load_network_spec  # noqa: E402
from uam_sim.runner.scenario import run_scenario  # noqa: E402

TINY = "config/networks/tiny.yaml"
NS = 1_000_000_000
STORM = Constraint("storm", 1, "storm", 240.0, 900.0, center_m=(0.0, 0.0), radius_m=150.0,
                   lower_m=0.0, upper_m=500.0)


def record(path):
    net = load_network_spec(TINY)
    seen = {"planner": None}
    plans = []
    with McapRecorder(path) as rec:
        rec.add_topic("/uam/requests", FlightRequest)
        rec.add_topic("/uam/flight_plans", FlightPlan)
        rec.add_topic("/uam/constraints", String)
        rec.add_metadata(AIRSPACE_METADATA, airspace_metadata("sphere", 100.0))

        def before(planner, t, k):
            seen["planner"] = planner
            if k == 6:
                planner.update_constraint("add", STORM, t)

        def observer(t_s, epoch, submitted, refused, res):
            ns = int(t_s * NS)
            for r in submitted:
                rec.write("/uam/requests", m.request_to_msg(r), ns)
            for f in res.approved:
                plans.append(m.approved_plan(f, t_s, "mwis"))
                rec.write("/uam/flight_plans", plans[-1], ns)
            for u in res.plan_updates:
                plans.append(m.plan_update_msg(u, t_s, "mwis"))
                rec.write("/uam/flight_plans", plans[-1], ns)
            if res.plan_updates or epoch == 6:
                cons = seen["planner"].config.constraints or ()
                rec.write("/uam/constraints", String(data=set_geojson(cons, t_s)), ns)

        run_scenario(net, "greedy", 4.0, 3, 420.0, make_config({"network": TINY, "audit": False}),
                     observer=observer, before_epoch=before)
    return plans


@pytest.mark.slow  # not in `make test-fast`: a run and its recording, ~5 s
def test_export_writes_every_version_valid(tmp_path, capsys):
    plans = record(tmp_path / "run.mcap")
    out = tmp_path / "f3548"
    assert main([str(tmp_path / "run.mcap"), "--out", str(out), "--network", TINY]) == 0
    index = json.loads((out / "index.json").read_text())
    said = capsys.readouterr()
    # the count is of what the index lists, and the export says what it is doing meanwhile
    assert f"{len(index['constraints'])} constraint versions (" in said.out, said.out
    assert "export_f3548: [0 s] reading the requests and constraints" in said.err
    assert "plan versions as operational intents" in said.err
    rows = index["operational_intents"]
    approved = [p for p in plans if p.outcome == FlightPlan.OUTCOME_APPROVED]
    assert len([r for r in rows if r["file"]]) == len(approved)  # each approved version, live at its decision
    assert max(r["version"] for r in rows) >= 2  # the storm made new versions
    for p in approved:
        oid = intent_id(p.operator_id, p.request_id)
        v = max(1, int(p.version))
        row = next(r for r in rows if r["id"] == oid and r["version"] == v)
        doc = json.loads((out / row["file"]).read_text())
        assert errors(doc, "GetOperationalIntentDetailsResponse") == []
        validate_implicit(doc, "GetOperationalIntentDetailsResponse")
        ref = doc["operational_intent"]["reference"]
        assert (ref["id"], ref["version"]) == (oid, intent_version(v, ref["state"]))
    cancelled = [p for p in plans if p.outcome != FlightPlan.OUTCOME_APPROVED and int(p.version) > 1]
    for p in cancelled:
        assert any(r["request_id"] == p.request_id and r["state"] == "Ended" and r["file"] is None
                   for r in rows)
    crow = [r for r in index["constraints"] if r["constraint_id"] == "storm"]
    assert len(crow) == 1 and crow[0]["id"] == constraint_entity_id("storm")
    assert errors(json.loads((out / crow[0]["file"]).read_text()), "GetConstraintDetailsResponse") == []
    assert index["scenario_start_utc"].endswith("Z") and index["separation"]["separation_m"] == 100.0


def test_export_refuses_a_missing_recording(tmp_path, capsys):
    assert main([str(tmp_path / "nope.mcap"), "--out", str(tmp_path / "o"), "--network", TINY]) == 2
    assert "recording: no file at" in capsys.readouterr().err
