"""The safety audit of what flew (issue 23): exact closest approach between flown tracks.

A flown track is known at samples (the fleet states of a recording, every ``step_s``; or the
disturbance model's samples in process) and taken as linear between them: the closest approach
of every pair of such tracks is computed exactly by the same sweep as the plans' audit
(:func:`uam_sim.audit.sweep_audit`: every pair of time-overlapping straight pieces, closest
approach clamped to the overlap).

The sampling error, bounded: if an aircraft's speed never exceeds ``v`` between two samples
``dt`` apart, its true position at any time of that interval is within ``v dt / 2`` of the linear
interpolation (write the chord point as ``(1-l) x0 + l x1``; the true point is within ``v l dt``
of ``x0`` and ``v (1-l) dt`` of ``x1``, so within ``2 l (1-l) v dt <= v dt / 2`` of it). Two
aircraft are then at most ``v dt`` closer than their interpolated tracks: a pair is a **loss**
when the interpolated tracks come closer than the minimum, and a **possible loss** when they come
closer than the minimum plus that bound (``sampling_bound_m``, with v the largest speed of the
sampled tracks; the cylinder's V is widened by the same bound). In process the simulated
aircraft flies exactly the interpolation of the model's samples, so the losses are exact there;
the bound then covers the model's own motion inside a step.
"""

from __future__ import annotations

from collections import defaultdict
from typing import Iterable, Mapping

import numpy as np

from uam_planner.separation import SeparationModel, as_separation_model
from uam_planner.trajectory import Trajectory

from .audit import sweep_audit, sweep_audits

OUTCOME_APPROVED = 0  # uam_msgs/FlightPlan.OUTCOME_APPROVED


def tracks_from_samples(samples: Iterable[tuple[float, list, np.ndarray]]) -> dict[str, Trajectory]:
    """Per vehicle, its track from fleet samples ``(t_s, vehicle_ids, positions (v, 3))`` in time
    order; a vehicle seen at one sample only has no track (nothing to interpolate)."""
    times: dict = defaultdict(list)
    pts: dict = defaultdict(list)
    for t, ids, pos in samples:
        for vid, p in zip(ids, np.asarray(pos, dtype=np.float64).reshape(-1, 3)):
            if times[vid] and t <= times[vid][-1]:
                continue  # a repeated sample (a duplicate message)
            times[vid].append(float(t))
            pts[vid].append(p)
    return {vid: Trajectory(np.array(times[vid]), np.array(pts[vid]))
            for vid in sorted(times) if len(times[vid]) >= 2}


def max_speed_mps(tracks: Iterable[Trajectory]) -> float:
    """The largest speed of any piece of the tracks [m/s]."""
    best = 0.0
    for tr in tracks:
        _t0, _t1, _p0, v = tr.segments()
        if v.shape[0]:
            best = max(best, float(np.sqrt(np.square(v).sum(axis=1)).max()))
    return best


def flown_audit(tracks: Mapping[str, Trajectory], separation, sample_step_s: float | None = None,
                prune: bool = True) -> dict:
    """Losses of separation in what flew.

    Args:
        tracks: vehicle id -> flown track (linear between samples).
        separation: the true minimum (a number: the sphere; or a SeparationModel), never a
            planning buffer.
        sample_step_s: the largest time between two samples of a track; None = the tracks are
            the motion itself (no sampling error).
        prune: False checks every time-overlapping pair of pieces (the slow reference; the
            result is the same, ``uam_planner.audit.sweep_audits``).
    Returns: the :func:`uam_sim.audit.sweep_audit` dict of the interpolated tracks, plus
    ``what`` ("flown"), ``sampling_bound_m`` (the bound above, 0 without sampling),
    ``possible_losses`` (pairs closer than the minimum plus the bound) and ``max_speed_mps``.
    """
    model = as_separation_model(separation)
    ids = sorted(tracks)
    trajs = [tracks[i] for i in ids]
    vmax = max_speed_mps(trajs)
    bound = vmax * float(sample_step_s) if sample_step_s else 0.0
    if bound > 0 and trajs:
        # one candidate search for both minima (uam_planner.audit.sweep_audits)
        wide = SeparationModel(model.kind, model.separation_m + bound, model.vertical_separation_m + bound)
        out, wide_out = sweep_audits(trajs, [model, wide], labels=ids, prune=prune)
        possible = wide_out["losses"]
    else:
        out = sweep_audit(trajs, model, labels=ids, prune=prune)
        possible = out["losses"]
    out.update({"what": "flown", "sampling_bound_m": bound, "possible_losses": possible,
                "max_speed_mps": vmax})
    return out


def recording_flown(path, separation, bounds=None, plans=None, prune: bool = True) -> dict:
    """What flew in a recording: the flown tracks from every ``uam/fleet_state`` (positions read
    straight from the CDR), their exact audit in the true minimum (:func:`flown_audit`, sampling
    step = the largest gap between fleet states), and the F3548 conformance of each flown track
    with its plan: each sample with the plan version in force at that instant (version 1 from
    the departure, each later version from its ``effective_time``;
    ``uam_sim.conformance.versioned_conformance``). ``plans``: the FlightPlan messages, every
    version (else read from ``uam/flight_plans``); a vehicle flies the plans of its
    ``operator/request`` id.
    ``prune``: as :func:`flown_audit` (False: the slow reference sweep, the same result).
    Returns {} when the recording holds no fleet positions."""
    from uam_contract import names
    from uam_contract.names import resolved
    from uam_contract.stamps import stamp_s

    from .audit import trajectory_of
    from .cdr import fleet_state_digest
    from .conformance import ConformanceBounds, f3548_statistics, versioned_conformance
    from .mcap_reader import deserialize, is_complete, read_messages, read_messages_tolerant

    fleet_topic, plan_topic = resolved(names.TOPIC_FLEET), resolved(names.TOPIC_PLANS)
    records = (read_messages(path, topics=[fleet_topic, plan_topic]) if is_complete(path)
               else sorted((r for r in read_messages_tolerant(path) if r.topic in (fleet_topic, plan_topic)),
                           key=lambda r: r.log_time_ns))
    samples, found_plans = [], []
    for rec in records:
        if rec.topic == fleet_topic:
            d = fleet_state_digest(rec.data, positions=True)
            if d is None:  # big-endian data: decode in full
                msg = deserialize(rec)
                ids = [v.vehicle_id for v in msg.vehicles]
                pos = np.array([(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]).reshape(-1, 3)
                samples.append((stamp_s(msg.header.stamp), ids, pos))
            else:
                samples.append((stamp_s(d.header.stamp), d.vehicle_ids, d.positions_m))
        elif plans is None:
            found_plans.append(deserialize(rec))
    if not samples:
        return {}
    samples.sort(key=lambda s: s[0])
    ts = np.array([s[0] for s in samples])
    step = float(np.max(np.diff(ts))) if ts.size > 1 else 0.0
    tracks = tracks_from_samples(samples)
    out = flown_audit(tracks, separation, sample_step_s=step, prune=prune)
    out["sample_step_s"] = step
    from uam_contract.wire import scoped_id
    from .flown_audit import effective_s as version_effective_s, plan_version
    versions: dict = {}   # key -> {version: plan}, the first message of each version
    for p in (plans if plans is not None else found_plans):
        # the vehicle id of a plan: operator/request (uam_sim.analysis.request_key)
        key = scoped_id(p.operator_id, p.request_id) if p.operator_id else str(p.request_id)
        if plan_version(p) == 1 and int(p.outcome) != OUTCOME_APPROVED:
            continue
        versions.setdefault(key, {}).setdefault(plan_version(p), p)
    # each flown track against the plan version in force at each of its samples (issue 22 item
    # 5): version 1 from the departure, version n + 1 from the instant it took effect; a
    # cancellation (no waypoints) ends the flight, so no sample should follow it (one that does
    # is compared with the version before)
    pieces_of = {}
    for key, by_v in versions.items():
        if 1 not in by_v:
            continue  # updates without an approval: the analysis' chain check reports them
        pieces = []
        for v in sorted(by_v):
            p = by_v[v]
            if not p.waypoints:
                continue
            t, pts = trajectory_of(p)
            if t.size >= 2 and np.all(np.diff(t) > 0):
                pieces.append((version_effective_s(p), Trajectory(t, pts)))
        if pieces:
            pieces_of[key] = pieces
    bounds = bounds or ConformanceBounds()
    conf = [versioned_conformance(vid, pieces_of[vid], tr, bounds) for vid, tr in tracks.items()
            if vid in pieces_of]
    out["versioned_flights"] = sum(len(pieces_of[v]) > 1 for v in tracks if v in pieces_of)
    out["conformance"] = f3548_statistics(conf).as_dict()
    out["conformance_bounds"] = {"lateral_m": bounds.lateral_m, "vertical_m": bounds.vertical_m,
                                 "time_s": bounds.time_s}
    return out
