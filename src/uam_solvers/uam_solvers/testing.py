"""The backend contract, for plugin authors (as ``dimod.testing`` is for samplers).

    from uam_solvers.testing import assert_backend_contract

    def test_my_backend_keeps_the_contract():
        assert_backend_contract(MyBackend)          # a Backend subclass, instance or registered name

Every check the project's own backends pass (``src/uam_solvers/test/test_backend_contract.py``
runs these same functions over every registered backend):

- :func:`assert_answer_kept`: solved through a :class:`~uam_solvers.executor.SolveService` (as the
  solver node and the runner solve), the answer is an independent set, its objective is the sum
  of its weights, the backend itself answered (no worker killed at the limit, no fallback);
- :func:`assert_options_validated`: an unknown option and a number option given a string are
  refused with ``MwisInputError`` naming ``options['key']``;
- :func:`assert_deterministic`: the same seed gives the same set (asked with
  ``deterministic=True``: a backend that runs to its time limit, an anytime search, may answer
  more or less of its search in a loaded second).

No timing is asserted (the limit is measured by ``python -m uam_solvers.bench``); a backend that
does not answer by its limit plus the service's margin is killed and fails the first check.
"""

from __future__ import annotations

import numpy as np

from . import MwisInputError
from .instances import large_instance, paper_instance

#: the problems of the contract: a paper-sized graph and a large sparse one
CONTRACT_PROBLEMS = {"paper-8": lambda: paper_instance(8, seed=11),
                     "large-400": lambda: large_instance(400, seed=12)}


def assert_answer_kept(service, backend, problem, time_limit_s: float = 1.0, seed: int = 0) -> None:
    """The answer of ``backend`` on ``problem`` through ``service`` keeps the contract."""
    r = service.solve(problem, backend=backend, time_limit_s=time_limit_s, seed=seed)
    assert problem.is_independent(r.selected), f"not an independent set: {r.selected!r}"
    total = float(np.sum(problem.weights[r.selected]))
    assert abs(r.objective - total) <= 1e-12 * max(1.0, abs(total)), (r.objective, total)
    assert r.stats["executor"] in ("inline", "worker"), (r.stats["executor"], r.message)
    assert not r.fallback, r.message


def assert_options_validated(service, backend, problem, options_spec, time_limit_s: float = 1.0) -> None:
    """An unknown option, and every number option given a string, refused naming the option."""
    for key, value in [("bogus", 1)] + [(k, "not a number") for k, spec in options_spec.items()
                                         if spec.kind in ("int", "float")]:
        try:
            service.solve(problem, backend=backend, time_limit_s=time_limit_s, options={key: value})
        except MwisInputError as exc:
            assert f"options[{key!r}]" in str(exc), str(exc)
        else:
            raise AssertionError(f"options {{{key!r}: {value!r}}} was accepted")


def assert_deterministic(service, backend, problem, time_limit_s: float = 1.0, seed: int = 3) -> None:
    """Two solves with one seed give one set."""
    a = service.solve(problem, backend=backend, time_limit_s=time_limit_s, seed=seed)
    b = service.solve(problem, backend=backend, time_limit_s=time_limit_s, seed=seed)
    assert sorted(np.asarray(a.selected).tolist()) == sorted(np.asarray(b.selected).tolist())


def assert_backend_contract(backend, time_limit_s: float = 1.0, service=None,
                            deterministic: bool = False) -> None:
    """Every check above on the contract's problems, warmed up first (a backend's first solve pays
    its imports, which the contract does not hold it to). ``backend``: a registered name, a
    Backend instance or a Backend subclass; ``service``: a SolveService (default: a new one,
    closed at the end)."""
    from .executor import SolveService
    from .registry import get_backend
    if isinstance(backend, type):
        backend = backend()
    instance = get_backend(backend) if isinstance(backend, str) else backend
    own = service is None
    service = SolveService(small_workers=1, large_workers=1, margin_s=10.0) if own else service
    try:
        problems = {k: make() for k, make in CONTRACT_PROBLEMS.items()}
        service.solve(problems["paper-8"], backend=backend, time_limit_s=3.0, seed=0)   # warm-up
        for problem in problems.values():
            assert_answer_kept(service, backend, problem, time_limit_s)
        assert_options_validated(service, backend, problems["paper-8"], instance.options_spec, time_limit_s)
        if deterministic:
            assert_deterministic(service, backend, problems["paper-8"], time_limit_s)
    finally:
        if own:
            service.close()
