"""LBF's features: their names, the inputs read from a frame, the frame's position scale.

Primary features (compared by the filter): world position normalised by the frame's scene
scale (3), shading normal (3), albedo (3) and direct-light visibility (1). When the frame has no
``visibility`` channel the stand-in is the geometry-coverage mask (1 on surfaces, 0 on the
background), which carries the silhouette but no shadow information.

Secondary features (the network's 36 inputs, :data:`FEATURE_NAMES`), per group (colour,
position, normal, albedo, visibility): standard deviation over 7x7 and 3x3 blocks, mean
absolute deviation in 3x3, gradient magnitude, and a robust noise estimate (median over 3x3 of
the absolute Haar HH coefficient / 0.6745); 7x7 means and pixel values of colour, albedo and
visibility; the colour's deviation over samples, its 7x7 mean and its ratio to the 7x7 block
deviation; 1/spp; the 7x7 foreground fraction. The colour signal is ``log1p(color)`` so that
fireflies do not dominate the statistics; its deviation over samples is the delta-method
``sqrt(mean_ch variance / (1 + color)^2)``.

"Over samples" statistics use what a frame carries: the ``variance`` channel for the colour.
A frame whose ``variance`` is zero everywhere carries no variance (a 1-spp path tracer cannot
estimate it); then the variance of the pixel mean is estimated spatially, as the colour's
variance over the clamped 5x5 window (:func:`.kernels.variance_estimate_px`), and that estimate
stands in for the channel everywhere (features, filter).
The G-buffer comes from a pinhole camera with one primary hit per pixel, so the deviation of the
geometric features over samples is zero; those features are not inputs, and the filter's
feature denominators ``max(1e-4, var_i(f))`` equal the floor 1e-4 (Kalantari et al. 2015).
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

from harness import pinhole_position

from . import kernels as K

GROUPS = ("color", "position", "normal", "albedo", "visibility")

#: names of the 36 network inputs, in order (stored in the weights file and checked on load)
FEATURE_NAMES = tuple(
    [f"std7_{g}" for g in GROUPS]
    + [f"std3_{g}" for g in GROUPS]
    + [f"mad3_{g}" for g in GROUPS]
    + [f"grad_{g}" for g in GROUPS]
    + [f"noise_{g}" for g in GROUPS]
    + ["mean7_color", "mean7_albedo", "mean7_visibility"]
    + ["pixel_color", "pixel_albedo", "pixel_visibility"]
    + ["sample_std_color", "mean7_sample_std_color", "sample_to_block_std_color"]
    + ["inv_spp", "mean7_foreground"]
)
assert len(FEATURE_NAMES) == K.N_FEATURES

#: the floor of the filter's feature denominators max(floor, var_i(f))
FEATURE_VAR_FLOOR = 1e-4

@dataclass
class Inputs:
    """The frame channels LBF reads, as contiguous arrays (see :func:`gather_inputs`)."""

    color: np.ndarray
    variance: np.ndarray
    position: np.ndarray
    normal: np.ndarray
    albedo: np.ndarray
    vis: np.ndarray
    has_vis: bool
    spp: np.ndarray
    has_spp: bool
    estimate_variance: bool

    @property
    def shape(self) -> tuple[int, int]:
        return self.color.shape[:2]


def gather_inputs(frame, visibility: str = "auto") -> Inputs:
    """Collect the channels of ``frame`` that LBF reads.

    Parameters
    ----------
    frame : harness.Frame
        Needs ``color``, ``normal``, ``albedo``; ``variance``, ``position``, ``visibility`` and
        ``spp`` are used when present (without ``variance`` it is estimated from the image,
        without ``position`` a pinhole stand-in from ``depth`` or unit depth is used).
    visibility : {"auto", "standin"}
        ``auto`` uses the ``visibility`` channel when the frame has one, else the stand-in (the
        foreground mask); ``standin`` always uses the stand-in.

    Returns
    -------
    Inputs
    """
    if visibility not in ("auto", "standin"):
        raise ValueError(f"lbf: visibility must be 'auto' or 'standin', got {visibility!r}")

    def arr(name, dtype=np.float32):
        return _readonly(np.ascontiguousarray(frame[name], dtype=dtype))

    has_vis = visibility == "auto" and "visibility" in frame
    has_spp = "spp" in frame
    # degraded modes: no variance channel is a zero one (estimated spatially, below); no position
    # a pinhole stand-in from depth, or from the pixel grid at unit depth
    variance = arr("variance") if "variance" in frame else _readonly(np.zeros((*frame.shape, 3), np.float32))
    position = arr("position") if "position" in frame else _readonly(
        pinhole_position(frame.shape, frame["depth"] if "depth" in frame else None))
    return Inputs(
        color=arr("color"),
        variance=variance,
        position=position,
        normal=arr("normal"),
        albedo=arr("albedo"),
        vis=arr("visibility") if has_vis else _readonly(np.zeros((1, 1), np.float32)),
        has_vis=has_vis,
        spp=arr("spp", np.int32) if has_spp else _readonly(np.ones((1, 1), np.int32)),
        has_spp=has_spp,
        estimate_variance=not bool(np.any(variance > 0)),
    )


def _readonly(a: np.ndarray) -> np.ndarray:
    """A read-only view: frames hold read-only arrays, and one array type means one compilation."""
    view = a.view()
    view.flags.writeable = False
    return view


@njit(cache=True)
def _counts(position, normal, i, j):
    """Foreground (non-zero normal) with a position of modest finite size: enters the scale."""
    if normal[i, j, 0] == 0.0 and normal[i, j, 1] == 0.0 and normal[i, j, 2] == 0.0:
        return False
    for ch in range(3):
        if not abs(position[i, j, ch]) <= 1e18:  # NaN, +-Inf and absurd values
            return False
    return True


@njit(parallel=True, cache=True)
def _position_rows(position, normal, rows):
    h, w, _ = position.shape
    for i in prange(h):
        n = 0.0
        s0 = 0.0
        s1 = 0.0
        s2 = 0.0
        for j in range(w):
            if _counts(position, normal, i, j):
                n += 1.0
                s0 += position[i, j, 0]
                s1 += position[i, j, 1]
                s2 += position[i, j, 2]
        rows[i, 0] = n
        rows[i, 1] = s0
        rows[i, 2] = s1
        rows[i, 3] = s2


@njit(parallel=True, cache=True)
def _position_spread_rows(position, normal, mu, rows):
    h, w, _ = position.shape
    for i in prange(h):
        s = 0.0
        for j in range(w):
            if _counts(position, normal, i, j):
                for ch in range(3):
                    d = position[i, j, ch] - mu[ch]
                    s += d * d
        rows[i] = s


def position_stats(position: np.ndarray, normal: np.ndarray) -> tuple[np.ndarray, float]:
    """Mean and scale of the foreground positions of a frame.

    Parameters
    ----------
    position, normal : ndarray (H, W, 3) float32
        Foreground pixels are those with a non-zero normal.

    Returns
    -------
    mu : ndarray (3,) float64
        Mean foreground position (zero without foreground). Positions that are not finite
        (or beyond 1e18) are left out of the mean and scale.
    scale : float
        Root-mean-square distance of foreground positions from ``mu`` (1 when that is zero or
        there is no foreground). Positions are compared as ``(p - mu) / scale``.
    """
    h = position.shape[0]
    rows = np.zeros((h, 4))
    _position_rows(position, normal, rows)
    tot = rows.sum(axis=0)
    if tot[0] <= 0:
        return np.zeros(3), 1.0
    mu = tot[1:] / tot[0]
    spread = np.zeros(h)
    _position_spread_rows(position, normal, mu, spread)
    scale = float(np.sqrt(spread.sum() / tot[0]))
    if not np.isfinite(scale) or scale <= 1e-12:
        scale = 1.0
    return mu, scale
