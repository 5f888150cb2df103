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

Where the parts live (this module is the command line and re-exports them for callers):
:mod:`uam_sim.mcap_schema` (type names, definitions, hashes), :mod:`uam_contract.qos_spec` (offered
QoS YAML), :mod:`uam_contract.stamps` (a message's simulation time), :mod:`uam_sim.cdr` (CDR bytes:
exact size, fields read without deserializing), :mod:`uam_sim.mcap_writer` (the writer),
:mod:`uam_sim.mcap_reader` (reading, decoding), :mod:`uam_sim.mcap_recover` (repairing a torn
file), :mod:`uam_sim.recording_bench` (the write/read benchmark).

None of them imports rclpy at import time; only :meth:`McapRecorder.write` with a message
object (rather than CDR bytes) and deserializing import ``rclpy.serialization``.
"""

from __future__ import annotations

import sys
from pathlib import Path

from .cdr import cdr_size, serialize_exact
from .mcap_reader import (RecordedMessage, deserialize, is_complete, iter_decoded, read_messages,
                          read_messages_tolerant)
from .mcap_recover import recover
from .mcap_schema import (DEFINITION_SEPARATOR, MESSAGE_ENCODING, ROS2_PROFILE, ROSBAG2_METADATA_VERSION,
                          SCHEMA_ENCODING, RecordingError, library_string, message_class,
                          message_definition, split_type_name, type_hash, type_name_of)
from .mcap_writer import McapRecorder, bag_metadata_yaml
from uam_contract.qos_spec import INFINITE_DURATION, QosSpec, offered_qos_yaml, parse_offered_qos
from .recording_bench import benchmark
from uam_contract.stamps import sim_stamp_ns

__all__ = ["DEFINITION_SEPARATOR", "INFINITE_DURATION", "MESSAGE_ENCODING", "ROS2_PROFILE",
           "ROSBAG2_METADATA_VERSION", "SCHEMA_ENCODING", "McapRecorder", "QosSpec",
           "RecordedMessage", "RecordingError", "bag_metadata_yaml", "benchmark", "cdr_size",
           "deserialize", "is_complete", "iter_decoded", "library_string", "main", "message_class",
           "message_definition", "offered_qos_yaml", "parse_offered_qos", "read_messages",
           "read_messages_tolerant", "recover", "serialize_exact", "sim_stamp_ns", "split_type_name",
           "type_hash", "type_name_of"]


def main(argv: list[str] | None = None) -> int:
    """``python -m uam_sim.recording recover TORN.mcap FIXED.mcap`` | ``info FILE.mcap`` | ``bench``."""
    import argparse

    ap = argparse.ArgumentParser(allow_abbrev=False, prog="python -m uam_sim.recording")
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
    sys.exit(main())
