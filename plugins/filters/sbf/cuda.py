"""CUDA kernels of SBF (``numba.cuda``): one thread per pixel, same maths and entry points as :mod:`.cpu`.

The host wrappers take the same padded planes (:mod:`.layout`) and fill the same NumPy arrays
as the CPU kernels, so the pipeline calls either module alike. The device keeps every
candidate and SURE map in full-frame buffers (GPU memory is not the constraint here); they are
copied into the host's ring buffers only when those hold every row (``keep``). Feature weights
are ``exp(-min(d, 87))`` as on the CPU; sums are float64.
"""

from __future__ import annotations

import math

import numpy as np
from numba import cuda, float64

#: most candidates a bank may hold (the local accumulators are sized for it)
MAX_CANDIDATES = 16
_ACC_SIZE = 4 * MAX_CANDIDATES
_THREADS = (16, 16)
_EXP_CLAMP = 87.0
_FLOAT32_MAX = 3.4028234663852886e38


@cuda.jit(device=True)
def _weight(fpad, mask, i, a, ii, b):
    d = 0.0
    for c in range(fpad.shape[0]):
        e = float64(fpad[c, i, a]) - float64(fpad[c, ii, b])
        d += e * e
    return math.exp(-min(d, _EXP_CLAMP)) * mask[ii, b]


@cuda.jit
def _bank_kernel(cpad, fpad, inside, valid, var, table, first, pad, out_f, out_sure):
    j, i = cuda.grid(2)
    h, w = var.shape[0], var.shape[1]
    if i >= h or j >= w:
        return
    n_k = table.shape[0]
    a = pad + j
    if valid[i, a] == 0:
        for k in range(n_k):
            for ch in range(3):
                out_f[k, ch, i, j] = cpad[ch, i, a]
            out_sure[k, i, a] = 0.0
        return
    big = (table.shape[1] - 1) // 2
    acc = cuda.local.array(_ACC_SIZE, float64)
    for k in range(4 * n_k):
        acc[k] = 0.0
    for dy in range(-big, big + 1):
        ii = i + dy
        if ii < 0 or ii >= h:
            continue
        for dx in range(-big, big + 1):
            e = _weight(fpad, inside, i, a, ii, a + dx)
            c0 = e * cpad[0, ii, a + dx]
            c1 = e * cpad[1, ii, a + dx]
            c2 = e * cpad[2, ii, a + dx]
            for k in range(first[max(abs(dy), abs(dx))], n_k):
                g = table[k, dy + big, dx + big]
                acc[4 * k] += g * c0
                acc[4 * k + 1] += g * c1
                acc[4 * k + 2] += g * c2
                acc[4 * k + 3] += g * e
    for k in range(n_k):
        wsum = acc[4 * k + 3]  # >= 1: the centre tap
        risk = 0.0
        for ch in range(3):
            f = acc[4 * k + ch] / wsum
            y = float64(cpad[ch, i, a])
            v = float64(var[i, j, ch])
            out_f[k, ch, i, j] = f
            risk += (f - y) * (f - y) + 2.0 * v / wsum - v
        out_sure[k, i, a] = risk / 3.0


@cuda.jit
def _select_kernel(cpad, fpad, valid, table, pad, f_bank, sure, out, best, min_sure):
    j, i = cuda.grid(2)
    h, w = out.shape[0], out.shape[1]
    if i >= h or j >= w:
        return
    n_k = sure.shape[0]
    a = pad + j
    if valid[i, a] == 0:
        for ch in range(3):
            out[i, j, ch] = cpad[ch, i, a]
        best[i, j] = 0
        min_sure[i, j] = 0.0
        return
    rad = (table.shape[0] - 1) // 2
    acc = cuda.local.array(MAX_CANDIDATES, float64)
    for k in range(n_k):
        acc[k] = 0.0
    wsum = 0.0
    for dy in range(-rad, rad + 1):
        ii = i + dy
        if ii < 0 or ii >= h:
            continue
        for dx in range(-rad, rad + 1):
            e = table[dy + rad, dx + rad] * _weight(fpad, valid, i, a, ii, a + dx)
            wsum += e
            for k in range(n_k):
                acc[k] += e * sure[k, ii, a + dx]
    pick = 0
    low = acc[0] / wsum  # wsum >= 1: the centre tap
    for k in range(1, n_k):
        value = acc[k] / wsum
        if value < low:
            low = value
            pick = k
    for ch in range(3):
        out[i, j, ch] = f_bank[pick, ch, i, j]
    best[i, j] = pick
    min_sure[i, j] = low


@cuda.jit
def _variance_kernel(cpad, fpad, inside, unknown, radius, pad, out):
    j, i = cuda.grid(2)
    h, w = unknown.shape
    if i >= h or j >= w or unknown[i, j] == 0:
        return
    a = pad + j
    sw = 0.0
    sw2 = 0.0
    s = cuda.local.array(3, float64)
    q = cuda.local.array(3, float64)
    for ch in range(3):
        s[ch] = 0.0
        q[ch] = 0.0
    for ii in range(max(i - radius, 0), min(i + radius + 1, h)):
        for dx in range(-radius, radius + 1):
            wt = _weight(fpad, inside, i, a, ii, a + dx)
            sw += wt
            sw2 += wt * wt
            for ch in range(3):
                y = float64(cpad[ch, ii, a + dx])
                s[ch] += wt * y
                q[ch] += wt * y * y
    denom = sw - sw2 / sw  # sw >= 1: the centre tap
    for ch in range(3):
        v = 0.0
        if denom > 1e-3:
            v = min(max(q[ch] - s[ch] * s[ch] / sw, 0.0) / denom, _FLOAT32_MAX)
        out[i, j, ch] = v


def _grid(h, w):
    return ((w + _THREADS[0] - 1) // _THREADS[0], (h + _THREADS[1] - 1) // _THREADS[1])


def sbf_pass(cpad, fpad, inside, valid, var, table, first, radius, stable, pad, out, best,
             min_sure, cand, sure, slots):
    """CUDA version of :func:`.cpu.sbf_pass` (same arguments; ``radius`` and ``slots`` unused).

    ``cand`` and ``sure`` receive every row when they hold at least ``H`` rows.
    """
    n_k = table.shape[0]
    if n_k > MAX_CANDIDATES:
        raise ValueError(f"sbf (cuda): at most {MAX_CANDIDATES} candidates, got {n_k}")
    h, w = out.shape[:2]
    grid = _grid(h, w)
    d_cpad, d_fpad, d_valid = cuda.to_device(cpad), cuda.to_device(fpad), cuda.to_device(valid)
    d_f = cuda.device_array((n_k, 3, h, w), np.float32)
    d_s = cuda.to_device(np.zeros((n_k, h, cpad.shape[2])))
    _bank_kernel[grid, _THREADS](d_cpad, d_fpad, cuda.to_device(inside), d_valid,
                                 cuda.to_device(var), cuda.to_device(table), cuda.to_device(first),
                                 pad, d_f, d_s)
    d_out = cuda.device_array(out.shape, out.dtype)
    d_best = cuda.device_array(best.shape, best.dtype)
    d_min = cuda.device_array(min_sure.shape, min_sure.dtype)
    _select_kernel[grid, _THREADS](d_cpad, d_fpad, d_valid, cuda.to_device(stable), pad, d_f, d_s,
                                   d_out, d_best, d_min)
    d_out.copy_to_host(out)
    d_best.copy_to_host(best)
    d_min.copy_to_host(min_sure)
    if cand.shape[2] >= h:
        cand[:, :, :h] = d_f.copy_to_host()
        sure[:, :h] = d_s.copy_to_host()
    cuda.synchronize()


def spatial_variance(cpad, fpad, inside, unknown, radius, pad, out, slots):
    """CUDA version of :func:`.cpu.spatial_variance` (same arguments; ``out`` updated)."""
    d_out = cuda.to_device(out)
    h, w = unknown.shape
    _variance_kernel[_grid(h, w), _THREADS](cuda.to_device(cpad), cuda.to_device(fpad),
                                            cuda.to_device(inside), cuda.to_device(unknown),
                                            radius, pad, d_out)
    d_out.copy_to_host(out)
    cuda.synchronize()
