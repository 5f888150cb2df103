"""First-call costs of the backends, paid once per process and counted inside a time limit.

The first solve with a backend in a process imports its library and sets it up before it
solves: measured on a quiet machine, OR-Tools ~0.3 s (``exact``, ``auto``), dwave-samplers
0.15-0.2 s (``sa``, ``tabu``), dwave-system and minorminer ~0.75 s (``qpu-emulator``); under
load several times that. Counted outside the limit, that made a cold process's first solve
overrun it.

* :func:`warm_up` pays these costs now, for the backends a run may use: what a node or the
  runner calls at start (through :func:`uam_solvers.warm_up`, which with ``service=True``
  also starts and warms the process's shared solve service,
  :func:`uam_solvers.executor.shared_service`).
* :func:`start_up` is what :func:`uam_solvers.solve` calls first: nothing when the backend is
  warm (the backend then gets the whole limit, as before), otherwise the warm-up on a guard
  thread, waited for at most until the deadline; the solve then gets the time left.

Each backend's warm-up is its :meth:`uam_solvers.base.Backend.warm_up` (an availability check
that imports its library and, for the local backends, one solve of a four-vertex graph). A
backend is warm once its warm-up ended, whether it succeeded or not (an unavailable backend's
solve says why).
"""
from __future__ import annotations

import logging
import threading
import time
from typing import Iterable

from .base import Backend

__all__ = ["warm_up", "start_up", "is_warm"]

log = logging.getLogger("uam_solvers")

#: backend name (or Backend class, for an instance) -> seconds its warm-up took
_WARM: dict = {}
#: warm-ups under way: key -> Event set when it ends
_WARMING: dict = {}
_LOCK = threading.Lock()


def _key(backend: str | Backend):
    return backend if isinstance(backend, str) else type(backend)


def _label(backend: str | Backend) -> str:
    return backend if isinstance(backend, str) else backend.name


def is_warm(backend: str | Backend) -> bool:
    """Whether ``backend`` (a name, or an instance: its class) has been warmed in this process."""
    return _key(backend) in _WARM


def _warm_now(backend: str | Backend) -> None:
    """Warm ``backend`` in this thread unless it is warm; a warm-up of it already under way
    (another thread's) is waited for instead of repeated."""
    key = _key(backend)
    with _LOCK:
        if key in _WARM:
            return
        event = _WARMING.get(key)
        owner = event is None
        if owner:
            event = _WARMING[key] = threading.Event()
    if not owner:
        event.wait()
        return
    t0 = time.perf_counter()
    try:
        if isinstance(backend, str):
            from .registry import get_backend

            backend = get_backend(backend)
        backend.warm_up()
    except Exception as exc:  # noqa: BLE001 - the solve that needs it reports the failure
        log.debug("warm-up of backend %r: %s: %s", _label(backend), type(exc).__name__, exc)
    finally:
        with _LOCK:
            _WARM[key] = time.perf_counter() - t0
            del _WARMING[key]
        event.set()


def warm_up(backends: Iterable[str | Backend] = ("auto",)) -> dict[str, float]:
    """Pay the first-call costs of ``backends`` (names or instances) in this process now.

    Call it at start-up with every backend the run may use, so that no solve spends its time
    limit on imports and set-up. Thread-safe; a backend already warm costs nothing.

    Returns the wall time spent per backend name [s] (about 0 for one already warm). Raises
    UnknownBackendError for an unknown name, before warming anything.
    """
    from .registry import check_name

    backends = list(backends)
    for b in backends:
        if isinstance(b, str):
            check_name(b)
        elif not isinstance(b, Backend):
            raise TypeError(f"backends: {b!r} is neither a backend name nor a Backend")
    spent: dict[str, float] = {}
    for b in backends:
        t0 = time.perf_counter()
        _warm_now(b)
        spent[_label(b)] = time.perf_counter() - t0
    return spent


def start_up(backend: str | Backend, deadline: float) -> float | None:
    """Make ``backend`` warm before a solve, waiting at most until ``deadline`` (a
    ``time.perf_counter()`` value).

    Returns 0.0 when it was warm already (nothing was spent), the seconds spent warming it,
    or None when the deadline came first: the warm-up goes on in the background (a daemon
    thread) and a later solve finds the backend warm. Raises UnknownBackendError for an
    unknown name.
    """
    if _key(backend) in _WARM:
        return 0.0
    if isinstance(backend, str):
        from .registry import check_name

        check_name(backend)
    t0 = time.perf_counter()
    done = threading.Event()

    def run() -> None:
        try:
            _warm_now(backend)
        finally:
            done.set()

    threading.Thread(target=run, name="uam-solvers-warm-up", daemon=True).start()
    if not done.wait(max(deadline - time.perf_counter(), 0.0)):
        return None
    return time.perf_counter() - t0
