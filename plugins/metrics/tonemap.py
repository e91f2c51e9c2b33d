"""The tone mapping shared by the perceptual metrics (SSIM, FLIP) on HDR images."""

from __future__ import annotations

import numpy as np


def to_display(image: np.ndarray) -> np.ndarray:
    """Clamp linear radiance to [0, 1] and apply the sRGB transfer curve; float64.

    The source paper scores tone-mapped 8-bit-range images; this is the simplest such mapping
    and is documented with the metrics.
    """
    x = np.clip(np.asarray(image, np.float64), 0.0, 1.0)
    return np.where(x <= 0.0031308, 12.92 * x, 1.055 * np.power(x, 1.0 / 2.4) - 0.055)
