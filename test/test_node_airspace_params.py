"""The planner node's airspace parameters (issue 10): checked at start-up, read-only, and what the
planner plans with; the defaults are the paper's model."""

from __future__ import annotations

import pytest

rclpy = pytest.importorskip("rclpy", reason="needs the built workspace (scripts/test.sh sources it)")
from rclpy.parameter import Parameter  # noqa: E402

from graph_harness import make_planner  # noqa: E402
from uam_planner.planning import AirspaceConfig  # noqa: E402
from uam_planner.separation import SeparationModel  # noqa: E402

pytestmark = pytest.mark.ros


def test_defaults_are_the_paper_model_and_the_parameters_reach_the_planner(ros_context):
    paper = make_planner(ros_context)
    try:
        assert paper.config.airspace == AirspaceConfig()
    finally:
        paper.destroy_node()
    planner = make_planner(ros_context, separation_model="cylinder", vertical_separation_m=25.0,
                           departure_slot_s=5.0, climb_rate_mps=4.0, descent_rate_mps=2.0)
    try:
        assert planner.config.separation == SeparationModel("cylinder", 100.0, 25.0)
        assert planner.config.airspace == AirspaceConfig("cylinder", 25.0, 5.0, 4.0, 2.0)
        # read at start-up only: a change at run time is refused with the parameter named
        res = planner.set_parameters([Parameter("departure_slot_s", value=10.0)])[0]
        assert not res.successful and "departure_slot_s" in res.reason
        assert planner.config.airspace.departure_slot_s == 5.0
    finally:
        planner.destroy_node()


@pytest.mark.parametrize("name, value, words", [
    ("separation_model", "cube", "'cube' is not one of '', sphere, cylinder"),
    ("departure_slot_s", -5.0, "below the minimum"),
    ("vertical_separation_m", 0.0, "below the minimum"),
])
def test_bad_airspace_values_are_refused_at_start_up_naming_the_parameter(ros_context, name, value, words):
    with pytest.raises(ValueError) as err:
        make_planner(ros_context, **{name: value})
    assert name in str(err.value) and words in str(err.value)
