"""The ``cpu`` backend: parallel Numba loops over image rows.

Preparation and remodulation run the row-vectorized forms of the per-pixel stage functions
(:mod:`.prepare_rows`), reprojection calls its per-pixel function (inlined); the
variance uses the row-vectorized kernel of :mod:`.variance_rows`, the à-trous iterations the
padded planes of :mod:`.atrous_planes`. Every stage runs one ``prange`` iteration per thread,
the threads taking tasks of consecutive rows from a shared counter
(:func:`harness.kernels.take_range`). NumPy's error model: no zero-division branches (every
division in the stages is guarded or has a positive denominator).
"""

from __future__ import annotations

import numpy as np
from numba import get_num_threads, njit, prange

from harness import kernels

from .atrous_planes import PlanePool, atrous_level, pack_planes
from .params import TASK_ROWS
from .prepare_rows import prepare_row, remodulate_row
from .reproject import gradient_pixel, reproject_pixel
from .variance_rows import variance_rows


@njit(parallel=True, cache=True, error_model="numpy")
def _prepare(color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in, obj_in,
             motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion, grad, nthreads):
    h, w = depth_in.shape
    counter = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        while True:
            start, stop = kernels.take_range(counter, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                prepare_row(i, color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in,
                            obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion)
    gradient_tasks = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        while True:
            start, stop = kernels.take_range(gradient_tasks, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                for j in range(w):
                    gradient_pixel(i, j, depth, valid, grad)


@njit(parallel=True, cache=True, error_model="numpy")
def _reproject(sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom, prev_hist,
               prev_valid, prev_depth, prev_normal, prev_obj, has_prev, depth_tol, normal_tol,
               alpha_color, alpha_moments, history_average, max_history, acc_sig, acc_mom, hist, nthreads):
    h, w = valid.shape
    counter = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        while True:
            start, stop = kernels.take_range(counter, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                for j in range(w):
                    reproject_pixel(i, j, sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom,
                                    prev_hist, prev_valid, prev_depth, prev_normal, prev_obj, has_prev,
                                    depth_tol, normal_tol, alpha_color, alpha_moments, history_average,
                                    max_history, acc_sig, acc_mom, hist)


@njit(parallel=True, cache=True, error_model="numpy")
def _remodulate(sig, albedo, valid, color, emission, has_emission, out, nthreads):
    h, w = valid.shape
    counter = np.zeros(1, np.int64)
    for _ in prange(kernels.thread_count(nthreads, h, TASK_ROWS)):
        while True:
            start, stop = kernels.take_range(counter, h, TASK_ROWS)
            if start >= stop:
                break
            for i in range(start, stop):
                remodulate_row(i, sig, albedo, valid, color, emission, has_emission, out)


class Ops:
    """Array allocation and stage launches of the ``cpu`` backend (NumPy arrays, Numba loops)."""

    def __init__(self):
        self._pool = None

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

    def prepare(self, *args):
        """Demodulation, planar G-buffer and depth gradient (:func:`.modulation.prepare_pixel`)."""
        _prepare(*args, get_num_threads())

    def reproject(self, *args):
        """Reprojection and accumulation (:func:`.reproject.reproject_pixel`)."""
        _reproject(*args, get_num_threads())

    def variance(self, *args):
        """Luminance variance (:func:`.variance_rows.variance_rows`)."""
        variance_rows(*args, get_num_threads())

    def atrous(self, it, iterations, sig, var, valid, depth, normal, grad, sigma_z, sigma_n, sigma_l,
               depth_eps, lum_eps, sig_out, var_out, keep):
        """Iteration ``it`` of ``iterations`` on the padded planes of :mod:`.atrous_planes`.

        The first iteration packs the G-buffer, ``sig`` and ``var`` into the pool; later ones
        read the pool's previous output (their ``sig`` and ``var`` are not read). The filtered
        signals are written to ``sig_out`` only when ``keep``; the variances stay in the pool
        (``var_out`` is not written).
        """
        nsig, _, h, w = sig.shape
        pool = self._pool
        if it == 0:
            if pool is None or pool.key != (nsig, h, w, iterations):
                pool = self._pool = PlanePool(nsig, h, w, iterations)
            pack_planes(valid, depth, normal, grad, sig, var, sigma_z, depth_eps, pool.halo, pool.stride,
                        pool.plane_size, pool.signal_plane(0), pool.planes)
        atrous_level(pool.planes, pool.plane_size, nsig, h, w, pool.halo, pool.stride, 1 << it,
                     pool.signal_plane(it % 2), pool.signal_plane((it + 1) % 2), sigma_n, sigma_l, lum_eps, keep,
                     sig_out, get_num_threads())

    def remodulate(self, *args):
        """Remodulation (:func:`.modulation.remodulate_pixel`)."""
        _remodulate(*args, get_num_threads())
