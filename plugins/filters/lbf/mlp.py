"""LBF's per-pixel network on the CPU (Numba): z-normalise, 36 -> 10 (sigmoid) -> 6 (softplus)."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import kernels as K

_mlp_px = njit(cache=True)(K.mlp_px)


@njit(parallel=True, cache=True)
def _mlp_cpu(feat, mean, inv_std, w1, b1, w2, b2, params):
    h, w, _ = feat.shape
    for i in prange(h):
        z = np.empty(w1.shape[1])
        hidden = np.empty(w1.shape[0])
        for j in range(w):
            _mlp_px(i, j, feat, mean, inv_std, w1, b1, w2, b2, z, hidden, params)


def predict_bandwidths(features: np.ndarray, model) -> np.ndarray:
    """Per-pixel filter bandwidths from the secondary features.

    Parameters
    ----------
    features : ndarray (H, W, 36) float32
        Raw secondary features (:func:`.features.extract_features`).
    model : LBFWeights
        Network weights and normalisation statistics (:mod:`.weights`).

    Returns
    -------
    ndarray (H, W, 6) float32
        ``(a, c, b_position, b_normal, b_albedo, b_visibility)``, all > 0 (softplus): the
        screen-distance, colour and feature bandwidths of :func:`.filter_cpu.cross_bilateral`.
    """
    h, w, _ = features.shape
    params = np.empty((h, w, model.w2.shape[0]), np.float32)
    _mlp_cpu(features, model.mean, model.inv_std, model.w1, model.b1, model.w2, model.b2, params)
    return params
