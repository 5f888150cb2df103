"""The Examples in the public entry points' docstrings run, as written (doctest): what a reader
copies from them works."""

from __future__ import annotations

import doctest
import importlib

import pytest

MODULES = ("uam_solvers", "uam_planner.audit", "uam_planner.conformance", "uam_planner.planning",
           "uam_contract.disturbances")


@pytest.mark.parametrize("name", MODULES)
def test_the_examples_run(name):
    module = importlib.import_module(name)
    result = doctest.testmod(module, optionflags=doctest.ELLIPSIS | doctest.NORMALIZE_WHITESPACE)
    assert result.attempted > 0, f"{name} has no Examples"
    assert result.failed == 0, f"{name}: {result.failed} of {result.attempted} examples failed (output above)"
