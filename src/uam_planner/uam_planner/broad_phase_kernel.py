"""Compiled steps of the broad phase of ``separation`` (numba), beside the numpy steps they
replace (``separation._COMPILED_KEYS`` off: numpy).

Each kernel returns the same arrays as its numpy step, to the last bit: the pieces of
``separation._cut_pieces``, the cell index ranges of ``separation._Grid.ranges``, the packed
(cell, side, item) codes of ``separation._expand_keys``, a stage's merged codes of
``separation._KeyedSets.stage``, the cell coordinates of ``separation._cell_coordinates``, the
cell mates of ``separation._cell_mates`` and the box columns of ``separation._gather_table``.
Why: the numpy steps make a temporary array per operation and repeat every per-piece value per
key; here one loop writes each result once (``test_broad_phase_compiled.py`` compares the two).

The floating-point rules of ``separation_kernel`` hold: the same operations in the same order
as numpy, no fastmath (no reassociation, no fused multiply-add), numpy's minimum / maximum
(``separation_kernel._min`` / ``_max``) and a norm summed as numpy sums it
((x x + y y) + z z). Integer codes are exact; where numpy's sort would order them, the
kernels write them in sorted order (the codes are unique, so any correct order is the same).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit

from .separation_kernel import _JIT, _max, _min

# Above this many pieces per segment the numpy path cuts (its errors and memory use stand)
_MAX_PIECES_PER_SEGMENT = float(1 << 31)


@njit(**_JIT)
def _norm(v, s):
    """``np.linalg.norm(v, axis=1)[s]``: the squares summed as numpy sums them."""
    return math.sqrt((v[s, 0] * v[s, 0] + v[s, 1] * v[s, 1]) + v[s, 2] * v[s, 2])


@njit(**_JIT)
def speeds(v):
    """``np.linalg.norm(v, axis=1)`` of (s, 3) velocities (``separation._grid_size``)."""
    out = np.empty(v.shape[0])
    for s in range(v.shape[0]):
        out[s] = _norm(v, s)
    return out


@njit(**_JIT)
def piece_counts(t0_s, t1_s, v, cell_m, bucket_s):
    """Per segment, its number of pieces (as ``separation._cut_pieces``), and whether every
    count is a finite number the kernels take (else the numpy path cuts)."""
    n = np.empty(t0_s.shape[0], dtype=np.int64)
    for s in range(t0_s.shape[0]):
        dur = t1_s[s] - t0_s[s]
        nf = _max(_max(np.ceil(_norm(v, s) * dur / cell_m), np.ceil(dur / bucket_s)), 1.0)
        if not (nf <= _MAX_PIECES_PER_SEGMENT):
            return n, False
        n[s] = int(nf)
    return n, True


@njit(**_JIT)
def cut_pieces(t0_s, t1_s, p0_m, v, n, half_m, half_z_m):
    """The pieces of ``separation._cut_pieces`` from the segments and their counts ``n``:
    (seg, t0, t1, p0, (xlo, xhi, ylo, yhi, zlo, zhi))."""
    q = 0
    for s in range(n.shape[0]):
        q += n[s]
    seg = np.empty(q, dtype=np.int64)
    t0 = np.empty(q)
    t1 = np.empty(q)
    p0 = np.empty((q, 3))
    box = (np.empty(q), np.empty(q), np.empty(q), np.empty(q), np.empty(q), np.empty(q))
    halves = (half_m, half_m, half_z_m)
    p = 0
    for s in range(n.shape[0]):
        nk = n[s]
        base = t0_s[s]
        step = (t1_s[s] - base) / nk
        for k in range(nk):
            seg[p] = s
            a = base + k * step
            b = t1_s[s] if k + 1 == nk else base + (k + 1) * step
            t0[p] = a
            t1[p] = b
            for d in range(3):
                x = p0_m[s, d] + v[s, d] * (a - base)
                x1 = x + v[s, d] * (b - a)
                p0[p, d] = x
                box[2 * d][p] = _min(x, x1) - halves[d]
                box[2 * d + 1][p] = _max(x, x1) + halves[d]
            p += 1
    return seg, t0, t1, p0, box


@njit(**_JIT)
def _cells(x, origin, size, out):
    """``np.floor((x - origin) / size).astype(np.int64)`` into ``out`` (the grid's checks keep
    every quotient finite and below 2^62)."""
    for k in range(x.shape[0]):
        out[k] = math.floor((x[k] - origin) / size)


@njit(**_JIT)
def _counted(b, x, strict):
    return b < x or (not strict and b == x)


@njit(**_JIT)
def _count_at_most(bounds, x, strict, inv_step):
    """#{b in the sorted ``bounds``: b < x (``strict``) or b <= x}: ``np.searchsorted``'s
    index, side 'left' or 'right', for a finite x (z is in the keys only when every z box is
    finite). Started at the guess (x - bounds[0]) ``inv_step`` and settled by comparisons
    alone (the guess's rounding cannot change the count), so nearly no branch is mispredicted
    as in a bisection."""
    n = bounds.shape[0]
    f = (x - bounds[0]) * inv_step + 1.0
    g = 0 if not f > 0.0 else (n if f > n else int(f))
    while g < n and _counted(bounds[g], x, strict):
        g += 1
    while g > 0 and not _counted(bounds[g - 1], x, strict):
        g -= 1
    return g


@njit(**_JIT)
def cell_ranges(box, t0, t1, grid, z_bounds, use_z):
    """``separation._Grid.ranges``: per piece (ix0, ix1, iy0, iy1, it0, it1, iz0, iz1); the z
    pair only with ``use_z`` (else empty). ``box``: (xlo, xhi, ylo, yhi, zlo, zhi); ``grid``:
    (x0, y0, tt0, cell, bucket)."""
    x0, y0, tt0, cell, bucket = grid
    q = t0.shape[0]
    nz = q if use_z else 0
    r = (np.empty(q, dtype=np.int64), np.empty(q, dtype=np.int64),
         np.empty(q, dtype=np.int64), np.empty(q, dtype=np.int64),
         np.empty(q, dtype=np.int64), np.empty(q, dtype=np.int64),
         np.empty(nz, dtype=np.int64), np.empty(nz, dtype=np.int64))
    _cells(box[0], x0, cell, r[0])
    _cells(box[1], x0, cell, r[1])
    _cells(box[2], y0, cell, r[2])
    _cells(box[3], y0, cell, r[3])
    _cells(t0, tt0, bucket, r[4])
    _cells(t1, tt0, bucket, r[5])
    inv_step = 1.0 / (z_bounds[1] - z_bounds[0]) if z_bounds.shape[0] > 1 else 0.0
    for k in range(nz):
        # the first z cell: #{b <= zlo} - 1, the last: #{b < zhi} - 1 (separation._z_ranges)
        r[6][k] = _count_at_most(z_bounds, box[4][k], False, inv_step) - 1
        r[7][k] = _count_at_most(z_bounds, box[5][k], True, inv_step) - 1
    return r


@njit(**_JIT)
def key_count(r, idx, use_idx, use_z):
    """How many keys the pieces ``idx`` (``use_idx``; else all) with index ranges ``r`` have."""
    m = idx.shape[0] if use_idx else r[0].shape[0]
    total = 0
    for e in range(m):
        k = idx[e] if use_idx else e
        c = (r[1][k] - r[0][k] + 1) * (r[3][k] - r[2][k] + 1) * (r[5][k] - r[4][k] + 1)
        if use_z:
            c *= r[7][k] - r[6][k] + 1
        total += c
    return total


@njit(**_JIT)
def pack_keys(r, idx, use_idx, use_z, side, offset, shape, item_bits, out, pos):
    """``separation._expand_keys`` packed (not widened): the codes
    ((((t ny + y) nx + x) nz + z) 2 + side) << item_bits | item of the pieces ``idx``
    (``use_idx``: item idx[e]; else every piece, item offset + e), written from ``out[pos]``
    in its order (piece by piece; z, then x, then y, then t fastest to slowest). ``shape``:
    (ny, nx, nz). Returns the position after the last code."""
    ny, nx, nz = shape
    ix0, ix1, iy0, iy1, it0, it1, iz0, iz1 = r
    # the code is linear in the coordinates (exact: every code fits int64), so its strides
    # per z, x, y and t cell replace the products per key
    sz = 2 << item_bits
    sx = nz * sz
    sy = nx * sx
    st = ny * sy
    m = idx.shape[0] if use_idx else ix0.shape[0]
    for e in range(m):
        k = idx[e] if use_idx else e
        tail = (side << item_bits) | (k if use_idx else offset + e)
        z0 = iz0[k] * sz if use_z else 0
        z1 = iz1[k] * sz if use_z else 0
        x0 = ix0[k] * sx
        x1 = ix1[k] * sx
        y0 = iy0[k] * sy
        y1 = iy1[k] * sy
        t = it0[k] * st + tail
        t_end = it1[k] * st + tail
        while t <= t_end:
            y = t + y0
            y_end = t + y1
            while y <= y_end:
                x = y + x0
                x_end = y + x1
                while x <= x_end:
                    z = x + z0
                    z_end = x + z1
                    while z <= z_end:
                        out[pos] = z
                        pos += 1
                        z += sz
                    x += sx
                y += sy
            t += st
    return pos


@njit(**_JIT)
def merge_stage(a_codes, b_codes, b_cell, cell_shift):
    """A stage's sorted codes (``separation._KeyedSets.stage``): a's sorted codes and, in each
    cell a's codes touch, b's codes of that cell after them (side 0 < 1), cells ascending.
    ``b_codes`` sorted, ``b_cell`` their cells; a code's cell is code >> ``cell_shift``."""
    out = np.empty(a_codes.shape[0] + b_codes.shape[0], dtype=np.int64)
    n = 0
    j = 0
    i = 0
    na = a_codes.shape[0]
    nb = b_cell.shape[0]
    while i < na:
        c = a_codes[i] >> cell_shift
        while i < na and (a_codes[i] >> cell_shift) == c:
            out[n] = a_codes[i]
            n += 1
            i += 1
        while j < nb and b_cell[j] < c:
            j += 1
        while j < nb and b_cell[j] == c:
            out[n] = b_codes[j]
            n += 1
            j += 1
    return out[:n]


@njit(**_JIT)
def cell_coordinates(codes, item_bits, shape, use_z):
    """``separation._cell_coordinates`` of sorted packed codes: (items, keys, cell_key, kt, ky,
    kx, kz), kz empty unless ``use_z``. ``shape``: (ny, nx, nz)."""
    ny, nx, nz = shape
    m = codes.shape[0]
    mask = (1 << item_bits) - 1
    items = np.empty(m, dtype=np.int64)
    keys = np.empty(m, dtype=np.int64)
    cell_key = np.empty(m, dtype=np.int64)
    kt = np.empty(m, dtype=np.int64)
    ky = np.empty(m, dtype=np.int64)
    kx = np.empty(m, dtype=np.int64)
    kz = np.empty(m if use_z else 0, dtype=np.int64)
    for p in range(m):
        items[p] = codes[p] & mask
        key = codes[p] >> item_bits
        keys[p] = key
        rest = key >> 1
        cell_key[p] = rest
        if p > 0 and rest == cell_key[p - 1]:
            # the entries of one cell lie together: its coordinates once (divisions are slow)
            kt[p] = kt[p - 1]
            ky[p] = ky[p - 1]
            kx[p] = kx[p - 1]
            if use_z:
                kz[p] = kz[p - 1]
            continue
        if use_z:
            kz[p] = rest % nz
            rest //= nz
        kx[p] = rest % nx
        rest //= nx
        ky[p] = rest % ny
        kt[p] = rest // ny
    return items, keys, cell_key, kt, ky, kx, kz


@njit(**_JIT)
def _mates(left_pos, right_first, n_right, n, lo, hi, first, end):
    """Entries lo..hi-1 each with the partners first..end-1: written from position ``n``;
    returns the position after them."""
    for e in range(lo, hi):
        left_pos[n] = e
        right_first[n] = first
        n_right[n] = end - first
        n += 1
    return n


@njit(**_JIT)
def cell_mates(keys, cell_key, single, run_label, use_label):
    """``separation._cell_mates``: (left_pos, right_first, n_right) of the sorted entries with
    partners in their cell; within one set the entries after each (with ``use_label``: after
    its run of equal ``run_label`` in its cell), across two sets a's entries and the b entries
    of their cell."""
    m = keys.shape[0]
    left_pos = np.empty(m, dtype=np.int64)
    right_first = np.empty(m, dtype=np.int64)
    n_right = np.empty(m, dtype=np.int64)
    n = 0
    g = 0
    while g < m:
        end = g + 1
        while end < m and cell_key[end] == cell_key[g]:
            end += 1
        if single:
            p = g
            while p < end:
                run_end = p + 1
                if use_label:
                    while run_end < end and run_label[run_end] == run_label[p]:
                        run_end += 1
                if end > run_end:
                    n = _mates(left_pos, right_first, n_right, n, p, run_end, run_end, end)
                p = run_end
        else:
            first_b = g
            while first_b < end and (keys[first_b] & 1) == 0:
                first_b += 1
            if end > first_b:
                n = _mates(left_pos, right_first, n_right, n, g, first_b, first_b, end)
        g = end
    return left_pos[:n], right_first[:n], n_right[:n]


@njit(**_JIT)
def box_rows(cols):
    """The piece table's eight box columns (t0, t1 swept, xlo, xhi, ylo, yhi, zlo, zhi) as
    the rows of one (q, 8) array: a gather then reads one cache line per piece, not eight."""
    t0, t1, xlo, xhi, ylo, yhi, zlo, zhi = cols
    rows = np.empty((t0.shape[0], 8))
    for k in range(t0.shape[0]):
        rows[k, 0] = t0[k]
        rows[k, 1] = t1[k]
        rows[k, 2] = xlo[k]
        rows[k, 3] = xhi[k]
        rows[k, 4] = ylo[k]
        rows[k, 5] = yhi[k]
        rows[k, 6] = zlo[k]
        rows[k, 7] = zhi[k]
    return rows


@njit(**_JIT)
def gather_boxes(items, rows, labels, use):
    """The columns of ``rows[items]`` (:func:`box_rows`) and ``labels[c][items]`` for the int
    columns (traj, group, iz0) with ``use[c]`` (else empty), in one pass over ``items``: what
    ``separation._gather_table`` gathers column by column."""
    m = items.shape[0]
    out = (np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m), np.empty(m),
           np.empty(m), np.empty(m))
    o0, o1, o2, o3, o4, o5, o6, o7 = out
    traj, group, iz0 = labels
    use_traj, use_group, use_iz0 = use
    lab = (np.empty(m if use_traj else 0, dtype=np.int64),
           np.empty(m if use_group else 0, dtype=np.int64),
           np.empty(m if use_iz0 else 0, dtype=np.int64))
    l0, l1, l2 = lab
    for p in range(m):
        k = items[p]
        o0[p] = rows[k, 0]
        o1[p] = rows[k, 1]
        o2[p] = rows[k, 2]
        o3[p] = rows[k, 3]
        o4[p] = rows[k, 4]
        o5[p] = rows[k, 5]
        o6[p] = rows[k, 6]
        o7[p] = rows[k, 7]
        if use_traj:
            l0[p] = traj[k]
        if use_group:
            l1[p] = group[k]
        if use_iz0:
            l2[p] = iz0[k]
    return out, lab
