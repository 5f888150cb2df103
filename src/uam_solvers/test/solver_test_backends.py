"""Backends that misbehave on purpose, for the solve-service tests (imported by module name in
worker processes, so this directory is put on sys.path by the tests that use them)."""
import os
import re

from uam_solvers.base import Backend, make_result


class GilHoldingBackend(Backend):
    """Holds the GIL in one C call that never ends in practice: the regex engine backtracking
    over 2^40 ways to split a run of 'a's (the re module does not release the GIL)."""

    name = "test-gil-hog"
    description = "test: one endless C call holding the GIL"

    def solve(self, problem, *, time_limit_s, seed, options):
        re.match(r"(a+)+$", "a" * 40 + "b")
        return make_result(problem, [], proven_optimal=False, solve_time_s=0.0, backend=self.name)


class CrashingBackend(Backend):
    """Ends its process at once, as a segfaulting extension would."""

    name = "test-crash"
    description = "test: the worker process dies"

    def solve(self, problem, *, time_limit_s, seed, options):
        os._exit(3)


class WorkerPidBackend(Backend):
    """Answers the empty set and reports its process id and the seed it got (to see where a
    solve ran and what reached it)."""

    name = "test-pid"
    description = "test: reports the solving process id and seed"

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [], proven_optimal=False, solve_time_s=0.0, backend=self.name,
                           stats={"pid": os.getpid(), "seed": seed})


class LimitReportingBackend(Backend):
    """Answers the empty set and reports the time limit it was given."""

    name = "test-limit"
    description = "test: reports the time limit that reached it"

    def solve(self, problem, *, time_limit_s, seed, options):
        return make_result(problem, [], proven_optimal=False, solve_time_s=0.0, backend=self.name,
                           stats={"limit_s": float(time_limit_s)})
