"""Running per-pixel sums of a frame, shared by the renderer and its adaptive sampler."""

from __future__ import annotations

import numpy as np


class PixelState:
    """Running per-pixel sums of one frame: what a :class:`Frame` is computed from.

    Attributes
    ----------
    acc, acc_sq, acc_direct : ndarray (N, 3) float64
        Sums of radiance, squared radiance and direct radiance over the samples taken.
    shadow : ndarray (N, 2) float64
        First-hit light samples and those that reached their light.
    spp : ndarray (N,) int64
        Samples taken per pixel.
    """

    def __init__(self, n: int):
        self.acc = np.zeros((n, 3))
        self.acc_sq = np.zeros((n, 3))
        self.acc_direct = np.zeros((n, 3))
        self.shadow = np.zeros((n, 2))
        self.spp = np.zeros(n, np.int64)
