"""``python -m uam_sim.recording recover | info | bench``: repair, list or benchmark a recording."""

from __future__ import annotations

import sys
from pathlib import Path

from ..studies.recording_bench import benchmark
from . import RecordingError, is_complete, read_messages, read_messages_tolerant, recover


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
