"""Guide locality of ``sbf`` and ``lbf``: a broken guide value changes only pixels near it.

The stress battery (:mod:`harness.stress.cases`, run for every filter by
``tests/test_conformance.py``) checks that broken guides give finite, bounded output; this file
checks what the battery cannot know for a filter in general: how far the damage reaches. Each
filter's reach is its footprint (SBF: the largest bank scale plus its SURE smoothing window;
LBF: the filter radius plus the feature window), and pixels farther away keep their clean output.
Negative colour is filtered as given (both filters are linear in the colour), so the same bounds
hold there.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness import Frame, FrameMeta
from plugins.filters.lbf.denoiser import LBFFilter
from plugins.filters.sbf import SBFFilter

FILTERS = {"sbf": SBFFilter, "lbf": LBFFilter}
#: channels each filter reads as guides
GUIDES = {"sbf": ("normal", "albedo", "depth"), "lbf": ("normal", "albedo", "position",
                                                      "visibility")}
#: pixels farther than this (Chebyshev) from a broken guide pixel must keep their clean output
REACH = {"sbf": 16 + 8, "lbf": 5 + 3 + 1}
F32_MAX = np.finfo(np.float32).max


def base_frame(h: int = 30, w: int = 34, seed: int = 0, **changes) -> Frame:
    """Two surfaces (a split in normal and albedo), a background corner, smooth noisy colour."""
    rng = np.random.default_rng(seed)
    x = np.arange(w)[None, :] * np.ones((h, 1))
    y = np.arange(h)[:, None] * np.ones((1, w))
    left = x < w // 2
    normal = np.where(left[..., None], [0.0, 0.0, 1.0], [0.0, 0.6, 0.8])
    albedo = np.where(left[..., None], [0.5, 0.5, 0.5], [0.2, 0.7, 0.3])
    depth = 2.0 + 0.01 * x + 0.02 * y
    position = np.stack([x * 0.1, y * 0.1, depth], axis=-1)
    clean = albedo * (0.5 + 0.5 * np.sin(x / 7.0)[..., None])
    variance = np.full((h, w, 3), 0.01)
    color = clean + rng.normal(0.0, 0.1, (h, w, 3))
    bg = (x < 4) & (y < 4)
    normal[bg] = 0.0
    albedo[bg] = 0.0
    depth[bg] = np.inf
    position[bg] = 0.0
    color[bg] = 0.7
    variance[bg] = 0.0
    channels = {
        "color": color, "variance": variance, "normal": normal, "albedo": albedo,
        "depth": depth, "position": position,
        "visibility": (~bg).astype(np.float64), "spp": np.full((h, w), 4),
    }
    channels.update(changes)
    arrays = {k: np.asarray(v, np.int32 if k == "spp" else np.float32) for k, v in channels.items()}
    return Frame(arrays, FrameMeta(scene="stress"))


def run(name: str, frame: Frame) -> np.ndarray:
    out = FILTERS[name]()(frame)
    assert out.shape == frame["color"].shape and out.dtype == np.float32
    return out


def assert_bounded(out: np.ndarray, color: np.ndarray):
    """Finite, and inside the input colour's range (a convex combination of inputs)."""
    assert np.isfinite(out).all(), f"{np.count_nonzero(~np.isfinite(out))} non-finite values"
    lo, hi = float(color.min()), float(color.max())
    out = out.astype(np.float64)
    span = max(abs(lo), abs(hi))
    tol = 1e-6 * span
    assert out.min() >= lo - tol and out.max() <= hi + tol, (out.min(), out.max(), lo, hi)


@pytest.mark.parametrize("name", FILTERS)
def test_negative_colour_is_filtered_as_given(name):
    """Invalid radiance: documented as filtered linearly (no clamp, no error)."""
    frame = base_frame()
    color = frame["color"] - np.float32(0.5)
    out = run(name, frame.replace(color=color))
    assert_bounded(out, color)
    assert out.min() < 0


BAD_VALUES = {"nan": np.nan, "+inf": np.inf, "-inf": -np.inf, "f32max": F32_MAX, "-f32max": -F32_MAX}


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("bad", BAD_VALUES)
def test_broken_guide_pixel_stays_local(name, bad):
    """One guide value NaN/+-Inf/float32 max: finite, bounded output, unchanged far away."""
    frame = base_frame()
    clean = run(name, frame)
    i, j = 15, 24
    far = np.ones(frame.shape, bool)
    far[max(i - REACH[name], 0):i + REACH[name] + 1, max(j - REACH[name], 0):j + REACH[name] + 1] = False
    for channel in GUIDES[name]:
        guide = frame[channel].copy()
        guide[i, j] = BAD_VALUES[bad]  # every component of the pixel
        out = run(name, frame.replace(**{channel: guide}))
        assert_bounded(out, frame["color"])
        # LBF normalises positions by the frame's foreground mean and spread, which the broken
        # pixel leaves (its position is not counted): far pixels move only by that
        atol = 1e-3 if (name, channel) == ("lbf", "position") else 1e-6
        if far.any():
            np.testing.assert_allclose(out[far], clean[far], rtol=1e-5, atol=atol,
                                       err_msg=f"{channel} = {bad}")
