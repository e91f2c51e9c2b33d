"""CPU backend of the EAW filter: the à-trous iterations on the padded planes of :mod:`.layout`.

A frame costs :func:`.layout.prepare` (two parallel passes over the inputs) and one parallel
:func:`atrous_pass` per iteration, the last of which writes the output frame.

Symmetry. The edge-stopping weight of a pair is symmetric: each is computed once, for the 12
forward taps, and kept (times the kernel tap) in a ring buffer for the pixels that see the pair
backwards.

Row order. At hole spacing ``s`` a row meets only the rows ``s`` and ``2 s`` away, so the rows
are visited class by class of ``y mod s`` (:func:`row_order`): row ``y`` then needs the weights
of the two rows visited just before it, and the ring holds 3 rows per tap at every ``s``
(``12 x 3`` rows: a few hundred KiB, resident in the core's L2 cache) instead of ``2 s + 1``.

Vectorization. Each pixel loop runs over a row, branch-free, with all 12 taps in its body: a
pixel's own values are loaded once for its 12 pair weights and once for its 24 taps, and the
sums stay in registers. LLVM vectorizes the loops (contiguous unsigned indices, no libm call:
:func:`harness.kernels.exp2_minus`); the parallel loop body creates no array views, so Numba marks
the arrays ``noalias`` and LLVM needs no run-time aliasing tests. The packed values are bounded
(:mod:`.layout`), so the loops hold no overflow guard.
"""

from __future__ import annotations

import time

import numpy as np
from numba import get_num_threads, njit, prange, uint64

from harness import kernels

from .layout import A_N_MIN, ACTIVE, MAX_RUNS, Buffers, prepare, unpack_row

#: the forward half of the 5x5 taps as (dx, dy) in hole-spacing units: dy > 0, or dy = 0 and
#: dx > 0 (row-major kernel indices 13 to 24)
FORWARD = ((1, 0), (2, 0), (-2, 1), (-1, 1), (0, 1), (1, 1), (2, 1), (-2, 2), (-1, 2), (0, 2), (1, 2), (2, 2))
#: ring rows per forward tap: the row being filtered and the two rows it meets before it
SLOTS = 3


@njit(cache=True, fastmath=True, inline="always")
def _weight(cp, gp, ps, iq, c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, e_k):
    """``2**-(e_k + b_c |dc|^2 + b_n |dn|^2 + b_x |dx|^2)`` between the pixel whose colour,
    normal and position are ``c*``, ``n*``, ``x*`` and the pixel at flat plane index ``iq``
    (colour planes ``cp`` and guide planes ``gp`` of ``ps`` floats each): the pair weight times
    the kernel tap ``h_k`` for ``b = a log2(e)`` and ``e_k = -log2(h_k)``. A background pixel's
    normal (``BACKGROUND_NORMAL``) makes the weight 0 with ``a_n >= A_N_MIN``."""
    o1 = ps
    o2 = o1 + ps
    o3 = o2 + ps
    o4 = o3 + ps
    o5 = o4 + ps
    d0 = cp[iq] - c0
    d1 = cp[o1 + iq] - c1
    d2 = cp[o2 + iq] - c2
    e0 = gp[iq] - n0
    e1 = gp[o1 + iq] - n1
    e2 = gp[o2 + iq] - n2
    f0 = gp[o3 + iq] - x0
    f1 = gp[o4 + iq] - x1
    f2 = gp[o5 + iq] - x2
    return kernels.exp2_minus(e_k + b_c * (d0 * d0 + d1 * d1 + d2 * d2) + b_n * (e0 * e0 + e1 * e1 + e2 * e2)
                              + b_x * (f0 * f0 + f1 * f1 + f2 * f2))


@njit(cache=True, fastmath=True, inline="always")
def _row_weights(cp, gp, ps, row, n, ring, fw, offs, ek, b_c, b_n, b_x):
    """The 12 forward pair weights (times the kernel tap) of the ``n`` pixels of a row starting
    at flat index ``row``: tap ``o`` of pixel ``j`` goes to ``ring[fw[o] + j]``."""
    o1 = ps
    o2 = o1 + ps
    o3 = o2 + ps
    o4 = o3 + ps
    o5 = o4 + ps
    for j in range(n):
        ip = row + j
        c0 = cp[ip]
        c1 = cp[o1 + ip]
        c2 = cp[o2 + ip]
        n0 = gp[ip]
        n1 = gp[o1 + ip]
        n2 = gp[o2 + ip]
        x0 = gp[o3 + ip]
        x1 = gp[o4 + ip]
        x2 = gp[o5 + ip]
        ring[fw[0] + j] = _weight(cp, gp, ps, ip + offs[0], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[0])
        ring[fw[1] + j] = _weight(cp, gp, ps, ip + offs[1], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[1])
        ring[fw[2] + j] = _weight(cp, gp, ps, ip + offs[2], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[2])
        ring[fw[3] + j] = _weight(cp, gp, ps, ip + offs[3], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[3])
        ring[fw[4] + j] = _weight(cp, gp, ps, ip + offs[4], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[4])
        ring[fw[5] + j] = _weight(cp, gp, ps, ip + offs[5], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[5])
        ring[fw[6] + j] = _weight(cp, gp, ps, ip + offs[6], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[6])
        ring[fw[7] + j] = _weight(cp, gp, ps, ip + offs[7], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[7])
        ring[fw[8] + j] = _weight(cp, gp, ps, ip + offs[8], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[8])
        ring[fw[9] + j] = _weight(cp, gp, ps, ip + offs[9], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x, ek[9])
        ring[fw[10] + j] = _weight(cp, gp, ps, ip + offs[10], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x,
                                   ek[10])
        ring[fw[11] + j] = _weight(cp, gp, ps, ip + offs[11], c0, c1, c2, n0, n1, n2, x0, x1, x2, b_c, b_n, b_x,
                                   ek[11])


@njit(cache=True, fastmath=True, inline="always")
def _tap(sp, ps, ic, off, wf, wb, c0, c1, c2, s0, s1, s2, sw):
    """Add the forward tap ``ic + off`` (weight ``wf``) and the backward tap ``ic - off``
    (weight ``wb``) to the sums of colour changes ``s*`` and of weights ``sw``."""
    qf = ic + off
    qb = ic - off
    s0 += wf * (sp[qf] - c0) + wb * (sp[qb] - c0)
    s1 += wf * (sp[ps + qf] - c1) + wb * (sp[ps + qb] - c1)
    s2 += wf * (sp[ps + ps + qf] - c2) + wb * (sp[ps + ps + qb] - c2)
    sw += wf + wb
    return s0, s1, s2, sw


@njit(cache=True, fastmath=True, inline="always")
def _accumulate(sp, dp, ps, row, x0, n, state, y, ring, fw, bw, offs, centre):
    """Filter the ``n`` pixels from column ``x0`` of row ``y`` (flat index ``row + x``): the sums
    over the 24 taps, forward weights at ``ring[fw[o] + x]``, backward ones at ``ring[bw[o] +
    x]``, then ``dp = sp + change`` on active pixels and ``dp = sp`` on the others."""
    for j in range(n):
        x = x0 + j
        ic = row + x
        c0 = sp[ic]
        c1 = sp[ps + ic]
        c2 = sp[ps + ps + ic]
        s0 = np.float32(0.0)
        s1 = np.float32(0.0)
        s2 = np.float32(0.0)
        sw = centre  # the centre tap: weight 1, no change
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[0], ring[fw[0] + x], ring[bw[0] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[1], ring[fw[1] + x], ring[bw[1] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[2], ring[fw[2] + x], ring[bw[2] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[3], ring[fw[3] + x], ring[bw[3] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[4], ring[fw[4] + x], ring[bw[4] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[5], ring[fw[5] + x], ring[bw[5] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[6], ring[fw[6] + x], ring[bw[6] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[7], ring[fw[7] + x], ring[bw[7] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[8], ring[fw[8] + x], ring[bw[8] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[9], ring[fw[9] + x], ring[bw[9] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[10], ring[fw[10] + x], ring[bw[10] + x], c0, c1, c2, s0, s1, s2, sw)
        s0, s1, s2, sw = _tap(sp, ps, ic, offs[11], ring[fw[11] + x], ring[bw[11] + x], c0, c1, c2, s0, s1, s2, sw)
        inv = np.float32(state[y, x] == ACTIVE) / sw  # only active pixels change (runs span short gaps)
        dp[ic] = c0 + s0 * inv
        dp[ps + ic] = c1 + s1 * inv
        dp[ps + ps + ic] = c2 + s2 * inv


@njit(cache=True, inline="always")
def _tap_rows(base, pitch):
    """Flat ring indices of one slot's row for each of the 12 taps: ``base + o pitch``."""
    b1 = base + pitch
    b2 = b1 + pitch
    b3 = b2 + pitch
    b4 = b3 + pitch
    b5 = b4 + pitch
    b6 = b5 + pitch
    b7 = b6 + pitch
    b8 = b7 + pitch
    b9 = b8 + pitch
    b10 = b9 + pitch
    b11 = b10 + pitch
    return (base, b1, b2, b3, b4, b5, b6, b7, b8, b9, b10, b11)


@njit(cache=True, fastmath=True, inline="always")
def _slot_weights(cp, gp, ps, y, halo, stride, row_surface, n, ring, fw, offs, ek, b_c, b_n, b_x):
    """The forward pair weights of row ``y`` into the ring rows ``fw`` (:func:`_row_weights`);
    weight 0 for a row above the image (``y < 0``) or without a surface."""
    if y >= 0 and row_surface[y] != 0:
        _row_weights(cp, gp, ps, uint64((y + halo) * stride + halo), n, ring, fw, offs, ek, b_c, b_n, b_x)
    else:
        for o in range(12):
            for j in range(n):
                ring[fw[o] + j] = np.float32(0.0)


@njit(parallel=True, cache=True, fastmath=True)
def atrous_pass(src, dst, gbuf, state, runs, run_count, row_surface, halo, stride, step, b_c, b_n, b_x, centre,
                exponents, order, starts, ring, final, color, out, inv_scale, scale):
    """One à-trous iteration over the active runs: ``dst = src + sum w (src_q - src) / sum w``.

    Each part of the work is a stretch ``order[starts[t]:starts[t + 1]]`` of the rows in class
    order (:func:`row_order`). For each row ``y`` the weights to the 12 taps of the forward half
    of the 5x5 kernel (``dy > 0``, or ``dy = 0, dx > 0``), times the kernel tap, go to ring slot
    ``(y // step) % 3`` of the part; pixel ``p`` then takes its forward taps from that slot and
    its backward taps ``p - o`` from the slot of row ``y - dy``, filled ``dy / step`` rows before
    in the same class: 12 exponentials per pixel instead of 24 (the centre tap, weight 1 and no
    change, is not evaluated). A part that starts inside a class first computes the weights of
    the two rows of the class above it; at the start of a class the two slots are 0 (no row
    above the image).

    Parameters
    ----------
    src, dst : ndarray (3 * planesize,) float32
        Colour planes of this iteration and the next (only the active runs are written).
    gbuf : ndarray (7 * planesize,) float32
        Normal, position, surface mask planes (the mask is not read: see
        :data:`.layout.BACKGROUND_NORMAL`).
    state : ndarray (H, W) int8
        Pixel classes: only ACTIVE pixels change.
    runs, run_count, row_surface : ndarray
        Active runs per row and rows with a surface pixel (see :func:`.layout.pack`).
    halo, stride, step : int
        Padding, row stride and hole spacing ``2**i`` in pixels (``2 step <= halo``).
    b_c, b_n, b_x : float32
        Coefficients of the squared colour, normal and position distances in the exponent of 2:
        ``a log2(e)`` for the weight's ``exp(-a ...)`` (``a_n >= A_N_MIN``).
    centre : float32
        The kernel's centre tap.
    exponents : ndarray (12,) float32
        ``-log2`` of the kernel taps of the forward half, in the order of :data:`FORWARD`.
    order : ndarray (H,) int64
        The rows in class order (:func:`row_order`).
    starts : ndarray (parts + 1,) int64
        Part ``t`` filters the rows ``order[starts[t]:starts[t + 1]]`` (:func:`balanced_parts`).
    ring : ndarray float32
        Scratch of at least ``parts * 12 * 3 * stride`` floats, zero outside the image's columns.
    final : bool
        Last iteration: also write every pixel of ``out``: ``color + (result - normalised
        color) * scale`` on active pixels, ``color`` elsewhere. Writing the change keeps a
        constant image exactly constant.
    color, out : ndarray (H * W * 3,) float32
        The input colour and the output, flat.
    inv_scale, scale : float
        1 / colour scale and colour scale.
    """
    w = state.shape[1]
    ps = uint64(src.shape[0] // 3)
    wu = uint64(w)
    a = uint64(step)  # one hole to the right
    b = uint64(stride * step)  # one hole down
    offs = (a, a + a, b - a - a, b - a, b, b + a, b + a + a, b + b - a - a, b + b - a, b + b, b + b + a, b + b + a + a)
    ek = (exponents[0], exponents[1], exponents[2], exponents[3], exponents[4], exponents[5], exponents[6],
          exponents[7], exponents[8], exponents[9], exponents[10], exponents[11])
    pitch = uint64(SLOTS * stride)  # one tap to the next in a part's ring
    part_size = 12 * SLOTS * stride
    for t in prange(starts.shape[0] - 1):
        r0 = uint64(np.int64(t) * part_size + halo)  # column 0 of slot 0 of tap 0 of this part's ring
        for i in range(starts[t], starts[t + 1]):
            y = order[i]
            k = y // step  # the row's place in its class
            if i == starts[t] or k == 0:
                # the two rows of the class above y: computed, or weight 0 above the image
                for back in range(2, 0, -1):
                    _slot_weights(src, gbuf, ps, y - back * step, halo, stride, row_surface, wu, ring,
                                  _tap_rows(r0 + uint64(((k - back) % SLOTS) * stride), pitch), offs, ek, b_c, b_n,
                                  b_x)
            fw = _tap_rows(r0 + uint64((k % SLOTS) * stride), pitch)  # this row's slot
            _slot_weights(src, gbuf, ps, y, halo, stride, row_surface, wu, ring, fw, offs, ek, b_c, b_n, b_x)
            row = uint64((y + halo) * stride + halo)
            # backward tap o of pixel x: the forward weight of pixel x - dx in row y - dy
            f1 = _tap_rows(r0 + uint64(((k - 1) % SLOTS) * stride), pitch)  # the slot of row y - step
            f2 = _tap_rows(r0 + uint64(((k - 2) % SLOTS) * stride), pitch)  # of row y - 2 step
            bw = (fw[0] - a, fw[1] - a - a,
                  f1[2] + a + a, f1[3] + a, f1[4], f1[5] - a, f1[6] - a - a,
                  f2[7] + a + a, f2[8] + a, f2[9], f2[10] - a, f2[11] - a - a)
            for r in range(run_count[y]):
                xa = runs[y, r, 0]
                _accumulate(src, dst, ps, row, uint64(xa), uint64(runs[y, r, 1] - xa), state, y, ring, fw, bw,
                            offs, centre)
            if final:
                unpack_row(dst, ps, row, state, y, color, out, wu, inv_scale, scale)


def row_order(height: int, step: int) -> np.ndarray:
    """The rows in class order at hole spacing ``step``: ``0, step, 2 step, ...``, then ``1, 1 +
    step, ...``, up to the class ``step - 1``.

    Returns
    -------
    ndarray (height,) int64
    """
    return np.concatenate([np.arange(r, height, step, dtype=np.int64) for r in range(min(step, height))])


def balanced_parts(buffers: Buffers, parts: int, step: int = 1):
    """Cut the rows, in class order, into ``parts`` stretches of about equal work at hole spacing ``step``.

    A row's work is estimated as its pair weights (the whole row, where the row has a surface
    pixel: 12 exponentials per pixel) plus its accumulation (its active runs; about half as
    much per pixel) plus a little for the rest (a sky row costs almost nothing). A part that
    starts inside a class also computes the weights of the two rows above its first row: that
    refill is counted in its work, and a cut between two classes needs none. Each cut is placed
    where the larger of its part's work and the mean work of the parts after it is least.

    Returns
    -------
    order : ndarray (H,) int64
        :func:`row_order`.
    starts : ndarray (parts + 1,) int64
        Part ``t`` is ``order[starts[t]:starts[t + 1]]``.
    """
    b = buffers
    order = row_order(b.height, step)
    lengths = b.runs[:, :, 1] - b.runs[:, :, 0]
    lengths[np.arange(MAX_RUNS)[None, :] >= b.run_count[:, None]] = 0
    weights = 2.0 * b.width * (b.row_surface != 0)
    cost = (weights + lengths.sum(axis=1) + 0.05 * b.width)[order]
    total = np.concatenate(([0.0], np.cumsum(cost)))
    padded = np.concatenate((np.zeros(2 * step), weights))  # rows above the image: no refill
    refill = np.zeros(b.height + 1)  # a part starting at position i (the end: nothing)
    refill[:-1] = padded[order + step] + padded[order]  # rows y - step and y - 2 step
    refill[:-1][order < step] = 0.0  # the start of a class
    typical = float(np.median(refill))
    starts = np.zeros(parts + 1, np.int64)
    starts[parts] = b.height
    for t in range(1, parts):
        s = starts[t - 1]
        ends = np.arange(s, b.height + 1)
        own = total[ends] - total[s] + refill[s]
        rest = (total[-1] - total[ends] + refill[ends] + (parts - t - 1) * typical) / (parts - t)
        starts[t] = ends[int(np.argmin(np.maximum(own, rest)))]
    return order, starts


def run(frame, params, coefficients, taps, buffers: Buffers):
    """Filter one frame.

    Parameters
    ----------
    frame : harness.Frame
        ``color``, ``normal``, ``position``; ``object_id``, ``depth``, ``variance`` if present.
    params : EAWParams
    coefficients : ndarray (N, 3) float32
        Per-iteration ``(a_c, a_n, a_x)``.
    taps : ndarray (25,) float32
    buffers : Buffers
        Of the frame's size and the parameters' halo (reused across frames).

    Returns
    -------
    out : ndarray (H, W, 3) float32
    stage_ms : dict
        Milliseconds of ``prepare`` (survey, scales, packing) and ``atrous`` (all iterations,
        the last writing the output).
    """
    t0 = time.perf_counter()
    color, scale = prepare(frame, params, buffers)
    t1 = time.perf_counter()
    out = iterate(buffers, coefficients, taps, color, scale)
    t2 = time.perf_counter()
    return out, {"prepare": (t1 - t0) * 1e3, "atrous": (t2 - t1) * 1e3}


def iterate(buffers: Buffers, coefficients, taps, color, scale: float):
    """The à-trous iterations on prepared buffers, on all of Numba's threads.

    Parameters
    ----------
    buffers : Buffers
        Filled by :func:`.layout.prepare` (their colour planes are overwritten).
    coefficients : ndarray (N, 3) float32
    taps : ndarray (25,) float32
    color : ndarray (H, W, 3) float32
        The frame's colour, C-contiguous.
    scale : float
        The colour scale of :func:`.layout.prepare`.

    Returns
    -------
    ndarray (H, W, 3) float32
    """
    b = buffers
    parts = get_num_threads()
    ring = b.thread_ring(parts * 12 * SLOTS)
    out = np.empty_like(color)
    src, dst = b.color
    forward = np.array([taps[(dy + 2) * 5 + dx + 2] for dx, dy in FORWARD], np.float64)
    exponents = (-np.log2(forward)).astype(np.float32)
    last = coefficients.shape[0] - 1
    for i in range(last + 1):
        a_c, a_n, a_x = (np.float64(v) for v in coefficients[i])
        a_n = max(a_n, A_N_MIN)  # keeps the background marker effective
        b_c, b_n, b_x = (np.float32(v * kernels.LOG2E) for v in (a_c, a_n, a_x))
        order, starts = balanced_parts(b, parts, 2**i)
        atrous_pass(src, dst, b.guide, b.state, b.runs, b.run_count, b.row_surface, b.halo, b.stride, 2**i, b_c,
                    b_n, b_x, taps[12], exponents, order, starts, ring, i == last, color.reshape(-1),
                    out.reshape(-1), 1.0 / scale, scale)
        src, dst = dst, src
    return out
