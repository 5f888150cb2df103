"""Find MWIS backends by name.

Two sources, like a setuptools plugin table (Nav2's planner plugins in Python form):

- the built-in table :data:`BUILTIN_BACKENDS`, name -> ``"module:Class"``, imported lazily so a
  backend whose optional dependency is missing does not break the others;
- third-party backends advertised in the ``importlib.metadata`` entry-point group
  ``uam_solvers.backends`` (entry-point name = backend name, value = ``module:Class``). A built-in
  name wins over an entry point of the same name;
- backends registered at run time with :func:`register_backend` (a class or ``"module:Class"``;
  a plugin's own module, or a test): the same lookup as an entry point (docs/extending.md).

CLI: ``python -m uam_solvers.registry`` prints one line per backend.
"""
from __future__ import annotations

import functools
import importlib
import sys
from importlib import metadata

from .base import Backend

__all__ = ["BUILTIN_BACKENDS", "ENTRY_POINT_GROUP", "UnknownBackendError", "backend_class",
           "check_name", "get_backend", "register_backend", "unregister_backend",
           "list_backends", "backend_names", "sampling_backends", "PARAM_RULES", "backend_problem",
           "backend_name_problem"]

ENTRY_POINT_GROUP = "uam_solvers.backends"

BUILTIN_BACKENDS: dict[str, str] = {
    "auto": "uam_solvers.auto:AutoBackend",
    "greedy": "uam_solvers.greedy:GreedyBackend",
    "exact": "uam_solvers.cpsat:CpSatBackend",
    "kamis": "uam_solvers.chszla:KamisBackend",
    "chils": "uam_solvers.chszla:ChilsBackend",
    "gurobi": "uam_solvers.gurobi_backend:GurobiBackend",
    "sa": "uam_solvers.annealing:SimulatedAnnealingBackend",
    "tabu": "uam_solvers.annealing:TabuBackend",
    "qpu": "uam_solvers.qpu:QpuBackend",
    "qpu-emulator": "uam_solvers.qpu:QpuEmulatorBackend",
}


class UnknownBackendError(KeyError):
    """No backend of that name; the message lists the known names."""

    def __str__(self) -> str:  # KeyError would quote the whole message
        return str(self.args[0]) if self.args else ""


@functools.lru_cache(maxsize=1)
def _entry_points() -> dict[str, str]:
    """Entry points of the group, scanned once per process (scanning costs ~20 ms);
    ``_entry_points.cache_clear()`` rescans."""
    try:
        eps = metadata.entry_points(group=ENTRY_POINT_GROUP)
    except Exception:  # noqa: BLE001 - a broken installed distribution must not break lookup
        return {}
    return {ep.name: ep.value for ep in eps}


#: backends registered at run time (:func:`register_backend`): name -> class or "module:Class"
_REGISTERED: dict = {}


def register_backend(name: str, target) -> None:
    """Register a backend class (or ``"module:Class"``) under ``name`` for this process; a
    built-in name cannot be taken (ValueError naming it). In a process pool the workers see it
    when they import the module that registers it."""
    if not isinstance(name, str) or not name or name in BUILTIN_BACKENDS:
        raise ValueError(f"backend name: {name!r} is empty or a built-in backend's")
    if not (isinstance(target, str) or (isinstance(target, type) and issubclass(target, Backend))):
        raise ValueError(f"backend {name!r}: {target!r} is neither a Backend subclass nor 'module:Class'")
    _REGISTERED[name] = target


def unregister_backend(name: str) -> None:
    _REGISTERED.pop(name, None)


def _table() -> dict:
    table = dict(_entry_points())
    table.update(_REGISTERED)
    table.update(BUILTIN_BACKENDS)
    return table


def backend_names() -> list[str]:
    """All known backend names (built-in first, then entry points and run-time registrations,
    sorted)."""
    extra = sorted({*_entry_points(), *_REGISTERED} - set(BUILTIN_BACKENDS))
    return list(BUILTIN_BACKENDS) + extra


def _load(target) -> type:
    if isinstance(target, type):
        return target
    module_name, _, attr = target.partition(":")
    module = importlib.import_module(module_name)
    obj = module
    for part in attr.split("."):
        obj = getattr(obj, part)
    return obj  # type: ignore[return-value]


def check_name(name: str) -> None:
    """Raise :class:`UnknownBackendError` listing the known names when no backend is called
    ``name`` (no module is imported)."""
    if not isinstance(name, str) or name not in _table():
        raise UnknownBackendError(
            f"backend: unknown name {name!r}; known backends: {', '.join(backend_names())}"
        )


def get_backend(name: str) -> Backend:
    """A fresh instance of the backend called ``name``.

    Raises :class:`UnknownBackendError` (a KeyError) listing the known names when ``name`` is not
    registered, and ImportError when the backend's module fails to import. An instance of an
    unavailable backend is returned; its ``solve`` raises BackendUnavailable with the reason.
    """
    check_name(name)
    table = _table()
    cls = _load(table[name])
    backend = cls()
    if not isinstance(backend, Backend):
        raise TypeError(f"backend {name!r}: {table[name]} is not a uam_solvers Backend")
    return backend


def backend_class(name: str) -> type:
    """The class of the backend called ``name``, not instantiated (its traits are class
    attributes: ``Backend.samples``, ...). UnknownBackendError as :func:`get_backend`."""
    check_name(name)
    return _load(_table()[name])


def sampling_backends() -> tuple[str, ...]:
    """The names of the backends that sample (``Backend.samples``), in :func:`backend_names`
    order; a backend whose module does not import is left out (it cannot run here)."""
    out = []
    for name in backend_names():
        try:
            if getattr(backend_class(name), "samples", False):
                out.append(name)
        except ImportError:
            continue
    return tuple(out)


def list_backends() -> list[tuple[str, str, bool, str]]:
    """``(name, description, available, reason)`` for every known backend.

    A backend whose module cannot be imported is listed as unavailable with the import error.
    """
    rows = []
    table = _table()
    for name in backend_names():
        try:
            backend = get_backend(name)
            ok, reason = backend.available()
            rows.append((name, backend.description, bool(ok), reason))
        except Exception as exc:  # noqa: BLE001 - listing must survive any one broken backend
            rows.append((name, f"({table[name]})", False, f"{type(exc).__name__}: {exc}"))
    return rows


def format_backend_table() -> str:
    """One line per backend: name, [available|unavailable: reason], description."""
    rows = list_backends()
    width = max((len(r[0]) for r in rows), default=4)
    lines = []
    for name, desc, ok, reason in rows:
        status = "available" if ok else f"unavailable ({reason})"
        lines.append(f"{name:<{width}}  {desc}  [{status}]")
    return "\n".join(lines)


def backend_problem(name) -> str:
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
    try:
        get_backend(name)
    except (UnknownBackendError, TypeError):
        return f"unknown backend {name!r}; known: {', '.join(backend_names())}"
    return ""


#: the parameter rules the nodes' tables name (``Param.rule``): name -> value -> '' or the reason
PARAM_RULES = {"backend_name": backend_name_problem, "backend_available": backend_problem}


def main(argv: list[str] | None = None) -> int:
    """``python -m uam_solvers.registry [list]``: print the backends, one line each."""
    args = list(sys.argv[1:] if argv is None else argv)
    if args and args[0] not in ("list",):
        print("usage: python -m uam_solvers.registry [list]", file=sys.stderr)
        return 2
    print(format_backend_table())
    return 0


if __name__ == "__main__":
    sys.exit(main())

