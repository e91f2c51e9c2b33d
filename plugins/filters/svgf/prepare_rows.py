"""Row-vectorized demodulation and remodulation for the ``cpu`` backend.

The same results as :func:`.modulation.prepare_pixel` and :func:`.modulation.remodulate_pixel`
(bit for bit: the same float64 operations in the same order, no ``fastmath``), written as
branch-free loops over the pixels of a row with unsigned column indices, so that LLVM
vectorizes them: the per-pixel functions (which the CUDA backend runs) branch on the pixel's
class and index with signed integers, which kept the loops scalar.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, uint64

from .modulation import DEPTH_MAX, F32_BIG, demodulation_albedo, largest_albedo, pixel_kind


@njit(cache=True, inline="always")
def _finite_or_zero(x):
    """``x`` as float64 where it is finite, else 0 (as :func:`.modulation.finite_or_zero`)."""
    return np.float64(x) if math.isfinite(x) else 0.0


@njit(cache=True, error_model="numpy", inline="always")
def prepare_row(i, color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in, obj_in,
                motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion):
    """:func:`.modulation.prepare_pixel` for every pixel of row ``i`` (same arguments, no ``j``)."""
    h = depth_in.shape[0]
    w = depth_in.shape[1]
    lim = float(h + w + 4)
    for t in range(w):
        j = uint64(t)
        z = depth_in[i, j]
        oid = obj_in[i, j]
        n0 = normal_in[i, j, 0]
        n1 = normal_in[i, j, 1]
        n2 = normal_in[i, j, 2]
        ok = np.int64(oid >= 0) * np.int64(math.isfinite(z)) * np.int64(math.isfinite(n0)) \
            * np.int64(math.isfinite(n1)) * np.int64(math.isfinite(n2)) \
            * np.int64((n0 != 0.0) | (n1 != 0.0) | (n2 != 0.0))
        largest = largest_albedo(albedo_in[i, j, 0], albedo_in[i, j, 1], albedo_in[i, j, 2])
        valid[i, j] = np.uint8(pixel_kind(ok != 0, largest))
        obj[i, j] = oid
        depth[i, j] = min(max(z, -DEPTH_MAX), DEPTH_MAX) if ok != 0 else 0.0
        normal[0, i, j] = min(max(n0, -1.0), 1.0) if ok != 0 else 0.0
        normal[1, i, j] = min(max(n1, -1.0), 1.0) if ok != 0 else 0.0
        normal[2, i, j] = min(max(n2, -1.0), 1.0) if ok != 0 else 0.0
        for k in range(2):
            m = motion_in[i, j, k]
            motion[k, i, j] = min(max(m, -lim), lim) if m == m else lim  # NaN: outside, no history
    for c in range(3):
        for t in range(w):
            j = uint64(t)
            largest = largest_albedo(albedo_in[i, j, 0], albedo_in[i, j, 1], albedo_in[i, j, 2])
            a = demodulation_albedo(albedo_in[i, j, c], largest, albedo_eps)
            albedo[c, i, j] = a
            e = _finite_or_zero(emission[i, j, c]) if has_emission else 0.0
            rest = _finite_or_zero(color[i, j, c]) - e
            ok = np.int64(valid[i, j])  # (an int: bool variables cost the arrays their noalias)
            if nsig == 2:
                ind = _finite_or_zero(indirect[i, j, c])
                rest -= ind
                sig[1, c, i, j] = min(max(ind / a, -F32_BIG), F32_BIG) if ok != 0 else 0.0
            sig[0, c, i, j] = min(max(rest / a, -F32_BIG), F32_BIG) if ok != 0 else 0.0


@njit(cache=True, error_model="numpy", inline="always")
def _remodulated(sig, albedo, emission, has_emission, nsig, c, i, j):
    """``albedo * (sum of the signals) + emission`` of channel ``c`` at (i, j), bounded (float64,
    the operations of :func:`.modulation.remodulate_pixel`)."""
    acc = 0.0 + sig[0, c, i, j]
    if nsig == 2:
        acc += sig[1, c, i, j]
    e = _finite_or_zero(emission[i, j, c]) if has_emission else 0.0
    return min(max(albedo[c, i, j] * acc + e, -F32_BIG), F32_BIG)


@njit(cache=True, error_model="numpy", inline="always")
def remodulate_row(i, sig, albedo, valid, color, emission, has_emission, out):
    """:func:`.modulation.remodulate_pixel` for every pixel of row ``i`` (same arguments, no
    ``j``), branch-free."""
    nsig = sig.shape[0]
    for t in range(valid.shape[1]):
        j = uint64(t)
        ok = np.int64(valid[i, j])  # (an int: bool variables cost the arrays their noalias)
        r = _remodulated(sig, albedo, emission, has_emission, nsig, 0, i, j)
        g = _remodulated(sig, albedo, emission, has_emission, nsig, 1, i, j)
        b = _remodulated(sig, albedo, emission, has_emission, nsig, 2, i, j)
        out[i, j, 0] = r if ok != 0 else color[i, j, 0]
        out[i, j, 1] = g if ok != 0 else color[i, j, 1]
        out[i, j, 2] = b if ok != 0 else color[i, j, 2]
