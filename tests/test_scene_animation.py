"""Mitsuba scenes as sequences: the animation.toml sidecar, the generated default path, exact motion.

A small room (a closed box lit by a ceiling light, a textured floor and back wall, a box that
moves) written to a temporary folder; the shared third-party scenes where ``../shared/scenes``
exists (slow).
"""

from __future__ import annotations

import dataclasses
import textwrap
import warnings
from pathlib import Path

import numpy as np
import pytest

from harness import CameraPath, load_plugins
from plugins.scenes.mitsuba import MitsubaWarning, load
from plugins.scenes.mitsuba.animation import DEFAULT_FRAMES, eased
from plugins.scenes.mitsuba.camera_path import DOLLY_FRACTION, PAN, RaysFrom, crossings, scene_bounds
from tests.conftest import cli

ROOT = Path(__file__).resolve().parents[1]
SHARED = ROOT.parent / "shared" / "scenes"

ROOM_XML = """\
<?xml version="1.0"?>
<scene version="0.6.0">
  <texture type="bitmap" id="checker"><string name="filename" value="checker.png"/></texture>
  <bsdf type="diffuse" id="Floor"><ref name="reflectance" id="checker"/></bsdf>
  <bsdf type="diffuse" id="Grey"><rgb name="reflectance" value="0.5, 0.5, 0.5"/></bsdf>
  <bsdf type="diffuse" id="Red"><rgb name="reflectance" value="0.8, 0.1, 0.1"/></bsdf>
  <sensor type="perspective">
    <float name="fov" value="60"/><string name="fovAxis" value="x"/>
    <transform name="toWorld"><lookat origin="0, 1.5, 3" target="0, 1.2, -5" up="0, 1, 0"/></transform>
    <film type="hdrfilm"><integer name="width" value="96"/><integer name="height" value="54"/></film>
  </sensor>
  <shape type="cube"><transform name="toWorld"><scale x="5" y="3" z="5"/><translate y="2.99"/></transform>
    <ref id="Grey"/></shape>
  <shape type="obj"><string name="filename" value="floor.obj"/><ref id="Floor"/></shape>
  <shape type="obj"><string name="filename" value="wall.obj"/><ref id="Floor"/></shape>
  <shape type="cube" id="box"><transform name="toWorld"><scale value="0.5"/><translate x="1" y="0.5" z="-1"/>
    </transform><ref id="Red"/></shape>
  <shape type="rectangle"><transform name="toWorld"><rotate x="1" angle="90"/><translate y="5.9"/></transform>
    <emitter type="area"><rgb name="radiance" value="10, 10, 10"/></emitter></shape>
  <emitter type="constant"><rgb name="radiance" value="1, 1, 1"/></emitter>
</scene>
"""


def quad_obj(corners) -> str:
    lines = [f"v {x} {y} {z}" for x, y, z in corners]
    lines += ["vt 0 0", "vt 1 0", "vt 1 1", "vt 0 1", "f 1/1 2/2 3/3 4/4"]
    return "\n".join(lines) + "\n"


ANIMATION = """\
frames = 8
[camera]
ease = "in-out"
[[camera.keys]]
frame = 0
[[camera.keys]]
frame = 7
position = [0.6, 1.7, 2.2]
target = [0.4, 1.2, -5.0]
fov = 40.0
[[shapes]]
name = "box"
[[shapes.keys]]
frame = 0
[[shapes.keys]]
frame = 7
translate = [-1.0, 0.0, 0.6]
rotate = [0, 1, 0, 40]
"""


@pytest.fixture
def room(tmp_path):
    return write_room(tmp_path / "room")


def write_room(folder: Path) -> Path:
    """The small room's scene folder (scene.xml, two OBJ quads, a texture) at ``folder``."""
    import OpenImageIO as oiio

    folder.mkdir()
    (folder / "scene.xml").write_text(ROOM_XML)
    (folder / "floor.obj").write_text(quad_obj([(-5, 0, 5), (5, 0, 5), (5, 0, -5), (-5, 0, -5)]))
    (folder / "wall.obj").write_text(quad_obj([(-5, 0, -4.99), (5, 0, -4.99), (5, 6, -4.99), (-5, 6, -4.99)]))
    # a smooth plaid (4 periods across): warping by the motion resamples it with little error, while
    # a one-pixel shift changes it everywhere
    y, x = np.indices((256, 256)) * (2 * np.pi / 64)
    plaid = 0.5 + 0.45 * np.sin(x) * np.sin(y)
    image = np.stack([plaid, 0.5 + 0.45 * np.sin(x + 1.0), 0.5 + 0.45 * np.sin(y + 2.0)], axis=2)
    image = np.round(255 * image).astype(np.uint8)
    out = oiio.ImageOutput.create(str(folder / "checker.png"))
    out.open(str(folder / "checker.png"), oiio.ImageSpec(256, 256, 3, "uint8"))
    out.write_image(image)
    out.close()
    return folder


def quiet_load(path, **kw):
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        return load(path, **kw)


def test_keyframed_camera_and_shape_follow_the_sidecar(room):
    (room / "animation.toml").write_text(ANIMATION)
    scene = quiet_load(room)
    assert scene.frame_count == 8 and "dynamic" in scene.tags and "moving_objects" in scene.tags
    cam = scene.camera
    assert cam.positions.shape == (8, 3) and cam.targets.shape == (8, 3)
    np.testing.assert_allclose(cam.eye(0), [0, 1.5, 3])  # the first key takes the sensor's pose
    np.testing.assert_allclose(cam.eye(7), [0.6, 1.7, 2.2])
    np.testing.assert_allclose(cam.targets[7], [0.4, 1.2, -5.0])
    # in-out easing: smoothstep of s = t / 7
    s = 3 / 7
    e = s * s * (3 - 2 * s)
    np.testing.assert_allclose(cam.eye(3), (1 - e) * np.array([0, 1.5, 3]) + e * np.array([0.6, 1.7, 2.2]))
    sensor_fov = np.degrees(2 * np.arctan(np.tan(np.radians(30)) * 54 / 96))
    assert cam.fov_at(0) == pytest.approx(sensor_fov) and cam.fov_at(7) == pytest.approx(40.0)
    assert cam.fov_at(3) == pytest.approx((1 - e) * sensor_fov + e * 40.0)
    assert cam.ups is None  # no roll given: one up for all frames
    # the box: shape named by its id, translated and turned about its own centre
    (box_index,) = [k for k, o in enumerate(scene.objects) if o.name == "box"]
    box = scene.objects[box_index]
    assert box.transforms.shape == (8, 4, 4)
    np.testing.assert_allclose(box.transform(0), np.eye(4), atol=1e-12)
    centre = np.array([1.0, 0.5, -1.0])
    moved = box.transform(7) @ np.append(centre, 1.0)
    np.testing.assert_allclose(moved[:3], centre + [-1.0, 0.0, 0.6], atol=1e-12)
    angle = np.degrees(np.arctan2(box.transform(7)[0, 2], box.transform(7)[0, 0]))
    assert angle == pytest.approx(40.0)
    assert all(o.transforms is None for o in scene.objects if o.name != "box")
    # objects map to their elements: shape<k> for shapes without an id
    assert [s["object"] for s in scene.params["shapes"]] == ["shape0", "shape1", "shape2", "box", "shape4"]
    assert [s["element"] for s in scene.params["shapes"]] == [0, 1, 2, 3, 4]
    assert scene.params["animation"]["camera"] == "keyframes"


def test_easings():
    s = np.linspace(0, 1, 5)
    np.testing.assert_allclose(eased(s, "linear"), s)
    np.testing.assert_allclose(eased(s, "in"), s * s)
    np.testing.assert_allclose(eased(s, "out"), 1 - (1 - s) ** 2)
    np.testing.assert_allclose(eased(0.5, "in-out"), 0.5)


def test_default_path_dollies_and_pans_inside_the_room(room):
    scene = quiet_load(room)
    assert scene.frame_count == DEFAULT_FRAMES and scene.params["animation"]["camera"] == "default path"
    cam = scene.camera
    eyes = cam.positions
    np.testing.assert_allclose(eyes[0], [0, 1.5, 3])
    soup = scene.triangles(0)
    low, high = scene_bounds(soup.vertices, eyes[0])
    assert ((eyes >= low) & (eyes <= high)).all()
    assert (np.linalg.norm(np.diff(eyes, axis=0), axis=1) > 0).all()  # moves on every frame
    assert crossings(eyes, soup.vertices) == []
    record = scene.params["animation"]["default_path"]
    assert record["direction"] == "forward" and abs(record["pan_degrees"]) == PAN
    # the dolly keeps the camera in front of the nearest surface ahead: at most DOLLY_FRACTION of it
    forward = cam.basis(0)[2]
    ahead = RaysFrom(eyes[0], soup.vertices).closest(forward)[0]
    assert 0 < record["dolly"] <= DOLLY_FRACTION * ahead + 1e-9
    np.testing.assert_allclose(np.linalg.norm(eyes[-1] - eyes[0]), record["dolly"])
    turned = np.degrees(np.arccos(np.clip(np.dot(cam.basis(0)[2], cam.basis(DEFAULT_FRAMES - 1)[2]), -1, 1)))
    assert turned == pytest.approx(PAN, abs=0.5)


def test_default_path_stops_short_of_a_near_wall(room):
    """A camera 1 unit from the back wall: the dolly turns away from it, or covers at most 0.3 units."""
    xml = ROOM_XML.replace('origin="0, 1.5, 3" target="0, 1.2, -5"', 'origin="0, 1.5, -3.99" target="0, 1.5, -5"')
    (room / "scene.xml").write_text(xml)
    scene = quiet_load(room)
    eyes = scene.camera.positions
    record = scene.params["animation"]["default_path"]
    if record["direction"] == "forward":
        assert np.linalg.norm(eyes[-1] - eyes[0]) <= DOLLY_FRACTION * 1.0 + 1e-6
    assert (eyes[:, 2] > -4.99).all()
    assert crossings(eyes, scene.triangles(0).vertices) == []


LEAVING = ANIMATION.replace("position = [0.6, 1.7, 2.2]", "position = [0.6, 1.7, 9.0]")


def test_a_path_leaving_the_bounds_is_refused_in_one_line(room):
    (room / "animation.toml").write_text(LEAVING)
    registry = load_plugins()
    with pytest.raises(ValueError, match=r"leaves the scene bounds at frame 3: eye \(") as info:
        registry.open_scene(room)
    assert "\n" not in str(info.value) and "animation.toml" in str(info.value)


def test_the_cli_refuses_a_path_leaving_the_bounds_with_exit_status_2(room, tmp_path):
    (room / "animation.toml").write_text(LEAVING)
    run = cli(["run", "--scene-dir", room, "--filters", "passthrough", "--out", tmp_path / "out", "--no-cache",
               "--quiet"], check=False)
    assert run.returncode == 2, run.stderr
    lines = [line for line in run.stderr.splitlines() if "warning" not in line]
    assert len(lines) == 1 and "leaves the scene bounds" in lines[0], run.stderr


@pytest.mark.parametrize("change, message", [
    ("frame = 7\nposition", "unknown key"),
    ('name = "box"', "names no object"),
    ("frames = 8", "past the last frame"),
    ('ease = "in-out"', "must be one of"),
])
def test_bad_sidecars_are_one_line_errors(room, change, message):
    broken = {
        "frame = 7\nposition": "frame = 7\nspeed = 3\nposition",
        'name = "box"': 'name = "no-such-shape"',
        "frames = 8": "frames = 6",
        'ease = "in-out"': 'ease = "bouncy"',
    }[change]
    (room / "animation.toml").write_text(ANIMATION.replace(change, broken, 1))
    with pytest.raises(ValueError, match=message) as info:
        quiet_load(room)
    assert "animation.toml" in str(info.value) and "\n" not in str(info.value)


def test_a_sidecar_folder_animates_a_scene_kept_elsewhere(room, tmp_path):
    mine = tmp_path / "my-room"
    mine.mkdir()
    (mine / "animation.toml").write_text(f'scene = "../room/scene.xml"\n{ANIMATION}')
    registry = load_plugins()
    with warnings.catch_warnings():
        warnings.simplefilter("ignore", MitsubaWarning)
        scene = registry.open_scene(mine)
    assert scene.name == "my-room" and scene.frame_count == 8
    np.testing.assert_allclose(scene.camera.eye(7), [0.6, 1.7, 2.2])


def reference(raster, scene, t, size, what: str) -> np.ndarray:
    """Frame ``t``'s 4x4-supersampled ``color`` (the raster renderer's reference) or ``albedo``
    (rendered at 4x the size and box-filtered)."""
    if what == "color":
        return raster.reference(scene, t, spp=16, resolution=size)
    w, h = size
    big = raster.render(scene, t, channels={"albedo"}, resolution=(4 * w, 4 * h))["albedo"]
    return big.reshape(h, 4, w, 4, 3).mean(axis=(1, 3))


def reprojection_errors(scene, frames, size, what: str = "color"):
    """(error of the warped previous reference, error of the unwarped one, share of pixels kept) over
    the pixels that are not disoccluded, for each frame t of ``frames``.

    Motion and object ids from the path tracer's G-buffer (pixel-centre first hits); the images
    are the raster renderer's 4x4-supersampled references (deterministic), of ``what``: ``color``
    (its local shading, view-independent where nothing is glossy) or ``albedo``. A pixel is
    disoccluded when its surface point, moved back to frame t-1 with its object's motion, falls
    outside the image or is not what frame t-1 sees there (another object, or a point farther
    than 1% of its depth from the one seen).
    """
    registry = load_plugins()
    tracer = registry.get("renderer", "pathtracer").factory(max_depth=1)
    raster = registry.get("renderer", "raster").factory()
    w, h = size
    channels = {"motion", "object_id", "position", "depth"}
    out = []
    for t in frames:
        now = tracer.render(scene, t, channels=channels, resolution=size)
        before = tracer.render(scene, t - 1, channels=channels, resolution=size)
        ref_now, ref_before = (reference(raster, scene, k, size, what).astype(np.float64) for k in (t, t - 1))
        ii, jj = np.mgrid[0:h, 0:w]
        x = jj + now["motion"][..., 0]
        y = ii + now["motion"][..., 1]
        x0, y0 = np.floor(x).astype(int), np.floor(y).astype(int)
        inside = (x0 >= 0) & (y0 >= 0) & (x0 + 1 < w) & (y0 + 1 < h)
        x0c, y0c = np.clip(x0, 0, w - 2), np.clip(y0, 0, h - 2)
        oid = now["object_id"]
        same = inside & (oid >= 0)
        for dy in (0, 1):
            for dx in (0, 1):
                same &= before["object_id"][y0c + dy, x0c + dx] == oid
        # the surface point moved back to t-1 against what t-1 sees at the nearest pixel
        moved = now["position"].astype(np.float64).copy()
        for k, obj in enumerate(scene.objects):
            if obj.transforms is not None and (oid == k).any():
                m = obj.transform(t - 1) @ np.linalg.inv(obj.transform(t))
                moved[oid == k] = moved[oid == k] @ m[:3, :3].T + m[:3, 3]
        xr, yr = np.clip(np.rint(x).astype(int), 0, w - 1), np.clip(np.rint(y).astype(int), 0, h - 1)
        seen = before["position"][yr, xr].astype(np.float64)
        near = np.linalg.norm(seen - moved, axis=-1) <= 0.01 * np.maximum(now["depth"], 1e-6) + 0.02
        kept = same & near
        fx, fy = (x - x0c)[..., None], (y - y0c)[..., None]
        warped = ((1 - fy) * ((1 - fx) * ref_before[y0c, x0c] + fx * ref_before[y0c, x0c + 1])
                  + fy * ((1 - fx) * ref_before[y0c + 1, x0c] + fx * ref_before[y0c + 1, x0c + 1]))
        err_warped = np.abs(warped - ref_now)[kept].mean()
        err_still = np.abs(ref_before - ref_now)[kept].mean()
        moving = np.linalg.norm(now["motion"], axis=-1) > 0.05
        out.append((err_warped, err_still, kept.mean(), moving.mean()))
    return out


def test_motion_vectors_warp_the_previous_reference_onto_the_frame(room):
    """Exact motion (camera and the moving box): the previous frame's reference, warped by the motion
    vectors, matches the frame on every pixel that is not disoccluded, far better than unwarped."""
    (room / "animation.toml").write_text(ANIMATION)
    scene = quiet_load(room)
    for err_warped, err_still, kept, moving in reprojection_errors(scene, [4], (80, 45)):
        assert moving > 0.95 and kept > 0.6
        assert err_warped < 0.15 * err_still, (err_warped, err_still)


@pytest.mark.slow
@pytest.mark.parametrize("name", ["classroom", "living-room", "sponza"])
def test_shared_scene_default_path_moves_every_pixel_with_exact_motion(name):
    """The default path of a shared scene moves every pixel, and its motion vectors warp the previous
    frame onto the next. The scenes' detail is finer than a pixel, which bilinear resampling cannot
    move exactly, so the check takes the path every 4th frame (a step of four frames' motion, about
    2 pixels at 192x108) and the albedo (the local shading of glossy materials changes with the
    view, which no warp can follow)."""
    folder = SHARED / name
    if not (folder / "scene.xml").is_file():
        pytest.skip(f"third-party scene folder {folder} is absent")
    scene = quiet_load(folder)
    assert scene.frame_count == DEFAULT_FRAMES
    cam = scene.camera
    eyes = cam.positions
    low, high = scene_bounds(scene.triangles(0).vertices, eyes[0])
    assert ((eyes >= low) & (eyes <= high)).all()
    step = CameraPath(positions=eyes[::4], targets=cam.targets[::4], up=cam.up, fov=cam.fov, near=cam.near,
                      far=cam.far)
    every_fourth = dataclasses.replace(scene, camera=step, frame_count=len(step.positions))
    for err_warped, err_still, kept, moving in reprojection_errors(every_fourth, [3], (192, 108), "albedo"):
        assert moving > 0.95 and kept > 0.5
        assert err_warped < 0.5 * err_still, (err_warped, err_still)


@pytest.mark.slow
def test_example_sidecars_of_the_shared_scenes():
    """examples/animations/<name>/animation.toml: each loads its shared scene with its keyframes."""
    registry = load_plugins()
    found = 0
    for folder in sorted((ROOT / "examples" / "animations").iterdir()):
        text = (folder / "animation.toml").read_text()
        assert "scene = " in text and "[[camera.keys]]" in text
        if not (SHARED / folder.name / "scene.xml").is_file():
            continue
        found += 1
        with warnings.catch_warnings():
            warnings.simplefilter("ignore", MitsubaWarning)
            scene = registry.open_scene(folder)
        assert scene.name == folder.name and scene.frame_count > 1
        assert scene.params["animation"]["camera"] == "keyframes"
    if not found:
        pytest.skip("no shared scene folder beside the project: the examples were only parsed")


def test_registered_shared_scenes_declare_their_frames():
    registry = load_plugins()
    for name in ("classroom", "living-room", "sponza"):
        spec = registry.get("scene", name)
        assert spec.tier == "real" and spec.frames == DEFAULT_FRAMES and "dynamic" in spec.tags


def test_sidecar_text_in_the_docs_parses(tmp_path):
    """The format's example in plugins/scenes/mitsuba/animation.py is valid TOML the parser accepts."""
    from plugins.scenes.mitsuba import animation

    doc = animation.__doc__
    block = textwrap.dedent(doc[doc.index("::") + 2: doc.index("Between two keys")]).strip()
    path = tmp_path / "animation.toml"
    path.write_text(block)
    parsed = animation.read(path)
    assert parsed.frames == 24 and len(parsed.camera_keys) == 2 and parsed.shapes[0].name == "shape12"
