"""Planner.modify: an operator's new version of its approved flight, decided at the next epoch
(a PlanUpdate of kind 'modified', version + 1, the same request id), or refused with the
previous version kept; what cannot be modified is refused naming the field."""

from uam_planner.network import load_network
from uam_planner.planning import FlightRequest, Planner, PlanningConfig
from uam_planner.replanning import KIND_MODIFIED
from uam_solvers import solve

TINY = __file__.rsplit("/src/", 1)[0] + "/config/networks/tiny.yaml"


def planner_with_a_reservation():
    """A planner with flight x (A -> B) reserved at the epoch at 60 s to depart at 150 s."""
    pl = Planner(load_network(TINY), PlanningConfig(horizon_epochs=4, commit_ahead=True),
                 solve_mwis=lambda w, e, g: solve(w, e, groups=g, backend="greedy"))
    assert pl.submit(FlightRequest("x", "A", "B", 45.0, 150.0, 445.0, operator_id="op")) is None
    assert [f.request_id for f in pl.plan(60.0, 2).approved] == ["x"]
    return pl


def test_a_modification_is_a_new_version_of_the_same_request():
    pl = planner_with_a_reservation()
    old = pl.flight("x")
    assert pl.modify(FlightRequest("x", "B", "A", 70.0, 130.0, 470.0, operator_id="op"), 90.0) is None
    r = pl.plan(90.0, 3)
    assert r.approved == [] and r.refused_modifications == {}
    (u,) = r.plan_updates
    assert (u.request_id, u.kind, u.version, u.previous) == ("x", KIND_MODIFIED, old.version + 1, old)
    new = pl.flight("x")
    assert new is u.flight and (new.origin_id, new.destination_id, new.effective_s) == ("B", "A", 90.0)
    assert [f.request_id for f in pl.active] == ["x"]


def test_a_modification_with_no_candidate_at_its_epoch_keeps_the_previous_version():
    pl = planner_with_a_reservation()
    old = pl.flight("x")
    # a window beyond the horizon of the next epoch: no candidate there
    assert pl.modify(FlightRequest("x", "B", "A", 70.0, 400.0, 470.0, operator_id="op"), 90.0) is None
    r = pl.plan(90.0, 3)
    why, kept = r.refused_modifications["x"]
    assert kept and "previous version stays in force" in why and r.plan_updates == []
    assert pl.flight("x") is old and not pl.pending


def test_what_cannot_be_modified_is_refused_naming_the_field():
    pl = planner_with_a_reservation()
    assert "is not an approved flight" in pl.modify(FlightRequest("y", "A", "B", 70.0, 130.0, 470.0), 90.0)
    assert "departed at 150 s" in pl.modify(FlightRequest("x", "B", "A", 70.0, 160.0, 470.0), 180.0)
    assert "destination_id: 'A' is the same as origin_id" in pl.modify(
        FlightRequest("x", "A", "A", 70.0, 130.0, 470.0), 90.0)
    assert pl.modify(FlightRequest("x", "B", "A", 70.0, 130.0, 470.0), 90.0) is None
    assert "modification waiting" in pl.modify(FlightRequest("x", "B", "C", 70.0, 130.0, 470.0), 90.0)
    # cancelled before its epoch: the modification goes with it
    assert pl.cancel("x", 90.0) is None
    r = pl.plan(90.0, 3)
    assert [(u.kind, u.version) for u in r.plan_updates] == [("cancelled", 2)] and pl.flight("x") is None
