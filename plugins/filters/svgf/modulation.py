"""Per-pixel input preparation (albedo demodulation, planar G-buffer) and remodulation.

Planar layouts: signals ``(S, 3, H, W)``, normals ``(3, H, W)``, motion ``(2, H, W)``. ``S`` is 2
when the frame carries ``direct`` and ``indirect`` (filtered separately), else 1 (``color``).
"""

from __future__ import annotations

import math

from numba import njit

#: demodulated values are clamped to this magnitude so that sums of a few of them stay finite in float32
F32_BIG = 1.0e37


@njit(cache=True, inline="always")
def prepare_pixel(i, j, first, second, nsig, emission, has_emission, albedo_in, normal_in, depth_in,
                  obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion):
    """Demodulate pixel (i, j) and write its planar G-buffer.

    The first signal is demodulated as ``(first - emission) / max(albedo, albedo_eps)`` (the
    emitted radiance is direct light and is not filtered; :func:`remodulate_pixel` adds it back).

    Parameters
    ----------
    i, j : int
        Row and column.
    first, second : ndarray (H, W, 3) float32
        The signals (``direct`` and ``indirect``, or ``color`` twice with ``nsig == 1``).
    nsig : int
        Number of signals, 1 or 2.
    emission : ndarray (H, W, 3) float32
        Radiance emitted by the first-hit surface (read only when ``has_emission``).
    has_emission : bool
        Whether the frame has an ``emission`` channel.
    albedo_in, normal_in : ndarray (H, W, 3) float32
    depth_in : ndarray (H, W) float32
    obj_in : ndarray (H, W) int32
    motion_in : ndarray (H, W, 2) float32
    albedo_eps : float
        Demodulation divides by ``max(albedo, albedo_eps)``.
    sig, albedo, valid, depth, normal, obj, motion : ndarray
        Outputs: ``(S, 3, H, W)``, ``(3, H, W)``, ``(H, W)`` uint8, ``(H, W)``, ``(3, H, W)``,
        ``(H, W)`` int32, ``(2, H, W)``.
    """
    h = depth_in.shape[0]
    w = depth_in.shape[1]
    z = depth_in[i, j]
    oid = obj_in[i, j]
    ok = oid >= 0 and math.isfinite(z)
    valid[i, j] = 1 if ok else 0
    obj[i, j] = oid
    depth[i, j] = z if ok else 0.0
    lim = float(h + w + 4)
    motion[0, i, j] = min(max(motion_in[i, j, 0], -lim), lim)
    motion[1, i, j] = min(max(motion_in[i, j, 1], -lim), lim)
    for c in range(3):
        normal[c, i, j] = normal_in[i, j, c] if ok else 0.0
        a = max(albedo_in[i, j, c], albedo_eps)
        albedo[c, i, j] = a
        if ok:
            e = emission[i, j, c] if has_emission else 0.0
            sig[0, c, i, j] = min(max((first[i, j, c] - e) / a, -F32_BIG), F32_BIG)
            if nsig == 2:
                sig[1, c, i, j] = min(max(second[i, j, c] / a, -F32_BIG), F32_BIG)
        else:
            for s in range(nsig):
                sig[s, c, i, j] = 0.0


@njit(cache=True, inline="always")
def remodulate_pixel(i, j, sig, albedo, valid, color, emission, has_emission, out):
    """Write ``albedo * sum of filtered signals + emission`` at pixel (i, j), the input colour on
    background.

    Parameters
    ----------
    sig : ndarray (S, 3, H, W) float32
        Filtered demodulated signals.
    albedo : ndarray (3, H, W) float32
        ``max(albedo, albedo_eps)`` from :func:`prepare_pixel`.
    valid : ndarray (H, W) uint8
    color : ndarray (H, W, 3) float32
        The input colour (copied on background pixels).
    emission : ndarray (H, W, 3) float32
        Emitted radiance added back unfiltered (read only when ``has_emission``).
    has_emission : bool
    out : ndarray (H, W, 3) float32
    """
    if valid[i, j] == 0:
        for c in range(3):
            out[i, j, c] = color[i, j, c]
        return
    for c in range(3):
        acc = 0.0
        for s in range(sig.shape[0]):
            acc += sig[s, c, i, j]
        e = emission[i, j, c] if has_emission else 0.0
        out[i, j, c] = min(max(albedo[c, i, j] * acc + e, -F32_BIG), F32_BIG)
