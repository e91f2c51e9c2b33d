"""The ``mitsuba`` and ``pathtracer`` renderers agree on the same scene file.

The diffuse box of ``tests/test_mitsuba_renderer.py`` (walls, a cube, a panel, an area lamp), loaded
once by the Mitsuba scene plugin and rendered by both: the first hits are the same surfaces at the
same points (the G-buffers are equal where both see the same object), and the converged mean
radiance over each object's pixels agrees within 2% (each mean's standard error, from the
variance channels, is checked to be small enough for 2% to mean something).
"""

from __future__ import annotations

import numpy as np
import pytest

pytest.importorskip("mitsuba")

from plugins.renderers.mitsuba import MitsubaRenderer  # noqa: E402
from plugins.renderers.pathtracer import PathTracer  # noqa: E402
from tests import test_mitsuba_renderer as base  # noqa: E402

RESOLUTION = (48, 36)
SPP = 512
GBUFFER = frozenset({"position", "normal", "albedo", "depth", "object_id", "emission"})


@pytest.fixture(scope="module")
def frames(tmp_path_factory):
    scene = base.box_scene(tmp_path_factory.mktemp("agreement"), resolution=RESOLUTION)
    mitsuba = MitsubaRenderer()
    if mitsuba.variant == "scalar_rgb":
        pytest.skip("no JIT variant works here (see docs/mitsuba.md: libLLVM)")
    channels = GBUFFER | {"variance"}
    return scene, (mitsuba.render(scene, 0, spp=SPP, seed=1, channels=channels),
                   PathTracer().render(scene, 0, spp=SPP, seed=1, channels=channels))


@pytest.mark.slow
def test_gbuffers_equal_on_shared_first_hits(frames):
    _, (ours, theirs) = frames
    assert ((ours["object_id"] >= 0) == (theirs["object_id"] >= 0)).mean() > 0.98
    shared = (ours["object_id"] == theirs["object_id"]) & (ours["object_id"] >= 0)
    assert shared.sum() > 0.97 * (theirs["object_id"] >= 0).sum()  # rays along edges may pick either face
    for name in GBUFFER - {"object_id"}:
        np.testing.assert_allclose(ours[name][shared], theirs[name][shared], rtol=1e-4, atol=1e-4, err_msg=name)


@pytest.mark.slow
def test_converged_region_means_agree_within_2_percent(frames):
    scene, (ours, theirs) = frames
    shared = (ours["object_id"] == theirs["object_id"]) & (ours["object_id"] >= 0)
    checked = 0
    for k, obj in enumerate(scene.objects):
        region = shared & (ours["object_id"] == k)
        if region.sum() < 20:
            continue
        means, errors = [], []
        for frame in (ours, theirs):
            pixels = frame["color"][region].astype(np.float64)
            means.append(pixels.mean(0))
            errors.append(np.sqrt(frame["variance"][region].astype(np.float64).sum(0)) / region.sum())
        assert (np.hypot(*errors) < 0.006 * means[1] + 1e-4).all(), (obj.name, errors)  # converged enough
        np.testing.assert_allclose(means[0], means[1], rtol=0.02, err_msg=obj.name)
        checked += 1
    assert checked >= 6
