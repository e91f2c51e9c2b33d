"""CPU kernels of SBF (Numba): the candidate bank with its SURE, and smoothing + selection.

Images are planar float32 (C, H, W). Work is split into tiles of one row by ``BLOCK`` pixels;
inner loops run along the row so that they vectorise. Sums are float64. Tiles without a noisy
pixel are skipped (their pixels keep the input).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

BLOCK = 256
# exp(-d) is evaluated as (exp(-d / 2^10))^(2^10), d clamped at 128 (exp(-128) < 3e-56)
_EXP_CLAMP = 128.0
_EXP_SCALE = 1.0 / 1024.0


@njit(cache=True, fastmath=True)
def exp_neg(d):
    """``exp(-d)`` for ``d >= 0`` in float64 with mul/add only, so that loops vectorise.

    A degree-7 Taylor polynomial on ``[-1/8, 0]`` and ten squarings; relative error < 2e-9
    for ``d <= 128``, and ``exp(-128)`` for larger ``d``.
    """
    x = -min(d, _EXP_CLAMP) * _EXP_SCALE
    p = 1.0 + x * (1.0 + x * (0.5 + x * (1.0 / 6.0 + x * (1.0 / 24.0 + x * (
        1.0 / 120.0 + x * (1.0 / 720.0 + x * (1.0 / 5040.0)))))))
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    p = p * p
    return p * p


@njit(cache=True, fastmath=True)
def _feature_distance(feat, i, ii, ja, dx, n, dist):
    """``dist[:n] = |f(i, ja + j) - f(ii, ja + j + dx)|^2`` for j < n."""
    for j in range(n):
        dist[j] = 0.0
    for c in range(feat.shape[0]):
        # 1-D views indexed by a range variable: no negative-index wraparound, loops vectorise
        a = feat[c, i, ja:ja + n]
        b = feat[c, ii, ja + dx:ja + dx + n]
        for j in range(n):
            e = a[j] - b[j]
            dist[j] += e * e


@njit(cache=True)
def _tile_is_noisy(noisy, i, j0, j1):
    for j in range(j0, j1):
        if noisy[i, j]:
            return True
    return False


@njit(parallel=True, cache=True, fastmath=True)
def candidate_bank(color, var, feat, noisy, table, first, out_f, out_sure):
    """Every candidate's filtered colour and per-pixel SURE.

    Parameters
    ----------
    color, var : ndarray (3, H, W) float32
        Noisy colour and variance of the pixel mean.
    feat : ndarray (C, H, W) float32
        Scaled guide features (:func:`.features.guide_features`).
    noisy : ndarray (H, W) uint8
        Pixels to filter; the others keep the input and get SURE 0.
    table, first : ndarray
        From :func:`.bank.spatial_table`.
    out_f : ndarray (K, 3, H, W) float32
        Filtered colour of each candidate (written).
    out_sure : ndarray (K, H, W) float64
        SURE of each candidate, mean over RGB (written).
    """
    n_k = table.shape[0]
    big = (table.shape[1] - 1) // 2
    h, w = noisy.shape
    n_blocks = (w + BLOCK - 1) // BLOCK
    for t in prange(h * n_blocks):
        i = t // n_blocks
        j0 = (t - i * n_blocks) * BLOCK
        j1 = min(j0 + BLOCK, w)
        acc = np.zeros((n_k, 4, BLOCK))
        if _tile_is_noisy(noisy, i, j0, j1):
            dist = np.empty(BLOCK, np.float32)
            wgt = np.empty(BLOCK)
            for dy in range(-big, big + 1):
                ii = i + dy
                if ii < 0 or ii >= h:
                    continue
                for dx in range(-big, big + 1):
                    ja = max(j0, -dx)
                    jb = min(j1, w - dx)
                    if ja >= jb:
                        continue
                    n = jb - ja
                    off = ja - j0
                    _feature_distance(feat, i, ii, ja, dx, n, dist)
                    c0 = color[0, ii, ja + dx:jb + dx]
                    c1 = color[1, ii, ja + dx:jb + dx]
                    c2 = color[2, ii, ja + dx:jb + dx]
                    for j in range(n):
                        wgt[j] = exp_neg(dist[j])
                    for k in range(first[max(abs(dy), abs(dx))], n_k):
                        g = table[k, dy + big, dx + big]
                        a0 = acc[k, 0, off:off + n]
                        a1 = acc[k, 1, off:off + n]
                        a2 = acc[k, 2, off:off + n]
                        a3 = acc[k, 3, off:off + n]
                        for j in range(n):
                            e = g * wgt[j]
                            a0[j] += e * c0[j]
                            a1[j] += e * c1[j]
                            a2[j] += e * c2[j]
                            a3[j] += e
        for j in range(j0, j1):
            for k in range(n_k):
                if not noisy[i, j]:
                    for ch in range(3):
                        out_f[k, ch, i, j] = color[ch, i, j]
                    out_sure[k, i, j] = 0.0
                    continue
                wsum = acc[k, 3, j - j0]  # >= 1: the centre tap
                risk = 0.0
                for ch in range(3):
                    f = acc[k, ch, j - j0] / wsum
                    y = np.float64(color[ch, i, j])
                    v = np.float64(var[ch, i, j])
                    out_f[k, ch, i, j] = f
                    risk += (f - y) * (f - y) + 2.0 * v / wsum - v
                out_sure[k, i, j] = risk / 3.0


@njit(parallel=True, cache=True, fastmath=True)
def smooth_and_select(color, feat, noisy, table, f_bank, sure, out, best, min_sure):
    """Smooth every SURE map with a feature-only cross-bilateral filter; take the argmin.

    Parameters
    ----------
    color : ndarray (3, H, W) float32
    feat : ndarray (C, H, W) float32
    noisy : ndarray (H, W) uint8
        Only noisy neighbours enter the smoothing; other pixels keep the input.
    table : ndarray (2r+1, 2r+1) float64
        Spatial weights of the smoothing filter.
    f_bank : ndarray (K, 3, H, W) float32
    sure : ndarray (K, H, W) float64
    out : ndarray (3, H, W) float32
        The selected candidate's colour (written).
    best : ndarray (H, W) int32
        Index of the selected candidate (lowest index on ties; written).
    min_sure : ndarray (H, W) float64
        The smoothed SURE of the selected candidate (written).
    """
    n_k = sure.shape[0]
    rad = (table.shape[0] - 1) // 2
    h, w = noisy.shape
    n_blocks = (w + BLOCK - 1) // BLOCK
    for t in prange(h * n_blocks):
        i = t // n_blocks
        j0 = (t - i * n_blocks) * BLOCK
        j1 = min(j0 + BLOCK, w)
        acc = np.zeros((n_k, BLOCK))
        wsum = np.zeros(BLOCK)
        if _tile_is_noisy(noisy, i, j0, j1):
            dist = np.empty(BLOCK, np.float32)
            wgt = np.empty(BLOCK)
            for dy in range(-rad, rad + 1):
                ii = i + dy
                if ii < 0 or ii >= h:
                    continue
                for dx in range(-rad, rad + 1):
                    ja = max(j0, -dx)
                    jb = min(j1, w - dx)
                    if ja >= jb:
                        continue
                    n = jb - ja
                    off = ja - j0
                    g = table[dy + rad, dx + rad]
                    _feature_distance(feat, i, ii, ja, dx, n, dist)
                    valid = noisy[ii, ja + dx:jb + dx]
                    ws = wsum[off:off + n]
                    for j in range(n):
                        e = g * exp_neg(dist[j]) * valid[j]
                        wgt[j] = e
                        ws[j] += e
                    for k in range(n_k):
                        src = sure[k, ii, ja + dx:jb + dx]
                        a = acc[k, off:off + n]
                        for j in range(n):
                            a[j] += wgt[j] * src[j]
        for j in range(j0, j1):
            pick = 0
            low = 0.0
            if noisy[i, j]:
                norm = wsum[j - j0]  # >= 1: the centre tap
                low = acc[0, j - j0] / norm
                for k in range(1, n_k):
                    value = acc[k, j - j0] / norm
                    if value < low:
                        low = value
                        pick = k
                for ch in range(3):
                    out[ch, i, j] = f_bank[pick, ch, i, j]
            else:
                for ch in range(3):
                    out[ch, i, j] = color[ch, i, j]
            best[i, j] = pick
            min_sure[i, j] = low


@njit(parallel=True, cache=True, fastmath=True)
def spatial_variance(color, feat, radius, unknown, out):
    """Estimate the per-sample colour variance from a feature-weighted neighbourhood.

    For each pixel with ``unknown`` set, the unbiased weighted variance
    ``sum w (y - m)^2 / (sum w - sum w^2 / sum w)`` over the ``(2 radius + 1)^2`` window, with
    feature weights ``exp(-|f_i - f_j|^2)``, is written to ``out[:, i, j]`` (float32, clamped
    to the float32 range); 0 where the window holds no other pixel of the same surface.

    Parameters
    ----------
    color : ndarray (3, H, W) float32
    feat : ndarray (C, H, W) float32
    radius : int
    unknown : ndarray (H, W) uint8
    out : ndarray (3, H, W) float32
        Written where ``unknown``; left as is elsewhere.
    """
    h, w = unknown.shape
    big = np.float64(np.finfo(np.float32).max)
    n_blocks = (w + BLOCK - 1) // BLOCK
    for t in prange(h * n_blocks):
        i = t // n_blocks
        j0 = (t - i * n_blocks) * BLOCK
        j1 = min(j0 + BLOCK, w)
        if not _tile_is_noisy(unknown, i, j0, j1):
            continue
        # rows: sum w, sum w^2, sum w y (RGB), sum w y^2 (RGB)
        acc = np.zeros((8, BLOCK))
        dist = np.empty(BLOCK, np.float32)
        for dy in range(-radius, radius + 1):
            ii = i + dy
            if ii < 0 or ii >= h:
                continue
            for dx in range(-radius, radius + 1):
                ja = max(j0, -dx)
                jb = min(j1, w - dx)
                if ja >= jb:
                    continue
                n = jb - ja
                off = ja - j0
                _feature_distance(feat, i, ii, ja, dx, n, dist)
                c0 = color[0, ii, ja + dx:jb + dx]
                c1 = color[1, ii, ja + dx:jb + dx]
                c2 = color[2, ii, ja + dx:jb + dx]
                sw = acc[0, off:off + n]
                sw2 = acc[1, off:off + n]
                s0 = acc[2, off:off + n]
                s1 = acc[3, off:off + n]
                s2 = acc[4, off:off + n]
                q0 = acc[5, off:off + n]
                q1 = acc[6, off:off + n]
                q2 = acc[7, off:off + n]
                for j in range(n):
                    e = exp_neg(dist[j])
                    y0 = np.float64(c0[j])
                    y1 = np.float64(c1[j])
                    y2 = np.float64(c2[j])
                    sw[j] += e
                    sw2[j] += e * e
                    s0[j] += e * y0
                    s1[j] += e * y1
                    s2[j] += e * y2
                    q0[j] += e * y0 * y0
                    q1[j] += e * y1 * y1
                    q2[j] += e * y2 * y2
        for j in range(j0, j1):
            if not unknown[i, j]:
                continue
            a = acc[:, j - j0]
            denom = a[0] - a[1] / a[0]  # a[0] >= 1: the centre tap
            for ch in range(3):
                v = 0.0
                if denom > 1e-3:
                    v = min(max(a[5 + ch] - a[2 + ch] * a[2 + ch] / a[0], 0.0) / denom, big)
                out[ch, i, j] = v
