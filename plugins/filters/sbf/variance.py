"""Which pixels' noise variance is unknown, and the estimate SBF then uses.

SURE needs the variance of each pixel mean. Renderers give it as the ``variance`` channel,
but a pixel with fewer than two samples has no sample variance (renderers report 0). There,
SBF estimates the per-sample variance from a feature-weighted 7x7 neighbourhood (kernel
``spatial_variance``) and divides it by the pixel's samples. The estimate includes the signal's
own variation inside a surface, so SURE built on it is no longer exactly unbiased: it leans
toward larger filters. With the ``variance_source="given"`` setting the channel is used as is.
A NaN or negative variance counts as 0 (:mod:`.layout` sanitises it), i.e. as unknown.
"""

from __future__ import annotations

import numpy as np

SOURCES = ("auto", "given", "spatial")


def unknown_variance(frame, var: np.ndarray, any_variance: bool, source: str) -> np.ndarray:
    """Pixels whose variance must be estimated, uint8 (H, W).

    Parameters
    ----------
    frame : Frame
        Its ``spp`` channel is used when present.
    var : ndarray (H, W, 3)
        The sanitised variance (:func:`.layout.pack`).
    any_variance : bool
        Whether any value of ``var`` is > 0.
    source : {"auto", "given", "spatial"}
        ``given``: none; ``spatial``: all; ``auto``: pixels whose variance is 0 in every
        channel and that have fewer than 2 samples; without an ``spp`` channel, every pixel when
        the whole variance is zero (a 1-spp frame), else none.
    """
    shape = frame.shape
    if source == "given":
        unknown = np.zeros(shape, bool)
    elif source == "spatial":
        unknown = np.ones(shape, bool)
    elif "spp" in frame:
        unknown = ~var.any(axis=-1) & (frame["spp"] < 2)
    else:
        unknown = np.full(shape, not any_variance)
    return np.ascontiguousarray(unknown, dtype=np.uint8)


def samples_per_pixel(frame) -> np.ndarray:
    """Samples of each pixel mean, at least 1, float32 (H, W) (1 without an ``spp`` channel)."""
    if "spp" not in frame:
        return np.ones(frame.shape, np.float32)
    return np.maximum(frame["spp"], 1).astype(np.float32)
