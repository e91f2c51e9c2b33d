"""CPU backend of the EAW filter: the à-trous iterations on the padded planes of :mod:`.layout`.

A frame costs :func:`.layout.prepare` (two parallel passes over the inputs) and one parallel
:func:`atrous_pass` per iteration, the last of which writes the output frame.

Symmetry. The edge-stopping weight of a pair is symmetric: each is computed once, for the 12
forward taps, and kept (times the kernel tap) in a ring buffer of rows for the pixels that see
the pair backwards.

Vectorization. The tap loops are outside the pixel loops: for each tap, a branch-free loop over
up to ``CHUNK`` consecutive pixels of a row; LLVM vectorizes them (contiguous unsigned indices,
no libm call: :func:`.fastexp.fast_exp_minus`). The parallel loop body creates no array views,
so Numba marks the arrays ``noalias`` and LLVM needs no run-time aliasing tests. The packed
values are bounded (:mod:`.layout`), so the loops hold no overflow guard.
"""

from __future__ import annotations

import time

import numpy as np
from numba import get_num_threads, njit, prange, uint64

from .fastexp import fast_exp_minus
from .layout import A_N_MIN, ACTIVE, MAX_RUNS, SCRATCH, Buffers, normalised, prepare

#: pixels per accumulation chunk of the inner loop
CHUNK = SCRATCH // 4
#: the forward half of the 5x5 taps (row-major index k > 12: dy > 0, or dy = 0 and dx > 0)
FORWARD_TAPS = np.arange(13, 25, dtype=np.int64)


@njit(cache=True, fastmath=True, inline="always")
def _pair_weights(cp, gp, ps, ip0, iq0, e, e0, n, hk, a_c, a_n, a_x):
    """``e[e0 + j] = h_k exp(-(a_c |dc|^2 + a_n |dn|^2 + a_x |dx|^2))`` for ``p = ip0 + j``,
    ``q = iq0 + j``, ``j < n`` (flat plane indices; colour planes ``cp`` and guide planes ``gp``
    of ``ps`` floats each; the weight is symmetric in p and q). A background pixel's normal
    (``BACKGROUND_NORMAL``) makes the weight 0 with ``a_n >= A_N_MIN``."""
    # plane offsets, all uint64 (a signed index makes Numba emit wraparound code: gathers)
    o1 = ps
    o2 = o1 + ps
    o3 = o2 + ps
    o4 = o3 + ps
    o5 = o4 + ps
    for j in range(n):
        ip = ip0 + j
        iq = iq0 + j
        c0 = cp[iq] - cp[ip]
        c1 = cp[o1 + iq] - cp[o1 + ip]
        c2 = cp[o2 + iq] - cp[o2 + ip]
        d0 = gp[iq] - gp[ip]
        d1 = gp[o1 + iq] - gp[o1 + ip]
        d2 = gp[o2 + iq] - gp[o2 + ip]
        f0 = gp[o3 + iq] - gp[o3 + ip]
        f1 = gp[o4 + iq] - gp[o4 + ip]
        f2 = gp[o5 + iq] - gp[o5 + ip]
        arg = (a_c * (c0 * c0 + c1 * c1 + c2 * c2) + a_n * (d0 * d0 + d1 * d1 + d2 * d2)
               + a_x * (f0 * f0 + f1 * f1 + f2 * f2))
        e[e0 + j] = hk * fast_exp_minus(arg)


@njit(cache=True, fastmath=True, inline="always")
def _accumulate(sp, ps, cb, qf, qb, rf, rb, qf2, qb2, rf2, rb2, ring, acc, a0, n):
    """Add two forward taps ``qf``, ``qf2`` and their backward taps ``qb``, ``qb2`` (pair
    weights times kernel tap at ``ring[rf + j]`` ...) of ``n`` pixels from ``cb`` to the sums at
    ``acc[a0:]`` (red, green, blue changes and the weight, ``CHUNK`` floats each)."""
    o1 = ps
    o2 = o1 + ps
    ag = a0 + uint64(CHUNK)
    ab = ag + uint64(CHUNK)
    aw = ab + uint64(CHUNK)
    for j in range(n):
        ic = cb + j
        wf = ring[rf + j]
        wb = ring[rb + j]
        wf2 = ring[rf2 + j]
        wb2 = ring[rb2 + j]
        cr = sp[ic]
        cg = sp[o1 + ic]
        cbl = sp[o2 + ic]
        acc[a0 + j] += (wf * (sp[qf + j] - cr) + wb * (sp[qb + j] - cr)
                        + wf2 * (sp[qf2 + j] - cr) + wb2 * (sp[qb2 + j] - cr))
        acc[ag + j] += (wf * (sp[o1 + qf + j] - cg) + wb * (sp[o1 + qb + j] - cg)
                        + wf2 * (sp[o1 + qf2 + j] - cg) + wb2 * (sp[o1 + qb2 + j] - cg))
        acc[ab + j] += (wf * (sp[o2 + qf + j] - cbl) + wb * (sp[o2 + qb + j] - cbl)
                        + wf2 * (sp[o2 + qf2 + j] - cbl) + wb2 * (sp[o2 + qb2 + j] - cbl))
        acc[aw + j] += (wf + wb) + (wf2 + wb2)


@njit(parallel=True, cache=True, fastmath=True)
def atrous_pass(src, dst, gbuf, state, runs, run_count, row_surface, halo, stride, step, a_c, a_n, a_x, taps,
                starts, ring, scratch, final, color, out, inv_scale, scale):
    """One à-trous iteration over the active runs: ``dst = src + sum w (src_q - src) / sum w``.

    For each row ``y`` (top to bottom within a band of rows) the weights to the 12 taps of the
    forward half of the 5x5 kernel (``dy > 0``, or ``dy = 0, dx > 0``), times the kernel tap,
    are stored in a ring buffer of ``2 step + 1`` rows; pixel ``p`` then takes its forward taps
    from its own row's weights and its backward taps ``p - o`` from the weights stored ``dy``
    rows earlier: 12 exponentials per pixel instead of 24 (the centre tap, weight 1 and no
    change, is not evaluated). A band first fills the ring with the ``2 step`` rows above it
    (recomputed, not shared between threads).

    Parameters
    ----------
    src, dst : ndarray (3 * planesize,) float32
        Colour planes of this iteration and the next (only active pixels are written).
    gbuf : ndarray (7 * planesize,) float32
        Normal, position, surface mask planes (the mask is not read: see
        :data:`.layout.BACKGROUND_NORMAL`).
    state : ndarray (H, W) int8
        Pixel classes: only ACTIVE pixels change.
    runs, run_count, row_surface : ndarray
        Active runs per row and rows with a surface pixel (see :func:`.layout.pack`).
    halo, stride, step : int
        Padding, row stride and hole spacing ``2**i`` in pixels.
    a_c, a_n, a_x : float32
        Coefficients of the squared colour, normal and position distances (``a_n >= A_N_MIN``).
    taps : ndarray (25,) float32
        B3-spline kernel.
    starts : ndarray (threads + 1,) int64
        Thread ``t`` filters rows ``starts[t]`` to ``starts[t + 1]`` (one band of consecutive
        rows per thread, of about equal work: :func:`balanced_rows`).
    ring : ndarray float32
        Scratch of at least ``threads * 12 * (2 step + 1) * stride`` floats, zero outside the
        image's columns.
    scratch : ndarray float32
        Scratch of at least ``threads * 4 * CHUNK`` floats.
    final : bool
        Last iteration: instead of ``dst``, write every pixel of ``out``: ``color + (result -
        normalised color) * scale`` on active pixels, ``color`` elsewhere. Writing the change
        keeps a constant image exactly constant.
    color, out : ndarray (H, W, 3) float32
    inv_scale, scale : float
        1 / colour scale and colour scale.
    """
    w = color.shape[1]
    ps = uint64(src.shape[0] // 3)
    ps2 = ps + ps
    ring_rows = 2 * step + 1
    ring_size = 12 * ring_rows * stride
    for t in prange(starts.shape[0] - 1):
        r0 = np.int64(t) * ring_size  # this thread's ring: 12 taps x ring_rows rows x stride
        a0 = uint64(np.int64(t) * 4 * CHUNK)  # this thread's sums: 4 x CHUNK
        aw = a0 + uint64(3 * CHUNK)
        y0 = starts[t]
        y1 = starts[t + 1]
        if y0 < 2 * step:
            for j in range(r0, r0 + ring_size):
                ring[j] = np.float32(0.0)  # rows above the image: weight 0
        for y in range(max(y0 - 2 * step, 0), y1):
            slot = y % ring_rows
            row = (y + halo) * stride + halo
            for o in range(12):
                k = FORWARD_TAPS[o]
                e0 = uint64(r0 + (o * ring_rows + slot) * stride + halo)
                if row_surface[y] != 0:
                    off = ((k // 5 - 2) * stride + (k % 5 - 2)) * step
                    for xa in range(0, w, CHUNK):
                        n = uint64(min(CHUNK, w - xa))
                        _pair_weights(src, gbuf, ps, uint64(row + xa), uint64(row + xa + off), ring,
                                      e0 + uint64(xa), n, taps[k], a_c, a_n, a_x)
                else:
                    for j in range(w):
                        ring[e0 + uint64(j)] = np.float32(0.0)
            if y < y0:
                continue
            if final:
                for x in range(w):
                    for c in range(3):
                        out[y, x, c] = color[y, x, c]
            for r in range(run_count[y]):
                xa = runs[y, r, 0]
                xe = runs[y, r, 1]
                while xa < xe:
                    n = uint64(min(CHUNK, xe - xa))
                    cb = uint64(row + xa)
                    for j in range(3 * CHUNK):
                        scratch[a0 + uint64(j)] = np.float32(0.0)
                    for j in range(CHUNK):
                        scratch[aw + uint64(j)] = taps[12]  # the centre tap: weight 1, no change
                    for o in range(0, 12, 2):
                        k = FORWARD_TAPS[o]
                        dy = (k // 5 - 2) * step
                        dx = (k % 5 - 2) * step
                        off = dy * stride + dx
                        rf = uint64(r0 + (o * ring_rows + slot) * stride + halo + xa)
                        rb = uint64(r0 + (o * ring_rows + (y - dy) % ring_rows) * stride + halo + xa - dx)
                        k2 = FORWARD_TAPS[o + 1]
                        dy2 = (k2 // 5 - 2) * step
                        dx2 = (k2 % 5 - 2) * step
                        off2 = dy2 * stride + dx2
                        rf2 = uint64(r0 + ((o + 1) * ring_rows + slot) * stride + halo + xa)
                        rb2 = uint64(r0 + ((o + 1) * ring_rows + (y - dy2) % ring_rows) * stride + halo + xa - dx2)
                        _accumulate(src, ps, cb, uint64(row + xa + off), uint64(row + xa - off), rf, rb,
                                    uint64(row + xa + off2), uint64(row + xa - off2), rf2, rb2, ring, scratch,
                                    a0, n)
                    if final:
                        for x in range(xa, xa + np.int64(n)):
                            if state[y, x] == ACTIVE:
                                j = uint64(x - xa)
                                ic = cb + j
                                inv = np.float32(1.0) / scratch[aw + j]
                                for c in range(3):
                                    v = color[y, x, c]
                                    f = src[uint64(c) * ps + ic] + scratch[a0 + uint64(c * CHUNK) + j] * inv
                                    delta = np.float64(f) - np.float64(normalised(v, inv_scale))
                                    out[y, x, c] = np.float32(np.float64(v) + delta * scale)
                    else:
                        for j in range(n):
                            ic = cb + j
                            # only active pixels change (runs may span short gaps)
                            inv = np.float32(state[y, uint64(xa) + j] == ACTIVE) / scratch[aw + j]
                            dst[ic] = src[ic] + scratch[a0 + j] * inv
                            dst[ps + ic] = src[ps + ic] + scratch[a0 + uint64(CHUNK) + j] * inv
                            dst[ps2 + ic] = src[ps2 + ic] + scratch[a0 + uint64(2 * CHUNK) + j] * inv
                    xa += CHUNK


def balanced_rows(buffers: Buffers, parts: int, step: int = 1) -> np.ndarray:
    """Cut the rows into ``parts`` bands of consecutive rows of about equal work at hole spacing ``step``.

    A row's work is estimated as its pair weights (the whole row, where the row has a surface
    pixel: 12 exponentials per pixel) plus its accumulation (its active runs; about half as
    much per pixel) plus a little for the rest (a sky row costs almost nothing). One band per
    thread: each band after the first also recomputes the pair weights of the ``2 step`` rows
    above it for its ring, and that refill is counted in its work, so the bands below the
    first are shorter by about as much (at ``step`` 16 on a 720-row frame, 32 rows of weights:
    without it the second of two threads had 9 % more work than the first).

    Returns
    -------
    ndarray (parts + 1,) int64
        Band ``t`` is rows ``starts[t]`` to ``starts[t + 1]``.
    """
    b = buffers
    lengths = b.runs[:, :, 1] - b.runs[:, :, 0]
    lengths[np.arange(MAX_RUNS)[None, :] >= b.run_count[:, None]] = 0
    weights = 2.0 * b.width * (b.row_surface != 0)
    total = np.concatenate(([0.0], np.cumsum(weights + lengths.sum(axis=1) + 0.05 * b.width)))
    refill_sums = np.concatenate(([0.0], np.cumsum(weights)))
    rows = np.arange(b.height + 1)
    refill = refill_sums - refill_sums[np.maximum(rows - 2 * step, 0)]  # band starting at row r
    typical_refill = float(np.median(refill))
    starts = np.zeros(parts + 1, np.int64)
    starts[parts] = b.height
    for t in range(1, parts):
        s = starts[t - 1]
        own = refill[s] if t > 1 else 0.0
        # this band's share of what is left (the rest's refills estimated), nearest row boundary
        target = (total[-1] - total[s] + own + (parts - t) * typical_refill) / (parts - t + 1)
        due = total[s] + target - own
        i = min(int(np.searchsorted(total, due)), b.height)
        if i > s and due - total[i - 1] < total[i] - due:
            i -= 1
        starts[t] = max(i, s)
    return starts


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
    b = buffers
    threads = get_num_threads()
    iterations = coefficients.shape[0]
    ring, scratch = b.thread_scratch(threads, iterations)
    out = np.empty_like(color)
    src, dst = b.color
    for i in range(iterations):
        a_c, a_n, a_x = (np.float32(v) for v in coefficients[i])
        a_n = max(a_n, np.float32(A_N_MIN))  # keeps the background marker effective
        starts = balanced_rows(b, threads, 2**i)
        atrous_pass(src, dst, b.guide, b.state, b.runs, b.run_count, b.row_surface, b.halo, b.stride, 2**i, a_c,
                    a_n, a_x, taps, starts, ring, scratch, i == iterations - 1, color, out, 1.0 / scale, scale)
        src, dst = dst, src
    t2 = time.perf_counter()
    return out, {"prepare": (t1 - t0) * 1e3, "atrous": (t2 - t1) * 1e3}
