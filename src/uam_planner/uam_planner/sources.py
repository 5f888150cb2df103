"""What the planner takes from the topics only its simulator may publish: fleet states and the
conformance reports of them.

Anyone on the DDS domain can publish on ``uam/fleet_state`` and ``uam/conformance``. The planner
counts a message only when it carries the run token (``session``) of the simulator it is bound
to (the simulator of its first epoch call). The token is no secret (every message shows it), so
a forger can copy it; but the simulator publishes exactly one fleet state per step, so two
*different* messages of one kind for one step under the bound session mean that one of them is
forged. The planner cannot tell which it already believed, so :class:`BoundSource` records the
problem and the planner refuses the next epoch call with it: the simulator ends the run with the
reason, and the recording is NOT VERIFIED (docs/security.md).

rclpy-free: the node passes each message's kind, session, step and a digest of its content; a
fleet state as a :class:`FleetView` read straight from its bytes.
"""

from __future__ import annotations

from collections import OrderedDict
from dataclasses import dataclass

import numpy as np

#: how many recent steps per kind are remembered to compare a second message with
REMEMBERED_STEPS = 4096


class BoundSource:
    """The bound simulator's session, the messages taken from it and any forgery seen."""

    def __init__(self):
        self.session: str | None = None
        #: messages refused because they carry another session (or none), per kind
        self.foreign: dict[str, int] = {}
        #: the first forgery seen ("" while none): why the run cannot go on
        self.problem = ""
        self._seen: OrderedDict = OrderedDict()

    def bind(self, session: str) -> None:
        self.session = session

    def take(self, kind: str, session: str, step_index: int, digest) -> bool:
        """Whether to count this message: it carries the bound session and is the first of its
        kind for its step (a repeat of the same content is not counted again). A different
        message for a step already taken sets :attr:`problem`. Before the planner is bound no
        message is taken (the caller keeps it until then)."""
        if self.session is None or session != self.session:
            self.foreign[kind] = self.foreign.get(kind, 0) + 1
            return False
        key = (kind, int(step_index))
        prev = self._seen.get(key)
        if prev is None:
            self._seen[key] = digest
            if len(self._seen) > 2 * REMEMBERED_STEPS:
                self._seen.popitem(last=False)
            return True
        if prev != digest and not self.problem:
            self.problem = (f"{kind}: two different messages of step {int(step_index)} carry the bound simulator's "
                            f"session {session!r}; the simulator publishes one, so one is forged (its session "
                            "copied) and what the planner observed cannot be trusted")
        return False

    def refused(self, kind: str) -> int:
        return self.foreign.get(kind, 0)


@dataclass(frozen=True)
class FleetView:
    """What the planner takes from a FleetState: its stamp, step, session, vehicle ids and
    positions (n, 3) [m], and a digest of its content (stamp, ids, positions) that tells two
    messages of one step apart. Made from the serialized message
    (:func:`uam_planner.fleet_state_cdr.observed_fleet`) or from a deserialized one
    (:meth:`of_message`); both give the same view and digest."""
    sec: int
    nanosec: int
    step_index: int
    session: str
    vehicle_ids: tuple
    positions_m: np.ndarray
    digest: int

    @classmethod
    def make(cls, sec, nanosec, step_index, session, vehicle_ids, positions_m) -> "FleetView":
        ids = tuple(vehicle_ids)
        pos = np.ascontiguousarray(positions_m, dtype=np.float64).reshape(len(ids), 3)
        return cls(int(sec), int(nanosec), int(step_index), str(session), ids, pos,
                   hash((int(sec), int(nanosec), ids, pos.tobytes())))

    @classmethod
    def of_message(cls, msg) -> "FleetView":
        """From a deserialized FleetState (anything with its fields)."""
        s = msg.header.stamp
        return cls.make(s.sec, s.nanosec, msg.step_index, msg.session,
                        [v.vehicle_id for v in msg.vehicles],
                        [(v.position.x, v.position.y, v.position.z) for v in msg.vehicles])

    @classmethod
    def of_cdr(cls, data: bytes) -> "FleetView | None":
        """From the serialized message (little-endian CDR); None for big-endian data."""
        from .fleet_state_cdr import observed_fleet
        d = observed_fleet(data)
        if d is None:
            return None
        s = d.header.stamp
        return cls.make(s.sec, s.nanosec, d.step_index, d.session, d.vehicle_ids, d.positions_m)

    @property
    def t_s(self) -> float:
        return self.sec + self.nanosec * 1e-9


def fleet_digest(msg) -> int:
    """A digest of a FleetState's content (its stamp, ids and positions), as :class:`FleetView`
    computes it."""
    return msg.digest if isinstance(msg, FleetView) else FleetView.of_message(msg).digest


def conformance_digest(msg) -> int:
    """A digest of a Conformance report's content (its stamp, ids and verdicts)."""
    s = msg.header.stamp
    return hash((int(s.sec), int(s.nanosec), tuple(msg.vehicle_ids), tuple(bool(x) for x in msg.conforming)))


__all__ = ["BoundSource", "FleetView", "REMEMBERED_STEPS", "conformance_digest", "fleet_digest"]
