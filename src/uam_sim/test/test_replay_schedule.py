"""Replay: the schedule math (no ROS), the plan read from a recording, and the node in-process."""

from __future__ import annotations

import math

import numpy as np
import pytest

from uam_contract.qos_spec import QosSpec
from uam_sim.views.replay import ReplayPlan, replay_qos, schedule_offsets_s


def test_offsets_scale_with_rate():
    ns = [5_000_000_000, 6_000_000_000, 8_000_000_000]
    assert list(schedule_offsets_s(ns, 1.0)) == [0.0, 1.0, 3.0]
    assert list(schedule_offsets_s(ns, 2.0)) == [0.0, 0.5, 1.5]
    assert list(schedule_offsets_s(ns, 0.5)) == [0.0, 2.0, 6.0]
    assert list(schedule_offsets_s(ns, 0)) == [0.0, 0.0, 0.0]  # as fast as possible
    assert schedule_offsets_s([], 3.0).size == 0


@pytest.mark.parametrize("rate", [-1.0, math.nan, math.inf])
def test_bad_rate_is_refused(rate):
    with pytest.raises(ValueError, match="rate"):
        schedule_offsets_s([0, 1], rate)


def test_out_of_order_times_are_refused_with_the_index():
    with pytest.raises(ValueError, match="index 2"):
        schedule_offsets_s([0, 5, 3], 1.0)


def test_due_hands_out_each_message_once_in_order():
    plan = ReplayPlan(data=[b"a", b"b", b"c", b"d"], topic_of=["/x"] * 4,
                      offsets_s=np.array([0.0, 0.5, 0.5, 1.5]))
    assert list(plan.due(0.0)) == [0]
    assert list(plan.due(0.4)) == []
    assert plan.seconds_until_next(0.4) == pytest.approx(0.1)
    assert list(plan.due(0.5)) == [1, 2]
    assert list(plan.due(0.5)) == []
    assert list(plan.due(10.0, limit=5)) == [3]
    assert plan.done and plan.seconds_until_next(11.0) == math.inf


def test_due_respects_the_batch_limit():
    plan = ReplayPlan(data=[b""] * 5, topic_of=["/x"] * 5, offsets_s=np.zeros(5))
    assert list(plan.due(0.0, limit=2)) == [0, 1]
    assert list(plan.due(0.0, limit=2)) == [2, 3]
    assert list(plan.due(0.0, limit=2)) == [4]


def test_replay_qos_follows_agreeing_offers_and_falls_back_on_mixed_ones():
    latched = QosSpec(depth=20000, durability="transient_local")
    assert replay_qos([latched, latched]).durability == "transient_local"
    assert replay_qos([latched]).depth == 20000
    mixed = replay_qos([latched, QosSpec(reliability="best_effort")])
    assert (mixed.reliability, mixed.durability) == ("reliable", "volatile")
    endpoint = QosSpec(history="unknown", depth=0, durability="transient_local")  # as DDS reports it
    assert replay_qos([endpoint]).depth == 20000
    assert replay_qos([]) == QosSpec()
