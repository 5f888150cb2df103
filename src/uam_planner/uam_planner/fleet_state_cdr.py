"""Reading a FleetState straight from its CDR bytes: stamp, step, vehicle ids, positions and
the session, with no VehicleState object per vehicle.

The simulator publishes the whole fleet every simulated second; rclpy's deserialization builds a
VehicleState, a Point and a Vector3 object per vehicle (in the paper scenario's planner node,
197,000 VehicleStates: the largest part of its CPU). The planner node, the recorder and the
analysis read the few fields they need from the serialized message instead: plain CDR (XCDR1,
little endian), the layout ``uam_sim.recording.cdr`` writes and rmw_fastrtps serializes
(``test_fleet_cdr.py`` holds the two equal). rclpy-free.
"""

from __future__ import annotations

import struct
from types import SimpleNamespace
from typing import Any

import numpy as np


def _align(pos: int, n: int) -> int:
    return pos + (-pos) % n


#: bytes of a VehicleState after its vehicle_id, from the 8-aligned end of the id: Point and
#: Vector3 (6 float64), phase uint8 (+3 padding), segment_index uint32, two float64
_VEHICLE_TAIL = 48 + 4 + 4 + 16


def _equal_length_run(data: bytes, pos: int, n: int, r: int) -> bool:
    """True if the r vehicle records from 8-aligned payload offset ``pos`` all have an id of the
    length n (incl. NUL), i.e. they are records of one stride (checked with a strided view)."""
    stride = _align(4 + n, 8) + _VEHICLE_TAIL
    if n == 0 or 4 + pos + r * stride > len(data):
        return False
    lengths = np.ndarray((r,), dtype="<u4", buffer=data, offset=4 + pos, strides=(stride,))
    return bool(np.all(lengths == n))


def _step_index_at(data: bytes) -> int:
    """Payload offset of a little-endian FleetState's step_index: after the stamp and the
    frame_id string, aligned to 8 (see :func:`fleet_state_digest` for the layout)."""
    n_frame, = struct.unpack_from("<I", data, 12)
    pos = 12 + n_frame
    return pos + (-pos) % 8


def fleet_state_step_index(data: bytes) -> int | None:
    """The step_index of a FleetState read from its little-endian CDR; None for big-endian or
    short data. O(1)."""
    if len(data) < 16 or data[1] != 1:
        return None
    pos = _step_index_at(data)
    if len(data) < 4 + pos + 8:
        return None
    return struct.unpack_from("<Q", data, 4 + pos)[0]


def fleet_state_digest(data: bytes, positions: bool = False, session: bool = False) -> Any | None:
    """Stamp, step, vehicle ids (and positions) of a FleetState read straight from its CDR.

    Layout (XCDR1, offsets from the payload after the 4-byte encapsulation header): stamp sec
    int32 @0, nanosec uint32 @4, frame_id string (uint32 length incl. NUL, bytes) @8, step_index
    uint64 aligned to 8, vehicles count uint32, then per vehicle its vehicle_id string (aligned
    to 4) and a fixed tail aligned to 8 (position x, y, z first). Returns a namespace with
    ``header.stamp``, ``step_index``, ``vehicle_ids``, ``vehicles`` (the ids: only their count
    is used), with ``positions``, ``positions_m`` (n, 3) and ``velocities_mps`` (n, 3, the
    fixed tail's second vector), with ``session`` the ``session`` string after the vehicles
    (raises ValueError when the data end before it); None for big-endian data (the
    caller deserializes fully then). No VehicleState objects: when the ids have one length (the
    simulator's do), the records have one stride and are read as strided numpy views, else one
    struct read per vehicle (measured: ~2 ms per 130-vehicle message in Python, loaded machine).
    """
    if len(data) < 16 or data[1] != 1:
        return None
    sec, nanosec = struct.unpack_from("<iI", data, 4)
    pos = _step_index_at(data)
    step_index, = struct.unpack_from("<Q", data, 4 + pos)
    pos += 8
    pos += (-pos) % 4
    count, = struct.unpack_from("<I", data, 4 + pos)
    pos += 4
    ids: list = []
    xyz: list = []
    vel: list = []
    k = 0
    while k < count:
        pos += (-pos) % 4
        n, = struct.unpack_from("<I", data, 4 + pos)
        if pos % 8 == 0 and _equal_length_run(data, pos, n, count - k):
            # the simulator's ids all have one length: the rest are records of one stride
            r, stride, tail = count - k, _align(4 + n, 8) + _VEHICLE_TAIL, _align(4 + n, 8)
            names = np.ndarray((r,), dtype=f"S{n - 1}", buffer=data, offset=4 + pos + 4, strides=(stride,))
            try:
                ids += names.astype(f"U{n - 1}").tolist() if n > 1 else [""] * r
            except UnicodeDecodeError:
                ids += [b.decode("utf-8") for b in names.tolist()]
            if positions:
                xyz.append(np.ndarray((r, 3), dtype="<f8", buffer=data, offset=4 + pos + tail,
                                      strides=(stride, 8)))
                vel.append(np.ndarray((r, 3), dtype="<f8", buffer=data, offset=4 + pos + tail + 24,
                                      strides=(stride, 8)))
            break
        ids.append(data[8 + pos:8 + pos + n - 1].decode("utf-8"))
        pos += 4 + n
        pos += (-pos) % 8
        if positions:
            xyz.append(np.asarray(struct.unpack_from("<3d", data, 4 + pos)).reshape(1, 3))
            vel.append(np.asarray(struct.unpack_from("<3d", data, 4 + pos + 24)).reshape(1, 3))
        pos += _VEHICLE_TAIL
        k += 1
    out = SimpleNamespace(header=SimpleNamespace(stamp=SimpleNamespace(sec=sec, nanosec=nanosec)),
                          step_index=step_index, vehicle_ids=ids, vehicles=ids)
    if session:
        out.session = _session_after(data, pos, count - k, ids)
    if positions:
        out.positions_m = np.concatenate(xyz).astype(np.float64) if xyz else np.zeros((0, 3))
        out.velocities_mps = np.concatenate(vel).astype(np.float64) if vel else np.zeros((0, 3))
    return out


def _session_after(data: bytes, pos: int, r: int, ids: list) -> str:
    """The session string that follows the vehicle records: ``pos`` is the payload offset of the
    first of the last ``r`` records, which have one stride (or none is left: r == 0)."""
    if r:
        n = len(ids[-1].encode("utf-8")) + 1
        pos += r * (_align(4 + n, 8) + _VEHICLE_TAIL)
    pos += (-pos) % 4
    if len(data) < 4 + pos + 4:
        raise ValueError(f"FleetState: the data end at byte {len(data)} before its session string")
    n, = struct.unpack_from("<I", data, 4 + pos)
    if n == 0 or len(data) < 4 + pos + 4 + n:
        raise ValueError(f"FleetState: a session string of length {n} does not fit the data "
                         f"({len(data)} bytes)")
    return data[8 + pos:8 + pos + n - 1].decode("utf-8")


def observed_fleet(data: bytes):
    """What the planner takes from a serialized FleetState: ``header.stamp``, ``step_index``,
    ``vehicle_ids``, ``positions_m`` (n, 3) and ``session``; None for big-endian data (the
    caller deserializes it fully then)."""
    return fleet_state_digest(data, positions=True, session=True)


__all__ = ["fleet_state_digest", "fleet_state_step_index", "observed_fleet"]
