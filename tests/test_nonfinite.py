"""The non-finite policy covers every channel, and repaired values are safe for every filter."""

import numpy as np
import pytest

from harness import NonFiniteError, load_plugins
from harness.nonfinite import MOTION_MAX, SAFE_MAX, apply_nonfinite_policy
from harness.testing import make_frame

BIG = np.finfo(np.float32).max


@pytest.mark.parametrize("channel", ["normal", "position", "albedo", "motion", "variance", "direct", "visibility"])
def test_raise_covers_every_guide_channel(channel):
    frame = make_frame(4, 5)
    bad = frame[channel].copy()
    bad.reshape(-1)[3] = np.nan
    with pytest.raises(NonFiniteError, match=rf"\({channel} 1\)"):
        apply_nonfinite_policy(frame.replace(**{channel: bad}), "raise")


def test_repair_gives_documented_safe_values():
    frame = make_frame(4, 5)
    color, normal, depth = frame["color"].copy(), frame["normal"].copy(), frame["depth"].copy()
    color[0, 0] = (np.inf, -np.inf, np.nan)
    color[0, 1] = (BIG, -BIG, 1.0)
    normal[1, 1] = (np.inf, 0.0, 0.0)
    normal[1, 2] = (BIG, 0.0, BIG)
    depth[2, 2] = np.nan
    depth[2, 3] = -1.0
    motion = frame["motion"].copy()
    motion[3, 3] = (np.nan, 1e9)
    ids = frame["object_id"].copy()
    ids[3, 4] = -7
    spp = frame["spp"].copy()
    spp[0, 4] = -2
    bad = frame.replace(color=color, normal=normal, depth=depth, motion=motion, object_id=ids, spp=spp)
    fixed, count = apply_nonfinite_policy(bad, "repair")
    assert fixed["color"][0, 0].tolist() == [0, 0, 0]
    assert fixed["color"][0, 1].tolist() == [SAFE_MAX, -SAFE_MAX, 1.0]
    # a broken normal makes its pixel background; a huge finite one is renormalised
    assert fixed["normal"][1, 1].tolist() == [0, 0, 0] and fixed["object_id"][1, 1] == -1
    assert np.isposinf(fixed["depth"][1, 1]) and fixed["albedo"][1, 1].tolist() == [0, 0, 0]
    np.testing.assert_allclose(fixed["normal"][1, 2], [2**-0.5, 0, 2**-0.5], rtol=1e-6)
    assert np.isposinf(fixed["depth"][2, 2]) and np.isposinf(fixed["depth"][2, 3])
    assert fixed["motion"][3, 3].tolist() == [0.0, MOTION_MAX]
    assert fixed["object_id"][3, 4] == -1 and fixed["spp"][0, 4] == 0
    assert count == 3 + 2 + 1 + 1 + 2 + 2 + 1 + 1
    for name in fixed.channels:
        assert np.isfinite(fixed[name]).all() or name == "depth"


@pytest.mark.parametrize("name", ["eaw", "svgf", "sbf", "lbf", "opencv_jbf", "gaussian", "passthrough"])
def test_repaired_guides_never_crash_a_builtin_filter(name):
    """The repaired values of the worst inputs (Inf, NaN, float32 max) are safe for the built-ins."""
    reg = load_plugins()
    if name not in reg.filters:
        pytest.skip(f"{name} is not installed")
    spec = reg.filters[name]
    frame = make_frame(9, 11, spec.requires | spec.optional)
    arrays = {n: frame[n].copy() for n in frame.channels}
    for n, a in arrays.items():
        if a.dtype.kind == "f" and n != "depth":
            flat = a.reshape(-1)
            flat[0], flat[7], flat[13] = np.inf, np.nan, BIG
    fixed, count = apply_nonfinite_policy(frame.replace(**arrays), "repair")
    assert count > 0
    out = spec.factory(backend="cpu", **dict(spec.params))(fixed)
    assert out.shape == (9, 11, 3) and np.isfinite(out).all()
