"""``ssim``: scikit-image's structural similarity on tone-mapped images.

Images are clamped to [0, 1] and sRGB-encoded (:func:`harness.encode_srgb`), then
``skimage.metrics.structural_similarity`` runs with ``data_range=1``, ``channel_axis=2`` and
Wang et al.'s Gaussian window (``gaussian_weights=True, sigma=1.5,
use_sample_covariance=False``, hence an 11x11 window). Images smaller than 11x11 use the
largest odd uniform window that fits; below 3x3, ``1 - MSE`` of the encoded images.

With a ``mask`` (the harness leaves emitter pixels out by default) the score is the mean of
the SSIM map over the scored pixels (NaN when none is left); windows still see every pixel.
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, encode_srgb, hookimpl


def ssim(output: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean SSIM in [-1, 1] (1 = identical), over the pixels of ``mask`` when given."""
    from skimage.metrics import structural_similarity

    a, b = encode_srgb(output), encode_srgb(reference)
    side = min(a.shape[0], a.shape[1])
    if side >= 11:  # room for the 11x11 Gaussian window (sigma 1.5, truncated at 3.5 sigma)
        mean, full = structural_similarity(a, b, data_range=1.0, channel_axis=2, gaussian_weights=True, sigma=1.5,
                                           use_sample_covariance=False, full=True)
    elif side >= 3:  # small images: the largest odd uniform window that fits
        win = side if side % 2 else side - 1
        mean, full = structural_similarity(a, b, data_range=1.0, channel_axis=2, win_size=win,
                                           use_sample_covariance=False, full=True)
    else:
        mean, full = 1.0 - np.mean((a - b) ** 2), 1.0 - (a - b) ** 2
    if mask is None:
        return float(mean)
    scored = np.asarray(full, np.float64)[np.asarray(mask, bool)]
    return float(scored.mean()) if scored.size else float("nan")


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="ssim",
            version="1.1",
            factory=lambda: ssim,
            higher_is_better=True,
            description="scikit-image SSIM on clamped sRGB-encoded images, emitters excluded",
            accepts={"mask"},
        )
    ]
