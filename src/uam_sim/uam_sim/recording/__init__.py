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

Where the parts live (this package re-exports them for callers; ``__main__`` is the command line):
:mod:`uam_sim.recording.mcap_schema` (type names, definitions, hashes), :mod:`uam_contract.qos_spec` (offered
QoS YAML), :mod:`uam_contract.stamps` (a message's simulation time), :mod:`uam_sim.recording.cdr` (CDR bytes:
exact size, fields read without deserializing), :mod:`uam_sim.recording.mcap_writer` (the writer),
:mod:`uam_sim.recording.mcap_reader` (reading, decoding), :mod:`uam_sim.recording.mcap_recover` (repairing a torn
file), :mod:`uam_sim.studies.recording_bench` (the write/read benchmark).

None of them imports rclpy at import time; only :meth:`McapRecorder.write` with a message
object (rather than CDR bytes) and deserializing import ``rclpy.serialization``.
"""

from __future__ import annotations

from .cdr import cdr_size, serialize_exact
from .mcap_reader import (RecordedMessage, deserialize, is_complete, iter_decoded, read_messages,
                          read_messages_tolerant)
from .mcap_recover import recover
from .mcap_schema import (DEFINITION_SEPARATOR, MESSAGE_ENCODING, ROS2_PROFILE, ROSBAG2_METADATA_VERSION,
                          SCHEMA_ENCODING, RecordingError, library_string, message_class,
                          message_definition, split_type_name, type_hash, type_name_of)
from .mcap_writer import McapRecorder, bag_metadata_yaml
from uam_contract.qos_spec import INFINITE_DURATION, QosSpec, offered_qos_yaml, parse_offered_qos
from uam_contract.stamps import sim_stamp_ns

__all__ = ["DEFINITION_SEPARATOR", "INFINITE_DURATION", "MESSAGE_ENCODING", "ROS2_PROFILE",
           "ROSBAG2_METADATA_VERSION", "SCHEMA_ENCODING", "McapRecorder", "QosSpec",
           "RecordedMessage", "RecordingError", "bag_metadata_yaml", "cdr_size",
           "deserialize", "is_complete", "iter_decoded", "library_string", "message_class",
           "message_definition", "offered_qos_yaml", "parse_offered_qos", "read_messages",
           "read_messages_tolerant", "recover", "serialize_exact", "sim_stamp_ns", "split_type_name",
           "type_hash", "type_name_of"]
