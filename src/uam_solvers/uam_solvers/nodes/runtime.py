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
