"""CUDA backend of the EAW filter: one ``numba.cuda`` kernel launch per à-trous iteration.

The frame is surveyed and packed on the host into the padded planar layout of :mod:`.layout`
(the same passes as the CPU backend), copied to the device once, filtered there, and the final
colour planes are copied back. One thread per pixel; threads of background and noise-free
pixels return at once. The packed values are bounded, so the kernel needs no overflow guard.

No shared-memory tiling: at hole spacing ``2**i`` a block's 5x5 footprint spans
``(block + 4 * 2**i)`` pixels per axis, which for the later iterations exceeds shared memory for
10 planes, while the first iterations' footprints are served by the L1/texture cache. Not
measured here (no GPU on the development machine).

Import this module only when the backend is used (:func:`harness.load_backend` does):
``NUMBA_ENABLE_CUDASIM`` must be set before ``numba.cuda`` is first imported.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import cuda

from .layout import ACTIVE, Buffers, prepare, unpack

BLOCK = (8, 32)  # threads per block (rows, columns)
#: largest exponent of the weight; exp(-100) is below float32's smallest normal
ARG_MAX = np.float32(100.0)


@cuda.jit(fastmath=True)
def _atrous_kernel(src, dst, guide, state, halo, stride, step, a_c, a_n, a_x, taps):
    y, x = cuda.grid(2)
    h, w = state.shape
    if y >= h or x >= w or state[y, x] != ACTIVE:
        return
    ps = src.shape[0] // 3
    ic = (y + halo) * stride + halo + x
    cr = src[ic]
    cg = src[ps + ic]
    cb = src[2 * ps + ic]
    n0 = guide[ic]
    n1 = guide[ps + ic]
    n2 = guide[2 * ps + ic]
    p0 = guide[3 * ps + ic]
    p1 = guide[4 * ps + ic]
    p2 = guide[5 * ps + ic]
    sr = np.float32(0.0)
    sg = np.float32(0.0)
    sb = np.float32(0.0)
    ws = taps[12]  # the centre tap: weight 1, no change
    for k in range(25):
        if k == 12:
            continue
        iq = ic + ((k // 5 - 2) * stride + (k % 5 - 2)) * step
        dr = src[iq] - cr
        dg = src[ps + iq] - cg
        db = src[2 * ps + iq] - cb
        e0 = guide[iq] - n0
        e1 = guide[ps + iq] - n1
        e2 = guide[2 * ps + iq] - n2
        f0 = guide[3 * ps + iq] - p0
        f1 = guide[4 * ps + iq] - p1
        f2 = guide[5 * ps + iq] - p2
        arg = (a_c * (dr * dr + dg * dg + db * db) + a_n * (e0 * e0 + e1 * e1 + e2 * e2)
               + a_x * (f0 * f0 + f1 * f1 + f2 * f2))
        wt = taps[k] * guide[6 * ps + iq] * math.exp(-min(arg, ARG_MAX))
        sr += wt * dr
        sg += wt * dg
        sb += wt * db
        ws += wt
    inv = np.float32(1.0) / ws
    dst[ic] = cr + sr * inv
    dst[ps + ic] = cg + sg * inv
    dst[2 * ps + ic] = cb + sb * inv


def run(frame, params, coefficients, taps, buffers: Buffers):
    """Filter one frame on the GPU; same arguments and results as :func:`.cpu.run` (stages
    ``prepare``, ``atrous`` and ``unpack``)."""
    t0 = time.perf_counter()
    color, scale = prepare(frame, params, buffers)
    b = buffers
    src = cuda.to_device(b.color[0])
    dst = cuda.to_device(b.color[1])
    guide = cuda.to_device(b.guide)
    d_state = cuda.to_device(b.state)
    d_taps = cuda.to_device(taps)
    t1 = time.perf_counter()
    h, w = b.state.shape
    grid = (math.ceil(h / BLOCK[0]), math.ceil(w / BLOCK[1]))
    for i in range(coefficients.shape[0]):
        a_c, a_n, a_x = (np.float32(v) for v in coefficients[i])
        _atrous_kernel[grid, BLOCK](src, dst, guide, d_state, b.halo, b.stride, 2**i, a_c, a_n, a_x, d_taps)
        src, dst = dst, src
    cuda.synchronize()
    t2 = time.perf_counter()
    out = np.empty(color.shape, np.float32)
    unpack(color, b.state, src.copy_to_host(), 1.0 / scale, scale, b.halo, b.stride, out)
    t3 = time.perf_counter()
    return out, {"prepare": (t1 - t0) * 1e3, "atrous": (t2 - t1) * 1e3, "unpack": (t3 - t2) * 1e3}
