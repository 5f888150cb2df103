"""The uss node with a DSS (dss_url): a flight planned through InterUSS's flight_planning
interface gets its operational intent reference in the DSS before the answer comes back, the
served reference is the DSS's (its version and OVN), and the reference is deleted with the
flight plan. The DSS is the stand-in (uam_sim.f3548.dss_standin) on a loopback socket, not an
InterUSS DSS."""

from __future__ import annotations

import threading

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")
requests = pytest.importorskip("requests")

from graph_harness import TINY, build_graph, params, shutdown  # noqa: E402
from test_node_uss_flight_planning import FID, OP, call, upsert  # noqa: E402
import flask  # noqa: E402,F401  the uss node's server, imported before any node's start-up thread
# imports the solvers (two threads importing werkzeug at once raised KeyError 'werkzeug')

pytestmark = [pytest.mark.ros, pytest.mark.slow]


@pytest.fixture
def standin_dss(tmp_path):
    """The stand-in DSS on 127.0.0.1 (a free port), trusting the development key pair it
    returns: (url, the stand-in's state, private key, public key)."""
    from werkzeug.serving import make_server

    from uam_sim.f3548.auth import TokenVerifier, generate_dev_keys
    from uam_sim.f3548.dss_standin import create_app
    private, public = generate_dev_keys(tmp_path / "keys")
    app = create_app(TokenVerifier.from_file(public, ("127.0.0.1",)))
    server = make_server("127.0.0.1", 0, app, threaded=True)
    thread = threading.Thread(target=server.serve_forever, kwargs={"poll_interval": 0.05}, daemon=True)
    thread.start()
    yield f"http://127.0.0.1:{server.server_port}", app.dss, private, public
    server.shutdown()
    thread.join(timeout=5)


def test_a_planned_flight_is_referenced_in_the_dss_and_served_with_its_ovn(ros_context, spin_until, tmp_path,
                                                                          standin_dss):
    from uam_planner.authority import write_authority
    from uam_planner.f3548 import intent_id
    from uam_sim.f3548.auth import mint_token
    from uam_sim.f3548.flight_planning import PREFIX, SCOPE_PLAN
    from uam_sim.f3548.uss_server import SCOPE_INTENTS
    from uam_sim.nodes.uss_node import UssNode

    dss_url, dss, private, public = standin_dss
    listing, _caa = write_authority(tmp_path / "auth", "caa")
    _listing, uss_key = write_authority(tmp_path / "auth", "uss-peers", admin=False, add=True, operators=[OP])
    user = {"Authorization": f"Bearer {mint_token(private, 'localhost', [SCOPE_PLAN, SCOPE_INTENTS])}"}
    journal = tmp_path / "planner-journal.jsonl"
    executor, nodes, obs = build_graph(
        ros_context, rate=0.3, duration_s=900.0, backend="greedy",
        planner_extra={"authorities_file": str(listing), "journal": str(journal), "horizon_epochs": 4,
                       "commit_ahead": True, "intent_volume_piece_s": 5.0},
        simulator_extra={"mode": "realtime", "real_time_factor": 15.0})
    # one development key signs the tokens of the DSS, of this USS's server and of its callers
    uss = UssNode(context=ros_context, parameter_overrides=params(
        port=0, network=TINY, auth_key=str(public), journal=str(journal), authority_key=str(uss_key),
        dss_url=dss_url, dss_dev_key=str(private), dss_subject="uss1", dss_retry_s=0.5))
    nodes["uss"] = uss
    executor.add_node(uss)
    base, planner, sim = uss.server.url, nodes["planner"], nodes["simulator"]
    ctx, net = uss.store.ctx, uss.network
    oid = intent_id(OP, FID)
    try:
        assert spin_until(executor, lambda: planner.epochs_planned >= 1 and uss.decider.ready(), timeout_s=60)
        t = sim.t_s
        r = call(executor, spin_until, lambda: requests.put(
            f"{base}{PREFIX}/flight_plans/{FID}", json=upsert(ctx, net, "r1", t + 150.0, t + 400.0),
            headers=user, timeout=60))
        got = r.json()
        assert (got["planning_result"], got["flight_plan_status"]) == ("Completed", "Planned"), got
        # the answer came after the DSS's reference: there now, managed by this USS, Accepted
        ref = dss.intents[oid].doc
        assert (ref["manager"], ref["state"], ref["uss_base_url"]) == ("uss1", "Accepted", base)
        served = requests.get(f"{base}/uss/v1/operational_intents/{oid}", headers=user, timeout=10).json()
        assert served["operational_intent"]["reference"] == ref     # version, OVN, subscription: the DSS's
        # the generator's flights are served, so referenced, too; none refused, none failed
        stats = uss.dss_sync.stats
        assert stats["created"] >= 1 and stats["failures"] == 0 and stats["conflicts"] == 0, stats
        assert all(e.manager == "uss1" for e in dss.intents.values())

        r = call(executor, spin_until, lambda: requests.delete(f"{base}{PREFIX}/flight_plans/{FID}", headers=user,
                                                               timeout=60))
        assert r.status_code == 200 and r.json()["flight_plan_status"] == "Closed"
        assert oid not in dss.intents   # the answer came after the delete
        assert uss.dss_sync.stats["deleted"] >= 1 and stats["failures"] == 0
    finally:
        shutdown(executor, nodes)
        uss.close()


def test_without_dss_url_no_dss_is_called(ros_context, tmp_path):
    """The default (dss_url '') is the node as it was: no sync, nothing woken by the store."""
    from uam_sim.f3548.auth import generate_dev_keys
    from uam_sim.nodes.uss_node import UssNode
    _private, public = generate_dev_keys(tmp_path / "keys")
    uss = UssNode(context=ros_context, parameter_overrides=params(port=0, network=TINY, auth_key=str(public)))
    try:
        assert uss.dss_sync is None and uss.store.on_change is None
    finally:
        uss.close()
        uss.destroy_node()
