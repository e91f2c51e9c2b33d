"""Separable Gaussian blur with renormalised weights at the image border."""

from __future__ import annotations

import numpy as np
from numba import njit, prange


def gaussian_taps(sigma: float) -> np.ndarray:
    """Normalised 1-D Gaussian taps of radius ``ceil(3 sigma)``, float32."""
    radius = max(int(np.ceil(3.0 * sigma)), 0)
    x = np.arange(-radius, radius + 1, dtype=np.float64)
    taps = np.exp(-0.5 * (x / sigma) ** 2) if sigma > 0 else np.ones(1)
    return (taps / taps.sum()).astype(np.float32)


@njit(parallel=True, cache=True)
def _blur_rows(src, taps, dst):
    h, w, c = src.shape
    r = (taps.shape[0] - 1) // 2
    for i in prange(h):
        for j in range(w):
            acc0 = 0.0
            acc1 = 0.0
            acc2 = 0.0
            wsum = 0.0
            for k in range(-r, r + 1):
                jj = j + k
                if 0 <= jj < w:
                    t = taps[k + r]
                    acc0 += t * src[i, jj, 0]
                    acc1 += t * src[i, jj, 1]
                    acc2 += t * src[i, jj, 2]
                    wsum += t
            dst[i, j, 0] = acc0 / wsum
            dst[i, j, 1] = acc1 / wsum
            dst[i, j, 2] = acc2 / wsum


class GaussianBlur:
    """Blur ``frame["color"]`` with a Gaussian of standard deviation ``sigma`` pixels.

    Parameters
    ----------
    backend : {"cpu"}
    sigma : float
        Standard deviation in pixels (0 returns the input).

    Notes
    -----
    Sums are accumulated in float64, so inputs near the float32 limit stay finite: each output is
    a convex combination of inputs.
    """

    def __init__(self, backend: str = "cpu", sigma: float = 1.5):
        if backend != "cpu":
            raise ValueError(f"gaussian: unsupported backend {backend!r}")
        if not np.isfinite(sigma) or sigma < 0:
            raise ValueError(f"gaussian: sigma must be a finite number >= 0, got {sigma}")
        self.sigma = float(sigma)
        self._taps = gaussian_taps(self.sigma)

    def reset(self) -> None:
        """Stateless."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        src = np.ascontiguousarray(frame["color"], dtype=np.float32)
        tmp = np.empty_like(src)
        _blur_rows(src, self._taps, tmp)
        cols = np.ascontiguousarray(tmp.transpose(1, 0, 2))
        res = np.empty_like(cols)
        _blur_rows(cols, self._taps, res)
        return np.ascontiguousarray(res.transpose(1, 0, 2))
