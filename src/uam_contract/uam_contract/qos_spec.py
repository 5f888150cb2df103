"""QoS profiles as rosbag2 writes them into a recording (``offered_qos_profiles`` YAML).

:class:`QosSpec` is a plain, rclpy-free record of one profile; :func:`offered_qos_yaml` writes
the YAML list rosbag2 Jazzy puts into a channel's metadata, :func:`parse_offered_qos` reads it.
"""

from __future__ import annotations

import functools
from dataclasses import dataclass
from typing import Any, Sequence

import yaml

INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}


@dataclass(frozen=True)
class QosSpec:
    """A QoS profile in rosbag2's words (lower-case policy names, as in metadata version 9).

    ``history``: keep_last | keep_all | system_default | unknown; ``depth``: history depth;
    ``reliability``: reliable | best_effort | system_default; ``durability``: volatile |
    transient_local | system_default; ``liveliness``: automatic | manual_by_topic |
    system_default; durations in nanoseconds, None = infinite (the default of every profile).
    """

    history: str = "keep_last"
    depth: int = 10
    reliability: str = "reliable"
    durability: str = "volatile"
    deadline_ns: int | None = None
    lifespan_ns: int | None = None
    liveliness: str = "automatic"
    liveliness_lease_duration_ns: int | None = None
    avoid_ros_namespace_conventions: bool = False

    @staticmethod
    def _duration(ns: int | None) -> dict:
        if ns is None or ns <= 0:  # 0 is "unspecified": a DDS publisher offers infinity
            return dict(INFINITE_DURATION)
        return {"sec": int(ns // 1_000_000_000), "nsec": int(ns % 1_000_000_000)}

    def to_dict(self) -> dict:
        """The mapping rosbag2 writes for one offered profile (key order as rosbag2)."""
        return {
            "history": self.history,
            "depth": int(self.depth),
            "reliability": self.reliability,
            "durability": self.durability,
            "deadline": self._duration(self.deadline_ns),
            "lifespan": self._duration(self.lifespan_ns),
            "liveliness": self.liveliness,
            "liveliness_lease_duration": self._duration(self.liveliness_lease_duration_ns),
            "avoid_ros_namespace_conventions": bool(self.avoid_ros_namespace_conventions),
        }

    @classmethod
    def from_profile(cls, profile: Any) -> "QosSpec":
        """From an ``rclpy.qos.QoSProfile`` (duck-typed), a QosSpec, a dict or None (defaults)."""
        if profile is None:
            return cls()
        if isinstance(profile, QosSpec):
            return profile
        if isinstance(profile, dict):
            return cls(**profile)

        def name(policy: Any, resolved: str) -> str:
            # "system_default" is resolved by the DDS layer before rosbag2 sees the offer.
            text = getattr(policy, "name", str(policy)).lower()
            return resolved if text == "system_default" else text

        def ns(duration: Any) -> int | None:
            value = getattr(duration, "nanoseconds", duration)
            return None if value is None else int(value)

        return cls(
            history=name(profile.history, "keep_last"),
            depth=int(profile.depth),
            reliability=name(profile.reliability, "reliable"),
            durability=name(profile.durability, "volatile"),
            deadline_ns=ns(profile.deadline),
            lifespan_ns=ns(profile.lifespan),
            liveliness=name(profile.liveliness, "automatic"),
            liveliness_lease_duration_ns=ns(profile.liveliness_lease_duration),
            avoid_ros_namespace_conventions=bool(profile.avoid_ros_namespace_conventions),
        )


def offered_qos_yaml(profiles: Sequence[Any]) -> str:
    """The ``offered_qos_profiles`` channel metadata: a YAML list of profiles (rosbag2 Jazzy)."""
    return _qos_yaml(tuple(QosSpec.from_profile(p) for p in profiles))


@functools.lru_cache(maxsize=256)
def _qos_yaml(specs: tuple[QosSpec, ...]) -> str:
    # cached: the recorder adds one channel per vehicle for the views, all with one profile
    return yaml.safe_dump([s.to_dict() for s in specs], sort_keys=False, default_flow_style=False)


def parse_offered_qos(text: str) -> list[QosSpec]:
    """Inverse of :func:`offered_qos_yaml` (for replay): the offered profiles of a channel."""
    items = yaml.safe_load(text) if text else []
    out = []
    for item in items or []:
        def dur(key: str) -> int | None:
            d = item.get(key) or {}
            sec, nsec = int(d.get("sec", 0)), int(d.get("nsec", 0))
            if (sec, nsec) == (INFINITE_DURATION["sec"], INFINITE_DURATION["nsec"]) or sec >= 2**31 - 1:
                return None
            return sec * 1_000_000_000 + nsec
        out.append(QosSpec(
            history=str(item.get("history", "keep_last")), depth=int(item.get("depth", 10)),
            reliability=str(item.get("reliability", "reliable")),
            durability=str(item.get("durability", "volatile")),
            deadline_ns=dur("deadline"), lifespan_ns=dur("lifespan"),
            liveliness=str(item.get("liveliness", "automatic")),
            liveliness_lease_duration_ns=dur("liveliness_lease_duration"),
            avoid_ros_namespace_conventions=bool(item.get("avoid_ros_namespace_conventions", False))))
    return out
