"""The captured renderer: exact round trips, bad captures, sidecar checks, conventions, presets."""

from __future__ import annotations

import json
import shutil
import warnings

import numpy as np
import pytest

from harness import CHANNELS, CameraPath, NonFiniteError, load_plugins, read_channels, write_capture, write_channels
from harness.exr import layer_channels
from harness.nonfinite import apply_nonfinite_policy
from plugins.renderers.captured import CaptureError, CaptureWarning, open_capture
from plugins.renderers.captured import conventions as conv
from tests.pathtracer_scenes import box_scene

ALL = frozenset(CHANNELS)
SIZE = (24, 16)  # (width, height)


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def synthetic(registry):
    """Three frames of ``synthetic-moving`` (every channel) and their references."""
    scene = registry.get("scene", "synthetic-moving").factory()
    renderer = registry.get("renderer", "synthetic").factory()
    frames = [renderer.render(scene, t, spp=2, seed=3, channels=ALL, resolution=SIZE) for t in range(3)]
    refs = [renderer.reference(scene, t, resolution=SIZE) for t in range(3)]
    return frames, refs


def assert_same_frame(got, want):
    assert got.channels == want.channels
    for name in want.channels:
        assert got[name].dtype == want[name].dtype and got[name].shape == want[name].shape, name
        assert got[name].tobytes() == want[name].tobytes(), name
    assert got.meta.to_dict() == want.meta.to_dict()


def ingest(registry, folder, frames, spp):
    scene = registry.open_scene(folder)
    renderer = registry.get("renderer", "captured").factory()
    got = [renderer.render(scene, t, spp=spp, channels=ALL, resolution=scene.resolution) for t in range(len(frames))]
    return scene, renderer, got


def test_registered_with_its_declarations(registry):
    spec = registry.get("renderer", "captured")
    assert spec.provides == ALL
    assert spec.scene_kinds == frozenset({"captured"})
    assert spec.references and not spec.adaptive and not spec.chunked
    assert spec.tasks == frozenset({"denoise"})


def test_synthetic_export_then_ingest_is_bit_exact(registry, synthetic, tmp_path):
    frames, refs = synthetic
    write_capture(tmp_path / "cap", frames, refs, spp=2)
    scene, renderer, got = ingest(registry, tmp_path / "cap", frames, spp=2)
    assert scene.kind == "captured" and scene.name == "synthetic-moving"
    assert scene.frame_count == 3 and scene.resolution == SIZE
    assert scene.params["channels"] == sorted(ALL)
    for g, f in zip(got, frames):
        assert_same_frame(g, f)
    for t in range(3):
        assert renderer.reference(scene, t, resolution=SIZE).tobytes() == refs[t].tobytes()


def test_pathtracer_export_then_ingest_is_bit_exact(registry, tmp_path):
    scene = box_scene(size=(16, 12))
    renderer = registry.get("renderer", "pathtracer").factory()
    frames = [renderer.render(scene, t, spp=2, seed=7, channels=ALL) for t in range(2)]
    refs = [renderer.reference(scene, t, spp=4, seed=1) for t in range(2)]
    assert frames[1].meta.view_proj is not None
    write_capture(tmp_path / "street", frames, refs, spp=2, reference_spp=4, tags=sorted(scene.tags))
    captured, reader, got = ingest(registry, tmp_path / "street", frames, spp=2)
    assert captured.tags >= scene.tags
    for g, f in zip(got, frames):
        assert_same_frame(g, f)
    assert reader.reference(captured, 1).tobytes() == np.asarray(refs[1], np.float32).tobytes()


def test_scene_hash_follows_the_files(registry, synthetic, tmp_path):
    frames, refs = synthetic
    write_capture(tmp_path / "a", frames[:1], refs[:1])
    shutil.copytree(tmp_path / "a", tmp_path / "b")
    first = registry.open_scene(tmp_path / "a").content_hash()
    assert registry.open_scene(tmp_path / "b").content_hash() == first  # the folder's place does not count
    changed = frames[0].replace(color=frames[0]["color"] + np.float32(1))
    write_capture(tmp_path / "b", [changed], refs[:1])
    assert registry.open_scene(tmp_path / "b").content_hash() != first


def test_missing_channels_are_not_provided(registry, synthetic, tmp_path):
    frames, _ = synthetic
    write_capture(tmp_path / "cap", [f.subset({"albedo"}) for f in frames])
    scene = registry.open_scene(tmp_path / "cap")
    assert scene.params["channels"] == ["albedo", "color"]
    assert scene.params["references"] is False
    renderer = registry.get("renderer", "captured").factory()
    frame = renderer.render(scene, 0, channels={"albedo", "normal", "motion"})
    assert frame.channels == {"color", "albedo"}
    with pytest.raises(ValueError, match="no references"):
        renderer.reference(scene, 0)


def test_serving_limits(registry, synthetic, tmp_path):
    frames, refs = synthetic
    write_capture(tmp_path / "cap", frames, refs, spp=2)
    scene = registry.open_scene(tmp_path / "cap")
    renderer = registry.get("renderer", "captured").factory()
    with pytest.raises(ValueError, match="--spp 2"):
        renderer.render(scene, 0, spp=1)
    with pytest.raises(ValueError, match="cannot be served at 48x32"):
        renderer.render(scene, 0, spp=2, resolution=(48, 32))
    with pytest.raises(ValueError, match="frames 0..2"):
        renderer.render(scene, 3, spp=2)


def test_open_scene_ignores_folders_without_a_sidecar(tmp_path):
    assert open_capture(tmp_path) is None


# ------------------------------------------------------------------------------ bad captures
def _bad_missing_frame(folder):
    (folder / "frames" / "0002.exr").unlink()
    return "open", "0002.exr: missing file"


def _bad_sizes(folder):
    # one file per AOV: the albedo files are smaller than the colour
    data = json.loads((folder / "capture.json").read_text())
    data["channels"]["albedo"] = {"file": "albedo/{frame:04d}.exr", "layer": ""}
    (folder / "capture.json").write_text(json.dumps(data))
    for t in range(3):
        write_channels(folder / "albedo" / f"{t:04d}.exr", {c: np.zeros((8, 12), np.float32) for c in "RGB"})
    return "open", "0000.exr: 12x8 pixels, but the colour of frame 0 is 24x16"


def _bad_layer(folder):
    data = json.loads((folder / "capture.json").read_text())
    data["channels"]["albedo"] = "diffuse_albedo"
    (folder / "capture.json").write_text(json.dumps(data))
    return "open", "0000.exr: no layer 'diffuse_albedo' for channel 'albedo'; layers in the file: ["


def _bad_unreadable(folder):
    (folder / "frames" / "0001.exr").write_bytes(b"\x76\x2f\x31\x01 this is not an EXR")
    return "open", "0001.exr: unreadable"


def _bad_truncated(folder):
    path = folder / "frames" / "0001.exr"
    path.write_bytes(path.read_bytes()[:-600])
    return "render", "0001.exr: unreadable"


def _bad_reference_missing(folder):
    (folder / "reference" / "0001.exr").unlink()
    return "open", "reference/0001.exr: missing file"


def _bad_fractional_id(folder):
    path = folder / "frames" / "0001.exr"
    channels, _ = read_channels(path)
    channels["object_id.Y"] = channels["object_id.Y"] + np.float32(0.5)
    write_channels(path, channels)
    return "render", "0001.exr: layer 'object_id' (object_id): 384 non-integer value(s)"


BAD = {
    "missing-frame": _bad_missing_frame,
    "aov-sizes-differ": _bad_sizes,
    "absent-layer": _bad_layer,
    "unreadable-file": _bad_unreadable,
    "truncated-file": _bad_truncated,
    "missing-reference": _bad_reference_missing,
    "fractional-object-id": _bad_fractional_id,
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_capture_one_line_naming_file_and_problem(registry, synthetic, tmp_path, case):
    frames, refs = synthetic
    folder = tmp_path / "cap"
    write_capture(folder, frames, refs, spp=2)
    stage, expected = BAD[case](folder)
    with pytest.raises(CaptureError) as info:
        scene = open_capture(folder)
        assert stage == "render", "expected opening to fail"
        registry.get("renderer", "captured").factory().render(scene, 1, spp=2, channels=ALL)
    message = str(info.value)
    assert "\n" not in message
    assert str(folder) in message
    assert expected in message


def test_nonfinite_values_are_kept_reported_and_left_to_the_policy(registry, synthetic, tmp_path):
    frames, refs = synthetic
    folder = tmp_path / "cap"
    write_capture(folder, frames, refs, spp=2)
    path = folder / "frames" / "0001.exr"
    channels, _ = read_channels(path)
    channels["color.G"][2, 3] = np.nan
    channels["normal.X"][0, 0] = np.inf
    write_channels(path, channels)
    scene = open_capture(folder)
    renderer = registry.get("renderer", "captured").factory()
    with pytest.warns(CaptureWarning) as record:
        frame = renderer.render(scene, 1, spp=2, channels=ALL)
    messages = sorted(str(w.message) for w in record)
    assert len(messages) == 2 and all("\n" not in m and str(path) in m for m in messages)
    assert "layer 'color' (color) holds 1 non-finite value(s) (1 NaN, 0 Inf)" in messages[0]
    assert "layer 'normal' (normal) holds 1 non-finite value(s) (0 NaN, 1 Inf)" in messages[1]
    assert np.isnan(frame["color"][2, 3, 1]) and np.isposinf(frame["normal"][0, 0, 0])  # kept as read
    with pytest.raises(NonFiniteError, match="2 non-finite"):
        apply_nonfinite_policy(frame, "raise", owner="renderer 'captured'")
    repaired, count = apply_nonfinite_policy(frame, "repair")
    assert count == 2 and np.isfinite(repaired["color"]).all()
    with warnings.catch_warnings():
        warnings.simplefilter("error")
        renderer.render(scene, 0, spp=2, channels=ALL)  # background depth (+inf) is not reported


# ------------------------------------------------------------------------------ sidecar checks
def _sidecar(folder, text, name="capture.toml"):
    (folder / name).write_text(text)
    return folder


SIDECAR_ERRORS = {
    "unknown-key": ('frames = 1\ncolour = "x"\n', "unknown key(s) ['colour']"),
    "no-frames": ('file = "a.exr"\n', "'frames' must be a positive integer"),
    "unknown-preset": ('frames = 1\npreset = "unreal"\n', "unknown preset 'unreal'"),
    "unknown-channel": ('frames = 1\nfile = "a.exr"\n[channels]\nbeauty = "x"\n', "unknown channel(s) ['beauty']"),
    "bad-convention": ('frames = 1\nfile = "a.exr"\n[conventions]\nmotion_y = "sideways"\n',
                       "convention 'motion_y' must be one of ['down', 'up']"),
    "unknown-convention": ('frames = 1\nfile = "a.exr"\n[conventions]\nhandedness = "left"\n',
                           "unknown convention 'handedness'"),
    "ray-distance-without-fov": ('frames = 1\nfile = "a.exr"\n[conventions]\ndepth = "ray_distance"\n',
                                 "needs the camera's field of view"),
    "camera-normals-without-view": ('frames = 1\nfile = "a.exr"\n[conventions]\nnormal_space = "camera"\n',
                                    "camera-space normals need"),
    "ndc-without-near-far": ('frames = 1\nfile = "a.exr"\n[conventions]\ndepth = "ndc_gl"\n', "'near' and 'far'"),
    "no-color": ('frames = 1\nfile = "a.exr"\n[channels]\ncolor = false\n', "no source for the 'color' channel"),
    "bad-components": ('frames = 1\nfile = "a.exr"\n[channels]\nmotion = { layer = "v", components = ["X"] }\n',
                       "must list 2 component name(s)"),
    "frame-entries": ('frames = 2\nfile = "a.exr"\n[[frame]]\nseed = 1\n', "'frame' has 1 entries for 2 frames"),
    "invalid-toml": ('frames = = 1\n', "not valid TOML"),
}


@pytest.mark.parametrize("case", sorted(SIDECAR_ERRORS))
def test_sidecar_errors_name_the_sidecar(tmp_path, case):
    text, expected = SIDECAR_ERRORS[case]
    _sidecar(tmp_path, text)
    with pytest.raises(CaptureError) as info:
        open_capture(tmp_path)
    message = str(info.value)
    assert "\n" not in message and str(tmp_path / "capture.toml") in message and expected in message


def test_invalid_json_sidecar(tmp_path):
    _sidecar(tmp_path, "{frames: 1", name="capture.json")
    with pytest.raises(CaptureError, match="not valid JSON"):
        open_capture(tmp_path)


# ------------------------------------------------------------------------------ conventions
def _write_layers(path, arrays: dict):
    """Write harness-shaped arrays under the given layer names (components as the harness writes)."""
    planes = {}
    for (layer, channel), array in arrays.items():
        planes.update(layer_channels(layer, channel, array))
    write_channels(path, planes)


def test_foreign_conventions_convert_to_the_harness(registry, synthetic, tmp_path):
    """Bottom-left origin, a velocity in UV units with y up, camera-space normals: back to the harness."""
    frames, _ = synthetic
    frame = frames[2]
    h, w = frame.shape
    view = CameraPath(positions=[(1.0, 2.0, 3.0)], targets=[(0.2, 0.5, -1.0)]).view_matrix(0)
    velocity = -frame["motion"].astype(np.float64) / (w, h) * (1.0, -1.0)
    normal_cam = frame["normal"].astype(np.float64) @ view[:3, :3].T
    stored = {
        ("beauty", "color"): frame["color"][::-1],
        ("mv", "motion"): velocity.astype(np.float32)[::-1],
        ("N", "normal"): normal_cam.astype(np.float32)[::-1],
        ("Z", "depth"): frame["depth"][::-1],
    }
    _write_layers(tmp_path / "img.0007.exr", stored)
    _sidecar(tmp_path, f'''frames = 1
first_frame = 7
file = "img.{{frame:04d}}.exr"
[channels]
color = "beauty"
motion = "mv"
normal = "N"
depth = "Z"
[conventions]
origin = "bottom_left"
motion_vector = "current_minus_previous"
motion_units = "uv"
motion_y = "up"
normal_space = "camera"
[camera]
view = {json.dumps(view.tolist())}
''')
    scene = open_capture(tmp_path)
    got = registry.get("renderer", "captured").factory().render(scene, 0, channels=ALL)
    assert got["color"].tobytes() == frame["color"].tobytes()
    assert got["depth"].tobytes() == frame["depth"].tobytes()
    np.testing.assert_allclose(got["motion"], frame["motion"], atol=1e-4)
    hit = np.linalg.norm(frame["normal"], axis=-1) > 0
    np.testing.assert_allclose(got["normal"][hit], frame["normal"][hit], atol=1e-6)


@pytest.mark.parametrize("axis", ["fov_y", "fov_x"])
def test_ray_distance_to_view_z_matches_the_harness_camera(axis):
    w, h = 32, 20
    cam = CameraPath(positions=[(0.0, 0.0, 0.0)], targets=[(0.0, 0.0, -1.0)], fov=50.0)
    _, dirs = cam.primary_rays(0, w, h)
    cos = -dirs[..., 2]  # the camera looks down -z
    view_z = np.linspace(1.0, 9.0, w * h).reshape(h, w)
    ray = (view_z / cos).astype(np.float32)
    ray[0, 0] = 0.0  # Mitsuba's background marker
    fov_y = 50.0
    fov_x = float(np.degrees(2 * np.arctan(np.tan(np.radians(fov_y) / 2) * w / h)))
    camera = {"fov_y": fov_y} if axis == "fov_y" else {"fov_x": fov_x}
    conventions = {"depth": "ray_distance", "depth_background": 0.0}
    got = conv.depth(ray, conventions, camera)
    assert np.isposinf(got[0, 0])
    np.testing.assert_allclose(got.ravel()[1:], view_z.ravel()[1:], rtol=2e-6)


@pytest.mark.parametrize("kind", ["ndc_gl", "ndc_d3d"])
def test_ndc_depth_to_view_z(kind):
    near, far = 0.1, 50.0
    cam = CameraPath(positions=[(0.0, 0.0, 0.0)], targets=[(0.0, 0.0, -1.0)], near=near, far=far)
    proj = cam.projection_matrix(4, 4)
    view_z = np.array([[0.2, 1.0, 7.5, 49.0]])
    clip_z = proj[2, 2] * -view_z + proj[2, 3]
    ndc = clip_z / view_z  # clip w = view z
    if kind == "ndc_d3d":
        ndc = ndc * 0.5 + 0.5
    got = conv.depth(ndc.astype(np.float32), {"depth": kind}, {"near": near, "far": far})
    np.testing.assert_allclose(got, view_z, rtol=1e-5)


def test_acescg_white_stays_white_and_variance_is_refused(tmp_path, registry):
    white = conv.color(np.ones((1, 1, 3), np.float32), "acescg")
    np.testing.assert_allclose(white, 1.0, atol=1e-4)
    _write_layers(tmp_path / "f.exr", {("c", "color"): np.ones((2, 2, 3), np.float32),
                                       ("v", "variance"): np.ones((2, 2, 3), np.float32)})
    _sidecar(tmp_path, 'frames = 1\nfile = "f.exr"\n[channels]\ncolor = "c"\nvariance = "v"\n'
                       '[conventions]\ncolor_space = "acescg"\n')
    scene = open_capture(tmp_path)
    with pytest.raises(CaptureError, match="covariances"):
        registry.get("renderer", "captured").factory().render(scene, 0, channels={"variance"})


# ------------------------------------------------------------------------------ presets
def test_blender_preset(registry, synthetic, tmp_path):
    """Blender's multi-layer names, 1-based numbering, 1e10 background depth, y-up pixel vectors."""
    frame = synthetic[0][1]
    depth = np.where(np.isinf(frame["depth"]), np.float32(1e10), frame["depth"])
    vector = np.concatenate([frame["motion"] * np.float32([1, -1]), np.zeros_like(frame["motion"])], axis=-1)
    planes = {}
    for layer, array, comps in [
        ("ViewLayer.Combined", np.concatenate([frame["color"], np.ones_like(frame["depth"])[..., None]], -1), "RGBA"),
        ("ViewLayer.Denoising Albedo", frame["albedo"], "RGB"),
        ("ViewLayer.Normal", frame["normal"], "XYZ"),
        ("ViewLayer.Depth", depth[..., None], "Z"),
        ("ViewLayer.Vector", vector, "XYZW"),
    ]:
        planes.update({f"{layer}.{c}": array[..., k] for k, c in enumerate(comps)})
    write_channels(tmp_path / "0001.exr", planes)
    _sidecar(tmp_path, 'preset = "blender"\nframes = 1\n')
    scene = open_capture(tmp_path)
    assert scene.params["channels"] == ["albedo", "color", "depth", "motion", "normal"]  # no position etc.
    got = registry.get("renderer", "captured").factory().render(scene, 0, channels=ALL)
    for name in ("color", "albedo", "normal", "depth", "motion"):
        assert got[name].tobytes() == frame[name].tobytes(), name


def test_falcor_preset_one_file_per_output(registry, synthetic, tmp_path):
    frame = synthetic[0][2]
    h, w = frame.shape
    rgba = {c: np.ones((h, w), np.float32) for c in "RGBA"}

    def write(output, array):
        planes = dict(rgba)
        planes.update({c: array[..., k] for k, c in enumerate("RGBA"[: array.shape[-1]])})
        write_channels(tmp_path / f"Mogwai.{output}.120.exr", planes)

    write("PathTracer.color", frame["color"])
    write("GBufferRT.mvec", (frame["motion"] / np.float32([w, h])).astype(np.float32))
    write("GBufferRT.linearZ", np.stack([frame["depth"], np.zeros_like(frame["depth"])], -1))
    _sidecar(tmp_path, 'preset = "falcor"\nframes = 1\nfirst_frame = 120\n')
    scene = open_capture(tmp_path)
    assert scene.params["channels"] == ["color", "depth", "motion"]
    got = registry.get("renderer", "captured").factory().render(scene, 0, channels=ALL)
    assert got["color"].tobytes() == frame["color"].tobytes()
    assert got["depth"].tobytes() == frame["depth"].tobytes()
    np.testing.assert_allclose(got["motion"], frame["motion"], atol=1e-5)


def test_preset_channels_are_optional_but_sidecar_channels_required(tmp_path):
    write_channels(tmp_path / "0001.exr", {f"ViewLayer.Combined.{c}": np.zeros((2, 2), np.float32) for c in "RGB"})
    _sidecar(tmp_path, 'preset = "blender"\nframes = 1\n')
    assert open_capture(tmp_path).params["channels"] == ["color"]
    _sidecar(tmp_path, 'preset = "blender"\nframes = 1\n[channels]\nnormal = "ViewLayer.Normal"\n')
    with pytest.raises(CaptureError, match="no layer 'ViewLayer.Normal' for channel 'normal'"):
        open_capture(tmp_path)


def test_a_deterministic_renderer_runs_one_seed_and_says_so(registry, synthetic, tmp_path):
    """Captured frames are the same for every seed: three seeds were three runs of one input and
    zero-width intervals. The planner runs the first seed and says so in one line."""
    from harness.plan import make_plan
    from harness.renders import RenderStore, scene_selection

    assert registry.get("renderer", "captured").deterministic
    assert not registry.get("renderer", "synthetic").deterministic
    frames, refs = synthetic
    write_capture(tmp_path / "cap", frames, refs, spp=2)
    store = RenderStore(registry)
    specs = scene_selection(registry, store, ["synthetic-edges"], [tmp_path / "cap"], ["denoise"])
    plan = make_plan(registry, store, specs, ["passthrough"], ["ssim"], spp=(2,), seeds=(0, 1, 2), frames=1)
    seeds = {(j.scene, j.seed) for j in plan.jobs}
    assert seeds == {("synthetic-edges", 0), ("synthetic-edges", 1), ("synthetic-edges", 2), ("synthetic-moving", 0)}
    assert plan.notes == ["scene 'synthetic-moving': renderer 'captured' returns the same frames for every seed: "
                          "one seed (0) instead of 3"]
