"""LBF on the GPU (``numba.cuda``): the per-pixel bodies of :mod:`.kernels`, one thread a pixel.

The only host-side work is the frame's position mean and scale (two scalar reductions, done
with the CPU code of :func:`.features.position_stats`), the test whether the frame carries a
variance, the filter's planar colour and variance, and the transfers. :class:`Denoiser` is the
entry point, as in :mod:`.cpu`. Runs under Numba's CUDA simulator (``NUMBA_ENABLE_CUDASIM=1``)
for tests.
"""

from __future__ import annotations

import time

import numpy as np
from numba import cuda, float64

from . import kernels as K
from .features import FEATURE_VAR_FLOOR, Inputs, position_stats

_signals_d = cuda.jit(device=True)(K.signals_px)
_haar_d = cuda.jit(device=True)(K.haar_px)
_box7_d = cuda.jit(device=True)(K.box7_px)
_combine_d = cuda.jit(device=True)(K.combine_px)
_mlp_d = cuda.jit(device=True)(K.mlp_px)
_filter_d = cuda.jit(device=True)(K.filter_px)
_color_rows_d = cuda.jit(device=True)(K.color_rows_px)
_variance_estimate_d = cuda.jit(device=True)(K.variance_estimate_px)

BLOCK = (16, 16)


@cuda.jit
def _color_rows_k(color, r, dst):
    j, i = cuda.grid(2)
    if i < color.shape[0] and j < color.shape[1]:
        _color_rows_d(i, j, color, r, dst)


@cuda.jit
def _variance_estimate_k(rows, r, out):
    j, i = cuda.grid(2)
    if i < rows.shape[0] and j < rows.shape[1]:
        _variance_estimate_d(i, j, rows, r, out)


@cuda.jit
def _signals_k(color, variance, position, normal, albedo, vis, has_vis, spp, has_spp,
               mu0, mu1, mu2, inv_scale, sig, aux):
    j, i = cuda.grid(2)
    if i < color.shape[0] and j < color.shape[1]:
        _signals_d(i, j, color, variance, position, normal, albedo, vis, has_vis, spp, has_spp,
                   mu0, mu1, mu2, inv_scale, sig, aux)


@cuda.jit
def _haar_k(sig, hh):
    j, i = cuda.grid(2)
    if i < sig.shape[1] and j < sig.shape[2]:
        _haar_d(i, j, sig, hh)


@cuda.jit
def _features_network_k(sig, aux, hh, mean, inv_std, w1, b1, w2, b2, params):
    j, i = cuda.grid(2)
    if i < sig.shape[1] and j < sig.shape[2]:
        col7 = cuda.local.array(K.N_BOX7, float64)
        med = cuda.local.array(9, float64)
        feat = cuda.local.array(K.N_FEATURES, float64)
        z = cuda.local.array(K.N_FEATURES, float64)
        hidden = cuda.local.array(K.N_HIDDEN, float64)
        out = cuda.local.array(K.N_OUT, float64)
        _box7_d(i, j, sig, aux, col7)
        _combine_d(i, j, sig, aux, hh, col7, med, feat)
        _mlp_d(feat, mean, inv_std, w1, b1, w2, b2, z, hidden, out)
        for o in range(K.N_OUT):
            params[o, i, j] = out[o]


@cuda.jit
def _filter_k(color, variance, sig, params, radius, inv_tau, out):
    j, i = cuda.grid(2)
    if i < color.shape[1] and j < color.shape[2]:
        _filter_d(i, j, color, variance, sig, params, radius, inv_tau, out)


def _planes(color: np.ndarray, variance: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """The filter's planar colour (NaN -> 0, clamped to float32) and sanitised variance."""
    big = np.finfo(np.float32).max
    c = np.clip(np.nan_to_num(np.moveaxis(color, -1, 0), nan=0.0), -big, big)
    with np.errstate(invalid="ignore"):
        v = np.moveaxis(variance, -1, 0)
        v = np.where(v > 0, np.minimum(v, K.VAR_MAX), 0.0)
    return np.ascontiguousarray(c, np.float32), np.ascontiguousarray(v, np.float32)


class Denoiser:
    """The LBF pipeline on the GPU, with the network's weights kept on the device.

    Parameters
    ----------
    model : LBFWeights
    """

    def __init__(self, model):
        if model.w1.shape[0] != K.N_HIDDEN:
            raise ValueError(
                f"lbf cuda: the kernels are built for {K.N_HIDDEN} hidden units, "
                f"got {model.w1.shape[0]}"
            )
        arrays = (model.mean, model.inv_std, model.w1, model.b1, model.w2, model.b2)
        self._w = [cuda.to_device(a) for a in arrays]

    def __call__(self, inputs: Inputs, radius: int) -> tuple[np.ndarray, dict]:
        """Filter one frame; returns the output (H, W, 3) float32 and the per-stage milliseconds."""
        h, w = inputs.shape
        grid = ((w + BLOCK[0] - 1) // BLOCK[0], (h + BLOCK[1] - 1) // BLOCK[1])
        t0 = time.perf_counter_ns()
        mu, scale = position_stats(inputs.position, inputs.normal)
        d = {name: cuda.to_device(getattr(inputs, name))
             for name in ("color", "variance", "position", "normal", "albedo", "vis", "spp")}
        cuda.synchronize()
        t1 = time.perf_counter_ns()
        if inputs.estimate_variance:
            rows = cuda.device_array((h, w, 6), np.float64)
            _color_rows_k[grid, BLOCK](d["color"], K.VAR_RADIUS, rows)
            d["variance"] = cuda.device_array((h, w, 3), np.float32)
            _variance_estimate_k[grid, BLOCK](rows, K.VAR_RADIUS, d["variance"])
        sig = cuda.device_array((K.N_SIG, h, w), np.float32)
        aux = cuda.device_array((h, w, 3), np.float32)
        _signals_k[grid, BLOCK](d["color"], d["variance"], d["position"], d["normal"], d["albedo"],
                                d["vis"], inputs.has_vis, d["spp"], inputs.has_spp,
                                float(mu[0]), float(mu[1]), float(mu[2]), 1.0 / scale, sig, aux)
        hh = cuda.device_array((h, w, 5), np.float32)
        _haar_k[grid, BLOCK](sig, hh)
        cuda.synchronize()
        t2 = time.perf_counter_ns()
        params = cuda.device_array((K.N_OUT, h, w), np.float32)
        _features_network_k[grid, BLOCK](sig, aux, hh, *self._w, params)
        cuda.synchronize()
        t3 = time.perf_counter_ns()
        variance = d["variance"].copy_to_host() if inputs.estimate_variance else inputs.variance
        cplane, vplane = _planes(inputs.color, variance)
        out = cuda.device_array((h, w, 3), np.float32)
        _filter_k[grid, BLOCK](cuda.to_device(cplane), cuda.to_device(vplane), sig, params,
                               int(radius), 1.0 / FEATURE_VAR_FLOOR, out)
        cuda.synchronize()
        t4 = time.perf_counter_ns()
        result = out.copy_to_host()
        t5 = time.perf_counter_ns()
        stage_ms = {
            "upload": (t1 - t0) / 1e6,
            "signals": (t2 - t1) / 1e6,
            "network": (t3 - t2) / 1e6,
            "bilateral": (t4 - t3) / 1e6,
            "download": (t5 - t4) / 1e6,
        }
        return result, stage_ms
