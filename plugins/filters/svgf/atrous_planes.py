"""À-trous iterations of the ``cpu`` backend on padded float32 planes held in one array.

The same filter as :func:`plugins.filters.svgf.atrous.atrous_pixel` (same taps and weights),
laid out for LLVM's loop vectorizer:

* **One pool.** Every plane an iteration reads (surface mask, depth, depth slope, normal, and
  each signal's colour, variance and luminance) lies in one flat float32 array,
  :class:`PlanePool`, one plane after the other; the iterations ping-pong between two slots of
  signal planes in it. A tap loop then loads from
  one array and updates one small per-thread array of accumulators, so the vectorizer needs a
  single run-time aliasing test instead of giving up over dozens.
* **Padding.** Planes have a zero border of ``2**iterations`` columns (the largest tap offset)
  and a row stride that is an odd multiple of 16 floats, so a tap never needs a column bounds
  test (a tap in the border has mask 0, hence weight 0) and every loop runs over a multiple
  of 16 pixels; rows outside the image are skipped a whole tap row at a time.
* **Chunks.** Each thread filters ``CHUNK`` pixels of a row at a time: per tap, one
  branch-free loop computes the depth/normal part of the weight that the signals share, then
  one loop per signal the luminance weight and the five sums (weight, colour, squared-weight
  variance). Rows are dealt to the threads interleaved, so sky at the top of the image does
  not leave one thread idle.

Variance planes are float32 and clamped at ``VAR_MAX`` when packed (a sum of 25 weighted
variances then stays finite); colour and weight sums are float32 (25 terms).
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange, uint64

from .weights import b3_tap, expneg, gauss3_tap, neg_log_series

#: pixels of a row filtered together (the accumulators of a chunk stay in L1)
CHUNK = 256
#: geometry planes of the pool: surface mask, depth, sigma_z times the depth gradient (x, y),
#: the depth weight's epsilon (``depth_eps |z|`` + a tiny floor), normal (x, y, z)
MASK, DEPTH, SLOPE_X, SLOPE_Y, DEPTH_EPS, NORMAL_X, NORMAL_Y, NORMAL_Z = range(8)
GEOMETRY_PLANES = 8
#: planes per signal and slot: red, green, blue, luminance variance, luminance
SIGNAL_PLANES = 5
#: variances are clamped here when packed into float32 (25 x VAR_MAX stays finite)
VAR_MAX = 1.0e36
_LR = np.float32(0.2126)
_LG = np.float32(0.7152)
_LB = np.float32(0.0722)
_TINY = np.float32(1e-20)
_ARG_MAX = np.float32(1024.0)
_F32_MAX = np.float32(3.0e38)
_ZERO = np.float32(0.0)
_ONE = np.float32(1.0)
# regions (of CHUNK floats) of a thread's scratch array, as flat offsets: per signal the sums
# (weight, red, green, blue, variance) and the centre's terms (luminance, inverse luminance
# scale, luminance difference limit), signal 1's regions _SIGNAL_1 after signal 0's; then the
# prefilter's weight sum, and the current tap's shared weight factor and exponent. Flat indices
# are uint64 throughout (no wraparound tests; Numba turns a mix of int64 and uint64 into
# float64, so every constant added to one is uint64 too).
_OW, _OR, _OG, _OB, _OV, _OLP, _OIL, _OLIM = (np.uint64(k * CHUNK) for k in range(8))
_SIGNAL_1 = np.uint64(8 * CHUNK)
_OPDEN = np.uint64(16 * CHUNK)
_OM = np.uint64(17 * CHUNK)
_ODR = np.uint64(18 * CHUNK)
_REGIONS = 19


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
        Number of à-trous iterations; the border is ``2**iterations`` columns.

    Attributes
    ----------
    planes : ndarray (planes * height * stride,) float32
        Geometry planes, then slot 0 and slot 1 of the signal planes, one after the other; the
        borders hold zeros and every value ever written is finite.
    plane_size, halo, stride : int
        Floats per plane, border width and row stride in floats.
    """

    def __init__(self, nsig: int, height: int, width: int, iterations: int):
        self.key = (nsig, height, width, iterations)
        self.halo = 1 << iterations
        self.stride = padded_stride(width, self.halo)
        self.plane_size = height * self.stride
        count = GEOMETRY_PLANES + 2 * SIGNAL_PLANES * nsig
        self.planes = np.zeros(count * self.plane_size, np.float32)

    def signal_plane(self, slot: int, signal: int = 0) -> int:
        """Index of the first (red) plane of ``signal`` in ``slot``."""
        return GEOMETRY_PLANES + (slot * self.key[0] + signal) * SIGNAL_PLANES


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
    sz = np.float32(sigma_z)
    de = np.float32(depth_eps)
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        row = i * stride + halo
        for j in range(w):
            planes[MASK * plane_size + row + j] = np.float32(valid[i, j] != 0)
            planes[DEPTH * plane_size + row + j] = depth[i, j]
            planes[SLOPE_X * plane_size + row + j] = sz * grad[0, i, j]
            planes[SLOPE_Y * plane_size + row + j] = sz * grad[1, i, j]
            planes[DEPTH_EPS * plane_size + row + j] = de * abs(depth[i, j]) + _TINY
            planes[NORMAL_X * plane_size + row + j] = normal[0, i, j]
            planes[NORMAL_Y * plane_size + row + j] = normal[1, i, j]
            planes[NORMAL_Z * plane_size + row + j] = normal[2, i, j]
        for s in range(nsig):
            base = (first_plane + s * SIGNAL_PLANES) * plane_size + row
            for c in range(3):
                for j in range(w):
                    planes[base + c * plane_size + j] = sig[s, c, i, j]
            for j in range(w):
                planes[base + 3 * plane_size + j] = np.float32(min(var[s, i, j], VAR_MAX))
            for j in range(w):
                planes[base + 4 * plane_size + j] = (_LR * sig[s, 0, i, j] + _LG * sig[s, 1, i, j]
                                                     + _LB * sig[s, 2, i, j])


@njit(cache=True, fastmath=True, error_model="numpy")
def _centre_terms(pool, acc, ps, nsig, h, i, cb, n, stride, src, sl, le):
    """Per signal, the centre's luminance, ``1 / (sigma_l sqrt(g3x3(Var)) + eps)`` and the
    largest luminance difference that enters a weight, into the scratch regions; zero sums.

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
        y = i + dy
        if y < 0 or y >= h:
            continue
        for dx in range(-1, 2):
            q0 = uint64(np.int64(cb) + dy * stride + dx)
            g = np.float32(gauss3_tap(dy) * gauss3_tap(dx))
            for j in range(n):
                acc[_OPDEN + j] += g * pool[q0 + j]
            for s in range(nsig):
                ov = uint64(src + s * SIGNAL_PLANES + 3) * ps + q0
                r = uint64(s) * _SIGNAL_1 + _OLP
                for j in range(n):
                    acc[r + j] += g * pool[q0 + j] * pool[ov + j]
    for s in range(nsig):
        oc = uint64(src + s * SIGNAL_PLANES) * ps + cb
        r = uint64(s) * _SIGNAL_1
        for j in range(n):
            pv = acc[r + _OLP + j] / max(acc[_OPDEN + j], _TINY)
            den = sl * math.sqrt(pv) + le
            acc[r + _OIL + j] = _ONE / den
            acc[r + _OLIM + j] = min(_ARG_MAX * den, _F32_MAX)
            acc[r + _OLP + j] = pool[oc + uint64(4) * ps + j]
            acc[r + _OW + j] = _ZERO
            acc[r + _OR + j] = _ZERO
            acc[r + _OG + j] = _ZERO
            acc[r + _OB + j] = _ZERO
            acc[r + _OV + j] = _ZERO


@njit(cache=True, fastmath=True, error_model="numpy")
def _add_tap(pool, acc, r, oc, ps, q, j, m, dr):
    """Add neighbour ``q`` of a signal (scratch regions from ``r``, red plane at flat offset
    ``oc``) to the sums of chunk pixel ``j``: ``m`` is the tap's kernel weight times its mask
    and normal cut-off, ``dr`` the depth and normal part of the exponent."""
    k = r + j
    c0 = pool[oc + q]
    c1 = pool[oc + ps + q]
    c2 = pool[oc + ps + ps + q]
    lq = pool[oc + uint64(4) * ps + q]
    wt = m * expneg(-(dr + min(abs(acc[k + _OLP] - lq), acc[k + _OLIM]) * acc[k + _OIL]))
    acc[k + _OW] += wt
    acc[k + _OR] += wt * c0
    acc[k + _OG] += wt * c1
    acc[k + _OB] += wt * c2
    acc[k + _OV] += wt * wt * pool[oc + ps + ps + ps + q]


@njit(cache=True, fastmath=True, error_model="numpy")
def _add_centre(pool, acc, r, oc, ps, p, j, m):
    """The centre tap of a signal: weight ``m`` exactly (no luminance term)."""
    k = r + j
    acc[k + _OW] += m
    acc[k + _OR] += m * pool[oc + p]
    acc[k + _OG] += m * pool[oc + ps + p]
    acc[k + _OB] += m * pool[oc + ps + ps + p]
    acc[k + _OV] += m * m * pool[oc + ps + ps + ps + p]


@njit(cache=True, fastmath=True, error_model="numpy")
def _geometry(pool, og, p, q, dxf, dyf, sn):
    """Weight factors of tap ``q`` (offset ``(dxf, dyf)``) for centre ``p`` shared by the signals:
    (mask times normal cut-off, depth distance + sigma_n (-ln n_p . n_q)); ``og`` holds the
    geometry planes' flat offsets."""
    onx, ony, onz, oz, osx, osy, oe = og
    d = pool[onx + p] * pool[onx + q] + pool[ony + p] * pool[ony + q] + pool[onz + p] * pool[onz + q]
    m = pool[q] * np.float32(d > _ZERO)  # the mask is plane 0
    zp = pool[oz + p]
    den = abs(pool[osx + p] * dxf + pool[osy + p] * dyf) + pool[oe + p]
    dr = min(abs(zp - pool[oz + q]) / den, _ARG_MAX) + sn * neg_log_series(d)
    return m, dr


@njit(cache=True, fastmath=True, error_model="numpy")
def _filter_chunk(pool, acc, ps, nsig, h, i, cb, n, stride, step, src, sn, sl, le):
    """The 25 taps of ``n`` pixels of row ``i`` from flat pixel index ``cb`` into the sums."""
    _centre_terms(pool, acc, ps, nsig, h, i, cb, n, stride, src, sl, le)
    o0 = uint64(src) * ps
    o1 = uint64(src + SIGNAL_PLANES) * ps
    og = (uint64(NORMAL_X) * ps, uint64(NORMAL_Y) * ps, uint64(NORMAL_Z) * ps, uint64(DEPTH) * ps,
          uint64(SLOPE_X) * ps, uint64(SLOPE_Y) * ps, uint64(DEPTH_EPS) * ps)
    r0 = uint64(0)
    for ky in range(-2, 3):
        y = i + ky * step
        if y < 0 or y >= h:
            continue
        for kx in range(-2, 3):
            hk = np.float32(b3_tap(ky) * b3_tap(kx))
            if kx == 0 and ky == 0:
                for j in range(n):
                    _add_centre(pool, acc, r0, o0, ps, cb + j, j, hk * pool[cb + j])
                if nsig == 2:
                    for j in range(n):
                        _add_centre(pool, acc, _SIGNAL_1, o1, ps, cb + j, j, hk * pool[cb + j])
                continue
            q0 = uint64(np.int64(cb) + (ky * stride + kx) * step)
            dxf = np.float32(kx * step)
            dyf = np.float32(ky * step)
            for j in range(n):
                m, dr = _geometry(pool, og, cb + j, q0 + j, dxf, dyf, sn)
                acc[_OM + j] = hk * m
                acc[_ODR + j] = dr
            for j in range(n):
                _add_tap(pool, acc, r0, o0, ps, q0 + j, j, acc[_OM + j], acc[_ODR + j])
            if nsig == 2:
                for j in range(n):
                    _add_tap(pool, acc, _SIGNAL_1, o1, ps, q0 + j, j, acc[_OM + j], acc[_ODR + j])


@njit(cache=True, fastmath=True, error_model="numpy")
def _write_chunk(pool, acc, ps, nsig, cb, n, dst, store, sig_out, i, xa):
    """Normalise the sums of ``n`` pixels into the output slot (0 off the surface) and, if
    ``store``, into ``sig_out``."""
    for s in range(nsig):
        od = uint64(dst + s * SIGNAL_PLANES) * ps + cb
        r = uint64(s) * _SIGNAL_1
        for j in range(n):
            # the centre tap has weight h(0)^2 > 0 on the surface; off it every sum is 0
            inv = pool[cb + j] / max(acc[r + _OW + j], _TINY)
            pool[od + j] = acc[r + _OR + j] * inv
            pool[od + ps + j] = acc[r + _OG + j] * inv
            pool[od + ps + ps + j] = acc[r + _OB + j] * inv
            pool[od + ps + ps + ps + j] = acc[r + _OV + j] * inv * inv
            pool[od + uint64(4) * ps + j] = (_LR * pool[od + j] + _LG * pool[od + ps + j]
                                             + _LB * pool[od + ps + ps + j])
        if store:
            for c in range(3):
                oc = od + uint64(c) * ps
                for j in range(n):
                    sig_out[s, c, i, xa + np.int64(j)] = pool[oc + j]


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
        Parallel workers; rows are dealt to ``16 nthreads`` interleaved bands.
    """
    sn = np.float32(sigma_n)
    sl = np.float32(sigma_l)
    le = np.float32(lum_eps)
    psu = uint64(ps)
    nbands = max(min(h, 16 * nthreads), 1)
    for band in prange(nbands):
        acc = np.empty(_REGIONS * CHUNK, np.float32)
        for i in range(np.int64(band), h, nbands):
            row = i * stride + halo
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
                n = min(CHUNK, -(-(jhi - xa) // 16) * 16)
                _filter_chunk(pool, acc, psu, nsig, h, i, uint64(row + xa), uint64(n), stride, step, src,
                              sn, sl, le)
                x1 = min(xa + n, w)
                _write_chunk(pool, acc, psu, nsig, uint64(row + xa), uint64(x1 - xa), dst, store, sig_out, i, xa)
            if store:
                for s in range(nsig):
                    for c in range(3):
                        for j in range(x0):
                            sig_out[s, c, i, j] = 0.0
                        for j in range(x1, w):
                            sig_out[s, c, i, j] = 0.0
