"""Parameter rules that need the backend registry, for the nodes that declare ``backend``
parameters (``Param.rule`` in :mod:`uam_contract.params`: "backend_name", "backend_available");
the rules themselves live in :mod:`uam_solvers.registry` (library code checks with them too)."""

from __future__ import annotations

from uam_solvers.registry import PARAM_RULES, backend_name_problem, backend_problem

#: the rules the planner's and the solver's tables name
RULES = dict(PARAM_RULES)

__all__ = ["RULES", "backend_name_problem", "backend_problem"]
