"""Reading recordings: complete files (indexed, log-time order) and files cut short by a crash.

Imports no rclpy unless messages are deserialized (:func:`deserialize`, :func:`iter_decoded`).
"""

from __future__ import annotations

import os
import struct
from dataclasses import dataclass
from pathlib import Path
from typing import Any, Iterable, Iterator, Sequence

from uam_contract import names
from uam_contract.names import resolved
from .cdr import fleet_state_digest
from .mcap_schema import message_class

#: The topic whose messages ``iter_decoded(fleet_digest_only=True)`` reads as digests.
FLEET_STATE_TOPIC = resolved(names.TOPIC_FLEET)

#: MCAP metadata record of the recording's clock: ``log_time_zero_ns``, the log time
#: [ns since the Unix epoch] of simulation time 0 (the scenario's UTC start), and
#: ``log_time_start_utc``, that instant as ISO 8601 (or "sim": log times are simulation time).
CLOCK_METADATA = "uam_clock"


@dataclass
class RecordedMessage:
    """One message as stored: topic, type name, CDR bytes, log and publish time [ns]."""

    topic: str
    type_name: str
    data: bytes
    log_time_ns: int
    publish_time_ns: int
    qos_yaml: str = ""
    schema: Any = None   # the file's mcap Schema record (its ros2msg definition), if any


def read_messages(path: str | os.PathLike, topics: Sequence[str] | None = None) -> Iterator[RecordedMessage]:
    """Messages of a complete recording in log-time order (mcap's indexed reader)."""
    from mcap.reader import make_reader

    with open(path, "rb") as f:
        reader = make_reader(f)
        for schema, channel, message in reader.iter_messages(topics=list(topics) if topics else None,
                                                             log_time_order=True):
            yield RecordedMessage(channel.topic, schema.name if schema else "", message.data,
                                  message.log_time, message.publish_time,
                                  channel.metadata.get("offered_qos_profiles", ""), schema)


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
                                  channel.metadata.get("offered_qos_profiles", ""), schema)


#: The first bytes of every MCAP file (the specification's magic: 0x89 "MCAP0" CR LF).
MCAP_MAGIC = b"\x89MCAP0\r\n"


def require_mcap(path: str | os.PathLike) -> None:
    """Raise ValueError naming the file unless it starts with the MCAP magic (a README, a .rrd
    or an empty file is not a recording); FileNotFoundError if there is no such file."""
    with open(path, "rb") as f:
        head = f.read(len(MCAP_MAGIC))
    if head != MCAP_MAGIC:
        raise ValueError(f"recording: {str(path)!r} is not an MCAP file (it starts with {head[:8]!r}, "
                         f"not the MCAP magic {MCAP_MAGIC!r})")


def recorded_topics(path: str | os.PathLike) -> set[str] | None:
    """The topics (channels) of a complete recording, whether or not they carried a message;
    None when the file has no summary to list them (cut short)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
    except Exception:  # noqa: BLE001 - a torn file has no summary
        return None
    return None if summary is None else {c.topic for c in summary.channels.values()}


def is_complete(path: str | os.PathLike) -> bool:
    """True if the file ends with a valid footer and summary (it was closed properly)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            summary = make_reader(f).get_summary()
        return summary is not None
    except Exception:  # noqa: BLE001 - any failure to read the summary means "not complete"
        return False


def read_metadata(path: str | os.PathLike, name: str) -> dict[str, str]:
    """The MCAP metadata record ``name`` of a complete recording ({} if absent or torn)."""
    from mcap.reader import make_reader

    try:
        with open(path, "rb") as f:
            for record in make_reader(f).iter_metadata():
                if record.name == name:
                    return dict(record.metadata)
    except Exception:  # noqa: BLE001 - a torn file has no summary: read its records up to the tear
        from .mcap_recover import _metadata_before_cut
        try:
            return next((data for n, data in _metadata_before_cut(path) if n == name), {})
        except Exception:  # noqa: BLE001 - not an MCAP file at all
            return {}
    return {}


def log_time_zero_ns(path: str | os.PathLike) -> int:
    """The log time of simulation time 0 in a recording [ns since the Unix epoch]: the
    ``uam_clock`` record's ``log_time_zero_ns`` (the scenario's UTC start), 0 for a recording
    without one (made before log times were put on the scenario's clock: log time = sim time).
    Raises ValueError naming the record if its value is not a non-negative integer."""
    value = read_metadata(path, CLOCK_METADATA).get("log_time_zero_ns", "0")
    try:
        zero = int(value)
    except ValueError:
        raise ValueError(f"{CLOCK_METADATA}.log_time_zero_ns: {value!r} is not an integer") from None
    if zero < 0:
        raise ValueError(f"{CLOCK_METADATA}.log_time_zero_ns: {value!r} must be >= 0")
    return zero


def deserialize(record: RecordedMessage) -> Any:
    """The rclpy message object of a recorded message (imports rclpy).

    A recording made with an older definition of the type (its schema differs from the
    installed one, e.g. a ``FlightPlan`` before ``observed_progress_rate``) is decoded
    with its own schema (mcap_ros2's dynamic decoder) and copied into the installed class: the
    fields it has keep their values, the newer ones keep their defaults (0, "", [])."""
    from rclpy.serialization import deserialize_message
    cls = message_class(record.type_name)
    schema = record.schema
    if schema is not None and schema.data and _differs(record.type_name, schema.data):
        return _copy_into(cls, _old_decoder(schema)(record.data))
    return deserialize_message(record.data, cls)


_DIFFERS: dict = {}
_DECODERS: dict = {}


def _differs(type_name: str, schema_data: bytes) -> bool:
    key = (type_name, bytes(schema_data))
    if key not in _DIFFERS:
        from .mcap_schema import message_definition
        try:
            _DIFFERS[key] = message_definition(type_name).strip() != bytes(schema_data).decode().strip()
        except Exception:  # noqa: BLE001 - no installed definition to compare: rclpy decides
            _DIFFERS[key] = False
    return _DIFFERS[key]


def _old_decoder(schema):
    key = (schema.name, bytes(schema.data))
    if key not in _DECODERS:
        from mcap_ros2.decoder import DecoderFactory
        _DECODERS[key] = DecoderFactory().decoder_for("cdr", schema)
    return _DECODERS[key]


def _copy_into(cls, old) -> Any:
    """An instance of the installed message class ``cls`` with the fields ``old`` (a decoded
    namespace) has, recursively; missing fields keep their defaults."""
    msg = cls()
    for name, typ in cls.get_fields_and_field_types().items():
        if not hasattr(old, name):
            continue
        value = getattr(old, name)
        base = typ.split("<")[0]
        seq = base.startswith("sequence") or "[" in base
        inner = typ[typ.index("<") + 1:typ.rindex(">")] if base.startswith("sequence") else typ.split("[")[0]
        if "/" in inner:   # a message type (pkg/Type)
            pkg, name_ = inner.split("/")[0], inner.split("/")[-1]
            sub = message_class(f"{pkg}/msg/{name_}")
            value = [_copy_into(sub, v) for v in value] if seq else _copy_into(sub, value)
        elif seq and not isinstance(value, (bytes, str)):
            value = list(value)
        setattr(msg, name, value)
    return msg


def iter_decoded(path: str | Path, reader: str = "rclpy",
                 topics: Iterable[str] | None = None,
                 fleet_digest_only: bool = False) -> Iterator[tuple[str, int, Any]]:
    """(topic, sim_time_ns, message) of the given topics (None: every topic), in log-time order.

    The time is the message's log time in simulation time: the file's log times are on the
    scenario's UTC clock (:data:`CLOCK_METADATA`), and the ``log_time_zero_ns`` recorded there is
    subtracted, so the analysis works in seconds from the start as before.

    ``reader``: "rclpy" (mcap + rclpy deserialization; a torn file yields what was written) or
    "rosbags" (the independent rosbags library, every message decoded in full; needs a complete
    file). ``fleet_digest_only`` (rclpy reader): FleetStates come back as their stamp,
    step_index and a ``vehicles`` range of the right length only, read from the CDR directly.
    """
    wanted = None if topics is None else set(topics)
    zero = log_time_zero_ns(path) if reader in ("rclpy", "rosbags") else 0
    if reader == "rclpy":
        if is_complete(path):
            records = read_messages(path, topics=sorted(wanted) if wanted is not None else None)
        else:  # crash-cut file: file order is log order here, but sort to be sure
            records = sorted((r for r in read_messages_tolerant(path) if wanted is None or r.topic in wanted),
                             key=lambda r: r.log_time_ns)
        for rec in records:
            if rec.topic == FLEET_STATE_TOPIC and fleet_digest_only:
                digest = fleet_state_digest(rec.data)
                if digest is not None:
                    yield rec.topic, rec.log_time_ns - zero, digest
                    continue
            yield rec.topic, rec.log_time_ns - zero, deserialize(rec)
    elif reader == "rosbags":
        from rosbags.highlevel import AnyReader
        from rosbags.typesys import Stores, get_typestore

        with AnyReader([Path(path)], default_typestore=get_typestore(Stores.ROS2_JAZZY)) as r:
            conns = [c for c in r.connections if wanted is None or c.topic in wanted]
            for conn, timestamp, raw in r.messages(connections=conns):
                yield conn.topic, timestamp - zero, r.deserialize(raw, conn.msgtype)
    else:
        raise ValueError(f"reader: {reader!r} is not 'rclpy' or 'rosbags'")
