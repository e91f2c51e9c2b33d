"""Per-pixel bodies of LBF's feature extraction, network and filter, shared by both backends.

Each function here is plain Python over scalars and arrays, computing the result of one pixel
``(i, j)``. :mod:`.cpu` compiles them with ``numba.njit`` and loops over pixels in parallel
(its filter is a separate vectorised kernel over rows); :mod:`.cuda` compiles the very same
functions as ``numba.cuda`` device functions and calls them from one thread per pixel. Sharing
the bodies is what makes the two backends agree.

Layout of the 13 planar "signal" channels ``sig`` (float32, 13 x H x W): ``log1p(color)``
(0-2), normalised position (3-5), normal (6-8), albedo (9-11), visibility (12). Channels 3-12
are the primary features the filter compares. Statistics are taken per group: colour 0-2,
position 3-5, normal 6-8, albedo 9-11, visibility 12. ``aux`` (H x W x 3): sample deviation of
the colour signal, foreground mask, 1/spp. Image borders are clamped (replicated) for the
statistics; the filter skips taps outside the image.

Guards (free: they sit where the data is read anyway): a NaN guide value becomes 0 and an
infinite or huge one +-:data:`FEATURE_LIMIT`, so no feature difference is NaN and every squared
difference is finite in float32; NaN and negative colour count as 0 in the statistics (the
filter averages the colour as given); NaN and negative variance count as 0, +Inf as the float32
maximum; z-normalised network inputs that are NaN become 0.
"""

from __future__ import annotations

import math

from numba import float64 as f64

#: number of signal channels, and the width of the 7x7 box sums (means + squares + aux)
N_SIG = 13
N_BOX7 = 2 * N_SIG + 2
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
#: largest variance kept (float32 range)
VAR_MAX = 3e38
#: bound of a guide value (position after normalisation, normal, albedo, visibility)
FEATURE_LIMIT = 1e15
#: smallest colour bandwidth used by the filter (keeps ``c * inf`` from being ``0 * inf``)
MIN_BANDWIDTH = 1e-30


def clean_variance(v):
    """A variance with NaN and negatives -> 0 and the top clamped to :data:`VAR_MAX`."""
    if v > 0.0:
        return min(v, VAR_MAX)
    return 0.0


def color_rows_px(i, j, color, r, dst):
    """Horizontal sums (clamped window 2r+1) of the colour (0-2) and its square (3-5)."""
    w = color.shape[1]
    for ch in range(3):
        s1 = 0.0
        s2 = 0.0
        for k in range(-r, r + 1):
            jj = min(max(j + k, 0), w - 1)
            x = f64(color[i, jj, ch])
            if not x - x == 0.0:  # NaN or +-Inf: no information
                x = 0.0
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
        v = s2 / n - m * m
        out[i, j, ch] = min(v, VAR_MAX) if v > 0.0 else 0.0


def signals_px(i, j, color, variance, position, normal, albedo, vis, has_vis, spp, has_spp,
               mu0, mu1, mu2, inv_scale, sig, aux):
    """Signal channels and ``aux`` of pixel (i, j)."""
    n0 = normal[i, j, 0]
    n1 = normal[i, j, 1]
    n2 = normal[i, j, 2]
    fg = 1.0 if (n0 != 0.0 or n1 != 0.0 or n2 != 0.0) else 0.0
    vs = 0.0
    for ch in range(3):
        c = f64(color[i, j, ch])
        c = c if c > 0.0 else 0.0
        sig[ch, i, j] = math.log1p(min(c, VAR_MAX))
        v = f64(variance[i, j, ch])
        v = min(v, VAR_MAX) if v > 0.0 else 0.0
        vs += v / ((1.0 + c) * (1.0 + c))
        x = f64(normal[i, j, ch])
        sig[6 + ch, i, j] = min(max(x, -FEATURE_LIMIT), FEATURE_LIMIT) if x == x else 0.0
        x = f64(albedo[i, j, ch])
        sig[9 + ch, i, j] = min(max(x, -FEATURE_LIMIT), FEATURE_LIMIT) if x == x else 0.0
    mu = (mu0, mu1, mu2)
    for ch in range(3):
        x = (f64(position[i, j, ch]) - mu[ch]) * inv_scale
        sig[3 + ch, i, j] = min(max(x, -FEATURE_LIMIT), FEATURE_LIMIT) if x == x else 0.0
    if has_vis:
        x = f64(vis[i, j])
        sig[12, i, j] = min(max(x, -FEATURE_LIMIT), FEATURE_LIMIT) if x == x else 0.0
    else:
        sig[12, i, j] = fg
    aux[i, j, 0] = math.sqrt(vs / 3.0)
    aux[i, j, 1] = fg
    if has_spp:
        aux[i, j, 2] = 1.0 / max(f64(spp[i, j]), 1.0)
    else:
        aux[i, j, 2] = 1.0


def haar_px(i, j, sig, hh):
    """|HH| Haar detail coefficient of each group's channel mean at the 2x2 block at (i, j)."""
    h = sig.shape[1]
    w = sig.shape[2]
    i1 = min(i + 1, h - 1)
    j1 = min(j + 1, w - 1)
    for g in range(5):
        c0 = 3 * g
        c1 = 13 if g == 4 else 3 * g + 3
        a = 0.0
        for ch in range(c0, c1):
            a += f64(sig[ch, i, j]) - f64(sig[ch, i, j1])
            a += f64(sig[ch, i1, j1]) - f64(sig[ch, i1, j])
        hh[i, j, g] = abs(a) * 0.5 / (c1 - c0)


def box7_px(i, j, sig, aux, col7):
    """Means over the clamped 7x7 window of the signals (0-12), their squares (13-25) and the
    first two ``aux`` channels (26-27), written to ``col7`` (28)."""
    h = sig.shape[1]
    w = sig.shape[2]
    for ch in range(N_BOX7):
        col7[ch] = 0.0
    for di in range(-3, 4):
        ii = min(max(i + di, 0), h - 1)
        for dj in range(-3, 4):
            jj = min(max(j + dj, 0), w - 1)
            for ch in range(N_SIG):
                x = f64(sig[ch, ii, jj])
                col7[ch] += x
                col7[N_SIG + ch] += x * x
            col7[2 * N_SIG] += f64(aux[ii, jj, 0])
            col7[2 * N_SIG + 1] += f64(aux[ii, jj, 1])
    for ch in range(N_BOX7):
        col7[ch] /= 49.0


def combine_px(i, j, sig, aux, hh, col7, med, feat):
    """The 36 secondary features of pixel (i, j) (see :data:`.features.FEATURE_NAMES`).

    ``col7`` holds the 7x7 means of :func:`box7_px`; the 3x3 statistics are taken here;
    ``med`` (9) is scratch for the median; ``feat`` (36) receives the features.
    """
    h = sig.shape[1]
    w = sig.shape[2]
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
            centre = f64(sig[ch, i, j])
            s1 = 0.0
            s2 = 0.0
            for di in range(-1, 2):
                ii = min(max(i + di, 0), h - 1)
                for dj in range(-1, 2):
                    jj = min(max(j + dj, 0), w - 1)
                    x = f64(sig[ch, ii, jj])
                    s1 += x
                    s2 += x * x
                    mad += abs(x - centre)
            m = s1 / 9.0
            v3 += max(s2 / 9.0 - m * m, 0.0)
            gx = 0.5 * (f64(sig[ch, i, jp]) - f64(sig[ch, i, jm]))
            gy = 0.5 * (f64(sig[ch, ip, j]) - f64(sig[ch, im, j]))
            grad += gx * gx + gy * gy
        feat[g] = math.sqrt(v7 / n)
        if g == 0:
            sd7_color = math.sqrt(v7 / n)
        feat[5 + g] = math.sqrt(v3 / n)
        feat[10 + g] = mad / (9.0 * n)
        feat[15 + g] = math.sqrt(grad)
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
        feat[20 + g] = med[4] / HAAR_MAD
    feat[25] = (col7[0] + col7[1] + col7[2]) / 3.0
    feat[26] = (col7[9] + col7[10] + col7[11]) / 3.0
    feat[27] = col7[12]
    feat[28] = (f64(sig[0, i, j]) + f64(sig[1, i, j]) + f64(sig[2, i, j])) / 3.0
    feat[29] = (f64(sig[9, i, j]) + f64(sig[10, i, j]) + f64(sig[11, i, j])) / 3.0
    feat[30] = sig[12, i, j]
    s = f64(aux[i, j, 0])
    feat[31] = s
    feat[32] = col7[2 * N_SIG]
    feat[33] = s / (sd7_color + 1e-3)
    feat[34] = aux[i, j, 2]
    feat[35] = col7[2 * N_SIG + 1]


def mlp_px(feat, mean, inv_std, w1, b1, w2, b2, z, hidden, out):
    """The network of one pixel: z-normalise (and clamp), 36 -> 10 (sigmoid) -> 6 (softplus).

    ``feat`` (36) holds the raw features, ``z`` (36) and ``hidden`` (10) are scratch, ``out``
    (6) receives the bandwidths.
    """
    nf = w1.shape[1]
    for f in range(nf):
        x = (f64(feat[f]) - f64(mean[f])) * f64(inv_std[f])
        z[f] = min(max(x, -Z_CLAMP), Z_CLAMP) if x == x else 0.0
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
        out[o] = max(a, 0.0) + math.log1p(math.exp(-abs(a)))


def filter_px(i, j, color, variance, sig, params, radius, inv_tau, out):
    """Cross-bilateral filter of pixel (i, j) with its own bandwidths ``params[:, i, j]``.

    ``D = a |dp|^2 + c sum_ch dc^2 / (var_i + var_j + 1e-10) + sum_k b_k sum_ch df_k^2 * inv_tau``
    and weight ``exp(-D)``; ``inv_tau`` is ``1 / max(1e-4, var_i(f))`` (see :mod:`.features`).
    ``color`` and ``variance`` are the filter's planar (3, H, W) planes (variance sanitised).
    A pixel whose colour variance is zero is noise-free and is copied. Taps with ``D >
    D_CUT`` (weight below 4e-18, against 1 for the centre) are skipped without an ``exp``.
    (The CPU backend runs the same arithmetic as a vectorised row kernel.)
    """
    h = color.shape[1]
    w = color.shape[2]
    v0 = f64(variance[0, i, j])
    v1 = f64(variance[1, i, j])
    v2 = f64(variance[2, i, j])
    if v0 + v1 + v2 == 0.0:
        # noise-free pixel (sky, emitter): nothing to filter
        out[i, j, 0] = color[0, i, j]
        out[i, j, 1] = color[1, i, j]
        out[i, j, 2] = color[2, i, j]
        return
    a = f64(params[0, i, j])
    cc = max(f64(params[1, i, j]), MIN_BANDWIDTH)
    bp = f64(params[2, i, j]) * inv_tau
    bn = f64(params[3, i, j]) * inv_tau
    ba = f64(params[4, i, j]) * inv_tau
    bv = f64(params[5, i, j]) * inv_tau
    c0 = f64(color[0, i, j])
    c1 = f64(color[1, i, j])
    c2 = f64(color[2, i, j])
    v0 += 1e-10
    v1 += 1e-10
    v2 += 1e-10
    acc0 = 0.0
    acc1 = 0.0
    acc2 = 0.0
    wsum = 0.0
    for ii in range(max(i - radius, 0), min(i + radius + 1, h)):
        di = ii - i
        for jj in range(max(j - radius, 0), min(j + radius + 1, w)):
            dj = jj - j
            d = a * (di * di + dj * dj)
            for g in range(4):
                b = bp if g == 0 else (bn if g == 1 else ba)
                c_end = 6 + 3 * g if g < 3 else 13
                if g == 3:
                    b = bv
                s = 0.0
                for ch in range(3 + 3 * g, c_end):
                    t = f64(sig[ch, i, j]) - f64(sig[ch, ii, jj])
                    s += t * t
                d += b * s
            if d > D_CUT:
                continue
            q0 = f64(color[0, ii, jj])
            q1 = f64(color[1, ii, jj])
            q2 = f64(color[2, ii, jj])
            e0 = c0 - q0
            e1 = c1 - q1
            e2 = c2 - q2
            d += cc * (e0 * e0 / (v0 + f64(variance[0, ii, jj]))
                       + e1 * e1 / (v1 + f64(variance[1, ii, jj]))
                       + e2 * e2 / (v2 + f64(variance[2, ii, jj])))
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
