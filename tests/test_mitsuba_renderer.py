"""The ``mitsuba`` renderer: channels and conventions, seeds, sample streams, variance, poses, variants.

The scene is a small diffuse box written as Mitsuba 3 XML into a temporary folder and loaded
by the Mitsuba scene plugin, as ``--scene-dir`` would. The unmarked tests use ``scalar_rgb``
(no LLVM probe, a tiny image); the others use the variant ``auto`` picks (``llvm_ad_rgb`` where
an LLVM works) and are marked slow.
"""

from __future__ import annotations

import dataclasses
import warnings

import numpy as np
import pytest

from harness import CHANNELS, CameraPath, load_plugins

pytest.importorskip("mitsuba")

from plugins.renderers.mitsuba import MitsubaRenderer  # noqa: E402
from plugins.renderers.mitsuba.streams import base_key, image_seed  # noqa: E402
from plugins.renderers.mitsuba.sums import lane_batches  # noqa: E402
from plugins.renderers.mitsuba.variants import VariantError, probe  # noqa: E402
from plugins.scenes.mitsuba import load  # noqa: E402

PROVIDED = frozenset({"color", "variance", "spp", "albedo", "normal", "depth", "position", "object_id", "motion",
                      "emission"})
WALLS = {"red": (0.7, 0.1, 0.1), "green": (0.1, 0.6, 0.1), "white": (0.7, 0.7, 0.7)}

BOX_XML = """<scene version="3.0.0">
  <bsdf type="diffuse" id="white"><rgb name="reflectance" value="0.7, 0.7, 0.7"/></bsdf>
  <bsdf type="diffuse" id="red"><rgb name="reflectance" value="0.7, 0.1, 0.1"/></bsdf>
  <bsdf type="diffuse" id="green"><rgb name="reflectance" value="0.1, 0.6, 0.1"/></bsdf>
  <shape type="rectangle" id="floor">
    <transform name="to_world"><rotate x="1" angle="-90"/><translate y="-1"/></transform><ref id="white"/>
  </shape>
  <shape type="rectangle" id="ceiling">
    <transform name="to_world"><rotate x="1" angle="90"/><translate y="1"/></transform><ref id="white"/>
  </shape>
  <shape type="rectangle" id="back">
    <transform name="to_world"><translate z="-1"/></transform><ref id="white"/>
  </shape>
  <shape type="rectangle" id="left">
    <transform name="to_world"><rotate y="1" angle="90"/><translate x="-1"/></transform><ref id="red"/>
  </shape>
  <shape type="rectangle" id="right">
    <transform name="to_world"><rotate y="1" angle="-90"/><translate x="1"/></transform><ref id="green"/>
  </shape>
  <shape type="rectangle" id="lamp">
    <transform name="to_world"><rotate x="1" angle="90"/><scale value="0.35"/><translate y="0.98"/></transform>
    <emitter type="area"><rgb name="radiance" value="12, 12, 12"/></emitter>
  </shape>
  <shape type="cube">
    <transform name="to_world"><scale value="0.3"/><rotate y="1" angle="25"/><translate x="0.3" y="-0.7" z="-0.2"/>
    </transform><ref id="white"/>
  </shape>
  <shape type="obj" id="panel">
    <string name="filename" value="panel.obj"/><ref id="green"/>
  </shape>
  <sensor type="perspective">
    <float name="fov" value="50"/>
    <transform name="to_world"><lookat origin="0, 0, 3.4" target="0, 0, 0" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="32"/><integer name="height" value="24"/></film>
  </sensor>
</scene>
"""


# a square on the back wall; its last vertex is used by no face (Mitsuba's own bounding box of the
# mesh holds it, the scene plugin's mesh does not)
PANEL_OBJ = """v -0.6 0.0 -0.99
v -0.2 0.0 -0.99
v -0.2 0.4 -0.99
v -0.6 0.4 -0.99
v 5.0 5.0 5.0
f 1 2 3
f 1 3 4
"""


def write_box_scene(folder):
    """Write the diffuse test box (``scene.xml``, ``panel.obj``) into ``folder`` and return the folder."""
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "scene.xml").write_text(BOX_XML)
    (folder / "panel.obj").write_text(PANEL_OBJ)
    return folder


def box_scene(folder, resolution=(32, 24)):
    """The test box loaded by the Mitsuba scene plugin at ``resolution``."""
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        scene = load(write_box_scene(folder))
    return dataclasses.replace(scene, resolution=resolution)


def animated(scene, frames=3):
    """The box with a camera moving right and the cube moving left, ``frames`` frames."""
    eye = scene.camera.eye(0)
    target = scene.camera.positions[0] + scene.camera.basis(0)[2]
    shift = np.array([0.08, 0.0, 0.0])
    camera = CameraPath(positions=[eye + k * shift for k in range(frames)],
                        targets=[target + k * shift for k in range(frames)], up=scene.camera.up,
                        fov=scene.camera.fov)
    objects = list(scene.objects)
    cube = next(k for k, o in enumerate(objects) if o.name.startswith("shape"))
    moves = np.stack([np.eye(4)] * frames)
    moves[:, 0, 3] = -0.1 * np.arange(frames)
    objects[cube] = dataclasses.replace(objects[cube], transforms=moves)
    return dataclasses.replace(scene, camera=camera, objects=objects, frame_count=frames), cube


@pytest.fixture(scope="module")
def box(tmp_path_factory):
    return box_scene(tmp_path_factory.mktemp("mitsuba-box"))


@pytest.fixture(scope="module")
def scalar():
    return MitsubaRenderer(variant="scalar")


@pytest.fixture(scope="module")
def jit():
    renderer = MitsubaRenderer()
    if renderer.variant == "scalar_rgb":
        pytest.skip("no JIT variant works here (see docs/mitsuba.md: libLLVM)")
    return renderer


# ---------------------------------------------------------------- fast tier (scalar_rgb)
def test_registered_with_its_declarations():
    spec = load_plugins().renderers["mitsuba"]
    assert spec.provides == PROVIDED
    assert spec.references and spec.adaptive and spec.chunked
    assert spec.scene_kinds == frozenset({"mesh"}) and spec.tasks == frozenset({"denoise"})


def test_scalar_frame_channels_and_conventions(box, scalar):
    frame = scalar.render(box, 0, spp=2, seed=3, channels=PROVIDED)
    assert frame.channels == PROVIDED and frame.shape == (24, 32)
    for name in PROVIDED:
        assert frame[name].dtype == CHANNELS[name][1], name
    hit = frame["object_id"] >= 0
    assert 0.5 < hit.mean() < 1.0  # the open front of the box shows background
    np.testing.assert_allclose(np.linalg.norm(frame["normal"][hit], axis=-1), 1.0, atol=1e-5)
    assert np.isinf(frame["depth"][~hit]).all() and (frame["normal"][~hit] == 0).all()
    ids = {box.objects[k].name for k in np.unique(frame["object_id"][hit])}
    assert ids == {"floor", "ceiling", "back", "left", "right", "lamp", "panel"} | {
        o.name for o in box.objects if o.name.startswith("shape")}
    red = frame["object_id"] == [o.name for o in box.objects].index("left")
    np.testing.assert_allclose(frame["albedo"][red], np.broadcast_to(WALLS["red"], frame["albedo"][red].shape),
                               rtol=1e-5)
    lamp = frame["object_id"] == [o.name for o in box.objects].index("lamp")
    np.testing.assert_allclose(frame["emission"][lamp], 12.0, rtol=1e-5)
    assert (frame["emission"][~lamp] == 0).all()
    assert (frame["spp"] == 2).all() and (frame["motion"] == 0).all()


def test_scalar_seeds_reproducible_and_independent(box, scalar):
    a = scalar.render(box, 0, spp=1, seed=1)["color"]
    assert np.array_equal(a, scalar.render(box, 0, spp=1, seed=1)["color"])
    b = scalar.render(box, 0, spp=1, seed=2)["color"]
    lit = a.mean(-1) > 0
    assert np.mean(a[lit] != b[lit]) > 0.5


def test_scalar_chunks_add_up(box, scalar):
    whole = scalar.accumulate(box, 0, first_sample=0, count=6, seed=4)
    parts = scalar.accumulate(box, 0, first_sample=0, count=2, seed=4) + scalar.accumulate(
        box, 0, first_sample=2, count=4, seed=4)
    np.testing.assert_allclose(parts, whole, rtol=1e-12, atol=1e-12)
    np.testing.assert_allclose(scalar.reference(box, 0, spp=6, seed=4), (whole / 6).astype(np.float32))


def test_lane_batches_cover_every_sample_once():
    start = np.array([0, 5, 2, 0])
    counts = np.array([3, 0, 1, 4])
    lanes = [(p, s) for pixels, samples in lane_batches(start, counts, 3) for p, s in zip(pixels, samples)]
    assert sorted(lanes) == sorted((p, start[p] + j) for p in range(4) for j in range(counts[p]))
    assert all(len(pixels) <= 3 for pixels, _ in lane_batches(start, counts, 3))


def test_stream_keys_differ_by_seed_frame_purpose():
    keys = {base_key(s, f, p) for s in range(3) for f in range(3) for p in (1, 2)}
    assert len(keys) == 18
    assert image_seed(keys.pop(), 0) != image_seed(base_key(0, 0, 1), 1)


def test_not_a_mitsuba_scene_is_one_line_error(box, scalar):
    other = dataclasses.replace(box, params={})
    with pytest.raises(ValueError, match="Mitsuba XML") as err:
        scalar.render(other, 0)
    assert "\n" not in str(err.value)


def test_bad_variant_is_an_error():
    with pytest.raises(VariantError, match="variant must be one of"):
        MitsubaRenderer(variant="opengl")


def test_variant_from_the_environment(monkeypatch):
    monkeypatch.setenv("DENOISE_MITSUBA_VARIANT", "scalar")
    renderer = MitsubaRenderer()
    assert renderer.variant == "scalar_rgb" and renderer.settings()["variant"] == "scalar_rgb"


def test_probe_survives_a_broken_llvm(tmp_path):
    broken = tmp_path / "libLLVM-99.so"
    broken.write_bytes(b"not a library")
    assert probe("llvm_ad_rgb", str(broken)) is False


# ---------------------------------------------------------------- slow tier (JIT variant)
@pytest.mark.slow
def test_rays_are_the_harness_pixel_centre_rays(box, jit):
    frame = jit.render(box, 0, spp=1, seed=0, channels={"position", "object_id", "depth"})
    hit = frame["object_id"] >= 0
    origins, dirs = box.camera.primary_rays(0, 32, 24)
    seen = frame["position"] - origins
    seen /= np.linalg.norm(seen, axis=-1, keepdims=True)
    np.testing.assert_allclose(seen[hit], dirs[hit], atol=2e-5)
    forward = box.camera.basis(0)[2]
    np.testing.assert_allclose(frame["depth"][hit], ((frame["position"] - origins) @ forward)[hit], rtol=1e-5)


@pytest.mark.slow
def test_jit_and_scalar_gbuffers_agree(box, jit, scalar):
    channels = {"position", "normal", "albedo", "depth", "object_id", "emission"}
    a = jit.render(box, 0, spp=1, channels=channels)
    b = scalar.render(box, 0, spp=1, channels=channels)
    same = a["object_id"] == b["object_id"]
    assert same.mean() > 0.97  # rays along the box's edges may fall on either face (1.6% here)
    for name in channels - {"object_id"}:
        np.testing.assert_allclose(a[name][same], b[name][same], atol=1e-4, err_msg=name)


@pytest.mark.slow
def test_samples_do_not_depend_on_batching(box, jit):
    whole = jit.accumulate(box, 0, first_sample=0, count=6, seed=9)
    engine = jit.loaded(box).engine
    saved = engine.max_lanes
    try:
        engine.max_lanes = 100  # other batches, other lane positions: the same samples
        again = jit.accumulate(box, 0, first_sample=0, count=6, seed=9)
    finally:
        engine.max_lanes = saved
    np.testing.assert_allclose(again, whole, rtol=1e-12, atol=1e-12)
    parts = jit.accumulate(box, 0, first_sample=0, count=1, seed=9) + jit.accumulate(
        box, 0, first_sample=1, count=5, seed=9)
    np.testing.assert_allclose(parts, whole, rtol=1e-12, atol=1e-12)
    assert not np.allclose(jit.accumulate(box, 0, first_sample=6, count=6, seed=9), whole)


@pytest.mark.slow
def test_adaptive_sampler_continues_the_streams(box, jit):
    sampler = jit.sampler(box, 0, spp=2, seed=5, channels={"variance"})
    extra = np.zeros((24, 32), np.int32)
    extra[:, :16] = 3
    frame = sampler.add_samples(extra)
    assert sampler.samples_used == 2 * 32 * 24 + 3 * 16 * 24
    whole = jit.render(box, 0, spp=5, seed=5)["color"]
    np.testing.assert_allclose(frame["color"][:, :16], whole[:, :16], rtol=1e-6, atol=1e-7)
    assert (frame["spp"][:, :16] == 5).all() and (frame["spp"][:, 16:] == 2).all()


@pytest.mark.slow
def test_variance_matches_the_spread_over_seeds(box, jit):
    """The variance channel (own samples at 4 spp; the independent set at 1 spp) estimates the
    variance of the pixel mean: its average over pixels is within 15% of the spread of the
    colour over 48 seeds."""
    for spp in (4, 1):
        frames = [jit.render(box, 0, spp=spp, seed=s, channels={"variance"}) for s in range(48)]
        colors = np.stack([f["color"] for f in frames]).astype(np.float64)
        empirical = colors.var(axis=0, ddof=1)
        stated = np.mean([f["variance"] for f in frames], axis=0)
        lit = colors.mean(0).mean(-1) > 0.05
        ratio = stated[lit].mean() / empirical[lit].mean()
        assert 0.85 < ratio < 1.15, (spp, ratio)
    one = jit.render(box, 0, spp=1, seed=0, channels={"variance"})
    assert np.array_equal(one["variance"], jit.render(box, 0, spp=1, seed=0, channels={"variance"})["variance"])
    assert not np.array_equal(one["variance"], jit.render(box, 0, spp=1, seed=1, channels={"variance"})["variance"])


@pytest.mark.slow
def test_camera_path_and_object_motion(box, jit):
    scene, cube = animated(box)
    channels = {"position", "object_id", "motion", "depth"}
    f0, f1 = (jit.render(scene, k, spp=1, channels=channels) for k in (0, 1))
    assert np.abs(f1["motion"]).max() > 0.5
    # the cube really moved: its points in frame 1, moved back 0.1 to the right, lie on its rest surface
    # (the XML's cube: half size 0.3, turned 25 degrees about y, centred at (0.3, -0.7, -0.2))
    for frame, shift in ((f0, 0.0), (f1, 0.1)):
        points = frame["position"][frame["object_id"] == cube] + [shift, 0.0, 0.0] - [0.3, -0.7, -0.2]
        turn = np.radians(25.0)
        local_x = np.cos(turn) * points[:, 0] - np.sin(turn) * points[:, 2]
        local_z = np.sin(turn) * points[:, 0] + np.cos(turn) * points[:, 2]
        extent = np.max(np.abs([local_x, points[:, 1], local_z]), axis=0) / 0.3
        assert len(points) > 10
        np.testing.assert_allclose(extent, 1.0, atol=1e-4)
    # following the motion vector of a static surface lands on the same point in frame 0
    ii, jj = np.mgrid[0:24, 0:32]
    x = np.rint(jj + f1["motion"][..., 0]).astype(int)
    y = np.rint(ii + f1["motion"][..., 1]).astype(int)
    inside = (x >= 0) & (x < 32) & (y >= 0) & (y < 24) & (f1["object_id"] >= 0) & (f1["object_id"] != cube)
    same = inside & (f0["object_id"][y.clip(0, 23), x.clip(0, 31)] == f1["object_id"])
    assert same.mean() > 0.6
    gap = np.linalg.norm(f0["position"][y[same], x[same]] - f1["position"][same], axis=-1)
    assert np.median(gap) < 0.05


@pytest.mark.slow
def test_area_references_integrate_the_pixel_as_mitsuba_does(box, jit):
    """References over the pixel area converge to Mitsuba's own ``mi.render`` (box filter, uniform
    points in the pixel); pixel-centre references differ from it at the edges, by more than the noise."""
    import mitsuba as mi

    from plugins.renderers.mitsuba.camera import sensor
    from plugins.renderers.mitsuba.variants import active

    spp = 512
    area = jit.reference(box, 0, spp=spp, seed=3).astype(np.float64)
    centre = MitsubaRenderer(variant=jit.variant, reference_pixel="centre").reference(
        box, 0, spp=spp, seed=3).astype(np.float64)
    loaded, view = jit.loaded(box), jit.setup(box, 0).view
    with active(mi, jit.variant):
        theirs = np.array(mi.render(loaded.engine.scene, sensor=sensor(mi, view), integrator=loaded.engine.integrator,
                                    spp=spp, seed=11), np.float64)[..., :3]
    error_area = np.mean((area - theirs) ** 2)
    error_centre = np.mean((centre - theirs) ** 2)
    assert error_area < 0.5 * error_centre, (error_area, error_centre)
    np.testing.assert_allclose(area.mean(), theirs.mean(), rtol=0.01)
    with pytest.raises(ValueError, match="reference_pixel"):
        MitsubaRenderer(variant="scalar", reference_pixel="corner")


def test_files_outside_the_scene_folder_are_refused(tmp_path, monkeypatch):
    """A scene file changed after loading to name a mesh outside its folder (or through a default) is
    refused in one line, unless the scene plugin's variable allows it."""
    scene = box_scene(tmp_path / "room")
    (tmp_path / "panel.obj").write_text(PANEL_OBJ)
    xml = tmp_path / "room" / "scene.xml"
    for named in ('"../panel.obj"', '"$mesh"'):
        text = BOX_XML.replace('"panel.obj"', named).replace('<scene version="3.0.0">', '<scene version="3.0.0">'
                                                             '<default name="mesh" value="../panel.obj"/>')
        xml.write_text(text)
        with pytest.raises(ValueError, match="outside the scene folder") as err:
            MitsubaRenderer(variant="scalar").render(scene, 0)
        assert "\n" not in str(err.value)
    monkeypatch.setenv("DENOISE_HARNESS_ALLOW_OUTSIDE_FILES", "1")
    assert MitsubaRenderer(variant="scalar").render(scene, 0)["color"].shape == (24, 32, 3)


def test_every_shape_has_its_own_id_and_its_objects_index(box, scalar):
    """Shapes map to the scene plugin's objects through its record (``params["shapes"]``): named
    shapes to the object of that name, unnamed ones (the cube) to ``shape<k>``; all ids distinct."""
    loaded = scalar.loaded(box)
    assert len(set(loaded.ids.values())) == len(loaded.ids) == 8 and loaded.unmatched == 0
    names = {obj.name: k for k, obj in enumerate(box.objects)}
    for shape in ("floor", "ceiling", "back", "left", "right", "lamp", "panel"):
        assert loaded.ids[shape] == names[shape]
    assert loaded.ids["harness_shape_6"] == names["shape6"]
