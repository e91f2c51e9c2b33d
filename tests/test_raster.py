"""The ``raster`` renderer: exact float G-buffer, conventions, motion, textures, supersampling."""

from __future__ import annotations

import numpy as np
import pytest

from harness import CameraPath, Material, Scene, SceneObject, load_plugins

W, H = 64, 48
GBUFFER = frozenset({"albedo", "normal", "depth", "position", "object_id", "motion"})


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def renderer(registry):
    return registry.get("renderer", "raster").factory(jitter=False)


@pytest.fixture(scope="module")
def atrium(registry):
    return registry.get("scene", "atrium").factory()


@pytest.fixture(scope="module")
def street(registry):
    return registry.get("scene", "street").factory()


def test_spec_declares_the_gbuffer(registry):
    spec = registry.get("renderer", "raster")
    assert GBUFFER | {"color"} == spec.provides
    assert spec.references and spec.scene_kinds == {"mesh"}
    r = spec.factory(supersample=2, jitter=True)
    assert r.settings() == {"supersample": 2, "jitter": True}


def test_serves_antialiasing_jittered_and_declares_one_input_per_seed(registry, atrium):
    """The renderer serves the anti-aliasing task, whose filters expect jittered frames: jitter is
    on unless asked off. Its frames do not depend on the seed, which it declares, so the planner
    runs one seed of an AA scene instead of counting copies of one input as replicates."""
    from harness.plan import make_plan
    from harness.renders import RenderStore, scene_selection

    spec = registry.get("renderer", "raster")
    assert spec.tasks == {"antialias"} and spec.deterministic
    default = spec.factory()
    assert default.settings()["jitter"]
    a, b = (default.render(atrium, 3, resolution=(W, H), seed=s)["color"] for s in (0, 7))
    np.testing.assert_array_equal(a, b)
    assert default.render(atrium, 3, resolution=(W, H)).meta.jitter != (0.0, 0.0)
    store = RenderStore(registry)
    specs = scene_selection(registry, store, ["aa-fence"], [], ["antialias"])
    plan = make_plan(registry, store, specs, ["taa"], ["ssim"], spp=(1,), seeds=(0, 1, 2), frames=2,
                     tasks=("antialias",))
    assert {j.seed for j in plan.jobs} == {0}
    assert plan.notes == ["scene 'aa-fence': renderer 'raster' returns the same frames for every seed: "
                          "one seed (0) instead of 3"]


def test_channels_dtypes_background_and_meta(renderer, atrium):
    frame = renderer.render(atrium, 0, channels=GBUFFER, resolution=(W, H), seed=3)
    assert frame.channels == GBUFFER | {"color"}
    for name in GBUFFER - {"object_id"}:
        assert frame[name].dtype == np.float32
    assert frame["object_id"].dtype == np.int32
    bg = frame["object_id"] < 0
    assert bg.any() and (~bg).any(), "the atrium shows sky through its open roof"
    assert np.isinf(frame["depth"][bg]).all() and np.isfinite(frame["depth"][~bg]).all()
    for name in ("normal", "position", "albedo"):
        assert (frame[name][bg] == 0).all()
    assert frame.meta.camera_cut and frame.meta.index == 0 and frame.meta.seed == 3
    assert frame.meta.scene == "atrium"
    only = renderer.render(atrium, 0, channels={"depth"}, resolution=(W, H))
    assert only.channels == {"color", "depth"}
    with pytest.raises(ValueError, match="variance"):
        renderer.render(atrium, 0, channels={"variance"}, resolution=(W, H))


@pytest.mark.parametrize("jitter", [False, True])
def test_position_reprojects_to_its_own_pixel_and_depth_is_view_z(registry, atrium, jitter):
    r = registry.get("renderer", "raster").factory(jitter=jitter)
    frame = r.render(atrium, 3, channels={"position", "depth", "object_id"}, resolution=(W, H))
    hit = frame["object_id"] >= 0
    jx, jy = frame.meta.jitter
    assert (jx != 0.0) == jitter
    xy = atrium.camera.project(frame["position"], 3, W, H, jitter=(jx, jy))
    jj, ii = np.meshgrid(np.arange(W), np.arange(H))
    err = np.hypot(xy[..., 0] - jj, xy[..., 1] - ii)[hit]
    assert err.max() < 2e-3, err.max()
    view = atrium.camera.view_matrix(3)
    z = -(frame["position"].astype(np.float64) @ view[2, :3] + view[2, 3])
    np.testing.assert_allclose(frame["depth"][hit], z[hit], rtol=1e-5)
    np.testing.assert_allclose(frame.meta.view_proj, atrium.camera.view_projection(3, W, H, (jx, jy)))


def test_normals_unit_and_facing_the_camera(renderer, atrium):
    frame = renderer.render(atrium, 0, channels={"normal", "object_id", "position"}, resolution=(W, H))
    hit = frame["object_id"] >= 0
    n = frame["normal"][hit].astype(np.float64)
    np.testing.assert_allclose(np.linalg.norm(n, axis=1), 1.0, atol=1e-5)
    to_eye = atrium.camera.eye(0) - frame["position"][hit]
    assert ((n * to_eye).sum(axis=1) > -1e-3).mean() > 0.99


def test_untextured_albedo_is_the_exact_material_value(registry):
    cornell = registry.get("scene", "cornell").factory()
    r = registry.get("renderer", "raster").factory(jitter=False)
    frame = r.render(cornell, 0, channels={"albedo", "object_id"}, resolution=(W, W))
    values = {tuple(v) for v in frame["albedo"][frame["object_id"] >= 0].tolist()}
    expected = {tuple(np.float32(c) for c in m.albedo) for m in cornell.materials}
    assert values <= {tuple(float(c) for c in v) for v in expected}
    assert len(values) == 4  # white, red, green and the light are all in view


def _plane_scene(texture: np.ndarray, base=(0.5, 0.75, 1.0)) -> Scene:
    """A unit-texture square that exactly fills a 90-degree square view at distance 1."""
    import pyvista as pv

    pts = np.array([[-1, -1, 0], [1, -1, 0], [1, 1, 0], [-1, 1, 0]], np.float32)
    mesh = pv.PolyData(pts, faces=np.array([3, 0, 1, 2, 3, 0, 2, 3]))
    mesh.point_data["uv"] = np.array([[0, 0], [1, 0], [1, 1], [0, 1]], np.float32)
    mesh.cell_data["material"] = np.zeros(2, np.int32)
    camera = CameraPath(positions=[(0, 0, 1)], targets=[(0, 0, 0)], fov=90.0, near=0.1, far=10.0)
    return Scene("plane", objects=[SceneObject("plane", mesh)],
                 materials=[Material("checker", albedo=base, texture=texture)], camera=camera, resolution=(64, 64))


def test_textured_plane_samples_the_right_texels(renderer):
    rng = np.random.default_rng(0)
    texture = rng.random((64, 64, 3)).astype(np.float32)  # asymmetric: catches flips and transposes
    scene = _plane_scene(texture)
    frame = renderer.render(scene, 0, channels={"albedo", "object_id"}, resolution=(64, 64))
    assert (frame["object_id"] == 0).all()
    expected = texture * np.array([0.5, 0.75, 1.0], np.float32)
    np.testing.assert_allclose(frame["albedo"], expected, atol=2e-5)


def test_checkerboard_squares_land_on_their_pixels(renderer):
    from plugins.scenes.builtin.textures import checker

    texture = checker(64, squares=8, dark=(0.1, 0.1, 0.1), light=(0.9, 0.9, 0.9))
    scene = _plane_scene(texture, base=(1.0, 1.0, 1.0))
    frame = renderer.render(scene, 0, channels={"albedo"}, resolution=(32, 32))
    ii, jj = np.meshgrid(np.arange(32), np.arange(32), indexing="ij")
    # pixel (i, j) of the 32x32 image covers texels 2i..2i+1: square (i // 4, j // 4)
    light = ((ii // 4 + jj // 4) % 2 == 0)
    inner = ((ii % 4) != 0) & ((ii % 4) != 3) & ((jj % 4) != 0) & ((jj % 4) != 3)
    albedo = frame["albedo"][..., 0]
    np.testing.assert_allclose(albedo[light & inner], 0.9, atol=1e-5)
    np.testing.assert_allclose(albedo[~light & inner], 0.1, atol=1e-5)


def _two_frame_camera_motion(scene: Scene) -> Scene:
    """``scene`` with a two-frame camera path that translates and turns (no object motion)."""
    cam = scene.camera
    eye, target = cam.eye(0), cam.targets[0]
    moved = CameraPath(positions=[eye, eye + np.array([0.35, 0.1, 0.25])],
                       targets=[target, target + np.array([0.0, 0.3, -0.8])],
                       fov=cam.fov, near=cam.near, far=cam.far)
    return Scene(scene.name, frame_count=2, resolution=scene.resolution, tags=scene.tags, objects=scene.objects,
                 materials=scene.materials, sun=scene.sun, environment=scene.environment, camera=moved)


def _bilinear(image: np.ndarray, x: np.ndarray, y: np.ndarray) -> np.ndarray:
    h, w = image.shape[:2]
    x0 = np.clip(np.floor(x).astype(int), 0, w - 2)
    y0 = np.clip(np.floor(y).astype(int), 0, h - 2)
    fx = (x - x0)[..., None]
    fy = (y - y0)[..., None]
    return ((image[y0, x0] * (1 - fx) + image[y0, x0 + 1] * fx) * (1 - fy)
            + (image[y0 + 1, x0] * (1 - fx) + image[y0 + 1, x0 + 1] * fx) * fy)


def test_warping_previous_frame_by_motion_matches_except_disocclusions(renderer, atrium):
    scene = _two_frame_camera_motion(atrium)
    w, h = 96, 64
    prev = renderer.render(scene, 0, channels={"depth", "object_id", "position"}, resolution=(w, h))
    cur = renderer.render(scene, 1, channels={"motion", "depth", "object_id", "position"}, resolution=(w, h))
    mv = cur["motion"]
    assert np.abs(mv).max() > 2.0, "the camera moves"
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    x, y = jj + mv[..., 0], ii + mv[..., 1]
    x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
    # pixels whose 2x2 neighbourhood in the previous frame shows the same object
    same = (x0 >= 0) & (y0 >= 0) & (x0 < w - 1) & (y0 < h - 1) & (cur["object_id"] >= 0)
    ids = prev["object_id"]
    for dy in (0, 1):
        for dx in (0, 1):
            same &= ids[np.clip(y0 + dy, 0, h - 1), np.clip(x0 + dx, 0, w - 1)] == cur["object_id"]
    # disocclusion test: inverse depth is affine in screen space on a plane, so its bilinear
    # warp must equal the inverse of the depth the current point had in the previous view
    view = scene.camera.view_matrix(0)
    expected_depth = -(cur["position"].astype(np.float64) @ view[2, :3] + view[2, 3])
    inv_depth = 1.0 / np.where(np.isfinite(prev["depth"]), prev["depth"], np.inf)
    agree = np.abs(_bilinear(inv_depth[..., None], x, y)[..., 0] * expected_depth - 1.0) < 0.01
    valid = same & agree
    assert valid.mean() > 0.55
    assert (same & ~agree).mean() < 0.08, "only disoccluded (self-occluded) pixels may disagree"
    # object ids are stable: the surface seen now carries the id it had in the previous frame
    xr, yr = np.rint(x).astype(int)[valid], np.rint(y).astype(int)[valid]
    assert (prev["object_id"][yr, xr] == cur["object_id"][valid]).all()
    # warped world positions land on the same surface points (within a pixel's footprint)
    warped = _bilinear(prev["position"].astype(np.float64), x, y)
    gap = np.linalg.norm(warped - cur["position"], axis=-1)[valid]
    footprint = cur["depth"][valid] * 2 * np.tan(np.radians(scene.camera.fov / 2)) / h
    assert np.median(gap / footprint) < 0.05
    assert np.mean(gap / footprint < 1.0) > 0.97
    # and the colour warps too (the raster shading is view independent under sun and sky)
    prev_color = renderer.render(scene, 0, resolution=(w, h))["color"]
    warped_color = _bilinear(prev_color.astype(np.float64), x, y)
    err = np.abs(warped_color - cur["color"]).max(axis=-1)[valid]
    assert np.median(err) < 0.02


def test_object_motion_points_to_the_same_object_point(renderer, street):
    t = 12
    w, h = 96, 54
    prev = renderer.render(street, t - 1, channels={"position", "object_id"}, resolution=(w, h))
    cur = renderer.render(street, t, channels={"position", "object_id", "motion"}, resolution=(w, h))
    car = next(k for k, obj in enumerate(street.objects) if obj.name == "car")
    on_car = cur["object_id"] == car
    assert on_car.sum() > 20
    mv = cur["motion"]
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    xr = np.rint(jj + mv[..., 0]).astype(int)
    yr = np.rint(ii + mv[..., 1]).astype(int)
    inside = on_car & (xr >= 0) & (xr < w) & (yr >= 0) & (yr < h)  # the car enters from the left
    ok = inside & (prev["object_id"][np.clip(yr, 0, h - 1), np.clip(xr, 0, w - 1)] == car)
    assert ok.sum() > 0.9 * inside.sum() > 50
    local_now = _to_object(street.objects[car].transform(t), cur["position"][ok])
    local_prev = _to_object(street.objects[car].transform(t - 1), prev["position"][yr[ok], xr[ok]])
    # nearest-pixel lookup: the points agree within about a pixel's footprint (~0.1 m here)
    assert np.median(np.linalg.norm(local_now - local_prev, axis=1)) < 0.1
    # the car moves about 1 m per frame: without the object transform the match would fail
    static_guess = _to_object(street.objects[car].transform(t), prev["position"][yr[ok], xr[ok]])
    assert np.median(np.linalg.norm(local_now - static_guess, axis=1)) > 0.5


def _to_object(matrix: np.ndarray, points: np.ndarray) -> np.ndarray:
    inv = np.linalg.inv(matrix)
    return points.astype(np.float64) @ inv[:3, :3].T + inv[:3, 3]


def test_reference_is_supersampled_colour(registry, atrium):
    r = registry.get("renderer", "raster").factory(jitter=False)
    color = r.render(atrium, 0, resolution=(W, H))["color"]
    ref1 = r.reference(atrium, 0, spp=1, resolution=(W, H))
    np.testing.assert_array_equal(ref1, color)
    ref = r.reference(atrium, 0, spp=16, resolution=(W, H))
    assert ref.shape == (H, W, 3) and ref.dtype == np.float32
    ss = registry.get("renderer", "raster").factory(supersample=4, jitter=False).render(atrium, 0, resolution=(W, H))["color"]
    np.testing.assert_allclose(ss, ref, atol=1e-6)
    diff = np.abs(ref - color).max(axis=-1)
    assert (diff > 1e-3).mean() > 0.02  # edges and textures are anti-aliased
    # the box filter of a 4x4 grid equals the mean of the 4x4 grid rendered at 4x the size
    big = r.render(atrium, 0, resolution=(4 * W, 4 * H))["color"]
    np.testing.assert_allclose(big.reshape(H, 4, W, 4, 3).mean(axis=(1, 3)), ref, atol=1e-5)


def test_furnace_colour_is_rho_headlight_plus_emission(registry):
    from plugins.renderers.raster.shading import HEADLIGHT

    furnace = registry.get("scene", "furnace").factory()
    r = registry.get("renderer", "raster").factory(jitter=False)
    frame = r.render(furnace, 0, channels={"normal"}, resolution=(32, 32))
    rho, le = furnace.params["rho"], furnace.params["Le"]
    color = frame["color"][..., 0]
    assert (color <= rho * HEADLIGHT + le + 1e-5).all() and (color >= le).all()


@pytest.mark.parametrize("jitter", [False, True])
def test_motion_equals_the_scene_definition(registry, street, jitter):
    r = registry.get("renderer", "raster").factory(jitter=jitter)
    for t in (0, 1, 12):
        frame = r.render(street, t, channels={"position", "object_id", "motion"}, resolution=(W, H))
        expected = street.motion(frame["position"], frame["object_id"], t, W, H)
        np.testing.assert_allclose(frame["motion"], expected, atol=1e-3)
    assert np.abs(frame["motion"]).max() > 1.0


@pytest.mark.parametrize("rotation", [0.0, 90.0])
def test_exr_environment_map_shows_in_the_background(tmp_path, renderer, rotation):
    import OpenImageIO as oiio

    from harness import Environment

    image = np.random.default_rng(4).random((8, 16, 3)).astype(np.float32)
    path = tmp_path / "sky.exr"
    out = oiio.ImageOutput.create(str(path))
    out.open(str(path), oiio.ImageSpec(16, 8, 3, "float"))
    out.write_image(image)
    out.close()
    env = Environment(kind="map", image=str(path), radiance=(2.0, 2.0, 2.0), rotation=rotation)
    np.testing.assert_array_equal(env.image_array(), image)
    camera = CameraPath(positions=[(0, 0, 0)], targets=[(0, 0, -1)], fov=10.0)
    scene = Scene("sky", environment=env, camera=camera, resolution=(16, 16))
    frame = renderer.render(scene, 0, channels={"object_id", "depth"}, resolution=(16, 16))
    assert (frame["object_id"] == -1).all() and np.isinf(frame["depth"]).all()
    # pixel (8, 8) looks just right of and below -z: u = 0.5+ + rotation / 360, v = 0.5+
    col = int((0.5 + rotation / 360.0) * 16) % 16
    np.testing.assert_allclose(frame["color"][8, 8], 2.0 * image[4, col], rtol=1e-6)


def test_draws_from_several_threads_match_one_thread(registry, atrium):
    """An OpenGL context belongs to one thread: renders requested from a pool's threads (a Dask
    client drawing references) must give the images one thread gives, at changing sizes."""
    from concurrent.futures import ThreadPoolExecutor

    shared = registry.get("renderer", "raster").factory(jitter=False)
    sizes = [(W, H), (2 * W, 2 * H), (W + 8, H + 4)]
    got = []
    for size in sizes:  # each call on a new thread: the pool is made and dropped per call
        with ThreadPoolExecutor(1) as pool:
            got.append(pool.submit(shared.render, atrium, 0, channels={"object_id"}, resolution=size).result())
    alone = registry.get("renderer", "raster").factory(jitter=False)
    for size, frame in zip(sizes, got):
        want = alone.render(atrium, 0, channels={"object_id"}, resolution=size)
        np.testing.assert_array_equal(frame["object_id"], want["object_id"])
        np.testing.assert_array_equal(frame["color"], want["color"])
