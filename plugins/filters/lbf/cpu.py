"""LBF on the CPU (Numba): signals, features + network fused per row, a vectorised filter.

Stages of :class:`Denoiser`:

``signals``
    The variance stand-in when the frame carries none, the frame's position scale, the 13
    planar signals with the planar Haar details (:func:`_signals`, :func:`_haar`: the arithmetic
    of :func:`.kernels.signals_px` and :func:`.kernels.haar_px` row by row), and the filter's
    planar colour and sanitised variance planes, in the passes that read the frame. NaN colour
    is filtered as 0 and +-Inf as +-float32 max (the harness repairs or rejects non-finite
    colour before a filter sees it; this keeps one bad pixel from spreading).
``network``
    Row by row: the 7x7 means (from per-row vertical sums, so no full-frame box buffer), the 36
    secondary features (:func:`_row_features`: the arithmetic of :func:`.kernels.combine_px`,
    bit for bit, in loops along the row that vectorise) and the network (:func:`_row_mlp`:
    that of :func:`.kernels.mlp_px`, with :mod:`.vecmath`'s ``exp`` and ``log1p``); only the
    6 bandwidths are stored.
``bilateral``
    The cross-bilateral filter over rows: float32 distances and weights
    (:func:`harness.kernels.exp_neg`), loops along the row that vectorise, column-padded planes so
    that every tap is an in-bounds load, float32 partial sums per window row added in float64.

Rows (or tiles of a row) are dealt cyclically to ``numba.get_num_threads()`` workers, so the
work of the sky and of the geometry is shared evenly. Every buffer is kept between calls of the
same size (no per-call allocation but the output).
"""

from __future__ import annotations

import math
import time

import numba
import numpy as np
from numba import njit, prange

from harness import kernels

from . import kernels as K
from .features import FEATURE_VAR_FLOOR, Inputs, position_stats
from .vecmath import exp_neg64, log1p64

BLOCK = 256
#: colours above this magnitude are scaled down by a power of two where the float32 filter sums
#: them (the distances use the unscaled colour)
COLOUR_LIMIT = 2.0**100
#: the filter's variance planes are clamped here, so ``var_i + var_j + 1e-10`` is finite and > 0
VAR_PLANE_MAX = 1e38
_FLOAT32_MAX = float(np.finfo(np.float32).max)

_haar_px = njit(cache=True)(K.haar_px)
_combine_px = njit(cache=True)(K.combine_px)
_color_rows_px = njit(cache=True)(K.color_rows_px)
_variance_estimate_px = njit(cache=True)(K.variance_estimate_px)
_clean_variance = njit(cache=True)(K.clean_variance)


@njit(parallel=True, cache=True)
def _color_rows(color, r, dst, slots):
    h, w, _ = color.shape
    for s in prange(slots):
        for i in range(s, h, slots):
            for j in range(w):
                _color_rows_px(i, j, color, r, dst)


@njit(parallel=True, cache=True)
def _variance_estimate(rows, r, out, slots):
    h, w, _ = rows.shape
    for s in prange(slots):
        for i in range(s, h, slots):
            for j in range(w):
                _variance_estimate_px(i, j, rows, r, out)


@njit(parallel=True, cache=True, error_model="numpy")
def _signals(color, variance, position, normal, albedo, vis, has_vis, spp, has_spp, mu0, mu1, mu2,
             inv_scale, sig, aux, pad, cplane, vplane, peaks, slots):
    """:func:`.kernels.signals_px` row by row, in its arithmetic (the same values), with loops
    along the row that vectorise; only ``log1p`` (libm) stays a scalar loop of its own. Also
    writes the filter's colour and variance planes and each row's largest colour magnitude."""
    h, w, _ = color.shape
    fl = K.FEATURE_LIMIT
    vmax = K.VAR_MAX
    for s in prange(slots):
        clip = np.empty((3, w))
        vs = np.empty(w)
        for i in range(s, h, slots):
            cmax = 0.0
            vs[:] = 0.0
            for ch in range(3):
                cl = clip[ch]
                cp_row = cplane[ch, i, pad:pad + w]
                vp_row = vplane[ch, i, pad:pad + w]
                s_n = sig[6 + ch, i]
                s_a = sig[9 + ch, i]
                s_p = sig[3 + ch, i]
                mu = mu0 if ch == 0 else (mu1 if ch == 1 else mu2)
                for j in range(w):
                    c = np.float64(color[i, j, ch])
                    c = c if c > 0.0 else 0.0
                    cl[j] = min(c, vmax)
                    v = np.float64(variance[i, j, ch])
                    v = min(v, vmax) if v > 0.0 else 0.0
                    vs[j] += v / ((1.0 + c) * (1.0 + c))
                    x = np.float64(normal[i, j, ch])
                    s_n[j] = min(max(x, -fl), fl) if x == x else 0.0
                    x = np.float64(albedo[i, j, ch])
                    s_a[j] = min(max(x, -fl), fl) if x == x else 0.0
                    x = (np.float64(position[i, j, ch]) - mu) * inv_scale
                    s_p[j] = min(max(x, -fl), fl) if x == x else 0.0
                    # the filter's planes: colour (NaN -> 0, +-Inf -> +-float32 max), variance
                    c = np.float64(color[i, j, ch])
                    c = min(max(c, -_FLOAT32_MAX), _FLOAT32_MAX) if c == c else 0.0
                    cp_row[j] = c
                    cmax = max(cmax, abs(c))
                    vp_row[j] = min(_clean_variance(np.float64(variance[i, j, ch])), VAR_PLANE_MAX)
            for ch in range(3):  # libm's log1p: a call per element
                cl = clip[ch]
                dst = sig[ch, i]
                for j in range(w):
                    dst[j] = math.log1p(cl[j])
            s_v = sig[12, i]
            for j in range(w):
                fg = 1.0 if (normal[i, j, 0] != 0.0 or normal[i, j, 1] != 0.0
                             or normal[i, j, 2] != 0.0) else 0.0
                aux[i, j, 0] = math.sqrt(vs[j] / 3.0)
                aux[i, j, 1] = fg
                if not has_vis:
                    s_v[j] = fg
            if has_vis:
                for j in range(w):
                    x = np.float64(vis[i, j])
                    s_v[j] = min(max(x, -fl), fl) if x == x else 0.0
            if has_spp:
                for j in range(w):
                    aux[i, j, 2] = 1.0 / max(np.float64(spp[i, j]), 1.0)
            else:
                for j in range(w):
                    aux[i, j, 2] = 1.0
            peaks[i] = cmax


@njit(parallel=True, cache=True)
def _haar(sig, hh, slots):
    """``hh[g, i, j]`` (planar): :func:`.kernels.haar_px` with loops along the row that
    vectorise, in its order of operations (float64 sums; the last column, clamped, by the
    per-pixel body)."""
    h = sig.shape[1]
    w = sig.shape[2]
    hh_px = hh.transpose(1, 2, 0)
    for s in prange(slots):
        acc = np.empty(w)
        for i in range(s, h, slots):
            i1 = min(i + 1, h - 1)
            for g in range(5):
                c0 = 3 * g
                c1 = 13 if g == 4 else 3 * g + 3
                acc[:] = 0.0
                for ch in range(c0, c1):
                    r0 = sig[ch, i]
                    r1 = sig[ch, i1]
                    for j in range(w - 1):
                        a = acc[j] + (np.float64(r0[j]) - np.float64(r0[j + 1]))
                        acc[j] = a + (np.float64(r1[j + 1]) - np.float64(r1[j]))
                dst = hh[g, i]
                for j in range(w - 1):
                    dst[j] = abs(acc[j]) * 0.5 / (c1 - c0)
            _haar_px(i, w - 1, sig, hh_px)


@njit(cache=True)
def _vertical7(sig, aux, i, v):
    """``v[ch, j]``: sums over the clamped rows i-3..i+3 of the signals, squares and aux 0-1.

    One pass per channel with the seven rows summed in registers (in the order of the rows,
    from 0.0, as :func:`.kernels.combine_px` sums them): one store per sum, not seven
    read-modify-writes of the row of sums.
    """
    h = sig.shape[1]
    w = sig.shape[2]
    r0 = max(i - 3, 0)
    r1 = max(i - 2, 0)
    r2 = max(i - 1, 0)
    r3 = i
    r4 = min(i + 1, h - 1)
    r5 = min(i + 2, h - 1)
    r6 = min(i + 3, h - 1)
    for ch in range(K.N_SIG):
        y0 = sig[ch, r0]
        y1 = sig[ch, r1]
        y2 = sig[ch, r2]
        y3 = sig[ch, r3]
        y4 = sig[ch, r4]
        y5 = sig[ch, r5]
        y6 = sig[ch, r6]
        s1 = v[ch]
        s2 = v[K.N_SIG + ch]
        for j in range(w):
            x0 = np.float64(y0[j])
            x1 = np.float64(y1[j])
            x2 = np.float64(y2[j])
            x3 = np.float64(y3[j])
            x4 = np.float64(y4[j])
            x5 = np.float64(y5[j])
            x6 = np.float64(y6[j])
            s1[j] = 0.0 + x0 + x1 + x2 + x3 + x4 + x5 + x6
            s2[j] = 0.0 + x0 * x0 + x1 * x1 + x2 * x2 + x3 * x3 + x4 * x4 + x5 * x5 + x6 * x6
    for k in range(2):
        y0 = aux[r0, :, k]
        y1 = aux[r1, :, k]
        y2 = aux[r2, :, k]
        y3 = aux[r3, :, k]
        y4 = aux[r4, :, k]
        y5 = aux[r5, :, k]
        y6 = aux[r6, :, k]
        dst = v[2 * K.N_SIG + k]
        for j in range(w):
            dst[j] = (0.0 + np.float64(y0[j]) + np.float64(y1[j]) + np.float64(y2[j])
                      + np.float64(y3[j]) + np.float64(y4[j]) + np.float64(y5[j])
                      + np.float64(y6[j]))


@njit(cache=True)
def _horizontal7(v, box):
    """``box[ch, j]``: sums of ``v[ch]`` over the clamped columns j-3..j+3 (vectorised inside)."""
    w = v.shape[1]
    for ch in range(v.shape[0]):
        src = v[ch]
        dst = box[ch]
        if w > 6:  # the seven taps summed in registers, in order from 0.0
            for j in range(3, w - 3):
                dst[j] = (0.0 + src[j - 3] + src[j - 2] + src[j - 1] + src[j] + src[j + 1]
                          + src[j + 2] + src[j + 3])
        for j in list(range(min(3, w))) + list(range(max(w - 3, 3), w)):
            acc = 0.0
            for dj in range(-3, 4):
                acc += src[min(max(j + dj, 0), w - 1)]
            dst[j] = acc


@njit(cache=True, error_model="numpy")
def _tap(v, c, s1, s2, md):
    x = np.float64(v)
    return s1 + x, s2 + x * x, md + abs(x - c)


@njit(cache=True, error_model="numpy")
def _taps9(rm, r0, rp, j, c):
    """Sum, sum of squares and absolute deviation from ``c`` of the 3x3 block at column ``j``
    (rows ``rm, r0, rp``), accumulated in the order of :func:`.kernels.combine_px`."""
    s1 = 0.0
    s2 = 0.0
    md = 0.0
    s1, s2, md = _tap(rm[j - 1], c, s1, s2, md)
    s1, s2, md = _tap(rm[j], c, s1, s2, md)
    s1, s2, md = _tap(rm[j + 1], c, s1, s2, md)
    s1, s2, md = _tap(r0[j - 1], c, s1, s2, md)
    s1, s2, md = _tap(r0[j], c, s1, s2, md)
    s1, s2, md = _tap(r0[j + 1], c, s1, s2, md)
    s1, s2, md = _tap(rp[j - 1], c, s1, s2, md)
    s1, s2, md = _tap(rp[j], c, s1, s2, md)
    s1, s2, md = _tap(rp[j + 1], c, s1, s2, md)
    return s1, s2, md


@njit(cache=True, error_model="numpy")
def _sort2(a, b):
    """``min(a, b), max(a, b)`` for values that are not NaN, as plain selects (vectorise)."""
    lower = a <= b
    return (a if lower else b), (b if lower else a)


@njit(cache=True, error_model="numpy")
def _median9(x0, x1, x2, x3, x4, x5, x6, x7, x8):
    """The 5th smallest of nine values (no NaN), by a min/max network: branch-free, so a loop
    over pixels vectorises; the same value as sorting."""
    x1, x2 = _sort2(x1, x2)
    x4, x5 = _sort2(x4, x5)
    x7, x8 = _sort2(x7, x8)
    x0, x1 = _sort2(x0, x1)
    x3, x4 = _sort2(x3, x4)
    x6, x7 = _sort2(x6, x7)
    x1, x2 = _sort2(x1, x2)
    x4, x5 = _sort2(x4, x5)
    x7, x8 = _sort2(x7, x8)
    # rows sorted; the median is the median of (max of minima, median of medians, min of maxima)
    lo = max(max(x0, x3), x6)
    hi = min(min(x2, x5), x8)
    x4, x7 = _sort2(x4, x7)
    x1, x4 = _sort2(x1, x4)
    x4, x7 = _sort2(x4, x7)
    lo, x4 = _sort2(lo, x4)
    x4, hi = _sort2(x4, hi)
    lo, x4 = _sort2(lo, x4)
    return x4


@njit(cache=True, error_model="numpy")
def _row_features(sig, aux, hh, i, box, acc, feat):
    """``feat[:, j]``: the 36 features of the pixels ``(i, 1 .. w - 2)`` of row ``i``.

    The arithmetic of :func:`.kernels.combine_px` in its order (so the values are identical),
    with loops along the row that vectorise; the border columns 0 and ``w - 1`` (clamped
    windows) are left to the caller. ``hh`` is the planar (5, h, w) Haar detail buffer (rows
    loaded contiguously), ``box`` holds the 7x7 sums of :func:`_horizontal7`; ``acc`` (6, w) is
    scratch.
    """
    h = sig.shape[1]
    w = sig.shape[2]
    im = max(i - 1, 0)
    ip = min(i + 1, h - 1)
    v7 = acc[0]
    v3 = acc[1]
    mad = acc[2]
    grad = acc[3]
    sd7 = acc[4]
    for g in range(5):
        c0 = 3 * g
        c1 = 13 if g == 4 else 3 * g + 3
        n = c1 - c0
        v7[:] = 0.0
        v3[:] = 0.0
        mad[:] = 0.0
        grad[:] = 0.0
        for ch in range(c0, c1):
            b1 = box[ch]
            b2 = box[K.N_SIG + ch]
            rm = sig[ch, im]
            r0 = sig[ch, i]
            rp = sig[ch, ip]
            for j in range(1, w - 1):
                m = b1[j] / 49.0
                v7[j] += max(b2[j] / 49.0 - m * m, 0.0)
                centre = np.float64(r0[j])
                s1, s2, md = _taps9(rm, r0, rp, j, centre)
                mad[j] += md
                m = s1 / 9.0
                v3[j] += max(s2 / 9.0 - m * m, 0.0)
                gx = 0.5 * (np.float64(r0[j + 1]) - np.float64(r0[j - 1]))
                gy = 0.5 * (np.float64(rp[j]) - np.float64(rm[j]))
                grad[j] += gx * gx + gy * gy
        f0 = feat[g]
        f5 = feat[5 + g]
        f10 = feat[10 + g]
        f15 = feat[15 + g]
        f20 = feat[20 + g]
        hm = hh[g, im]
        h0 = hh[g, i]
        hp = hh[g, ip]
        for j in range(1, w - 1):
            f0[j] = math.sqrt(v7[j] / n)
            f5[j] = math.sqrt(v3[j] / n)
            f10[j] = mad[j] / (9.0 * n)
            f15[j] = math.sqrt(grad[j])
            f20[j] = _median9(np.float64(hm[j - 1]), np.float64(hm[j]), np.float64(hm[j + 1]),
                              np.float64(h0[j - 1]), np.float64(h0[j]), np.float64(h0[j + 1]),
                              np.float64(hp[j - 1]), np.float64(hp[j]), np.float64(hp[j + 1])
                              ) / K.HAAR_MAD
        if g == 0:
            for j in range(1, w - 1):
                sd7[j] = math.sqrt(v7[j] / n)
    for j in range(1, w - 1):
        feat[25, j] = (box[0, j] / 49.0 + box[1, j] / 49.0 + box[2, j] / 49.0) / 3.0
        feat[26, j] = (box[9, j] / 49.0 + box[10, j] / 49.0 + box[11, j] / 49.0) / 3.0
        feat[27, j] = box[12, j] / 49.0
        feat[28, j] = (np.float64(sig[0, i, j]) + np.float64(sig[1, i, j])
                       + np.float64(sig[2, i, j])) / 3.0
        feat[29, j] = (np.float64(sig[9, i, j]) + np.float64(sig[10, i, j])
                       + np.float64(sig[11, i, j])) / 3.0
        feat[30, j] = sig[12, i, j]
        s = np.float64(aux[i, j, 0])
        feat[31, j] = s
        feat[32, j] = box[2 * K.N_SIG, j] / 49.0
        feat[33, j] = s / (sd7[j] + 1e-3)
        feat[34, j] = aux[i, j, 2]
        feat[35, j] = box[2 * K.N_SIG + 1, j] / 49.0


@njit(cache=True, error_model="numpy")
def _row_mlp(feat, mean, inv_std, w1, b1, w2, b2, i, z, hidden, a, params):
    """``params[:, i, :]``: the network of :func:`.kernels.mlp_px` on every pixel of row ``i``
    (``feat`` (36, w)), in its order of operations, with loops along the row; ``z`` (36, w),
    ``hidden`` (10, w) and ``a`` (w) are scratch.

    The sigmoid and softplus take ``exp(-|a|)`` and ``log1p`` from :mod:`.vecmath` (a few
    float64 ulps from libm's), so the loops vectorise; the bandwidths agree with
    :func:`.kernels.mlp_px` to float64 round-off, before their rounding to float32.
    """
    nf = w1.shape[1]
    w = feat.shape[1]
    zc = K.Z_CLAMP
    for f in range(nf):
        mu = np.float64(mean[f])
        s = np.float64(inv_std[f])
        src = feat[f]
        dst = z[f]
        for j in range(w):
            x = (src[j] - mu) * s
            dst[j] = min(max(x, -zc), zc) if x == x else 0.0
    for u in range(w1.shape[0]):
        a[:w] = np.float64(b1[u])
        for f in range(nf):
            c = np.float64(w1[u, f])
            src = z[f]
            for j in range(w):
                a[j] += c * src[j]
        hu = hidden[u]
        for j in range(w):
            x = a[j]
            e = exp_neg64(abs(x))
            hu[j] = (1.0 if x >= 0.0 else e) / (1.0 + e)
    for o in range(w2.shape[0]):
        a[:w] = np.float64(b2[o])
        for u in range(w2.shape[1]):
            c = np.float64(w2[o, u])
            src = hidden[u]
            for j in range(w):
                a[j] += c * src[j]
        dst = params[o, i]
        for j in range(w):
            x = a[j]
            dst[j] = max(x, 0.0) + log1p64(exp_neg64(abs(x)))


@njit(parallel=True, cache=True)
def _features_network(sig, aux, hh, hh_px, mean, inv_std, w1, b1, w2, b2, params, feat_out, keep, slots):
    h = sig.shape[1]
    w = sig.shape[2]
    for s in prange(slots):
        v = np.empty((K.N_BOX7, w))
        box = np.empty((K.N_BOX7, w))
        col7 = np.empty(K.N_BOX7)
        med = np.empty(9)
        feat = np.empty((K.N_FEATURES, w))
        acc = np.empty((5, w))
        px = np.empty(K.N_FEATURES)
        z = np.empty((K.N_FEATURES, w))
        hidden = np.empty((K.N_HIDDEN, w))
        a = np.empty(w)
        for i in range(s, h, slots):
            _vertical7(sig, aux, i, v)
            _horizontal7(v, box)
            _row_features(sig, aux, hh, i, box, acc, feat)
            # the border columns (clamped windows): the per-pixel body
            for j in (0, w - 1):
                for ch in range(K.N_BOX7):
                    col7[ch] = box[ch, j] / 49.0
                _combine_px(i, j, sig, aux, hh_px, col7, med, px)
                feat[:, j] = px
            if keep:
                for f in range(K.N_FEATURES):
                    for j in range(w):
                        feat_out[i, j, f] = feat[f, j]
            _row_mlp(feat, mean, inv_std, w1, b1, w2, b2, i, z, hidden, a, params)


@njit(cache=True)
def _filter_tile(sp, cp, vp, inside, params, radius, inv_tau, scale, pad, i, j0, n, cen, part,
                 acc, out):
    """Filter the pixels ``(i, j0 .. j0 + n)`` (see :func:`.kernels.filter_px` for D).

    Every term of D is finite or +Inf, never NaN (bounded features, variance planes <= 1e38,
    colour bandwidth >= 1e-30), and a tap with ``D > 40`` (Inf included) has weight 0. The
    weighted colours are summed as ``colour * scale`` (a power of two, 1 unless the colour
    exceeds 2^100) so that float32 sums cannot overflow.
    """
    h = sp.shape[1]
    a = pad + j0
    f32 = np.float32
    # per-pixel bandwidths of the tile (float32), the feature ones divided by the floor
    p_a = cen[0]
    p_c = cen[1]
    p_p = cen[2]
    p_n = cen[3]
    p_al = cen[4]
    p_v = cen[5]
    wt = cen[6]
    for j in range(n):
        p_a[j] = params[0, i, j0 + j]
        p_c[j] = max(params[1, i, j0 + j], K.MIN_BANDWIDTH)
        p_p[j] = params[2, i, j0 + j] * inv_tau
        p_n[j] = params[3, i, j0 + j] * inv_tau
        p_al[j] = params[4, i, j0 + j] * inv_tau
        p_v[j] = params[5, i, j0 + j] * inv_tau
    x3 = sp[3, i, a:a + n]
    x4 = sp[4, i, a:a + n]
    x5 = sp[5, i, a:a + n]
    x6 = sp[6, i, a:a + n]
    x7 = sp[7, i, a:a + n]
    x8 = sp[8, i, a:a + n]
    x9 = sp[9, i, a:a + n]
    x10 = sp[10, i, a:a + n]
    x11 = sp[11, i, a:a + n]
    x12 = sp[12, i, a:a + n]
    c0 = cp[0, i, a:a + n]
    c1 = cp[1, i, a:a + n]
    c2 = cp[2, i, a:a + n]
    u0 = vp[0, i, a:a + n]
    u1 = vp[1, i, a:a + n]
    u2 = vp[2, i, a:a + n]
    acc[:, :n] = 0.0
    cut = f32(K.D_CUT)
    eps = f32(1e-10)
    for dy in range(-radius, radius + 1):
        ii = i + dy
        if ii < 0 or ii >= h:
            continue
        part[:, :n] = 0.0
        s0 = part[0, :n]
        s1 = part[1, :n]
        s2 = part[2, :n]
        s3 = part[3, :n]
        for dx in range(-radius, radius + 1):
            b = a + dx
            d2 = f32(dy * dy + dx * dx)
            y3 = sp[3, ii, b:b + n]
            y4 = sp[4, ii, b:b + n]
            y5 = sp[5, ii, b:b + n]
            y6 = sp[6, ii, b:b + n]
            y7 = sp[7, ii, b:b + n]
            y8 = sp[8, ii, b:b + n]
            y9 = sp[9, ii, b:b + n]
            y10 = sp[10, ii, b:b + n]
            y11 = sp[11, ii, b:b + n]
            y12 = sp[12, ii, b:b + n]
            q0 = cp[0, ii, b:b + n]
            q1 = cp[1, ii, b:b + n]
            q2 = cp[2, ii, b:b + n]
            w0 = vp[0, ii, b:b + n]
            w1 = vp[1, ii, b:b + n]
            w2 = vp[2, ii, b:b + n]
            m = inside[ii, b:b + n]
            for j in range(n):
                t0 = x3[j] - y3[j]
                t1 = x4[j] - y4[j]
                t2 = x5[j] - y5[j]
                d = p_a[j] * d2 + p_p[j] * (t0 * t0 + t1 * t1 + t2 * t2)
                t0 = x6[j] - y6[j]
                t1 = x7[j] - y7[j]
                t2 = x8[j] - y8[j]
                d += p_n[j] * (t0 * t0 + t1 * t1 + t2 * t2)
                t0 = x9[j] - y9[j]
                t1 = x10[j] - y10[j]
                t2 = x11[j] - y11[j]
                d += p_al[j] * (t0 * t0 + t1 * t1 + t2 * t2)
                t0 = x12[j] - y12[j]
                d += p_v[j] * (t0 * t0)
                e0 = c0[j] - q0[j]
                e1 = c1[j] - q1[j]
                e2 = c2[j] - q2[j]
                # max(., eps) is a no-op (variances >= 0) that lets LLVM vectorise the loop
                d += p_c[j] * (e0 * e0 / max(u0[j] + w0[j] + eps, eps)
                               + e1 * e1 / max(u1[j] + w1[j] + eps, eps)
                               + e2 * e2 / max(u2[j] + w2[j] + eps, eps))
                wt[j] = kernels.exp_neg(d) * m[j] if d <= cut else f32(0.0)
            for j in range(n):
                e = wt[j] * scale
                s0[j] += e * q0[j]
                s1[j] += e * q1[j]
                s2[j] += e * q2[j]
                s3[j] += wt[j]
        for ch in range(4):
            t = acc[ch, :n]
            src = part[ch, :n]
            for j in range(n):
                t[j] += src[j]
    for j in range(n):
        if u0[j] + u1[j] + u2[j] == 0:  # noise-free pixel: copied
            out[i, j0 + j, 0] = c0[j] * scale
            out[i, j0 + j, 1] = c1[j] * scale
            out[i, j0 + j, 2] = c2[j] * scale
        else:  # acc[3] >= 1: the centre tap
            out[i, j0 + j, 0] = acc[0, j] / acc[3, j]
            out[i, j0 + j, 1] = acc[1, j] / acc[3, j]
            out[i, j0 + j, 2] = acc[2, j] / acc[3, j]


@njit(parallel=True, cache=True)
def _filter(sp, cp, vp, inside, params, radius, inv_tau, scale, pad, out, slots):
    h = out.shape[0]
    w = out.shape[1]
    n_blocks = (w + BLOCK - 1) // BLOCK
    items = h * n_blocks
    for s in prange(slots):
        cen = np.empty((7, BLOCK), np.float32)
        part = np.empty((4, BLOCK), np.float32)
        acc = np.empty((4, BLOCK))
        for t in range(s, items, slots):
            i = t // n_blocks
            j0 = (t % n_blocks) * BLOCK
            _filter_tile(sp, cp, vp, inside, params, radius, inv_tau, scale, pad, i, j0,
                         min(BLOCK, w - j0), cen, part, acc, out)


def _buffer(work: dict, name: str, shape: tuple, dtype, zero: bool = False) -> np.ndarray:
    a = work.get(name)
    if a is None or a.shape != shape or a.dtype != dtype:
        a = work[name] = np.zeros(shape, dtype) if zero else np.empty(shape, dtype)
    return a


class Denoiser:
    """The LBF pipeline on the CPU (the ``cpu`` backend's entry point).

    Parameters
    ----------
    model : LBFWeights

    Notes
    -----
    Calling it with ``(inputs, radius)`` returns the output (H, W, 3) float32 and the
    milliseconds of the ``signals``, ``network`` and ``bilateral`` stages. Scratch (about
    ``(13 + 6 + 4) * 4 + 32`` bytes per pixel, plus the column padding of the planes) is kept
    between calls of the same size. With ``keep`` set, the last call's variance, signals,
    features and bandwidths are kept in ``last`` (tests and analysis).
    """

    def __init__(self, model):
        self.model = model
        self.work: dict = {}
        self.keep = False
        self.last: dict = {}

    def __call__(self, inputs: Inputs, radius: int):
        t0 = time.perf_counter_ns()
        sp, cp, vp, inside, pad, hh, aux = self._signals(inputs, radius)
        t1 = time.perf_counter_ns()
        params = self._network(sp[:, :, pad:pad + inputs.shape[1]], aux, hh)
        t2 = time.perf_counter_ns()
        out = np.empty(inputs.shape + (3,), np.float32)
        _filter(sp, cp, vp, inside, params, int(radius), np.float32(1.0 / FEATURE_VAR_FLOOR),
                np.float32(self.work["scale"]), pad, out, numba.get_num_threads())
        if self.work["scale"] != 1.0:
            out /= np.float32(self.work["scale"])
        t3 = time.perf_counter_ns()
        stage_ms = {"signals": (t1 - t0) / 1e6, "network": (t2 - t1) / 1e6,
                    "bilateral": (t3 - t2) / 1e6}
        return out, stage_ms

    def _signals(self, inputs: Inputs, radius: int):
        work = self.work
        slots = numba.get_num_threads()
        h, w = inputs.shape
        pad = max(int(radius), 1)
        wp = w + 2 * pad
        variance = inputs.variance
        if inputs.estimate_variance:
            rows = _buffer(work, "color_rows", (h, w, 6), np.float64)
            _color_rows(inputs.color, K.VAR_RADIUS, rows, slots)
            variance = _buffer(work, "variance", (h, w, 3), np.float32)
            _variance_estimate(rows, K.VAR_RADIUS, variance, slots)
        mu, scale = position_stats(inputs.position, inputs.normal)
        sp = _buffer(work, "sig", (K.N_SIG, h, wp), np.float32, zero=True)
        cp = _buffer(work, "color", (3, h, wp), np.float32, zero=True)
        vp = _buffer(work, "var", (3, h, wp), np.float32, zero=True)
        inside = work.get("inside")
        if inside is None or inside.shape != (h, wp):
            inside = work["inside"] = np.zeros((h, wp), np.float32)
            inside[:, pad:pad + w] = 1.0
        aux = _buffer(work, "aux", (h, w, 3), np.float32)
        peaks = _buffer(work, "peaks", (h,), np.float64)
        _signals(inputs.color, variance, inputs.position, inputs.normal, inputs.albedo, inputs.vis,
                 inputs.has_vis, inputs.spp, inputs.has_spp, float(mu[0]), float(mu[1]),
                 float(mu[2]), 1.0 / scale, sp[:, :, pad:pad + w], aux, pad, cp, vp, peaks, slots)
        work["scale"] = _colour_scale(peaks)
        hh = _buffer(work, "haar", (5, h, w), np.float32)
        _haar(sp[:, :, pad:pad + w], hh, slots)
        if self.keep:
            self.last = {"variance": np.array(variance),
                         "sig": np.moveaxis(sp[:, :, pad:pad + w], 0, -1).copy()}
        return sp, cp, vp, inside, pad, hh, aux

    def _network(self, sig, aux, hh):
        h, w = sig.shape[1:]
        m = self.model
        params = _buffer(self.work, "params", (K.N_OUT, h, w), np.float32)
        feat = np.empty((h, w, K.N_FEATURES), np.float32) if self.keep else \
            np.empty((1, 1, 1), np.float32)
        _features_network(sig, aux, hh, hh.transpose(1, 2, 0), m.mean, m.inv_std, m.w1, m.b1, m.w2, m.b2, params, feat,
                          self.keep, numba.get_num_threads())
        if self.keep:
            self.last["features"] = feat
            self.last["params"] = np.moveaxis(params, 0, -1).copy()
        return params


def _colour_scale(peaks: np.ndarray) -> float:
    """1, or the power of two that brings the largest colour magnitude under 2^100."""
    cmax = float(peaks.max(initial=0.0))
    if cmax <= COLOUR_LIMIT:
        return 1.0
    return 2.0 ** (100 - math.ceil(math.log2(min(cmax, _FLOAT32_MAX))))
