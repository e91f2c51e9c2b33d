"""Degraded modes (issue 32): the paper filters run on the guides a capture has, and say so.

Each filter runs on colour + albedo + normal only (what an OIDN user has), on a frame of the
``synthetic`` renderer: the output is finite and closer to the reference than the noisy input.
The ``guides`` column names the guides a job had and, for a degraded one, those it lacked.
"""

from __future__ import annotations

import numpy as np
import pytest

from harness import CHANNELS, load_plugins

CAPTURE = frozenset({"color", "albedo", "normal"})


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def frame_and_reference(registry):
    renderer = registry.renderers["synthetic"].factory()
    scene = registry.scenes["synthetic-edges"].factory()
    frame = renderer.render(scene, 0, spp=1, seed=3, channels=frozenset(CHANNELS), resolution=(64, 48))
    return frame, renderer.reference(scene, 0, resolution=(64, 48))


def _rmse(a, b):
    return float(np.sqrt(np.mean((np.asarray(a, np.float64) - b) ** 2)))


@pytest.mark.parametrize("name, guides", [
    ("eaw", CAPTURE), ("eaw", CAPTURE | {"depth"}), ("svgf", CAPTURE), ("svgf", CAPTURE | {"depth"}),
    ("sbf", CAPTURE), ("lbf", CAPTURE)])
def test_paper_filters_run_on_colour_albedo_normal(registry, frame_and_reference, name, guides):
    frame, reference = frame_and_reference
    spec = registry.filters[name]
    assert spec.requires <= guides, f"{name} requires {sorted(spec.requires - guides)} beyond a capture's guides"
    seen = frame.subset(guides & (spec.requires | spec.optional))
    filt = spec.factory(backend="cpu")
    filt.reset()
    out = filt(seen)
    assert out.shape == (*frame.shape, 3) and np.isfinite(out).all()
    noisy, filtered = _rmse(frame["color"], reference), _rmse(out, reference)
    assert filtered < 0.8 * noisy, (name, filtered, noisy)
    assert "; without " in spec.guides_used(seen.channels)


def test_svgf_without_motion_keeps_no_history(registry, frame_and_reference):
    frame, _ = frame_and_reference
    filt = registry.filters["svgf"].factory(backend="cpu")
    seen = frame.subset(CAPTURE)
    first = filt(seen)
    again = filt(seen.with_meta(camera_cut=False))
    np.testing.assert_array_equal(first, again)  # spatial only: the second call is the first again
    assert filt.history_length().max() <= 1.0


def test_guides_name_what_a_filter_had_and_lacked(registry):
    svgf = registry.filters["svgf"]
    assert svgf.guides_used(CHANNELS) == "albedo,depth,emission,indirect,motion,normal,object_id"
    assert svgf.guides_used(CAPTURE) == "albedo,normal; without depth,motion,object_id"
    assert registry.filters["oidn"].guides_used(CAPTURE) == "albedo,normal"
    assert registry.filters["passthrough"].guides_used(CAPTURE) == ""
