"""The node graph's reaction between epochs (docs/disturbances.md): the instants at
which the planner takes its own observations in that mode (the service's name is
``uam_contract.names.SERVICE_REACT``).
"""

from __future__ import annotations

#: before an epoch at t the planner observes every flight airborne at t at t - 20, t - 10 and t:
#: the in-process runner's monitor (``uam_sim.runner.scenario._Reaction.OBSERVE_BACK_S``, held equal by
#: test/test_node_reaction_between.py); between epochs, at the reaction instant only
OBSERVE_BACK_S = (20.0, 10.0, 0.0)


def stamp_key(t_s: float) -> int:
    """A simulation time as an integer number of microseconds: fleet states are looked up by it."""
    return int(round(float(t_s) * 1e6))
