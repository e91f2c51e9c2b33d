"""CUDA backend of the EAW filter: one ``numba.cuda`` kernel launch per à-trous iteration.

The frame is classified and packed on the host into the same padded planar layout as the CPU
backend (:mod:`.cpu`), copied to the device once, filtered there, and the final colour planes
are copied back. One thread per pixel; threads of background and noise-free pixels return at
once.

No shared-memory tiling: at hole spacing ``2**i`` a block's 5x5 footprint spans
``(block + 4 * 2**i)`` pixels per axis, which for the later iterations exceeds shared memory for
10 planes, while the first iterations' footprints are served by the L1/texture cache. Not
measured here (no GPU on the development machine).

Import this module only when the backend is used: ``NUMBA_ENABLE_CUDASIM`` must be set before
``numba.cuda`` is first imported.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import cuda

from . import cpu

BLOCK = (8, 32)  # threads per block (rows, columns)


@cuda.jit(fastmath=True)
def _atrous_kernel(src, dst, guide, state, halo, stride, step, a_c, a_n, a_x, taps):
    y, x = cuda.grid(2)
    h, w = state.shape
    if y >= h or x >= w or state[y, x] != cpu.ACTIVE:
        return
    ic = (y + halo) * stride + halo + x
    cr = src[0, ic]
    cg = src[1, ic]
    cb = src[2, ic]
    n0 = guide[0, ic]
    n1 = guide[1, ic]
    n2 = guide[2, ic]
    p0 = guide[3, ic]
    p1 = guide[4, ic]
    p2 = guide[5, ic]
    sr = np.float32(0.0)
    sg = np.float32(0.0)
    sb = np.float32(0.0)
    ws = taps[12]  # the centre tap: weight 1, no change
    for k in range(25):
        if k == 12:
            continue
        iq = ic + ((k // 5 - 2) * stride + (k % 5 - 2)) * step
        dr = src[0, iq] - cr
        dg = src[1, iq] - cg
        db = src[2, iq] - cb
        er = min(abs(dr), cpu.DIFF_MAX)
        eg = min(abs(dg), cpu.DIFF_MAX)
        eb = min(abs(db), cpu.DIFF_MAX)
        e0 = guide[0, iq] - n0
        e1 = guide[1, iq] - n1
        e2 = guide[2, iq] - n2
        f0 = guide[3, iq] - p0
        f1 = guide[4, iq] - p1
        f2 = guide[5, iq] - p2
        arg = (a_c * (er * er + eg * eg + eb * eb) + a_n * (e0 * e0 + e1 * e1 + e2 * e2)
               + a_x * (f0 * f0 + f1 * f1 + f2 * f2))
        wt = taps[k] * guide[6, iq] * math.exp(-min(arg, cpu.ARG_MAX))
        sr += wt * dr
        sg += wt * dg
        sb += wt * db
        ws += wt
    inv = np.float32(1.0) / ws
    dst[0, ic] = cr + sr * inv
    dst[1, ic] = cg + sg * inv
    dst[2, ic] = cb + sb * inv


def run(color, normal, position, state, coefficients, taps, scale, origin, pos_unit, halo):
    """Filter one frame on the GPU; same arguments and results as :func:`.cpu.run`.

    Parameters
    ----------
    halo : int
        Padding of the planar buffers (``2**iterations``).
    """
    t0 = time.perf_counter()
    h, w = state.shape
    buffers = cpu.Buffers(h, w, halo)
    inv_scale = 1.0 / scale
    host_a, host_b = buffers.color
    cpu.pack(color, normal, position, state, inv_scale, origin, 1.0 / pos_unit,
             halo, buffers.stride, host_a, host_b, buffers.guide)
    src = cuda.to_device(host_a)
    dst = cuda.to_device(host_b)
    guide = cuda.to_device(buffers.guide)
    d_state = cuda.to_device(state)
    d_taps = cuda.to_device(taps)
    t1 = time.perf_counter()
    grid = (math.ceil(h / BLOCK[0]), math.ceil(w / BLOCK[1]))
    for i in range(coefficients.shape[0]):
        a_c, a_n, a_x = (np.float32(v) for v in coefficients[i])
        _atrous_kernel[grid, BLOCK](src, dst, guide, d_state, halo, buffers.stride, 2**i, a_c, a_n, a_x, d_taps)
        src, dst = dst, src
    cuda.synchronize()
    t2 = time.perf_counter()
    out = np.empty(color.shape, np.float32)
    cpu.unpack(color, state, src.copy_to_host(), inv_scale, scale, halo, buffers.stride, out)
    t3 = time.perf_counter()
    return out, {"pack": (t1 - t0) * 1e3, "atrous": (t2 - t1) * 1e3, "unpack": (t3 - t2) * 1e3}
