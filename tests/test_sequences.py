"""The built-in sequences: fly-throughs of >= 32 frames with a moving object and its moving shadow."""

import numpy as np
import pytest

from harness import load_plugins


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def shadow_point(scene, obj, frame):
    """Where the sun's ray through the object's origin meets the floor (y = 0)."""
    centre = obj.transform(frame)[:3, 3] + np.array([0.0, 0.45, 0.0])
    sun = np.asarray(scene.sun.direction)
    return centre - sun * (centre[1] / sun[1])


@pytest.mark.parametrize("name, mover", [("atrium", "ball"), ("courtyard", "trolley")])
def test_fly_through_with_a_moving_object_and_its_shadow_in_view(registry, name, mover):
    spec = registry.get("scene", name)
    scene = spec.factory()
    assert spec.frames == scene.frame_count >= 32
    assert {"dynamic", "moving_shadow"} <= scene.tags and "static" not in scene.tags
    eyes = np.array([scene.camera.eye(t) for t in range(scene.frame_count)])
    assert np.linalg.norm(eyes[-1] - eyes[0]) > 3.0  # the camera travels
    assert (np.linalg.norm(np.diff(eyes, axis=0), axis=1) > 0).all()  # and moves on every frame
    obj = next(o for o in scene.objects if o.name == mover)
    w, h = scene.resolution
    shadows_in_view = 0
    for t in range(scene.frame_count):
        assert np.isfinite(obj.transform(t)).all()
        x, y = scene.camera.project(shadow_point(scene, obj, t)[None], t, w, h)[0]
        shadows_in_view += bool(0 <= x < w and 0 <= y < h)
    assert shadows_in_view >= scene.frame_count // 2, shadows_in_view
    travel = shadow_point(scene, obj, scene.frame_count - 1) - shadow_point(scene, obj, 0)
    assert np.linalg.norm(travel) > 2.0  # the shadow moves over the floor
    soup0, soup1 = scene.triangles(0), scene.triangles(scene.frame_count - 1)
    assert len(soup0.vertices) == len(soup1.vertices) and not np.allclose(soup0.vertices, soup1.vertices)


def test_cornell_moves_its_short_block_under_a_static_camera(registry):
    scene = registry.get("scene", "cornell").factory()
    assert scene.frame_count == 8 and "moving_shadow" in scene.tags
    assert np.array_equal(scene.camera.eye(0), scene.camera.eye(7))
    block = next(o for o in scene.objects if o.name == "short_block")
    assert np.linalg.norm(block.transform(7)[:3, 3] - block.transform(0)[:3, 3]) > 0.5
    assert not np.allclose(block.transform(7)[:3, :3], block.transform(0)[:3, :3])  # it turns too


def test_motion_vectors_follow_the_moving_object(registry):
    """The G-buffer's motion at the ball points to where the ball was in the previous frame."""
    scene = registry.get("scene", "atrium").factory()
    renderer = registry.renderers["pathtracer"].factory()
    w, h = 96, 54
    t = 20
    frame = renderer.render(scene, t, spp=1, seed=0, channels={"motion", "object_id", "position"}, resolution=(w, h))
    ball = [i for i, o in enumerate(scene.objects) if o.name == "ball"][0]
    pixels = np.argwhere(frame["object_id"] == ball)
    assert len(pixels) > 3
    i, j = pixels[len(pixels) // 2]
    obj = scene.objects[ball]
    local = np.linalg.inv(obj.transform(t)) @ np.append(frame["position"][i, j], 1.0)
    before = (obj.transform(t - 1) @ local)[:3]
    expected = scene.camera.project(before[None], t - 1, w, h)[0] - np.array([j, i])
    np.testing.assert_allclose(frame["motion"][i, j], expected, atol=0.05)


def test_the_furnace_is_out_of_the_default_suite(registry):
    suite = {n for n, s in registry.scenes.items() if s.suite and s.kind == "mesh" and "denoise" in s.tasks}
    assert suite == {"atrium", "courtyard", "cornell", "street"}
    assert registry.scenes["furnace"].frames == 1
