"""Metrics: known values on small cases and agreement with the reference libraries."""

import math

import numpy as np
import pytest
from skimage.metrics import structural_similarity

from harness.testing import registry


def metric(name):
    return registry().metrics[name].factory()


def test_pixel_errors_known_values():
    ref = np.zeros((2, 2, 3), np.float32)
    out = np.ones((2, 2, 3), np.float32)
    assert metric("rmse")(out, ref) == pytest.approx(1.0)
    assert metric("psnr")(out, ref) == pytest.approx(0.0)
    assert metric("psnr")(out * 0.1, ref) == pytest.approx(20.0)
    assert math.isinf(metric("psnr")(ref, ref))
    assert metric("relmse")(out, ref) == pytest.approx(1.0 / 0.01)
    half = np.full((2, 2, 3), 0.5, np.float32)
    assert metric("relmse")(out, half) == pytest.approx(0.25 / 0.26)


def test_ssim_matches_scikit_image_on_ldr_images():
    rng = np.random.default_rng(0)
    ref = rng.uniform(0, 1, (32, 32, 3)).astype(np.float32)
    out = np.clip(ref + rng.normal(0, 0.1, ref.shape), 0, 1).astype(np.float32)

    def encode(x):
        return np.where(x <= 0.0031308, 12.92 * x, 1.055 * x ** (1 / 2.4) - 0.055)

    expected = structural_similarity(
        encode(out.astype(np.float64)),
        encode(ref.astype(np.float64)),
        data_range=1.0,
        channel_axis=2,
        gaussian_weights=True,
        sigma=1.5,
        use_sample_covariance=False,
    )
    assert metric("ssim")(out, ref) == pytest.approx(expected, abs=1e-12)
    assert metric("ssim")(ref, ref) == pytest.approx(1.0)


def test_flip_is_zero_for_identical_and_grows_with_error():
    rng = np.random.default_rng(1)
    ref = rng.uniform(0, 1, (24, 24, 3)).astype(np.float32)
    small = np.clip(ref + 0.02, 0, 1).astype(np.float32)
    large = np.clip(ref + 0.3, 0, 1).astype(np.float32)
    flip = metric("flip")
    assert flip(ref, ref) == 0.0
    assert 0.0 < flip(small, ref) < flip(large, ref) <= 1.0


def test_temporal_error_known_values():
    te = metric("temporal_error")
    refs = [np.full((2, 2, 3), v, np.float32) for v in (0.0, 1.0, 2.0)]
    assert te(refs, refs) == 0.0
    # a constant offset does not flicker: zero temporal error even though every frame is wrong
    assert te([r + 0.5 for r in refs], refs) == pytest.approx(0.0)
    # an output that lags one frame behind: differences (0, 1) vs (1, 1) -> RMSE sqrt(1/2)
    lagging = [refs[0], refs[0], refs[1]]
    assert te(lagging, refs) == pytest.approx(math.sqrt(0.5))
    with pytest.raises(ValueError, match=">= 2 frames"):
        te(refs[:1], refs[:1])
