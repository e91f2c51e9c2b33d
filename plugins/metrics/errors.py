"""Squared-error metrics, bias-corrected for the reference's own noise, on HDR and displayed images.

HDR metrics on linear radiance: ``rmse``, ``psnr`` (peak 1) and ``relmse``
(``(x - r)^2 / (r^2 + 0.01)``, Rousselle et al.). Display-referred metrics on the harness's
display mapping (:func:`harness.encode_srgb`: exposure 1, clamp to [0, 1], sRGB curve, the
same images SSIM and FLIP see): ``display_rmse`` and ``display_psnr`` (peak 1 = white). The
paper's RMSE values are on a displayed scale; compare them with ``display_rmse``.

**Bias correction.** A Monte Carlo reference ``r`` is the true image ``mu`` plus noise of
variance ``v`` (its per-pixel variance of the mean), independent of the output ``x``. Then
``E[(x - r)^2] = (x - mu)^2 + v``: the squared error against the reference overstates the
error against the truth by the reference's variance. Given ``reference_variance`` these
metrics subtract it per pixel, which makes the MSE an unbiased estimate of the MSE against
the true image: ``mse = mean((x - r)^2 - v)``. ``relmse`` divides each pixel's corrected term
by ``r^2 + 0.01`` (first order: the denominator's own noise is neglected); the display metrics
use the variance of the displayed reference, ``encode_srgb'(r)^2 v`` (the delta method,
:func:`harness.display_variance`). An estimate can fall below zero when the output is closer
to the truth than the reference's noise can resolve: RMSE is then 0, PSNR at most
``10 log10(1 / 1e-10) = 100`` dB, and relMSE keeps its (small, negative) unbiased value. The
uncorrected RMSE is ``sqrt(rmse^2 + floor^2)`` with the row's ``reference_noise`` floor.

**Emitters.** Given a ``mask`` (True where a pixel is scored) only those pixels count; the
harness passes one that leaves out pixels whose first hit is an emitter (from the ``emission``
channel) unless a run says ``--emitters include``. With no pixel left the score is NaN.

All sums are float64, averaged over the scored pixels and the three channels.
"""

from __future__ import annotations

import math

import numpy as np

from harness import MetricSpec, display_variance, encode_srgb, hookimpl

RELMSE_EPS = 0.01
#: the smallest bias-corrected MSE a PSNR is computed from (caps PSNR at 100 dB)
MSE_FLOOR = 1e-10
INPUTS = frozenset({"reference_variance", "mask"})


def _pixels(array, mask) -> np.ndarray:
    """Float64 values of the scored pixels: (n, 3) with a mask, else the whole array."""
    a = np.asarray(array, np.float64)
    return a if mask is None else a[np.asarray(mask, bool)]


def squared_errors(output, reference, reference_variance=None, mask=None, weight=None) -> float:
    """Mean over scored pixels and channels of ``((x - r)^2 - v) * weight`` (v, weight optional).

    Returns NaN when the mask leaves no pixel.
    """
    d = _pixels(output, mask) - _pixels(reference, mask)
    term = d * d
    if reference_variance is not None:
        term = term - _pixels(reference_variance, mask)
    if weight is not None:
        term = term * _pixels(weight, mask)
    return float(np.mean(term)) if term.size else math.nan


def _rmse(mse: float) -> float:
    return math.nan if math.isnan(mse) else math.sqrt(max(mse, 0.0))


def _psnr(mse: float, corrected: bool, peak: float = 1.0) -> float:
    if math.isnan(mse):
        return math.nan
    if mse <= 0.0 and not corrected:
        return math.inf
    return float(10.0 * np.log10(peak * peak / max(mse, MSE_FLOOR)))


def rmse(output, reference, reference_variance=None, mask=None) -> float:
    """Root-mean-square error on linear radiance (bias-corrected when given the variance)."""
    return _rmse(squared_errors(output, reference, reference_variance, mask))


def psnr(output, reference, reference_variance=None, mask=None, peak: float = 1.0) -> float:
    """PSNR in dB on linear radiance for a peak of ``peak``; inf when equal (uncorrected)."""
    mse = squared_errors(output, reference, reference_variance, mask)
    return _psnr(mse, reference_variance is not None, peak)


def relmse(output, reference, reference_variance=None, mask=None, eps: float = RELMSE_EPS) -> float:
    """Relative MSE, ``mean(((x - r)^2 - v) / (r^2 + eps))`` (eps = 0.01)."""
    ref = np.asarray(reference, np.float64)
    return squared_errors(output, reference, reference_variance, mask, weight=1.0 / (ref * ref + eps))


def _display(output, reference, reference_variance):
    var = None if reference_variance is None else display_variance(reference, reference_variance)
    return encode_srgb(output), encode_srgb(reference), var


def display_rmse(output, reference, reference_variance=None, mask=None) -> float:
    """RMSE of the displayed images (clamped, sRGB-encoded; bias-corrected when given the variance)."""
    return _rmse(squared_errors(*_display(output, reference, reference_variance), mask))


def display_psnr(output, reference, reference_variance=None, mask=None) -> float:
    """PSNR in dB of the displayed images (peak 1 = display white)."""
    mse = squared_errors(*_display(output, reference, reference_variance), mask)
    return _psnr(mse, reference_variance is not None)


def _spec(name, function, higher, description, floor="") -> MetricSpec:
    return MetricSpec(name=name, version="2.0", factory=lambda: function, higher_is_better=higher,
                      description=description, accepts=INPUTS, noise_floor=floor)


@hookimpl
def register_metrics():
    return [
        _spec("rmse", rmse, False, "RMSE, linear HDR radiance, bias-corrected, emitters excluded", "reference_noise"),
        _spec("psnr", psnr, True, "PSNR in dB (peak 1.0), linear HDR radiance, bias-corrected, emitters excluded"),
        _spec("relmse", relmse, False, "relative MSE (x-r)^2/(r^2+0.01), HDR, bias-corrected, emitters excluded"),
        _spec("display_rmse", display_rmse, False,
              "RMSE of the displayed image (exposure 1, clamp, sRGB), bias-corrected, emitters excluded",
              "reference_noise_display"),
        _spec("display_psnr", display_psnr, True,
              "PSNR in dB of the displayed image (exposure 1, clamp, sRGB), bias-corrected, emitters excluded"),
    ]
