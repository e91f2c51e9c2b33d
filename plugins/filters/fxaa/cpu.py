"""FXAA on the CPU (Numba): one pass, a thread a row band.

Per pixel, after Lottes' FXAA (NVIDIA 2009-2011, the "console" variant): the perceptual luma
``sqrt(Y / (1 + Y))`` (``Y`` the luma of YCoCg of the linear colour) of the pixel and of the four
diagonal half-pixel points (bilinear averages of 2x2 pixels); below a local contrast of
``max(edge_threshold_min, edge_threshold * luma_max)`` the pixel is kept. Otherwise the edge's
tangent is estimated from the diagonal lumas, scaled so that its shorter component is about a
pixel and clamped to ``span_max`` pixels, and the colour is blended from two (``A``) or four
(``B``) bilinear samples along it; ``B`` is used unless its luma leaves the local luma range.
"""

from __future__ import annotations

import math

import numpy as np
from numba import njit, prange

REDUCE_MUL = 1.0 / 8.0
REDUCE_MIN = 1.0 / 128.0


@njit(cache=True, inline="always")
def _luma(r, g, b):
    y = max(0.25 * r + 0.5 * g + 0.25 * b, 0.0)
    return math.sqrt(y / (1.0 + y))


@njit(cache=True, inline="always")
def _sample(color, x, y, c):
    """Bilinear lookup of channel ``c`` at image point (x, y) (pixel centres on integers, clamped)."""
    h, w = color.shape[0], color.shape[1]
    x = min(max(x, 0.0), w - 1.0)
    y = min(max(y, 0.0), h - 1.0)
    x0 = min(int(math.floor(x)), w - 1)
    y0 = min(int(math.floor(y)), h - 1)
    x1 = min(x0 + 1, w - 1)
    y1 = min(y0 + 1, h - 1)
    fx = x - x0
    fy = y - y0
    top = color[y0, x0, c] * (1.0 - fx) + color[y0, x1, c] * fx
    bottom = color[y1, x0, c] * (1.0 - fx) + color[y1, x1, c] * fx
    return top * (1.0 - fy) + bottom * fy


@njit(cache=True, inline="always")
def _luma_at(color, x, y):
    return _luma(_sample(color, x, y, 0), _sample(color, x, y, 1), _sample(color, x, y, 2))


@njit(cache=True, parallel=True)
def _fxaa(color, edge_threshold, edge_threshold_min, span_max, out):
    h, w = color.shape[0], color.shape[1]
    for i in prange(h):
        for j in range(w):
            x = float(j)
            y = float(i)
            m = _luma(color[i, j, 0], color[i, j, 1], color[i, j, 2])
            nw = _luma_at(color, x - 0.5, y - 0.5)
            ne = _luma_at(color, x + 0.5, y - 0.5)
            sw = _luma_at(color, x - 0.5, y + 0.5)
            se = _luma_at(color, x + 0.5, y + 0.5)
            lo = min(m, min(min(nw, ne), min(sw, se)))
            hi = max(m, max(max(nw, ne), max(sw, se)))
            if hi - lo < max(edge_threshold_min, hi * edge_threshold):
                for c in range(3):
                    out[i, j, c] = color[i, j, c]
                continue
            dx = -((nw + ne) - (sw + se))
            dy = (nw + sw) - (ne + se)
            reduce = max((nw + ne + sw + se) * 0.25 * REDUCE_MUL, REDUCE_MIN)
            scale = 1.0 / (min(abs(dx), abs(dy)) + reduce)
            dx = min(max(dx * scale, -span_max), span_max)
            dy = min(max(dy * scale, -span_max), span_max)
            a = np.empty(3)
            b = np.empty(3)
            for c in range(3):
                a[c] = 0.5 * (_sample(color, x + dx * (1.0 / 3.0 - 0.5), y + dy * (1.0 / 3.0 - 0.5), c)
                              + _sample(color, x + dx * (2.0 / 3.0 - 0.5), y + dy * (2.0 / 3.0 - 0.5), c))
                b[c] = 0.5 * a[c] + 0.25 * (_sample(color, x - 0.5 * dx, y - 0.5 * dy, c)
                                            + _sample(color, x + 0.5 * dx, y + 0.5 * dy, c))
            lb = _luma(b[0], b[1], b[2])
            use_a = lb < lo or lb > hi
            for c in range(3):
                out[i, j, c] = max(a[c] if use_a else b[c], 0.0)


def fxaa(color: np.ndarray, edge_threshold: float, edge_threshold_min: float, span_max: float) -> np.ndarray:
    """Anti-alias one (H, W, 3) float32 image; see the module docstring."""
    out = np.empty(color.shape, np.float32)
    _fxaa(np.ascontiguousarray(color, np.float32), edge_threshold, edge_threshold_min, span_max, out)
    return out
