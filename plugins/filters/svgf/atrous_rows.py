"""Row-vectorized à-trous iteration for the ``cpu`` backend.

The same filter as :func:`plugins.filters.svgf.atrous.atrous_pixel` (same taps, same weights,
same order of accumulation), with the loops turned inside out: each thread takes one image row
and, for each of the 25 taps, sweeps the row with branch-free float32 arithmetic into per-row
accumulators, so that LLVM vectorizes the inner loop (the exponential is
:func:`.weights.expneg`, the normal power folded into its argument by
:func:`.weights.neg_log_series`). Background pixels enter with weight 0 and are written as 0;
each row is swept only between its first and last surface pixel.

To let LLVM vectorize, the inner loops run over row slices from index 0 (provably
non-negative: no wraparound tests), divisions follow NumPy's error model (no
zero-division branch; every denominator here is positive) and each loop stores to few arrays
(few pointer pairs to test for aliasing at run time): the tap weights go to a buffer first,
then one loop updates the weight and colour sums, another the float64 variance sum.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .weights import b3_tap, expneg, gauss3_tap, neg_log_series

_LR = np.float32(0.2126)
_LG = np.float32(0.7152)
_LB = np.float32(0.0722)
_TINY = np.float32(1e-20)
#: arguments of the exponential are clamped here (expneg is exactly 0 below -1024); luminance
#: differences are clamped at _ARG_MAX times their scale, so no product overflows (fastmath)
_ARG_MAX = np.float32(1024.0)
_F32_MAX = 3.0e38
_TINY64 = 1e-300


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def atrous_rows(step, sig, var, valid, depth, normal, grad, sigma_z, sigma_n, sigma_l,
                depth_eps, lum_eps, sig_out, var_out):
    """One à-trous iteration over the whole image (arguments as ``atrous_pixel``, no i, j)."""
    nsig = sig.shape[0]
    h = valid.shape[0]
    w = valid.shape[1]
    sz = np.float32(sigma_z)
    de = np.float32(depth_eps)
    sn = np.float32(sigma_n)
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        # the columns from the first to the last surface pixel of the row: only those are
        # filtered (background is written as 0; a row of background costs nothing more)
        jlo = w
        jhi = 0
        for j in range(w):
            if valid[i, j] != 0:
                jlo = min(jlo, j)
                jhi = j + 1
        if jlo >= jhi:
            for s in range(nsig):
                for j in range(w):
                    for c in range(3):
                        sig_out[s, c, i, j] = 0.0
                    var_out[s, i, j] = 0.0
            continue
        lp = np.empty((nsig, w), np.float32)
        il = np.empty((nsig, w), np.float32)
        lim = np.empty((nsig, w), np.float32)
        acc = np.zeros((nsig, 4, w), np.float32)
        accv = np.zeros((nsig, w), np.float64)
        wn = np.empty(w, np.float32)
        dist = np.empty(w, np.float32)
        wbuf = np.empty(w, np.float32)
        # 3x3 Gaussian prefilter of the variance over valid neighbours (as
        # variance.prefiltered_variance), row-vectorized: weighted sums, then their ratio
        pnum = np.zeros((nsig, w), np.float64)
        pden = np.zeros(w, np.float32)
        for dy in range(-1, 2):
            y = i + dy
            if y < 0 or y >= h:
                continue
            for dx in range(-1, 2):
                j0 = max(0, -dx)
                j1 = min(w, w - dx)
                if j0 >= j1:
                    continue
                n = j1 - j0
                g = np.float32(gauss3_tap(dy) * gauss3_tap(dx))
                vq = valid[y, j0 + dx:j1 + dx]
                pd = pden[j0:j1]
                for k in range(n):
                    pd[k] += g * np.float32(vq[k])
                for s in range(nsig):
                    pn = pnum[s, j0:j1]
                    vr = var[s, y, j0 + dx:j1 + dx]
                    for k in range(n):
                        pn[k] += np.float64(g * np.float32(vq[k])) * vr[k]
        for s in range(nsig):
            lpr = lp[s]
            ilr = il[s]
            limr = lim[s]
            pn = pnum[s]
            c0 = sig[s, 0, i]
            c1 = sig[s, 1, i]
            c2 = sig[s, 2, i]
            # branch-free (vectorized): where no neighbour is valid pnum is 0 too
            for j in range(w):
                lpr[j] = _LR * c0[j] + _LG * c1[j] + _LB * c2[j]
                pv = pn[j] / max(np.float64(pden[j]), _TINY64)
                den = sigma_l * math.sqrt(pv) + lum_eps
                ilr[j] = 1.0 / den
                limr[j] = min(1024.0 * den, _F32_MAX)
        for ky in range(-2, 3):
            y = i + ky * step
            if y < 0 or y >= h:
                continue
            dyf = np.float32(ky * step)
            for kx in range(-2, 3):
                off = kx * step
                j0 = max(jlo, -off)
                j1 = min(jhi, w - off)
                if j0 >= j1:
                    continue
                hk = np.float32(b3_tap(ky) * b3_tap(kx))
                n = j1 - j0
                q0, q1 = j0 + off, j1 + off
                wnr = wn[j0:j1]
                dr = dist[j0:j1]
                vq = valid[y, q0:q1]
                if kx == 0 and ky == 0:
                    for k in range(n):
                        wnr[k] = hk * np.float32(vq[k])
                        dr[k] = 0.0
                else:
                    dxf = np.float32(off)
                    n0p, n1p, n2p = normal[0, i, j0:j1], normal[1, i, j0:j1], normal[2, i, j0:j1]
                    n0q, n1q, n2q = normal[0, y, q0:q1], normal[1, y, q0:q1], normal[2, y, q0:q1]
                    zpr = depth[i, j0:j1]
                    zqr = depth[y, q0:q1]
                    gxr = grad[0, i, j0:j1]
                    gyr = grad[1, i, j0:j1]
                    for k in range(n):
                        d = n0p[k] * n0q[k] + n1p[k] * n1q[k] + n2p[k] * n2q[k]
                        wnr[k] = hk * np.float32(vq[k]) * np.float32(d > np.float32(0.0))
                        zp = zpr[k]
                        den = sz * abs(gxr[k] * dxf + gyr[k] * dyf) + de * abs(zp) + _TINY
                        # w_z w_n = exp(-(depth distance + sigma_n (-ln d)))
                        dr[k] = min(abs(zp - zqr[k]) / den, _ARG_MAX) + sn * neg_log_series(d)
                wt = wbuf[j0:j1]
                for s in range(nsig):
                    c0 = sig[s, 0, y, q0:q1]
                    c1 = sig[s, 1, y, q0:q1]
                    c2 = sig[s, 2, y, q0:q1]
                    lpr = lp[s, j0:j1]
                    ilr = il[s, j0:j1]
                    limr = lim[s, j0:j1]
                    if kx == 0 and ky == 0:
                        # the centre's own luminance: weight h(0) exactly (no rounding of
                        # l_p - l_q under a tiny variance can zero it)
                        for k in range(n):
                            wt[k] = wnr[k]
                    else:
                        for k in range(n):
                            lq = _LR * c0[k] + _LG * c1[k] + _LB * c2[k]
                            arg = dr[k] + min(abs(lpr[k] - lq), limr[k]) * ilr[k]
                            wt[k] = wnr[k] * expneg(-min(arg, _ARG_MAX))
                    aw = acc[s, 0, j0:j1]
                    ar = acc[s, 1, j0:j1]
                    ag = acc[s, 2, j0:j1]
                    ab = acc[s, 3, j0:j1]
                    for k in range(n):
                        t = wt[k]
                        aw[k] += t
                        ar[k] += t * c0[k]
                        ag[k] += t * c1[k]
                        ab[k] += t * c2[k]
                    av = accv[s, j0:j1]
                    vr = var[s, y, q0:q1]
                    for k in range(n):
                        av[k] += np.float64(wt[k] * wt[k]) * vr[k]
        for s in range(nsig):
            for j in range(w):
                if valid[i, j] != 0:
                    inv = np.float32(1.0) / acc[s, 0, j]
                    for c in range(3):
                        sig_out[s, c, i, j] = acc[s, c + 1, j] * inv
                    var_out[s, i, j] = accv[s, j] * np.float64(inv) * np.float64(inv)
                else:
                    for c in range(3):
                        sig_out[s, c, i, j] = 0.0
                    var_out[s, i, j] = 0.0
