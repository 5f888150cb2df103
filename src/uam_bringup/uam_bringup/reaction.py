"""The node graph's reaction between epochs (issue 23, docs/disturbances.md): the service name and
the instants at which the planner takes its own observations in that mode. Here, beside the
other rclpy glue, because ``uam_contract`` is run code (its version keys the studies' cells):
once no study is running, ``SERVICE_REACT`` belongs in ``uam_contract.names`` (beside
``SERVICE_PLAN_EPOCH``, as a literal) and this module's constants with it.
"""

from __future__ import annotations

from uam_contract import names as _names

#: the simulator asks the planner to react between epochs (``uam_msgs/srv/React``): ``uam/react``,
#: in the contract's namespace (the epoch protocol's; relative, so a launch namespace moves it too)
SERVICE_REACT = _names.SERVICE_PLAN_EPOCH.rsplit("/", 1)[0] + "/react"

#: before an epoch at t the planner observes every flight airborne at t at t - 20, t - 10 and t:
#: the in-process runner's monitor (``uam_sim.scenario._Reaction.OBSERVE_BACK_S``, held equal by
#: test/test_node_reaction_between.py); between epochs, at the reaction instant only
OBSERVE_BACK_S = (20.0, 10.0, 0.0)


def stamp_key(t_s: float) -> int:
    """A simulation time as an integer number of microseconds: fleet states are looked up by it."""
    return int(round(float(t_s) * 1e6))
