"""CUDA kernels of SBF (``numba.cuda``): one thread per pixel, same maths as :mod:`.cpu`.

The host wrappers take and fill the same NumPy arrays as the CPU kernels, so the pipeline
calls either module alike. Sums are float64; ``exp`` is the device's, clamped at ``exp(-128)``
as on the CPU.
"""

from __future__ import annotations

import math

from numba import cuda, float32, float64

#: most candidates a bank may hold (the local accumulators are sized for it)
MAX_CANDIDATES = 16
_ACC_SIZE = 4 * MAX_CANDIDATES
_THREADS = (16, 16)
_EXP_CLAMP = 128.0
_FLOAT32_MAX = 3.4028234663852886e38


@cuda.jit(device=True)
def _feature_distance(feat, i, j, ii, jj):
    d = float32(0.0)
    for c in range(feat.shape[0]):
        e = feat[c, i, j] - feat[c, ii, jj]
        d += e * e
    return d


@cuda.jit
def _bank_kernel(color, var, feat, noisy, table, first, out_f, out_sure):
    j, i = cuda.grid(2)
    h, w = noisy.shape
    if i >= h or j >= w:
        return
    n_k = table.shape[0]
    if noisy[i, j] == 0:
        for k in range(n_k):
            for ch in range(3):
                out_f[k, ch, i, j] = color[ch, i, j]
            out_sure[k, i, j] = 0.0
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
            jj = j + dx
            if jj < 0 or jj >= w:
                continue
            d = float64(_feature_distance(feat, i, j, ii, jj))
            e = math.exp(-min(d, _EXP_CLAMP))
            c0 = e * color[0, ii, jj]
            c1 = e * color[1, ii, jj]
            c2 = e * color[2, ii, jj]
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
            y = float64(color[ch, i, j])
            v = float64(var[ch, i, j])
            out_f[k, ch, i, j] = f
            risk += (f - y) * (f - y) + 2.0 * v / wsum - v
        out_sure[k, i, j] = risk / 3.0


@cuda.jit
def _select_kernel(color, feat, noisy, table, f_bank, sure, out, best, min_sure):
    j, i = cuda.grid(2)
    h, w = noisy.shape
    if i >= h or j >= w:
        return
    n_k = sure.shape[0]
    if noisy[i, j] == 0:
        for ch in range(3):
            out[ch, i, j] = color[ch, i, j]
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
            jj = j + dx
            if jj < 0 or jj >= w or noisy[ii, jj] == 0:
                continue
            d = float64(_feature_distance(feat, i, j, ii, jj))
            e = table[dy + rad, dx + rad] * math.exp(-min(d, _EXP_CLAMP))
            wsum += e
            for k in range(n_k):
                acc[k] += e * sure[k, ii, jj]
    pick = 0
    low = acc[0] / wsum  # wsum >= 1: the centre tap
    for k in range(1, n_k):
        value = acc[k] / wsum
        if value < low:
            low = value
            pick = k
    for ch in range(3):
        out[ch, i, j] = f_bank[pick, ch, i, j]
    best[i, j] = pick
    min_sure[i, j] = low


def _grid(shape):
    h, w = shape
    return ((w + _THREADS[0] - 1) // _THREADS[0], (h + _THREADS[1] - 1) // _THREADS[1])


def _check_bank_size(n_k):
    if n_k > MAX_CANDIDATES:
        raise ValueError(f"sbf (cuda): at most {MAX_CANDIDATES} candidates, got {n_k}")


def candidate_bank(color, var, feat, noisy, table, first, out_f, out_sure):
    """CUDA version of :func:`.cpu.candidate_bank` (same arguments; outputs copied back)."""
    _check_bank_size(table.shape[0])
    d_f = cuda.device_array(out_f.shape, out_f.dtype)
    d_s = cuda.device_array(out_sure.shape, out_sure.dtype)
    args = [cuda.to_device(a) for a in (color, var, feat, noisy, table, first)]
    _bank_kernel[_grid(noisy.shape), _THREADS](*args, d_f, d_s)
    d_f.copy_to_host(out_f)
    d_s.copy_to_host(out_sure)
    cuda.synchronize()


def smooth_and_select(color, feat, noisy, table, f_bank, sure, out, best, min_sure):
    """CUDA version of :func:`.cpu.smooth_and_select` (same arguments; outputs copied back)."""
    _check_bank_size(sure.shape[0])
    d_out = cuda.device_array(out.shape, out.dtype)
    d_best = cuda.device_array(best.shape, best.dtype)
    d_min = cuda.device_array(min_sure.shape, min_sure.dtype)
    args = [cuda.to_device(a) for a in (color, feat, noisy, table, f_bank, sure)]
    _select_kernel[_grid(noisy.shape), _THREADS](*args, d_out, d_best, d_min)
    d_out.copy_to_host(out)
    d_best.copy_to_host(best)
    d_min.copy_to_host(min_sure)
    cuda.synchronize()


@cuda.jit
def _variance_kernel(color, feat, radius, unknown, out):
    j, i = cuda.grid(2)
    h, w = unknown.shape
    if i >= h or j >= w or unknown[i, j] == 0:
        return
    sw = 0.0
    sw2 = 0.0
    s = cuda.local.array(3, float64)
    q = cuda.local.array(3, float64)
    for ch in range(3):
        s[ch] = 0.0
        q[ch] = 0.0
    for ii in range(max(i - radius, 0), min(i + radius + 1, h)):
        for jj in range(max(j - radius, 0), min(j + radius + 1, w)):
            d = float64(_feature_distance(feat, i, j, ii, jj))
            wt = math.exp(-min(d, _EXP_CLAMP))
            sw += wt
            sw2 += wt * wt
            for ch in range(3):
                y = float64(color[ch, ii, jj])
                s[ch] += wt * y
                q[ch] += wt * y * y
    denom = sw - sw2 / sw  # sw >= 1: the centre tap
    for ch in range(3):
        v = 0.0
        if denom > 1e-3:
            v = min(max(q[ch] - s[ch] * s[ch] / sw, 0.0) / denom, _FLOAT32_MAX)
        out[ch, i, j] = v


def spatial_variance(color, feat, radius, unknown, out):
    """CUDA version of :func:`.cpu.spatial_variance` (same arguments; ``out`` updated)."""
    d_out = cuda.to_device(out)
    args = [cuda.to_device(a) for a in (color, feat)]
    _variance_kernel[_grid(unknown.shape), _THREADS](*args, radius, cuda.to_device(unknown), d_out)
    d_out.copy_to_host(out)
    cuda.synchronize()
