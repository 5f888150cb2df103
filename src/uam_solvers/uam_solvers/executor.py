"""Solves whose deadlines hold: a solve service with warm worker processes.

A thread cannot stop a solver that holds the GIL (chszlablib's KaMIS and CHILS, minorminer) or
one that ignores its time limit; a process can be killed. :class:`SolveService` therefore runs
solves in worker processes and kills a worker whose solve is still running at
``time_limit_s + margin_s``; the caller then gets the fallback answer (greedy, flagged) at once,
the killed process leaves no CPU or memory behind, and a fresh worker replaces it.

Rules (all parameters of the constructor):

* **In-process** (no process hop, ~no overhead): a solve whose problem has at most
  ``backend.inline_max_vertices`` vertices (after the service's own ``inline_max_vertices`` cap).
  Backends set that where they are known to return well within any limit at that size
  (greedy: 2,000; exact, kamis and auto: 64; everything else 0, i.e. always a
  worker). These run under the thread guard of :class:`uam_solvers.layers.ValidateFallback`.
* **Lanes**: every other solve goes to a warm worker of the *small* lane
  (``small_workers`` processes, problems of at most ``small_lane_max_vertices`` vertices) or of
  the *large* lane (``large_workers`` processes), so a small request never waits behind large
  ones. A request that finds no free worker in its lane waits, and the wait counts against its
  time limit; when the limit passes first it gets the fallback answer, flagged.
* **Bounds**: problems above ``max_vertices`` and time limits above ``max_time_limit_s`` are
  refused with an MwisInputError naming the field and value.
* **Answer**: the worker's answer is checked in this process (independent in the input graph,
  objective recomputed); an invalid answer, an exception in the worker, a crashed worker or a
  kill all give the fallback answer with ``fallback=True`` and the reason in ``message``.
  ``stats["executor"]`` says how the solve ran: ``inline``, ``worker``, ``killed``,
  ``worker-crashed`` or ``no-free-worker``; ``stats["queue_wait_s"]`` the wait for a worker.

Workers are forked from a ``forkserver`` that has imported uam_solvers (no import cost per
worker; forking a fresh worker after a kill takes tens of ms) and die with their parent
(``PR_SET_PDEATHSIG`` on Linux, and the forkserver exits when this process does).

Usage (what the solver node does)::

    service = SolveService(large_workers=2)
    result = service.solve(problem, backend="auto", time_limit_s=1.0, seed=0, options={})
    service.close()   # kills the workers

Also here: :func:`solve_in_child`, one solve in a child forked from the caller and killed at
its deadline (what :func:`uam_solvers.solve` does with a backend a thread cannot stop: no worker
to start, so it holds from a cold process), and the process's shared service
(:func:`shared_service`; :func:`ready_shared_service` for a solve that cannot wait for its start).
"""
from __future__ import annotations

import atexit
import ctypes
import logging
import multiprocessing as mp
import signal
import threading
import time
import weakref
from typing import Any, Mapping

import numpy as np

from .base import Backend, MwisInputError, MwisProblem, MwisResult, check_selection, make_result
from .greedy import conflict_pairs_estimate
from .options import check_seed, check_time_limit

__all__ = ["SolveService", "DEFAULT_MARGIN_S", "NODE_LAYOUT", "node_service", "shared_service",
           "close_shared_service", "ready_shared_service", "start_shared_service_in_background",
           "solve_in_child", "fallback_answer",
           "start_process"]

log = logging.getLogger("uam_solvers")

#: Time a worker may run past the limit before it is killed [s]: covers sending the answer back.
DEFAULT_MARGIN_S = 0.4
#: above this many vertices the worker sends the fallback answer before it solves
PRECOMPUTE_FALLBACK_ABOVE = 20_000
#: a solve runs in-process only up to this many conflict pairs too (greedy, inline up to 2,000
#: vertices, took 2.2 s on a clique of 1,000 with pendants: 5 x 10^5 pairs)
INLINE_MAX_PAIRS = 20_000

_PRELOAD = ["uam_solvers", "uam_solvers.layers", "uam_solvers.registry", "uam_solvers.greedy",
            "uam_solvers.cpsat", "uam_solvers.chszla", "uam_solvers.auto", "uam_solvers.annealing",
            "numpy", "scipy.sparse", "ortools.sat.python.cp_model", "chszlablib._kamis_wmis",
            "chszlablib._chils", "dwave.samplers", "dwave.system", "minorminer",
            "uam_solvers.qpu", "uam_solvers.decompose"]


# ---------------------------------------------------------------------------------------------
# The worker process
# ---------------------------------------------------------------------------------------------

def _die_with_parent() -> None:
    """Ask Linux to SIGKILL this process when its parent (the forkserver) exits."""
    try:
        libc = ctypes.CDLL("libc.so.6", use_errno=True)
        libc.prctl(1, signal.SIGKILL, 0, 0, 0)  # PR_SET_PDEATHSIG
    except OSError:  # not Linux: the worker ends when its pipe closes
        pass


def _pack(problem: MwisProblem) -> tuple:
    """The problem's arrays only (no cached derived data), groups concatenated."""
    if problem.groups:
        lengths = np.fromiter((g.size for g in problem.groups), dtype=np.int64,
                              count=len(problem.groups))
        flat = np.concatenate(problem.groups)
    else:
        lengths, flat = np.zeros(0, dtype=np.int64), np.zeros(0, dtype=np.int32)
    return problem.weights, problem.edges, flat, lengths


def _unpack(weights, edges, flat, lengths) -> MwisProblem:
    groups = tuple(np.split(flat, np.cumsum(lengths)[:-1])) if lengths.size else ()
    return MwisProblem(weights=weights, edges=edges, groups=groups)


def _load_backend(spec) -> Backend:
    if isinstance(spec, Backend):
        return spec
    from .registry import _load

    return _load(spec)()


#: backends every worker warms when it starts (auto's warm-up covers CP-SAT, KaMIS, CHILS and
#: LearnAndReduce: measured ~3 s on the first CHILS solve of a fresh worker under load)
WORKER_WARM_UP = ("greedy", "exact", "kamis", "chils", "auto")


def _warm_up() -> None:
    """Pay every first-call cost once when the worker starts (entry-point scan, then
    :func:`uam_solvers.warm_up` of WORKER_WARM_UP)."""
    from .registry import _entry_points
    from .warmup import warm_up

    _entry_points()
    warm_up(WORKER_WARM_UP)


def _worker_main(conn) -> None:
    """Serve jobs from ``conn`` until it closes: (backend spec, packed problem, limit, seed,
    options, layers) -> ("ok", MwisResult) or ("error", text, is_input_error)."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when a worker stops
    from .layers import ComponentSplit, Reduce

    while True:
        try:
            job = conn.recv()
        except (EOFError, OSError):
            return
        if job is None:
            return
        if job == "warm":
            try:
                _warm_up()
                conn.send(("warm", ""))
            except BaseException as exc:  # noqa: BLE001 - reported, the worker still serves
                conn.send(("warm", f"{type(exc).__name__}: {exc}"))
            continue
        spec, packed, limit_s, seed, options, layers = job
        try:
            backend = _load_backend(spec)
            problem = _unpack(*packed)
            # no best-so-far of its own: above PRECOMPUTE_FALLBACK_ABOVE vertices the parent
            # computes the fallback on a thread while this solves (_fallback_meanwhile),
            # so the whole limit goes to the solve
            inner = Reduce(ComponentSplit(backend)) if layers else backend
            result = inner.solve(problem, time_limit_s=limit_s, seed=seed, options=options)
            result.stats = {k: v for k, v in result.stats.items()
                            if isinstance(v, (int, float, str, bool, np.integer, np.floating))}
            reply = ("ok", result)
        except BaseException as exc:  # noqa: BLE001 - every failure is reported to the parent
            reply = ("error", f"{type(exc).__name__}: {exc}", isinstance(exc, MwisInputError))
        try:
            conn.send(reply)
        except (EOFError, OSError):
            return


def start_process(process) -> None:
    """``process.start()``, also from a daemonic process: a Dask worker process is daemonic,
    and multiprocessing refuses children of a daemonic process lest they be orphaned; ours die
    with it (PR_SET_PDEATHSIG, and the forkserver exits when its pipe closes)."""
    me = mp.current_process()
    daemonic = bool(me._config.get("daemon"))
    if daemonic:
        me._config["daemon"] = False
    try:
        process.start()
    finally:
        if daemonic:
            me._config["daemon"] = True


class _Worker:
    """One worker process and the parent's end of its pipe."""

    def __init__(self, ctx, lane: str):
        self.lane = lane
        self.killed = False  # SIGKILL sent: no longer a worker, even before it is reaped
        self.conn, child = ctx.Pipe(duplex=True)
        self.process = ctx.Process(target=_worker_main, args=(child,), daemon=True,
                                   name=f"uam-solver-{lane}")
        start_process(self.process)
        child.close()

    def warm(self, timeout_s: float = 60.0, closing=lambda: False) -> None:
        """Run the warm-up job (first-call costs) and wait for it. A lost pipe is reported
        unless ``closing()`` says the service is being closed: then the worker died with it
        (a replacement warmed while the process exits), which is no fault."""
        try:
            self.conn.send("warm")
            if self.conn.poll(timeout_s):
                reply = self.conn.recv()
                if reply[1]:
                    log.warning("solver worker warm-up: %s", reply[1])
        except (EOFError, OSError) as exc:
            if not closing():
                log.warning("solver worker warm-up failed: %s", exc)

    @property
    def pid(self) -> int | None:
        return self.process.pid

    def signal_kill(self) -> None:
        """SIGKILL the process without waiting for it to be reaped (the kernel frees its CPU at
        once; :meth:`kill` joins it)."""
        self.killed = True
        try:
            self.process.kill()
        except (OSError, ValueError):
            pass

    def kill(self) -> None:
        self.signal_kill()
        self.process.join(5.0)
        try:
            self.conn.close()
        except OSError:
            pass

    def stop(self) -> None:
        try:
            self.conn.send(None)
        except (OSError, ValueError):
            pass
        self.process.join(0.5)
        if self.process.is_alive():
            self.kill()
        else:
            self.conn.close()


def _stop_workers(idle: list[_Worker], busy: list[_Worker], grace_s: float = 0.5,
                  reap_s: float = 2.0) -> None:
    """Stop workers all at once, in bounded time: the idle ones are asked to exit and given
    ``grace_s`` together, the busy ones and any still alive then are SIGKILLed together and
    reaped within ``reap_s`` together. (One by one, each idle worker had 0.5 s and each kill
    5 s of join: at load 17 the solver node once took more than run_fleet.sh's 10 s to end.)
    A worker not reaped by then is left to the kernel: it is a child of the forkserver and
    dies with it (PR_SET_PDEATHSIG), and the forkserver exits when this process does."""
    for w in idle:
        try:
            w.conn.send(None)
        except (OSError, ValueError):
            pass
    end = time.monotonic() + grace_s
    for w in idle:
        w.process.join(max(0.0, end - time.monotonic()))
    doomed = list(busy) + [w for w in idle if w.process.is_alive()]
    for w in doomed:
        w.signal_kill()
    end = time.monotonic() + reap_s
    for w in doomed:
        w.process.join(max(0.0, end - time.monotonic()))
    for w in list(idle) + list(busy):
        try:
            w.conn.close()
        except OSError:
            pass


# ---------------------------------------------------------------------------------------------
# The service
# ---------------------------------------------------------------------------------------------

_LIVE: "weakref.WeakSet[SolveService]" = weakref.WeakSet()


#: set when the interpreter exits (before the services close): a worker lost then is no fault
_EXITING = False


@atexit.register
def _close_all() -> None:
    global _EXITING
    _EXITING = True
    for service in list(_LIVE):
        service.close()


class SolveService:
    """Thread-safe MWIS solves with deadlines that hold (see the module docstring).

    Args:
        small_workers: worker processes of the small lane (>= 1).
        large_workers: worker processes of the large lane (>= 1).
        small_lane_max_vertices: problems up to this size use the small lane.
        inline_max_vertices: cap on every backend's ``inline_max_vertices`` (0: never inline).
        margin_s: how long past the limit a worker may run before it is killed [s].
        max_time_limit_s: larger time limits are refused [s].
        max_vertices: larger problems are refused.
        start_method: multiprocessing start method ("forkserver"; "spawn" where there is none).
    """

    def __init__(self, *, small_workers: int = 1, large_workers: int = 1,
                 small_lane_max_vertices: int = 2000, inline_max_vertices: int = 1000,
                 margin_s: float = DEFAULT_MARGIN_S, max_time_limit_s: float = 60.0,
                 max_vertices: int = 200_000, start_method: str | None = None):
        for name, value, lo in (("small_workers", small_workers, 1),
                                ("large_workers", large_workers, 1),
                                ("small_lane_max_vertices", small_lane_max_vertices, 0),
                                ("inline_max_vertices", inline_max_vertices, 0),
                                ("max_vertices", max_vertices, 1)):
            if isinstance(value, bool) or not isinstance(value, int) or value < lo or value > 10**8:
                raise MwisInputError(f"{name}: {value!r} must be an integer in [{lo}, 1e8]")
        self.max_time_limit_s = check_time_limit(max_time_limit_s, "max_time_limit_s")
        self.margin_s = check_time_limit(margin_s, "margin_s", max_s=60.0)
        self.small_lane_max_vertices = small_lane_max_vertices
        self.inline_max_vertices = inline_max_vertices
        self.max_vertices = max_vertices
        if start_method is None:
            start_method = "forkserver" if "forkserver" in mp.get_all_start_methods() else "spawn"
        self._ctx = mp.get_context(start_method)
        if start_method == "forkserver":
            self._ctx.set_forkserver_preload(_PRELOAD)
        self._size = {"small": small_workers, "large": large_workers}
        self._idle: dict[str, list[_Worker]] = {"small": [], "large": []}
        self._busy: set[_Worker] = set()
        #: replacements being started (a killed or crashed worker's), per lane
        self._replacing = {"small": 0, "large": 0}
        self._cond = threading.Condition()
        self._closed = False
        self.counts = {"inline": 0, "worker": 0, "killed": 0, "worker-crashed": 0,
                       "no-free-worker": 0}
        from .registry import backend_names, get_backend

        # First-call costs in this process are not a request's: the entry-point scan and each
        # backend's availability check (imports of OR-Tools, chszlablib: ~1 s under load).
        for name in backend_names():
            try:
                get_backend(name).available()
            except Exception:  # noqa: BLE001 - a broken backend is reported when requested
                pass
        started = []
        for lane, size in self._size.items():
            for _ in range(size):
                started.append(_Worker(self._ctx, lane))
        for worker in started:
            worker.warm()
        self._idle = {lane: [w for w in started if w.lane == lane] for lane in self._size}
        _LIVE.add(self)

    # -- public API -----------------------------------------------------------------------

    def worker_pids(self) -> list[int]:
        """Process ids of the live workers (idle and busy); a killed worker is not one, even
        before it is reaped."""
        with self._cond:
            workers = [w for lane in self._idle.values() for w in lane] + list(self._busy)
        return [w.pid for w in workers if not w.killed and w.process.is_alive()]

    def wait_until_ready(self, timeout_s: float = 60.0) -> bool:
        """Wait until no replacement worker is being started (after a kill or a crash, the
        replacement starts and warms up in the background: on a loaded machine that took
        longer than a 1 s limit, and the next solve fell back "no free worker"). True when
        every lane has its workers, False when ``timeout_s`` [s] passed first or the service
        is closed. Waits on a condition, not a sleep."""
        timeout_s = check_time_limit(timeout_s, "timeout_s", max_s=86_400.0)
        end = time.monotonic() + timeout_s
        with self._cond:
            while not self._closed and any(self._replacing.values()):
                left = end - time.monotonic()
                if left <= 0:
                    return False
                self._cond.wait(left)
            return not self._closed

    def close(self) -> None:
        """Stop every worker (killing busy ones); later solves raise RuntimeError."""
        with self._cond:
            if self._closed:
                return
            self._closed = True
            workers = [w for lane in self._idle.values() for w in lane] + list(self._busy)
            self._idle = {"small": [], "large": []}
            self._cond.notify_all()
        busy = set(self._busy)
        _stop_workers([w for w in workers if w not in busy], [w for w in workers if w in busy])
        _LIVE.discard(self)

    def __enter__(self) -> "SolveService":
        return self

    def __exit__(self, *exc) -> None:
        self.close()

    def solve(self, problem: MwisProblem, backend: str | Backend = "auto",
              time_limit_s: float = 1.0, seed: int = 0,
              options: Mapping[str, Any] | None = None, layers: bool = True,
              started_at: float | None = None) -> MwisResult:
        """Solve ``problem`` and return within ``time_limit_s + margin_s`` (plus the fallback's
        own time, well under a second even at 10^5 vertices). ``started_at``: the
        ``time.perf_counter()`` the caller's limit counts from (e.g. before it validated the
        arrays, ~0.5 s at 27 M conflict pairs); default now. A worker gets the time left.

        Raises MwisInputError (bad limit, seed, size or options: nothing is solved),
        UnknownBackendError, BackendUnavailable; every solver failure becomes a flagged
        fallback answer instead.
        """
        from . import build_pipeline

        t0 = time.perf_counter() if started_at is None else min(float(started_at), time.perf_counter())
        limit = check_time_limit(time_limit_s, max_s=self.max_time_limit_s)
        seed = check_seed(seed)
        if problem.n > self.max_vertices:
            raise MwisInputError(f"weights: {problem.n} vertices exceed the limit "
                                 f"max_vertices={self.max_vertices}")
        instance, spec = _backend_and_spec(backend)
        instance.require_available()
        opts = instance.validate_options(options)
        inline_max = min(int(getattr(instance, "inline_max_vertices", 0)), self.inline_max_vertices)
        inline = problem.n <= inline_max and conflict_pairs_estimate(problem) <= INLINE_MAX_PAIRS
        if inline or not _picklable(opts):
            res = build_pipeline(instance, layers=layers).solve(
                problem, time_limit_s=limit, seed=seed, options=opts)
            res.stats["executor"] = "inline"
            self.counts["inline"] += 1
            return res
        return self._solve_in_worker(problem, instance.name, spec, t0, limit, seed, opts, layers)

    def solve_arrays(self, weights, edges, groups=None, **kwargs) -> MwisResult:
        """:meth:`solve` from plain arrays (validated by MwisProblem.from_arrays)."""
        problem = MwisProblem.from_arrays(weights, edges, groups, max_vertices=self.max_vertices)
        return self.solve(problem, **kwargs)

    # -- internals ------------------------------------------------------------------------

    def _solve_in_worker(self, problem: MwisProblem, name: str, spec: Any, t0: float,
                         limit: float, seed: int, opts: Mapping[str, Any],
                         layers: bool) -> MwisResult:
        """One solve on a warm worker of its lane: the worker's checked answer, or the flagged
        fallback when no worker frees up in time, the job cannot be sent or the worker is killed
        at the deadline."""
        lane = "small" if problem.n <= self.small_lane_max_vertices else "large"
        deadline = t0 + limit
        worker = self._acquire(lane, deadline)
        waited = time.perf_counter() - t0
        if worker is None:
            self.counts["no-free-worker"] += 1
            return self._fallback(problem, name, t0, "no-free-worker", waited,
                                  f"no free {lane}-lane worker within the time limit "
                                  f"{limit:g} s (all busy)")
        # started before the job is sent: sending 10^7 edges takes a part of the limit
        background = _fallback_meanwhile(problem)
        remaining = max(deadline - time.perf_counter(), 1e-3)
        try:
            worker.conn.send((spec, _pack(problem), remaining, seed, opts, bool(layers)))
        except (OSError, ValueError) as exc:
            self._replace_in_background(worker)
            self.counts["worker-crashed"] += 1
            return self._fallback(problem, name, t0, "worker-crashed", waited,
                                  f"sending the job to the worker failed ({exc})")
        reply = self._await_reply(worker, deadline)
        precomputed = background.result() if reply is None and background is not None else None
        if reply is None:
            worker.signal_kill()  # SIGKILL now: no CPU or memory left behind; reaped below
            self._replace_in_background(worker)
            self.counts["killed"] += 1
            return self._fallback(problem, name, t0, "killed", waited, precomputed=precomputed,
                                  reason=
                                  f"backend {name!r} exceeded its time limit: still "
                                  f"running after {time.perf_counter() - t0:.3f} s (limit "
                                  f"{limit:g} s + margin {self.margin_s:g} s); worker killed"
                                  + ("; answer: the greedy answer made while the worker "
                                     "solved" if precomputed is not None else ""))
        return self._worker_answer(problem, name, worker, reply, t0, waited)

    def _await_reply(self, worker: _Worker, deadline: float) -> Any:
        """Wait for the worker's reply until ``deadline + margin_s``. Returns the reply, None
        when the time ran out, or the EOFError or OSError of a broken pipe."""
        try:
            if not worker.conn.poll(max(deadline + self.margin_s - time.perf_counter(), 0.0)):
                return None
            return worker.conn.recv()
        except (EOFError, OSError) as exc:
            return exc

    def _worker_answer(self, problem: MwisProblem, name: str, worker: _Worker, reply: Any,
                       t0: float, waited: float) -> MwisResult:
        """The answer from a worker's reply: checked in this process and rebuilt, or the flagged
        fallback for a crashed worker, a solver's exception or an invalid set (a bad option or
        input the backend found raises MwisInputError, the caller's error)."""
        try:
            if isinstance(reply, BaseException):
                raise reply
        except (EOFError, OSError) as exc:
            worker.process.join(1.0)
            code = worker.process.exitcode
            self._replace_in_background(worker)
            self.counts["worker-crashed"] += 1
            return self._fallback(problem, name, t0, "worker-crashed", waited,
                                  f"worker process of backend {name!r} died "
                                  f"(exit code {code}, {type(exc).__name__})")
        self._release(worker)
        if reply[0] == "error":
            if reply[2]:  # a bad option or input found by the backend itself: the caller's error
                raise MwisInputError(reply[1])
            return self._fallback(problem, name, t0, "worker", waited,
                                  f"backend {name!r} raised {reply[1]}")
        res = reply[1]
        ok, why = check_selection(problem, res.selected)
        if not ok:
            return self._fallback(problem, name, t0, "worker", waited,
                                  f"backend {name!r} returned an invalid answer: {why}")
        elapsed = time.perf_counter() - t0
        out = make_result(problem, res.selected, proven_optimal=res.proven_optimal,
                          solve_time_s=elapsed, backend=res.backend,
                          stats={**res.stats, "executor": "worker", "queue_wait_s": waited},
                          message=res.message)
        self.counts["worker"] += 1
        return out

    def _acquire(self, lane: str, deadline: float) -> _Worker | None:
        with self._cond:
            while True:
                if self._closed:
                    raise RuntimeError("SolveService is closed")
                if self._idle[lane]:
                    worker = self._idle[lane].pop()
                    if not worker.process.is_alive():
                        worker = _Worker(self._ctx, lane)
                    self._busy.add(worker)
                    return worker
                remaining = deadline - time.perf_counter()
                if remaining <= 0:
                    return None
                self._cond.wait(remaining)

    def _release(self, worker: _Worker) -> None:
        with self._cond:
            self._busy.discard(worker)
            if self._closed:
                worker.stop()
                return
            self._idle[worker.lane].append(worker)
            self._cond.notify()

    def _replace_in_background(self, worker: _Worker) -> None:
        """SIGKILL ``worker`` now; reap it and start and warm its replacement on a thread (the
        caller's answer waits for neither)."""
        worker.signal_kill()
        with self._cond:
            self._replacing[worker.lane] += 1
        threading.Thread(target=self._replace, args=(worker,), daemon=True,
                         name="uam-solver-replace").start()

    def _replace(self, worker: _Worker) -> None:
        """Kill ``worker`` and put a fresh one in its lane (counted in ``_replacing`` until
        then, for :meth:`wait_until_ready`)."""
        fresh = None
        try:
            worker.kill()
            with self._cond:
                self._busy.discard(worker)
                if self._closed:
                    return
            fresh = _Worker(self._ctx, worker.lane)
            fresh.warm(closing=lambda: self._closed or _EXITING)
            with self._cond:
                if self._closed:
                    fresh.stop()
                    return
                self._idle[worker.lane].append(fresh)
        finally:
            with self._cond:
                self._replacing[worker.lane] -= 1
                self._cond.notify_all()

    @staticmethod
    def _fallback(problem: MwisProblem, requested: str, t0: float, how: str, waited: float,
                  reason: str, precomputed: tuple | None = None) -> MwisResult:
        out = fallback_answer(problem, requested, t0, how, reason, precomputed)
        out.stats["queue_wait_s"] = waited
        return out


def fallback_answer(problem: MwisProblem, requested: str, t0: float, how: str, reason: str,
                    precomputed: tuple | None = None) -> MwisResult:
    """The greedy fallback's answer (``precomputed``: its ``(selection, rule)`` when already
    computed), flagged: ``fallback=True``, ``reason`` in ``message`` (logged as a warning),
    ``stats["executor"] = how``; ``solve_time_s`` counted from ``t0``."""
    from .greedy import fallback_selection

    log.warning("MWIS fallback to greedy: %s", reason)
    sel, rule = precomputed if precomputed is not None else fallback_selection(problem)
    # (edges and groups listed, not all_edges(): that costs ~0.5 s at 10^6 edges)
    out = make_result(problem, sel, proven_optimal=problem.m == 0 and not problem.groups,
                      solve_time_s=time.perf_counter() - t0, backend="greedy",
                      stats={"rule": rule, "requested_backend": requested, "executor": how},
                      message=reason)
    out.fallback = True
    return out


#: The solver node's worker layout: one worker per lane keeps the node within the two
#: cores of the target machine; problems up to 2,000 vertices (every planner epoch of the
#: paper's scenarios) use the small lane, so a city-scale graph never delays them; a worker may
#: run ``margin_s`` past the request's limit before it is killed: 0.3 s as the shared service's
#: (with 0.4 s killed solves answered at 1.40-1.47 s and, on a loaded machine, up to 1.69 s
#: with a 1 s limit: BENCHMARKS.md; the fallback is ready at the kill).
NODE_LAYOUT = {"small_workers": 1, "large_workers": 1, "small_lane_max_vertices": 2000,
               "margin_s": 0.3}


def node_service(max_time_limit_s: float = 60.0, max_vertices: int = 20_000) -> SolveService:
    """The SolveService exactly as the solver node (``uam_solvers.nodes.solver_node``) builds
    it, for the node and for benchmarks of the node's path without ROS."""
    return SolveService(**NODE_LAYOUT, max_time_limit_s=float(max_time_limit_s),
                        max_vertices=int(max_vertices))


def _backend_and_spec(backend: str | Backend) -> tuple[Backend, Any]:
    """The backend instance and what a worker gets to build its own: the registry entry for a
    name, the instance itself otherwise."""
    from .registry import _table, get_backend

    if isinstance(backend, str):
        return get_backend(backend), _table()[backend]
    return backend, backend


def _fallback_meanwhile(problem: MwisProblem):
    """The fallback answer made on a thread while a worker or child solves (a Future), or
    None where it is made only if needed: above PRECOMPUTE_FALLBACK_ABOVE vertices and where
    the fallback is the vectorised rule (``needs_fast_fallback``: dense graphs, 0.13 s at 10^6
    pairs, ~0.8 s at the large city's 27 M), so that it is ready at a kill and never delays
    it; GWMIN on the others takes < 0.05 s after the kill."""
    from .greedy import needs_fast_fallback

    if problem.n > PRECOMPUTE_FALLBACK_ABOVE or needs_fast_fallback(problem):
        return _fallback_in_background(problem)
    return None


def _fallback_in_background(problem: MwisProblem):
    """A Future of the fallback answer (``fallback_selection``), computed on a thread of this
    process while the worker solves, started before the job is sent: on the large city's graphs
    (10^5 vertices, 27 M pairs) it takes ~1 s, and computed only after a kill at the limit +
    margin it came on top. numpy releases the GIL, so the thread uses the other core. Its answer
    is dropped when the worker's comes in time."""
    from concurrent.futures import Future

    from .greedy import fallback_selection

    fut: Future = Future()

    def run() -> None:
        try:
            fut.set_result(fallback_selection(problem))
        except BaseException as exc:  # noqa: BLE001 - raised to the caller by result()
            fut.set_exception(exc)
    threading.Thread(target=run, name="uam-solvers-fallback", daemon=True).start()
    return fut


def _picklable(options: Mapping[str, Any]) -> bool:
    """Options that cannot cross a process boundary (a sampler factory closure) run inline."""
    import pickle

    try:
        pickle.dumps(dict(options))
    except Exception:  # noqa: BLE001 - any pickling failure means "not picklable"
        return False
    return True


# ---------------------------------------------------------------------------------------------
# One solve in a forked child: the bounded path of uam_solvers.solve
# ---------------------------------------------------------------------------------------------

def _child_main(conn, pipeline: Backend, problem: MwisProblem, time_limit_s: float, seed: int,
                options: Mapping[str, Any]) -> None:
    """Solve once and send ("ok", MwisResult) or ("error", text, is_input_error)."""
    _die_with_parent()
    signal.signal(signal.SIGINT, signal.SIG_IGN)  # the parent decides when the child stops
    try:
        reply: tuple = ("ok", pipeline.solve(problem, time_limit_s=time_limit_s, seed=seed,
                                             options=options))
    except BaseException as exc:  # noqa: BLE001 - every failure is reported to the parent
        reply = ("error", f"{type(exc).__name__}: {exc}", isinstance(exc, MwisInputError))
    try:
        conn.send(reply)
    except Exception:  # noqa: BLE001 - stats that do not pickle: the scalar ones are sent
        if reply[0] != "ok":
            raise
        res = reply[1]
        res.stats = {k: v for k, v in res.stats.items()
                     if isinstance(v, (int, float, str, bool, np.integer, np.floating))}
        conn.send(reply)


def solve_in_child(pipeline: Backend, problem: MwisProblem, time_limit_s: float, seed: int,
                   options: Mapping[str, Any], t0: float,
                   margin_s: float | None = None) -> MwisResult:
    """``pipeline.solve(problem, ...)`` in a child process forked from this one, answered
    within ``time_limit_s + margin_s`` [s] (plus the fallback's own time).

    Forked (~10 ms): the child inherits the warm libraries, the pipeline and the problem, and
    only the answer is pickled, so options that cannot cross a process boundary (a sampler
    factory) work, and it costs no worker start from a cold process. A child still running at
    the limit + ``margin_s`` (default OVERRUN_MARGIN_S) is SIGKILLed (no CPU or memory left
    behind; it also dies with this process) and the answer is the greedy fallback, flagged,
    ``stats["executor"] = "killed"``; a child that dies gives the fallback with
    ``"child-crashed"``. An answer of the child is returned with ``stats["executor"] =
    "child"`` after the same independence check as the solve service's. An MwisInputError
    raised in the child is raised here. ``t0``: when the caller's solve started (its
    ``solve_time_s`` counts from there).
    """
    from .layers import OVERRUN_MARGIN_S

    margin_s = OVERRUN_MARGIN_S if margin_s is None else float(margin_s)
    ctx = mp.get_context("fork")
    recv, send = ctx.Pipe(duplex=False)
    kill_at = time.perf_counter() + time_limit_s + margin_s
    process = ctx.Process(target=_child_main, daemon=True, name="uam-solver-child",
                          args=(send, pipeline, problem, time_limit_s, seed, options))
    start_process(process)
    send.close()
    # on a thread, not here before the wait: made first, it delayed the poll and so the kill
    # (a cold sa answered after 2.5 s at a 1 s limit on the large city's graph)
    background = _fallback_meanwhile(problem)
    reply: Any = None
    try:
        if recv.poll(max(kill_at - time.perf_counter(), 0.0)):
            reply = recv.recv()
    except (EOFError, OSError) as exc:
        reply = exc
    finally:
        recv.close()
    if reply is None:
        process.kill()  # first: the fallback's thread then has the core to itself
    precomputed = background.result() if background is not None and \
        (reply is None or isinstance(reply, BaseException) or reply[0] == "error") else None
    if reply is None:   # SIGKILLed above; reaped by multiprocessing at its next start or exit
        return fallback_answer(
            problem, pipeline.name, t0, "killed", precomputed=precomputed, reason=(
                f"backend {pipeline.name!r} exceeded its time limit: still running after "
                f"{time.perf_counter() - t0:.3f} s (limit {time_limit_s:g} s + margin "
                f"{margin_s:g} s); child process killed"))
    if isinstance(reply, BaseException):
        process.join(1.0)
        return fallback_answer(problem, pipeline.name, t0, "child-crashed", precomputed=precomputed,
                               reason=f"child process of backend {pipeline.name!r} died (exit "
                                      f"code {process.exitcode}, {type(reply).__name__})")
    if reply[0] == "error":
        if reply[2]:  # a bad option or input found by the backend itself: the caller's error
            raise MwisInputError(reply[1])
        return fallback_answer(problem, pipeline.name, t0, "child", precomputed=precomputed,
                               reason=f"backend {pipeline.name!r} raised {reply[1]}")
    res = reply[1]
    ok, why = check_selection(problem, res.selected)
    if not ok:
        return fallback_answer(problem, pipeline.name, t0, "child", precomputed=precomputed,
                               reason=f"backend {pipeline.name!r} returned an invalid answer: "
                                      f"{why}")
    res.stats["executor"] = "child"
    return res


# ---------------------------------------------------------------------------------------------
# The process's shared service: the one bounded path of in-process callers
# ---------------------------------------------------------------------------------------------

#: how long past the limit a worker of the shared service may run [s]
SHARED_MARGIN_S = 0.3
_SHARED: SolveService | None = None
_SHARED_LOCK = threading.Lock()


def shared_service() -> SolveService:
    """This process's SolveService (one small-lane and one large-lane worker), started and
    warmed on the first call: what :func:`uam_solvers.solve_bounded` uses, so the in-process
    runner and the planner's local solve keep every limit as the solver node does (a solve
    past ``limit + margin_s`` is killed, the fallback is ready at once). Call it at start-up
    to pay the warm-up (~1-3 s: worker start, first CP-SAT/KaMIS/CHILS calls) there instead of
    in the first epoch. Thread-safe; closed at exit."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is None or _SHARED._closed:
            # margin 0.3 s (not 0.4): the fallback is ready at the kill, so limit + 0.5 s
            # holds with the transfer of a 10^6-pair graph (1.52 s measured at 0.4)
            _SHARED = SolveService(small_workers=1, large_workers=1, max_time_limit_s=3600.0,
                                   max_vertices=10**7, margin_s=SHARED_MARGIN_S)
            _warm_up_here()
        return _SHARED


_STARTER: threading.Thread | None = None
_STARTER_LOCK = threading.Lock()


def ready_shared_service() -> SolveService | None:
    """The shared service when it is started and warm, else None (nothing is started: see
    :func:`start_shared_service_in_background`). What a solve with a time limit asks: the
    service's start (1-3 s, more under load) cannot be in its limit."""
    service = _SHARED
    if service is not None and not service._closed:
        return service
    return None


def start_shared_service_in_background() -> None:
    """Start and warm the shared service on a daemon thread (unless it is started or being
    started), for the solves to come."""
    global _STARTER
    if ready_shared_service() is not None:
        return
    with _STARTER_LOCK:
        if _STARTER is None or not _STARTER.is_alive():
            _STARTER = threading.Thread(target=_start_shared_quietly, daemon=True,
                                        name="uam-solver-service-start")
            _STARTER.start()


def _start_shared_quietly() -> None:
    try:
        shared_service()
    except Exception as exc:  # noqa: BLE001 - solves go on in process; logged for the operator
        if not _EXITING:
            log.warning("starting the shared solve service failed: %s: %s",
                        type(exc).__name__, exc)


def close_shared_service() -> None:
    """Stop the shared service's workers (a later :func:`shared_service` starts new ones)."""
    global _SHARED
    with _SHARED_LOCK:
        if _SHARED is not None:
            _SHARED.close()
            _SHARED = None


#: backends whose small solves run in this process when the shared service starts (inline: the
#: auto fast path, the clique branch and bound, CP-SAT and KaMIS on small graphs)
INLINE_WARM_UP = ("auto", "exact", "kamis", "greedy")


def _warm_up_here() -> None:
    """First-call costs of the solves that run in this process (:data:`INLINE_WARM_UP`): the
    backends' warm-up, then one small solve of each through ``solve`` (the pipelines)."""
    try:
        from . import solve
        from .warmup import warm_up

        warm_up(INLINE_WARM_UP)
        w, e, g = [1.0, 0.9, 0.8, 1.0, 0.7], [[0, 3], [1, 4], [2, 3]], [[0, 1, 2], [3, 4]]
        for name in INLINE_WARM_UP:
            solve(w, e, g, backend=name, time_limit_s=0.5)
    except Exception as exc:  # noqa: BLE001 - a backend that cannot run is reported when asked
        log.warning("solver warm-up in process: %s", exc)
