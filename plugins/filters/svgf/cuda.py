"""The ``cuda`` backend: ``numba.cuda`` kernels, one thread per pixel.

The kernels run the same per-pixel stage functions as the ``cpu`` backend: each ``@njit``
function (and every ``@njit`` helper it calls) is recompiled as a CUDA device function, so both
backends share one implementation of the algorithm. Tested under ``NUMBA_ENABLE_CUDASIM=1``.
"""

from __future__ import annotations

import types

import numpy as np
from numba import cuda
from numba.core.registry import CPUDispatcher

from .atrous import atrous_pixel
from .modulation import prepare_pixel, remodulate_pixel
from .reproject import gradient_pixel, reproject_pixel
from .variance import variance_pixel

_DEVICE: dict = {}


def _device(dispatcher):
    """A CUDA device function compiled from an ``@njit`` function, its helpers converted too."""
    if dispatcher in _DEVICE:
        return _DEVICE[dispatcher]
    func = dispatcher.py_func
    names = dict(func.__globals__)
    for name in func.__code__.co_names:
        value = names.get(name)
        if isinstance(value, CPUDispatcher):
            names[name] = _device(value)
    rebuilt = types.FunctionType(func.__code__, names, func.__name__, func.__defaults__, func.__closure__)
    _DEVICE[dispatcher] = cuda.jit(device=True)(rebuilt)
    return _DEVICE[dispatcher]


_prepare_px = _device(prepare_pixel)
_gradient_px = _device(gradient_pixel)
_reproject_px = _device(reproject_pixel)
_variance_px = _device(variance_pixel)
_atrous_px = _device(atrous_pixel)
_remodulate_px = _device(remodulate_pixel)


@cuda.jit
def _prepare_kernel(color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in,
                    obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion):
    j, i = cuda.grid(2)
    if i < depth_in.shape[0] and j < depth_in.shape[1]:
        _prepare_px(i, j, color, indirect, nsig, emission, has_emission, albedo_in, normal_in,
                    depth_in, obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal,
                    obj, motion)


@cuda.jit
def _gradient_kernel(depth, valid, grad):
    j, i = cuda.grid(2)
    if i < depth.shape[0] and j < depth.shape[1]:
        _gradient_px(i, j, depth, valid, grad)


@cuda.jit
def _reproject_kernel(sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom, prev_hist,
                      prev_valid, prev_depth, prev_normal, prev_obj, has_prev, depth_tol,
                      normal_tol, alpha_color, alpha_moments, history_average, max_history,
                      acc_sig, acc_mom, hist):
    j, i = cuda.grid(2)
    if i < valid.shape[0] and j < valid.shape[1]:
        _reproject_px(i, j, sig, valid, depth, normal, obj, grad, motion, prev_sig, prev_mom,
                      prev_hist, prev_valid, prev_depth, prev_normal, prev_obj, has_prev,
                      depth_tol, normal_tol, alpha_color, alpha_moments, history_average,
                      max_history, acc_sig, acc_mom, hist)


@cuda.jit
def _variance_kernel(mom, hist, valid, depth, normal, grad, variance_frames, sigma_z, sigma_n,
                     depth_eps, var):
    j, i = cuda.grid(2)
    if i < valid.shape[0] and j < valid.shape[1]:
        _variance_px(i, j, mom, hist, valid, depth, normal, grad, variance_frames, sigma_z,
                     sigma_n, depth_eps, var)


@cuda.jit
def _atrous_kernel(step, sig, var, valid, depth, normal, grad, sigma_z, sigma_n, sigma_l,
                   depth_eps, lum_eps, sig_out, var_out):
    j, i = cuda.grid(2)
    if i < valid.shape[0] and j < valid.shape[1]:
        _atrous_px(i, j, step, sig, var, valid, depth, normal, grad, sigma_z, sigma_n, sigma_l,
                   depth_eps, lum_eps, sig_out, var_out)


@cuda.jit
def _remodulate_kernel(sig, albedo, valid, color, emission, has_emission, out):
    j, i = cuda.grid(2)
    if i < valid.shape[0] and j < valid.shape[1]:
        _remodulate_px(i, j, sig, albedo, valid, color, emission, has_emission, out)


_BLOCK = (16, 8)


def _grid(h, w):
    return ((w + _BLOCK[0] - 1) // _BLOCK[0], (h + _BLOCK[1] - 1) // _BLOCK[1])


class Ops:
    """Array allocation and stage launches of the ``cuda`` backend (device arrays)."""

    def empty(self, shape, dtype):
        """An uninitialised device array."""
        return cuda.device_array(shape, dtype)

    def upload(self, array):
        """Copy a host array to the device."""
        return cuda.to_device(np.ascontiguousarray(array))

    def download(self, array):
        """Copy a device array to the host."""
        return array.copy_to_host()

    def synchronize(self):
        """Wait for every launched kernel."""
        cuda.synchronize()

    def prepare(self, color, indirect, nsig, emission, has_emission, albedo_in, normal_in, depth_in,
                obj_in, motion_in, albedo_eps, sig, albedo, valid, depth, normal, obj, motion, grad):
        """Demodulate, convert the G-buffer to planar layouts, compute the depth gradient."""
        g = _grid(*depth_in.shape)
        _prepare_kernel[g, _BLOCK](color, indirect, nsig, emission, has_emission, albedo_in,
                                   normal_in, depth_in, obj_in, motion_in, albedo_eps, sig, albedo,
                                   valid, depth, normal, obj, motion)
        _gradient_kernel[g, _BLOCK](depth, valid, grad)

    def reproject(self, *args):
        """Temporal reprojection and accumulation (see :func:`.reproject.reproject_pixel`)."""
        _reproject_kernel[_grid(*args[1].shape), _BLOCK](*args)

    def variance(self, *args):
        """Luminance variance (see :func:`.variance.variance_pixel`)."""
        _variance_kernel[_grid(*args[2].shape), _BLOCK](*args)

    def atrous(self, it, iterations, sig, var, valid, depth, normal, grad, sigma_z, sigma_n, sigma_l,
               depth_eps, lum_eps, sig_out, var_out, keep):
        """Iteration ``it`` of ``iterations`` (see :func:`.atrous.atrous_pixel`); every output is
        written, ``keep`` or not."""
        _atrous_kernel[_grid(*valid.shape), _BLOCK](1 << it, sig, var, valid, depth, normal, grad, sigma_z,
                                                    sigma_n, sigma_l, depth_eps, lum_eps, sig_out, var_out)

    def remodulate(self, sig, albedo, valid, color, emission, has_emission, out):
        """Multiply the filtered signals by the albedo and add the emission (input colour on
        background)."""
        _remodulate_kernel[_grid(*valid.shape), _BLOCK](sig, albedo, valid, color, emission,
                                                        has_emission, out)
