"""Row-vectorized luminance variance for the ``cpu`` backend.

The same estimate as :func:`plugins.filters.svgf.variance.variance_pixel`: temporal
``mu2 - mu1^2`` where the history is long enough, else the 7x7 depth- and normal-weighted
spatial estimate. Rows without a short-history pixel skip the spatial sums; other rows sweep
each run of short-history pixels with one branch-free loop per tap that computes the float32
weight (:func:`.weights.expneg` of the depth and normal terms, as the à-trous iterations) and
adds it, times each signal's moments, to float64 sums. The centre's depth slope and epsilon
are bounded once per row, so every exponent stays finite without a test in the tap loops.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange, uint64

from harness import kernels

from .params import TASK_ROWS
from .variance import SPATIAL_RADIUS
from .weights import expneg, neg_log_series

_TINY = np.float32(1e-20)
_ARG_MAX = np.float32(1024.0)
#: bound of the centre's depth slope and epsilon terms (depths are at most 1e30)
_SLOPE_MAX = 1.0e30


#: centres of a row summed together (their sums stay in L1)
CHUNK = 256
# regions (of CHUNK values) of the float64 sums: weight, then per signal mu1 and mu2
_SW, _S10, _S20, _S11, _S21 = (np.uint64(k * CHUNK) for k in range(5))
# regions of the float32 centre terms: sigma_z times the depth slope (x, y), depth epsilon;
# then the weights of the 7 taps of one row of the window (dx = -3 .. 3)
_GX, _GY, _EPS, _WT = (np.uint64(k * CHUNK) for k in range(4))
_CEN_REGIONS = 3 + 2 * SPATIAL_RADIUS + 1


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _tap_weights(i, y, dx, dy, j0, n, o, valid, depth, normal, cen, sn, region):
    """The float32 weights of tap ``(dy, dx)`` of the 7x7 window for the ``n`` centres of row
    ``i`` from column ``j0`` (``y = i + dy``; the tap's columns ``j + dx`` are inside the image),
    into ``cen[region + o ...]`` (``o``: the first centre's place in the chunk)."""
    dxf = np.float32(dx)
    dyf = np.float32(dy)
    centre = abs(dx) + abs(dy)  # 0 at the centre (an int: bool variables cost the noalias)
    # unsigned column indices: a signed index makes Numba emit wraparound code (no vectors)
    for t in range(n):
        j = uint64(j0) + t
        q = uint64(j0 + dx) + t
        k = o + t
        m = np.float32(valid[y, q] == valid[i, j])  # a neighbour of the centre's kind (never background)
        if centre == 0:
            wt = m
        else:
            d = (normal[0, i, j] * normal[0, y, q] + normal[1, i, j] * normal[1, y, q]
                 + normal[2, i, j] * normal[2, y, q])
            den = abs(cen[_GX + k] * dxf + cen[_GY + k] * dyf) + cen[_EPS + k]
            dist = min(abs(depth[i, j] - depth[y, q]), _ARG_MAX * den) / den
            wt = m * np.float32(d > 0.0) * expneg(-(dist + sn * neg_log_series(d)))
        cen[region + k] = wt


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _tap_sums(y, dx, j0, n, o, mom, cen, region, sums):
    """Add one tap's weights (:func:`_tap_weights`), times each signal's moments, to the float64
    sums (a loop of its own: with them, the float32 weights would be computed at the float64
    vector width, half as many lanes)."""
    nsig = mom.shape[0]
    for t in range(n):
        q = uint64(j0 + dx) + t
        k = o + t
        w64 = np.float64(cen[region + k])
        sums[_SW + k] += w64
        sums[_S10 + k] += w64 * mom[0, 0, y, q]
        sums[_S20 + k] += w64 * mom[0, 1, y, q]
        if nsig == 2:
            sums[_S11 + k] += w64 * mom[1, 0, y, q]
            sums[_S21 + k] += w64 * mom[1, 1, y, q]


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _dot7(w0, w1, w2, w3, w4, w5, w6, mom, s, m, y, q):
    """``sum_k w_k mom[s, m, y, q + k]`` for ``k = 0 .. 6``."""
    one = uint64(1)  # (uint64 plus an int literal would be a float64 in Numba)
    q1 = q + one
    q2 = q1 + one
    q3 = q2 + one
    q4 = q3 + one
    q5 = q4 + one
    q6 = q5 + one
    return (((w0 * mom[s, m, y, q] + w1 * mom[s, m, y, q1]) + (w2 * mom[s, m, y, q2] + w3 * mom[s, m, y, q3]))
            + ((w4 * mom[s, m, y, q4] + w5 * mom[s, m, y, q5]) + w6 * mom[s, m, y, q6]))


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _row_sums(y, j0, n, mom, cen, sums):
    """Add the 7 taps of row ``y`` of the window (weights at ``_WT``, one region per ``dx``) to
    the sums of ``n`` centres from column ``j0``, all 7 in one loop (the sums are loaded and
    stored once for 7 taps); every tap column must be inside the image."""
    nsig = mom.shape[0]
    r1 = _WT + uint64(CHUNK)
    r2 = r1 + uint64(CHUNK)
    r3 = r2 + uint64(CHUNK)
    r4 = r3 + uint64(CHUNK)
    r5 = r4 + uint64(CHUNK)
    r6 = r5 + uint64(CHUNK)
    for t in range(n):
        q = uint64(j0 - SPATIAL_RADIUS) + t
        w0 = np.float64(cen[_WT + t])
        w1 = np.float64(cen[r1 + t])
        w2 = np.float64(cen[r2 + t])
        w3 = np.float64(cen[r3 + t])
        w4 = np.float64(cen[r4 + t])
        w5 = np.float64(cen[r5 + t])
        w6 = np.float64(cen[r6 + t])
        sums[_SW + t] += ((w0 + w1) + (w2 + w3)) + ((w4 + w5) + w6)
        sums[_S10 + t] += _dot7(w0, w1, w2, w3, w4, w5, w6, mom, 0, 0, y, q)
        sums[_S20 + t] += _dot7(w0, w1, w2, w3, w4, w5, w6, mom, 0, 1, y, q)
        if nsig == 2:
            sums[_S11 + t] += _dot7(w0, w1, w2, w3, w4, w5, w6, mom, 1, 0, y, q)
            sums[_S21 + t] += _dot7(w0, w1, w2, w3, w4, w5, w6, mom, 1, 1, y, q)


@njit(cache=True)
def _temporal_row(mom, hist, valid, variance_frames, i, var):
    """Temporal variance of row ``i`` where the history is long enough, 0 off the surface;
    returns the number of short-history pixels."""
    short = 0
    for j in range(valid.shape[1]):
        if valid[i, j] != 0:
            if hist[i, j] >= variance_frames:
                for s in range(mom.shape[0]):
                    m1 = mom[s, 0, i, j]
                    var[s, i, j] = max(mom[s, 1, i, j] - m1 * m1, 0.0)
            else:
                short += 1
        else:
            for s in range(mom.shape[0]):
                var[s, i, j] = 0.0
    return short


@njit(cache=True)
def _next_run(valid, hist, variance_frames, i, start):
    """The next run ``[a, b)`` of short-history surface pixels of row ``i`` from ``start``
    (``a == width`` when there is none)."""
    w = valid.shape[1]
    a = start
    while a < w and not (valid[i, a] != 0 and hist[i, a] < variance_frames):
        a += 1
    b = a
    while b < w and valid[i, b] != 0 and hist[i, b] < variance_frames:
        b += 1
    return a, b


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def variance_rows(mom, hist, valid, depth, normal, grad, variance_frames, sigma_z, sigma_n, depth_eps, var,
                  nthreads):
    """Luminance variance of every signal (arguments as ``variance_pixel``, no i, j; ``nthreads``
    parallel workers taking tasks of rows from a shared counter, :func:`harness.kernels.take_range`).

    The parallel body holds no bool variable and no array view (Numba's alias analysis would
    take either for an alias and drop the ``noalias`` that lets LLVM vectorize the tap loops).
    """
    nsig = mom.shape[0]
    h = valid.shape[0]
    w = valid.shape[1]
    sn = np.float32(sigma_n)
    counter = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        sums = np.empty(5 * CHUNK, np.float64)
        cen = np.empty(_CEN_REGIONS * CHUNK, np.float32)
        while True:
            start, stop = kernels.take_range(counter, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                if _temporal_row(mom, hist, valid, variance_frames, i, var) == 0:
                    continue
                # sweep each run [a, b) of consecutive short-history pixels only (a camera pan
                # adds a thin column of them to every row), CHUNK centres at a time
                b = 0
                while b < w:
                    a, b = _next_run(valid, hist, variance_frames, i, b)
                    for c0 in range(a, b, CHUNK):
                        c1 = min(c0 + CHUNK, b)
                        for k in range(5 * CHUNK):
                            sums[k] = 0.0
                        # the centre's depth terms, bounded so that every ratio below is finite
                        for j in range(c0, c1):
                            k = uint64(j - c0)
                            cen[_GX + k] = np.float32(min(max(sigma_z * np.float64(grad[0, i, j]), -_SLOPE_MAX),
                                                          _SLOPE_MAX))
                            cen[_GY + k] = np.float32(min(max(sigma_z * np.float64(grad[1, i, j]), -_SLOPE_MAX),
                                                          _SLOPE_MAX))
                            cen[_EPS + k] = (np.float32(min(depth_eps * abs(np.float64(depth[i, j])), _SLOPE_MAX))
                                             + _TINY)
                        inside = np.int64(c0 >= SPATIAL_RADIUS) * np.int64(c1 + SPATIAL_RADIUS <= w)
                        for y in range(max(i - SPATIAL_RADIUS, 0), min(i + SPATIAL_RADIUS + 1, h)):
                            for dx in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
                                j0 = max(c0, -dx)
                                j1 = min(c1, w - dx)
                                if j0 < j1:
                                    region = _WT + uint64((dx + SPATIAL_RADIUS) * CHUNK)
                                    _tap_weights(i, y, dx, y - i, j0, uint64(j1 - j0), uint64(j0 - c0), valid,
                                                 depth, normal, cen, sn, region)
                                    if inside == 0:  # at the image's left or right border: tap by tap
                                        _tap_sums(y, dx, j0, uint64(j1 - j0), uint64(j0 - c0), mom, cen, region,
                                                  sums)
                            if inside != 0:
                                _row_sums(y, c0, uint64(c1 - c0), mom, cen, sums)
                        for j in range(c0, c1):
                            k = j - c0
                            inv = 1.0 / sums[k]
                            for s in range(nsig):
                                m1 = sums[(1 + 2 * s) * CHUNK + k] * inv
                                var[s, i, j] = max(sums[(2 + 2 * s) * CHUNK + k] * inv - m1 * m1, 0.0)
