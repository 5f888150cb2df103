"""Fast CDR encoding of the simulator's per-step messages (FleetState, PoseArray), free of rclpy.

The simulator publishes the whole fleet every simulated second. Building a FleetState of ~150
VehicleState Python objects and letting rclpy convert it costs ~15-20 ms per step, which alone
would cap a 3500 s run at a real-time factor near 50. rclpy publishers also accept the serialized
message as bytes, so these functions write the same bytes directly from numpy arrays: plain CDR
(XCDR1, little endian, encapsulation header 00 01 00 00), with each primitive aligned to its size
relative to the start of the payload, exactly as rmw_fastrtps serializes. A test holds them equal
to ``rclpy.serialization.serialize_message`` of the equivalent message objects.
"""

from __future__ import annotations

import struct

import numpy as np

_ENCAPSULATION = b"\x00\x01\x00\x00"  # CDR_LE


class _Writer:
    __slots__ = ("buf",)

    def __init__(self):
        self.buf = bytearray()

    def align(self, n: int) -> None:
        pad = (-len(self.buf)) % n
        if pad:
            self.buf += b"\x00" * pad

    def u32(self, v: int) -> None:
        self.align(4)
        self.buf += struct.pack("<I", v)

    def i32(self, v: int) -> None:
        self.align(4)
        self.buf += struct.pack("<i", v)

    def u64(self, v: int) -> None:
        self.align(8)
        self.buf += struct.pack("<Q", v)

    def string(self, s: str) -> None:
        data = s.encode("utf-8")
        self.u32(len(data) + 1)
        self.buf += data + b"\x00"

    def header(self, sec: int, nanosec: int, frame_id: str) -> None:
        self.i32(sec)
        self.u32(nanosec)
        self.string(frame_id)


# The fixed part of a VehicleState after its id: position and velocity (6 float64), phase (uint8,
# then 3 bytes of padding to align the uint32), segment_index (uint32), distance flown and remaining
# (2 float64). 72 bytes, a multiple of 8: every vehicle after the first starts 8-aligned.
_VEHICLE_FIXED = np.dtype([("pv", "<f8", (6,)), ("phase", "u1"), ("pad", "V3"), ("segment", "<u4"),
                           ("distances", "<f8", (2,))])
assert _VEHICLE_FIXED.itemsize == 72


def _id_block(vehicle_id: str, offset: int) -> bytes:
    """A vehicle id as CDR starting at ``offset`` (4-aligned): length, bytes, NUL, then padding up
    to the 8-alignment of the position that follows."""
    data = vehicle_id.encode("utf-8")
    end = offset + 4 + len(data) + 1
    return struct.pack("<I", len(data) + 1) + data + b"\x00" + b"\x00" * ((-end) % 8)


_ID_BLOCKS: dict[str, bytes] = {}  # id -> its block at an 8-aligned offset (ids repeat every step)


def encode_fleet_state(sec: int, nanosec: int, frame_id: str, step_index: int, vehicle_ids, positions_m,
                       velocities_mps, phases, segment_indices, flown_m, remaining_m) -> bytes:
    """Serialized uam_msgs/FleetState. Arrays have one row per vehicle (positions (n, 3) ENU m).

    The fixed part of all vehicles is one numpy structured array; only the ids (whose length sets
    the padding) are joined in Python, each cached: ~10x faster than packing field by field
    (BENCHMARKS.md, node graph)."""
    w = _Writer()
    w.header(sec, nanosec, frame_id)
    w.u64(step_index)
    n = len(vehicle_ids)
    w.u32(n)
    if n == 0:
        return _ENCAPSULATION + bytes(w.buf)
    fixed = np.zeros(n, dtype=_VEHICLE_FIXED)
    fixed["pv"][:, :3] = np.asarray(positions_m, dtype=np.float64).reshape(n, 3)
    fixed["pv"][:, 3:] = np.asarray(velocities_mps, dtype=np.float64).reshape(n, 3)
    fixed["phase"] = np.asarray(phases, dtype=np.uint8)
    fixed["segment"] = np.asarray(segment_indices, dtype=np.uint32)
    fixed["distances"][:, 0] = flown_m
    fixed["distances"][:, 1] = remaining_m
    raw = memoryview(fixed.tobytes())
    parts = [_ENCAPSULATION, bytes(w.buf), _id_block(vehicle_ids[0], len(w.buf)), raw[:72]]
    blocks = _ID_BLOCKS
    for i in range(1, n):
        vid = vehicle_ids[i]
        block = blocks.get(vid)
        if block is None:
            if len(blocks) > 100_000:  # bounded: a long run flies many more vehicles than are airborne
                blocks.clear()
            block = blocks[vid] = _id_block(vid, 0)
        parts.append(block)
        parts.append(raw[72 * i: 72 * (i + 1)])
    return b"".join(parts)


def encode_pose_array(sec: int, nanosec: int, frame_id: str, positions_m, orientations_xyzw) -> bytes:
    """Serialized geometry_msgs/PoseArray (positions (n, 3), quaternions (n, 4) as x, y, z, w)."""
    w = _Writer()
    w.header(sec, nanosec, frame_id)
    pos = np.asarray(positions_m, dtype="<f8").reshape(-1, 3)
    quat = np.asarray(orientations_xyzw, dtype="<f8").reshape(-1, 4)
    w.u32(pos.shape[0])
    if pos.shape[0]:
        w.align(8)
        w.buf += np.concatenate([pos, quat], axis=1).tobytes()
    return _ENCAPSULATION + bytes(w.buf)


def yaw_quaternions(velocities_mps) -> np.ndarray:
    """(n, 4) quaternions x, y, z, w of the heading (yaw from the horizontal velocity)."""
    v = np.asarray(velocities_mps, dtype=np.float64).reshape(-1, 3)
    yaw = np.arctan2(v[:, 1], v[:, 0])
    q = np.zeros((v.shape[0], 4))
    q[:, 2] = np.sin(yaw / 2)
    q[:, 3] = np.cos(yaw / 2)
    return q
