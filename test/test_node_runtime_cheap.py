"""The node runtime's start-up savings: rclpy's logger names its caller without reading sources,
and the start-up heap is frozen out of the cyclic collector."""

from __future__ import annotations

import gc
import inspect
import os

import pytest

pytest.importorskip("rclpy", reason="needs the built workspace (source scripts/env.sh)")

from rclpy.impl import rcutils_logger  # noqa: E402

from uam_bringup import runtime  # noqa: E402


def _caller_here():
    return rcutils_logger.CallerId()


def test_the_logger_names_the_same_caller_without_inspect_reading_sources(monkeypatch):
    monkeypatch.setattr(rcutils_logger, "inspect", inspect)
    before = _caller_here()
    assert runtime.cheap_log_caller()
    assert runtime.cheap_log_caller()   # a second call keeps one wrapper
    assert isinstance(rcutils_logger.inspect, runtime._CheapInspect)
    assert not isinstance(rcutils_logger.inspect._inspect, runtime._CheapInspect)
    after = _caller_here()
    assert after.function_name == before.function_name == "_caller_here"
    assert after.file_path == before.file_path == os.path.abspath(__file__)

    def no_sources(*_a, **_k):
        raise AssertionError("the logger read a source file")

    # what made the first log call of a node cost ~0.5 CPU-s
    monkeypatch.setattr(inspect, "findsource", no_sources)
    monkeypatch.setattr(inspect, "getmodule", no_sources)
    assert _caller_here().line_number == after.line_number


def test_a_log_call_through_a_logger_still_works_with_the_cheap_caller(monkeypatch, capfd):
    import rclpy.logging

    monkeypatch.setattr(rcutils_logger, "inspect", inspect)
    runtime.cheap_log_caller()
    logger = rclpy.logging.get_logger("cheap_caller_probe")
    logged = [logger.info("probe once", once=True) for _ in range(2)]
    assert logged == [True, False]   # "once" keys on the caller: one line, logged once


def test_frozen_start_up_objects_stay_alive_and_out_of_the_collector():
    probe = [[i] for i in range(1000)]
    try:
        runtime.freeze_start_up_objects()
        assert gc.get_freeze_count() >= 1000
        assert probe[999] == [999]
    finally:
        gc.unfreeze()
