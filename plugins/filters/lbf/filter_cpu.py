"""LBF's cross-bilateral filter on the CPU (Numba)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import kernels as K
from .features import FEATURE_VAR_FLOOR

_filter_px = njit(cache=True, fastmath={"nsz", "arcp", "contract", "reassoc"})(K.filter_px)


@njit(parallel=True, cache=True)
def _filter_cpu(color, variance, sig, params, radius, inv_tau, out):
    h, w, _ = color.shape
    for i in prange(h):
        for j in range(w):
            _filter_px(i, j, color, variance, sig, params, radius, inv_tau, out)


def cross_bilateral(color: np.ndarray, variance: np.ndarray, sig: np.ndarray, params: np.ndarray,
                    radius: int) -> np.ndarray:
    """Filter ``color`` with per-pixel bandwidths (Kalantari et al. 2015, eq. 3).

    Parameters
    ----------
    color, variance : ndarray (H, W, 3) float32
        Noisy colour and the variance of its pixel mean.
    sig : ndarray (H, W, 13) float32
        Signals of :func:`.features.extract_features` (channels 3-12: primary features).
    params : ndarray (H, W, 6) float32
        Bandwidths ``(a, c, b_position, b_normal, b_albedo, b_visibility)``.
    radius : int
        Window radius in pixels (window ``2 radius + 1`` square; taps outside the image are
        skipped).

    Returns
    -------
    ndarray (H, W, 3) float32
        ``sum_j w_ij c_j / sum_j w_ij`` with ``w_ij = exp(-D_ij)``,
        ``D = a |p_i - p_j|^2 + c sum_ch (c_i - c_j)^2 / (var_i + var_j + 1e-10)
        + sum_k b_k sum_ch (f_ik - f_jk)^2 / max(1e-4, var_i(f_k))``.
    """
    out = np.empty(color.shape, np.float32)
    _filter_cpu(color, variance, sig, params, int(radius), 1.0 / FEATURE_VAR_FLOOR, out)
    return out
