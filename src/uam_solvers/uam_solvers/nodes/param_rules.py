"""Parameter rules that need the backend registry, for the nodes that declare ``backend``
parameters (``Param.rule`` in :mod:`uam_contract.params`: "backend_name", "backend_available")."""

from __future__ import annotations


def backend_problem(name) -> str:
    from uam_solvers.registry import UnknownBackendError, backend_names, get_backend

    if not isinstance(name, str) or not name:
        return f"{name!r} is not a backend name; known: {', '.join(backend_names())}"
    try:
        backend = get_backend(name)
    except UnknownBackendError:
        return f"unknown backend {name!r}; known: {', '.join(backend_names())}"
    ok, reason = backend.available()
    return "" if ok else f"backend {name!r} is unavailable here: {reason}"


def backend_name_problem(name) -> str:
    """Known name (availability is the solver's business: it may run on another machine)."""
    from uam_solvers.registry import UnknownBackendError, backend_names, get_backend

    try:
        get_backend(name)
    except (UnknownBackendError, TypeError):
        return f"unknown backend {name!r}; known: {', '.join(backend_names())}"
    return ""



#: the rules the planner's and the solver's tables name
RULES = {"backend_name": backend_name_problem, "backend_available": backend_problem}
