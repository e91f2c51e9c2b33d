"""Per-pixel bodies of LBF's feature extraction, network and filter.

Each function here is plain Python over scalars and arrays, computing the result of one pixel
``(i, j)``. :mod:`.features`, :mod:`.mlp` and :mod:`.filter_cpu` compile them with
``numba.njit`` and loop over pixels in parallel; :mod:`.cuda` compiles the very same functions
as ``numba.cuda`` device functions and calls them from one thread per pixel. Sharing the bodies
is what makes the two backends agree.

Layout of the 13 "signal" channels ``sig`` (float32, H x W x 13): ``log1p(color)`` (0-2),
normalised position (3-5), normal (6-8), albedo (9-11), visibility (12). Channels 3-12 are the
primary features the filter compares. Statistics are taken per group: colour 0-2, position 3-5,
normal 6-8, albedo 9-11, visibility 12. ``aux`` (H x W x 3): sample deviation of the colour
signal, foreground mask, 1/spp. Image borders are clamped (replicated) for the statistics; the
filter skips taps outside the image.
"""

from __future__ import annotations

import math

from numba import float64 as f64

#: number of signal channels, and the row-box output width (means + squares + aux)
N_SIG = 13
N_BOX7 = 2 * N_SIG + 2
N_BOX3 = 2 * N_SIG
N_FEATURES = 36
N_HIDDEN = 10
N_OUT = 6
HAAR_MAD = 0.6745
#: z-normalised features are clamped to +-Z_CLAMP (the sigmoid saturates long before)
Z_CLAMP = 1e6
#: radius of the window of the spatial variance estimate (used when a frame has no variance)
VAR_RADIUS = 2
#: filter taps with D above this have negligible weight (exp(-40) = 4e-18) and are skipped
D_CUT = 40.0
#: largest variance estimate kept (float32 range)
VAR_MAX = 3e38


def color_rows_px(i, j, color, r, dst):
    """Horizontal sums (clamped window 2r+1) of the colour (0-2) and its square (3-5)."""
    w = color.shape[1]
    for ch in range(3):
        s1 = 0.0
        s2 = 0.0
        for k in range(-r, r + 1):
            jj = min(max(j + k, 0), w - 1)
            x = f64(color[i, jj, ch])
            s1 += x
            s2 += x * x
        dst[i, j, ch] = s1
        dst[i, j, 3 + ch] = s2


def variance_estimate_px(i, j, rows, r, out):
    """Spatial stand-in for the variance of the pixel mean: the colour's variance over the
    clamped (2r+1)^2 window (from the row sums of :func:`color_rows_px`)."""
    h = rows.shape[0]
    n = (2 * r + 1) * (2 * r + 1)
    for ch in range(3):
        s1 = 0.0
        s2 = 0.0
        for k in range(-r, r + 1):
            ii = min(max(i + k, 0), h - 1)
            s1 += rows[ii, j, ch]
            s2 += rows[ii, j, 3 + ch]
        m = s1 / n
        out[i, j, ch] = min(max(s2 / n - m * m, 0.0), VAR_MAX)


def signals_px(i, j, color, variance, position, normal, albedo, vis, has_vis, spp, has_spp,
               mu0, mu1, mu2, inv_scale, sig, aux):
    """Signal channels and ``aux`` of pixel (i, j)."""
    n0 = normal[i, j, 0]
    n1 = normal[i, j, 1]
    n2 = normal[i, j, 2]
    fg = 1.0 if (n0 != 0.0 or n1 != 0.0 or n2 != 0.0) else 0.0
    vs = 0.0
    for ch in range(3):
        c = max(f64(color[i, j, ch]), 0.0)
        sig[i, j, ch] = math.log1p(c)
        v = max(f64(variance[i, j, ch]), 0.0)
        vs += v / ((1.0 + c) * (1.0 + c))
        sig[i, j, 6 + ch] = normal[i, j, ch]
        sig[i, j, 9 + ch] = albedo[i, j, ch]
    sig[i, j, 3] = (f64(position[i, j, 0]) - mu0) * inv_scale
    sig[i, j, 4] = (f64(position[i, j, 1]) - mu1) * inv_scale
    sig[i, j, 5] = (f64(position[i, j, 2]) - mu2) * inv_scale
    if has_vis:
        sig[i, j, 12] = vis[i, j]
    else:
        sig[i, j, 12] = fg
    aux[i, j, 0] = math.sqrt(vs / 3.0)
    aux[i, j, 1] = fg
    if has_spp:
        aux[i, j, 2] = 1.0 / max(f64(spp[i, j]), 1.0)
    else:
        aux[i, j, 2] = 1.0


def haar_px(i, j, sig, hh):
    """|HH| Haar detail coefficient of each group's channel mean at the 2x2 block at (i, j)."""
    h = sig.shape[0]
    w = sig.shape[1]
    i1 = min(i + 1, h - 1)
    j1 = min(j + 1, w - 1)
    for g in range(5):
        c0 = 3 * g
        c1 = 13 if g == 4 else 3 * g + 3
        a = 0.0
        for ch in range(c0, c1):
            a += f64(sig[i, j, ch]) - f64(sig[i, j1, ch])
            a += f64(sig[i1, j1, ch]) - f64(sig[i1, j, ch])
        hh[i, j, g] = abs(a) * 0.5 / (c1 - c0)


def box_rows_px(i, j, sig, aux, r, n_aux, dst):
    """Horizontal box sums (clamped, width 2r+1) of the signals, their squares and ``n_aux`` aux."""
    w = sig.shape[1]
    for ch in range(N_SIG):
        s1 = 0.0
        s2 = 0.0
        for k in range(-r, r + 1):
            jj = min(max(j + k, 0), w - 1)
            x = f64(sig[i, jj, ch])
            s1 += x
            s2 += x * x
        dst[i, j, ch] = s1
        dst[i, j, N_SIG + ch] = s2
    for a in range(n_aux):
        s1 = 0.0
        for k in range(-r, r + 1):
            jj = min(max(j + k, 0), w - 1)
            s1 += f64(aux[i, jj, a])
        dst[i, j, 2 * N_SIG + a] = s1


def combine_px(i, j, sig, aux, hh, r7, r3, out, col7, col3, med):
    """The 36 secondary features of pixel (i, j) (see :data:`.features.FEATURE_NAMES`).

    ``r7``/``r3`` are the horizontal box sums of :func:`box_rows_px` (radius 3 and 1); the
    vertical sums are taken here into the scratch arrays ``col7`` (28), ``col3`` (26);
    ``med`` (9) is scratch for the median.
    """
    h = sig.shape[0]
    w = sig.shape[1]
    for ch in range(N_BOX7):
        s = 0.0
        for k in range(-3, 4):
            ii = min(max(i + k, 0), h - 1)
            s += r7[ii, j, ch]
        col7[ch] = s / 49.0
    for ch in range(N_BOX3):
        s = 0.0
        for k in range(-1, 2):
            ii = min(max(i + k, 0), h - 1)
            s += r3[ii, j, ch]
        col3[ch] = s / 9.0
    im = max(i - 1, 0)
    ip = min(i + 1, h - 1)
    jm = max(j - 1, 0)
    jp = min(j + 1, w - 1)
    sd7_color = 0.0
    for g in range(5):
        c0 = 3 * g
        c1 = 13 if g == 4 else 3 * g + 3
        n = c1 - c0
        v7 = 0.0
        v3 = 0.0
        mad = 0.0
        grad = 0.0
        for ch in range(c0, c1):
            m = col7[ch]
            v7 += max(col7[N_SIG + ch] - m * m, 0.0)
            m = col3[ch]
            v3 += max(col3[N_SIG + ch] - m * m, 0.0)
            centre = f64(sig[i, j, ch])
            for di in range(-1, 2):
                ii = min(max(i + di, 0), h - 1)
                for dj in range(-1, 2):
                    jj = min(max(j + dj, 0), w - 1)
                    mad += abs(f64(sig[ii, jj, ch]) - centre)
            gx = 0.5 * (f64(sig[i, jp, ch]) - f64(sig[i, jm, ch]))
            gy = 0.5 * (f64(sig[ip, j, ch]) - f64(sig[im, j, ch]))
            grad += gx * gx + gy * gy
        out[i, j, g] = math.sqrt(v7 / n)
        if g == 0:
            sd7_color = math.sqrt(v7 / n)
        out[i, j, 5 + g] = math.sqrt(v3 / n)
        out[i, j, 10 + g] = mad / (9.0 * n)
        out[i, j, 15 + g] = math.sqrt(grad)
        k = 0
        for di in range(-1, 2):
            ii = min(max(i + di, 0), h - 1)
            for dj in range(-1, 2):
                jj = min(max(j + dj, 0), w - 1)
                # insertion into the sorted prefix med[0:k]
                x = f64(hh[ii, jj, g])
                p = k
                while p > 0 and med[p - 1] > x:
                    med[p] = med[p - 1]
                    p -= 1
                med[p] = x
                k += 1
        out[i, j, 20 + g] = med[4] / HAAR_MAD
    out[i, j, 25] = (col7[0] + col7[1] + col7[2]) / 3.0
    out[i, j, 26] = (col7[9] + col7[10] + col7[11]) / 3.0
    out[i, j, 27] = col7[12]
    out[i, j, 28] = (f64(sig[i, j, 0]) + f64(sig[i, j, 1]) + f64(sig[i, j, 2])) / 3.0
    out[i, j, 29] = (f64(sig[i, j, 9]) + f64(sig[i, j, 10]) + f64(sig[i, j, 11])) / 3.0
    out[i, j, 30] = sig[i, j, 12]
    s = f64(aux[i, j, 0])
    out[i, j, 31] = s
    out[i, j, 32] = col7[2 * N_SIG]
    out[i, j, 33] = s / (sd7_color + 1e-3)
    out[i, j, 34] = aux[i, j, 2]
    out[i, j, 35] = col7[2 * N_SIG + 1]


def mlp_px(i, j, feat, mean, inv_std, w1, b1, w2, b2, z, hidden, params):
    """The network of pixel (i, j): z-normalise (and clamp), 36 -> 10 (sigmoid) -> 6 (softplus).

    ``z`` (36) and ``hidden`` (10) are scratch arrays.
    """
    nf = w1.shape[1]
    for f in range(nf):
        x = (f64(feat[i, j, f]) - f64(mean[f])) * f64(inv_std[f])
        z[f] = min(max(x, -Z_CLAMP), Z_CLAMP)
    for u in range(w1.shape[0]):
        a = f64(b1[u])
        for f in range(nf):
            a += f64(w1[u, f]) * z[f]
        if a >= 0.0:
            hidden[u] = 1.0 / (1.0 + math.exp(-a))
        else:
            e = math.exp(a)
            hidden[u] = e / (1.0 + e)
    for o in range(w2.shape[0]):
        a = f64(b2[o])
        for u in range(w2.shape[1]):
            a += f64(w2[o, u]) * hidden[u]
        # softplus, stable for any sign
        params[i, j, o] = max(a, 0.0) + math.log1p(math.exp(-abs(a)))


def filter_px(i, j, color, variance, sig, params, radius, inv_tau, out):
    """Cross-bilateral filter of pixel (i, j) with its own bandwidths ``params[i, j]``.

    ``D = a |dp|^2 + c sum_ch dc^2 / (var_i + var_j + 1e-10) + sum_k b_k sum_ch df_k^2 * inv_tau``
    and weight ``exp(-D)``; ``inv_tau`` is ``1 / max(1e-4, var_i(f))`` (see :mod:`.features`).
    A pixel whose colour variance is zero is noise-free and is copied. Taps with ``D >
    D_CUT`` (weight below 4e-18, against 1 for the centre) are skipped without an ``exp``.
    """
    h = color.shape[0]
    w = color.shape[1]
    vraw = max(f64(variance[i, j, 0]), 0.0) + max(f64(variance[i, j, 1]), 0.0)
    vraw += max(f64(variance[i, j, 2]), 0.0)
    if vraw == 0.0:
        # noise-free pixel (sky, emitter): nothing to filter
        out[i, j, 0] = color[i, j, 0]
        out[i, j, 1] = color[i, j, 1]
        out[i, j, 2] = color[i, j, 2]
        return
    a = f64(params[i, j, 0])
    cc = f64(params[i, j, 1])
    bp = f64(params[i, j, 2]) * inv_tau
    bn = f64(params[i, j, 3]) * inv_tau
    ba = f64(params[i, j, 4]) * inv_tau
    bv = f64(params[i, j, 5]) * inv_tau
    c0 = f64(color[i, j, 0])
    c1 = f64(color[i, j, 1])
    c2 = f64(color[i, j, 2])
    v0 = max(f64(variance[i, j, 0]), 0.0) + 1e-10
    v1 = max(f64(variance[i, j, 1]), 0.0) + 1e-10
    v2 = max(f64(variance[i, j, 2]), 0.0) + 1e-10
    p0 = f64(sig[i, j, 3])
    p1 = f64(sig[i, j, 4])
    p2 = f64(sig[i, j, 5])
    n0 = f64(sig[i, j, 6])
    n1 = f64(sig[i, j, 7])
    n2 = f64(sig[i, j, 8])
    a0 = f64(sig[i, j, 9])
    a1 = f64(sig[i, j, 10])
    a2 = f64(sig[i, j, 11])
    vis = f64(sig[i, j, 12])
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    wsum = 0.0
    for ii in range(max(i - radius, 0), min(i + radius + 1, h)):
        di = ii - i
        for jj in range(max(j - radius, 0), min(j + radius + 1, w)):
            dj = jj - j
            t0 = p0 - f64(sig[ii, jj, 3])
            t1 = p1 - f64(sig[ii, jj, 4])
            t2 = p2 - f64(sig[ii, jj, 5])
            d = a * (di * di + dj * dj) + bp * (t0 * t0 + t1 * t1 + t2 * t2)
            t0 = n0 - f64(sig[ii, jj, 6])
            t1 = n1 - f64(sig[ii, jj, 7])
            t2 = n2 - f64(sig[ii, jj, 8])
            d += bn * (t0 * t0 + t1 * t1 + t2 * t2)
            t0 = a0 - f64(sig[ii, jj, 9])
            t1 = a1 - f64(sig[ii, jj, 10])
            t2 = a2 - f64(sig[ii, jj, 11])
            d += ba * (t0 * t0 + t1 * t1 + t2 * t2)
            t0 = vis - f64(sig[ii, jj, 12])
            d += bv * t0 * t0
            if d > D_CUT:
                continue
            q0 = f64(color[ii, jj, 0])
            q1 = f64(color[ii, jj, 1])
            q2 = f64(color[ii, jj, 2])
            e0 = c0 - q0
            e1 = c1 - q1
            e2 = c2 - q2
            d += cc * (e0 * e0 / (v0 + max(f64(variance[ii, jj, 0]), 0.0))
                       + e1 * e1 / (v1 + max(f64(variance[ii, jj, 1]), 0.0))
                       + e2 * e2 / (v2 + max(f64(variance[ii, jj, 2]), 0.0)))
            if d > D_CUT:
                continue
            wt = math.exp(-d)
            acc0 += wt * q0
            acc1 += wt * q1
            acc2 += wt * q2
            wsum += wt
    # the centre tap has D = 0, so wsum >= 1
    out[i, j, 0] = acc0 / wsum
    out[i, j, 1] = acc1 / wsum
    out[i, j, 2] = acc2 / wsum
