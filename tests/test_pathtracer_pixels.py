"""The path tracer's declared pixel sampling: pixel-area references, pixel-centre or jittered noisy frames.

The scene is emitters against black seen directly (``max_depth=1``): a sample's radiance is then a
function of its position in the pixel alone, so a pixel's value is exactly the emission times the
fraction of the pixel each emitter covers, and every sampling convention can be checked against
averages of renders through known sub-pixel points.
"""

from __future__ import annotations

import numba
import numpy as np
import pytest
import pyvista as pv

from harness import JITTER_CYCLE, CameraPath, Material, Scene, SceneObject, halton_jitter
from plugins.renderers.pathtracer import PathTracer
from plugins.renderers.pathtracer.pixels import PixelState

SIZE = (24, 16)


def emitters() -> Scene:
    """A thin bar (a third of a pixel wide), a tilted square and a triangle, emitting, on black."""
    def quad(corners):
        return pv.PolyData(np.asarray(corners, float), faces=[4, 0, 1, 2, 3]).triangulate()

    bar = quad([[-0.9, -0.6, 0], [-0.87, -0.6, 0], [-0.87, 0.6, 0], [-0.9, 0.6, 0]])
    c, s = np.cos(0.4), np.sin(0.4)
    square = quad([[0.1 + 0.4 * (c * x - s * y), 0.4 * (s * x + c * y), 0] for x, y in ((-1, -1), (1, -1), (1, 1),
                                                                                         (-1, 1))])
    tri = pv.PolyData(np.array([[-0.6, -0.5, 0.0], [-0.2, 0.55, 0.0], [-0.45, 0.6, 0.0]]), faces=[3, 0, 1, 2])
    materials = [Material("a", emission=(4.0, 2.0, 1.0), albedo=(0, 0, 0)),
                 Material("b", emission=(1.0, 3.0, 2.0), albedo=(0, 0, 0))]
    objects = [SceneObject("bar", bar, 0), SceneObject("square", square, 1), SceneObject("tri", tri, 0)]
    camera = CameraPath(positions=[[0, 0, 2.5]], targets=[[0, 0, 0]], fov=40.0)
    return Scene("emitters", objects=objects, materials=materials, camera=camera, resolution=SIZE, max_depth=1,
                 frame_count=4)


@pytest.fixture(scope="module")
def scene():
    return emitters()


def through(tracer: PathTracer, scene, offset) -> np.ndarray:
    """One sample per pixel through the pixel centre shifted by ``offset`` (deterministic here)."""
    setup = tracer.setup(scene, 0, SIZE, jitter=offset)
    state = PixelState(SIZE[0] * SIZE[1])
    tracer.add_samples(setup, state, np.ones(state.spp.shape, np.int64), 0, moments=False, split=False)
    return state.acc.reshape(SIZE[1], SIZE[0], 3)


def subpixel_mean(tracer, scene, k: int) -> np.ndarray:
    """The mean over a k x k grid of points of each pixel (the midpoint rule of the box-filtered pixel):
    one sample through each pixel centre of the k-times larger image, whose pixel (k i + b, k j + a)
    is centred on point ((a + 0.5) / k, (b + 0.5) / k) of pixel (i, j); checked against renders
    through those offsets of the small image."""
    w, h = SIZE
    big = tracer.setup(scene, 0, (k * w, k * h), jitter=(0.0, 0.0))
    state = PixelState(k * w * k * h)
    tracer.add_samples(big, state, np.ones(state.spp.shape, np.int64), 0, moments=False, split=False)
    return state.acc.reshape(h, k, w, k, 3).mean(axis=(1, 3))


def test_the_subpixel_mean_is_the_mean_of_offset_renders(scene):
    tracer = PathTracer(max_depth=1)
    offsets = (np.arange(3) + 0.5) / 3 - 0.5
    by_offset = np.mean([through(tracer, scene, (x, y)) for y in offsets for x in offsets], axis=0)
    np.testing.assert_allclose(subpixel_mean(tracer, scene, 3), by_offset, rtol=1e-6, atol=1e-9)


def test_pixel_area_reference_converges_to_the_mean_of_subpixel_renders(scene):
    tracer = PathTracer(max_depth=1)
    truth = subpixel_mean(tracer, scene, 32)  # itself within about 0.007 of the exact coverage here
    centre = through(tracer, scene, (0.0, 0.0))
    edge = np.abs(centre - truth).max(axis=-1) > 0.05  # pixels the edges cross
    assert edge.sum() > 40
    errors = {}
    for spp in (64, 4096):
        area = tracer.reference(scene, 0, spp=spp, resolution=SIZE).astype(np.float64)
        errors[spp] = np.abs(area - truth)[edge].mean()
    centre_error = np.abs(centre - truth)[edge].mean()
    # pixel centres miss the area (the thin bar vanishes or fills whole pixels); the area reference
    # converges to the sub-pixel mean as 1/sqrt(N) (measured: 0.067 at 64 spp, 0.010 at 4096,
    # against 0.48 for the pixel centres)
    assert errors[4096] < 0.05 * centre_error, (errors, centre_error)
    assert errors[4096] < errors[64] / 4, errors
    # away from edges the conventions agree exactly (one emitter covers the whole pixel)
    inside = ~edge & (truth.max(axis=-1) > 0)
    area = tracer.reference(scene, 0, spp=16, resolution=SIZE)
    np.testing.assert_allclose(area[inside], centre[inside], rtol=1e-6)


def test_centre_references_are_still_available(scene):
    area = PathTracer(max_depth=1).reference(scene, 0, spp=8, resolution=SIZE)
    centre = PathTracer(max_depth=1, reference_pixel="centre").reference(scene, 0, spp=8, resolution=SIZE)
    np.testing.assert_array_equal(centre, through(PathTracer(max_depth=1), scene, (0.0, 0.0)).astype(np.float32))
    assert not np.array_equal(area, centre)
    with pytest.raises(ValueError, match="reference_pixel"):
        PathTracer(reference_pixel="gauss")


def test_area_samples_are_resumable_and_thread_independent(scene):
    tracer = PathTracer(max_depth=1)
    whole = tracer.accumulate(scene, 0, first_sample=0, count=24, seed=5, resolution=SIZE)
    parts = (tracer.accumulate(scene, 0, first_sample=0, count=10, seed=5, resolution=SIZE)
             + tracer.accumulate(scene, 0, first_sample=10, count=14, seed=5, resolution=SIZE))
    np.testing.assert_allclose(parts, whole, rtol=1e-12)
    threads = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        single = tracer.accumulate(scene, 0, first_sample=0, count=24, seed=5, resolution=SIZE)
    finally:
        numba.set_num_threads(threads)
    np.testing.assert_array_equal(single, whole)


def test_noisy_frames_take_pixel_centres_or_the_frames_halton_jitter(scene):
    centred, jittered = PathTracer(max_depth=1), PathTracer(max_depth=1, jitter=True)
    assert jittered.settings()["jitter"] and not centred.settings()["jitter"]
    offsets = {halton_jitter(t) for t in range(JITTER_CYCLE)}
    assert len(offsets) == JITTER_CYCLE and all(-0.5 <= v < 0.5 for o in offsets for v in o)
    assert halton_jitter(0) == pytest.approx((0.0, -1 / 6)) and halton_jitter(JITTER_CYCLE) == halton_jitter(0)
    channels = {"object_id", "position", "albedo", "emission"}
    for t in range(3):
        plain = centred.render(scene, t, channels=channels, resolution=SIZE)
        assert plain.meta.jitter == (0.0, 0.0)
        frame = jittered.render(scene, t, channels=channels, resolution=SIZE)
        assert frame.meta.jitter == halton_jitter(t)
        np.testing.assert_allclose(frame.meta.view_proj, scene.camera.view_projection(t, *SIZE, halton_jitter(t)))
        # the frame's rays are CameraPath's primary rays through the jittered points, bit for bit
        setup = jittered.setup(scene, t, SIZE)
        _, d = scene.camera.primary_rays(t, *SIZE, jitter=halton_jitter(t))
        np.testing.assert_array_equal(setup.dirs, d.reshape(-1, 3))
        # G-buffer and colour come from the same first hit: colour is the hit emitter's emission
        hit = frame["object_id"] >= 0
        assert np.array_equal(frame["color"].max(axis=-1) > 0, hit)
        np.testing.assert_array_equal(frame["color"], frame["emission"])
    first, second = (jittered.render(scene, t, channels={"object_id"}, resolution=SIZE)["object_id"] for t in (0, 1))
    assert not np.array_equal(first, second)  # the thin bar and the edges move between jittered frames


def test_the_conventions_are_settings():
    """Both options are settings: part of every cache key and job identity, and of a run's manifest
    (``settings.renderer_settings``, tests/test_profiles.py)."""
    assert PathTracer(jitter=True, reference_pixel="centre").settings() == {
        "max_depth": None, "rr_depth": 5, "strategy": "mis", "jitter": True, "reference_pixel": "centre"}
    with pytest.raises(ValueError, match="jitter"):
        PathTracer(jitter="yes")
