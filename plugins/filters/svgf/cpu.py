"""The ``cpu`` backend: parallel Numba loops over image rows.

Preparation, reprojection and remodulation call the per-pixel stage functions (inlined); the
variance and the à-trous iterations use the row-vectorized kernels of :mod:`.variance_rows`
and :mod:`.atrous_rows`. NumPy's error model: no zero-division branches (every division in the
stages is guarded or has a positive denominator).
"""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from .atrous_rows import atrous_rows
from .modulation import prepare_pixel, remodulate_pixel
from .reproject import gradient_pixel, reproject_pixel
from .variance_rows import variance_rows


@njit(parallel=True, cache=True, error_model="numpy")
def _prepare(first, second, nsig, emission, has_emission, albedo_in, normal_in, depth_in, obj_in,
             motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion, grad):
    h, w = depth_in.shape
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        for j in range(w):
            prepare_pixel(i, j, first, second, nsig, emission, has_emission, albedo_in, normal_in,
                          depth_in, obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal,
                          obj, motion)
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        for j in range(w):
            gradient_pixel(i, j, depth, valid, grad)


@njit(parallel=True, cache=True, error_model="numpy")
def _reproject(sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom, prev_hist,
               prev_valid, prev_depth, prev_normal, prev_obj, has_prev, depth_tol, normal_tol,
               alpha_color, alpha_moments, history_average, max_history, acc_sig, acc_mom, hist):
    h, w = valid.shape
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        for j in range(w):
            reproject_pixel(i, j, sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom,
                            prev_hist, prev_valid, prev_depth, prev_normal, prev_obj, has_prev,
                            depth_tol, normal_tol, alpha_color, alpha_moments, history_average,
                            max_history, acc_sig, acc_mom, hist)


@njit(parallel=True, cache=True, error_model="numpy")
def _remodulate(sig, albedo, valid, color, emission, has_emission, out):
    h, w = valid.shape
    for r in prange(h):
        i = np.int64(r)  # prange indices may be unsigned
        for j in range(w):
            remodulate_pixel(i, j, sig, albedo, valid, color, emission, has_emission, out)


class CpuOps:
    """Array allocation and stage launches of the ``cpu`` backend (NumPy arrays, Numba loops)."""


    def empty(self, shape, dtype):
        """An uninitialised host array."""
        return np.empty(shape, dtype)

    def upload(self, array):
        """Host arrays are used as they are."""
        return np.ascontiguousarray(array)

    def download(self, array):
        """Host arrays are returned as they are."""
        return array

    def synchronize(self):
        """Nothing to wait for."""

    prepare = staticmethod(_prepare)
    reproject = staticmethod(_reproject)
    variance = staticmethod(variance_rows)
    atrous = staticmethod(atrous_rows)
    remodulate = staticmethod(_remodulate)
