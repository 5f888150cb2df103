"""Priority by grant (uam_planner.grants): a request above its operator's granted class is
refused by the planning library, naming the field, the value and the grant."""

from __future__ import annotations

import pytest

from uam_planner.grants import PriorityGrants
from uam_planner.network import network_from_enu
from uam_planner.planning import FlightRequest, Planner, PlanningConfig


def _planner(grants):
    net = network_from_enu("ab", ["A", "B"], [(0.0, 0.0, 0.0), (1000.0, 0.0, 0.0)], [True, True], [("A", "B")])
    return Planner(net, PlanningConfig(priority_grants=grants))


def _request(rid, operator, priority):
    return FlightRequest(rid, "A", "B", 0.0, 0.0, 60.0, priority=priority, operator_id=operator)


def test_a_class_above_the_grant_is_refused_naming_it_and_nothing_else_changes(tmp_path):
    path = tmp_path / "grants.yaml"
    path.write_text("default: 0\noperators:\n  medevac: 200\n")
    grants = PriorityGrants.load(path)
    p = _planner(grants)
    assert p.submit(_request("a", "medevac", 200)) is None
    assert p.submit(_request("b", "medevac", 201)) == ("priority: 201 is above operator 'medevac''s grant 200 "
                                                       "(priority_grants: the classes each operator may ask for)")
    assert "operator 'anyone''s grant 0" in p.submit(_request("c", "anyone", 1))
    assert p.submit(_request("d", "anyone", 0)) is None
    assert [r.request_id for r in p.pending] == ["a", "d"]
    # without grants every class is taken (the paper's runs)
    assert _planner(None).submit(_request("e", "anyone", 255)) is None


@pytest.mark.parametrize("text, why", [
    ("default: 300\n", "default: 300 is not a priority class 0..255"),
    ("operators:\n  x: -1\n", "operators.x: -1 is not a priority class"),
    ("operators: [1, 2]\n", "is not a mapping of operator id to class"),
    ("grant: 3\n", "unknown key(s) grant"),
])
def test_a_bad_grants_file_is_refused_naming_the_entry(tmp_path, text, why):
    path = tmp_path / "g.yaml"
    path.write_text(text)
    with pytest.raises(ValueError, match="priority_grants: ") as err:
        PriorityGrants.load(path)
    assert why in str(err.value)


def test_grants_written_and_read_back(tmp_path):
    p = tmp_path / "ok.yaml"
    p.write_text(PriorityGrants(0, {"generator": 1}).as_yaml())
    back = PriorityGrants.load(p)
    assert (back.grant("generator"), back.grant("x")) == (1, 0)
