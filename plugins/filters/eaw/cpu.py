"""CPU backend of the EAW filter: Numba kernels on planar, padded float32 buffers.

Layout. Each quantity is a plane of ``(H + 2 halo) x stride`` float32 values, flattened to 1-D:
colour (3 planes, two ping-pong sets), normal (3), position (3) and a surface mask (1). The halo
(``2**iterations`` pixels, the largest tap offset) holds zeros and mask 0, so the inner loop
needs no bounds tests: a tap outside the image, or on the background, gets weight 0. The row
stride is padded to an odd multiple of 16 floats (64 bytes): rows 2, 4, 8, 16 apart then fall in
different L1 sets (a stride that is a multiple of 2 KiB measured 40 % slower, see the README).

Skipping. Pixels are classified once per frame: background (no surface), surface without
noise (``variance`` present and zero: kept as they are, still used as taps) and active. Each
row's active pixels are stored as runs, and the kernels loop over the runs only.

Symmetry. The edge-stopping weight of a pair is symmetric: each is computed once, for the 12
forward taps, and kept in a ring buffer of rows for the pixels that see the pair backwards
(:func:`atrous_pass`).

Vectorization. The tap loops are outside the pixel loops: for each tap, a branch-free loop over
up to ``CHUNK`` consecutive pixels of a row; LLVM vectorizes them (contiguous unsigned indices,
no libm call: :func:`.fastexp.fast_exp_minus`).
"""

from __future__ import annotations

import time

import numpy as np
from numba import get_num_threads, njit, prange, uint64

from .fastexp import fast_exp_minus
from .fastlog import fast_log

#: pixels per accumulation chunk of the inner loop
CHUNK = 256
#: largest magnitude of a colour difference entering the weight (keeps squares finite)
DIFF_MAX = np.float32(1e12)
#: largest magnitude of a normalised guide value (normals, positions)
GUIDE_MAX = 1e12
#: largest exponent of the weight in the CUDA kernel; exp(-100) is below float32's smallest normal
ARG_MAX = np.float32(100.0)
# Rec. 709 luminance weights
LUMA = (0.2126, 0.7152, 0.0722)

BACKGROUND, STILL, ACTIVE = 0, 1, 2
#: the forward half of the 5x5 taps (row-major index k > 12: dy > 0, or dy = 0 and dx > 0)
FORWARD_TAPS = np.arange(13, 25, dtype=np.int64)


def padded_stride(width: int, halo: int) -> int:
    """Row stride (floats) for an image ``width`` wide with ``halo`` on each side.

    The smallest value >= ``width + 2 halo`` that is an odd multiple of 16.
    """
    w = width + 2 * halo
    return w + (16 - w % 32) % 32


@njit(cache=True, fastmath=True)
def classify(normal, ids, depth, variance, has_ids, has_depth, has_variance, state):
    """Write BACKGROUND / STILL / ACTIVE per pixel into ``state`` (H, W) int8.

    Background: normal exactly zero, or ``object_id == -1``, or non-finite depth (when those
    channels are given). Still: a surface pixel whose ``variance`` is zero in all channels.
    """
    h, w = state.shape
    for y in range(h):
        for x in range(w):
            surface = (normal[y, x, 0] != 0.0) | (normal[y, x, 1] != 0.0) | (normal[y, x, 2] != 0.0)
            state[y, x] = np.int8(surface) * np.int8(2)
        if has_ids:
            for x in range(w):
                state[y, x] = state[y, x] if ids[y, x] != -1 else np.int8(BACKGROUND)
        if has_depth:
            for x in range(w):
                state[y, x] = state[y, x] if abs(depth[y, x]) < np.inf else np.int8(BACKGROUND)
        if has_variance:
            for x in range(w):
                noisy = (variance[y, x, 0] != 0.0) | (variance[y, x, 1] != 0.0) | (variance[y, x, 2] != 0.0)
                s = state[y, x]
                state[y, x] = s if noisy or s == BACKGROUND else np.int8(STILL)


@njit(cache=True, fastmath=True)
def surface_statistics(color, position, state):
    """Sums over surface pixels: log-luminance and its count, and the bounding box of positions.

    Returns
    -------
    log_sum : float
        Sum of ``log(L)`` over surface pixels whose luminance ``L`` (float32) is a finite number
        of at least float32's smallest normal value (float64 sum).
    count : int
        Number of those pixels.
    lo, hi : ndarray (3,) float64
        Bounding box of the positions of surface pixels (``lo > hi`` when there are none).
    """
    h, w = state.shape
    tiny = np.float32(np.finfo(np.float32).tiny)
    big = np.float32(np.inf)
    row_log = np.zeros(h)
    row_count = np.zeros(h, np.int64)
    row_lo = np.full((h, 3), np.inf, np.float32)
    row_hi = np.full((h, 3), -np.inf, np.float32)
    for y in range(h):
        total = 0.0
        count = 0
        lo0 = lo1 = lo2 = big
        hi0 = hi1 = hi2 = -big
        for x in range(w):
            surface = state[y, x] != BACKGROUND
            lum = (np.float32(LUMA[0]) * color[y, x, 0] + np.float32(LUMA[1]) * color[y, x, 1]
                   + np.float32(LUMA[2]) * color[y, x, 2])
            ok = surface & (lum >= tiny) & (lum < big)
            total += fast_log(lum if ok else np.float32(1.0))
            count += np.int64(ok)
            lo0 = min(lo0, position[y, x, 0] if surface else big)
            lo1 = min(lo1, position[y, x, 1] if surface else big)
            lo2 = min(lo2, position[y, x, 2] if surface else big)
            hi0 = max(hi0, position[y, x, 0] if surface else -big)
            hi1 = max(hi1, position[y, x, 1] if surface else -big)
            hi2 = max(hi2, position[y, x, 2] if surface else -big)
        row_log[y] = total
        row_count[y] = count
        row_lo[y, 0], row_lo[y, 1], row_lo[y, 2] = lo0, lo1, lo2
        row_hi[y, 0], row_hi[y, 1], row_hi[y, 2] = hi0, hi1, hi2
    lo = np.full(3, np.inf)
    hi = np.full(3, -np.inf)
    for y in range(h):
        for c in range(3):
            lo[c] = min(lo[c], np.float64(row_lo[y, c]))
            hi[c] = max(hi[c], np.float64(row_hi[y, c]))
    return row_log.sum(), row_count.sum(), lo, hi


@njit(cache=True)
def active_runs(state):
    """Runs of ACTIVE pixels per row, as CSR arrays.

    Returns
    -------
    row_ptr : ndarray (H + 1,) int64
        Runs of row ``y`` are ``row_ptr[y]:row_ptr[y + 1]``.
    x0, x1 : ndarray (runs,) int64
        Half-open column range of each run.
    """
    h, w = state.shape
    count = 0
    for y in range(h):
        inside = False
        for x in range(w):
            a = state[y, x] == ACTIVE
            if a and not inside:
                count += 1
            inside = a
    row_ptr = np.zeros(h + 1, np.int64)
    x0 = np.empty(count, np.int64)
    x1 = np.empty(count, np.int64)
    k = 0
    for y in range(h):
        x = 0
        while x < w:
            if state[y, x] == ACTIVE:
                start = x
                while x < w and state[y, x] == ACTIVE:
                    x += 1
                x0[k] = start
                x1[k] = x
                k += 1
            else:
                x += 1
        row_ptr[y + 1] = k
    return row_ptr, x0, x1


@njit(inline="always", cache=True)
def _normalised(value, inv_scale):
    """A colour value in units of the colour scale (the same rounding in pack and unpack)."""
    return np.float32(np.float64(value) * inv_scale)


@njit(parallel=True, cache=True)
def pack(color, normal, position, state, inv_scale, origin, inv_pos, halo, stride, cbuf_a, cbuf_b, gbuf):
    """Write the interior of the planar buffers (their halo stays zero).

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32
    state : ndarray (H, W) int8
    inv_scale : float
        1 / colour scale.
    origin : ndarray (3,) float64
        Subtracted from positions (keeps float32 differences accurate far from the origin).
    inv_pos : float
        1 / position unit.
    halo, stride : int
    cbuf_a, cbuf_b : ndarray (3, planesize) float32
        Both receive the normalised colour.
    gbuf : ndarray (7, planesize) float32
        Normal (3), position (3), surface mask (1).
    """
    h, w = state.shape
    for y in prange(h):
        base = (y + halo) * stride + halo
        for x in range(w):
            i = base + x
            for c in range(3):
                v = _normalised(color[y, x, c], inv_scale)
                cbuf_a[c, i] = v
                cbuf_b[c, i] = v
                n = min(max(np.float64(normal[y, x, c]), -GUIDE_MAX), GUIDE_MAX)
                gbuf[c, i] = np.float32(n)
                p = (np.float64(position[y, x, c]) - origin[c]) * inv_pos
                gbuf[3 + c, i] = np.float32(min(max(p, -GUIDE_MAX), GUIDE_MAX))
            gbuf[6, i] = np.float32(0.0) if state[y, x] == BACKGROUND else np.float32(1.0)


@njit(inline="always", cache=True)
def _write_change(color, out, y, x, c, filtered, inv_scale, scale):
    """``out[y, x, c] = color + (filtered - normalised color) * scale`` (float64 arithmetic)."""
    v = color[y, x, c]
    delta = np.float64(filtered) - np.float64(_normalised(v, inv_scale))
    out[y, x, c] = np.float32(np.float64(v) + delta * scale)


@njit(inline="always", cache=True, fastmath=True)
def _pair_weights(s0, s1, s2, n0, n1, n2, x0, x1, x2, mask, ip0, iq0, e, e0, n, a_c, a_n, a_x):
    """``e[e0 + j] = m(p) m(q) exp(-(a_c |dc|^2 + a_n |dn|^2 + a_x |dx|^2))`` for ``p = ip0 + j``,
    ``q = iq0 + j``, ``j < n`` (flat plane indices; the weight is symmetric in p and q)."""
    for j in range(n):
        ip = ip0 + j
        iq = iq0 + j
        cr = min(abs(s0[iq] - s0[ip]), DIFF_MAX)
        cg = min(abs(s1[iq] - s1[ip]), DIFF_MAX)
        cb = min(abs(s2[iq] - s2[ip]), DIFF_MAX)
        d0 = n0[iq] - n0[ip]
        d1 = n1[iq] - n1[ip]
        d2 = n2[iq] - n2[ip]
        f0 = x0[iq] - x0[ip]
        f1 = x1[iq] - x1[ip]
        f2 = x2[iq] - x2[ip]
        arg = (a_c * (cr * cr + cg * cg + cb * cb) + a_n * (d0 * d0 + d1 * d1 + d2 * d2)
               + a_x * (f0 * f0 + f1 * f1 + f2 * f2))
        e[e0 + j] = mask[ip] * mask[iq] * fast_exp_minus(arg)


@njit(parallel=True, cache=True, fastmath=True)
def atrous_pass(src, dst, gbuf, row_ptr, run_x0, run_x1, row_surface, halo, stride, step, a_c, a_n, a_x, taps,
                nthreads, final, color, out, inv_scale, scale):
    """One à-trous iteration over the active runs: ``dst = src + sum w (src_q - src) / sum w``.

    The edge-stopping weight of a pair of pixels is symmetric, so it is computed once per pair:
    for each row ``y`` (top to bottom within a band of rows) the weights to the 12 taps of the
    forward half of the 5x5 kernel (``dy > 0``, or ``dy = 0, dx > 0``) are stored in a ring
    buffer of ``2 step + 1`` rows; pixel ``p`` then takes its forward taps from its own row's
    weights and its backward taps ``p - o`` from the weights stored ``dy`` rows earlier. 12
    exponentials per pixel instead of 24. A band first fills the ring with the ``2 step`` rows
    above it (recomputed, not shared between threads).

    Parameters
    ----------
    src, dst : ndarray (3, planesize) float32
        Colour planes of this iteration and the next (only active pixels are written).
    gbuf : ndarray (7, planesize) float32
        Normal, position, surface mask planes.
    row_ptr, run_x0, run_x1 : ndarray int64
        Active runs (see :func:`active_runs`).
    row_surface : ndarray (H,) bool
        Whether a row has any surface pixel (rows of sky need no weights).
    halo, stride, step : int
        Padding, row stride and hole spacing ``2**i`` in pixels.
    a_c, a_n, a_x : float32
        Coefficients of the squared colour, normal and position distances.
    taps : ndarray (25,) float32
        B3-spline kernel.
    nthreads : int
        Parallel workers; the image is cut into ``4 nthreads`` bands of rows dealt round-robin
        (balances sky and ground).
    final : bool
        Last iteration: instead of ``dst``, write ``out = color + (result - normalised color) *
        scale`` for the active pixels (``out`` already holds ``color`` elsewhere). Writing the
        change keeps a constant image exactly constant.
    color, out : ndarray (H, W, 3) float32
    inv_scale, scale : float
        1 / colour scale and colour scale.
    """
    h = row_ptr.shape[0] - 1
    w = color.shape[1]
    s0 = src[0]
    s1 = src[1]
    s2 = src[2]
    o0 = dst[0]
    o1 = dst[1]
    o2 = dst[2]
    n0 = gbuf[0]
    n1 = gbuf[1]
    n2 = gbuf[2]
    x0 = gbuf[3]
    x1 = gbuf[4]
    x2 = gbuf[5]
    mask = gbuf[6]
    nbands = 4 * nthreads
    band = (h + nbands - 1) // nbands
    ring_rows = 2 * step + 1
    for t in prange(nthreads):
        # halo columns stay 0: taps beyond the left/right border get weight 0
        ring = np.zeros((12, ring_rows, stride), np.float32)
        acc = np.empty(4 * CHUNK, np.float32)
        for b in range(t, nbands, nthreads):
            y0 = b * band
            y1 = min(y0 + band, h)
            if y0 < 2 * step:
                ring[:] = 0.0  # rows above the image: weight 0
            for y in range(max(y0 - 2 * step, 0), y1):
                slot = y % ring_rows
                row = (y + halo) * stride + halo
                for xa in range(0, w, CHUNK):
                    n = uint64(min(CHUNK, w - xa))
                    for o in range(12):
                        k = FORWARD_TAPS[o]
                        e = ring[o, slot]
                        if row_surface[y]:
                            off = ((k // 5 - 2) * stride + (k % 5 - 2)) * step
                            _pair_weights(s0, s1, s2, n0, n1, n2, x0, x1, x2, mask, uint64(row + xa),
                                          uint64(row + xa + off), e, uint64(halo + xa), n, a_c, a_n, a_x)
                        else:
                            for j in range(halo + xa, halo + xa + np.int64(n)):
                                e[j] = np.float32(0.0)
                if y < y0:
                    continue
                for r in range(row_ptr[y], row_ptr[y + 1]):
                    xa = run_x0[r]
                    xe = run_x1[r]
                    while xa < xe:
                        n = uint64(min(CHUNK, xe - xa))
                        cb = uint64(row + xa)
                        for j in range(3 * CHUNK):
                            acc[j] = np.float32(0.0)
                        for j in range(3 * CHUNK, 4 * CHUNK):
                            acc[j] = taps[12]  # the centre tap: weight 1, no change
                        for o in range(12):
                            k = FORWARD_TAPS[o]
                            dy = (k // 5 - 2) * step
                            dx = (k % 5 - 2) * step
                            hk = taps[k]  # the kernel is symmetric: h(-o) = h(o)
                            ef = ring[o, slot]
                            eb = ring[o, (y - dy) % ring_rows]
                            qf = uint64(row + xa + dy * stride + dx)
                            qb = uint64(row + xa - dy * stride - dx)
                            jf = uint64(halo + xa)
                            jb = uint64(halo + xa - dx)
                            for j in range(n):
                                ic = cb + j
                                wf = hk * ef[jf + j]
                                wb = hk * eb[jb + j]
                                cr = s0[ic]
                                cg = s1[ic]
                                cbl = s2[ic]
                                acc[j] += wf * (s0[qf + j] - cr) + wb * (s0[qb + j] - cr)
                                acc[CHUNK + j] += wf * (s1[qf + j] - cg) + wb * (s1[qb + j] - cg)
                                acc[2 * CHUNK + j] += wf * (s2[qf + j] - cbl) + wb * (s2[qb + j] - cbl)
                                acc[3 * CHUNK + j] += wf + wb
                        if final:
                            for x in range(xa, xa + np.int64(n)):
                                j = x - xa
                                inv = np.float32(1.0) / acc[3 * CHUNK + j]
                                ic = cb + uint64(j)
                                _write_change(color, out, y, x, 0, s0[ic] + acc[j] * inv, inv_scale, scale)
                                _write_change(color, out, y, x, 1, s1[ic] + acc[CHUNK + j] * inv, inv_scale, scale)
                                _write_change(color, out, y, x, 2, s2[ic] + acc[2 * CHUNK + j] * inv, inv_scale, scale)
                        else:
                            for j in range(n):
                                inv = np.float32(1.0) / acc[3 * CHUNK + j]
                                o0[cb + j] = s0[cb + j] + acc[j] * inv
                                o1[cb + j] = s1[cb + j] + acc[CHUNK + j] * inv
                                o2[cb + j] = s2[cb + j] + acc[2 * CHUNK + j] * inv
                        xa += CHUNK


@njit(parallel=True, cache=True)
def unpack(color, state, cbuf, inv_scale, scale, halo, stride, out):
    """``out = color + (filtered - normalised colour) * scale`` on active pixels, else ``color``.

    Used by the CUDA backend (the CPU backend does this in its last pass).
    """
    h, w = state.shape
    for y in prange(h):
        base = (y + halo) * stride + halo
        for x in range(w):
            for c in range(3):
                if state[y, x] == ACTIVE:
                    _write_change(color, out, y, x, c, cbuf[c, base + x], inv_scale, scale)
                else:
                    out[y, x, c] = color[y, x, c]


class Buffers:
    """Planar buffers for one image size and halo, reused across frames."""

    def __init__(self, height: int, width: int, halo: int, stride: int | None = None):
        self.height, self.width, self.halo = height, width, halo
        self.stride = padded_stride(width, halo) if stride is None else stride
        size = (height + 2 * halo) * self.stride
        self.color = (np.zeros((3, size), np.float32), np.zeros((3, size), np.float32))
        self.guide = np.zeros((7, size), np.float32)
        self.state = np.empty((height, width), np.int8)

    def fits(self, height: int, width: int, halo: int) -> bool:
        return (height, width, halo) == (self.height, self.width, self.halo)


def run(color, normal, position, state, coefficients, taps, scale, origin, pos_unit, buffers):
    """Filter one frame on prepared inputs.

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32
    state : ndarray (H, W) int8
        From :func:`classify`.
    coefficients : ndarray (N, 3) float32
        Per-iteration ``(a_c, a_n, a_x)``.
    taps : ndarray (25,) float32
    scale : float
        Colour scale (1 for raw colour).
    origin : ndarray (3,) float64
    pos_unit : float
        Position unit (1 for world units).
    buffers : Buffers

    Returns
    -------
    out : ndarray (H, W, 3) float32
    stage_ms : dict
        Milliseconds of ``pack`` (and copy of the input) and ``atrous`` (all iterations).
    """
    t0 = time.perf_counter()
    halo, stride = buffers.halo, buffers.stride
    inv_scale = 1.0 / scale
    src, dst = buffers.color
    pack(color, normal, position, state, inv_scale, origin, 1.0 / pos_unit, halo, stride, src, dst, buffers.guide)
    row_ptr, x0, x1 = active_runs(state)
    row_surface = np.any(state != BACKGROUND, axis=1)
    out = color.copy()
    t1 = time.perf_counter()
    threads = get_num_threads()
    last = coefficients.shape[0] - 1
    for i in range(last + 1):
        a_c, a_n, a_x = (np.float32(v) for v in coefficients[i])
        atrous_pass(src, dst, buffers.guide, row_ptr, x0, x1, row_surface, halo, stride, 2**i, a_c, a_n, a_x, taps,
                    threads, i == last, color, out, inv_scale, scale)
        src, dst = dst, src
    t2 = time.perf_counter()
    return out, {"pack": (t1 - t0) * 1e3, "atrous": (t2 - t1) * 1e3}
