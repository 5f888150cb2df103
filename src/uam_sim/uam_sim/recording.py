"""MCAP recording exactly as rosbag2 (Jazzy, ``rosbag2_storage_mcap``) writes it.

What a reader of the file can rely on (checked by ``test_recording_*.py``):

- header profile ``ros2``; library string ``uam_sim/<version> (mcap-python/<version>)``;
- one schema per message type: name ``pkg/msg/Type``, encoding ``ros2msg``, data = the type's
  ``.msg`` file text as installed (comments kept, as rosbag2 keeps them), followed, for every
  dependency not yet written (depth first, in sorted order per file, each type once), by a
  newline, a line of 80 ``=``, a line ``MSG: pkg/Type`` and that type's ``.msg`` text;
- one channel per topic: message encoding ``cdr``, metadata ``offered_qos_profiles`` (the YAML
  list that rosbag2 Jazzy writes: ``history``/``reliability``/``durability``/``liveliness`` as
  lower-case names, durations as ``{sec, nsec}``) and ``topic_type_hash`` (the ``RIHS01_...``
  type hash of the installed interface, read from its ``.json`` type description);
- the message bytes are CDR as received from DDS (the recorder node subscribes raw, as rosbag2
  does); a message object given to :meth:`McapRecorder.write` is serialized with rclpy and
  trimmed to its exact CDR length (:func:`serialize_exact`);
- chunked and compressed (zstd by default), with message indexes, chunk indexes, statistics,
  summary offsets and CRCs; on :meth:`McapRecorder.close` a ``rosbag2`` metadata record with key
  ``serialized_metadata`` (the bag metadata YAML, version 9) is written, as rosbag2 does (and an
  empty one at the start, so that a crash-cut file still declares metadata version 9).

Crash safety: chunks are finished and written to the file when they reach ``chunk_size_bytes``
and at least every ``flush_period_s`` seconds of wall time (checked on each write; the recorder
node also flushes from a timer). A file cut short (process killed with SIGKILL, power loss) has no
summary and no footer, but every chunk written before the cut is intact and its messages are read
back by :func:`read_messages_tolerant` (mcap's non-seeking reader, stopping at the torn record).
At most the last ``flush_period_s`` of messages is lost.

This module does not import rclpy at import time; only :meth:`McapRecorder.write` with a message
object (rather than CDR bytes) imports ``rclpy.serialization``.
"""

from __future__ import annotations

import importlib
import importlib.metadata
import json
import os
import re
import struct
import time
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterator, Sequence

import yaml

ROS2_PROFILE = "ros2"
SCHEMA_ENCODING = "ros2msg"
MESSAGE_ENCODING = "cdr"
DEFINITION_SEPARATOR = "=" * 80
ROSBAG2_METADATA_VERSION = 9  # rosbag2 Jazzy writes bag metadata version 9

#: What rmw reports for an infinite duration (RMW_DURATION_INFINITE), as rosbag2 writes it.
INFINITE_DURATION = {"sec": 9223372036, "nsec": 854775807}

_PRIMITIVE_TYPES = frozenset(
    ["bool", "byte", "char", "float32", "float64", "int8", "uint8", "int16", "uint16", "int32",
     "uint32", "int64", "uint64", "string", "wstring"])
# A field line starts with its type: "pkg/Type name", "Type[] name", "string<=5 name", ...
_FIELD_TYPE_RE = re.compile(r"(?:^|\n)\s*([a-zA-Z0-9_/]+)(?:<=\d+)?(?:\[[^\]]*\])?\s+")
_TYPE_NAME_RE = re.compile(r"^([a-zA-Z][a-zA-Z0-9_]*)/(?:(msg|srv)/)?([a-zA-Z][a-zA-Z0-9_]*)$")


class RecordingError(ValueError):
    """A recording could not be written or read as asked; the message names the cause."""


def _version(dist: str) -> str:
    try:
        return importlib.metadata.version(dist)
    except importlib.metadata.PackageNotFoundError:
        return "unknown"


def library_string() -> str:
    """The MCAP header's library field: this writer and the mcap library under it."""
    return f"uam_sim/0.1.0 (mcap-python/{_version('mcap')})"


# --------------------------------------------------------------------------------------------
# Message types and definitions
# --------------------------------------------------------------------------------------------

def split_type_name(type_name: str) -> tuple[str, str, str]:
    """``"pkg/msg/Type"`` or ``"pkg/Type"`` -> ``(pkg, "msg", Type)``; raises on anything else."""
    m = _TYPE_NAME_RE.match(type_name)
    if not m:
        raise RecordingError(f"msg_type: {type_name!r} is not of the form 'pkg/msg/Type'")
    return m.group(1), m.group(2) or "msg", m.group(3)


def type_name_of(msg_type: Any) -> str:
    """``"pkg/msg/Type"`` of a generated message class, instance or type-name string."""
    if isinstance(msg_type, str):
        pkg, ns, name = split_type_name(msg_type)
        return f"{pkg}/{ns}/{name}"
    cls = msg_type if isinstance(msg_type, type) else type(msg_type)
    parts = cls.__module__.split(".")  # e.g. uam_msgs.msg._flight_plan
    if len(parts) < 2 or parts[1] not in ("msg", "srv"):
        raise RecordingError(f"msg_type: {cls!r} is not a generated ROS 2 interface class")
    return f"{parts[0]}/{parts[1]}/{cls.__name__}"


def message_class(type_name: str) -> type:
    """Import the generated Python class of ``pkg/msg/Type``."""
    pkg, ns, name = split_type_name(type_name)
    try:
        module = importlib.import_module(f"{pkg}.{ns}")
        return getattr(module, name)
    except (ImportError, AttributeError) as exc:
        raise RecordingError(f"msg_type: cannot import {type_name!r} ({exc}); is the workspace "
                             "sourced (scripts/env.sh)?") from None


def _share_dir(pkg: str) -> Path:
    from ament_index_python.packages import PackageNotFoundError, get_package_share_directory
    try:
        return Path(get_package_share_directory(pkg))
    except PackageNotFoundError:
        raise RecordingError(f"msg_type: package {pkg!r} is not in the ament index "
                             f"(AMENT_PREFIX_PATH={os.environ.get('AMENT_PREFIX_PATH', '')!r})") from None


def _msg_text(pkg: str, ns: str, name: str) -> str:
    path = _share_dir(pkg) / ns / f"{name}.msg"
    try:
        return path.read_text(encoding="utf-8")
    except OSError as exc:
        raise RecordingError(f"msg_type: no definition for {pkg}/{ns}/{name} at {path} ({exc})") from None


def _dependencies(text: str, package: str) -> list[str]:
    """Non-primitive field types of a .msg text as ``pkg/Type``, sorted (rosbag2 uses a std::set)."""
    deps = set()
    for m in _FIELD_TYPE_RE.finditer(text):
        t = m.group(1)
        if t in _PRIMITIVE_TYPES:
            continue
        deps.add(t if "/" in t else f"{package}/{t}")
    return sorted(deps)


def message_definition(type_name: str) -> str:
    """The full ``ros2msg`` definition of a type as rosbag2 writes it into the MCAP schema.

    The root type's .msg text, then each dependency once (depth first, sorted per file) as
    ``"\\n" + 80*"=" + "\\nMSG: pkg/Type\\n" + text``. Reads the installed .msg files through the
    ament index. Raises :class:`RecordingError` if a definition is missing.
    """
    pkg, ns, name = split_type_name(type_name)
    seen: set[str] = set()

    def append(pkg_: str, ns_: str, name_: str, depth: int) -> str:
        if depth <= 0:
            raise RecordingError(f"msg_type: definition of {type_name!r} nests too deep")
        text = _msg_text(pkg_, ns_, name_)
        out = text
        for dep in _dependencies(text, pkg_):
            if dep in seen:
                continue
            seen.add(dep)
            dpkg, dns, dname = split_type_name(dep)
            out += f"\n{DEFINITION_SEPARATOR}\nMSG: {dep}\n" + append(dpkg, dns, dname, depth - 1)
        return out

    return append(pkg, ns, name, 50)


def type_hash(type_name: str) -> str | None:
    """The ``RIHS01_...`` type hash of an installed interface, or None if it is not available."""
    pkg, ns, name = split_type_name(type_name)
    path = _share_dir(pkg) / ns / f"{name}.json"
    try:
        data = json.loads(path.read_text(encoding="utf-8"))
    except (OSError, ValueError):
        return None
    full = f"{pkg}/{ns}/{name}"
    for entry in data.get("type_hashes", []):
        if entry.get("type_name") == full:
            return entry.get("hash_string")
    return None


# --------------------------------------------------------------------------------------------
# QoS as rosbag2 writes it
# --------------------------------------------------------------------------------------------

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
    return yaml.safe_dump([QosSpec.from_profile(p).to_dict() for p in profiles],
                          sort_keys=False, default_flow_style=False)


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


# --------------------------------------------------------------------------------------------
# Simulation stamps
# --------------------------------------------------------------------------------------------

def _time_ns(stamp: Any) -> int:
    return int(stamp.sec) * 1_000_000_000 + int(stamp.nanosec)


def sim_stamp_ns(msg: Any) -> int | None:
    """The simulation time a message carries [ns], or None if its type carries none.

    ``header.stamp`` (FleetState, FlightPlan, PlanningReport, PoseArray), ``clock`` (/clock),
    ``epoch_time`` (EpochSync), ``request_time`` (FlightRequest). A zero stamp is simulation
    time 0 (the first step of a run), not a missing one.
    """
    for path in (("header", "stamp"), ("clock",), ("epoch_time",), ("request_time",)):
        obj = msg
        for attr in path:
            obj = getattr(obj, attr, None)
            if obj is None:
                break
        if obj is not None and hasattr(obj, "sec") and hasattr(obj, "nanosec"):
            return _time_ns(obj)
    return None


# --------------------------------------------------------------------------------------------
# Exact CDR size (rmw_serialize over-estimates it)
# --------------------------------------------------------------------------------------------

_PRIMITIVE_SIZE = {"boolean": 1, "octet": 1, "char": 1, "uint8": 1, "int8": 1, "int16": 2,
                   "uint16": 2, "int32": 4, "uint32": 4, "float": 4, "int64": 8, "uint64": 8,
                   "double": 8}
_SEQ_RE = re.compile(r"^sequence<([^,>]+)(?:,\s*\d+)?>$")
_ARRAY_RE = re.compile(r"^(.+)\[(\d+)\]$")


def _align(pos: int, n: int) -> int:
    return pos + (-pos) % n


def _cdr_advance(pos: int, type_str: str, value: Any) -> int:
    """Offset after serializing ``value`` of rosidl type ``type_str`` at payload offset ``pos``."""
    if type_str in _PRIMITIVE_SIZE:
        size = _PRIMITIVE_SIZE[type_str]
        return _align(pos, size) + size
    if type_str.startswith("string"):
        return _align(pos, 4) + 4 + len(value.encode("utf-8")) + 1
    if type_str.startswith("wstring"):
        raise RecordingError("wstring fields are not supported by the exact CDR size")
    m = _SEQ_RE.match(type_str)
    if m:
        pos = _align(pos, 4) + 4  # element count
        return _cdr_elements(pos, m.group(1).strip(), value)
    m = _ARRAY_RE.match(type_str)
    if m:
        return _cdr_elements(pos, m.group(1), value)
    return _cdr_message(pos, value)  # a nested message: no alignment of its own in XCDR1


def _cdr_elements(pos: int, elem: str, values: Any) -> int:
    n = len(values)
    if n == 0:
        return pos  # an empty sequence is not aligned for its (absent) elements
    if elem in _PRIMITIVE_SIZE:
        size = _PRIMITIVE_SIZE[elem]
        return _align(pos, size) + n * size
    for v in values:
        pos = _cdr_advance(pos, elem, v)
    return pos


def _cdr_message(pos: int, msg: Any) -> int:
    for name, type_str in msg.get_fields_and_field_types().items():
        pos = _cdr_advance(pos, type_str, getattr(msg, name))
    return pos


def cdr_size(msg: Any) -> int:
    """Exact length [bytes] of a message's CDR (XCDR1) serialization, encapsulation included.

    ``rclpy.serialization.serialize_message`` returns a buffer of rmw's *estimated* size, which
    for some messages (e.g. an empty ``float64[]`` before other fields) is a few bytes longer
    than the CDR written, with uninitialised bytes at the end; the bytes received from DDS are
    exact. A message with no fields still serializes one byte.
    """
    if not msg.get_fields_and_field_types():
        return 4 + 1
    return 4 + _cdr_message(0, msg)


def serialize_exact(msg: Any) -> bytes:
    """``serialize_message`` trimmed to the exact CDR length (what a DDS subscriber receives)."""
    from rclpy.serialization import serialize_message

    data = serialize_message(msg)
    try:
        n = cdr_size(msg)
    except RecordingError:
        return data
    if n > len(data):  # never cut bytes the serializer wrote; keep its buffer as it is
        return data
    return data[:n]


# --------------------------------------------------------------------------------------------
# The writer
# --------------------------------------------------------------------------------------------

def bag_metadata_yaml(file_name: str, topics: dict, counts: dict, start_ns: int | None,
                      end_ns: int | None) -> str:
    """The rosbag2 bag metadata (version 9) that goes into the ``rosbag2`` metadata record.

    ``topics``: topic -> {"type", "qos" (offered_qos_profiles YAML), "hash"}; ``counts``: topic ->
    messages. Key order and names as rosbag2 writes ``metadata.yaml``.
    """
    start = start_ns or 0
    duration = (end_ns - start_ns) if start_ns is not None and end_ns is not None else 0
    count = sum(counts.values())
    entries = []
    for topic, info in topics.items():
        entries.append({
            "topic_metadata": {
                "name": topic,
                "type": info["type"],
                "serialization_format": MESSAGE_ENCODING,
                "offered_qos_profiles": yaml.safe_load(info["qos"]) or [],
                "type_description_hash": info.get("hash", ""),
            },
            "message_count": int(counts.get(topic, 0)),
        })
    meta = {
        "version": ROSBAG2_METADATA_VERSION,
        "storage_identifier": "mcap",
        "duration": {"nanoseconds": duration},
        "starting_time": {"nanoseconds_since_epoch": start},
        "message_count": count,
        "topics_with_message_count": entries,
        "compression_format": "",
        "compression_mode": "",
        "relative_file_paths": [file_name],
        "files": [{"path": file_name, "starting_time": {"nanoseconds_since_epoch": start},
                   "duration": {"nanoseconds": duration}, "message_count": count}],
        "custom_data": {},
        "ros_distro": os.environ.get("ROS_DISTRO", "jazzy"),
    }
    return yaml.safe_dump(meta, sort_keys=False, default_flow_style=False)


_COMPRESSION = {"zstd": "ZSTD", "lz4": "LZ4", "none": "NONE", "": "NONE"}


class McapRecorder:
    """Write ROS 2 messages into one ``.mcap`` file as rosbag2 does.

    Usage::

        with McapRecorder("run.mcap") as rec:
            rec.add_topic("/uam/fleet_state", "uam_msgs/msg/FleetState", qos_profile)
            rec.write("/uam/fleet_state", msg_or_cdr_bytes, log_time_ns)

    Args:
        path: output file (parent directories are created); an existing file is replaced.
        chunk_size_bytes: a chunk is finished once its uncompressed size exceeds this.
        compression: "zstd" (default), "lz4" or "none".
        flush_period_s: wall time after which :meth:`write` finishes the open chunk, so a crash
            loses at most this much; None disables the periodic flush.
    Topics must be added before messages are written to them. Not thread safe.
    """

    def __init__(self, path: str | os.PathLike, chunk_size_bytes: int = 256 * 1024,
                 compression: str = "zstd", flush_period_s: float | None = 1.0) -> None:
        from mcap.writer import CompressionType, Writer

        if compression.lower() not in _COMPRESSION:
            raise RecordingError(f"compression: {compression!r} is not one of zstd, lz4, none")
        if int(chunk_size_bytes) <= 0:
            raise RecordingError(f"chunk_size_bytes: must be > 0, got {chunk_size_bytes!r}")
        if flush_period_s is not None and not flush_period_s > 0:
            raise RecordingError(f"flush_period_s: must be > 0 or None, got {flush_period_s!r}")
        self.path = Path(path)
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._stream = open(self.path, "wb")
        self._writer = Writer(self._stream, chunk_size=int(chunk_size_bytes),
                              compression=getattr(CompressionType, _COMPRESSION[compression.lower()]))
        self._writer.start(profile=ROS2_PROFILE, library=library_string())
        self._compression = compression.lower()
        self._flush_period_s = flush_period_s
        self._last_flush = time.monotonic()
        self._schemas: dict[str, int] = {}
        self._channels: dict[str, int] = {}
        self._topics: dict[str, dict] = {}
        self._counts: dict[str, int] = {}
        self._sequence: dict[str, int] = {}
        self._start_ns: int | None = None
        self._end_ns: int | None = None
        self._closed = False
        # rosbag2 reads the metadata version from this record; without one it parses the QoS
        # as version 8 (integers) and fails on ours. The final record is written on close; this
        # early one makes a crash-cut file (which rosbag2 reads by scanning) parse too.
        self._writer.add_metadata("rosbag2", {"serialized_metadata": self._bag_metadata_yaml()})

    # -- topics ---------------------------------------------------------------------------

    @property
    def topics(self) -> dict[str, str]:
        """Registered topics -> type names."""
        return {t: info["type"] for t, info in self._topics.items()}

    def add_topic(self, topic: str, msg_type: Any, qos_profile: Any = None,
                  offered_qos_profiles: Sequence[Any] | None = None) -> int:
        """Register a topic (its schema once per type, its channel once); returns the channel id.

        ``msg_type``: a generated message class or ``"pkg/msg/Type"``. ``qos_profile``: the
        profile the publisher offers (rclpy QoSProfile, :class:`QosSpec`, dict, or None for the
        defaults); ``offered_qos_profiles`` instead lists one per publisher, as rosbag2 records.
        Adding a topic again with the same type returns its channel; another type raises.
        """
        self._check_open()
        if not isinstance(topic, str) or not topic.startswith("/"):
            raise RecordingError(f"topic: {topic!r} must be an absolute topic name like '/uam/x'")
        type_name = type_name_of(msg_type)
        if topic in self._topics:
            if self._topics[topic]["type"] != type_name:
                raise RecordingError(f"topic: {topic!r} already recorded as "
                                     f"{self._topics[topic]['type']}, not {type_name}")
            return self._channels[topic]
        if type_name not in self._schemas:
            self._schemas[type_name] = self._writer.register_schema(
                name=type_name, encoding=SCHEMA_ENCODING,
                data=message_definition(type_name).encode("utf-8"))
        profiles = list(offered_qos_profiles) if offered_qos_profiles else [qos_profile]
        qos_yaml = offered_qos_yaml(profiles)
        metadata = {"offered_qos_profiles": qos_yaml}
        digest = type_hash(type_name)
        if digest:
            metadata["topic_type_hash"] = digest
        channel_id = self._writer.register_channel(
            topic=topic, message_encoding=MESSAGE_ENCODING, schema_id=self._schemas[type_name],
            metadata=metadata)
        self._channels[topic] = channel_id
        self._topics[topic] = {"type": type_name, "qos": qos_yaml, "hash": digest or ""}
        self._counts[topic] = 0
        self._sequence[topic] = 0
        return channel_id

    # -- messages ---------------------------------------------------------------------------

    def write(self, topic: str, msg_or_bytes: Any, log_time_ns: int,
              publish_time_ns: int | None = None) -> None:
        """Append one message. ``msg_or_bytes``: CDR bytes, or a message (serialized here).

        ``log_time_ns``: receive time [ns] (simulation time in this project); ``publish_time_ns``
        defaults to it. Raises :class:`RecordingError` for an unknown topic or a negative time.
        """
        self._check_open()
        if topic not in self._channels:
            raise RecordingError(f"topic: {topic!r} was not added with add_topic "
                                 f"(known: {sorted(self._channels)})")
        log_time_ns = int(log_time_ns)
        if log_time_ns < 0:
            raise RecordingError(f"log_time_ns: must be >= 0, got {log_time_ns}")
        publish_time_ns = log_time_ns if publish_time_ns is None else int(publish_time_ns)
        if isinstance(msg_or_bytes, (bytes, bytearray, memoryview)):
            data = bytes(msg_or_bytes)
        else:
            data = serialize_exact(msg_or_bytes)
        self._writer.add_message(channel_id=self._channels[topic], log_time=log_time_ns,
                                 data=data, publish_time=publish_time_ns,
                                 sequence=self._sequence[topic])
        self._sequence[topic] += 1
        self._counts[topic] += 1
        self._start_ns = log_time_ns if self._start_ns is None else min(self._start_ns, log_time_ns)
        self._end_ns = log_time_ns if self._end_ns is None else max(self._end_ns, log_time_ns)
        if self._flush_period_s is not None and time.monotonic() - self._last_flush >= self._flush_period_s:
            self.flush()

    def flush(self) -> None:
        """Finish the open chunk and push it to the OS, so it survives a crash of this process."""
        self._check_open()
        self._writer.flush()
        self._last_flush = time.monotonic()

    @property
    def message_counts(self) -> dict[str, int]:
        """Messages written so far per topic."""
        return dict(self._counts)

    # -- closing ----------------------------------------------------------------------------

    def _bag_metadata_yaml(self) -> str:
        return bag_metadata_yaml(self.path.name, self._topics, self._counts, self._start_ns, self._end_ns)

    def close(self) -> None:
        """Write the rosbag2 metadata record, summary and footer, and close the file. Idempotent."""
        if self._closed:
            return
        self._closed = True
        try:
            self._writer.add_metadata("rosbag2", {"serialized_metadata": self._bag_metadata_yaml()})
            self._writer.finish()
        finally:
            self._stream.close()

    @property
    def closed(self) -> bool:
        return self._closed

    def _check_open(self) -> None:
        if self._closed:
            raise RecordingError(f"recording {self.path} is already closed")

    def __enter__(self) -> "McapRecorder":
        return self

    def __exit__(self, *exc: Any) -> None:
        self.close()


# --------------------------------------------------------------------------------------------
# Reading
# --------------------------------------------------------------------------------------------

@dataclass
class RecordedMessage:
    """One message as stored: topic, type name, CDR bytes, log and publish time [ns]."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int
    qos_yaml: str = ""


def read_messages(path: str | os.PathLike, topics: Sequence[str] | None = None) -> Iterator[RecordedMessage]:
    """Messages of a complete recording in log-time order (mcap's indexed reader)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(topics=list(topics) if topics else None,
                                                             log_time_order=True):
            yield RecordedMessage(channel.topic, schema.name if schema else "", message.data,
                                  message.log_time, message.publish_time,
                                  channel.metadata.get("offered_qos_profiles", ""))


def read_messages_tolerant(path: str | os.PathLike) -> Iterator[RecordedMessage]:
    """Messages of a recording that may be cut short (no summary, no footer), in file order.

    Uses mcap's non-seeking reader and stops quietly at the first torn or missing record; every
    message in a chunk written completely before the cut is returned.
    """
    from mcap.exceptions import McapError
    from mcap.reader import NonSeekingReader

    with open(path, "rb") as f:
        reader = NonSeekingReader(f, validate_crcs=True)
        it = reader.iter_messages(log_time_order=False)  # the ordered mode buffers to the end
        while True:
            try:
                schema, channel, message = next(it)
            except StopIteration:
                return
            except (McapError, EOFError, ValueError, OSError, KeyError, struct.error):
                return  # the torn tail of a crashed recording
            yield RecordedMessage(channel.topic, schema.name if schema else "", message.data,
                                  message.log_time, message.publish_time,
                                  channel.metadata.get("offered_qos_profiles", ""))


def is_complete(path: str | os.PathLike) -> bool:
    """True if the file ends with a valid footer and summary (it was closed properly)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return summary is not None
    except Exception:  # noqa: BLE001 - any failure to read the summary means "not complete"
        return False


def deserialize(record: RecordedMessage) -> Any:
    """The rclpy message object of a recorded message (imports rclpy)."""
    from rclpy.serialization import deserialize_message
    return deserialize_message(record.data, message_class(record.type_name))


def recover(src: str | os.PathLike, dst: str | os.PathLike, compression: str = "zstd") -> int:
    """Rewrite a recording cut short by a crash into a complete file; returns the messages kept.

    Schemas, channels (with their metadata) and messages written before the cut are copied as
    they are, in file order; the new file gets indexes, statistics, summary and footer, so every
    reader (rerun, rosbags, ros2 bag) opens it. Works on complete files too (a plain copy).
    """
    from mcap.writer import CompressionType, Writer

    if Path(src).resolve() == Path(dst).resolve():
        raise RecordingError(f"dst: must differ from src ({src})")
    schema_ids: dict[int, int] = {}
    channel_ids: dict[int, int] = {}
    topics: dict[str, dict] = {}
    counts: dict[str, int] = {}
    start = end = None
    count = 0
    with open(dst, "wb") as out:
        writer = Writer(out, chunk_size=256 * 1024,
                        compression=getattr(CompressionType, _COMPRESSION[compression.lower()]))
        writer.start(profile=ROS2_PROFILE, library=library_string())
        # read the messages first: the tolerant reader stops at the tear
        from mcap.exceptions import McapError
        from mcap.reader import NonSeekingReader
        with open(src, "rb") as f:
            it = NonSeekingReader(f, validate_crcs=True).iter_messages(log_time_order=False)
            while True:
                try:
                    schema, channel, message = next(it)
                except StopIteration:
                    break
                except (McapError, EOFError, ValueError, OSError, KeyError, struct.error):
                    break
                if schema is not None and schema.id not in schema_ids:
                    schema_ids[schema.id] = writer.register_schema(schema.name, schema.encoding, schema.data)
                if channel.id not in channel_ids:
                    channel_ids[channel.id] = writer.register_channel(
                        channel.topic, channel.message_encoding,
                        schema_ids.get(channel.schema_id, 0), dict(channel.metadata))
                writer.add_message(channel_ids[channel.id], message.log_time, message.data,
                                   message.publish_time, message.sequence)
                count += 1
                topics.setdefault(channel.topic, {
                    "type": schema.name if schema else "",
                    "qos": channel.metadata.get("offered_qos_profiles", ""),
                    "hash": channel.metadata.get("topic_type_hash", "")})
                counts[channel.topic] = counts.get(channel.topic, 0) + 1
                start = message.log_time if start is None else min(start, message.log_time)
                end = message.log_time if end is None else max(end, message.log_time)
        writer.add_metadata("rosbag2", {"serialized_metadata": bag_metadata_yaml(
            Path(dst).name, topics, counts, start, end)})
        writer.finish()
    return count


def benchmark(path: str | os.PathLike, steps: int = 3500, vehicles: int = 70, seed: int = 0) -> dict:
    """Write and read back a paper-scale synthetic recording; wall times [s] of each part.

    ``steps`` fleet states (plus the same number of poses and clock ticks) with ``vehicles``
    airborne vehicles each, one planning report per 30 steps. Imports rclpy and uam_msgs.
    """
    import numpy as np
    from builtin_interfaces.msg import Time
    from geometry_msgs.msg import Point, Pose, PoseArray, Vector3
    from rosgraph_msgs.msg import Clock
    from uam_msgs.msg import FleetState, PlanningReport, VehicleState

    rng = np.random.default_rng(seed)
    pos = rng.uniform(0, 20000, size=(steps, vehicles, 3))
    msgs = []
    t0 = time.perf_counter()
    for k in range(steps):
        stamp = Time(sec=k)
        fs = FleetState(step_index=k, vehicles=[
            VehicleState(vehicle_id=f"r{j:05d}", position=Point(x=p[0], y=p[1], z=p[2]),
                         velocity=Vector3(x=20.0)) for j, p in enumerate(pos[k].tolist())])
        fs.header.stamp = stamp
        pa = PoseArray(poses=[Pose(position=Point(x=p[0], y=p[1], z=p[2])) for p in pos[k].tolist()])
        pa.header.stamp = stamp
        msgs.append((k, Clock(clock=stamp), fs, pa))
    build_s = time.perf_counter() - t0
    from rclpy.serialization import serialize_message
    t0 = time.perf_counter()
    cdr = [(k, serialize_message(c), serialize_message(f), serialize_message(p)) for k, c, f, p in msgs]
    serialize_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    with McapRecorder(path) as rec:
        rec.add_topic("/clock", Clock)
        rec.add_topic("/uam/fleet_state", FleetState)
        rec.add_topic("/uam/fleet_poses", PoseArray)
        rec.add_topic("/uam/planning_reports", PlanningReport)
        for k, c, f, p in cdr:
            ns = k * 1_000_000_000
            rec.write("/clock", c, ns)
            rec.write("/uam/fleet_state", f, ns)
            rec.write("/uam/fleet_poses", p, ns)
            if k % 30 == 0:
                rep = PlanningReport(epoch_index=k // 30)
                rep.header.stamp = Time(sec=k)
                rec.write("/uam/planning_reports", rep, ns)
    write_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_read = sum(1 for _ in read_messages(path))
    read_s = time.perf_counter() - t0
    from .analysis import summarize
    t0 = time.perf_counter()
    summary = summarize(path)
    analyze_s = time.perf_counter() - t0
    return {"messages": n_read, "file_MB": Path(path).stat().st_size / 1e6,
            "build_msgs_s": build_s, "serialize_s": serialize_s, "write_s": write_s,
            "read_s": read_s, "analyze_s": analyze_s,
            "write_msgs_per_s": n_read / write_s if write_s > 0 else float("inf"),
            "fleet_steps": summary.fleet_steps}


def main(argv: list[str] | None = None) -> int:
    """``python -m uam_sim.recording recover TORN.mcap FIXED.mcap`` | ``info FILE.mcap`` | ``bench``."""
    import argparse
    import sys

    ap = argparse.ArgumentParser(prog="python -m uam_sim.recording")
    sub = ap.add_subparsers(dest="command", required=True)
    rec = sub.add_parser("recover", help="rewrite a crash-cut recording into a complete file")
    rec.add_argument("src")
    rec.add_argument("dst")
    info = sub.add_parser("info", help="topics, types and message counts")
    info.add_argument("path")
    bench = sub.add_parser("bench", help="write and read a paper-scale synthetic recording; print times")
    bench.add_argument("--steps", type=int, default=3500)
    bench.add_argument("--vehicles", type=int, default=70)
    bench.add_argument("--out", default="", help="file to write (default: a temporary file)")
    args = ap.parse_args(argv)
    try:
        if args.command == "bench":
            import tempfile
            with tempfile.TemporaryDirectory() as tmp:
                r = benchmark(args.out or Path(tmp) / "bench.mcap", args.steps, args.vehicles)
            print(f"{'messages':24s} {r['messages']:10d}")
            print(f"{'file size [MB]':24s} {r['file_MB']:10.2f}")
            for key, label in (("build_msgs_s", "build messages [s]"), ("serialize_s", "serialize (rclpy) [s]"),
                               ("write_s", "write MCAP [s]"), ("read_s", "read back [s]"),
                               ("analyze_s", "analysis [s]")):
                print(f"{label:24s} {r[key]:10.3f}")
            print(f"{'write rate [msg/s]':24s} {r['write_msgs_per_s']:10.0f}")
            return 0
        if args.command == "recover":
            n = recover(args.src, args.dst)
            print(f"recovered {n} messages into {args.dst}")
            return 0
        counts: dict[tuple[str, str], int] = {}
        complete = is_complete(args.path)
        for m in (read_messages(args.path) if complete else read_messages_tolerant(args.path)):
            counts[(m.topic, m.type_name)] = counts.get((m.topic, m.type_name), 0) + 1
        print(f"{args.path}: {'complete' if complete else 'INCOMPLETE (no summary: crash-cut)'}")
        for (topic, type_name), n in sorted(counts.items()):
            print(f"  {topic:28s} {type_name:36s} {n:8d}")
        return 0
    except (OSError, RecordingError) as exc:
        print(f"recording: {exc}", file=sys.stderr)
        return 1


if __name__ == "__main__":
    import sys
    sys.exit(main())
