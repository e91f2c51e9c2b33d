"""Metric inputs: the reference's variance (bias correction), the emitter mask, display-referred errors."""

import math

import numpy as np
import pytest

from harness import Frame, FrameMeta, MetricSpec, display_variance, encode_srgb
from harness.jobs import GroupInputs, emitter_mask, run_job
from harness.plan import Job, MetricPlan
from harness.testing import registry


def metric(name):
    return registry().metrics[name].factory()


def test_squared_errors_subtract_the_reference_variance():
    ref = np.full((4, 4, 3), 0.5, np.float32)
    out = ref + 0.2
    var = np.full_like(ref, 0.01)
    assert metric("rmse")(out, ref) == pytest.approx(0.2)
    assert metric("rmse")(out, ref, reference_variance=var) == pytest.approx(math.sqrt(0.04 - 0.01))
    assert metric("psnr")(out, ref, reference_variance=var) == pytest.approx(10 * math.log10(1 / 0.03))
    assert metric("relmse")(out, ref, reference_variance=var) == pytest.approx(0.03 / 0.26)
    # closer to the truth than the reference can resolve: RMSE 0, PSNR capped, relMSE unbiased (negative)
    assert metric("rmse")(ref, ref, reference_variance=var) == 0.0
    assert metric("psnr")(ref, ref, reference_variance=var) == pytest.approx(100.0)
    assert metric("relmse")(ref, ref, reference_variance=var) == pytest.approx(-0.01 / 0.26)
    assert math.isinf(metric("psnr")(ref, ref))


def test_bias_correction_recovers_a_known_error_from_noisy_references():
    """Truth ``mu``, an output with a known error field, 40 references ``mu + N(0, v)`` with known,
    uneven ``v``: the corrected MSE is unbiased for the true MSE (mean within 3 standard errors,
    every draw within 10%: its standard deviation is about 2.5% here), the uncorrected one
    overstates it by ``mean(v)``."""
    rng = np.random.default_rng(3)
    mu = rng.uniform(0.2, 1.0, (64, 64, 3))
    out = (mu + rng.normal(0.0, 0.05, mu.shape)).astype(np.float32)
    true_mse = float(np.mean((out - mu) ** 2))
    var = rng.uniform(0.0, 2.0 * true_mse, mu.shape).astype(np.float32)  # as noisy as the error itself
    corrected, uncorrected = [], []
    for _ in range(40):
        ref = (mu + rng.normal(0.0, 1.0, mu.shape) * np.sqrt(var)).astype(np.float32)
        corrected.append(metric("rmse")(out, ref, reference_variance=var) ** 2)
        uncorrected.append(metric("rmse")(out, ref) ** 2)
    corrected, uncorrected = np.array(corrected), np.array(uncorrected)
    assert abs(corrected.mean() - true_mse) < 3 * corrected.std(ddof=1) / math.sqrt(len(corrected))
    assert np.all(np.abs(corrected / true_mse - 1) < 0.10)
    assert uncorrected.mean() == pytest.approx(true_mse + var.mean(), rel=0.02)
    assert np.all(uncorrected > 1.5 * true_mse)


def test_display_metrics_use_the_display_mapping_and_its_variance():
    rng = np.random.default_rng(0)
    ref = rng.uniform(0.0, 2.0, (8, 8, 3)).astype(np.float32)  # some pixels above display white
    out = (ref * 1.1).astype(np.float32)
    expected = np.sqrt(np.mean((encode_srgb(out) - encode_srgb(ref)) ** 2))
    assert metric("display_rmse")(out, ref) == pytest.approx(expected)
    var = np.full_like(ref, 1e-4)
    dvar = display_variance(ref, var)
    assert (dvar[ref > 1.0] == 0).all() and (dvar[ref < 1.0] > 0).all()  # clamped pixels have no display noise
    corrected = np.sqrt(np.mean((encode_srgb(out) - encode_srgb(ref)) ** 2 - dvar))
    assert metric("display_rmse")(out, ref, reference_variance=var) == pytest.approx(corrected)
    assert metric("display_psnr")(out, ref) == pytest.approx(-20 * math.log10(expected))


def test_display_variance_is_the_delta_method():
    """For a small noise, the variance of the encoded reference matches encode'(r)^2 var."""
    rng = np.random.default_rng(1)
    level = np.array([0.002, 0.05, 0.3, 0.8])
    sigma = 1e-4
    samples = encode_srgb(level[None, :] + rng.normal(0, sigma, (200_000, 4)))
    np.testing.assert_allclose(samples.var(axis=0), display_variance(level, np.full(4, sigma ** 2)), rtol=0.05)


@pytest.mark.parametrize("name", ["rmse", "psnr", "relmse", "display_rmse", "display_psnr", "ssim", "flip"])
def test_masked_pixels_do_not_count(name):
    rng = np.random.default_rng(2)
    ref = rng.uniform(0, 1, (24, 72, 3)).astype(np.float32)
    out = np.clip(ref + rng.normal(0, 0.05, ref.shape), 0, 1).astype(np.float32)
    mask = np.ones((24, 72), bool)
    mask[:, 12:] = False
    wild = out.copy()
    wild[:, 48:] = 40.0  # an emitter region the filter got badly wrong, beyond SSIM's and FLIP's windows
    m = metric(name)
    assert m(wild, ref, mask=mask) == pytest.approx(m(out, ref, mask=mask), rel=1e-6)
    assert m(wild, ref) != pytest.approx(m(out, ref), rel=1e-3)
    assert math.isnan(m(out, ref, mask=np.zeros((24, 72), bool)))


def test_temporal_error_is_corrected_and_masked():
    refs = [np.full((4, 4, 3), v, np.float32) for v in (0.2, 0.4)]
    outs = [r + 0.1 * k for k, r in enumerate(refs)]  # the output's change is 0.1 too large
    te = metric("temporal_error")
    var = [np.full((4, 4, 3), 0.001, np.float32)] * 2
    assert te(outs, refs) == pytest.approx(0.1)
    assert te(outs, refs, reference_variance=var) == pytest.approx(math.sqrt(0.01 - 0.002))
    mask = np.ones((4, 4), bool)
    mask[0, 0] = False
    bad = [o.copy() for o in outs]
    bad[1][0, 0] = 9.0
    assert te(bad, refs, mask=[mask, mask]) == pytest.approx(0.1)


def test_metric_spec_declares_only_known_inputs():
    with pytest.raises(ValueError, match="accepts unknown input"):
        MetricSpec(name="m", version="1", factory=lambda: None, accepts={"reference"})
    spec = MetricSpec(name="m", version="1", factory=lambda: None, accepts="mask")
    assert spec.accepts == frozenset({"mask"}) and spec.declarations()["accepts"] == ["mask"]


def test_emitter_mask_from_the_emission_channel():
    emission = np.zeros((3, 4, 3), np.float32)
    emission[1, 2] = (17.0, 12.0, 4.0)
    frame = Frame({"color": np.zeros((3, 4, 3), np.float32), "emission": emission}, FrameMeta(index=0))
    mask = emitter_mask(frame)
    assert mask.tolist() == [[True, False, False, False], [True, False, False, False], [True, False, False, False]]
    corner = np.zeros((3, 4, 3), np.float32)
    corner[0, 0, 1] = 1e-6
    frame = Frame({"color": np.zeros((3, 4, 3), np.float32), "emission": corner}, FrameMeta(index=0))
    assert emitter_mask(frame).sum() == 12 - 4
    assert emitter_mask(Frame({"color": np.zeros((3, 4, 3), np.float32)}, FrameMeta(index=0))) is None


def test_jobs_pass_variance_and_mask_only_to_metrics_that_accept_them():
    """A metric without ``accepts`` is called as before; the row carries the noise floors."""
    reg = registry()
    h, w = 6, 8
    emission = np.zeros((h, w, 3), np.float32)
    emission[0, :] = 5.0
    color = np.full((h, w, 3), 0.5, np.float32)
    color[0, :] = 7.0  # the emitter, wrong by 2
    frame = Frame({"color": color, "emission": emission}, FrameMeta(index=0))
    ref = np.full((h, w, 3), 0.4, np.float32)
    ref[0, :] = 5.0
    var = np.full((h, w, 3), 0.0025, np.float32)
    inputs = GroupInputs([frame], [ref], ["x"], [0], reference_variances=[var], reference_quality=[(64, 0.1)])
    job = Job("denoise", "s", "synthetic", "passthrough", "cpu", "{}", "", 1, 0, width=w, height=h, repeats=1,
              reference_spp=64)
    plan = MetricPlan(frame=["rmse", "ssim"])
    row = run_job(reg, job, inputs, plan).rows[0]
    assert row.metrics["rmse"] == pytest.approx(math.sqrt(0.01 - 0.0025))
    assert row.reference_noise == pytest.approx(0.05) and row.reference_spp == 64 and row.reference_error == 0.1
    assert row.reference_noise_display == pytest.approx(float(np.sqrt(display_variance(ref, var)[1:].mean())))
    included = run_job(reg, Job(**{**job.__dict__, "emitters": "include"}), inputs, plan).rows[0]
    assert included.metrics["rmse"] > row.metrics["rmse"]
