"""The run's record: one model of what was in force and what was allowed, from which the
audits, the F3548 documents and the studies' tables are derived.

A :class:`RunRecord` holds

- every approved flight (:class:`FlightRecord`): its plan versions in order and its parts in
  force (each version from the instant it took effect until the next one did, its first waypoint
  kept; a cancellation ends the flight as planned; :func:`uam_sim.audit.flown_audit.flown_trajectory`),
  with the problems of its chain (:func:`uam_sim.audit.flown_audit.chain_problems`);
- the constraint versions as the planner applied them (from the epoch each took effect at until
  it was replaced or withdrawn) and as the authority announced them (the gap between the two).

It is built alike from a recording (:meth:`RunRecord.from_plans`: the approvals and the plan
updates on ``uam/flight_plans``, the sets on ``uam/constraints``) and from the in-process
runner's state (:meth:`RunRecord.from_versions`: each flight's :class:`PlanVersion` list and the
planner's constraint timeline). What flew (the fleet states' tracks) is audited against its
parts by :func:`uam_sim.audit.flown.recording_flown`, which reads the same record.

rclpy-free; plans are anything with FlightPlan's fields, or :class:`PlanVersion`.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, field
from typing import Any, Sequence

import numpy as np

from .flown_audit import (Flown, announced_at, chain_problems, constraint_intervals,
                          contingency, effective_s, flown_trajectory, incursions, plan_version,
                          version_trajectory)


@dataclass
class PlanVersion:
    """One plan version as the in-process runner keeps it (the fields the record reads from a
    FlightPlan message): ``times_s``/``points_m`` empty for a cancellation; ``effective_s``
    ignored for version 1 (in force from its departure)."""

    version: int
    effective_s: float
    times_s: np.ndarray
    points_m: np.ndarray
    update_kind: str = ""
    origin_id: str = ""
    destination_id: str = ""
    constraint_ids: tuple = ()
    reason: str = ""
    state: int = 0

    @property
    def waypoints(self) -> bool:
        return len(self.times_s) > 0

    @classmethod
    def of(cls, version: int, effective: float, trajectory, **kw) -> "PlanVersion":
        """A version flying ``trajectory`` (a uam_planner Trajectory; None: a cancellation)."""
        if trajectory is None:
            return cls(int(version), float(effective), np.zeros(0), np.zeros((0, 3)), **kw)
        return cls(int(version), float(effective), np.asarray(trajectory.times_s, dtype=np.float64),
                   np.asarray(trajectory.points_m, dtype=np.float64).reshape(-1, 3), **kw)


@dataclass
class PlansInForce:
    """Every approved flight's plan while in force, one trajectory per part. ``labels``: the
    flight's label, with `` v<n> (contingency)`` on a contingency version's part; ``groups``:
    the flight's label, so that two parts of one flight are never a pair
    (:func:`uam_sim.audit.separation.audit_trajectories`); ``contingent``: a flag per part."""

    parts: list
    labels: list
    groups: list
    contingent: list

    def parts_as_trajectories(self) -> list:
        """The parts as uam_planner Trajectories (what the sweep audit takes)."""
        from uam_planner.trajectory import Trajectory
        return [Trajectory(t, x) for t, x in self.parts]

    def select(self, keep: Sequence[bool]) -> "PlansInForce":
        k = [i for i, x in enumerate(keep) if x]
        return PlansInForce(*([v[i] for i in k] for v in (self.parts, self.labels, self.groups, self.contingent)))


@dataclass
class FlightRecord:
    """One approved flight: its versions in order and what of them was in force (``flown``)."""

    key: str
    versions: list
    flown: Flown
    problems: list = field(default_factory=list)
    #: the request's key (operator/request; ``key`` adds ``#n`` to a second approval of one request)
    request: str = ""

    @property
    def updated(self) -> bool:
        return len(self.versions) > 1

    def pieces(self) -> list[tuple[float, Any]]:
        """[(from_s, Trajectory)] of each version with a path, in order: what a flown track is
        compared with at each sample (``uam_sim.world.conformance.versioned_conformance``)."""
        from uam_planner.trajectory import Trajectory

        out = []
        for p in self.versions:
            t, x = version_trajectory(p)
            if t.size >= 2 and np.all(np.diff(t) > 0):
                out.append((effective_s(p), Trajectory(t, x)))
        return out

    def path(self):
        """The flight's path in force as one Trajectory (the parts joined; a later part's first
        point replaces its predecessor's last), or None when it is not a valid trajectory."""
        from uam_planner.trajectory import Trajectory

        t, x = self.flown.times_s, self.flown.points_m
        if t.size >= 2 and np.all(np.diff(t) > 0):
            return Trajectory(t, x)
        return None


@dataclass
class RunRecord:
    """What was in force in one run (see the module docstring)."""

    flights: list[FlightRecord]
    #: (constraint version, from_s, until_s) while the planner had it in force
    applied: list = field(default_factory=list)
    problems: list[str] = field(default_factory=list)

    # ---- building ------------------------------------------------------------------------
    @classmethod
    def from_plans(cls, approved: Sequence[tuple[str, Any]], updates: dict | None = None,
                   sets: Sequence = ()) -> "RunRecord":
        """The record of a recording: ``approved`` (request key, approved plan = version 1) in
        order (a request approved twice, which the integrity check reports, is labelled
        ``key#2``, ...), ``updates`` request key -> {any: plan of version >= 2}, ``sets`` the
        recorded constraint sets (t_s, [(constraint, effective_s)]). Updates of a request with
        no or several approvals are a problem of the record (a plan nobody approved, or a
        recording that lost one): its approvals are taken as they are."""
        updates = updates or {}
        announced = announced_at(sets)
        counts: dict[str, int] = {}
        for key, _p in approved:
            counts[key] = counts.get(key, 0) + 1
        problems = []
        for key in sorted(updates):
            n = counts.get(key, 0)
            if n != 1:
                problems.append(f"{key}: {len(updates[key])} plan update(s) for a request with "
                                f"{'no approval' if not n else f'{n} different approvals'} in the recording")
        flights, seen = [], {}
        for key, p in approved:
            seen[key] = seen.get(key, 0) + 1
            label = key if seen[key] == 1 else f"{key}#{seen[key]}"
            later = updates.get(key) if counts[key] == 1 else None
            versions = sorted([p, *later.values()], key=plan_version) if later else [p]
            flights.append(cls._flight(label, versions, announced if later else None, key))
        problems += [x for f in flights for x in f.problems]
        return cls(flights, constraint_intervals(sets), problems)

    def without(self, requests) -> "RunRecord":
        """The record without the flights of ``requests`` (request keys; e.g. forged plans)."""
        drop = set(requests)
        if not drop:
            return self
        return RunRecord([f for f in self.flights if f.request not in drop], self.applied, self.problems)

    @classmethod
    def from_versions(cls, histories: Sequence[tuple[str, Sequence[Any]]],
                      applied: Sequence[tuple[Any, float, float]] = ()) -> "RunRecord":
        """The record of the in-process runner: (label, versions in order) per approved flight
        and the planner's constraint timeline (``uam_planner.replanning.constraint_timeline``)."""
        announced: dict[str, float] = {}
        for c, since, _until in applied:
            announced[c.constraint_id] = min(announced.get(c.constraint_id, math.inf), float(since))
        flights = [cls._flight(label, list(vs), announced if len(vs) > 1 else None, label)
                   for label, vs in histories]
        return cls(flights, list(applied), [x for f in flights for x in f.problems])

    @staticmethod
    def _flight(label: str, versions: list, announced: dict | None, request: str) -> FlightRecord:
        if announced is None:  # the approval alone: flown whole
            t, x = version_trajectory(versions[0])
            spans = [(plan_version(versions[0]), float(t[0]), float(t[-1]))] if len(t) else []
            return FlightRecord(label, versions, Flown(label, versions, t, x, spans), request=request)
        flown, gaps = flown_trajectory(label, versions)
        return FlightRecord(label, versions, flown, chain_problems(label, versions, announced) + gaps, request)

    # ---- reading -------------------------------------------------------------------------
    @property
    def updated(self) -> bool:
        """Whether any flight has a version after its approval."""
        return any(f.updated for f in self.flights)

    def by_key(self) -> dict[str, FlightRecord]:
        return {f.key: f for f in self.flights}

    def in_force(self) -> PlansInForce:
        """Every flight's parts in force, labelled (a contingency version's part with
        `` v<n> (contingency)``) and grouped by flight."""
        out = PlansInForce([], [], [], [])
        for f in self.flights:
            for t, x, version in f.flown.parts():
                c = version is not None and contingency(version)
                out.parts.append((t, x))
                out.labels.append(f"{f.key} v{plan_version(version)} (contingency)" if c else f.key)
                out.groups.append(f.key)
                out.contingent.append(c)
        return out

    def audit_plans(self, separation_m) -> tuple[Any, list]:
        """The exact separation audit of the deconflicted plans in force
        (:func:`uam_sim.audit.separation.audit_trajectories`, two parts of one flight never a
        pair) and the conflicts of contingency versions ([a, b, distance, t]), a class of their
        own: not deconflicted by design."""
        from .separation import audit_trajectories

        in_force = self.in_force()
        ok = in_force.select([not c for c in in_force.contingent])
        audit = audit_trajectories(ok.parts, ok.labels, separation_m, groups=ok.groups)
        if not any(in_force.contingent):
            return audit, []
        return audit, audit_trajectories(in_force.parts, in_force.labels, separation_m, groups=in_force.groups,
                                         only_pairs_with=in_force.contingent).losses

    def announced_gaps(self) -> list[tuple[Any, float, float]]:
        """(constraint version, announced_s, applied_s) of each version the planner applied after
        the authority announced it (``announce_s``): while it bound the airspace but not yet the
        planner's plans."""
        return [(c, float(c.announce_s), float(since)) for c, since, _until in self.applied
                if math.isfinite(getattr(c, "announce_s", -math.inf)) and c.announce_s < since]

    def incursions(self, network=None) -> tuple[list, list]:
        """Entries of every flight's parts in force into the constraints while the planner had
        them in force, and entries while a version was announced but not yet applied
        (:func:`uam_sim.audit.flown_audit.incursions`)."""
        if not self.applied:
            return [], []
        flights = [f.flown for f in self.flights]
        gaps = self.announced_gaps()
        return incursions(flights, self.applied, network), incursions(flights, gaps, network) if gaps else []

    def paths(self) -> dict:
        """label -> the flight's path in force as one Trajectory (what a flown track's sampling
        bound is computed from)."""
        out = {}
        for f in self.flights:
            tr = f.path()
            if tr is not None:
                out[f.key] = tr
        return out


__all__ = ["FlightRecord", "PlansInForce", "PlanVersion", "RunRecord"]
