"""Rewriting a recording cut short by a crash into a complete file."""

from __future__ import annotations

import os
import struct
from pathlib import Path

from .mcap_schema import ROS2_PROFILE, RecordingError, library_string
from .mcap_writer import _COMPRESSION, bag_metadata_yaml


#: written into every rebuilt file: uam_sim.audit.analysis then never takes it for a complete run
RECOVERED_METADATA = "uam_recovered"


def _metadata_before_cut(src) -> list[tuple[str, dict]]:
    """(name, data) of the Metadata records of ``src`` up to its tear, in file order."""
    from mcap.exceptions import McapError
    from mcap.records import Metadata
    from mcap.stream_reader import StreamReader

    out = []
    with open(src, "rb") as f:
        records = StreamReader(f, skip_magic=False).records
        while True:
            try:
                record = next(records)
            except StopIteration:
                break
            except (McapError, EOFError, ValueError, OSError, KeyError, struct.error):
                break
            if isinstance(record, Metadata):
                out.append((record.name, dict(record.metadata)))
    return out


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
        # the metadata written before the cut (the recorder writes the run's airspace first),
        # and the mark that keeps the rebuilt file from passing for a complete recording
        for name, data in _metadata_before_cut(src):
            if name not in ("rosbag2", RECOVERED_METADATA):
                writer.add_metadata(name, data)
        writer.add_metadata(RECOVERED_METADATA, {"source": str(src), "messages": str(count)})
        writer.add_metadata("rosbag2", {"serialized_metadata": bag_metadata_yaml(
            Path(dst).name, topics, counts, start, end)})
        writer.finish()
    return count
