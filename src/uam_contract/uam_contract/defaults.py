"""The paper's model in numbers: each default defined once, here ("one source for every
default").

The planning library (``uam_planner.planning.PlanningConfig``, ``AirspaceConfig``,
``uam_planner.separation``), the in-process runner (``uam_sim.runner.experiment_config``), the audit and
the analysis, the node parameter tables (``uam_contract.params``) and the launcher table
(``uam_contract.launch_options``, which ``scripts/run_fleet.sh`` and the launch file are held to
by ``test/test_launchers.py``) read these names. The YAML files in ``config/`` cannot import
Python, so ``src/uam_sim/test/test_one_source_for_defaults.py`` holds them to these values and to
the parameter tables, and fails on drift.

Times in seconds, distances in metres, speeds in m/s (the paper's values: Haba et al. 2025).
"""

from __future__ import annotations

#: separation minimum [m]: the paper's sphere radius, or the cylinder's horizontal minimum H
SEPARATION_M = 100.0
#: the cylinder's vertical minimum V [m] (unused by the paper's sphere)
VERTICAL_SEPARATION_M = 30.0
#: departure slot [s]; 0 = the paper's rule (depart at the epoch time)
DEPARTURE_SLOT_S = 0.0
#: vertical climb and descent rates at the vertiports of a layered network [m/s]
CLIMB_RATE_MPS = 5.0
DESCENT_RATE_MPS = 3.0
#: planning epoch [s], and the demand interval the request rate is counted over [s]
EPOCH_S = 30.0
INTERVAL_S = 30.0
#: latest departure = request time + WINDOW_S [s]
WINDOW_S = 60.0
#: candidate routes per request, and the penalised Dijkstra factor that makes them diverse
K = 5
PENALTY_FACTOR = 5.0
#: cruise speed [m/s]
SPEED_MPS = 10.0
#: the largest per-flight airspeed error bound (a share of the plan's speed): the simulator keeps
#: the ground speed at least 20 % of the airspeed, so the bound stays below 0.8; the simulator's
#: parameter table and the disturbance model (the Monte-Carlo's) refuse a larger one alike
SPEED_ERROR_MAX = 0.79


def as_text(value: float) -> str:
    """A default as a launcher writes it (``100.0`` -> ``"100"``; run_fleet.sh, launch file)."""
    return f"{value:g}"
