"""Process-level helpers shared by the nodes of every package: a node's main(), signals, CPU report."""

from __future__ import annotations

import os
import resource
import sys
import time

_T0 = time.monotonic()


def report_cpu_time(node_name: str) -> None:
    """Print this process's CPU and wall time on exit, for scripts/bench_graph.sh ("where the time goes")."""
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(f"[{node_name}] process cpu {usage.ru_utime + usage.ru_stime:.2f} s "
          f"(user {usage.ru_utime:.2f} s, system {usage.ru_stime:.2f} s), wall {time.monotonic() - _T0:.2f} s, "
          f"max rss {usage.ru_maxrss / 1024:.0f} MiB", file=sys.stderr, flush=True)


def report_cpu_time_at_exit(node_name: str) -> None:
    """Register :func:`report_cpu_time` to run when the interpreter exits, however main() ends."""
    import atexit

    atexit.register(report_cpu_time, node_name)


class _FrameInfo:
    """What rclpy's logger reads of ``inspect.getframeinfo(frame)``: the file name."""

    __slots__ = ("filename",)

    def __init__(self, frame) -> None:
        self.filename = frame.f_code.co_filename


class _CheapInspect:
    """``inspect`` for rclpy's logger (``rclpy.impl.rcutils_logger``), without reading sources.

    Every log call of rclpy (Jazzy) names its caller with ``inspect.getframeinfo(frame)``, which
    also finds the frame's module and reads its source line: the first call of a process maps
    every loaded module's file (thousands of ``realpath`` calls), ~0.5 CPU-s per node at start-up
    (1.2 s of the request generator's 2.7 CPU-s under the profiler, for its two log lines), and
    each later call still reads the line (ros2/rclpy#775). The logger uses only the file name,
    which for a Python frame is its code's ``co_filename``: the same value, none of that work."""

    def __init__(self, inspect_module) -> None:
        self._inspect = inspect_module

    @staticmethod
    def getframeinfo(frame, context: int = 1):  # noqa: ARG004 - inspect's signature
        return _FrameInfo(frame)

    def __getattr__(self, name: str):
        return getattr(self._inspect, name)


def cheap_log_caller() -> bool:
    """Let rclpy's logger name its caller from the frame's code instead of
    ``inspect.getframeinfo`` (:class:`_CheapInspect`); False if rclpy has no such module."""
    try:
        from rclpy.impl import rcutils_logger
    except ImportError:  # pragma: no cover - rclpy is a dependency of every node
        return False
    if not isinstance(rcutils_logger.inspect, _CheapInspect):
        rcutils_logger.inspect = _CheapInspect(rcutils_logger.inspect)
    return True


def freeze_start_up_objects() -> None:
    """Move every object alive once the node is built (modules, network, route templates) to
    the collector's permanent generation: a full collection then no longer walks them. The
    planner node spent ~10 % of its samples in the cyclic collector, rescanning the start-up
    heap. Objects stay alive as before; only the collector stops visiting them."""
    import gc

    gc.collect()
    gc.freeze()


def init_with_stop_event(args=None):
    """``rclpy.init`` with our own SIGINT/SIGTERM handling (and rclpy's logger naming its caller
    cheaply: :func:`cheap_log_caller`); returns an Event set on either signal.

    rclpy's own handlers raise KeyboardInterrupt wherever the main thread happens to be (inside a
    callback, or while destroying the node), which can kill a node before its clean-up. Here a
    signal only sets the event; the node's spin loop checks it and ends normally.
    """
    import signal
    import threading

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    stop = threading.Event()
    cheap_log_caller()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)

    def on_signal(_signum, _frame) -> None:
        if not stop.is_set():
            stop.signalled_at = time.monotonic()  # for the clean-up's timing report
        stop.set()

    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, on_signal)
    return stop


#: how long a node that ends waits for its subscribers to acknowledge what it published [s]
ACK_TIMEOUT_S = 30.0


def flush_publishers(node, timeout_s: float) -> bool:
    """Wait (at most ``timeout_s`` in all) until every reliable subscriber has acknowledged what
    ``node`` published; log the topics that were not. A reliable writer that goes away takes its
    unacknowledged samples with it: a recorder that lags behind the run (it runs niced and
    catches up after the end) then missed the last messages, the simulator's end-of-run
    announcement among them, and waited for it until run_fleet.sh stopped it."""
    from rclpy.duration import Duration

    end = time.monotonic() + timeout_s
    late = []
    for pub in list(node.publishers):
        try:
            if not pub.wait_for_all_acked(Duration(nanoseconds=int(max(end - time.monotonic(), 0.0) * 1e9))):
                late.append(pub.topic_name)
        except Exception:  # noqa: BLE001 - a publisher destroyed meanwhile, or an rmw without acks
            continue
    if late:
        node.get_logger().warning(f"not acknowledged within {timeout_s:g} s by every subscriber: {', '.join(late)}")
    return not late


def run_node(make_node, name: str, args=None, *, threads: int = 1, linger_s: float = 0.0,
             events_executor: bool = False, stateless: bool = False) -> int:
    """:func:`_run_node`, under cProfile when ``UAM_PROFILE_DIR`` is set (the profile of the
    main thread goes to ``$UAM_PROFILE_DIR/<name>.prof``, for ``python -m pstats``); then the
    process ends with its exit code (:func:`_exit_now`): this does not return."""
    import os

    out_dir = os.environ.get("UAM_PROFILE_DIR", "")
    if not out_dir:
        code = _run_node(make_node, name, args, threads=threads, linger_s=linger_s,
                         events_executor=events_executor, stateless=stateless)
    else:
        import cProfile
        from pathlib import Path

        Path(out_dir).mkdir(parents=True, exist_ok=True)
        prof = cProfile.Profile()
        try:
            code = prof.runcall(_run_node, make_node, name, args, threads=threads, linger_s=linger_s,
                                events_executor=events_executor, stateless=stateless)
        finally:
            prof.dump_stats(str(Path(out_dir) / f"{name}.prof"))
    _exit_now(code)


#: how long a node's exit handlers may take before the process ends anyway [s]
EXIT_HANDLERS_S = 3.0


def _exit_now(code: int) -> None:
    """End the process once the node is cleaned up: the exit handlers run (the CPU report,
    multiprocessing's reaping of worker processes), then ``os._exit``, skipping the interpreter's
    finalization. Finalization could hang: in a fresh-clone CI run the solver node printed its
    CPU report (an exit handler) at once on SIGINT and then did not end within run_fleet.sh's
    10 s (frozen daemon threads and rclpy/DDS destructors run there in no set order). Nothing
    of ours is left to finalize: recordings are closed by ``close()``, the node is destroyed and
    rclpy shut down before this. Callback threads still blocked are abandoned, as they would be
    by a kill; this is only called from a node process's main()."""
    import atexit
    import os
    import threading

    def flush_and_exit() -> None:
        for stream in (sys.stdout, sys.stderr):
            try:
                stream.flush()
            except (OSError, ValueError):
                pass
        os._exit(code)

    # The exit handlers get EXIT_HANDLERS_S at most: in a fresh-clone CI run the recorder printed
    # its CPU report (the last of ours) and then hung in a handler registered at import (logging's
    # or multiprocessing's, which take locks another thread may hold) past run_fleet.sh's 10 s.
    watchdog = threading.Timer(EXIT_HANDLERS_S, flush_and_exit)
    watchdog.daemon = True
    watchdog.start()
    # and a bound that needs no Python thread: the request generator once printed its CPU report
    # and hung on past 10 s with this watchdog armed (a handler blocked holding the GIL, so the
    # thread never ran). SIGALRM's default action ends the process (exit status 142) in the
    # kernel one second after the watchdog was due.
    import signal
    # and what hangs, if one does: faulthandler's own C thread (no GIL needed) prints every
    # Python thread's stack to stderr half a second before the watchdog is due, so the next
    # such hang names its handler (which one hung is not known yet: BENCHMARKS.md)
    import faulthandler
    try:
        faulthandler.dump_traceback_later(EXIT_HANDLERS_S - 0.5, exit=False)
    except (RuntimeError, ValueError, OSError):  # no usable stderr
        pass
    if threading.current_thread() is threading.main_thread():
        signal.signal(signal.SIGALRM, signal.SIG_DFL)
        signal.alarm(int(EXIT_HANDLERS_S) + 1)
    try:
        atexit._run_exitfuncs()  # noqa: SLF001 - the documented exit handlers, run once, here
    finally:
        flush_and_exit()


def _run_node(make_node, name: str, args=None, *, threads: int = 1, linger_s: float = 0.0,
              events_executor: bool = False, stateless: bool = False) -> int:
    """The main() of a node: init, spin until the node is ``finished`` or a signal, clean up.

    ``make_node()`` builds the node (a ValueError or OSError from it is a configuration error,
    e.g. a bad parameter or a missing file: printed, exit code 2). ``threads`` > 1 spins a MultiThreadedExecutor (needed where a callback waits
    on a service answer). After the loop, ``linger_s`` more seconds are spun so final messages
    leave. The exit code is the node's ``exit_code`` attribute if it has one, else 0. A node with a
    ``stopping`` threading.Event gets it set when the loop ends, for callbacks that wait; a node
    with a ``close()`` method (e.g. an open recording) gets it called before it is destroyed,
    however the loop ended. A node that ends by itself waits (ACK_TIMEOUT_S at most) until its
    reliable subscribers acknowledged everything it published (:func:`flush_publishers`).
    ``events_executor`` spins rclpy's C++ EventsExecutor instead of the
    SingleThreadedExecutor: far less overhead per message (the recorder takes ~14,000 messages
    a paper run; BENCHMARKS.md), but it does not run coroutine callbacks, so only for nodes
    without async callbacks. After a signal, a watcher (:func:`_watch_stop`) prints every
    thread's stack if the node has not ended STOP_DUMP_S later; a ``stateless`` node (nothing to
    save: the solver) is then ended by it too, with exit code 0 and a warning naming the wait.
    """
    import rclpy
    from rclpy.executors import ExternalShutdownException, MultiThreadedExecutor, SingleThreadedExecutor

    report_cpu_time_at_exit(name)
    stop = init_with_stop_event(args)
    import threading
    threading.Thread(target=_watch_stop, args=(name, stop, stateless), daemon=True,
                     name="uam-stop-watch").start()
    node = None
    try:
        node = make_node()
        freeze_start_up_objects()
        if events_executor:
            from rclpy.experimental import EventsExecutor
            executor = EventsExecutor()
        else:
            executor = MultiThreadedExecutor(num_threads=threads) if threads > 1 else SingleThreadedExecutor()
        executor.add_node(node)
        while rclpy.ok() and not getattr(node, "finished", False) and not stop.is_set():
            executor.spin_once(timeout_sec=0.1)
        end = time.monotonic() + linger_s
        while rclpy.ok() and time.monotonic() < end and not stop.is_set():
            executor.spin_once(timeout_sec=0.05)
        if not stop.is_set():
            flush_publishers(node, ACK_TIMEOUT_S)
        # A callback may still be waiting (e.g. the planner on a solver that already stopped);
        # tell it, so the executor's worker threads end and the process can exit at once.
        if hasattr(node, "stopping"):
            node.stopping.set()
        return int(getattr(node, "exit_code", 0))
    except (KeyboardInterrupt, ExternalShutdownException):
        return 0
    except (ValueError, OSError) as exc:
        print(f"{name}: {exc}", file=sys.stderr)
        return 2
    finally:
        cleanup = _CleanupTimer(name, getattr(stop, "signalled_at", None))
        # After a stop signal the node is closed (its recording, journal or worker processes) and
        # then left to the process's end (_exit_now), neither destroyed nor rclpy shut down: in a
        # loaded run the solver node's destroy_node() spun in rclpy's C++ holding the GIL for more
        # than 10 s (faulthandler: main thread in Node.destroy_node, state R), so neither its stop
        # watcher nor its exit handlers could run and run_fleet.sh killed it. Nothing is lost by
        # skipping it: os._exit follows, and the DDS participant's peers drop it by its lease. A
        # node that ended by itself is still destroyed and shut down as before.
        signalled = stop.is_set()
        try:
            if node is not None:
                try:
                    if hasattr(node, "close"):
                        node.close()
                        cleanup.phase("close")
                finally:
                    if not signalled:
                        node.destroy_node()
                        cleanup.phase("destroy_node")
            if not signalled:
                rclpy.try_shutdown()
                cleanup.phase("rclpy shutdown")
        finally:
            cleanup.done()
            _ignore_stop_signals()


#: after a signal, a node not ended this long after it prints every thread's stack [s]; a
#: stateless node is ended then (run_fleet.sh kills a node 10 s after its SIGINT and reports it).
#: ``UAM_STOP_DUMP_S`` sets another value (the runtime's test uses 1 s)
STOP_DUMP_S = 7.0


def _stop_dump_s() -> float:
    try:
        value = float(os.environ.get("UAM_STOP_DUMP_S", STOP_DUMP_S))
    except ValueError:
        return STOP_DUMP_S
    return value if 0.0 < value < 3600.0 else STOP_DUMP_S


def _watch_stop(name: str, stop, stateless: bool) -> None:
    """The stop watcher of :func:`_run_node` (a daemon thread): waits for the signal, then
    arms faulthandler, whose own C thread (no GIL needed) prints every thread's stack if the
    process is still running STOP_DUMP_S after the signal; for a ``stateless`` node it then
    ends the process itself, exit code 0, saying so. Why: in fresh-clone CI runs the solver
    node now and then did not end within run_fleet.sh's 10 s of a SIGINT; its log ended with
    its CPU report and no stack, so the exit handlers, which _exit_now bounds and dumps, were
    not what hung, and which part did is not known yet (BENCHMARKS.md).
    A process that ends in time prints nothing: os._exit takes this thread with it."""
    import faulthandler

    stop.wait()
    t_signal = getattr(stop, "signalled_at", time.monotonic())
    dump_s = _stop_dump_s()
    try:
        faulthandler.dump_traceback_later(max(dump_s - (time.monotonic() - t_signal), 0.01), exit=False)
    except (RuntimeError, ValueError, OSError):  # no usable stderr
        pass
    if not stateless:
        return
    time.sleep(max(dump_s + 0.3 - (time.monotonic() - t_signal), 0.0))
    print(f"[{name}] WARNING: not ended {time.monotonic() - t_signal:.1f} s after the stop signal "
          f"(every thread's stack is above); this node keeps no state, so it ends now",
          file=sys.stderr, flush=True)
    os._exit(0)


class _CleanupTimer:
    """Times a node's clean-up phase by phase; after a signal it prints the phases' times (and
    how long the spin loop took to see the signal) to stderr, so that a slow stop names its
    phase (see :func:`_watch_stop`). A normal end prints nothing."""

    def __init__(self, name: str, signalled_at: float | None):
        self.name, self.signalled_at = name, signalled_at
        self.t0 = self.last = time.monotonic()
        self.phases: list[tuple[str, float]] = []

    def phase(self, label: str) -> None:
        now = time.monotonic()
        self.phases.append((label, now - self.last))
        self.last = now

    def done(self) -> None:
        if self.signalled_at is None:
            return
        parts = ", ".join(f"{label} {dt:.2f} s" for label, dt in self.phases)
        print(f"[{self.name}] stopped by a signal: the loop ended {self.t0 - self.signalled_at:.2f} s after it; "
              f"clean-up {self.last - self.t0:.2f} s ({parts or 'nothing to clean'})", file=sys.stderr, flush=True)


def _ignore_stop_signals() -> None:
    """Ignore SIGINT and SIGTERM from here on: the node is done and cleaned up. While the
    interpreter finalizes, Python resets a signal with a Python handler to the default action, so
    the SIGINT that run_fleet.sh sends every node at the end of a run killed a node that was still
    exiting ("node 'planner' exited with code 130" after a normal run). Ignored signals stay ignored."""
    import signal
    import threading

    if threading.current_thread() is threading.main_thread():
        for sig in (signal.SIGINT, signal.SIGTERM):
            signal.signal(sig, signal.SIG_IGN)
