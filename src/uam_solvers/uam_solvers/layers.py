"""Layers that each add one concern around any MWIS backend (like dimod composites).

Each layer is itself a :class:`~uam_solvers.base.Backend`, so they nest:
``ValidateFallback(Reduce(ComponentSplit(get_backend("exact"))))`` is the default pipeline.

- :class:`ComponentSplit`: solve each connected component separately; single vertices and
  cliques are answered directly (optimally), the rest share the time budget by size.
- :class:`Reduce`: exact reductions that keep the optimum (see :mod:`uam_solvers.reductions`),
  then solve the remaining kernel with the child.
- :class:`ValidateFallback`: check the child's answer against the INPUT graph and fall back to
  greedy on an invalid answer, an exception or a time-limit overrun.
"""
from __future__ import annotations

import logging
import math
import os
import queue
import threading
import time
from typing import Any, Mapping

import numpy as np
from scipy.sparse.csgraph import connected_components

from .base import (Backend, MwisInputError, MwisProblem, MwisResult, check_selection,
                   induced_subproblem, make_result)
from .reductions import complete_maximal, reduce_problem

__all__ = ["ComponentSplit", "Reduce", "ValidateFallback", "induced_subproblem", "Layer"]

log = logging.getLogger("uam_solvers")

#: How long past its time limit a solve may run before it is abandoned (a guard thread) or
#: killed (a child process) and the fallback answers [s]: with the fallback's own time
#: (GWMIN < 0.05 s, the vectorised rule on dense graphs up to 0.13 s) every answer comes
#: within the limit + 0.5 s.
OVERRUN_MARGIN_S = 0.3


class _Worker:
    """A reusable daemon thread. Reusing threads matters: OR-Tools costs a few ms of
    per-thread set-up, which would dominate the solve of a 50-vertex graph."""

    _idle: list["_Worker"] = []
    _lock = threading.Lock()

    def __init__(self) -> None:
        self._jobs: "queue.SimpleQueue" = queue.SimpleQueue()
        self._thread = threading.Thread(target=self._loop, name="uam-solvers-worker", daemon=True)
        self._thread.start()

    def _loop(self) -> None:
        while True:
            fn, done = self._jobs.get()
            try:
                fn()
            finally:
                done.set()
                with _Worker._lock:  # back to the pool only once the (maybe late) job is over
                    _Worker._idle.append(self)

    @classmethod
    def acquire(cls) -> "_Worker":
        with cls._lock:
            if cls._idle:
                return cls._idle.pop()
        return cls()

    @classmethod
    def forget_pool(cls) -> None:
        """Empty the pool in a forked child: the parent's threads do not exist there, and a
        job queued for one would never run."""
        cls._idle = []
        cls._lock = threading.Lock()


os.register_at_fork(after_in_child=_Worker.forget_pool)


def _run_in_worker(fn, timeout_s: float) -> bool:
    """Run ``fn`` on a pooled worker thread; True when it finished within ``timeout_s``. A late
    job keeps its thread (which rejoins the pool when done); the caller moves on."""
    done = threading.Event()
    _Worker.acquire()._jobs.put((fn, done))
    return done.wait(timeout_s)


def _components(problem: MwisProblem) -> tuple[int, np.ndarray]:
    """(count, labels) of connected components; labels numbered by smallest vertex. Small graphs
    use min-label propagation over the edge arrays (no scipy overhead), large ones scipy."""
    n = problem.n
    e = problem.all_edges()
    if n > 256:
        return connected_components(problem.adjacency(), directed=False)
    labels = np.arange(n)
    u, v = e[:, 0], e[:, 1]
    while True:  # at most diameter + 1 rounds
        new = labels.copy()
        np.minimum.at(new, u, labels[v])
        np.minimum.at(new, v, labels[u])
        new = new[new]  # pointer jumping speeds up long paths
        if np.array_equal(new, labels):
            break
        labels = new
    roots, labels = np.unique(labels, return_inverse=True)
    return int(roots.size), labels


class Layer(Backend):
    """A backend wrapping a child backend; reports the child's name on its results."""

    def __init__(self, child: Backend):
        self.child = child
        self.name = child.name
        self.description = f"{type(self).__name__}({child.description})"
        # Properties of the innermost backend that outer layers look at.
        self.batch_components = getattr(child, "batch_components", False)
        self.reduces_itself = getattr(child, "reduces_itself", False)
        self.inline_max_vertices = getattr(child, "inline_max_vertices", 0)
        self.thread_inline_max_vertices = getattr(child, "thread_inline_max_vertices", None)
        self.reduce_min_vertices = getattr(child, "reduce_min_vertices", 0)
        self.bounded_in_process = getattr(child, "bounded_in_process", False)
        self.split_min_vertices = getattr(child, "split_min_vertices", 0)
        self.split_max_vertices = getattr(child, "split_max_vertices", 1 << 62)

    def available(self) -> tuple[bool, str]:
        return self.child.available()

    def warm_up(self) -> None:
        self.child.warm_up()

    @property
    def options_spec(self):  # the innermost backend's options
        return self.child.options_spec

    def validate_options(self, options):
        return self.child.validate_options(options)


class ComponentSplit(Layer):
    """Solve each connected component of the conflict graph on its own.

    Components of one vertex are selected; components that are cliques (e.g. a request whose
    candidates conflict with nobody else) get their heaviest vertex (lowest index on ties); both
    are optimal. Other components go to the child in increasing size with a time share
    ``remaining_s * size / remaining_size``, so time left by fast components passes to later ones.
    ``proven_optimal`` is the AND over components. Stats: the child's stats of the largest
    component plus ``components``, ``trivial_components``, ``largest_component``. A child whose
    class sets ``batch_components = True`` gets all non-trivial components in one call instead,
    and so does every child when they hold at most ``batch_below`` (64) vertices together.
    """

    def __init__(self, child: Backend, batch_below: int = 64):
        super().__init__(child)
        self.batch_below = int(batch_below)

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        t0 = time.perf_counter()
        n = problem.n
        if n == 0:
            return make_result(problem, [], proven_optimal=True, solve_time_s=0.0, backend=self.name,
                               stats={"components": 0})
        if n < getattr(self.child, "split_min_vertices", 0) or \
                n > getattr(self.child, "split_max_vertices", 1 << 62):
            # the child handles small graphs whole faster than a split costs (auto: KaMIS)
            return self.child.solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)
        ncomp, labels = _components(problem)
        sizes = np.bincount(labels, minlength=ncomp)
        e = problem.all_edges()
        edge_counts = np.bincount(labels[e[:, 0]], minlength=ncomp) if e.shape[0] else np.zeros(ncomp, int)
        trivial = edge_counts == sizes * (sizes - 1) // 2  # single vertices and cliques
        selected: list[np.ndarray] = []
        # Trivial components: heaviest vertex, lowest index on ties (lexsort: last key primary).
        triv_vertices = np.flatnonzero(trivial[labels])
        if triv_vertices.size:
            order = np.lexsort((triv_vertices, -problem.weights[triv_vertices], labels[triv_vertices]))
            ordered = triv_vertices[order]
            first = np.ones(ordered.size, dtype=bool)
            first[1:] = labels[ordered[1:]] != labels[ordered[:-1]]
            selected.append(ordered[first])
        hard = np.flatnonzero(~trivial)
        if hard.size == 0:
            return make_result(problem, np.concatenate(selected), proven_optimal=True,
                               solve_time_s=time.perf_counter() - t0, backend=self.name,
                               stats={"components": int(ncomp), "trivial_components": int(ncomp),
                                      "largest_component": int(sizes.max())})
        if hard.size == 1 and triv_vertices.size == 0:
            # One component: nothing to split; hand the problem over unchanged.
            res = self.child.solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)
            res.stats = {**res.stats, "components": 1, "trivial_components": 0, "largest_component": n}
            return res
        hard_vertices = int(sizes[hard].sum())
        if getattr(self.child, "batch_components", False) or hard_vertices <= self.batch_below:
            # One call on the union of the non-trivial components: for backends with a large
            # fixed cost per call (CHILS's ~70 ms set-up, a QPU round trip) and for small
            # remainders, where a call's fixed cost (~1 ms for CP-SAT) outweighs splitting.
            verts = np.flatnonzero(~trivial[labels])
            sub = induced_subproblem(problem, verts)
            budget = max(time_limit_s - (time.perf_counter() - t0), 1e-3)
            res = self.child.solve(sub, time_limit_s=budget, seed=seed, options=options)
            selected.append(verts[np.asarray(res.selected, dtype=np.int64)])
            stats = {**res.stats, "components": int(ncomp), "trivial_components": int(trivial.sum()),
                     "largest_component": int(sizes.max())}
            return make_result(problem, np.concatenate(selected), proven_optimal=res.proven_optimal,
                               solve_time_s=time.perf_counter() - t0, backend=self.name, stats=stats)
        # Vertices of each hard component, in index order.
        vorder = np.argsort(labels, kind="stable")
        starts = np.concatenate([[0], np.cumsum(sizes)])
        hard = hard[np.argsort(sizes[hard], kind="stable")]
        remaining_size = int(sizes[hard].sum())
        proven = True
        largest_stats: dict = {}
        largest = -1
        deadline = t0 + time_limit_s
        for c in hard:
            verts = vorder[starts[c]:starts[c + 1]]
            sub = induced_subproblem(problem, verts)
            remaining_s = max(deadline - time.perf_counter(), 0.0)
            share = max(remaining_s * sub.n / remaining_size, 1e-3)
            res = self.child.solve(sub, time_limit_s=share, seed=seed, options=options)
            remaining_size -= sub.n
            selected.append(verts[np.asarray(res.selected, dtype=np.int64)])
            proven = proven and res.proven_optimal
            if sub.n > largest:
                largest, largest_stats = sub.n, dict(res.stats)
        stats = {**largest_stats, "components": int(ncomp),
                 "trivial_components": int(trivial.sum()), "largest_component": int(sizes.max())}
        return make_result(problem, np.concatenate(selected), proven_optimal=proven,
                           solve_time_s=time.perf_counter() - t0, backend=self.name, stats=stats)


class Reduce(Layer):
    """Apply exact reductions (:func:`uam_solvers.reductions.reduce_problem`), solve the kernel
    with the child, lift the answer back and make it maximal.

    The reductions keep at least one optimum, so ``proven_optimal`` is the child's flag on the
    kernel (True when the kernel is empty). Stats add the reduction counters. A child that
    declares ``reduces_itself`` (KaMIS, CHILS) gets graphs above ``self_reduce_above`` (256)
    vertices unchanged: it reduces them itself, and the second pass would only eat its time
    budget (on a 10,000-vertex paper-shaped graph these rules remove ~2 % of the vertices).
    """

    def __init__(self, child: Backend, self_reduce_above: int = 256):
        super().__init__(child)
        self.self_reduce_above = int(self_reduce_above)

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        t0 = time.perf_counter()
        if getattr(self.child, "reduces_itself", False) and problem.n > self.self_reduce_above:
            return self.child.solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)
        if problem.n < getattr(self.child, "reduce_min_vertices", 0):
            return self.child.solve(problem, time_limit_s=time_limit_s, seed=seed, options=options)
        red = reduce_problem(problem)
        stats = dict(red.counts)
        proven = True
        chosen = [red.forced]
        if red.kernel.n:
            budget = max(time_limit_s - (time.perf_counter() - t0), 1e-3)
            res = self.child.solve(red.kernel, time_limit_s=budget, seed=seed, options=options)
            chosen.append(red.kept[np.asarray(res.selected, dtype=np.int64)])
            proven = res.proven_optimal
            stats = {**res.stats, **stats}
        sel = complete_maximal(problem, np.concatenate(chosen))
        return make_result(problem, sel, proven_optimal=proven,
                           solve_time_s=time.perf_counter() - t0, backend=self.name, stats=stats)


def _sorted_int32(selected) -> np.ndarray:
    """A checked answer (1-D, distinct, in range: :func:`check_selection`) as sorted int32: the
    backend's own array when it already is one (every backend's ``make_result``:
    ``np.unique`` again cost ~5 us of a 0.35 ms solve), else sorted."""
    a = np.asarray(selected)
    if a.dtype == np.int32 and a.ndim == 1 and (a.size < 2 or bool((a[1:] > a[:-1]).all())):
        return a
    return np.sort(a.astype(np.int64).reshape(-1)).astype(np.int32)


class ValidateFallback(Layer):
    """Check every answer of ``child`` and fall back to ``fallback`` (greedy GWMIN) when needed.

    The child runs on a pooled daemon worker thread so a solve that overruns ``time_limit_s`` by more
    than ``max(margin_s, margin_fraction * time_limit_s)`` (by default OVERRUN_MARGIN_S, so that
    the answer comes within the limit + 0.5 s) is abandoned (the thread is left to finish on its
    own) instead of blocking the caller; a backend that holds the GIL cannot be abandoned so
    (:func:`uam_solvers.solve` runs those in a child process). The answer must be a 1-D array of distinct
    in-range vertex indices that is independent in the input graph, groups included; the
    objective is recomputed in float64 (a differing reported objective is kept in
    ``stats["reported_objective"]``). On an invalid answer, an exception or an overrun the
    fallback's answer is returned with ``fallback=True`` and the reason in ``message``, and a
    warning is logged on the ``uam_solvers`` logger. No caller receives a non-independent set.
    """

    def __init__(self, child: Backend, fallback: Backend | None = None,
                 margin_s: float = OVERRUN_MARGIN_S, margin_fraction: float = 0.0):
        super().__init__(child)
        if fallback is None:
            from .greedy import GreedyBackend
            fallback = GreedyBackend()
        self.fallback = fallback
        self.margin_s = float(margin_s)
        self.margin_fraction = float(margin_fraction)

    def solve(self, problem: MwisProblem, *, time_limit_s: float, seed: int,
              options: Mapping[str, Any]) -> MwisResult:
        t0 = time.perf_counter()
        box: dict[str, Any] = {}

        def run() -> None:
            try:
                box["result"] = self.child.solve(problem, time_limit_s=time_limit_s, seed=seed,
                                                 options=options)
            except BaseException as exc:  # noqa: BLE001 - any failure means fall back
                box["error"] = exc

        allowed_s = time_limit_s + max(self.margin_s, self.margin_fraction * time_limit_s)
        inline_max = getattr(self.child, "thread_inline_max_vertices", None)
        if inline_max is None:
            inline_max = getattr(self.child, "inline_max_vertices", 0)
        if problem.n <= inline_max:
            # known to return within the limit at this size: no thread hand-off (which costs
            # milliseconds on a loaded machine, more than the solve of a 50-vertex graph)
            run()
            finished = True
        else:
            finished = _run_in_worker(run, allowed_s)
        elapsed = time.perf_counter() - t0
        reason = ""
        if not finished:
            reason = (f"backend {self.child.name!r} exceeded its time limit: still running after "
                      f"{elapsed:.3f} s (limit {time_limit_s:.3f} s + margin)")
        elif "error" in box:
            exc = box["error"]
            if isinstance(exc, MwisInputError):
                # input the backend cannot represent (e.g. weights too small to scale to
                # integers): the caller's error, as through the solve service, not a fallback
                raise exc
            reason = f"backend {self.child.name!r} raised {type(exc).__name__}: {exc}"
        else:
            res = box.get("result")
            if not isinstance(res, MwisResult):
                reason = f"backend {self.child.name!r} returned {type(res).__name__}, not MwisResult"
            else:
                ok, why = check_selection(problem, res.selected)
                if not ok:
                    reason = f"backend {self.child.name!r} returned an invalid answer: {why}"
                elif elapsed > allowed_s:
                    reason = (f"backend {self.child.name!r} exceeded its time limit: {elapsed:.3f} s "
                              f"(limit {time_limit_s:.3f} s + margin)")
        if not reason:
            sel = _sorted_int32(res.selected)
            obj = problem.objective(sel)
            stats = dict(res.stats)
            if not math.isclose(float(res.objective), obj, rel_tol=1e-9, abs_tol=1e-9):
                stats["reported_objective"] = float(res.objective)
            return MwisResult(selected=sel, objective=obj, proven_optimal=bool(res.proven_optimal),
                              solve_time_s=elapsed, backend=res.backend, stats=stats,
                              fallback=bool(res.fallback), message=res.message)
        log.warning("MWIS fallback to %s: %s", self.fallback.name, reason)
        try:
            from .greedy import GreedyBackend, fallback_selection, needs_fast_fallback

            if isinstance(self.fallback, GreedyBackend) and needs_fast_fallback(problem):
                sel, rule = fallback_selection(problem)  # bounded time on large graphs
                stats, proven = {"rule": rule}, False
            else:
                fb = self.fallback.solve(problem, time_limit_s=time_limit_s, seed=seed, options={})
                sel, stats, proven = fb.selected, dict(fb.stats), bool(fb.proven_optimal)
            ok, why = check_selection(problem, sel)
            if not ok:
                raise RuntimeError(why)
        except Exception as exc:  # noqa: BLE001 - last resort: the empty set is always independent
            log.error("MWIS fallback %s failed too: %s", self.fallback.name, exc)
            reason += f"; fallback {self.fallback.name!r} failed ({exc}), returning the empty set"
            sel, stats, proven = np.zeros(0, dtype=np.int32), {}, False
        out = make_result(problem, sel, proven_optimal=proven,
                          solve_time_s=time.perf_counter() - t0, backend=self.fallback.name,
                          stats={**stats, "requested_backend": self.child.name}, message=reason)
        out.fallback = True
        return out
