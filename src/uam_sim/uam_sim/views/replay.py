"""Replay of a recording: what to publish, on which topic with which QoS, and when.

No rclpy here: the node (``uam_sim.nodes.replay_node``) only publishes what :class:`ReplayPlan`
says is due. Timing: a message recorded at log time ``t`` is due ``(t - t_first) / rate`` wall
seconds after the replay starts; ``rate`` 0 means as fast as possible (everything is due at
once, published in log-time order).
"""

from __future__ import annotations

import math
import os
from dataclasses import dataclass, field
from typing import Sequence

import numpy as np

from ..recording.mcap_reader import is_complete, read_messages, read_messages_tolerant
from uam_contract.qos_spec import QosSpec, parse_offered_qos


def schedule_offsets_s(log_times_ns: Sequence[int], rate: float) -> np.ndarray:
    """Wall-time offsets [s] from the start of the replay at which each message is due.

    ``log_times_ns``: the messages' log times [ns] in replay order (non-decreasing);
    ``rate``: playback speed (2.0 = twice as fast), > 0, or 0 for as fast as possible.
    Returns an (n,) float64 array, non-decreasing, starting at 0. O(n).
    """
    if not isinstance(rate, (int, float)) or math.isnan(rate) or rate < 0 or math.isinf(rate):
        raise ValueError(f"rate: must be a finite number >= 0 (0 = as fast as possible), got {rate!r}")
    t = np.asarray(log_times_ns, dtype=np.int64)
    if t.ndim != 1:
        raise ValueError(f"log_times_ns: expected a 1-D sequence, got shape {t.shape}")
    if t.size == 0:
        return np.zeros(0)
    if np.any(np.diff(t) < 0):
        i = int(np.flatnonzero(np.diff(t) < 0)[0])
        raise ValueError(f"log_times_ns: not in order at index {i + 1} ({t[i + 1]} < {t[i]})")
    if rate == 0:
        return np.zeros(t.size)
    return (t - t[0]).astype(np.float64) * 1e-9 / float(rate)


def replay_qos(offered: Sequence[QosSpec]) -> QosSpec:
    """The QoS to publish a recorded topic with, from what its publishers offered.

    As rosbag2 does: if all offers agree on reliability and durability, use them; otherwise
    reliable + volatile (which every subscriber matches except a transient-local one). The
    history is keep_last with a depth large enough for a transient-local topic's late joiners.
    """
    if not offered:
        return QosSpec()
    rel = {q.reliability for q in offered}
    dur = {q.durability for q in offered}
    reliability = rel.pop() if len(rel) == 1 else "reliable"
    durability = dur.pop() if len(dur) == 1 else "volatile"
    if reliability not in ("reliable", "best_effort"):
        reliability = "reliable"
    if durability not in ("volatile", "transient_local"):
        durability = "volatile"
    depths = [q.depth for q in offered if q.history == "keep_last" and q.depth > 0]
    depth = max(depths) if depths else (20000 if durability == "transient_local" else 1000)
    return QosSpec(history="keep_last", depth=depth, reliability=reliability, durability=durability)


@dataclass
class ReplayTopic:
    """One recorded topic: its type and the QoS to publish it with."""

    topic: str
    type_name: str
    qos: QosSpec
    count: int = 0


@dataclass
class ReplayPlan:
    """Everything to replay, in log-time order, with each message's due offset [s]."""

    topics: dict = field(default_factory=dict)      # topic -> ReplayTopic
    topic_of: list = field(default_factory=list)    # per message
    data: list = field(default_factory=list)        # per message: CDR bytes
    log_times_ns: np.ndarray = field(default_factory=lambda: np.zeros(0, dtype=np.int64))
    offsets_s: np.ndarray = field(default_factory=lambda: np.zeros(0))
    rate: float = 1.0
    next_index: int = 0

    @property
    def total(self) -> int:
        return len(self.data)

    @property
    def done(self) -> bool:
        return self.next_index >= len(self.data)

    @property
    def duration_s(self) -> float:
        """Wall time the replay takes [s] (0 at rate 0)."""
        return float(self.offsets_s[-1]) if len(self.offsets_s) else 0.0

    def due(self, elapsed_s: float, limit: int | None = None) -> range:
        """Indices of the messages due at ``elapsed_s`` wall seconds after the start, not yet
        handed out (at most ``limit``); advances past them. O(log n)."""
        end = int(np.searchsorted(self.offsets_s, elapsed_s, side="right"))
        if limit is not None:
            end = min(end, self.next_index + int(limit))
        start = self.next_index
        self.next_index = max(start, end)
        return range(start, self.next_index)

    def seconds_until_next(self, elapsed_s: float) -> float:
        """Wall seconds until the next message is due (0 if one is due now; inf when done)."""
        if self.done:
            return math.inf
        return max(0.0, float(self.offsets_s[self.next_index]) - elapsed_s)


def load_plan(path: str | os.PathLike, rate: float = 1.0, topics: Sequence[str] | None = None) -> ReplayPlan:
    """Read a recording into a :class:`ReplayPlan` (a crash-cut file replays what was written).

    ``topics``: only these topics (None or empty: all). Raises ValueError for a bad rate or a
    topic not in the recording.
    """
    wanted = set(topics or ())
    records = read_messages(path) if is_complete(path) else \
        sorted(read_messages_tolerant(path), key=lambda r: r.log_time_ns)
    plan = ReplayPlan(rate=rate)
    times = []
    for rec in records:
        if wanted and rec.topic not in wanted:
            continue
        info = plan.topics.get(rec.topic)
        if info is None:
            info = ReplayTopic(rec.topic, rec.type_name, replay_qos(parse_offered_qos(rec.qos_yaml)))
            plan.topics[rec.topic] = info
        info.count += 1
        plan.topic_of.append(rec.topic)
        plan.data.append(rec.data)
        times.append(rec.log_time_ns)
    missing = wanted - set(plan.topics)
    if missing:
        raise ValueError(f"topics: {sorted(missing)} have no messages in {path}")
    plan.log_times_ns = np.asarray(times, dtype=np.int64)
    plan.offsets_s = schedule_offsets_s(plan.log_times_ns, rate)
    return plan
