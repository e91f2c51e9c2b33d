"""Padded planar buffers of the EAW filter and the two passes that fill them (both backends).

:func:`survey` reads the inputs once: pixel classes (background / still / active) and, per
row, the sums behind the colour and position scales (:func:`frame_scales`). :func:`pack` then
writes the padded planes and each row's runs of active pixels. :func:`prepare` runs both on a
frame; the CUDA backend copies the planes to the device, the CPU backend filters them in place.

Layout. Each quantity is a plane of ``(H + 2 halo) x stride`` float32 values, one flat array
per kind: colour (3 planes, two ping-pong sets), guides (normal 3, position 3, surface mask 1).
The halo (``2**iterations`` pixels, the largest tap offset) holds zeros and mask 0, so the
inner loops need no bounds tests: a tap outside the image, or on the background, gets weight 0.
The row stride is padded to an odd multiple of 16 floats (64 bytes): rows 2, 4, 8, 16 apart
then fall in different L1 sets (a stride that is a multiple of 2 KiB measured 40 % slower,
see the README).

Bounds and bad input. A pixel whose normal is zero or not finite, or whose position is not
finite, is background (passed through, never a tap), like ``object_id == -1`` and a non-finite
depth when those channels are given. Normalised colour is limited to +-``COLOR_MAX`` and guides
to +-``GUIDE_MAX`` when packed (NaN colour to 0), so every squared distance, weighted sum and
exponent of the filter stays finite in float32 without a test in the inner loops.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

from .fastexp import float32_bits_as_int32
from .fastlog import fast_log

#: largest magnitude of a normalised colour value in the planes: 3 (2 COLOR_MAX)^2 COEF_MAX and
#: sums of 24 weighted differences stay finite in float32
COLOR_MAX = 1e12
#: largest magnitude of a normalised guide value (normals, positions)
GUIDE_MAX = 1e12
#: the normal stored for background pixels and the halo: its distance to any packed surface
#: normal, squared and times the normal coefficient (at least ``A_N_MIN``), puts the weight's
#: exponent beyond the exponential's range, so the CPU kernel needs no mask (the CUDA kernel
#: and :func:`unpack` use the mask plane)
BACKGROUND_NORMAL = 1e18
#: smallest normal coefficient of the CPU kernel (``sigma_n = inf`` gives 0, which would
#: disable the background marker; 1e-30 times a squared distance of unit normals is no change)
A_N_MIN = 1e-30
#: runs of active pixels kept per row; further runs are merged into the last one (correct, as
#: the kernels leave every pixel that is not active unchanged, only slower)
MAX_RUNS = 8
#: gaps of at most this many inactive pixels are merged into the surrounding run
MIN_GAP = 16
# Rec. 709 luminance weights
LUMA = (0.2126, 0.7152, 0.0722)

BACKGROUND, STILL, ACTIVE = 0, 1, 2


def padded_stride(width: int, halo: int) -> int:
    """Row stride (floats) for an image ``width`` wide with ``halo`` on each side.

    The smallest value >= ``width + 2 halo`` that is an odd multiple of 16.
    """
    w = width + 2 * halo
    return w + (16 - w % 32) % 32


@njit(inline="always", cache=True)
def finite(x):
    """Whether float32 ``x`` is finite, from its exponent bits (exact under ``fastmath``, which
    lets the compiler assume that no value is NaN or infinite)."""
    return (float32_bits_as_int32(x) & np.int32(0x7F800000)) != np.int32(0x7F800000)


@njit(parallel=True, cache=True, fastmath=True)
def survey(color, normal, position, ids, depth, variance, has_ids, has_depth, has_variance, state,
           row_log, row_count, row_lo, row_hi):
    """Pixel classes and the per-row sums of the colour and position scales, in one pass.

    Background: a normal that is zero or not finite, a position that is not finite, and (when
    those channels are given) ``object_id == -1`` or a depth that is not finite. Still: a
    surface pixel whose ``variance`` is zero in all channels. Active: every other pixel.

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32
    ids : ndarray (H, W) int32
    depth : ndarray (H, W) float32
    variance : ndarray (H, W, 3) float32
    has_ids, has_depth, has_variance : bool
        Whether the three optional channels are real (else 1x1 stand-ins, never read).
    state : ndarray (H, W) int8
        Output: BACKGROUND, STILL or ACTIVE.
    row_log, row_count : ndarray (H,) float64, int64
        Output: per row, the sum of ``log(L)`` over surface pixels whose float32 luminance
        ``L`` is finite and at least float32's smallest normal value, and their number.
    row_lo, row_hi : ndarray (H, 3) float64
        Output: per row, the bounding box of the surface pixels' positions (``lo > hi`` when
        the row has none).
    """
    h, w = state.shape
    tiny = np.float32(np.finfo(np.float32).tiny)
    big = np.float32(np.inf)
    for r in prange(h):
        y = np.int64(r)
        # classes, branch-free
        for x in range(w):
            n0, n1, n2 = normal[y, x, 0], normal[y, x, 1], normal[y, x, 2]
            surface = (((n0 != 0.0) | (n1 != 0.0) | (n2 != 0.0)) & finite(n0) & finite(n1) & finite(n2)
                       & finite(position[y, x, 0]) & finite(position[y, x, 1]) & finite(position[y, x, 2]))
            state[y, x] = np.int8(surface) * np.int8(ACTIVE)
        if has_ids:
            for x in range(w):
                state[y, x] = state[y, x] if ids[y, x] != -1 else np.int8(BACKGROUND)
        if has_depth:
            for x in range(w):
                state[y, x] = state[y, x] if finite(depth[y, x]) else np.int8(BACKGROUND)
        if has_variance:
            for x in range(w):
                noisy = (variance[y, x, 0] != 0.0) | (variance[y, x, 1] != 0.0) | (variance[y, x, 2] != 0.0)
                s = state[y, x]
                state[y, x] = s if noisy or s == BACKGROUND else np.int8(STILL)
        # sums, branch-free (positions of background pixels may be anything: selected away)
        total = 0.0
        count = 0
        lo0 = lo1 = lo2 = big
        hi0 = hi1 = hi2 = -big
        for x in range(w):
            surface = state[y, x] != BACKGROUND
            lum = (np.float32(LUMA[0]) * color[y, x, 0] + np.float32(LUMA[1]) * color[y, x, 1]
                   + np.float32(LUMA[2]) * color[y, x, 2])
            ok = surface & (lum >= tiny) & finite(lum)
            total += fast_log(lum if ok else np.float32(1.0))
            count += np.int64(ok)
            lo0 = min(lo0, position[y, x, 0] if surface else big)
            lo1 = min(lo1, position[y, x, 1] if surface else big)
            lo2 = min(lo2, position[y, x, 2] if surface else big)
            hi0 = max(hi0, position[y, x, 0] if surface else -big)
            hi1 = max(hi1, position[y, x, 1] if surface else -big)
            hi2 = max(hi2, position[y, x, 2] if surface else -big)
        row_log[y] = total
        row_count[y] = count
        row_lo[y, 0], row_lo[y, 1], row_lo[y, 2] = lo0, lo1, lo2
        row_hi[y, 0], row_hi[y, 1], row_hi[y, 2] = hi0, hi1, hi2


def frame_scales(row_log, row_count, row_lo, row_hi, color_scale: str, position_units: str):
    """Colour scale, position origin and position unit of a frame from :func:`survey`'s rows.

    Returns
    -------
    scale : float
        Log-average luminance of the surface pixels with positive luminance (``logmean``), or 1.
    origin : ndarray (3,) float64
        Lower corner of the surfaces' bounding box (0 when there is no surface).
    pos_unit : float
        Diagonal of that box (``scene`` units) or 1 (``world``).
    """
    count = int(row_count.sum())
    scale = 1.0
    if color_scale == "logmean" and count > 0:
        scale = math.exp(float(row_log.sum()) / count)
        if not (math.isfinite(scale) and scale > 0.0):
            scale = 1.0
    lo, hi = row_lo.min(axis=0), row_hi.max(axis=0)
    box = bool(np.all(np.isfinite(lo)) and np.all(np.isfinite(hi)))
    origin = lo if box else np.zeros(3)
    pos_unit = 1.0
    if position_units == "scene" and box:
        diag = float(np.linalg.norm(hi - lo))
        if math.isfinite(diag) and diag > 0.0:
            pos_unit = diag
    return scale, np.ascontiguousarray(origin, dtype=np.float64), pos_unit


@njit(inline="always", cache=True)
def normalised(value, inv_scale):
    """A colour value in units of the colour scale, limited to +-COLOR_MAX (NaN gives 0); the
    same rounding in :func:`pack` and in the last pass."""
    v = np.float64(value) * inv_scale
    if not v == v:  # NaN
        return np.float32(0.0)
    return np.float32(min(max(v, -COLOR_MAX), COLOR_MAX))


@njit(parallel=True, cache=True)
def pack(color, normal, position, state, inv_scale, origin, inv_pos, halo, stride, cbuf_a, cbuf_b, gbuf,
         runs, run_count, row_surface):
    """Write the interior of the planar buffers (their halo stays zero) and the active runs.

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32
    state : ndarray (H, W) int8
    inv_scale : float
        1 / colour scale.
    origin : ndarray (3,) float64
        Subtracted from positions (keeps float32 differences accurate far from the origin).
    inv_pos : float
        1 / position unit.
    halo, stride : int
    cbuf_a, cbuf_b : ndarray (3 * planesize,) float32
        Both receive the normalised colour (plane ``c`` at ``c * planesize``).
    gbuf : ndarray (7 * planesize,) float32
        Normal (3), position (3), surface mask (1); on the background normal
        ``BACKGROUND_NORMAL``, position and mask 0.
    runs : ndarray (H, MAX_RUNS, 2) int64
        Output: half-open column ranges of each row's active pixels (gaps shorter than
        ``MIN_GAP`` merged; runs beyond ``MAX_RUNS`` merged into the last).
    run_count : ndarray (H,) int64
        Output: runs per row.
    row_surface : ndarray (H,) uint8
        Output: 1 where the row has a surface pixel (not bool: Numba's alias analysis takes a
        bool read for a possible array view, which costs the kernels their ``noalias``).
    """
    h, w = state.shape
    ps = cbuf_a.shape[0] // 3
    for r in prange(h):
        y = np.int64(r)
        base = (y + halo) * stride + halo
        k = 0
        last = -MIN_GAP - 1
        surface = False
        for x in range(w):
            i = base + x
            s = state[y, x]
            for c in range(3):
                v = normalised(color[y, x, c], inv_scale)
                cbuf_a[c * ps + i] = v
                cbuf_b[c * ps + i] = v
            if s != BACKGROUND:
                for c in range(3):
                    n = min(max(np.float64(normal[y, x, c]), -GUIDE_MAX), GUIDE_MAX)
                    gbuf[c * ps + i] = np.float32(n)
                    p = (np.float64(position[y, x, c]) - origin[c]) * inv_pos
                    gbuf[(3 + c) * ps + i] = np.float32(min(max(p, -GUIDE_MAX), GUIDE_MAX))
                gbuf[6 * ps + i] = np.float32(1.0)
                surface = True
            else:
                for c in range(3):
                    gbuf[c * ps + i] = np.float32(BACKGROUND_NORMAL)
                for c in range(3, 7):
                    gbuf[c * ps + i] = np.float32(0.0)
            if s == ACTIVE:
                if x - last <= MIN_GAP and k > 0:
                    runs[y, k - 1, 1] = x + 1  # extend the current run over a short gap
                elif k < MAX_RUNS:
                    runs[y, k, 0] = x
                    runs[y, k, 1] = x + 1
                    k += 1
                else:
                    runs[y, k - 1, 1] = x + 1
                last = x
        run_count[y] = k
        row_surface[y] = 1 if surface else 0


@njit(parallel=True, cache=True)
def unpack(color, state, cbuf, inv_scale, scale, halo, stride, out):
    """``out = color + (filtered - normalised colour) * scale`` on active pixels, else ``color``.

    Used by the CUDA backend (the CPU backend does this in its last pass).
    """
    h, w = state.shape
    ps = cbuf.shape[0] // 3
    for r in prange(h):
        y = np.int64(r)
        base = (y + halo) * stride + halo
        for x in range(w):
            for c in range(3):
                v = color[y, x, c]
                if state[y, x] == ACTIVE:
                    delta = np.float64(cbuf[c * ps + base + x]) - np.float64(normalised(v, inv_scale))
                    out[y, x, c] = np.float32(np.float64(v) + delta * scale)
                else:
                    out[y, x, c] = v


class Buffers:
    """Planar buffers and scratch for one image size and halo, reused across frames."""

    def __init__(self, height: int, width: int, halo: int, stride: int | None = None):
        self.height, self.width, self.halo = height, width, halo
        self.stride = padded_stride(width, halo) if stride is None else stride
        size = (height + 2 * halo) * self.stride
        self.color = (np.zeros(3 * size, np.float32), np.zeros(3 * size, np.float32))
        self.guide = np.zeros(7 * size, np.float32)
        self.guide[:3 * size] = BACKGROUND_NORMAL  # the halo too
        self.state = np.empty((height, width), np.int8)
        self.runs = np.zeros((height, MAX_RUNS, 2), np.int64)
        self.run_count = np.zeros(height, np.int64)
        self.row_surface = np.zeros(height, np.uint8)
        self.row_log = np.zeros(height)
        self.row_count = np.zeros(height, np.int64)
        self.row_lo = np.zeros((height, 3))
        self.row_hi = np.zeros((height, 3))
        self.ring = np.zeros(0, np.float32)

    def fits(self, height: int, width: int, halo: int) -> bool:
        return (height, width, halo) == (self.height, self.width, self.halo)

    def thread_ring(self, rows: int) -> np.ndarray:
        """Scratch of at least ``rows`` rows of the stride, zero where never written (grown, never shrunk)."""
        if self.ring.size < rows * self.stride:
            self.ring = np.zeros(rows * self.stride, np.float32)
        return self.ring


_NO_IDS = np.zeros((1, 1), np.int32)
_NO_DEPTH = np.zeros((1, 1), np.float32)
_NO_VARIANCE = np.zeros((1, 1, 3), np.float32)


def prepare(frame, params, buffers: Buffers):
    """Survey and pack one frame into ``buffers`` (shared by both backends).

    Returns
    -------
    color : ndarray (H, W, 3) float32
    scale : float
        The colour scale.
    """
    color = np.ascontiguousarray(frame["color"], dtype=np.float32)
    normal = np.ascontiguousarray(frame["normal"], dtype=np.float32)
    position = np.ascontiguousarray(frame["position"], dtype=np.float32)
    has_ids, has_depth, has_var = "object_id" in frame, "depth" in frame, "variance" in frame
    b = buffers
    survey(color, normal, position, frame["object_id"] if has_ids else _NO_IDS,
           frame["depth"] if has_depth else _NO_DEPTH, frame["variance"] if has_var else _NO_VARIANCE,
           has_ids, has_depth, has_var, b.state, b.row_log, b.row_count, b.row_lo, b.row_hi)
    scale, origin, pos_unit = frame_scales(b.row_log, b.row_count, b.row_lo, b.row_hi, params.color_scale,
                                           params.position_units)
    pack(color, normal, position, b.state, 1.0 / scale, origin, 1.0 / pos_unit, b.halo, b.stride, b.color[0],
         b.color[1], b.guide, b.runs, b.run_count, b.row_surface)
    return color, scale


