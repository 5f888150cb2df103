"""The compiled kernel of the check that decides (``separation.any_conflict``), with numba.

One stage of ``any_conflict`` walks, per left entry of the broad phase (a's pieces, in the
sorted keys' order), the entry's cell mates of b, keeps the pairs the box filter keeps
(``separation._box_filter``: z overlap, canonical z cell, time and x / y overlap in the
canonical cell) and runs the exact measure once per open candidate of a's trajectory, marking a
candidate blocked at its first loss. The numpy path materialises every cell-mate pair, then
every piece pair per candidate, and gathers their values: here nothing is materialised.
``lost_pairs`` does the same for ``separation.conflicting_pairs`` without shifts, ranks or
distances (the conflict graph's call): the box filter per cell-mate pair, one measure per pair
kept, and the codes of the trajectory pairs that lose separation.

The two measures are the numpy kernels (``separation._cpa_block`` for the sphere,
``separation.segment_pair_min_horizontal_m`` for the cylinder) written per pair with the same
floating-point operations in the same order, so every distance, hence every decision, is the
same to the last bit (``test_any_conflict_compiled.py`` compares the two paths). No fastmath:
the compiler must not reassociate or fuse a multiply and an add (an FMA rounds once, numpy
twice). ``cache=True`` keeps the machine code in ``__pycache__``: a process compiles at most
once (seconds), later processes load it (``separation.warm_up`` does it at start-up).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

# numpy semantics for a division by zero (inf / nan, no exception); the kernels divide only
# where the numpy code does, by a non-zero value
_JIT = dict(cache=True, error_model="numpy", nogil=True)


@njit(**_JIT)
def _max(a, b):
    """np.maximum of two floats (the first when equal, the NaN when either is NaN)."""
    return a if (a >= b or a != a) else b


@njit(**_JIT)
def _min(a, b):
    """np.minimum of two floats."""
    return a if (a <= b or a != a) else b


@njit(**_JIT)
def sphere_measure(t0a, t1a, ax, ay, az, vax, vay, vaz, t0b, t1b, bx, by, bz, vbx, vby, vbz):
    """Exact minimum 3D distance [m] of one segment pair over its common time (+inf without
    one): ``separation._cpa_block`` for one pair, operation for operation."""
    lo = _max(t0a, t0b)
    span = _min(t1a, t1b) - lo
    if span < 0.0:
        return math.inf
    da = lo - t0a
    db = lo - t0b
    rx = ((vax * da + ax) - bx) - vbx * db
    ry = ((vay * da + ay) - by) - vby * db
    rz = ((vaz * da + az) - bz) - vbz * db
    dvx = vax - vbx
    dvy = vay - vby
    dvz = vaz - vbz
    a = (dvx * dvx + dvy * dvy) + dvz * dvz
    b = -((rx * dvx + ry * dvy) + rz * dvz)
    tau = b / a if a > 0.0 else 0.0
    hi = _max(span, 0.0)
    # np.clip(tau, 0, hi): max with the lower bound first, then min with the upper one
    tau = tau if (tau > 0.0 or tau != tau) else 0.0
    tau = tau if (tau < hi or tau != tau) else hi
    rx = rx + dvx * tau
    ry = ry + dvy * tau
    rz = rz + dvz * tau
    return math.sqrt((rx * rx + ry * ry) + rz * rz)


@njit(**_JIT)
def cylinder_measure(t0a, t1a, ax, ay, az, vax, vay, vaz, t0b, t1b, bx, by, bz, vbx, vby, vbz,
                     vertical_m, tolerance_s):
    """Exact minimum horizontal distance [m] of one segment pair over the common times when
    the vertical distance is below ``vertical_m`` (+inf if never):
    ``separation.segment_pair_min_horizontal_m`` with ``_vertical_window`` for one pair."""
    lo = _max(t0a, t0b)
    span = _min(t1a, t1b) - lo
    if not span >= 0.0:
        return math.inf
    da = lo - t0a
    db = lo - t0b
    rx = (ax + vax * da) - (bx + vbx * db)
    ry = (ay + vay * da) - (by + vby * db)
    rz = (az + vaz * da) - (bz + vbz * db)
    dx = vax - vbx
    dy = vay - vby
    dz = vaz - vbz
    # the vertical window [wl, wh] of [0, span] where |rz + dz tau| < vertical_m
    if dz != 0.0:
        a = (-vertical_m - rz) / dz
        b = (vertical_m - rz) / dz
        vl = _min(a, b)
        vh = _max(a, b)
        if not (vl < span + tolerance_s and vh > -tolerance_s):
            return math.inf
    else:
        if not abs(rz) < vertical_m:
            return math.inf
        vl = -math.inf
        vh = math.inf
    wl = _max(vl, 0.0)
    wh = _min(vh, span)
    aa = dx * dx + dy * dy
    tau = -(rx * dx + ry * dy) / aa if aa > 0.0 else 0.0
    tau = _min(_max(tau, wl), _max(wh, wl))
    return math.hypot(rx + dx * tau, ry + dy * tau)


@njit(**_JIT)
def _near(lb, rb, lcell, r_iz0, use_z, grid):
    """The box filter of one sorted-entry pair (l, r) (``separation._box_filter``): z boxes
    overlapping with positive length, the canonical z cell (``use_z``), then time, x and y
    overlapping with the low corner of the intersection in l's cell. ``lb``, ``rb``: the two
    entries' (t0, t1 swept, xlo, xhi, ylo, yhi, zlo, zhi); ``lcell``: l's cell (kt, kx, ky, kz)
    and first z cell; ``r_iz0``: r's first z cell; ``grid``: (tt0, bucket, x0, y0, cell).
    Scalars only: an array argument would cost a reference count per pair."""
    t0l, t1l, xlol, xhil, ylol, yhil, zlol, zhil = lb
    t0r, t1r, xlor, xhir, ylor, yhir, zlor, zhir = rb
    kt, kx, ky, kz, iz0 = lcell
    tt0, bucket, x0, y0, cell = grid
    if not _max(zlol, zlor) < _min(zhil, zhir):
        return False
    if use_z and max(iz0, r_iz0) != kz:
        return False
    lo = _max(t0l, t0r)
    if not (lo <= _min(t1l, t1r) and math.floor((lo - tt0) / bucket) == kt):
        return False
    lo = _max(xlol, xlor)
    if not (lo <= _min(xhil, xhir) and math.floor((lo - x0) / cell) == kx):
        return False
    lo = _max(ylol, ylor)
    return lo <= _min(yhil, yhir) and math.floor((lo - y0) / cell) == ky


@njit(**_JIT)
def _measure(a, b, dt, shifted, cylinder, vertical_m, tolerance_s):
    """The model's measure of a's piece (its times + ``dt`` when ``shifted``) against b's;
    ``a``, ``b``: (t0, t1, x, y, z, vx, vy, vz)."""
    t0a, t1a, ax, ay, az, vax, vay, vaz = a
    t0b, t1b, bx, by, bz, vbx, vby, vbz = b
    if shifted:
        t0a += dt
        t1a += dt
    if cylinder:
        return cylinder_measure(t0a, t1a, ax, ay, az, vax, vay, vaz, t0b, t1b, bx, by, bz, vbx,
                                vby, vbz, vertical_m, tolerance_s)
    return sphere_measure(t0a, t1a, ax, ay, az, vax, vay, vaz, t0b, t1b, bx, by, bz, vbx, vby,
                          vbz)


@njit(**_JIT)
def _motion(k, t0, t1, p0, v):
    """Piece k's (t0, t1, x, y, z, vx, vy, vz)."""
    return (t0[k], t1[k], p0[k, 0], p0[k, 1], p0[k, 2], v[k, 0], v[k, 1], v[k, 2])


@njit(**_JIT)
def decide_pairs(left_pos, right_first, n_right, items, traj, box, cells, use_z, group,
                 use_group, grid, pieces, first, shift, shifted, cylinder, separation_m,
                 vertical_m, tolerance_s, blocked, open_count):
    """One stage of ``any_conflict``: per left entry e (sorted keys' order) whose trajectory
    ta = traj[items[left_pos[e]]] has an open candidate, per cell mate r of the
    ``n_right[e]`` from ``right_first[e]`` that passes the box filter (and has another group,
    with ``use_group``), per candidate c of ta not yet blocked (``first[ta] .. first[ta+1]-1``
    flown ``shift[c]`` s later when ``shifted``, else c = ta): c is blocked when the measure is
    below ``separation_m`` (strict). ``box``: (t0, t1 swept, xlo, xhi, ylo, yhi, zlo, zhi) per
    sorted entry; ``cells``: (kt, kx, ky, kz, iz0) per sorted entry (kz, iz0 read only with
    ``use_z``); ``pieces``: (t0, t1, p0, v) by item id. Updates ``blocked`` and
    ``open_count`` (open candidates per trajectory of a) in place; returns the number of exact
    measures taken."""
    t0, t1, xlo, xhi, ylo, yhi, zlo, zhi = box
    kt, kx, ky, kz, iz0 = cells
    pt0, pt1, pp0, pv = pieces
    n_exact = 0
    for e in range(left_pos.shape[0]):
        lp = left_pos[e]
        i = items[lp]
        ta = traj[i]
        if open_count[ta] <= 0:
            continue
        c0 = first[ta] if shifted else ta
        c1 = first[ta + 1] if shifted else ta + 1
        lb = (t0[lp], t1[lp], xlo[lp], xhi[lp], ylo[lp], yhi[lp], zlo[lp], zhi[lp])
        lcell = (kt[lp], kx[lp], ky[lp], kz[lp] if use_z else 0, iz0[lp] if use_z else 0)
        a = _motion(i, pt0, pt1, pp0, pv)
        for r in range(right_first[e], right_first[e] + n_right[e]):
            if use_group and group[lp] == group[r]:
                continue
            rb = (t0[r], t1[r], xlo[r], xhi[r], ylo[r], yhi[r], zlo[r], zhi[r])
            if not _near(lb, rb, lcell, iz0[r] if use_z else 0, use_z, grid):
                continue
            b = _motion(items[r], pt0, pt1, pp0, pv)
            for c in range(c0, c1):
                if blocked[c]:
                    continue
                n_exact += 1
                d = _measure(a, b, shift[c] if shifted else 0.0, shifted, cylinder, vertical_m,
                             tolerance_s)
                if d < separation_m:
                    blocked[c] = True
                    open_count[ta] -= 1
            if open_count[ta] <= 0:
                break
    return n_exact


@njit(**_JIT)
def _push(out, n, code):
    """``out`` with ``code`` at position n, doubled first when full."""
    if n == out.shape[0]:
        grown = np.empty(2 * n, dtype=np.int64)
        grown[:n] = out
        out = grown
    out[n] = code
    return out


@njit(**_JIT)
def _pair_code(ta, tb, single, nbt):
    """The code ``a * nbt + b`` of a trajectory pair: (min, max) within one set."""
    if single and tb < ta:
        return tb * nbt + ta
    return ta * nbt + tb


@njit(**_JIT)
def lost_pairs(left_pos, right_first, n_right, items, traj, box, cells, use_z, group, drop,
               grid, pieces, single, cylinder, separation_m, vertical_m, tolerance_s, nbt):
    """``conflicting_pairs`` without shifts, ranks or distances: per left entry e (sorted
    keys' order), per cell mate r of the ``n_right[e]`` from ``right_first[e]`` that passes
    the box filter, the measure of e's piece (first argument) against r's; a pair below
    ``separation_m`` (strict) records its trajectories' code (:func:`_pair_code`).
    ``drop``: which pairs the box filter drops first: 0 none; within one set, 1 the pairs of
    one trajectory, 2 also those of one group (``group`` by trajectory); across two sets, 3
    the pairs of one group (``group`` by sorted entry). A cell mate whose pair is
    the last one recorded is not measured again (the set is the same). ``box``, ``cells``,
    ``grid``, ``pieces``: as in :func:`decide_pairs`. Returns (codes with repeats, measures
    taken)."""
    t0, t1, xlo, xhi, ylo, yhi, zlo, zhi = box
    kt, kx, ky, kz, iz0 = cells
    pt0, pt1, pp0, pv = pieces
    out = np.empty(1024, dtype=np.int64)
    n = 0
    n_exact = 0
    last = -1
    for e in range(left_pos.shape[0]):
        lp = left_pos[e]
        i = items[lp]
        ta = traj[i]
        lb = (t0[lp], t1[lp], xlo[lp], xhi[lp], ylo[lp], yhi[lp], zlo[lp], zhi[lp])
        lcell = (kt[lp], kx[lp], ky[lp], kz[lp] if use_z else 0, iz0[lp] if use_z else 0)
        a = _motion(i, pt0, pt1, pp0, pv)
        for r in range(right_first[e], right_first[e] + n_right[e]):
            j = items[r]
            tb = traj[j]
            if (drop == 1 or drop == 2) and ta == tb:
                continue
            if (drop == 2 and group[ta] == group[tb]) or (drop == 3 and group[lp] == group[r]):
                continue
            code = _pair_code(ta, tb, single, nbt)
            if code == last:
                continue
            rb = (t0[r], t1[r], xlo[r], xhi[r], ylo[r], yhi[r], zlo[r], zhi[r])
            if not _near(lb, rb, lcell, iz0[r] if use_z else 0, use_z, grid):
                continue
            n_exact += 1
            d = _measure(a, _motion(j, pt0, pt1, pp0, pv), 0.0, False, cylinder, vertical_m,
                         tolerance_s)
            if d < separation_m:
                out = _push(out, n, code)
                n += 1
                last = code
    return out[:n], n_exact
