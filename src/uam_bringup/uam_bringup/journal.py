"""The planner's journal: its own approvals, on disk, so a restarted planner knows the traffic.

What the planner believes about the airspace must come from its own approvals, never from one
caller's word (docs/security.md). A planner that restarts mid-run loses its memory; the
simulator then sends the flights in the air (``PlanEpoch`` with ``resume``). With a journal the
restarted planner checks that claim against what it approved itself: a claim that leaves out a
flight it approved and that is still flying, adds one it never approved, or changes one, is
refused (the run then ends with the reason), so a faulty or forged resume can never make it
forget an aircraft.

Format: one JSON object per line, ``{"session": <simulator session>, "plan": <base64 of the
FlightPlan's CDR>, "priority": <the request's class>}``, appended and flushed before the plan is
published or answered (so every plan anyone can hold is in the journal first); and
``{"session": ..., "constraints": <the set's text>}`` for each constraint set the planner
publishes. The journal is the planner's own record: the USS node serves it (:class:`JournalTail`)
rather than the topics anyone on the domain can publish. Re-planned versions and cancellations
(``FlightPlan.version`` > 1) are journaled the same way, so a restarted planner takes each
flight's newest version (:func:`newest_versions`), not its first. Only the entries of the simulator session the
planner resumes for count: a journal left over from another run is ignored and started afresh.
"""

from __future__ import annotations

import base64
import json
import os
from pathlib import Path

from uam_contract.stamps import stamp_s
from uam_contract.wire import scoped_id


def newest_versions(plans, epoch_index: int, t_s: float) -> dict:
    """scoped request id -> the newest version of its plan that reached the simulator before the
    epoch ``epoch_index`` at ``t_s`` [s]: approvals of earlier epochs, and re-planned versions
    (``version`` > 1; a cancellation too) decided before ``t_s``. Later ones were
    never answered (the simulator asks for that epoch again), so they never flew."""
    own: dict = {}
    for p in plans:
        version = int(getattr(p, "version", 0) or 0)
        if version > 1:
            if stamp_s(p.header.stamp) >= t_s:
                continue
        elif int(p.epoch_index) >= epoch_index:
            continue
        key = scoped_id(p.operator_id, p.request_id)
        held = own.get(key)
        if held is None or version >= int(getattr(held, "version", 0) or 0):
            own[key] = p
    return own


class Journal:
    """Append-only record of approved FlightPlan messages, keyed by the simulator's session."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._file = None
        self._session = ""

    def read(self, session: str) -> list:
        """The approved plans journaled for ``session`` (empty when none or another run's)."""
        from rclpy.serialization import deserialize_message
        from uam_msgs.msg import FlightPlan

        if not self.path.is_file():
            return []
        lines = self.path.read_text(encoding="utf-8").splitlines()
        plans = []
        for n, line in enumerate(lines, 1):
            if not line.strip():
                continue
            try:
                entry = json.loads(line)
                if entry.get("session") != session or "constraints" in entry:
                    continue
                plans.append(deserialize_message(base64.b64decode(entry["plan"]), FlightPlan))
            except (ValueError, KeyError, TypeError, AttributeError) as exc:
                # a last line cut by a crash mid-write is the only expected damage: it was never
                # published (the write comes first), so it is skipped; anything else is a broken
                # journal, which must not be half-trusted
                if n == len(lines):
                    break
                raise ValueError(f"journal {self.path}: line {n} is not a journal entry ({exc})") from exc
        return plans

    def start(self, session: str, keep: bool) -> None:
        """Write for ``session`` from now on: appended to the existing entries when ``keep`` (a
        resume of the same run), else the file is started afresh."""
        self.close()
        self.path.parent.mkdir(parents=True, exist_ok=True)
        self._file = self.path.open("a" if keep else "w", encoding="utf-8")
        self._session = session

    @property
    def started(self) -> bool:
        return self._file is not None

    def append(self, plans, priorities: dict | None = None) -> None:
        """Journal approved ``plans`` (FlightPlan messages), each with its request's priority
        class (``priorities``: (operator_id, request_id) -> class); flushed to the OS before
        returning."""
        from rclpy.serialization import serialize_message

        if self._file is None:
            return
        for plan in plans:
            entry = {"session": self._session, "plan": base64.b64encode(serialize_message(plan)).decode("ascii")}
            if priorities:
                entry["priority"] = int(priorities.get((plan.operator_id, plan.request_id), 0))
            self._file.write(json.dumps(entry) + "\n")
        self._file.flush()

    def append_constraints(self, text: str) -> None:
        """Journal a constraint set the planner publishes (its text); flushed."""
        if self._file is None:
            return
        self._file.write(json.dumps({"session": self._session, "constraints": str(text)}) + "\n")
        self._file.flush()

    def close(self) -> None:
        if self._file is not None:
            self._file.close()
            self._file = None


class JournalTail:
    """A reader that follows a planner's journal as it grows (the USS node's source).

    :meth:`poll` returns the entries of the complete lines written since the last call, decoded:
    {"session", "plan" (FlightPlan) and "priority"} or {"session", "constraints" (text)}. A file
    that shrank (a planner that started afresh) is read again from its start and ``restarted``
    is set; a damaged line is skipped and counted in ``bad_lines``."""

    def __init__(self, path: str | os.PathLike):
        self.path = Path(path)
        self._offset = 0
        self._rest = b""
        self.restarted = False
        self.bad_lines = 0

    def poll(self) -> list[dict]:
        from rclpy.serialization import deserialize_message
        from uam_msgs.msg import FlightPlan

        self.restarted = False
        try:
            size = self.path.stat().st_size
        except OSError:
            return []
        if size < self._offset:
            self._offset, self._rest, self.restarted = 0, b"", True
        if size == self._offset:
            return []
        with self.path.open("rb") as f:
            f.seek(self._offset)
            data = f.read(size - self._offset)
        self._offset += len(data)
        *lines, self._rest = (self._rest + data).split(b"\n")
        out = []
        for line in lines:
            if not line.strip():
                continue
            try:
                entry = json.loads(line)
                if "constraints" in entry:
                    out.append({"session": str(entry["session"]), "constraints": str(entry["constraints"])})
                else:
                    out.append({"session": str(entry["session"]), "priority": int(entry.get("priority", 0)),
                                "plan": deserialize_message(base64.b64decode(entry["plan"]), FlightPlan)})
            except (ValueError, KeyError, TypeError, AttributeError):
                self.bad_lines += 1
        return out
