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
from numba import njit, prange, types, uint64
from numba.extending import intrinsic

from harness import kernels

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
#: gaps of fewer than this many inactive pixels are merged into the surrounding run
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
    """Whether float32 ``x`` is finite, from its exponent bits.

    Exact on a value loaded from memory under ``fastmath``. On a value computed by arithmetic
    carrying the ``nnan`` / ``ninf`` flags (``fastmath=True``), LLVM folds the test to true, so
    the functions that test computed values compile without those flags
    (:data:`SURVEY_FASTMATH`)."""
    return (kernels.float32_bits_as_int32(x) & np.int32(0x7F800000)) != np.int32(0x7F800000)


def _select_intrinsic(predicate):
    """An intrinsic ``f(a, b) = b if predicate(b, a) else a`` on two float32 values whose compare
    and select carry the ``nnan`` and ``nsz`` flags, as Python's ``min`` (``"<"``) and ``max``
    (``">"``) on values that are not NaN (infinities are fine)."""

    @intrinsic
    def select(typingctx, a, b):
        if a != types.float32 or b != types.float32:
            return None

        def codegen(context, builder, signature, args):
            a, b = args
            take = builder.fcmp_ordered(predicate, b, a, flags=("nnan", "nsz"))
            return builder.select(take, b, a, flags=("nnan", "nsz"))

        return types.float32(types.float32, types.float32), codegen

    return select


#: ``min`` and ``max`` of two float32 values that LLVM vectorizes as reductions: Numba's own
#: select carries no fast-math flags, and LLVM then keeps a min / max reduction scalar
fast_min = _select_intrinsic("<")
fast_max = _select_intrinsic(">")
#: :func:`survey`'s fast-math flags: all but ``nnan`` and ``ninf``, which would let LLVM fold
#: :func:`finite` of the computed luminance to true (a NaN or infinite luminance was then
#: counted in the colour scale)
SURVEY_FASTMATH = {"nsz", "arcp", "contract", "afn", "reassoc"}


@njit(inline="always", cache=True, fastmath=True)
def surface_flag(n0, n1, n2, p0, p1, p2):
    """Whether a pixel of normal ``(n0, n1, n2)`` and position ``(p0, p1, p2)`` (float32) is a
    surface: the normal is finite and not zero, the position finite (branch-free)."""
    return (((n0 != 0.0) | (n1 != 0.0) | (n2 != 0.0)) & finite(n0) & finite(n1) & finite(n2)
            & finite(p0) & finite(p1) & finite(p2))


@njit(parallel=True, cache=True, fastmath=SURVEY_FASTMATH, error_model="numpy")
def survey(color, normal, position, ids, depth, variance, has_ids, has_depth, has_variance, state,
           row_log, row_count, row_lo, row_hi):
    """Pixel classes and the per-row sums of the colour and position scales, in one pass.

    Background: a normal that is zero or not finite, a position that is not finite, and (when
    those channels are given) ``object_id == -1`` or a depth that is not finite. Still: a
    surface pixel whose ``variance`` is zero in all channels. Active: every other pixel.

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32, C-contiguous
    ids : ndarray (H, W) int32
    depth : ndarray (H, W) float32
    variance : ndarray (H, W, 3) float32
    has_ids, has_depth, has_variance : bool
        Whether the three optional channels are real (else 1x1 stand-ins, never read).
    state : ndarray (H, W) int8, C-contiguous
        Output: BACKGROUND, STILL or ACTIVE.
    row_log, row_count : ndarray (H,) float64, int64
        Output: per row, the sum of ``log(L)`` over surface pixels whose float32 luminance
        ``L`` is finite and at least float32's smallest normal value, and their number.
    row_lo, row_hi : ndarray (H, 3) float64
        Output: per row, the bounding box of the surface pixels' positions (``lo > hi`` when
        the row has none).

    Notes
    -----
    Each row is one branch-free loop that LLVM vectorizes: the surface test, the class and the
    sums of each pixel, after a loop each for the optional channels that are given (they set
    the classes the pixels may have). The inputs are read through flat views with unsigned
    indices, so that the channel stride is the constant 3 (indexing ``a[y, x, c]`` multiplies by
    the array's run-time shape and gives gathers).
    """
    h, w = state.shape
    cf = color.reshape(color.size)
    nf = normal.reshape(normal.size)
    pf = position.reshape(position.size)
    sf = state.reshape(state.size)
    tiny = np.float32(np.finfo(np.float32).tiny)
    big = np.float32(np.inf)
    for r in prange(h):
        y = np.int64(r)
        row = uint64(y * w)
        row3 = uint64(3) * row
        # the classes the optional channels allow (ACTIVE where none is given) ...
        for x in range(w):
            sf[row + uint64(x)] = np.int8(ACTIVE)
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
        # ... then, in one branch-free loop, the surface test and the sums (positions of
        # background pixels may be anything: selected away)
        total = 0.0
        count = 0
        lo0 = lo1 = lo2 = big
        hi0 = hi1 = hi2 = -big
        for x in range(w):
            j = row3 + uint64(3) * uint64(x)
            p0, p1, p2 = pf[j], pf[j + uint64(1)], pf[j + uint64(2)]
            allowed = sf[row + uint64(x)]
            surface = (surface_flag(nf[j], nf[j + uint64(1)], nf[j + uint64(2)], p0, p1, p2)
                       & (allowed != BACKGROUND))
            sf[row + uint64(x)] = allowed if surface else np.int8(BACKGROUND)
            lum = (np.float32(LUMA[0]) * cf[j] + np.float32(LUMA[1]) * cf[j + uint64(1)]
                   + np.float32(LUMA[2]) * cf[j + uint64(2)])
            ok = surface & (lum >= tiny) & finite(lum)
            total += kernels.fast_log(lum if ok else np.float32(1.0))
            count += np.int64(ok)
            lo0 = fast_min(lo0, p0 if surface else big)
            lo1 = fast_min(lo1, p1 if surface else big)
            lo2 = fast_min(lo2, p2 if surface else big)
            hi0 = fast_max(hi0, p0 if surface else -big)
            hi1 = fast_max(hi1, p1 if surface else -big)
            hi2 = fast_max(hi2, p2 if surface else -big)
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


@njit(inline="always", cache=True)
def row_runs(sf, row, w, runs, y):
    """Write the runs of active pixels of one row (``sf[row:row + w]``) to ``runs[y]`` (see
    :func:`pack`) and return their number.

    Scans for the edges of the maximal runs of consecutive active pixels; a run that starts
    fewer than ``MIN_GAP`` pixels after the end of the previous kept run extends it, and
    from the ``MAX_RUNS``-th kept run on every further run extends the last one.
    """
    k = 0
    x = 0
    while x < w:
        if sf[row + uint64(x)] != ACTIVE:
            x += 1
            continue
        start = x
        while x < w and sf[row + uint64(x)] == ACTIVE:
            x += 1
        if k > 0 and (start - runs[y, k - 1, 1] < MIN_GAP or k == MAX_RUNS):
            runs[y, k - 1, 1] = x
        else:
            runs[y, k, 0] = start
            runs[y, k, 1] = x
            k += 1
    return k


@njit(parallel=True, cache=True, error_model="numpy")
def pack(color, normal, position, state, inv_scale, origin, inv_pos, halo, stride, cbuf_a, cbuf_b, gbuf,
         runs, run_count, row_surface):
    """Write the interior of the planar buffers (their halo stays zero) and the active runs.

    Parameters
    ----------
    color, normal, position : ndarray (H, W, 3) float32, C-contiguous
    state : ndarray (H, W) int8, C-contiguous
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

    Notes
    -----
    Each row is one branch-free loop writing the 13 planes, which LLVM vectorizes (flat input
    views and unsigned indices, as in :func:`survey`; every value is loaded before it is
    selected: a load under a condition becomes a masked gather). The loop counts the row's
    active pixels: a row of them all is one run, a row of none has none; the other rows are
    scanned for their runs (:func:`row_runs`).
    """
    h, w = state.shape
    ps = uint64(cbuf_a.shape[0] // 3)
    cf = color.reshape(color.size)
    nf = normal.reshape(normal.size)
    pf = position.reshape(position.size)
    sf = state.reshape(state.size)
    o0, o1, o2 = origin[0], origin[1], origin[2]
    gmax = np.float32(GUIDE_MAX)  # no float32 lies in (float32(GUIDE_MAX), GUIDE_MAX]
    background = np.float32(BACKGROUND_NORMAL)
    zero = np.float32(0.0)
    for r in prange(h):
        y = np.int64(r)
        base = uint64((y + halo) * stride + halo)
        row = uint64(y * w)
        row3 = uint64(3) * row
        surfaces = 0
        actives = 0
        for x in range(w):
            i = base + uint64(x)
            j = row3 + uint64(3) * uint64(x)
            s = sf[row + uint64(x)]
            surface = s != BACKGROUND
            actives += np.int64(s == ACTIVE)
            c0 = normalised(cf[j], inv_scale)
            c1 = normalised(cf[j + uint64(1)], inv_scale)
            c2 = normalised(cf[j + uint64(2)], inv_scale)
            cbuf_a[i] = c0
            cbuf_a[ps + i] = c1
            cbuf_a[uint64(2) * ps + i] = c2
            cbuf_b[i] = c0
            cbuf_b[ps + i] = c1
            cbuf_b[uint64(2) * ps + i] = c2
            n0 = min(max(nf[j], -gmax), gmax)
            n1 = min(max(nf[j + uint64(1)], -gmax), gmax)
            n2 = min(max(nf[j + uint64(2)], -gmax), gmax)
            gbuf[i] = n0 if surface else background
            gbuf[ps + i] = n1 if surface else background
            gbuf[uint64(2) * ps + i] = n2 if surface else background
            p0 = np.float32(min(max((np.float64(pf[j]) - o0) * inv_pos, -GUIDE_MAX), GUIDE_MAX))
            p1 = np.float32(min(max((np.float64(pf[j + uint64(1)]) - o1) * inv_pos, -GUIDE_MAX), GUIDE_MAX))
            p2 = np.float32(min(max((np.float64(pf[j + uint64(2)]) - o2) * inv_pos, -GUIDE_MAX), GUIDE_MAX))
            gbuf[uint64(3) * ps + i] = p0 if surface else zero
            gbuf[uint64(4) * ps + i] = p1 if surface else zero
            gbuf[uint64(5) * ps + i] = p2 if surface else zero
            gbuf[uint64(6) * ps + i] = np.float32(surface)
            surfaces += np.int64(surface)
        row_surface[y] = np.uint8(surfaces > 0)
        if actives == w:  # the common rows need no scan
            runs[y, 0, 0] = 0
            runs[y, 0, 1] = w
            run_count[y] = 1
        elif actives == 0:
            run_count[y] = 0
        else:
            run_count[y] = row_runs(sf, row, w, runs, y)


@njit(inline="always", cache=True)
def unpack_row(cbuf, ps, base, state, y, color, out, w, inv_scale, scale):
    """Row ``y`` of the output from the colour planes ``cbuf`` (``ps`` floats each; the row's
    first pixel at flat index ``base``): ``color + (filtered - normalised colour) * scale`` on
    active pixels, ``color`` on the others. ``color`` and ``out`` are the flat ``(H, W, 3)``
    arrays, ``w`` (uint64) the row's width. One branch-free loop (unsigned indices, every value
    computed before it is selected), which LLVM vectorizes; shared by :func:`unpack` and the CPU
    backend's last pass."""
    row3 = uint64(y) * w * uint64(3)
    p1 = ps + base
    p2 = p1 + ps
    for x in range(w):
        active = state[y, x] == ACTIVE
        j = row3 + x * uint64(3)
        out[j] = _unpacked(color[j], cbuf[base + x], active, inv_scale, scale)
        out[j + uint64(1)] = _unpacked(color[j + uint64(1)], cbuf[p1 + x], active, inv_scale, scale)
        out[j + uint64(2)] = _unpacked(color[j + uint64(2)], cbuf[p2 + x], active, inv_scale, scale)


@njit(inline="always", cache=True)
def _unpacked(v, f, active, inv_scale, scale):
    """``v + (f - normalised v) * scale`` if ``active``, else ``v``."""
    changed = np.float32(np.float64(v) + (np.float64(f) - np.float64(normalised(v, inv_scale))) * scale)
    return changed if active else v


@njit(parallel=True, cache=True)
def unpack(color, state, cbuf, inv_scale, scale, halo, stride, out):
    """``out = color + (filtered - normalised colour) * scale`` on active pixels, else ``color``.

    Used by the CUDA backend (the CPU backend does this in its last pass, with the same
    :func:`unpack_row`). ``color`` and ``out`` are C-contiguous.
    """
    h, w = state.shape
    ps = uint64(cbuf.shape[0] // 3)
    cf = color.reshape(color.size)
    of = out.reshape(out.size)
    for r in prange(h):
        y = np.int64(r)
        unpack_row(cbuf, ps, uint64((y + halo) * stride + halo), state, y, cf, of, uint64(w), inv_scale, scale)


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


