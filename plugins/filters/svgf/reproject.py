"""Temporal reprojection and accumulation (Schied et al. 2017, section 4.1).

Each pixel follows its motion vector into the previous frame, tests the 2x2 bilinear taps there
for consistency (same object id, depth within a relative tolerance widened by the local depth
slope, normals within a cosine tolerance), falls back to the consistent taps of the 3x3
neighbourhood, and otherwise drops its history (disocclusion). Colour and the first two
luminance moments are blended with exponential moving averages.
"""

from __future__ import annotations

import math

from numba import njit

from .weights import luminance


@njit(cache=True, inline="always")
def gradient_pixel(i, j, depth, valid, grad):
    """Screen-space depth gradient at pixel (i, j), depth units per pixel.

    Per axis, the one-sided difference of smaller magnitude among valid neighbours (so an
    object edge does not widen the slope); 0 where no neighbour is valid.

    Parameters
    ----------
    depth : ndarray (H, W) float32
    valid : ndarray (H, W) uint8
    grad : ndarray (2, H, W) float32
        Output ``(dz/dx, dz/dy)``.
    """
    h = depth.shape[0]
    w = depth.shape[1]
    if valid[i, j] == 0:
        grad[0, i, j] = 0.0
        grad[1, i, j] = 0.0
        return
    z = depth[i, j]
    for axis in range(2):
        best = 0.0
        found = False
        for side in range(-1, 2, 2):
            y = i + side if axis == 1 else i
            x = j + side if axis == 0 else j
            if 0 <= y < h and 0 <= x < w and valid[y, x] != 0:
                d = (depth[y, x] - z) * side
                if not found or abs(d) < abs(best):
                    best = d
                    found = True
        grad[axis, i, j] = best


@njit(cache=True, inline="always")
def _consistent(y, x, kind, z, ztol, nx, ny, nz, oid, ntol, prev_valid, prev_depth, prev_normal, prev_obj):
    """Whether tap (y, x) of the previous frame shows the surface of the current pixel, of the
    same ``kind`` (its ``valid`` code: demodulated or not, :mod:`.modulation`)."""
    h = prev_depth.shape[0]
    w = prev_depth.shape[1]
    if y < 0 or y >= h or x < 0 or x >= w or prev_valid[y, x] != kind:
        return False
    if prev_obj[y, x] != oid or abs(prev_depth[y, x] - z) > ztol:
        return False
    d = nx * prev_normal[0, y, x] + ny * prev_normal[1, y, x] + nz * prev_normal[2, y, x]
    return d >= ntol


@njit(cache=True, inline="always")
def _add(s, y, x, wt, prev_sig, prev_mom, r, g, b, u, v):
    """The sums ``(r, g, b, u, v)`` of signal ``s`` plus ``wt`` times its history at (y, x)."""
    return (r + wt * prev_sig[s, 0, y, x], g + wt * prev_sig[s, 1, y, x], b + wt * prev_sig[s, 2, y, x],
            u + wt * prev_mom[s, 0, y, x], v + wt * prev_mom[s, 1, y, x])


@njit(cache=True, inline="always")
def _store(s, i, j, r, g, b, u, v, acc_sig, acc_mom):
    """Write colour ``(r, g, b)`` and moments ``(u, v)`` of signal ``s`` at pixel (i, j)."""
    acc_sig[s, 0, i, j] = r
    acc_sig[s, 1, i, j] = g
    acc_sig[s, 2, i, j] = b
    acc_mom[s, 0, i, j] = u
    acc_mom[s, 1, i, j] = v


@njit(cache=True, inline="always")
def _blend(s, i, j, sig, a_c, a_m, inv, r, g, b, u, v, acc_sig, acc_mom):
    """Blend signal ``s`` of the current frame with its history sums ``(r, g, b, u, v) * inv``."""
    cr = sig[s, 0, i, j]
    cg = sig[s, 1, i, j]
    cb = sig[s, 2, i, j]
    lum = luminance(float(cr), float(cg), float(cb))
    _store(s, i, j, a_c * cr + (1.0 - a_c) * (r * inv), a_c * cg + (1.0 - a_c) * (g * inv),
           a_c * cb + (1.0 - a_c) * (b * inv), a_m * lum + (1.0 - a_m) * (u * inv),
           a_m * lum * lum + (1.0 - a_m) * (v * inv), acc_sig, acc_mom)


@njit(cache=True, inline="always")
def reproject_pixel(i, j, sig, valid, depth, normal, obj, grad, motion,
                    prev_sig, prev_mom, prev_hist, prev_valid, prev_depth, prev_normal, prev_obj,
                    has_prev, depth_tol, normal_tol, alpha_color, alpha_moments, history_average,
                    max_history, acc_sig, acc_mom, hist):
    """Reproject, test and accumulate pixel (i, j).

    Parameters
    ----------
    sig : ndarray (S, 3, H, W) float32
        Current demodulated signals.
    valid, depth, normal, obj, grad, motion : ndarray
        Current planar G-buffer (see :mod:`.modulation`) and depth gradient.
    prev_sig : ndarray (S, 3, H, W) float32
        Colour history.
    prev_mom : ndarray (S, 2, H, W) float64
        Luminance moments history.
    prev_hist : ndarray (H, W) float32
        History length.
    prev_valid, prev_depth, prev_normal, prev_obj : ndarray
        Previous planar G-buffer.
    has_prev : bool
        False on the first frame after a reset.
    depth_tol : float
        Relative depth tolerance; the allowed difference is
        ``depth_tol * z + 2 (|dz/dx| + |dz/dy|)``.
    normal_tol : float
        Smallest allowed dot product of normals.
    alpha_color, alpha_moments : float
        Weights of the current frame.
    history_average : bool
        Use ``max(alpha, 1 / history_length)``.
    max_history : float
        Cap of the history length.
    acc_sig, acc_mom, hist : ndarray
        Outputs, shaped as ``prev_sig``, ``prev_mom``, ``prev_hist``.
    """
    two = sig.shape[0] == 2
    if valid[i, j] == 0:
        hist[i, j] = 0.0
        _store(0, i, j, 0.0, 0.0, 0.0, 0.0, 0.0, acc_sig, acc_mom)
        if two:
            _store(1, i, j, 0.0, 0.0, 0.0, 0.0, 0.0, acc_sig, acc_mom)
        return
    z = depth[i, j]
    ztol = depth_tol * abs(z) + 2.0 * (abs(grad[0, i, j]) + abs(grad[1, i, j]))
    nx = normal[0, i, j]
    ny = normal[1, i, j]
    nz = normal[2, i, j]
    oid = obj[i, j]
    # weighted sums of the history (colour r, g, b; moments u, v) of signals 0 and 1, kept in
    # registers
    wsum = 0.0
    hsum = 0.0
    r0 = g0 = b0 = u0 = v0 = 0.0
    r1 = g1 = b1 = u1 = v1 = 0.0
    if has_prev:
        px = j + motion[0, i, j]
        py = i + motion[1, i, j]
        x0 = int(math.floor(px))
        y0 = int(math.floor(py))
        fx = px - x0
        fy = py - y0
        for t in range(4):
            dx = t & 1
            dy = t >> 1
            x = x0 + dx
            y = y0 + dy
            wt = (fx if dx == 1 else 1.0 - fx) * (fy if dy == 1 else 1.0 - fy)
            if wt <= 0.0 or not _consistent(y, x, valid[i, j], z, ztol, nx, ny, nz, oid, normal_tol,
                                            prev_valid, prev_depth, prev_normal, prev_obj):
                continue
            wsum += wt
            hsum += wt * prev_hist[y, x]
            r0, g0, b0, u0, v0 = _add(0, y, x, wt, prev_sig, prev_mom, r0, g0, b0, u0, v0)
            if two:
                r1, g1, b1, u1, v1 = _add(1, y, x, wt, prev_sig, prev_mom, r1, g1, b1, u1, v1)
        if wsum < 1e-3:
            # no bilinear tap passed: the consistent taps of the 3x3 neighbourhood, equal weights
            wsum = 0.0
            hsum = 0.0
            r0 = g0 = b0 = u0 = v0 = 0.0
            r1 = g1 = b1 = u1 = v1 = 0.0
            xc = int(math.floor(px + 0.5))
            yc = int(math.floor(py + 0.5))
            for t in range(9):
                y = yc + t // 3 - 1
                x = xc + t % 3 - 1
                if not _consistent(y, x, valid[i, j], z, ztol, nx, ny, nz, oid, normal_tol,
                                   prev_valid, prev_depth, prev_normal, prev_obj):
                    continue
                wsum += 1.0
                hsum += prev_hist[y, x]
                r0, g0, b0, u0, v0 = _add(0, y, x, 1.0, prev_sig, prev_mom, r0, g0, b0, u0, v0)
                if two:
                    r1, g1, b1, u1, v1 = _add(1, y, x, 1.0, prev_sig, prev_mom, r1, g1, b1, u1, v1)
    if wsum > 0.0:
        inv = 1.0 / wsum
        n = min(hsum * inv + 1.0, max_history)
        a_c = alpha_color
        a_m = alpha_moments
        if history_average:
            a_c = max(a_c, 1.0 / n)
            a_m = max(a_m, 1.0 / n)
    else:
        inv = 0.0
        n = 1.0
        a_c = 1.0
        a_m = 1.0
    hist[i, j] = n
    _blend(0, i, j, sig, a_c, a_m, inv, r0, g0, b0, u0, v0, acc_sig, acc_mom)
    if two:
        _blend(1, i, j, sig, a_c, a_m, inv, r1, g1, b1, u1, v1, acc_sig, acc_mom)
