"""The ``fxaa`` filter: blends across stair-stepped edges, leaves flat areas alone."""

from __future__ import annotations

import numpy as np
import pytest

from harness import Frame, FrameMeta, load_plugins


@pytest.fixture(scope="module")
def fxaa():
    return load_plugins().get("filter", "fxaa")


def _edge(x, y):
    return np.where(y > 0.42 * x + 4.3, 0.9, 0.05)


def test_slanted_edge_gets_closer_to_the_box_filtered_image(fxaa):
    h, w = 40, 60
    jj, ii = np.meshgrid(np.arange(w, dtype=float), np.arange(h, dtype=float))
    aliased = np.repeat(_edge(jj, ii)[..., None], 3, axis=2).astype(np.float32)
    offsets = (np.arange(16) + 0.5) / 16 - 0.5
    ref = np.mean([_edge(jj + ox, ii + oy) for oy in offsets for ox in offsets], axis=0)
    ref = np.repeat(ref[..., None], 3, axis=2)
    out = fxaa.factory()(Frame({"color": aliased}, FrameMeta()))
    edge = np.abs(ref - aliased).max(axis=-1) > 0.05
    before = np.abs(aliased - ref)[edge].mean()
    after = np.abs(out - ref)[edge].mean()
    assert after < 0.75 * before, (before, after)
    # far from the edge nothing changes
    far = np.abs(ii - (0.42 * jj + 4.3)) > 3
    np.testing.assert_array_equal(out[far], aliased[far])


def test_parameters_are_validated(fxaa):
    with pytest.raises(ValueError, match="span_max"):
        fxaa.factory(span_max=0.0)
    with pytest.raises(TypeError, match="unknown"):
        fxaa.factory(subpix=0.75)
    assert fxaa.tasks == {"antialias"} and not fxaa.temporal
