"""The safety audit of what flew: exact closest approach between flown tracks.

A flown track is known at samples (the fleet states of a recording, every ``step_s``; or the
disturbance model's samples in process) and taken as linear between them: the closest approach
of every pair of such tracks is computed exactly by the same sweep as the plans' audit
(:func:`uam_sim.audit.separation.sweep_audit`: every pair of time-overlapping straight pieces, closest
approach clamped to the overlap).

The sampling error, bounded **per axis and per piece**. Between two
samples ``dt`` apart the true position differs from the chord (the linear interpolation) by
``f(t) = integral of (v - mean v)``, zero at both samples; if the velocity stays in a set of
diameter ``D`` on that interval, ``|f(t)| <= D dt / 4`` (the worst case: one velocity for a
share ``l`` of ``dt``, another for the rest, ``|f| = l (1 - l) D dt``). Applied to the horizontal
velocity (``D_h``) and to the vertical speed (its range ``R_v``) separately:

- a piece whose samples both lie on the flight's plan (every version as flown, to 1 mm: what
  the simulator flies) takes ``D_h`` and ``R_v`` from the plan's velocities over that interval:
  **0 on a straight level piece** (cruise), ``R_v dt / 4`` at the top of a climb (5 m/s, 1 s:
  1.25 m), the change of heading at a corridor node for ``D_h``. The plan is the assumption
  here (that the aircraft flies its plan's profile between two samples that lie on it);
- any other piece (no plan, or a sample off it) takes the global bound: a velocity anywhere in
  the ball of the largest sampled speed, per axis (``D = 2 v``: ``v_h dt / 2``, ``v_z dt / 2``;
  ``v_h``, ``v_z`` the largest horizontal and vertical chord speeds, and the plan's).

The error at the fraction ``l`` of a piece is at most ``l (1 - l) D dt``: 0 at both samples (a
sample is where the aircraft was) and the piece's bound ``D dt / 4`` only at its middle. A
pair's bound at an instant is the sum of the two aircraft's there, per axis. With those bounds a
pair is a **loss** when even the most favourable motion within them loses separation (the chords
closer than ``H - e_h`` while vertically closer than ``V - e_v``; the sphere: closer than the
minimum minus the 3D bound): proven by the samples, and at a sample instant of both aircraft
simply by the samples. It is a **possible loss** when the chords come within ``H + e_h`` while
within ``V + e_v``: the samples cannot exclude it; a possible loss that is not a loss is
*unresolved*, never cleared.

**The simulator's own motion.** A fleet state carries each aircraft's velocity, which the
simulator flies from that sample until its path's next vertex (``Fleet.sample``). Where the
reported velocity equals the chord to the next sample (to ``STRAIGHT_MPS``) no single vertex
lies inside the piece, so the aircraft flew the chord: the piece takes no bound (exact unless
two or more vertices inside one piece average exactly to the first velocity). The disturbance
model's tracks are linear between their samples, so a disturbed run's pieces are straight but
where a version or the landing falls inside a step.

The chords' own losses
(``interpolated_losses``) are reported too: the linear interpolation cuts the corner at the top
of each climb and descent, so two aircraft at adjacent levels (exactly V apart) seem to lose
separation there while the aircraft, on their plans, never do (a city run's 6 "flown losses",
e.g. at t = 1,671 s: one aircraft levelling off at 120 m 0.17 s after a sample,
the chord below 120 m until the next one, 86.5 m from one cruising at 90 m).

Without plans (``plans=None``) every piece takes the global bound, and ``losses`` are the chords'
(the tracks taken as the motion: in process the simulated aircraft flies exactly the
interpolation of the model's samples, so they are exact there).
"""

from __future__ import annotations

import math
from collections import defaultdict
from typing import Iterable, Mapping

import numpy as np

from uam_planner.separation import SeparationModel, as_separation_model
from uam_planner.trajectory import Trajectory

from .separation import TIE_RELATIVE, sweep_audit, sweep_audits

OUTCOME_APPROVED = 0  # uam_msgs/FlightPlan.OUTCOME_APPROVED


def tracks_from_samples(samples: Iterable[tuple]) -> dict[str, Trajectory]:
    """Per vehicle, its track from fleet samples ``(t_s, vehicle_ids, positions (v, 3))`` in time
    order; a vehicle seen at one sample only has no track (nothing to interpolate)."""
    return tracks_and_velocities(samples)[0]


def tracks_and_velocities(samples: Iterable[tuple]) -> tuple[dict[str, Trajectory], dict[str, np.ndarray]]:
    """:func:`tracks_from_samples`, and per vehicle the velocity reported at each of its samples
    (k, 3) where the samples carry one ``(t_s, vehicle_ids, positions, velocities)``."""
    times: dict = defaultdict(list)
    pts: dict = defaultdict(list)
    vels: dict = defaultdict(list)
    for sample in samples:
        t, ids, pos = sample[:3]
        vel = np.asarray(sample[3], dtype=np.float64).reshape(-1, 3) if len(sample) > 3 else None
        for n, (vid, p) in enumerate(zip(ids, np.asarray(pos, dtype=np.float64).reshape(-1, 3))):
            if times[vid] and t <= times[vid][-1]:
                continue  # a repeated sample (a duplicate message)
            times[vid].append(float(t))
            pts[vid].append(p)
            if vel is not None:
                vels[vid].append(vel[n])
    keep = [vid for vid in sorted(times) if len(times[vid]) >= 2]
    return ({vid: Trajectory(np.array(times[vid]), np.array(pts[vid])) for vid in keep},
            {vid: np.array(vels[vid]) for vid in keep if len(vels[vid]) == len(times[vid])})


def max_speed_mps(tracks: Iterable[Trajectory]) -> float:
    """The largest speed of any piece of the tracks [m/s]."""
    best = 0.0
    for tr in tracks:
        _t0, _t1, _p0, v = tr.segments()
        if v.shape[0]:
            best = max(best, float(np.sqrt(np.square(v).sum(axis=1)).max()))
    return best


def _axis_speeds(tracks: Iterable[Trajectory]) -> tuple[float, float]:
    """The largest horizontal and vertical speed of any piece of the tracks [m/s]."""
    vh = vz = 0.0
    for tr in tracks:
        _t0, _t1, _p0, v = tr.segments()
        if v.shape[0]:
            vh = max(vh, float(np.sqrt(np.square(v[:, :2]).sum(axis=1)).max()))
            vz = max(vz, float(np.abs(v[:, 2]).max()))
    return vh, vz


#: pairs listed per kind in the result
LISTED = 20

#: a sample within this of its plan's position counts as on the plan [m]
ON_PLAN_M = 1e-3


#: a piece flew straight when the velocity reported at its first sample is its chord's to this [m/s]
STRAIGHT_MPS = 1e-6


def straight_pieces(track: Trajectory, velocities_mps: np.ndarray | None) -> np.ndarray:
    """Per piece of ``track``: whether the simulator's own motion over it is the chord. The
    simulator reports at each sample the velocity it flies from that sample until its next
    vertex (``uam_sim.world.fleet.Fleet.sample``); where that velocity is the chord's (to
    STRAIGHT_MPS) the next vertex is not inside the piece (one vertex inside would change the
    average velocity), so the aircraft flew the chord. All False without velocities."""
    n = track.times_s.size - 1
    if velocities_mps is None or velocities_mps.shape[0] != track.times_s.size or n < 1:
        return np.zeros(max(n, 0), dtype=bool)
    _t0, _t1, _p0, chord = track.segments()
    if chord.shape[0] != n:
        return np.zeros(n, dtype=bool)
    return np.abs(velocities_mps[:-1] - chord).max(axis=1) <= STRAIGHT_MPS


#: a vertex found between two samples must reproduce the next sample to this [m]
VERTEX_M = 1e-6


def _one_turn(dt: float, p0: np.ndarray, p1: np.ndarray, v0: np.ndarray, v1: np.ndarray) -> float | None:
    """The instant ``tau`` into a piece of one turn from ``v0`` to ``v1`` that leads from ``p0``
    to ``p1`` (``p0 + v0 tau + v1 (dt - tau) = p1`` in every axis, to VERTEX_M), or None."""
    dv = v0 - v1
    rhs = p1 - p0 - v1 * dt
    den = float(dv @ dv)
    if den <= 0:
        return None
    tau = float(dv @ rhs) / den
    return tau if float(np.abs(dv * tau - rhs).max()) <= VERTEX_M else None


def simulator_motion(track: Trajectory, velocities_mps: np.ndarray | None) -> tuple[Trajectory, np.ndarray]:
    """The track as the simulator flew it, and per piece of it whether that piece is exact.

    A piece flew straight (:func:`straight_pieces`), or turned once: with ``v0`` the velocity
    reported at its first sample (flown until the path's next vertex) and ``v1`` the one at its
    last (flown since the path's last vertex), one vertex at ``tau`` into the piece fits when
    ``p0 + v0 tau + v1 (dt - tau) = p1``; where that holds in all three axes (to VERTEX_M) with
    0 < tau < dt, the vertex ``p0 + v0 tau`` is inserted and both parts are exact. Any other
    piece (two vertices or more in one step, no velocities) is kept, not exact."""
    n = track.times_s.size - 1
    straight = straight_pieces(track, velocities_mps)
    if n < 1 or velocities_mps is None or straight.all() or velocities_mps.shape[0] != n + 1:
        return track, straight
    t, p, v = track.times_s, track.points_m, velocities_mps
    times, points, exact = [t[:1]], [p[:1]], []
    for k in range(n):
        piece_exact = bool(straight[k])
        if not piece_exact:
            tau = _one_turn(t[k + 1] - t[k], p[k], p[k + 1], v[k], v[k + 1])
            if tau is not None and t[k] < t[k] + tau < t[k + 1]:
                times.append(np.array([t[k] + tau]))
                points.append((p[k] + v[k] * tau)[None, :])
                exact.append(True)
                piece_exact = True
        times.append(t[k + 1:k + 2])
        points.append(p[k + 1:k + 2])
        exact.append(piece_exact)
    return Trajectory(np.concatenate(times), np.vstack(points)), np.array(exact, dtype=bool)


def piece_bounds(track: Trajectory, plan: Trajectory | None, vh: float,
                 vz: float, exact: np.ndarray | None = None) -> tuple[np.ndarray, np.ndarray, int]:
    """Per piece of ``track``: the bound of one aircraft's horizontal and vertical distance from
    the chord (see the module docstring): 0 where the piece is ``exact`` (the simulator's own
    motion, :func:`simulator_motion`); from the plan's velocities where both samples lie on
    ``plan``; else ``vh dt / 2`` and ``vz dt / 2``; and how many samples are off the plan (by more
    than ON_PLAN_M, or outside its times; 0 without a plan)."""
    eh, ev, off = _plan_bounds(track, plan, vh, vz)
    if exact is not None:
        eh[exact] = 0.0
        ev[exact] = 0.0
    return eh, ev, off


def _plan_bounds(track: Trajectory, plan: Trajectory | None, vh: float,
                 vz: float) -> tuple[np.ndarray, np.ndarray, int]:
    """:func:`piece_bounds` but for the exact pieces (new arrays, the caller's to change)."""
    t = track.times_s
    dt = np.diff(t)
    eh, ev = vh * dt / 2.0, vz * dt / 2.0
    if plan is None or t.size < 2:
        return eh, ev, 0
    pt = plan.times_s
    inside = (t >= pt[0] - 1e-9) & (t <= pt[-1] + 1e-9)
    q = plan.position_at(np.clip(t, pt[0], pt[-1]), clamp=True)
    on = inside & (np.sqrt(np.square(q - track.points_m).sum(axis=1)) <= ON_PLAN_M)
    ok = on[:-1] & on[1:]
    off = int(t.size - on.sum())
    if not ok.any():
        return eh, ev, off
    _a, _b, _p, v = plan.segments()
    first = np.clip(np.searchsorted(pt, t[:-1], side="right") - 1, 0, v.shape[0] - 1)
    last = np.clip(np.searchsorted(pt, t[1:], side="left") - 1, 0, v.shape[0] - 1)
    one = ok & (last <= first)
    eh[one] = 0.0
    ev[one] = 0.0
    for k in np.flatnonzero(ok & (last > first)).tolist():
        w = v[first[k]:last[k] + 1]
        dh = w[:, None, :2] - w[None, :, :2]
        eh[k] = float(np.sqrt(np.square(dh).sum(axis=2)).max()) * dt[k] / 4.0
        ev[k] = float(w[:, 2].max() - w[:, 2].min()) * dt[k] / 4.0
    return eh, ev, off


def _bound_share(track: Trajectory, piece: np.ndarray, t0: np.ndarray, t1: np.ndarray) -> np.ndarray:
    """The largest share of its piece's bound that ``track``'s sampling error can reach on
    [t0, t1] inside ``piece``: the error at the fraction l of a piece is at most 4 l (1 - l)
    times the piece's bound (module docstring: ``l (1 - l) D dt`` of ``D dt / 4``), so 0 at a
    sample and 1 only at the middle of the piece."""
    ts = track.times_s
    start, span = ts[piece], ts[piece + 1] - ts[piece]
    with np.errstate(divide="ignore", invalid="ignore"):
        l0 = np.where(span > 0, (t0 - start) / span, 0.0)
        l1 = np.where(span > 0, (t1 - start) / span, 0.0)
    m = np.clip(0.5, np.clip(l0, 0.0, 1.0), np.clip(l1, 0.0, 1.0))
    return 4.0 * m * (1.0 - m)


def _pair_within(a: Trajectory, ea: tuple, b: Trajectory, eb: tuple, model, sign: float):
    """Whether two tracks come within the minimum widened (``sign`` +1) or shrunk (-1) by their
    per-piece bounds: (the smallest distance where they do, horizontal for the cylinder, or
    inf; its time). Exact on every sub-interval of the merged sample times (both linear), each
    taking the largest bound the two tracks reach on it, and at every sample instant of either
    track, where that track's bound is 0 (a sample is where the aircraft was)."""
    lo, hi = max(a.times_s[0], b.times_s[0]), min(a.times_s[-1], b.times_s[-1])
    if hi < lo:
        return math.inf, math.nan
    g = np.unique(np.concatenate([a.times_s, b.times_s, [lo, hi]]))
    g = g[(g >= lo) & (g <= hi)]
    # the sub-intervals between merged sample times, then each merged instant alone
    t0 = np.concatenate([g[:-1], g])
    t1 = np.concatenate([g[1:], g])
    mid = 0.5 * (t0 + t1)
    ia = np.clip(np.searchsorted(a.times_s, mid, side="right") - 1, 0, a.times_s.size - 2)
    ib = np.clip(np.searchsorted(b.times_s, mid, side="right") - 1, 0, b.times_s.size - 2)
    fa, fb = _bound_share(a, ia, t0, t1), _bound_share(b, ib, t0, t1)
    eh = ea[0][ia] * fa + eb[0][ib] * fb
    ev = ea[1][ia] * fa + eb[1][ib] * fb
    r0 = a.position_at(t0, clamp=True) - b.position_at(t0, clamp=True)
    r1 = a.position_at(t1, clamp=True) - b.position_at(t1, clamp=True)
    d = r1 - r0
    H, V = model.separation_m, model.vertical_separation_m
    if model.kind == "cylinder":
        ch, cv = H + sign * eh, V + sign * ev
        # the s in [0, 1] where |dz(s)| < cv (a tie, exactly cv, is separated)
        z0, dz = r0[:, 2], d[:, 2]
        cvt = cv * (1.0 - TIE_RELATIVE)
        with np.errstate(divide="ignore", invalid="ignore"):
            sa = (-cvt - z0) / dz
            sb = (cvt - z0) / dz
        s_lo = np.where(dz != 0, np.minimum(sa, sb), np.where(np.abs(z0) < cvt, 0.0, 1.0))
        s_hi = np.where(dz != 0, np.maximum(sa, sb), np.where(np.abs(z0) < cvt, 1.0, 0.0))
        s_lo, s_hi = np.maximum(s_lo, 0.0), np.minimum(s_hi, 1.0)
        live = (cv > 0) & ((s_hi > s_lo) | ((dz == 0) & (np.abs(z0) < cvt)))
        p0, dp = r0[:, :2], d[:, :2]
        limit = ch
    else:
        live = np.ones(t0.size, dtype=bool)
        s_lo, s_hi = np.zeros(t0.size), np.ones(t0.size)
        p0, dp = r0, d
        limit = H + sign * np.sqrt(np.square(eh) + np.square(ev))
    A = np.square(dp).sum(axis=1)
    B = (p0 * dp).sum(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        s_star = np.where(A > 0, -B / A, 0.0)
    s_star = np.clip(s_star, s_lo, s_hi)
    dist = np.sqrt(np.square(p0 + s_star[:, None] * dp).sum(axis=1))
    hit = live & (limit > 0) & (dist < limit * (1.0 - TIE_RELATIVE))
    if not hit.any():
        return math.inf, math.nan
    k = int(np.flatnonzero(hit)[np.argmin(dist[hit])])
    return float(dist[k]), float(t0[k] + s_star[k] * (t1[k] - t0[k]))


def _pieces(tracks: Mapping[str, Trajectory], ids: list, velocities) -> tuple[dict, dict]:
    """The tracks to audit (the simulator's motion when ``velocities`` are given) and per track
    which of its pieces are exact (flown straight, or one turn rebuilt; none without them)."""
    if velocities:
        motion = {i: simulator_motion(tracks[i], velocities.get(i)) for i in ids}
        return {i: motion[i][0] for i in ids}, {i: motion[i][1] for i in ids}
    return tracks, {i: np.zeros(max(tracks[i].times_s.size - 1, 0), dtype=bool) for i in ids}


def _widened(model: SeparationModel, bh: float, bv: float) -> SeparationModel:
    """The minimum widened by the largest pair bounds, horizontal ``bh`` and vertical ``bv`` [m]:
    for the cylinder each axis by its own, for the sphere the radius by their hypotenuse."""
    if model.kind == "cylinder":
        return SeparationModel(model.kind, model.separation_m + bh, model.vertical_separation_m + bv)
    return SeparationModel(model.kind, model.separation_m + math.hypot(bh, bv), model.vertical_separation_m)


def _pairs_within(pairs, tracks: Mapping, bounds: dict, model: SeparationModel, sign: float) -> list:
    """Of the listed ``pairs`` [a, b, ...], those whose bounded pieces come within the minimum
    (``sign`` +1: possibly, -1: provably), each [a, b, distance m, t s]."""
    found = []
    for a, b, _d, _t in pairs:
        d, t = _pair_within(tracks[a], bounds[a], tracks[b], bounds[b], model, sign)
        if math.isfinite(d):
            found.append([a, b, d, t])
    return found


def _with_plans(out: dict, proven: list, bounds: dict, plans: Mapping, ids: list, exact: dict) -> None:
    """Into ``out``: the proven losses in place of the chords' own (kept as interpolated_*), the
    samples off their plan, the tracks without a plan and the counts of exact pieces."""
    out["interpolated_losses"], out["interpolated_loss_pairs"] = out["losses"], out["loss_pairs"][:LISTED]
    out["losses"], out["loss_pairs"] = len(proven), sorted(proven, key=lambda x: x[2])
    # samples not on the plan flown (what the simulator flies: 0 without disturbances)
    out["samples_off_plan"] = sum(b[2] for i, b in bounds.items() if i in plans)
    out["tracks_without_plan"] = sum(i not in plans for i in ids)
    # pieces whose bound is 0 on both axes (on the plan, straight and level or one segment)
    out["pieces_exact"] = sum(int(((b[0] == 0) & (b[1] == 0)).sum()) for b in bounds.values())
    out["pieces"] = sum(int(b[0].size) for b in bounds.values())
    # pieces exact from the simulator's reported motion (flown straight, or one turn rebuilt)
    out["pieces_straight"] = sum(int(s.sum()) for s in exact.values())


def flown_audit(tracks: Mapping[str, Trajectory], separation, sample_step_s: float | None = None,
                prune: bool = True, plans: Mapping[str, Trajectory] | None = None,
                velocities: Mapping[str, np.ndarray] | None = None) -> dict:
    """Losses of separation in what flew.

    Args:
        tracks: vehicle id -> flown track (linear between samples).
        separation: the true minimum (a number: the sphere; or a SeparationModel), never a
            planning buffer.
        sample_step_s: the largest time between two samples of a track; None = the tracks are
            the motion itself (no sampling error).
        prune: False checks every time-overlapping pair of pieces (the slow reference; the
            result is the same, ``uam_planner.audit.sweep_audits``).
        plans: vehicle id -> its plan as flown (every version from its instant): the per-piece
            bounds of the module docstring, and ``losses`` are then those the samples prove.
        velocities: vehicle id -> the velocity reported at each sample of its track: the
            tracks become the simulator's motion (:func:`simulator_motion`), whose exact pieces
            take no bound.
    Returns: the :func:`uam_sim.audit.separation.sweep_audit` dict of the interpolated tracks, plus
    ``what`` ("flown"), ``sampling_bound_m`` / ``sampling_bound_v_m`` (the largest pair bound,
    horizontal and vertical; 0 without sampling), ``possible_losses`` (pairs the samples cannot
    clear), ``max_speed_mps``; with ``plans``: ``losses`` / ``loss_pairs`` the proven ones,
    ``interpolated_losses`` / ``interpolated_loss_pairs`` the chords' own, ``samples_off_plan``
    (samples more than 1 mm from their plan as flown), ``tracks_without_plan``, ``pieces`` and
    ``pieces_exact`` (bound 0 on both axes).
    """
    model = as_separation_model(separation)
    ids = sorted(tracks)
    trajs = [tracks[i] for i in ids]
    vmax = max_speed_mps(trajs)
    vh, vz = _axis_speeds(trajs)
    if plans:
        ph, pz = _axis_speeds([plans[i] for i in ids if i in plans])
        vh, vz = max(vh, ph), max(vz, pz)
    if not sample_step_s or not trajs:
        out = sweep_audit(trajs, model, labels=ids, prune=prune)
        out.update({"what": "flown", "sampling_bound_m": 0.0, "sampling_bound_v_m": 0.0,
                    "possible_losses": out["losses"], "unresolved": 0, "unresolved_pairs": [],
                    "max_speed_mps": vmax})
        return out
    tracks, exact = _pieces(tracks, ids, velocities)
    trajs = [tracks[i] for i in ids]
    bounds = {i: piece_bounds(tracks[i], (plans or {}).get(i), vh, vz, exact[i]) for i in ids}
    bh = 2.0 * max((float(b[0].max()) for b in bounds.values() if b[0].size), default=0.0)
    bv = 2.0 * max((float(b[1].max()) for b in bounds.values() if b[1].size), default=0.0)
    # one candidate search for both minima (uam_planner.audit.sweep_audits): the chords in the
    # minimum, and in the minimum widened by the largest pair bound (a superset of the possible)
    out, wide_out = sweep_audits(trajs, [model, _widened(model, bh, bv)], labels=ids, prune=prune,
                                 max_listed=None)
    possible = _pairs_within(wide_out["loss_pairs"], tracks, bounds, model, +1.0)
    if plans is not None:
        proven = _pairs_within(out["loss_pairs"], tracks, bounds, model, -1.0)
        _with_plans(out, proven, bounds, plans, ids, exact)
    proven_pairs = {(a, b) for a, b, _d, _t in out["loss_pairs"]}
    unresolved = sorted((x for x in possible if (x[0], x[1]) not in proven_pairs), key=lambda x: x[2])
    out["unresolved"], out["unresolved_pairs"] = len(unresolved), unresolved[:LISTED]
    out["loss_pairs"] = out["loss_pairs"][:LISTED]
    out.update({"what": "flown", "sampling_bound_m": bh, "sampling_bound_v_m": bv,
                "possible_losses": len(possible), "possible_loss_pairs": sorted(possible, key=lambda x: x[2])[:LISTED],
                "max_speed_mps": vmax})
    return out


def _record_of_plans(plans):
    """The run's record (:class:`uam_sim.audit.record.RunRecord`) of FlightPlan messages, every
    version: a vehicle flies the plans of its ``operator/request`` id, the first message of each
    version counts."""
    from uam_contract.wire import scoped_id

    from .flown_audit import plan_version
    from .record import RunRecord
    approved, updates = [], {}
    for p in plans:
        key = scoped_id(p.operator_id, p.request_id) if p.operator_id else str(p.request_id)
        if plan_version(p) == 1:
            if int(p.outcome) == OUTCOME_APPROVED and all(k != key for k, _ in approved):
                approved.append((key, p))
        else:
            updates.setdefault(key, {}).setdefault(plan_version(p), p)
    return RunRecord.from_plans(approved, updates)


def recording_flown(path, separation, bounds=None, plans=None, prune: bool = True, record=None) -> dict:
    """What flew in a recording: the flown tracks from every ``uam/fleet_state`` (positions read
    straight from the CDR), their exact audit in the true minimum (:func:`flown_audit`, sampling
    step = the largest gap between fleet states), and the F3548 conformance of each flown track
    with its plan: each sample with the plan version in force at that instant (version 1 from
    the departure, each later version from its ``effective_time``;
    ``uam_sim.world.conformance.versioned_conformance``). ``plans``: the FlightPlan messages, every
    version (else read from ``uam/flight_plans``); a vehicle flies the plans of its
    ``operator/request`` id.
    ``prune``: as :func:`flown_audit` (False: the slow reference sweep, the same result).
    ``record``: the run's :class:`uam_sim.audit.record.RunRecord` (the analysis passes its own;
    else built from ``plans``). Returns {} when the recording holds no fleet positions."""
    from uam_contract import names
    from uam_contract.names import resolved
    from uam_contract.stamps import stamp_s

    from ..recording.cdr import fleet_state_digest
    from ..world.conformance import ConformanceBounds, f3548_statistics, versioned_conformance
    from ..recording.mcap_reader import deserialize, is_complete, read_messages, read_messages_tolerant

    fleet_topic, plan_topic = resolved(names.TOPIC_FLEET), resolved(names.TOPIC_PLANS)
    topics = (fleet_topic,) if plans is not None or record is not None else (fleet_topic, plan_topic)
    records = (read_messages(path, topics=list(topics)) if is_complete(path)
               else sorted((r for r in read_messages_tolerant(path) if r.topic in topics),
                           key=lambda r: r.log_time_ns))
    samples, found_plans = [], []
    for rec in records:
        if rec.topic == fleet_topic:
            d = fleet_state_digest(rec.data, positions=True)
            if d is None:  # big-endian data: decode in full
                msg = deserialize(rec)
                ids = [v.vehicle_id for v in msg.vehicles]
                pos = np.array([(v.position.x, v.position.y, v.position.z) for v in msg.vehicles]).reshape(-1, 3)
                vel = np.array([(v.velocity.x, v.velocity.y, v.velocity.z) for v in msg.vehicles]).reshape(-1, 3)
                samples.append((stamp_s(msg.header.stamp), ids, pos, vel))
            else:
                samples.append((stamp_s(d.header.stamp), d.vehicle_ids, d.positions_m, d.velocities_mps))
        else:
            found_plans.append(deserialize(rec))
    if not samples:
        return {}
    samples.sort(key=lambda s: s[0])
    ts = np.array([s[0] for s in samples])
    step = float(np.max(np.diff(ts))) if ts.size > 1 else 0.0
    tracks, velocities = tracks_and_velocities(samples)
    if record is None:
        record = _record_of_plans(plans if plans is not None else found_plans)
    # each flown track against its flight's plan in force (uam_sim.audit.record): the sampling
    # bound from the plan flown there, the conformance with the version in force at each sample
    # (version 1 from the departure, version n + 1 from the instant it took effect)
    flights = record.by_key()
    flown_plans = record.paths()
    pieces_of = {key: pieces for key, f in flights.items() if (pieces := f.pieces())}
    out = flown_audit(tracks, separation, sample_step_s=step, prune=prune, plans=flown_plans,
                      velocities=velocities)
    out["sample_step_s"] = step
    bounds = bounds or ConformanceBounds()
    conf = [versioned_conformance(vid, pieces_of[vid], tr, bounds) for vid, tr in tracks.items()
            if vid in pieces_of]
    out["versioned_flights"] = sum(len(pieces_of[v]) > 1 for v in tracks if v in pieces_of)
    out["conformance"] = f3548_statistics(conf).as_dict()
    out["conformance_bounds"] = {"lateral_m": bounds.lateral_m, "vertical_m": bounds.vertical_m,
                                 "time_s": bounds.time_s}
    return out
