"""Live constraints (issue 22 item 1): the planner's ``uam/update_constraint`` service and its
latched ``uam/constraints`` topic, in-process. Bad input is refused naming the field and the
value, the node keeps serving, and nothing accepted before is lost; accepted updates take
effect at the next epoch and the graph plans around them from then on."""

from __future__ import annotations

import itertools
import json
import math
import tempfile
from pathlib import Path

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")

from rclpy.executors import SingleThreadedExecutor  # noqa: E402
from std_msgs.msg import String  # noqa: E402
from uam_msgs.msg import FlightPlan  # noqa: E402
from uam_msgs.srv import UpdateConstraint  # noqa: E402

from graph_harness import TINY, build_graph, make_planner, run_to_end, shutdown  # noqa: E402
from uam_bringup import qos  # noqa: E402
from uam_contract import names as c  # noqa: E402
from uam_planner.constraints import MAX_VERTICES, ConstraintSet  # noqa: E402
from uam_planner.network import load_network  # noqa: E402
from uam_planner.nodes import conversions as m  # noqa: E402
from uam_planner.live_constraints import constraints_from_text, withdrawals_from_text  # noqa: E402
from uam_planner.authority import sign_update, write_authority  # noqa: E402

pytestmark = pytest.mark.ros

ADD, CHANGE, WITHDRAW = (UpdateConstraint.Request.ACTION_ADD, UpdateConstraint.Request.ACTION_CHANGE,
                         UpdateConstraint.Request.ACTION_WITHDRAW)
NAMES = {ADD: "add", CHANGE: "change", WITHDRAW: "withdraw"}

# the airspace authorities of these tests: "caa" (admin) and "clinic" (its own constraints only)
_KEYS = Path(tempfile.mkdtemp(prefix="uam-authority-"))
AUTHORITIES, CAA_KEY = write_authority(_KEYS / "caa", "caa")
_CLINIC_FILE, CLINIC_KEY = write_authority(_KEYS / "clinic", "clinic", admin=False)
(_KEYS / "caa" / "clinic.pub.pem").write_bytes((_KEYS / "clinic" / "clinic.pub.pem").read_bytes())
AUTHORITIES.write_text(AUTHORITIES.read_text() + "  - id: clinic\n    public_key: clinic.pub.pem\n")
_SEQ = itertools.count(1)


def square(cid="hub", version=1, half=250.0, lower=0.0, upper=300.0, start=0.0, end=10000.0, ring=None):
    """A square of side 2 x ``half`` m over the tiny network's origin (its hub W7), in ENU metres."""
    ring = ring or [[-half, -half], [half, -half], [half, half], [-half, half], [-half, -half]]
    return json.dumps({"type": "Feature", "geometry": {"type": "Polygon", "coordinates": [ring]},
                       "properties": {"id": cid, "version": version, "reason": "event", "frame": "enu",
                                      "lower_m": lower, "upper_m": upper, "start_s": start, "end_s": end}})


def closure(cid="C-closed", version=1, vertiport="C", start=0.0, end=150.0):
    return json.dumps({"type": "Feature", "geometry": None,
                       "properties": {"id": cid, "version": version, "reason": "maintenance",
                                      "vertiport_id": vertiport, "start_s": start, "end_s": end}})


def request(action, cid, version, geojson="", reason="", by="caa"):
    """The update, signed by authority ``by`` (None: unsigned) with the next sequence number."""
    req = UpdateConstraint.Request(action=action, constraint_id=cid, version=version, geojson=geojson,
                                   reason=reason)
    if by is not None:
        key = {"caa": CAA_KEY, "clinic": CLINIC_KEY}[by]
        req.authorization = sign_update(req, NAMES.get(action, "add"), by, key.read_bytes(), next(_SEQ))
    return req


def call(executor, spin_until, client, req):
    fut = client.call_async(req)
    assert spin_until(executor, fut.done, 20)
    return fut.result()


def test_bad_updates_are_refused_naming_the_field_and_nothing_accepted_is_lost(ros_context, spin_until):
    planner = make_planner(ros_context, authorities_file=str(AUTHORITIES))
    caller = rclpy.create_node("authority", context=ros_context)
    client = caller.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
    executor = SingleThreadedExecutor(context=ros_context)
    executor.add_node(planner)
    executor.add_node(caller)
    try:
        assert spin_until(executor, client.service_is_ready, 20)
        ok = call(executor, spin_until, client, request(ADD, "hub", 1, square()))
        assert ok.accepted and ok.error == "" and ok.constraints == 1
        assert (ok.effective_time.sec, ok.effective_time.nanosec) == (0, 0)   # the first epoch
        bow_tie = [[0, 0], [100, 100], [100, 0], [0, 100], [0, 0]]
        n = MAX_VERTICES + 1   # ASTM F3548-21 CstrMaxVertices, as uas_standards gives it (1000)
        big = [[1000 * math.cos(2 * math.pi * k / n), 1000 * math.sin(2 * math.pi * k / n)] for k in range(n)]
        cases = [
            (request(ADD, "bow", 1, square("bow", ring=bow_tie)), "invalid polygon: Self-intersection"),
            (request(ADD, "inv", 1, square("inv", lower=300.0, upper=100.0)),
             "upper_m: 100.0 is not above lower_m 300.0"),
            (request(ADD, "old", 1, square("old", start=-100.0, end=0.0)), "end_s: 0.0 is in the past"),
            (request(ADD, "huge", 1, square("huge", ring=big + [big[0]])),
             f"{n + 1} positions, more than the {MAX_VERTICES} vertices of ASTM F3548-21"),
            (request(ADD, "nowhere", 1, closure("nowhere", vertiport="ZZ")),
             "vertiport_id: 'ZZ' is not a vertiport of network"),
            (request(ADD, "hub", 2, square("hub", version=2)), "constraint_id: 'hub' is already a constraint (v1)"),
            (request(CHANGE, "hub", 1, square("hub", version=1)), "version: 1 of 'hub' is not above the current version 1"),
            (request(CHANGE, "ghost", 2, square("ghost", version=2)), "constraint_id: 'ghost' is not a known constraint"),
            (request(WITHDRAW, "ghost", 2), "constraint_id: 'ghost' is not a known constraint (nothing to withdraw)"),
            (request(WITHDRAW, "hub", 1), "version: 1 is not above 'hub''s version 1"),
            (request(ADD, "x", 1, square("y")), "properties.id: 'y' differs from constraint_id 'x'"),
            (request(ADD, "x", 1, "{not json"), "geojson: not JSON"),
            (request(7, "x", 1, square("x")), "action: 7 is not 0 (add), 1 (change) or 2 (withdraw)"),
            (request(WITHDRAW, "hub", 2, square("hub", version=2)), "geojson: a withdrawal carries no geometry"),
            (request(ADD, "sky", 1, square("sky", half=1e300)), "beyond the network's extent plus 20000 m"),
        ]
        for req, expected in cases:
            res = call(executor, spin_until, client, req)
            assert not res.accepted and expected in res.error, (expected, res.error)
            assert res.constraints == 1
        # nothing accepted before is lost, and the node still serves
        held = planner._projected_constraints()
        assert list(held) == ["hub"] and held["hub"].version == 1
        assert planner.constraint_updates_refused == len(cases)
        changed = call(executor, spin_until, client, request(CHANGE, "hub", 2, square("hub", version=2, half=100.0)))
        assert changed.accepted and planner._projected_constraints()["hub"].version == 2
        gone = call(executor, spin_until, client, request(WITHDRAW, "hub", 3, reason="event over"))
        assert gone.accepted and gone.constraints == 0
        # queued in the planning library, in order, for its next epoch (t = 0: none planned yet)
        assert [(u.action, u.t_s) for u in planner.planner.queued_updates] == [("add", 0.0), ("change", 0.0),
                                                                             ("withdraw", 0.0)]
    finally:
        executor.shutdown()
        planner.destroy_node()
        caller.destroy_node()


def test_an_update_takes_effect_at_the_next_epoch_and_is_published_latched(ros_context, spin_until, tmp_path):
    """A 500 m square over hub W7 (0-300 m, from t = 0 on) added while the graph runs: from the
    epoch it takes effect at, no approved plan enters it, the flights it affects get new versions
    naming it, the set is on uam/constraints (latched), and the recording's audit of what flew
    finds no incursion and no loss."""
    out = tmp_path / "live.mcap"
    executor, nodes, obs = build_graph(ros_context, rate=3.0, seed=5, duration_s=240.0, record_to=out,
                                       planner_extra={"authorities_file": str(AUTHORITIES)})
    sets: list[str] = []
    listener = rclpy.create_node("constraint_listener", context=ros_context)
    listener.create_subscription(String, c.TOPIC_CONSTRAINTS, lambda msg: sets.append(msg.data), qos.QOS_CONSTRAINTS)
    client = listener.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
    executor.add_node(listener)
    nodes["listener"] = listener
    planner, sim = nodes["planner"], nodes["simulator"]
    try:
        # after the first epochs: the update is accepted for the planner's next epoch
        assert spin_until(executor, lambda: planner.epochs_planned >= 2 and client.service_is_ready(), 60)
        res = call(executor, spin_until, client, request(ADD, "hub", 1, square()))
        assert res.accepted, res.error
        effective_s = m.from_time(res.effective_time)
        assert effective_s > 0 and effective_s % 30.0 == 0
        run_to_end(executor, nodes, obs, spin_until)
        assert spin_until(executor, lambda: len(sets) >= 2, 10)
    finally:
        shutdown(executor, nodes)
    # the start-up set (empty), then the set from the epoch the update took effect at
    t0, first = constraints_from_text(sets[0])
    assert (t0, first) == (0.0, [])
    net = load_network(TINY)
    t1, later = constraints_from_text(sets[-1], net)
    assert t1 == effective_s and [(k.constraint_id, eff) for k, eff in later] == [("hub", effective_s)]
    assert later[0][0].author == "caa"   # the recording names who changed the airspace
    cset = ConstraintSet([later[0][0]], net)
    approved = [p for p in obs.plans if p.outcome == FlightPlan.OUTCOME_APPROVED
                and p.epoch_index * 30.0 >= effective_s]
    assert approved, "no flight approved after the update: the test shows nothing"
    trajs = [m.trajectory_from_plan(p) for p in approved]
    which, _ = cset.violations(trajs)
    assert (which == -1).all(), "a plan approved after the update enters the constraint"
    assert sim.finished and not sim.error and sim.fly_errors == 0
    # the flights it affected: new versions from the epoch it took effect at, naming it
    updates = [p for p in obs.plans if p.version > 1]
    assert updates, "the square over the hub affected no flight: the test shows nothing"
    assert all(list(p.constraint_ids) == ["hub"] and m.from_time(p.effective_time) == effective_s
               and p.update_kind in ("rerouted", "retimed", "diverted", "cancelled", "contingency")
               and "'hub' v1" in p.reason for p in updates), [(p.update_kind, p.reason) for p in updates]
    assert sim.versions_received == len(updates)
    from uam_sim.audit.analysis import summarize
    s = summarize(out)
    assert s.verified, s.problems
    assert s.audit.ok and s.incursions == [] and s.constraints_in_force == 1
    assert sum(s.plan_updates.values()) == len(updates)
    assert s.airspace_changes == [f"hub v1 by caa: announced {effective_s:g} s, in force {effective_s:g} s .. end"]


def test_the_command_line_client_builds_the_request_from_a_feature_file(tmp_path):
    from uam_planner.nodes.constraint_client import build_request

    path = tmp_path / "one.geojson"
    path.write_text(json.dumps({"type": "FeatureCollection", "frame": "enu", "features": [json.loads(square())]}))
    req = build_request("add", str(path))
    assert (req.action, req.constraint_id, req.version, req.reason) == (ADD, "hub", 1, "event")
    assert json.loads(req.geojson)["properties"]["frame"] == "enu"
    gone = build_request("withdraw", constraint_id="hub", version=2, reason="over")
    assert (gone.action, gone.constraint_id, gone.version, gone.geojson) == (WITHDRAW, "hub", 2, "")
    two = tmp_path / "two.geojson"
    two.write_text(json.dumps({"type": "FeatureCollection", "features": [json.loads(square()), json.loads(square("b"))]}))
    with pytest.raises(ValueError, match="2 features; one update carries exactly one"):
        build_request("add", str(two))


def test_only_a_configured_authority_may_change_the_airspace_and_only_its_own_constraints(ros_context, spin_until):
    """Anyone on the domain can call uam/update_constraint: an unsigned update, one signed by an
    unknown key, one whose content was changed after signing, a replayed one and one from a
    planner without authorities are refused naming ``authorization``; a non-admin authority may
    not change or withdraw another's constraint; the set records each constraint's author and
    each withdrawal's."""
    planner = make_planner(ros_context, authorities_file=str(AUTHORITIES))
    bare = make_planner(ros_context)   # no authorities file: live updates off
    caller = rclpy.create_node("caller", context=ros_context)
    client = caller.create_client(UpdateConstraint, c.SERVICE_UPDATE_CONSTRAINT)
    sets: list[str] = []
    caller.create_subscription(String, c.TOPIC_CONSTRAINTS, lambda msg: sets.append(msg.data), qos.QOS_CONSTRAINTS)
    executor = SingleThreadedExecutor(context=ros_context)
    for n in (planner, caller):
        executor.add_node(n)
    try:
        assert spin_until(executor, client.service_is_ready, 20)
        unsigned = request(ADD, "hub", 1, square(), by=None)
        stranger_dir = _KEYS / "stranger"
        _f, stranger_key = write_authority(stranger_dir, "caa")   # claims to be caa, another key
        forged = request(ADD, "hub", 1, square(), by=None)
        forged.authorization = sign_update(forged, "add", "caa", stranger_key.read_bytes(), next(_SEQ))
        tampered = request(ADD, "hub", 1, square())
        tampered.geojson = square(half=20000.0)
        ok = request(ADD, "hub", 1, square())
        replay = UpdateConstraint.Request(action=ADD, constraint_id="hub", version=1, geojson=square(),
                                          reason="", authorization=ok.authorization)
        for req, expected in ((unsigned, "authorization: empty"), (forged, "not signed by 'caa'"),
                              (tampered, "claim sha256")):
            res = call(executor, spin_until, client, req)
            assert not res.accepted and expected in res.error, (expected, res.error)
        assert call(executor, spin_until, client, ok).accepted
        res = call(executor, spin_until, client, replay)   # read off the wire and sent again
        assert not res.accepted and "a replayed update" in res.error, res.error
        # the clinic may add its own and change it, not the caa's; the caa (admin) may change any
        assert call(executor, spin_until, client, request(ADD, "pad", 1, closure("pad"), by="clinic")).accepted
        res = call(executor, spin_until, client, request(CHANGE, "hub", 2, square("hub", version=2), by="clinic"))
        assert not res.accepted and "'hub' is caa's; 'clinic' may not change or withdraw it" in res.error, res.error
        res = call(executor, spin_until, client, request(WITHDRAW, "hub", 2, by="clinic"))
        assert not res.accepted and "may not change or withdraw it" in res.error
        assert call(executor, spin_until, client, request(CHANGE, "pad", 2, closure("pad", version=2),
                                                          by="clinic")).accepted
        assert call(executor, spin_until, client, request(WITHDRAW, "pad", 3, by="caa")).accepted
        held = planner._projected_constraints()
        assert list(held) == ["hub"] and held["hub"].author == "caa"
        # applied at the next epoch: the published set names the author and the withdrawal's
        with planner._lock:
            list(planner.planner.prepare_steps(0.0, 0))
            planner._publish_constraint_changes(0.0)
        assert spin_until(executor, lambda: any('"author":"caa"' in x for x in sets), 10), sets
        (_t, [(hub, _eff)]) = constraints_from_text(sets[-1], load_network(TINY))
        assert hub.author == "caa"
        assert [(w["id"], w["version"], w["by"]) for w in withdrawals_from_text(sets[-1])] == [("pad", 2, "caa")]
        executor.remove_node(planner)
        executor.add_node(bare)
        assert spin_until(executor, client.service_is_ready, 20)
        res = call(executor, spin_until, client, request(ADD, "x", 1, square("x")))
        assert not res.accepted and "no airspace authority is configured" in res.error, res.error
    finally:
        executor.shutdown()
        for n in (planner, bare, caller):
            n.destroy_node()
