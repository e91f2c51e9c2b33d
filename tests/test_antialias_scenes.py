"""The anti-aliasing scenes: declared for the ``antialias`` task, animated, and actually aliasing."""

from __future__ import annotations

import numpy as np
import pytest

from harness import load_plugins
from plugins.metrics.ssim import ssim

AA_SCENES = ("aa-railing", "aa-fence", "aa-garden")


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def raster(registry):
    return registry.get("renderer", "raster").factory(jitter=True)


def test_the_antialias_scenes_are_registered_for_the_task(registry):
    aa = sorted(name for name, spec in registry.scenes.items() if "antialias" in spec.tasks)
    assert aa == sorted(AA_SCENES)
    for name in AA_SCENES:
        spec = registry.get("scene", name)
        assert spec.tasks == {"antialias"} and spec.suite and spec.kind == "mesh"
        assert spec.frames >= 16
        assert {"thin", "texture", "specular", "dynamic", "disocclusion"} <= spec.tags
        w, h = spec.resolution
        assert w * h <= 320 * 180, "small default resolution: the default run stays short"


@pytest.mark.parametrize("name", AA_SCENES)
def test_scene_moves_camera_and_objects_and_has_glossy_and_textured_materials(registry, name):
    scene = registry.get("scene", name).factory()
    cam = scene.camera
    assert np.linalg.norm(cam.eye(scene.frame_count - 1) - cam.eye(0)) > 0.5
    moving = [o for o in scene.objects if o.transforms is not None
              and not np.allclose(o.transform(0), o.transform(scene.frame_count - 1))]
    assert moving, "at least one moving object"
    assert any(m.texture is not None for m in scene.materials)
    assert any(m.kind in ("plastic", "conductor") and m.roughness <= 0.15 for m in scene.materials)
    assert scene.sun is not None and scene.environment is not None


@pytest.mark.parametrize("name", AA_SCENES)
def test_one_sample_per_pixel_aliases_against_the_ssaa_reference(registry, raster, name):
    scene = registry.get("scene", name).factory()
    size = (160, 90)
    frame = raster.render(scene, 4, resolution=size)
    ref = raster.reference(scene, 4, resolution=size)
    score = ssim(frame["color"], ref)
    assert score < 0.93, f"{name}: the aliased frame is too close to SSAA (SSIM {score:.3f})"
    # most of the picture is shaded surface, and the reference's values are finite and positive
    assert np.isfinite(ref).all() and (ref >= 0).all()


@pytest.mark.parametrize("name", AA_SCENES)
def test_sequences_have_disocclusions(registry, raster, name):
    scene = registry.get("scene", name).factory()
    w, h = 96, 54
    channels = {"object_id", "motion"}
    disoccluded = 0
    prev = raster.render(scene, 9, channels=channels, resolution=(w, h))
    for t in (10, 11):
        cur = raster.render(scene, t, channels=channels, resolution=(w, h))
        jj, ii = np.meshgrid(np.arange(w), np.arange(h))
        x = np.rint(jj + cur["motion"][..., 0]).astype(int)
        y = np.rint(ii + cur["motion"][..., 1]).astype(int)
        inside = (x >= 0) & (x < w) & (y >= 0) & (y < h) & (cur["object_id"] >= 0)
        before = prev["object_id"][np.clip(y, 0, h - 1), np.clip(x, 0, w - 1)]
        disoccluded += int((inside & (before != cur["object_id"])).sum())
        prev = cur
    assert disoccluded > 10, f"{name}: no disoccluded pixels in frames 10-11"
