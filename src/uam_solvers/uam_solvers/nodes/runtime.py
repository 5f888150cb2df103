"""Process-level helpers shared by the nodes of every package (uam_solvers is the package the
others depend on)."""

from __future__ import annotations

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


def init_with_stop_event(args=None):
    """``rclpy.init`` with our own SIGINT/SIGTERM handling; returns an Event set on either signal.

    rclpy's own handlers raise KeyboardInterrupt wherever the main thread happens to be (inside a
    callback, or while destroying the node), which can kill a node before its clean-up. Here a
    signal only sets the event; the node's spin loop checks it and ends normally.
    """
    import signal
    import threading

    import rclpy
    from rclpy.signals import SignalHandlerOptions

    stop = threading.Event()
    rclpy.init(args=args, signal_handler_options=SignalHandlerOptions.NO)
    for sig in (signal.SIGINT, signal.SIGTERM):
        signal.signal(sig, lambda _signum, _frame: stop.set())
    return stop
