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

from .schedule import TASK_ROWS, take
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
# then the current tap's weights
_GX, _GY, _EPS, _WT = (np.uint64(k * CHUNK) for k in range(4))


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _tap(i, y, dx, dy, j0, n, o, mom, valid, depth, normal, cen, sn, sums):
    """Add tap ``(dy, dx)`` of the 7x7 window to the sums of the ``n`` centres of row ``i`` from
    column ``j0``, which are at ``o`` in the chunk's scratch (``y = i + dy``; the tap's columns
    ``j + dx`` are inside the image)."""
    nsig = mom.shape[0]
    dxf = np.float32(dx)
    dyf = np.float32(dy)
    centre = abs(dx) + abs(dy)  # 0 at the centre (an int: bool variables cost the noalias)
    # unsigned column indices: a signed index makes Numba emit wraparound code (no vectors)
    for t in range(n):
        j = uint64(j0) + t
        q = uint64(j0 + dx) + t
        k = o + t
        m = np.float32(valid[y, q])
        if centre == 0:
            wt = m
        else:
            d = (normal[0, i, j] * normal[0, y, q] + normal[1, i, j] * normal[1, y, q]
                 + normal[2, i, j] * normal[2, y, q])
            den = abs(cen[_GX + k] * dxf + cen[_GY + k] * dyf) + cen[_EPS + k]
            dist = min(abs(depth[i, j] - depth[y, q]), _ARG_MAX * den) / den
            wt = m * np.float32(d > 0.0) * expneg(-(dist + sn * neg_log_series(d)))
        cen[_WT + k] = wt
    # the float64 sums in a loop of their own: together with them the float32 weights above
    # would be computed at the float64 vector width (half as many lanes)
    for t in range(n):
        q = uint64(j0 + dx) + t
        k = o + t
        w64 = np.float64(cen[_WT + k])
        sums[_SW + k] += w64
        sums[_S10 + k] += w64 * mom[0, 0, y, q]
        sums[_S20 + k] += w64 * mom[0, 1, y, q]
        if nsig == 2:
            sums[_S11 + k] += w64 * mom[1, 0, y, q]
            sums[_S21 + k] += w64 * mom[1, 1, y, q]


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
    parallel workers taking tasks of rows from a shared counter, :mod:`.schedule`).

    The parallel body holds no bool variable and no array view (Numba's alias analysis would
    take either for an alias and drop the ``noalias`` that lets LLVM vectorize the tap loops).
    """
    nsig = mom.shape[0]
    h = valid.shape[0]
    w = valid.shape[1]
    sn = np.float32(sigma_n)
    tasks = -(-h // TASK_ROWS)
    counter = np.zeros(1, np.int64)
    for _ in prange(max(min(nthreads, tasks), 1)):
        sums = np.empty(5 * CHUNK, np.float64)
        cen = np.empty(4 * CHUNK, np.float32)
        while True:
            task = take(counter)
            if task >= tasks:
                break
            for i in range(task * TASK_ROWS, min(task * TASK_ROWS + TASK_ROWS, h)):
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
                        for y in range(max(i - SPATIAL_RADIUS, 0), min(i + SPATIAL_RADIUS + 1, h)):
                            for dx in range(-SPATIAL_RADIUS, SPATIAL_RADIUS + 1):
                                j0 = max(c0, -dx)
                                j1 = min(c1, w - dx)
                                if j0 < j1:
                                    _tap(i, y, dx, y - i, j0, uint64(j1 - j0), uint64(j0 - c0), mom, valid, depth,
                                         normal, cen, sn, sums)
                        for j in range(c0, c1):
                            k = j - c0
                            inv = 1.0 / sums[k]
                            for s in range(nsig):
                                m1 = sums[(1 + 2 * s) * CHUNK + k] * inv
                                var[s, i, j] = max(sums[(2 + 2 * s) * CHUNK + k] * inv - m1 * m1, 0.0)
