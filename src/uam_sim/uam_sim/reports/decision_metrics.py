"""Kept for existing imports: the decision metrics (delay, detour, priorities, operator shares)
are computed by :func:`uam_sim.world.flights.run_metrics`, the one implementation the runner, the
analysis and the report share (``decision_metrics`` is that function)."""

from ..world.flights import jain_index, run_metrics as decision_metrics

__all__ = ["decision_metrics", "jain_index"]
