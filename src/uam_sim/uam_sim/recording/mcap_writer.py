"""Writing MCAP exactly as rosbag2 (Jazzy, ``rosbag2_storage_mcap``) writes it.

See :mod:`uam_sim.recording` for what a reader of the file can rely on (schemas, channels with
offered QoS and type hashes, CDR bytes, chunking, the ``rosbag2`` metadata record) and for crash
safety. Imports no rclpy unless a message object (rather than CDR bytes) is written.
"""

from __future__ import annotations

import copy
import os
import time
from pathlib import Path
from typing import Any, Sequence

import yaml

from .cdr import serialize_exact
from .mcap_schema import (MESSAGE_ENCODING, ROS2_PROFILE, ROSBAG2_METADATA_VERSION, SCHEMA_ENCODING,
                          RecordingError, library_string, message_definition, type_hash, type_name_of)
from uam_contract.qos_spec import offered_qos_yaml


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
    parsed: dict[str, Any] = {}   # QoS YAML -> parsed: the view topics (hundreds) share one
    for topic, info in topics.items():
        qos = parsed.get(info["qos"])
        if qos is None:
            qos = parsed[info["qos"]] = yaml.load(info["qos"], Loader=_SafeLoader) or []
        entries.append({
            "topic_metadata": {
                "name": topic,
                "type": info["type"],
                "serialization_format": MESSAGE_ENCODING,
                "offered_qos_profiles": copy.deepcopy(qos),
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
    # libyaml's dumper writes the same text as the pure-Python one, ~10x faster: with the
    # per-vehicle view topics (~370 channels) the pure-Python dump took ~3 s at close (BENCHMARKS.md)
    return yaml.dump(meta, Dumper=_SafeDumper, sort_keys=False, default_flow_style=False)


_SafeLoader = getattr(yaml, "CSafeLoader", yaml.SafeLoader)
_SafeDumper = getattr(yaml, "CSafeDumper", yaml.SafeDumper)

_COMPRESSION = {"zstd": "ZSTD", "lz4": "LZ4", "none": "NONE", "": "NONE"}


class McapRecorder:
    """Write ROS 2 messages into one ``.mcap`` file as rosbag2 does.

    Usage::

        with McapRecorder("run.mcap") as rec:
            rec.add_topic(topic, "uam_msgs/msg/FleetState", qos_profile)
            rec.write(topic, msg_or_cdr_bytes, log_time_ns)

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
        """Registered topics -> type names (a new dict; use :meth:`has_topic` per message)."""
        return {t: info["type"] for t, info in self._topics.items()}

    def has_topic(self, topic: str) -> bool:
        """True if ``topic`` was added (O(1): the recorder asks for every message it writes)."""
        return topic in self._channels

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
            raise RecordingError(f"topic: {topic!r} must be an absolute topic name (starting with '/')")
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

    def add_metadata(self, name: str, data: dict) -> None:
        """An MCAP metadata record ``name`` (values written as strings), e.g. the recorder's check
        of what it received (read back by :func:`uam_sim.recording.mcap_reader.read_metadata`)."""
        self._check_open()
        self._writer.add_metadata(name, {str(k): str(v) for k, v in data.items()})

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
