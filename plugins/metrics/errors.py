"""Pixel error metrics: ``rmse``, ``psnr``, ``relmse``.

All are computed in float64 on linear radiance (no tone mapping), averaged over pixels and the
three colour channels.
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, hookimpl

RELMSE_EPS = 0.01


def _diff(output: np.ndarray, reference: np.ndarray) -> np.ndarray:
    return np.asarray(output, np.float64) - np.asarray(reference, np.float64)


def rmse(output: np.ndarray, reference: np.ndarray) -> float:
    """Root-mean-square error."""
    return float(np.sqrt(np.mean(_diff(output, reference) ** 2)))


def psnr(output: np.ndarray, reference: np.ndarray, peak: float = 1.0) -> float:
    """Peak signal-to-noise ratio in dB for a peak of ``peak`` (1.0: linear radiance); inf when equal."""
    mse = float(np.mean(_diff(output, reference) ** 2))
    if mse == 0.0:
        return float("inf")
    return float(10.0 * np.log10(peak * peak / mse))


def relmse(output: np.ndarray, reference: np.ndarray, eps: float = RELMSE_EPS) -> float:
    """Relative MSE, ``mean((x - r)^2 / (r^2 + eps))`` (Rousselle et al.; eps = 0.01)."""
    ref = np.asarray(reference, np.float64)
    return float(np.mean(_diff(output, reference) ** 2 / (ref * ref + eps)))


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="rmse",
            version="1.0",
            factory=lambda: rmse,
            higher_is_better=False,
            description="root-mean-square error, linear radiance",
        ),
        MetricSpec(
            name="psnr",
            version="1.0",
            factory=lambda: psnr,
            higher_is_better=True,
            description="PSNR in dB, peak 1.0, linear radiance",
        ),
        MetricSpec(
            name="relmse",
            version="1.0",
            factory=lambda: relmse,
            higher_is_better=False,
            description="relative MSE (x-r)^2/(r^2+0.01)",
        ),
    ]
