"""MWIS solver backends behind one interface.

Quick use::

    from uam_solvers import solve
    result = solve(weights, edges, groups=[[0, 1, 2]], backend="exact", time_limit_s=1.0)
    result.selected, result.objective, result.proven_optimal, result.fallback

The default pipeline is ``ValidateFallback(Reduce(ComponentSplit(backend)))``: split the conflict
graph into connected components, apply exact reductions, solve what is left with the named
backend, then check the answer is an independent set of the input graph and fall back to greedy
when it is not (or the backend raised or ran past its time limit).

Backend ``auto`` (:mod:`uam_solvers.auto`) picks KaMIS, CP-SAT or CHILS by size and claims
optimality only when proven. Options are declared per backend (``backend.options_spec``,
dimod-style ``backend.parameters``); an unknown or malformed option is an MwisInputError.

Deadlines hold for every backend, from a cold process too: ``solve`` and ``solve_bounded``
answer within ``time_limit_s`` + 0.5 s. The first solve with a backend in a process pays its
import and set-up inside the limit (:mod:`uam_solvers.warmup`; :func:`warm_up` pays it at
start instead). ``solve`` runs backends that release the GIL in this process under a guard
thread, and the others (KaMIS, CHILS, ``auto``, the QPU paths, third-party backends) above
their ``inline_max_vertices`` in a forked child process killed at the limit + 0.3 s
(:func:`uam_solvers.executor.solve_in_child`). ``solve_bounded`` goes through the process's
shared :class:`uam_solvers.executor.SolveService` (warm worker processes, what the in-process
runner and the planner's default solve call) once it is started; until then, as ``solve``.
"""
from __future__ import annotations

import os
import threading
import time

# chszlablib (KaMIS, CHILS, learn-and-reduce) runs on its bundled libgomp, which reads this when
# it loads. A libgomp thread pool made in a process (any CHILS call there, e.g. a warm-up) hangs
# every child forked from it (solve_in_child forks one per large solve): after
# warm_up(["chils"]) each 150-vertex 'auto' solve was killed at its limit and answered by the
# greedy fallback. One thread keeps the forks sound; CHILS's default num_concurrent is 1, so
# its answers do not change. A caller who sets OMP_NUM_THREADS keeps it (and the hang).
os.environ.setdefault("OMP_NUM_THREADS", "1")
from typing import Any, Mapping, Sequence

from .base import (
    Backend,
    BackendUnavailable,
    MwisInputError,
    MwisProblem,
    MwisResult,
    check_selection,
)

# The registry is imported lazily so ``python -m uam_solvers.registry`` runs without a warning.


def get_backend(name: str) -> Backend:
    """A fresh instance of the backend called ``name`` (see :func:`uam_solvers.registry.get_backend`)."""
    from .registry import get_backend as _get

    return _get(name)


def list_backends() -> list[tuple[str, str, bool, str]]:
    """``(name, description, available, reason)`` per backend (see :mod:`uam_solvers.registry`)."""
    from .registry import list_backends as _list

    return _list()


def warm_up(backends=("auto",), *, service: bool = False) -> dict[str, float]:
    """Pay the first-call costs of ``backends`` (names or instances) in this process now (see
    :mod:`uam_solvers.warmup`): call it at start-up with every backend a run may use, so that
    no solve spends its time limit on imports and set-up; ``service=True`` starts and warms the
    shared solve service of :func:`solve_bounded` too (its worker processes, 1-3 s). Returns
    the seconds spent per backend name [s], and under ``"service"`` the service's start.
    Raises UnknownBackendError for an unknown name, before warming anything.

    Examples:
        >>> from uam_solvers import warm_up
        >>> sorted(warm_up(["greedy", "exact"]))
        ['exact', 'greedy']
    """
    from .warmup import warm_up as _warm_up

    spent = _warm_up(backends)
    if service:
        from .executor import shared_service

        t0 = time.perf_counter()
        shared_service()
        spent["service"] = time.perf_counter() - t0
    return spent


def __getattr__(attr: str):
    if attr == "UnknownBackendError":
        from .registry import UnknownBackendError

        return UnknownBackendError
    if attr == "SolveService":
        from .executor import SolveService

        return SolveService
    raise AttributeError(f"module 'uam_solvers' has no attribute {attr!r}")

__all__ = [
    "Backend",
    "BackendUnavailable",
    "MwisInputError",
    "MwisProblem",
    "MwisResult",
    "UnknownBackendError",
    "SolveService",
    "check_selection",
    "get_backend",
    "list_backends",
    "build_pipeline",
    "solve",
    "solve_problem",
    "solve_bounded",
    "warm_up",
]


def build_pipeline(backend: str | Backend, layers: bool = True) -> Backend:
    """The default pipeline around ``backend`` (a name or an instance).

    ``layers=True``: ValidateFallback(Reduce(ComponentSplit(backend))); ``layers=False``:
    ValidateFallback(backend) - validation is never skipped. Raises UnknownBackendError for an
    unknown name and BackendUnavailable when the backend cannot run here.
    """
    from .layers import ComponentSplit, Reduce, ValidateFallback

    inner = get_backend(backend) if isinstance(backend, str) else backend
    inner.require_available()
    if layers:
        inner = Reduce(ComponentSplit(inner))
    return ValidateFallback(inner)


#: backends whose instances hold no state between solves (checked: their attributes are set in
#: ``__init__`` only; ``auto`` builds its own split pipeline once, lazily): their default
#: pipelines are built once per thread and reused by :func:`solve_problem` (building
#: one per solve, ``AutoBackend()`` with its three inner backends, the layers and the
#: availability check, cost ~37 us of a 400 us ``auto`` solve at 100 vertices)
_STATELESS_BACKENDS = frozenset({"auto", "kamis", "chils", "exact", "greedy"})
_pipelines = threading.local()


def _pipeline(backend: str | Backend, layers: bool) -> Backend:
    """:func:`build_pipeline`, cached per thread for the names in _STATELESS_BACKENDS."""
    if not (isinstance(backend, str) and backend in _STATELESS_BACKENDS):
        return build_pipeline(backend, layers=layers)
    cache = getattr(_pipelines, "cache", None)
    if cache is None:
        cache = _pipelines.cache = {}
    key = (backend, bool(layers))
    pipe = cache.get(key)
    if pipe is None:
        pipe = cache[key] = build_pipeline(backend, layers=layers)
    return pipe


def solve_problem(
    problem: MwisProblem,
    backend: str | Backend = "greedy",
    time_limit_s: float = 10.0,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
    layers: bool = True,
) -> MwisResult:
    """Solve an already validated problem with the default pipeline (see :func:`build_pipeline`)
    within ``time_limit_s`` + 0.5 s, as :func:`solve`."""
    return _solve_problem(problem, backend, time_limit_s, seed, options, layers,
                          time.perf_counter())


def _solve_problem(problem: MwisProblem, backend: str | Backend, time_limit_s: float, seed: int,
                   options: Mapping[str, Any] | None, layers: bool, t0: float) -> MwisResult:
    """:func:`solve_problem` for a call that started at ``t0`` (``time.perf_counter()``).

    The limit holds from ``t0``: a backend not yet warm in this process is warmed first
    (imports, first-call set-up) and gets the time left; a warm one gets ``time_limit_s``
    exactly (the answers of a warm process are those of a solve without this step). Problems
    up to the backend's ``inline_max_vertices``, and up to ``PRECOMPUTE_FALLBACK_ABOVE``
    vertices for backends a guard thread can abandon (``bounded_in_process``), are solved
    here; the rest in a forked child killed at the limit + margin
    (:func:`uam_solvers.executor.solve_in_child`)."""
    from .options import check_seed, check_time_limit
    from .warmup import start_up

    time_limit_s = check_time_limit(time_limit_s)
    seed = check_seed(seed)
    if options:
        # a bad option is an error, never a fallback: checked on the backend itself (its
        # module's import, not its library's start-up) before a start-up that a cold backend
        # may not finish within the limit
        (get_backend(backend) if isinstance(backend, str) else backend).validate_options(options)
    spent = start_up(backend, t0 + time_limit_s)
    if spent is None:
        from .executor import fallback_answer

        name = backend if isinstance(backend, str) else backend.name
        return fallback_answer(problem, name, t0, "starting", reason=(
            f"backend {name!r} was still starting (imports, first call) at its time limit "
            f"{time_limit_s:g} s; its start goes on in the background"))
    pipeline = _pipeline(backend, layers)
    options = pipeline.validate_options(options)  # before any solve: errors, never a fallback
    budget = time_limit_s
    if spent > 0.0:  # the start-up was this call's: the backend gets the time left
        budget = max(time_limit_s - (time.perf_counter() - t0), 1e-3)
    from .executor import PRECOMPUTE_FALLBACK_ABOVE, solve_in_child

    # a guard thread abandons a bounded backend at its limit, but not the layers' reductions
    # before it: on the large city's graphs (10^5 vertices, 27 M pairs) an in-process sa
    # answered after 10.5 s at a 1 s limit, the abandoned thread slowing the fallback; those
    # go to a child killed at the limit, as every unbounded backend's graphs do
    if problem.n <= pipeline.inline_max_vertices or \
            (pipeline.bounded_in_process and problem.n <= PRECOMPUTE_FALLBACK_ABOVE):
        return pipeline.solve(problem, time_limit_s=budget, seed=seed, options=options)

    return solve_in_child(pipeline, problem, budget, seed, options, t0)


def _checked_fast_path(weights, edges, groups, backend, time_limit_s, seed, options, layers,
                       max_vertices) -> MwisResult | None:
    """Check the arguments (errors first, before the arrays are converted); then, for ``auto``
    without options, the fast path for the small graphs of one planning epoch: the auto
    backend's exact branch and bound straight from clean arrays (the same answer as through
    the pipeline, in about a third of the time). None: take the full path."""
    from .options import check_seed, check_time_limit

    check_time_limit(time_limit_s)
    check_seed(seed)
    if not (backend == "auto" and layers and (options is None or (isinstance(options, Mapping) and not options))):
        return None
    from .auto import bb_node_limit
    from .cliquebb import SMALL_MAX_VERTICES, solve_small_arrays

    t0 = time.perf_counter()
    cap = SMALL_MAX_VERTICES if max_vertices is None else min(SMALL_MAX_VERTICES, max_vertices)
    res = solve_small_arrays(weights, edges, groups, bb_node_limit(time_limit_s), cap)
    if res is not None:
        res.solve_time_s = time.perf_counter() - t0
    return res


def solve(
    weights: Any,
    edges: Any,
    groups: Sequence[Any] | None = None,
    backend: str | Backend = "greedy",
    time_limit_s: float = 10.0,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
    layers: bool = True,
    max_vertices: int | None = None,
) -> MwisResult:
    """Validate the arrays and solve MWIS with the named backend through the default pipeline.

    Inputs: ``weights`` (n,) finite >= 0; ``edges`` (m, 2) vertex pairs; ``groups`` optional
    clique groups; ``backend`` a registered name (``python -m uam_solvers.registry``) or Backend
    instance; ``time_limit_s`` wall-time budget [s], which holds whatever the backend does:
    the answer comes within ``time_limit_s`` + 0.5 s, from a cold process too (a backend's
    first call in the process pays its imports inside the limit; one that overruns is
    abandoned or killed and the greedy fallback answers, flagged; for a warm backend the
    arrays' validation comes on top, ~0.5 s at 5.5 M unsorted edges, inside the limit with
    :func:`solve_bounded`, so a city-sized graph is best validated once into an MwisProblem and
    given to :func:`solve_problem` or a SolveService); ``seed`` for stochastic
    backends; ``options`` passed to the backend; ``layers`` enables component split and
    reductions.
    Output: an MwisResult whose ``selected`` is always an independent set of the input graph.
    Raises MwisInputError (bad arrays), UnknownBackendError, BackendUnavailable.

    Examples:
        A path of three vertices: the two ends weigh more together than the middle one.

        >>> from uam_solvers import solve
        >>> r = solve([1.0, 2.0, 1.5], [(0, 1), (1, 2)], backend="exact")
        >>> r.selected.tolist(), r.objective, r.proven_optimal
        ([0, 2], 2.5, True)
    """
    t0 = time.perf_counter()
    res = _checked_fast_path(weights, edges, groups, backend, time_limit_s, seed, options, layers, max_vertices)
    if res is not None:
        return res
    problem = MwisProblem.from_arrays(weights, edges, groups, max_vertices=max_vertices)
    return _solve_problem(problem, backend, time_limit_s, seed, options, layers, t0)


def solve_bounded(
    weights: Any,
    edges: Any,
    groups: Sequence[Any] | None = None,
    backend: str | Backend = "greedy",
    time_limit_s: float = 10.0,
    seed: int = 0,
    options: Mapping[str, Any] | None = None,
    layers: bool = True,
    max_vertices: int | None = None,
) -> MwisResult:
    """:func:`solve` through this process's shared :class:`uam_solvers.executor.SolveService`
    (the same mechanism as the solver node's): at most ``time_limit_s`` + 0.5 s of wall time
    whatever the backend does (one that holds the GIL or ignores its limit is killed, and the
    answer is the fallback, flagged). The in-process runner and the planner's local solve call
    this. Small graphs the backend is known to finish at once run in this process (same
    answers as :func:`solve`); the rest in a warm worker process. A call before the service
    is started and warm (it takes 1-3 s) does not wait for it: it is answered as by
    :func:`solve`, then starts the service in the background for the calls after it (which
    share the CPU with that start); ``warm_up(..., service=True)`` at start-up avoids both.
    Same inputs, outputs and errors as :func:`solve`.
    """
    from .executor import ready_shared_service, start_shared_service_in_background

    t0 = time.perf_counter()
    # the exact clique branch and bound of the fast path is bounded by its node limit (pure
    # Python, about 5 us a node), so it runs in this process here as in solve()
    res = _checked_fast_path(weights, edges, groups, backend, time_limit_s, seed, options, layers, max_vertices)
    if res is not None:
        res.stats["executor"] = "inline"
        return res
    problem = MwisProblem.from_arrays(weights, edges, groups, max_vertices=max_vertices)
    service = ready_shared_service()
    if service is None:
        res = _solve_problem(problem, backend, time_limit_s, seed, options, layers, t0)
        start_shared_service_in_background()
        return res
    # the limit counts from this call's start: the arrays' validation is inside it
    return service.solve(problem, backend=backend, time_limit_s=time_limit_s,
                         seed=seed, options=options, layers=layers, started_at=t0)
