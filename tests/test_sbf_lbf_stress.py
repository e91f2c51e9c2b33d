"""Numerical stress cases of issue 18 for ``sbf`` and ``lbf``: extreme colour, broken guides,
broken variance, degenerate shapes.

Bounds are properties, not golden numbers: both filters output convex combinations of the input
colours (non-negative weights), so wherever the input is finite the output must be finite and
lie within ``[min, max]`` of the input colour. A broken guide value (NaN, +-Inf, float32 max) in
one pixel must neither poison the image nor change pixels far from it. Negative colour (invalid
radiance) has a documented behaviour: it is filtered as given (both filters are linear in the
colour), so the same bounds hold.
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


# --- colour ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("peak", [1e3, 1e5, 1e8, float(F32_MAX)])
def test_fireflies(name, peak):
    frame = base_frame()
    color = frame["color"].copy()
    color[10, 20] = peak
    color[20, 8, 1] = peak
    out = run(name, frame.replace(color=color))
    assert_bounded(out, color)
    # the firefly stays local: far pixels keep (almost) their clean output
    clean = run(name, frame)
    far = np.ones(frame.shape, bool)
    for i, j in ((10, 20), (20, 8)):
        far[max(i - REACH[name], 0):i + REACH[name] + 1, max(j - REACH[name], 0):j + REACH[name] + 1] = False
    if far.any():
        np.testing.assert_allclose(out[far], clean[far], rtol=1e-5, atol=1e-6)


@pytest.mark.parametrize("name", FILTERS)
def test_negative_zero_and_huge_dynamic_range(name):
    frame = base_frame()
    color = frame["color"].copy()
    color[5:9, 10:14] = -0.0
    color[15, :] = 1e-30
    color[16, :] = 1e30
    assert_bounded(run(name, frame.replace(color=color)), color)


@pytest.mark.parametrize("name", FILTERS)
def test_denormal_colour(name):
    frame = base_frame()
    color = (frame["color"] * np.float32(1e-39)).astype(np.float32)  # subnormal float32
    assert_bounded(run(name, frame.replace(color=color)), color)


@pytest.mark.parametrize("name", FILTERS)
def test_all_zero_and_constant(name):
    frame = base_frame()
    zeros = np.zeros_like(frame["color"])
    assert not run(name, frame.replace(color=zeros)).any()
    const = np.full_like(frame["color"], 0.37)
    np.testing.assert_allclose(run(name, frame.replace(color=const)), 0.37, rtol=1e-6)


@pytest.mark.parametrize("name", FILTERS)
def test_negative_colour_is_filtered_as_given(name):
    """Invalid radiance: documented as filtered linearly (no clamp, no error)."""
    frame = base_frame()
    color = frame["color"] - np.float32(0.5)
    out = run(name, frame.replace(color=color))
    assert_bounded(out, color)
    assert out.min() < 0


# --- guide channels -------------------------------------------------------------------------------

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


@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("bad", ["nan", "+inf", "f32max"])
def test_whole_guide_channel_broken(name, bad):
    frame = base_frame()
    for channel in GUIDES[name]:
        guide = np.full_like(frame[channel], BAD_VALUES[bad])
        assert_bounded(run(name, frame.replace(**{channel: guide})), frame["color"])


@pytest.mark.parametrize("name", FILTERS)
def test_degenerate_guides(name):
    """Zero-length normals, albedo 0, depth 0 and depth inf everywhere."""
    frame = base_frame()
    cases = [{"normal": np.zeros_like(frame["normal"])}, {"albedo": np.zeros_like(frame["albedo"])},
             {"depth": np.zeros_like(frame["depth"])}, {"depth": np.full_like(frame["depth"], np.inf)}]
    for change in cases:
        assert_bounded(run(name, frame.replace(**change)), frame["color"])


# --- variance and samples -------------------------------------------------------------------------

@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("value", [np.nan, -1.0, 3e38, np.inf, F32_MAX])
def test_broken_variance(name, value):
    frame = base_frame()
    var = frame["variance"].copy()
    var[12:14, 18:22] = value
    var[3, 30, 1] = value
    assert_bounded(run(name, frame.replace(variance=var)), frame["color"])
    whole = np.full_like(var, value)
    assert_bounded(run(name, frame.replace(variance=whole)), frame["color"])


@pytest.mark.parametrize("name", FILTERS)
def test_zero_spp(name):
    frame = base_frame(spp=np.zeros((30, 34)))
    assert_bounded(run(name, frame), frame["color"])
    blind = frame.replace(variance=np.zeros_like(frame["variance"]))
    assert_bounded(run(name, blind), frame["color"])


# --- shapes ---------------------------------------------------------------------------------------

@pytest.mark.parametrize("name", FILTERS)
@pytest.mark.parametrize("shape", [(1, 1), (1, 17), (17, 1), (7, 5), (2, 3), (33, 1)])
def test_degenerate_shapes(name, shape):
    frame = base_frame(*shape)
    assert_bounded(run(name, frame), frame["color"])


# --- SBF's adaptive mode with a sampler -----------------------------------------------------------

@pytest.mark.parametrize("shape", [(1, 1), (7, 5), (1, 9)])
def test_sbf_adaptive_with_sampler_on_small_and_odd_frames(shape):
    from harness import CHANNELS, load_plugins

    reg = load_plugins()
    if "synthetic" not in reg.renderers or "synthetic-edges" not in reg.scenes:
        pytest.skip("the synthetic renderer / synthetic-edges scene is not registered")
    renderer = reg.renderers["synthetic"].factory()
    scene = reg.scenes["synthetic-edges"].factory()
    h, w = shape
    sampler = renderer.sampler(scene, 0, spp=1, seed=3, channels=frozenset(CHANNELS),
                               resolution=(w, h))
    before = sampler.samples_used
    f = SBFFilter(mode="adaptive", extra_spp=4.0, passes=2)
    out = f(sampler.frame, sampler=sampler)
    assert out.shape == (h, w, 3) and np.isfinite(out).all()
    assert sampler.samples_used - before == f.samples_added <= round(4.0 * h * w)
