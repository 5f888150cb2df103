"""CPU cost of the recorder node's message handling, from a recording, without DDS.

    python -m uam_sim.nodes.recorder_bench RUN.mcap [--network NET.yaml] [--repeat 3]

Feeds the project topics of a recording (what the recorder received in that run: /clock, fleet
states, poses, requests, plans, reports, epoch handshakes) to a RecorderNode's message handler
in process, in file order, and prints the CPU seconds (process time, Rerun's threads included)
of each configuration: views and Rerun on (the default of scripts/bench_graph.sh), views only,
Rerun only, neither. rclpy's executor and DDS are not included (bench_graph.sh measures those).
The output recordings go to a temporary folder.
"""

from __future__ import annotations

import argparse
import sys
import tempfile
import time
from pathlib import Path

CONFIGS = (("views + Rerun .rrd", True, "save"), ("views only", True, "off"),
           ("Rerun .rrd only", False, "save"), ("neither", False, "off"))


def replay_cpu_s(messages, out: Path, network: str, views: bool, rerun: str) -> tuple[float, int]:
    """CPU seconds to handle ``messages`` [(relative topic, CDR bytes)] and close; view messages."""
    from rclpy.parameter import Parameter

    from uam_sim.nodes.recorder_node import RECORDED_TOPICS, RecorderNode

    node = RecorderNode(parameter_overrides=[
        Parameter("output", value=str(out)), Parameter("rerun", value=rerun),
        Parameter("views", value=views), Parameter("network", value=network)])
    try:
        t0 = time.process_time()
        for topic, data in messages:
            node._on_message(topic, RECORDED_TOPICS[topic][0], data)
        node.close()
        return time.process_time() - t0, node.view_messages_written
    finally:
        node.destroy_node()


def main(argv: list[str] | None = None) -> int:
    ap = argparse.ArgumentParser(prog="python -m uam_sim.nodes.recorder_bench", description=__doc__.split("\n")[0])
    ap.add_argument("mcap", help="a recording of the node graph (e.g. /tmp/uam-bench-graph/run.mcap)")
    ap.add_argument("--network", default="config/networks/singapore.yaml", help="the run's network")
    ap.add_argument("--repeat", type=int, default=3, help="runs per configuration; the best is printed")
    args = ap.parse_args(argv)
    import rclpy

    from uam_contract.names import resolved
    from uam_sim.recording.mcap_reader import read_messages
    from uam_sim.nodes.recorder_node import RECORDED_TOPICS

    names = {resolved(t): t for t in RECORDED_TOPICS}
    try:
        messages = [(names[r.topic], r.data) for r in read_messages(args.mcap) if r.topic in names]
    except OSError as exc:
        print(f"recorder_bench: {exc}", file=sys.stderr)
        return 1
    rclpy.init()
    try:
        with tempfile.TemporaryDirectory() as tmp:
            print(f"{len(messages)} messages from {args.mcap}; best of {args.repeat}, CPU s:")
            for label, views, rerun in CONFIGS:
                runs = [replay_cpu_s(messages, Path(tmp) / "out.mcap", args.network, views, rerun)
                        for _ in range(max(1, args.repeat))]
                best = min(r[0] for r in runs)
                print(f"  {label:20s} {best:6.2f} s ({runs[0][1]} view messages)")
    finally:
        rclpy.shutdown()
    return 0


if __name__ == "__main__":
    sys.exit(main())
