"""CPU kernels of SBF (Numba): the whole pass (bank, SURE, smoothing, selection) streamed by rows.

Layout. Colour and features are planar float32 planes whose rows carry ``pad`` columns of
zeros on both sides (:func:`.layout.pack`), so every tap of a window is an in-bounds load and
the inner loops, which run along a row, vectorise without edge cases; a plane ``inside`` (1 in
the image, 0 in the padding) zeroes the weights of taps outside the image, and a plane
``valid`` (1 on noisy pixels) those that the SURE smoothing must ignore.

Streaming. The image is processed in chunks of rows: the candidate bank of rows
``[r, r + C)``, then the smoothing and selection of the rows whose SURE window is complete
(``[r - R_s, r + C - R_s)``). Candidates and SURE live in ring buffers of ``C + 2 R_s`` rows
(row ``i`` in slot ``i % rows``), so the scratch memory does not grow with the image height.

Parallel loops. Inside a chunk, tiles of one row by ``BLOCK`` pixels are dealt cyclically to
``slots`` workers (tile ``t`` to worker ``t % slots``), so each worker gets every other tile
and neighbouring tiles (similar cost: both sky or both geometry) go to different workers; a
static split into halves would give one worker all the sky.

Arithmetic. Feature weights ``exp(-|f_i - f_j|^2)`` are float32 (:func:`harness.kernels.exp_neg`,
a few ulps); each candidate's four sums (weight, weighted RGB) add groups of ``GROUP``
neighbouring taps in float32 and accumulate the groups in float64; SURE and its smoothing are
float64. Tiles without a noisy pixel are skipped.
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from harness import kernels

BLOCK = 512
#: taps of a row summed together in one inner loop (fewer stores to the accumulators)
GROUP = 4


@njit(cache=True, fastmath=True)
def _tile_has(mask, i, c0, c1):
    for c in range(c0, c1):
        if mask[i, c] > 0:
            return True
    return False


@njit(cache=True, fastmath=True)
def _weights(fpad, mask, i, ii, a, b, n, wt):
    """``wt[:n] = exp(-|f(i, a + j) - f(ii, b + j)|^2) * mask[ii, b + j]`` (float32).

    Seven feature planes (normal, albedo, depth); 1-D views indexed by the range variable so
    that the loop vectorises.
    """
    fa0 = fpad[0, i, a:a + n]
    fa1 = fpad[1, i, a:a + n]
    fa2 = fpad[2, i, a:a + n]
    fa3 = fpad[3, i, a:a + n]
    fa4 = fpad[4, i, a:a + n]
    fa5 = fpad[5, i, a:a + n]
    fa6 = fpad[6, i, a:a + n]
    fb0 = fpad[0, ii, b:b + n]
    fb1 = fpad[1, ii, b:b + n]
    fb2 = fpad[2, ii, b:b + n]
    fb3 = fpad[3, ii, b:b + n]
    fb4 = fpad[4, ii, b:b + n]
    fb5 = fpad[5, ii, b:b + n]
    fb6 = fpad[6, ii, b:b + n]
    m = mask[ii, b:b + n]
    for j in range(n):
        e0 = fa0[j] - fb0[j]
        e1 = fa1[j] - fb1[j]
        e2 = fa2[j] - fb2[j]
        e3 = fa3[j] - fb3[j]
        e4 = fa4[j] - fb4[j]
        e5 = fa5[j] - fb5[j]
        e6 = fa6[j] - fb6[j]
        d = e0 * e0 + e1 * e1 + e2 * e2 + e3 * e3 + e4 * e4 + e5 * e5 + e6 * e6
        wt[j] = kernels.exp_neg(d) * m[j]


@njit(cache=True, fastmath=True)
def _bank_tile(cpad, fpad, inside, valid, var, table, first, radius, pad, i, j0, n,
               acc, wb, cand, sure, slot):
    """Candidates and SURE of the pixels ``(i, j0 .. j0 + n)``, written to ring slot ``slot``."""
    n_k = table.shape[0]
    big = (table.shape[1] - 1) // 2
    h = cpad.shape[1]
    acc[:, :, :n] = 0.0
    a = pad + j0
    for dy in range(-big, big + 1):
        ii = i + dy
        if ii < 0 or ii >= h:
            continue
        # weights and weighted colours of every tap of this row: wb[q, dx + big, j]
        for dx in range(-big, big + 1):
            b = a + dx
            w0 = wb[0, dx + big]
            _weights(fpad, inside, i, ii, a, b, n, w0)
            w1 = wb[1, dx + big]
            w2 = wb[2, dx + big]
            w3 = wb[3, dx + big]
            c0 = cpad[0, ii, b:b + n]
            c1 = cpad[1, ii, b:b + n]
            c2 = cpad[2, ii, b:b + n]
            for j in range(n):
                w1[j] = w0[j] * c0[j]
                w2[j] = w0[j] * c1[j]
                w3[j] = w0[j] * c2[j]
        for k in range(first[abs(dy)], n_k):
            r = radius[k]
            row = table[k, dy + big]
            for dx0 in range(-r, r + 1, GROUP):
                q = dx0 + big
                g0 = np.float32(row[q])
                g1 = np.float32(row[q + 1])
                g2 = np.float32(row[q + 2])
                g3 = np.float32(row[q + 3])
                for ch in range(4):
                    s = acc[k, ch, :n]
                    x0 = wb[ch, q, :n]
                    x1 = wb[ch, q + 1, :n]
                    x2 = wb[ch, q + 2, :n]
                    x3 = wb[ch, q + 3, :n]
                    for j in range(n):
                        s[j] += np.float64(g0 * x0[j] + g1 * x1[j] + g2 * x2[j] + g3 * x3[j])
    for j in range(n):
        jj = j0 + j
        for k in range(n_k):
            if not valid[i, a + j] > 0:
                for ch in range(3):
                    cand[k, ch, slot, jj] = cpad[ch, i, a + j]
                sure[k, slot, a + j] = 0.0
                continue
            wsum = acc[k, 0, j]  # >= 1: the centre tap
            risk = 0.0
            for ch in range(3):
                f = acc[k, 1 + ch, j] / wsum
                y = np.float64(cpad[ch, i, a + j])
                v = np.float64(var[i, jj, ch])
                cand[k, ch, slot, jj] = f
                risk += (f - y) * (f - y) + 2.0 * v / wsum - v
            sure[k, slot, a + j] = risk / 3.0


@njit(cache=True, fastmath=True)
def _select_tile(cpad, fpad, valid, stable, pad, i, j0, n, acc, ws, wt, wg, cand, sure,
                 slot, out, best, min_sure):
    """Smooth the SURE maps around ``(i, j0 .. j0 + n)``, pick the argmin, write the output."""
    n_k = sure.shape[0]
    rad = (stable.shape[0] - 1) // 2
    h = fpad.shape[1]
    rows = sure.shape[1]
    a = pad + j0
    acc[:, :n] = 0.0
    ws[:n] = 0.0
    for dy in range(-rad, rad + 1):
        ii = i + dy
        if ii < 0 or ii >= h:
            continue
        ring = ii % rows
        for dx in range(-rad, rad + 1):
            _weights(fpad, valid, i, ii, a, a + dx, n, wt)
            g = stable[dy + rad, dx + rad]
            x = wg[dx + rad]
            for j in range(n):
                x[j] = g * np.float64(wt[j])
        for dx0 in range(-rad, rad + 1, GROUP):
            q = dx0 + rad
            x0 = wg[q, :n]
            x1 = wg[q + 1, :n]
            x2 = wg[q + 2, :n]
            x3 = wg[q + 3, :n]
            s = ws[:n]
            for j in range(n):
                s[j] += x0[j] + x1[j] + x2[j] + x3[j]
            b = a + dx0
            for k in range(n_k):
                y0 = sure[k, ring, b:b + n]
                y1 = sure[k, ring, b + 1:b + 1 + n]
                y2 = sure[k, ring, b + 2:b + 2 + n]
                y3 = sure[k, ring, b + 3:b + 3 + n]
                s = acc[k, :n]
                for j in range(n):
                    s[j] += x0[j] * y0[j] + x1[j] * y1[j] + x2[j] * y2[j] + x3[j] * y3[j]
    slot = i % rows
    for j in range(n):
        jj = j0 + j
        pick = 0
        low = 0.0
        if valid[i, a + j] > 0:
            norm = ws[j]  # >= 1: the centre tap
            low = acc[0, j] / norm
            for k in range(1, n_k):
                value = acc[k, j] / norm
                if value < low:
                    low = value
                    pick = k
            for ch in range(3):
                out[i, jj, ch] = cand[pick, ch, slot, jj]
        else:
            for ch in range(3):
                out[i, jj, ch] = cpad[ch, i, a + j]
        best[i, jj] = pick
        min_sure[i, jj] = low


@njit(parallel=True, cache=True, fastmath=True)
def sbf_pass(cpad, fpad, inside, valid, var, table, first, radius, stable, pad,
             out, best, min_sure, cand, sure, slots):
    """One SBF pass: candidate bank with SURE, SURE smoothing, per-pixel argmin.

    Parameters
    ----------
    cpad, fpad : ndarray (3, H, W + 2 pad), (7, H, W + 2 pad) float32
        Padded planar colour and scaled features (:func:`.layout.pack`).
    inside, valid : ndarray (H, W + 2 pad) float32
        1 inside the image / on noisy pixels, 0 elsewhere (padding included).
    var : ndarray (H, W, 3) float32
        Variance of the pixel mean (>= 0, scaled like ``cpad``).
    table : ndarray (K, 2R + 1, 2R + GROUP) float64
        Spatial weights of the candidates (:func:`.bank.spatial_table`, zero columns appended).
    first, radius : ndarray int64
        First candidate reaching each ring; window radius of each candidate.
    stable : ndarray (2 R_s + 1, 2 R_s + GROUP) float64
        Spatial weights of the SURE smoothing, zero columns appended.
    pad : int
        Padding columns of the planes (at least ``max(R, R_s) + GROUP - 1``).
    out : ndarray (H, W, 3) float32
        The selected candidate per pixel, scaled like ``cpad`` (written).
    best, min_sure : ndarray (H, W) int32, float64
        Selected index (lowest on ties) and its smoothed SURE; 0 on noise-free pixels.
    cand, sure : ndarray (K, 3, rows, W) float32, (K, rows, W + 2 pad) float64
        Ring buffers of candidates and SURE (row ``i`` in slot ``i % rows``; with ``rows >= H``
        they hold every row afterwards). ``rows >= 2 R_s + 1``. ``sure`` must start finite
        (zeros).
    slots : int
        Parallel workers the tiles are dealt to.
    """
    n_k = table.shape[0]
    big = (table.shape[1] - 1) // 2
    rad = (stable.shape[0] - 1) // 2
    h = out.shape[0]
    w = out.shape[1]
    rows = sure.shape[1]
    chunk = max(rows - 2 * rad, 1)
    n_blocks = (w + BLOCK - 1) // BLOCK
    start = 0  # next bank row
    done = 0  # next selected row
    while done < h:
        stop = min(start + chunk, h)
        items = (stop - start) * n_blocks
        for s in prange(slots):
            acc = np.empty((n_k, 4, BLOCK))
            wb = np.zeros((4, 2 * big + GROUP, BLOCK), np.float32)
            for t in range(s, items, slots):
                i = start + t // n_blocks
                j0 = (t % n_blocks) * BLOCK
                n = min(BLOCK, w - j0)
                slot = i % rows
                if _tile_has(valid, i, pad + j0, pad + j0 + n):
                    _bank_tile(cpad, fpad, inside, valid, var, table, first, radius,
                               pad, i, j0, n, acc, wb, cand, sure, slot)
                else:
                    for j in range(j0, j0 + n):
                        for k in range(n_k):
                            for ch in range(3):
                                cand[k, ch, slot, j] = cpad[ch, i, pad + j]
                            sure[k, slot, pad + j] = 0.0
        start = stop
        last = h if start == h else max(start - rad, done)
        items = (last - done) * n_blocks
        for s in prange(slots):
            acc = np.empty((n_k, BLOCK))
            ws = np.empty(BLOCK)
            wt = np.empty(BLOCK, np.float32)
            wg = np.zeros((2 * rad + GROUP, BLOCK))
            for t in range(s, items, slots):
                i = done + t // n_blocks
                j0 = (t % n_blocks) * BLOCK
                n = min(BLOCK, w - j0)
                if _tile_has(valid, i, pad + j0, pad + j0 + n):
                    _select_tile(cpad, fpad, valid, stable, pad, i, j0, n, acc, ws, wt, wg,
                                 cand, sure, i % rows, out, best, min_sure)
                else:
                    for j in range(j0, j0 + n):
                        for ch in range(3):
                            out[i, j, ch] = cpad[ch, i, pad + j]
                        best[i, j] = 0
                        min_sure[i, j] = 0.0
        done = last


@njit(parallel=True, cache=True, fastmath=True)
def spatial_variance(cpad, fpad, inside, unknown, radius, pad, out, slots):
    """Estimate the per-sample colour variance from a feature-weighted neighbourhood.

    For each pixel with ``unknown`` set, the unbiased weighted variance
    ``sum w (y - m)^2 / (sum w - sum w^2 / sum w)`` over the ``(2 radius + 1)^2`` window, with
    feature weights ``exp(-|f_i - f_j|^2)``, is written to ``out[i, j, :]`` (float32, clamped
    to the float32 range); 0 where the window holds no other pixel of the same surface.

    Parameters
    ----------
    cpad, fpad, inside : ndarray
        As in :func:`sbf_pass`.
    unknown : ndarray (H, W) uint8
    radius, pad : int
        Window radius (at most ``pad - GROUP + 1``) and padding of the planes.
    out : ndarray (H, W, 3) float32
        Written where ``unknown``; left as is elsewhere.
    slots : int
        Parallel workers the rows are dealt to (cyclically).
    """
    h, w = unknown.shape
    big = np.float64(np.finfo(np.float32).max)
    n_blocks = (w + BLOCK - 1) // BLOCK
    items = h * n_blocks
    for s in prange(slots):
        # rows: sum w, sum w^2, sum w y (RGB), sum w y^2 (RGB)
        acc = np.empty((8, BLOCK))
        wt = np.empty(BLOCK, np.float32)
        for t in range(s, items, slots):
            i = t // n_blocks
            j0 = (t % n_blocks) * BLOCK
            n = min(BLOCK, w - j0)
            if not _tile_has(unknown, i, j0, j0 + n):
                continue
            acc[:, :n] = 0.0
            a = pad + j0
            for dy in range(-radius, radius + 1):
                ii = i + dy
                if ii < 0 or ii >= h:
                    continue
                for dx in range(-radius, radius + 1):
                    b = a + dx
                    _weights(fpad, inside, i, ii, a, b, n, wt)
                    c0 = cpad[0, ii, b:b + n]
                    c1 = cpad[1, ii, b:b + n]
                    c2 = cpad[2, ii, b:b + n]
                    sw = acc[0, :n]
                    sw2 = acc[1, :n]
                    s0 = acc[2, :n]
                    s1 = acc[3, :n]
                    s2 = acc[4, :n]
                    q0 = acc[5, :n]
                    q1 = acc[6, :n]
                    q2 = acc[7, :n]
                    for j in range(n):
                        e = np.float64(wt[j])
                        y0 = np.float64(c0[j])
                        y1 = np.float64(c1[j])
                        y2 = np.float64(c2[j])
                        sw[j] += e
                        sw2[j] += e * e
                        s0[j] += e * y0
                        s1[j] += e * y1
                        s2[j] += e * y2
                        q0[j] += e * y0 * y0
                        q1[j] += e * y1 * y1
                        q2[j] += e * y2 * y2
            for j in range(n):
                if not unknown[i, j0 + j]:
                    continue
                denom = acc[0, j] - acc[1, j] / acc[0, j]  # acc[0] >= 1: the centre tap
                for ch in range(3):
                    v = 0.0
                    if denom > 1e-3:
                        m2 = acc[5 + ch, j] - acc[2 + ch, j] * acc[2 + ch, j] / acc[0, j]
                        v = min(max(m2, 0.0) / denom, big)
                    out[i, j0 + j, ch] = v
