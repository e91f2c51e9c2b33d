"""Bias-corrected errors: against a 64-spp reference they agree with the error against the truth.

A filter's RMSE against a noisy reference overstates its RMSE against the true image by the
reference's variance (``E[(x - r)^2] = (x - mu)^2 + var(r)``). The squared-error metrics
subtract the reference's stored variance of the mean; these tests check that the corrected
value from a 64-spp reference agrees with the value against a far better reference (the
analytic image of the synthetic renderer; a 4096-spp path-traced reference of the Cornell box)
within a stated tolerance, where the uncorrected value does not.
"""

import numpy as np
import pytest

from harness import load_plugins
from harness.cache import Cache
from harness.jobs import emitter_mask
from harness.references import reference_record
from harness.renders import RenderStore

FILTERS = ("gaussian", "eaw", "svgf")
#: agreement asked of the corrected RMSE (relative to the RMSE against the better reference)
TOLERANCE = 0.08


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def outputs(registry, store, scene, renderer, frames, channels):
    """Each filter's output on the last of ``frames`` 1-spp frames (temporal filters see them all)."""
    inputs = [store.frame(scene, renderer, t, spp=1, seed=7, channels=channels) for t in frames]
    out = {}
    for name in FILTERS:
        spec = registry.filters[name]
        filt = spec.factory(backend="cpu")
        filt.reset()
        for frame in inputs:
            result = filt(frame.subset((spec.requires | spec.optional) & frame.channels))
        out[name] = result
    return out, inputs[-1]


def compare(registry, metric, outs, noisy, better, mask=None):
    """(corrected, uncorrected, against the better reference) per filter."""
    fn = registry.metrics[metric].factory()
    table = {}
    for name, out in outs.items():
        truth_side = fn(out, better.image, reference_variance=better.variance, mask=mask)
        table[name] = (fn(out, noisy.image, reference_variance=noisy.variance, mask=mask),
                       fn(out, noisy.image, reference_variance=None, mask=mask), truth_side)
    return table


def check(table, floor):
    for name, (corrected, uncorrected, truth) in table.items():
        assert corrected == pytest.approx(truth, rel=TOLERANCE), (name, corrected, truth)
        if floor > 0.5 * truth:  # the reference's noise is not negligible against this filter's error
            assert uncorrected != pytest.approx(truth, rel=TOLERANCE), (name, uncorrected, truth)
            assert uncorrected > truth


@pytest.mark.slow
def test_corrected_rmse_from_64_spp_matches_the_analytic_truth_synthetic(registry):
    store = RenderStore(registry, Cache(enabled=False), resolution=(96, 64))
    scene = "synthetic-moving"
    channels = set().union(*(registry.filters[f].requires | registry.filters[f].optional for f in FILTERS))
    channels &= registry.renderers["synthetic"].provides
    outs, last = outputs(registry, store, scene, "synthetic", range(4), channels)
    noisy = reference_record(store, scene, "synthetic", 3, spp=64)
    truth = reference_record(store, scene, "synthetic", 3, spp=0)
    for metric in ("rmse", "display_rmse"):
        table = compare(registry, metric, outs, noisy, truth)
        floor = float(np.sqrt(noisy.variance.mean()))
        check(table, floor if metric == "rmse" else 0.0)
        assert any(uncorrected > (1 + 2 * TOLERANCE) * exact for _, uncorrected, exact in table.values())


@pytest.mark.slow
def test_corrected_rmse_from_64_spp_matches_a_4096_spp_reference_cornell(registry):
    """Path-traced Cornell box at 32x32 (emitter pixels excluded as in a run)."""
    store = RenderStore(registry, Cache(enabled=False), resolution=(32, 32))
    channels = set().union(*(registry.filters[f].requires | registry.filters[f].optional for f in FILTERS))
    channels = (channels | {"emission"}) & registry.renderers["pathtracer"].provides
    outs, last = outputs(registry, store, "cornell", "pathtracer", range(2), channels)
    mask = emitter_mask(last)
    assert mask is not None and 0 < (~mask).sum() < mask.size
    noisy = reference_record(store, "cornell", "pathtracer", 1, spp=64)
    better = reference_record(store, "cornell", "pathtracer", 1, spp=4096, seed=77)
    floor = float(np.sqrt(noisy.variance[mask].mean()))
    table = compare(registry, "rmse", outs, noisy, better, mask)
    check(table, floor)
    assert any(uncorrected > (1 + 2 * TOLERANCE) * truth for _, uncorrected, truth in table.values())
