"""Documented behaviour of the built-in filters on invalid radiance and extreme constant images.

The stress battery (``color-negative``, ``color-flat-huge``) checks only that such frames give
finite, bounded output or a clear refusal; here each filter's documented choice is pinned:
``eaw``, ``svgf`` and ``opencv_jbf`` filter signed values (a negative constant stays that
constant), ``oidn`` clamps negative radiance to 0 and counts the repaired values, and keeps a
constant image at its own level from 1e-30 to 3e38. (``sbf`` and ``lbf``: tests/test_guide_locality.py.)
"""

from __future__ import annotations

import numpy as np
import pytest

from harness import load_plugins
from harness.testing.frames import make_frame

H, W = 20, 24


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def _frame(registry, name, level):
    if name not in registry.filters:
        pytest.skip(f"filter {name!r} is not registered (optional extra missing)")
    spec = registry.filters[name]
    frame = make_frame(H, W, spec.requires | spec.optional, seed=0, index=0)
    color = np.full((H, W, 3), level, np.float32)
    arrays = {"color": color}
    if "direct" in frame:
        arrays["direct"] = (color * np.float32(0.6)).astype(np.float32)
        arrays["indirect"] = (color - arrays["direct"]).astype(np.float32)
    if "emission" in frame:
        arrays["emission"] = np.zeros_like(color)
    return spec, frame.replace(**arrays)


@pytest.mark.parametrize("name", ["eaw", "svgf", "opencv_jbf"])
def test_signed_filters_keep_a_negative_constant(registry, name):
    spec, frame = _frame(registry, name, -0.25)
    np.testing.assert_allclose(spec.factory(backend="cpu")(frame), -0.25, rtol=1e-5)


def test_oidn_clamps_negative_radiance_and_counts_it(registry):
    spec, frame = _frame(registry, "oidn", -0.25)
    f = spec.factory(backend="cpu")
    out = f(frame)
    assert f.repaired == H * W * 3 and np.all(np.abs(out) < 0.05)


@pytest.mark.parametrize("level", [1e30, 1e-30, 3e38, 1.0])
def test_oidn_keeps_the_level_of_extreme_constants(registry, level):
    """A constant image comes back near its own level (it was clamped to 6e4, and a dim image
    came back at OIDN's floor of about 1e-3)."""
    spec, frame = _frame(registry, "oidn", level)
    out = spec.factory(backend="cpu")(frame).astype(np.float64)
    assert np.isfinite(out).all()
    assert abs(out.mean() / level - 1.0) < 0.05, out.mean()
