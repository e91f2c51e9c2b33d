"""Path tracer protocol: channels, G-buffer, determinism, resumable streams, adaptive sampler."""

from __future__ import annotations

import numba
import numpy as np
import pytest
import pyvista as pv

from harness import CHANNELS, CameraPath, Environment, Material, Scene, SceneObject, Sun, load_plugins
from plugins.renderers.pathtracer import PathTracer
from plugins.renderers.pathtracer.rng import stream_key, uniform
from tests.pathtracer_scenes import box_scene, furnace_scene

ALL = frozenset(CHANNELS)


@pytest.fixture(scope="module")
def box():
    return box_scene(size=(20, 16))


def test_registered_with_its_declarations():
    registry = load_plugins()
    spec = registry.renderers["pathtracer"]
    assert spec.provides == ALL
    assert spec.references and spec.adaptive
    assert spec.scene_kinds == frozenset({"mesh"})
    renderer = spec.factory()
    assert renderer.settings() == {"max_depth": None, "rr_depth": 5, "strategy": "mis", "jitter": False,
                                   "reference_pixel": "area"}


def test_all_channels_valid(box):
    frame = PathTracer().render(box, 2, spp=4, seed=1, channels=ALL)
    assert frame.channels == ALL
    assert frame.shape == (16, 20)
    for name in ALL:
        assert frame[name].dtype == CHANNELS[name][1]
    hit = frame["object_id"] >= 0
    assert hit.mean() > 0.8  # the camera sees mostly the inside of the box
    np.testing.assert_allclose(np.linalg.norm(frame["normal"][hit], axis=-1), 1.0, atol=1e-5)
    assert (frame["spp"] == 4).all()
    for name in ("color", "direct", "indirect", "variance", "visibility"):
        assert np.isfinite(frame[name]).all() and (frame[name] >= 0).all(), name
    assert frame["visibility"].max() <= 1.0
    np.testing.assert_allclose(frame["direct"] + frame["indirect"], frame["color"], rtol=1e-5, atol=1e-6)
    meta = frame.meta
    assert meta.index == 2 and meta.seed == 1 and meta.scene == box.name and not meta.camera_cut
    np.testing.assert_allclose(meta.view_proj, box.camera.view_projection(2, 20, 16))
    assert PathTracer().render(box, 0, spp=1).meta.camera_cut


def test_only_color_unless_asked(box):
    frame = PathTracer().render(box, 0, spp=1)
    assert frame.channels == frozenset({"color"})


def test_gbuffer_of_a_plane_and_background():
    """A square facing the camera at distance 2: depth 2, object 0, normal towards the camera;
    pixels beside it are background (inf depth, id -1, zero features)."""
    plane = pv.Plane(center=(0, 0, 0), direction=(0, 0, 1), i_size=1.0, j_size=1.0).triangulate()
    mats = [Material("grey", albedo=(0.2, 0.4, 0.6))]
    cam = CameraPath(positions=[(0.0, 0.0, 2.0)], targets=[(0.0, 0.0, 0.0)], fov=60)
    scene = Scene("pt-plane", objects=[SceneObject("plane", plane, 0)], materials=mats, camera=cam,
                  resolution=(24, 24))
    frame = PathTracer().render(scene, 0, spp=1, channels=ALL)
    hit = frame["object_id"] == 0
    assert 0.05 < hit.mean() < 0.5
    np.testing.assert_allclose(frame["depth"][hit], 2.0, rtol=1e-6)
    np.testing.assert_allclose(frame["normal"][hit] - [0, 0, 1], 0.0, atol=1e-6)
    np.testing.assert_allclose(frame["albedo"][hit] - [0.2, 0.4, 0.6], 0.0, atol=1e-6)
    np.testing.assert_allclose(frame["position"][hit][:, 2], 0.0, atol=1e-6)
    bg = ~hit
    assert (frame["object_id"][bg] == -1).all() and np.isinf(frame["depth"][bg]).all()
    for name in ("normal", "albedo", "position", "color"):
        assert (frame[name][bg] == 0).all(), name


def test_textured_albedo_orientation_and_shading():
    """A 2x2 texture on a unit square facing the camera: texel row 0 is the top (v = 1); under a
    constant sky Le a diffuse plane reflects exactly albedo x Le."""
    plane = pv.Plane(center=(0, 0, 0), direction=(0, 0, 1), i_size=1.0, j_size=1.0,
                     i_resolution=1, j_resolution=1).triangulate()
    plane.point_data["uv"] = np.asarray(plane.points)[:, :2] + 0.5
    texture = np.array([[[0.9, 0.1, 0.1], [0.1, 0.9, 0.1]], [[0.1, 0.1, 0.9], [0.9, 0.9, 0.9]]], np.float32)
    mats = [Material("tex", albedo=(1.0, 0.5, 1.0), texture=texture)]
    cam = CameraPath(positions=[(0.0, 0.0, 0.5 / np.tan(np.radians(30)))], targets=[(0.0, 0.0, 0.0)], fov=60)
    scene = Scene("pt-texture", objects=[SceneObject("plane", plane, 0)], materials=mats, camera=cam,
                  resolution=(32, 32), environment=Environment("constant", radiance=(2.0, 2.0, 2.0)))
    frame = PathTracer().render(scene, 0, spp=64, channels={"albedo", "variance"})
    # the square fills the image; these pixels lie 1/32 of a texel from texel centres
    assert (frame["color"] > 0).all()
    for (i, j), (ti, tj) in {(7, 7): (0, 0), (7, 24): (0, 1), (24, 7): (1, 0), (24, 24): (1, 1)}.items():
        want = texture[ti, tj] * np.array([1.0, 0.5, 1.0])
        np.testing.assert_allclose(frame["albedo"][i, j], want, atol=0.08)
        err = np.abs(frame["color"][i, j] - 2.0 * frame["albedo"][i, j])
        assert np.all(err <= 5 * np.sqrt(frame["variance"][i, j]) + 1e-6), err


def test_direct_only_paths_have_no_indirect(box):
    frame = PathTracer(max_depth=2).render(box, 0, spp=4, channels={"direct", "indirect"})
    assert (frame["indirect"] == 0).all()
    np.testing.assert_array_equal(frame["direct"], frame["color"])


def test_deterministic_and_thread_count_independent(box):
    renderer = PathTracer()
    a = renderer.render(box, 0, spp=3, seed=7, channels={"variance", "visibility"})
    before = numba.get_num_threads()
    try:
        numba.set_num_threads(1)
        b = PathTracer().render(box, 0, spp=3, seed=7, channels={"variance", "visibility"})
    finally:
        numba.set_num_threads(before)
    for name in ("color", "variance", "visibility"):
        np.testing.assert_array_equal(a[name], b[name])
    c = renderer.render(box, 0, spp=3, seed=8)
    assert not np.array_equal(a["color"], c["color"])  # the seed matters
    d = renderer.render(box, 1, spp=3, seed=7)
    assert not np.array_equal(a["color"], d["color"])  # so does the frame index


def test_last_segment_as_any_hit_query_changes_nothing():
    """Where no material emits, a path's last segment is an any-hit query (does it escape?); an
    emitting material that no triangle uses forces the closest-hit query there, and the images
    must be the same bit for bit (sky and sun through the open front of the box)."""
    lit = box_scene(size=(20, 16), emission=0.0)
    unlit = dict(objects=lit.objects, camera=lit.camera, resolution=lit.resolution,
                 environment=Environment("sky", radiance=(0.2, 0.3, 0.6), horizon=(0.6, 0.6, 0.6)),
                 sun=Sun(direction=(0.3, 1.0, 0.8), angular_radius=2.0, radiance=200.0))
    dark = Scene("pt-open-box", materials=lit.materials, **unlit)
    forced = Scene("pt-open-box-forced", materials=[*lit.materials, Material("unused", emission=(1.0, 1.0, 1.0))],
                   **unlit)
    for max_depth, strategy in ((3, "mis"), (4, "light"), (5, "bsdf"), (6, "mis")):
        kwargs = dict(spp=4, seed=3, channels={"direct", "indirect", "variance"})
        a = PathTracer(max_depth=max_depth, strategy=strategy).render(dark, 0, **kwargs)
        b = PathTracer(max_depth=max_depth, strategy=strategy).render(forced, 0, **kwargs)
        assert (a["indirect"] > 0).mean() > 0.2  # light that came in through the front, bounced
        for name in ("color", "direct", "variance"):
            np.testing.assert_array_equal(a[name], b[name])


def test_primary_rays_are_the_cameras(box):
    """The kernel's rays through the pixel centres are bit for bit those of CameraPath."""
    for frame, (w, h) in ((1, (20, 16)), (3, (37, 11))):
        setup = PathTracer().setup(box, frame, (w, h))
        o, d = box.camera.primary_rays(frame, w, h)
        np.testing.assert_array_equal(setup.origins, o.reshape(-1, 3))
        np.testing.assert_array_equal(setup.dirs, d.reshape(-1, 3))


def test_eight_then_eight_more_equals_sixteen(box):
    renderer = PathTracer()
    sixteen = renderer.render(box, 0, spp=16, seed=4, channels={"variance", "direct", "spp"})
    sampler = renderer.sampler(box, 0, spp=8, seed=4, channels={"variance", "direct"})
    assert sampler.samples_used == 8 * 20 * 16
    frame = sampler.add_samples(np.full((16, 20), 8, np.int32))
    assert sampler.samples_used == 16 * 20 * 16
    for name in ("color", "variance", "direct", "spp"):
        np.testing.assert_array_equal(frame[name], sixteen[name])


def test_adaptive_sampler_counts_and_continues_streams(box):
    renderer = PathTracer(reference_pixel="centre")  # accumulate() then continues the noisy frames' streams
    sampler = renderer.sampler(box, 0, spp=2, seed=9)
    extra = np.zeros((16, 20), np.int32)
    extra[3:7, 4:12] = 5
    extra[10, 10] = 1
    frame = sampler.add_samples(extra)
    assert sampler.samples_used == 2 * 320 + int(extra.sum())
    np.testing.assert_array_equal(frame["spp"], 2 + extra)
    for spp in (2, 3, 7):
        whole = renderer.accumulate(box, 0, first_sample=0, count=spp, seed=9) / spp
        sel = frame["spp"] == spp
        np.testing.assert_array_equal(frame["color"][sel], whole.astype(np.float32)[sel])
    with pytest.raises(ValueError):
        sampler.add_samples(np.full((16, 20), -1, np.int32))


def test_accumulate_chunks_and_reference_are_consistent(box):
    renderer = PathTracer()
    whole = renderer.accumulate(box, 0, first_sample=0, count=12, seed=2)
    assert whole.dtype == np.float64 and whole.shape == (16, 20, 3)
    chunks = renderer.accumulate(box, 0, first_sample=0, count=5, seed=2) + renderer.accumulate(
        box, 0, first_sample=5, count=7, seed=2)
    np.testing.assert_allclose(chunks, whole, rtol=1e-12, atol=1e-12)
    ref = renderer.reference(box, 0, spp=12, seed=2)
    assert ref.dtype == np.float32 and ref.shape == (16, 20, 3)
    np.testing.assert_array_equal(ref, (whole / 12).astype(np.float32))
    centre = PathTracer(reference_pixel="centre")  # pixel-centre references are the noisy frames' samples
    frame = centre.render(box, 0, spp=12, seed=2)
    np.testing.assert_array_equal(frame["color"], centre.reference(box, 0, spp=12, seed=2))


def test_variance_is_that_of_the_pixel_mean():
    scene = furnace_scene(size=(8, 8))
    renderer = PathTracer()
    frame = renderer.render(scene, 0, spp=16, seed=0, channels={"variance"})
    means = np.stack([renderer.render(scene, 0, spp=16, seed=s)["color"] for s in range(1, 25)])
    empirical = means.astype(np.float64).var(axis=0, ddof=1).mean()
    assert 0.6 < frame["variance"].astype(np.float64).mean() / empirical < 1.6
    single = renderer.render(scene, 0, spp=1, channels={"variance"})
    assert (single["variance"] == 0).all()  # undefined with one sample: reported as 0


def test_rejects_bad_arguments(box):
    with pytest.raises(ValueError, match="spp"):
        PathTracer().render(box, 0, spp=0)
    with pytest.raises(ValueError, match="strategy"):
        PathTracer(strategy="magic")
    with pytest.raises(ValueError, match="mesh"):
        PathTracer().render(Scene("p", kind="procedural"), 0)


def test_random_streams_uniform_and_decorrelated():
    u = np.array([uniform(np.uint64(stream_key(1, 0, p, s)), d)
                  for p in range(40) for s in range(25) for d in range(4)])
    assert u.min() >= 0.0 and u.max() < 1.0
    counts, _ = np.histogram(u, bins=20, range=(0, 1))
    expected = len(u) / 20
    chi2 = ((counts - expected) ** 2 / expected).sum()
    assert chi2 < 45  # 19 degrees of freedom: p < 1e-3 beyond this
    x = u.reshape(40 * 25, 4)
    assert abs(np.corrcoef(x[:-1, 0], x[1:, 0])[0, 1]) < 0.1  # neighbouring samples
    assert abs(np.corrcoef(x[:, 0], x[:, 1])[0, 1]) < 0.1  # neighbouring dimensions


@pytest.mark.parametrize("name", ["cornell", "atrium", "courtyard", "street"])
def test_first_hits_agree_with_raster(name):
    """Same surface point as the raster G-buffer: object id on >= 99.5% of pixels, and depth
    within 1e-3 (relative) on >= 99.5% of the pixels where both see the same object."""
    registry = load_plugins()
    if "raster" not in registry.renderers:
        pytest.skip("raster renderer not registered")
    if name not in registry.scenes:
        pytest.skip(f"scene {name!r} not registered")
    scene = registry.scenes[name].factory()
    raster = registry.renderers["raster"].factory(jitter=False)  # pixel centres, as the path tracer
    want = {"object_id", "depth"}
    frame = min(1, scene.frame_count - 1)
    a = raster.render(scene, frame, spp=1, seed=0, channels=want, resolution=(64, 48))
    b = PathTracer().render(scene, frame, spp=1, seed=0, channels=want, resolution=(64, 48))
    same = a["object_id"] == b["object_id"]
    assert same.mean() >= 0.995
    both = same & (b["object_id"] >= 0)
    rel = np.abs(a["depth"][both] - b["depth"][both]) / b["depth"][both]
    assert (rel <= 1e-3).mean() >= 0.995
