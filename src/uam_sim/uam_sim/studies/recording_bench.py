"""Benchmark of recording: write and read back a paper-scale synthetic recording."""

from __future__ import annotations

import os
import time
from pathlib import Path

from uam_contract import names
from uam_contract.names import resolved

from ..recording.mcap_reader import read_messages
from ..recording.mcap_writer import McapRecorder

FLEET, POSES, REPORTS = (resolved(t) for t in (names.TOPIC_FLEET, names.TOPIC_POSES, names.TOPIC_REPORTS))


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
        rec.add_topic(FLEET, FleetState)
        rec.add_topic(POSES, PoseArray)
        rec.add_topic(REPORTS, PlanningReport)
        for k, c, f, p in cdr:
            ns = k * 1_000_000_000
            rec.write("/clock", c, ns)
            rec.write(FLEET, f, ns)
            rec.write(POSES, p, ns)
            if k % 30 == 0:
                rep = PlanningReport(epoch_index=k // 30)
                rep.header.stamp = Time(sec=k)
                rec.write(REPORTS, rep, ns)
    write_s = time.perf_counter() - t0
    t0 = time.perf_counter()
    n_read = sum(1 for _ in read_messages(path))
    read_s = time.perf_counter() - t0
    from ..audit.analysis import summarize
    t0 = time.perf_counter()
    summary = summarize(path)
    analyze_s = time.perf_counter() - t0
    return {"messages": n_read, "file_MB": Path(path).stat().st_size / 1e6,
            "build_msgs_s": build_s, "serialize_s": serialize_s, "write_s": write_s,
            "read_s": read_s, "analyze_s": analyze_s,
            "write_msgs_per_s": n_read / write_s if write_s > 0 else float("inf"),
            "fleet_steps": summary.fleet_steps}
