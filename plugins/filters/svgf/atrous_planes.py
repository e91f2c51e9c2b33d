"""À-trous iterations of the ``cpu`` backend on padded float32 planes held in one array.

The same filter as :func:`plugins.filters.svgf.atrous.atrous_pixel` (same taps and weights),
laid out for LLVM's loop vectorizer:

* **One pool.** Every plane an iteration reads (surface mask, depth, depth slope, normal, and
  each signal's colour, variance and luminance) lies in one flat float32 array,
  :class:`PlanePool`, one plane after the other; the iterations ping-pong between two slots of
  signal planes in it. A tap loop loads from one array and updates one small per-thread array
  of accumulators; the parallel loop body creates no array view, so Numba marks both
  ``noalias`` and LLVM vectorizes without run-time aliasing tests.
* **Padding.** Planes have a zero border of ``2**iterations`` rows and columns (the largest tap
  offset) and a row stride that is an odd multiple of 16 floats, so a tap never needs a bounds
  test (a tap in the border has mask 0, hence weight 0) and every loop runs over a multiple of
  16 pixels.
* **Mirrored pairs.** The 24 taps around the centre form 12 pairs ``q = p + o``, ``q' = p - o``.
  The depth weight's denominator ``sigma_z |grad z(p) . o| + eps`` is the same for both, so a
  pair costs one reciprocal; a pair's loop also loads the centre's values once for two taps and
  updates the sums once (half the accumulator traffic of one loop per tap).
* **Chunks.** Each thread filters ``CHUNK`` pixels of a row at a time: per pair, one
  branch-free loop computes the depth/normal part of the two weights that the signals share,
  then one loop per signal the luminance weights and the five sums (weight, colour,
  squared-weight variance). The threads take tasks of a few consecutive rows from a shared
  counter (:func:`harness.kernels.take_range`): sky at the top of the image leaves no thread
  idle, and the threads walk down the image together, so the rows their taps read are shared in
  the caches (before, each thread filtered interleaved rows 16 threads apart, which re-read
  every tap row from memory).
* **Bounded values.** Colour is at most 1e37 in magnitude (:mod:`.modulation`), variances are
  clamped at ``VAR_MAX``, luminances at ``LUM_MAX`` and the luminance weight's inverse scale at
  ``INV_MAX`` (:mod:`.weights`; the per-pixel definition applies the same bounds), so every
  exponent and sum is finite: the inner loops need no overflow guard (``fastmath`` lets LLVM
  assume there is no infinity).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, uint64

from harness import kernels

from .params import TASK_ROWS
from .weights import INV_MAX, LUM_MAX, VAR_MAX, b3_tap, expneg, gauss3_tap, neg_log_series

#: pixels of a row filtered together (the accumulators of a chunk stay in L1)
CHUNK = 256
#: geometry planes of the pool: surface kind (the ``valid`` code: 0 background, 1 or 2 the two kinds
#: of surface pixel, :mod:`.modulation`), depth, sigma_z times the depth gradient (x, y),
#: the depth weight's epsilon (``depth_eps |z|`` + a tiny floor), normal (x, y, z)
MASK, DEPTH, SLOPE_X, SLOPE_Y, DEPTH_EPS, NORMAL_X, NORMAL_Y, NORMAL_Z = range(8)
GEOMETRY_PLANES = 8
#: planes per signal and slot: red, green, blue, luminance variance, luminance
SIGNAL_PLANES = 5
#: slopes and depth epsilons are clamped here (with depths of at most 1e30: a finite ratio)
SLOPE_MAX = 1.0e30
#: the mirrored tap pairs: (ky, kx) of the tap ``p + (ky, kx) step``; the other is ``p - ...``
PAIRS = tuple((ky, kx) for ky in range(0, 3) for kx in range(-2, 3) if ky > 0 or kx > 0)
#: the pairs two by two (ky, kx, ky', kx'): a signal's loop adds four taps at a time
PAIR_PAIRS = tuple(PAIRS[k] + PAIRS[k + 1] for k in range(0, len(PAIRS), 2))
_LR = np.float32(0.2126)
_LG = np.float32(0.7152)
_LB = np.float32(0.0722)
_TINY = np.float32(1e-20)
_ARG_MAX = np.float32(1024.0)
_ZERO = np.float32(0.0)
_ONE = np.float32(1.0)
# regions (of CHUNK floats) of a thread's scratch array, as flat offsets: per signal the sums
# (weight, red, green, blue, variance) and the centre's luminance and inverse luminance scale,
# signal 1's regions _SIGNAL_1 after signal 0's; then the prefilter's weight sum, and the
# current two pairs' weight factors and exponents. Flat indices are uint64 throughout (no
# wraparound tests; Numba turns a mix of int64 and uint64 into float64, so every constant
# added to one is uint64 too).
_OW, _OR, _OG, _OB, _OV, _OLP, _OIL = (np.uint64(k * CHUNK) for k in range(7))
_SIGNAL_1 = np.uint64(7 * CHUNK)
_OPDEN = np.uint64(14 * CHUNK)
_OMA, _ODA, _OMB, _ODB, _OMC, _ODC, _OMD, _ODD = (np.uint64(k * CHUNK) for k in range(15, 23))
_REGIONS = 23


def padded_stride(width: int, halo: int) -> int:
    """Row stride (floats) of a plane ``width`` wide with ``halo`` zero columns on each side.

    The smallest odd multiple of 16 that holds ``halo + ceil16(width) + halo``: every chunk
    may then run to a multiple of 16 pixels, and rows 2, 4, 8 ... apart do not map to the same
    L1 cache sets.
    """
    w = -(-width // 16) * 16 + 2 * halo
    return w + (16 - w % 32) % 32


class PlanePool:
    """The padded planes of the à-trous iterations (see the module notes).

    Parameters
    ----------
    nsig : int
        Number of signals (1 or 2).
    height, width : int
        Image size.
    iterations : int
        Number of à-trous iterations; the border is ``2**iterations`` rows and columns.

    Attributes
    ----------
    planes : ndarray (planes * plane_size,) float32
        Geometry planes, then slot 0 and slot 1 of the signal planes, one after the other; the
        borders hold zeros and every value ever written is finite.
    plane_size, halo, stride : int
        Floats per plane, border width and row stride in floats.
    """

    def __init__(self, nsig: int, height: int, width: int, iterations: int):
        self.key = (nsig, height, width, iterations)
        self.halo = 1 << iterations
        self.stride = padded_stride(width, self.halo)
        self.plane_size = (height + 2 * self.halo) * self.stride
        count = GEOMETRY_PLANES + 2 * SIGNAL_PLANES * nsig
        self.planes = np.zeros(count * self.plane_size, np.float32)

    def signal_plane(self, slot: int, signal: int = 0) -> int:
        """Index of the first (red) plane of ``signal`` in ``slot``."""
        return GEOMETRY_PLANES + (slot * self.key[0] + signal) * SIGNAL_PLANES

    def interior(self, plane: int) -> np.ndarray:
        """The image part of plane ``plane`` as an (H, W) view."""
        _, h, w, _ = self.key
        rows = self.planes[plane * self.plane_size:(plane + 1) * self.plane_size].reshape(-1, self.stride)
        return rows[self.halo:self.halo + h, self.halo:self.halo + w]


@njit(parallel=True, cache=True, error_model="numpy")
def pack_planes(valid, depth, normal, grad, sig, var, sigma_z, depth_eps, halo, stride, plane_size, first_plane,
                planes):
    """Copy the G-buffer, the signals and their variances into the pool.

    Parameters
    ----------
    valid, depth, normal, grad : ndarray
        Planar (H, W) G-buffer (valid uint8, the rest float32) and (2, H, W) depth gradient.
    sigma_z, depth_eps : float
        Parameters of the depth weight, folded into the slope and epsilon planes.
    sig : ndarray (S, 3, H, W) float32
        Demodulated signals.
    var : ndarray (S, H, W) float64
        Their luminance variances (clamped at ``VAR_MAX``).
    halo, stride, plane_size : int
        Pool layout.
    first_plane : int
        Plane of signal 0's red channel in the slot to fill.
    planes : ndarray float32
        :attr:`PlanePool.planes`.
    """
    nsig = sig.shape[0]
    h, w = valid.shape
    ps = uint64(plane_size)
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        row = uint64((i + halo) * stride + halo)
        # unsigned indices throughout: a signed one makes Numba emit wraparound code (no vectors)
        for t in range(w):
            j = uint64(t)
            k = row + j
            planes[uint64(MASK) * ps + k] = np.float32(valid[i, j])
            planes[uint64(DEPTH) * ps + k] = depth[i, j]
            planes[uint64(SLOPE_X) * ps + k] = min(max(sigma_z * grad[0, i, j], -SLOPE_MAX), SLOPE_MAX)
            planes[uint64(SLOPE_Y) * ps + k] = min(max(sigma_z * grad[1, i, j], -SLOPE_MAX), SLOPE_MAX)
            planes[uint64(DEPTH_EPS) * ps + k] = min(depth_eps * abs(depth[i, j]), SLOPE_MAX) + _TINY
            planes[uint64(NORMAL_X) * ps + k] = normal[0, i, j]
            planes[uint64(NORMAL_Y) * ps + k] = normal[1, i, j]
            planes[uint64(NORMAL_Z) * ps + k] = normal[2, i, j]
        for s in range(nsig):
            base = uint64(first_plane + s * SIGNAL_PLANES) * ps + row
            for c in range(3):
                oc = base + uint64(c) * ps
                for t in range(w):
                    j = uint64(t)
                    planes[oc + j] = sig[s, c, i, j]
            ov = base + uint64(3) * ps
            ol = base + uint64(4) * ps
            for t in range(w):
                j = uint64(t)
                planes[ov + j] = np.float32(min(var[s, i, j], VAR_MAX))
                lum = _LR * sig[s, 0, i, j] + _LG * sig[s, 1, i, j] + _LB * sig[s, 2, i, j]
                planes[ol + j] = min(max(lum, -LUM_MAX), LUM_MAX)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _centre_terms(pool, acc, ps, nsig, cb, n, stride, src, sl, le):
    """Per signal, the centre's luminance and ``1 / (sigma_l sqrt(g3x3(Var)) + eps)`` (at most
    ``INV_MAX``) into the scratch regions; zero sums.

    ``g3x3`` is the 3x3 Gaussian of the variance over surface neighbours (numerators summed in
    the luminance region first, the weight sum in ``_OPDEN``). ``ps`` is the plane size, ``src``
    the input slot's first plane, ``cb`` the chunk's first pixel, all flat (uint64).
    """
    for j in range(n):
        acc[_OPDEN + j] = _ZERO
    for s in range(nsig):
        r = uint64(s) * _SIGNAL_1
        for j in range(n):
            acc[r + _OLP + j] = _ZERO
    for dy in range(-1, 2):
        for dx in range(-1, 2):
            q0 = uint64(np.int64(cb) + dy * stride + dx)
            g = np.float32(gauss3_tap(dy) * gauss3_tap(dx))
            for j in range(n):
                acc[_OPDEN + j] += g * np.float32(pool[q0 + j] == pool[cb + j])
            for s in range(nsig):
                ov = uint64(src + s * SIGNAL_PLANES + 3) * ps + q0
                r = uint64(s) * _SIGNAL_1 + _OLP
                for j in range(n):
                    acc[r + j] += g * np.float32(pool[q0 + j] == pool[cb + j]) * pool[ov + j]
    for s in range(nsig):
        oc = uint64(src + s * SIGNAL_PLANES) * ps + cb
        r = uint64(s) * _SIGNAL_1
        for j in range(n):
            pv = acc[r + _OLP + j] / max(acc[_OPDEN + j], _TINY)
            acc[r + _OIL + j] = min(_ONE / (sl * math.sqrt(pv) + le), np.float32(INV_MAX))
            acc[r + _OLP + j] = pool[oc + uint64(4) * ps + j]
            acc[r + _OW + j] = _ZERO
            acc[r + _OR + j] = _ZERO
            acc[r + _OG + j] = _ZERO
            acc[r + _OB + j] = _ZERO
            acc[r + _OV + j] = _ZERO


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _add_centre(pool, acc, r, oc, ps, cb, n, hk):
    """The centre tap of a signal: weight ``h(0)^2`` times the mask exactly (no edge stop)."""
    o1 = ps
    o2 = o1 + ps
    o3 = o2 + ps
    for j in range(n):
        p = cb + j
        m = hk * np.float32(pool[p] != _ZERO)
        k = r + j
        acc[k + _OW] += m
        acc[k + _OR] += m * pool[oc + p]
        acc[k + _OG] += m * pool[oc + o1 + p]
        acc[k + _OB] += m * pool[oc + o2 + p]
        acc[k + _OV] += m * m * pool[oc + o3 + p]


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _pair_geometry(pool, acc, g, ps, cb, qa, qb, n, dxf, dyf, hk, sn):
    """For taps ``qa = p + o`` and ``qb = p - o`` of ``n`` centres from ``cb``: the weight
    factors shared by the signals (kernel tap times mask times normal cut-off) and the depth and
    normal part of the exponent (``|z_p - z_q| / (|slope(p) . o| + eps(p)) + sigma_n (-ln n_p.n_q)``),
    into the scratch regions ``g + _OMA ... g + _ODB`` (``g`` is 0 or ``_OMC - _OMA``)."""
    onx = uint64(NORMAL_X) * ps
    ony = uint64(NORMAL_Y) * ps
    onz = uint64(NORMAL_Z) * ps
    oz = uint64(DEPTH) * ps
    osx = uint64(SLOPE_X) * ps
    osy = uint64(SLOPE_Y) * ps
    oe = uint64(DEPTH_EPS) * ps
    for j in range(n):
        p = cb + j
        a = qa + j
        b = qb + j
        nx = pool[onx + p]
        ny = pool[ony + p]
        nz = pool[onz + p]
        zp = pool[oz + p]
        inv = _ONE / (abs(pool[osx + p] * dxf + pool[osy + p] * dyf) + pool[oe + p])
        da = nx * pool[onx + a] + ny * pool[ony + a] + nz * pool[onz + a]
        db = nx * pool[onx + b] + ny * pool[ony + b] + nz * pool[onz + b]
        # a tap of the centre's kind only (the kinds are plane 0; background centres have normal 0)
        acc[g + _OMA + j] = hk * np.float32(pool[a] == pool[p]) * np.float32(da > _ZERO)
        acc[g + _OMB + j] = hk * np.float32(pool[b] == pool[p]) * np.float32(db > _ZERO)
        acc[g + _ODA + j] = min(abs(zp - pool[oz + a]) * inv, _ARG_MAX) + sn * neg_log_series(da)
        acc[g + _ODB + j] = min(abs(zp - pool[oz + b]) * inv, _ARG_MAX) + sn * neg_log_series(db)


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _add_pairs(pool, acc, r, oc, ps, qa, qb, qc, qd, n):
    """Add the taps ``qa``, ``qb`` of one pair and ``qc``, ``qd`` of the next to a signal's sums
    (scratch regions from ``r``, red plane at flat offset ``oc``) for ``n`` centres, with the
    factors of :func:`_pair_geometry` (four taps per loop: the sums and the centre's terms are
    loaded and stored once for four taps)."""
    o1 = ps
    o2 = o1 + ps
    o3 = o2 + ps
    o4 = o3 + ps
    for j in range(n):
        k = r + j
        a = oc + qa + j
        b = oc + qb + j
        c = oc + qc + j
        d = oc + qd + j
        lp = acc[k + _OLP]
        il = acc[k + _OIL]
        wa = acc[_OMA + j] * expneg(-(acc[_ODA + j] + abs(lp - pool[o4 + a]) * il))
        wb = acc[_OMB + j] * expneg(-(acc[_ODB + j] + abs(lp - pool[o4 + b]) * il))
        wc = acc[_OMC + j] * expneg(-(acc[_ODC + j] + abs(lp - pool[o4 + c]) * il))
        wd = acc[_OMD + j] * expneg(-(acc[_ODD + j] + abs(lp - pool[o4 + d]) * il))
        acc[k + _OW] += (wa + wb) + (wc + wd)
        acc[k + _OR] += (wa * pool[a] + wb * pool[b]) + (wc * pool[c] + wd * pool[d])
        acc[k + _OG] += (wa * pool[o1 + a] + wb * pool[o1 + b]) + (wc * pool[o1 + c] + wd * pool[o1 + d])
        acc[k + _OB] += (wa * pool[o2 + a] + wb * pool[o2 + b]) + (wc * pool[o2 + c] + wd * pool[o2 + d])
        acc[k + _OV] += ((wa * wa * pool[o3 + a] + wb * wb * pool[o3 + b])
                         + (wc * wc * pool[o3 + c] + wd * wd * pool[o3 + d]))


@njit(cache=True, fastmath=True, error_model="numpy", inline="always")
def _write_chunk(pool, acc, ps, nsig, cb, n, dst, store, sig_out, i, xa):
    """Normalise the sums of ``n`` pixels into the output slot (0 off the surface) and, if
    ``store``, into ``sig_out``."""
    for s in range(nsig):
        od = uint64(dst + s * SIGNAL_PLANES) * ps + cb
        r = uint64(s) * _SIGNAL_1
        for j in range(n):
            # the centre tap has weight h(0)^2 > 0 on the surface; off it every sum is 0
            inv = np.float32(pool[cb + j] != _ZERO) / max(acc[r + _OW + j], _TINY)  # 0 on background
            c0 = acc[r + _OR + j] * inv
            c1 = acc[r + _OG + j] * inv
            c2 = acc[r + _OB + j] * inv
            pool[od + j] = c0
            pool[od + ps + j] = c1
            pool[od + ps + ps + j] = c2
            pool[od + ps + ps + ps + j] = acc[r + _OV + j] * inv * inv
            lum = _LR * c0 + _LG * c1 + _LB * c2
            pool[od + uint64(4) * ps + j] = min(max(lum, np.float32(-LUM_MAX)), np.float32(LUM_MAX))
        if store:
            for c in range(3):
                oc = od + uint64(c) * ps
                for j in range(n):
                    sig_out[s, c, i, uint64(xa) + j] = pool[oc + j]  # unsigned: no wraparound code


@njit(parallel=True, cache=True, fastmath=True, error_model="numpy")
def atrous_level(pool, ps, nsig, h, w, halo, stride, step, src, dst, sigma_n, sigma_l, lum_eps, store,
                 sig_out, nthreads):
    """One à-trous iteration from the signal slot at plane ``src`` to the one at plane ``dst``.

    Parameters
    ----------
    pool : ndarray float32
        :attr:`PlanePool.planes`.
    ps, nsig, h, w, halo, stride : int
        Floats per plane, signals, image size, border and row stride.
    step : int
        Hole size ``2**iteration``.
    src, dst : int
        First plane of the input and output slots (:meth:`PlanePool.signal_plane`).
    sigma_n, sigma_l, lum_eps : float
        Edge-stopping parameters (as :func:`.atrous.atrous_pixel`; ``sigma_z`` and ``depth_eps``
        are in the pool's planes, see :func:`pack_planes`).
    store : bool
        Also write the filtered signals to ``sig_out`` (S, 3, h, w) float32 (0 off the
        surface); the variances stay in the pool.
    nthreads : int
        Parallel workers; each takes tasks of ``TASK_ROWS`` consecutive rows from a shared
        counter (:func:`harness.kernels.take_range`).
    """
    sn = np.float32(sigma_n)
    sl = np.float32(sigma_l)
    le = np.float32(lum_eps)
    psu = uint64(ps)
    o0 = uint64(src) * psu
    o1 = uint64(src + SIGNAL_PLANES) * psu
    hc = np.float32(b3_tap(0) * b3_tap(0))
    counter = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        acc = np.empty(_REGIONS * CHUNK, np.float32)
        while True:
            start, stop = kernels.take_range(counter, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                row = (i + halo) * stride + halo
                # the chunks run from the first to the last surface pixel of the row
                jlo = w
                jhi = 0
                for j in range(w):
                    if pool[row + j] != _ZERO:  # the mask is plane 0
                        jlo = min(jlo, j)
                        jhi = j + 1
                x0 = jlo - jlo % 16
                x1 = x0
                for xa in range(x0, jhi, CHUNK):
                    n = uint64(min(CHUNK, -(-(jhi - xa) // 16) * 16))
                    cb = uint64(row + xa)
                    _centre_terms(pool, acc, psu, nsig, cb, n, stride, src, sl, le)
                    _add_centre(pool, acc, uint64(0), o0, psu, cb, n, hc)
                    if nsig == 2:
                        _add_centre(pool, acc, _SIGNAL_1, o1, psu, cb, n, hc)
                    for ky, kx, ky2, kx2 in PAIR_PAIRS:
                        off = (ky * stride + kx) * step
                        qa = uint64(np.int64(cb) + off)
                        qb = uint64(np.int64(cb) - off)
                        _pair_geometry(pool, acc, uint64(0), psu, cb, qa, qb, n, np.float32(kx * step),
                                       np.float32(ky * step), np.float32(b3_tap(ky) * b3_tap(kx)), sn)
                        off2 = (ky2 * stride + kx2) * step
                        qc = uint64(np.int64(cb) + off2)
                        qd = uint64(np.int64(cb) - off2)
                        _pair_geometry(pool, acc, _OMC - _OMA, psu, cb, qc, qd, n, np.float32(kx2 * step),
                                       np.float32(ky2 * step), np.float32(b3_tap(ky2) * b3_tap(kx2)), sn)
                        _add_pairs(pool, acc, uint64(0), o0, psu, qa, qb, qc, qd, n)
                        if nsig == 2:
                            _add_pairs(pool, acc, _SIGNAL_1, o1, psu, qa, qb, qc, qd, n)
                    x1 = min(xa + np.int64(n), w)
                    _write_chunk(pool, acc, psu, nsig, cb, uint64(x1 - xa), dst, store, sig_out, i, xa)
                if store:
                    for s in range(nsig):
                        for c in range(3):
                            for j in range(x0):
                                sig_out[s, c, i, j] = 0.0
                            for j in range(x1, w):
                                sig_out[s, c, i, j] = 0.0
