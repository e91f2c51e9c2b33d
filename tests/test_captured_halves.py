"""The captured renderer's half-buffers (issue 32): the colour is their mean, the variance is
served from them (unbiased, smoothed, guarded), bad sidecars are one-line errors, and SBF and LBF
denoise a path-traced capture better with that variance than with their spatial estimate."""

from __future__ import annotations

import importlib.util
import sys

import numpy as np
import pytest

from harness import load_plugins, write_channels
from plugins.renderers.captured import CaptureError, open_capture
from plugins.renderers.captured import conventions as conv
from plugins.renderers.captured.halves import half_variance, mean_of_halves, pair_variance
from tests.conftest import ROOT

SIDECAR = '''frames = {frames}
file = "frames/{{frame:04d}}.exr"
[channels]
color_halves = {halves}
albedo = "albedo"
normal = "normal"
{extra}'''
#: the line of ``color_halves`` in :data:`SIDECAR`
HALVES_LINE = 4


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


def rgb(layer: str, image: np.ndarray, names="RGB") -> dict:
    """The planes of an (H, W, 3) image as layer ``layer`` (``""``: unprefixed)."""
    prefix = f"{layer}." if layer else ""
    return {f"{prefix}{c}": np.ascontiguousarray(image[..., i], dtype=np.float32) for i, c in enumerate(names)}


def guides(height: int, width: int, albedo=None) -> dict:
    """Unit normals facing the camera and an albedo (grey 0.5 unless given) as planes."""
    normal = np.zeros((height, width, 3), np.float32)
    normal[..., 2] = 1.0
    albedo = np.full((height, width, 3), 0.5, np.float32) if albedo is None else albedo
    return {**rgb("albedo", albedo), **rgb("normal", normal, "XYZ")}


def write(folder, planes_by_frame, *, halves='["half_a", "half_b"]', extra="", files=None):
    """A capture folder: ``frames/{t:04d}.exr`` holding the given planes, the sidecar, other files."""
    (folder / "frames").mkdir(parents=True, exist_ok=True)
    for t, planes in enumerate(planes_by_frame):
        write_channels(folder / "frames" / f"{t:04d}.exr", planes)
    for name, planes in (files or {}).items():
        (folder / name).parent.mkdir(parents=True, exist_ok=True)
        write_channels(folder / name, planes)
    sidecar = folder / "capture.toml"
    sidecar.write_text(SIDECAR.format(frames=len(planes_by_frame), halves=halves, extra=extra))
    return sidecar


def serve(registry, folder, channels=frozenset({"color", "variance"}), t=0):
    scene = registry.open_scene(folder)
    return scene, registry.get("renderer", "captured").factory().render(scene, t, channels=channels)


# ------------------------------------------------------------------------- the served variance
#: per quadrant (row-major) and channel, the standard deviation of one half-buffer's pixel value
SIGMA_HALF = np.array([[0.1, 0.2, 0.05], [1.0, 0.5, 2.0], [0.01, 0.02, 0.03], [3.0, 3.0, 3.0]])
QUADRANT = 64


def quadrant(q: int) -> tuple:
    """Rows and columns of quadrant ``q`` (row-major) of the 128x128 frame."""
    return (slice((q // 2) * QUADRANT, (q // 2 + 1) * QUADRANT), slice((q % 2) * QUADRANT, (q % 2 + 1) * QUADRANT))


def quadrant_capture(folder, rng, noise="gaussian"):
    """Two half-buffers of a 128x128 frame of four quadrants, each with its own albedo, mean and
    noise (known standard deviation per quadrant and channel); returns them and the true
    variance of their mean."""
    size = 2 * QUADRANT
    sigma = np.zeros((size, size, 3))
    level = np.zeros((size, size, 3))
    albedo = np.zeros((size, size, 3), np.float32)
    for q in range(4):
        rows, cols = quadrant(q)
        sigma[rows, cols] = SIGMA_HALF[q]
        level[rows, cols] = 1.0 + q
        albedo[rows, cols] = 0.2 + 0.2 * q
    if noise == "gaussian":
        draw = lambda: rng.standard_normal((size, size, 3))  # noqa: E731
    else:  # exponential, heavy-tailed, mean 0 and variance 1
        draw = lambda: rng.exponential(1.0, (size, size, 3)) - 1.0  # noqa: E731
    a = (level + sigma * draw()).astype(np.float32)
    b = (level + sigma * draw()).astype(np.float32)
    write(folder, [{**rgb("half_a", a), **rgb("half_b", b), **guides(size, size, albedo)}])
    return a, b, sigma**2 / 2.0  # Var(mean of two halves) = Var(half) / 2


@pytest.mark.parametrize("noise", ["gaussian", "exponential"])
def test_served_variance_is_unbiased_per_region(registry, tmp_path, noise):
    """Mean over each quadrant and channel of the served variance equals the true variance of the
    mean within 5 standard errors of the one-pair estimate (its 4096 values per quadrant), for
    Gaussian and heavy-tailed noise; the albedo guide keeps the quadrants apart at their borders."""
    rng = np.random.default_rng(20261128)
    _, _, true = quadrant_capture(tmp_path, rng, noise)
    scene, frame = serve(registry, tmp_path)
    assert scene.params["channels"] == ["albedo", "color", "normal", "variance"]
    served = frame["variance"]
    assert served.dtype == np.float32 and np.isfinite(served).all()
    # relative standard error of a mean of n one-pair estimates: sqrt(2 / n) (Gaussian), sqrt((kurtosis - 1) / n)
    # with the kurtosis of a - b (Gaussian 3; the difference of two exponentials: 6)
    n = QUADRANT * QUADRANT
    tolerance = 5.0 * np.sqrt((2.0 if noise == "gaussian" else 5.0) / n)
    for q in range(4):
        rows, cols = quadrant(q)
        ratio = served[rows, cols].astype(np.float64).mean(axis=(0, 1)) / true[rows, cols].mean(axis=(0, 1))
        assert np.all(np.abs(ratio - 1.0) < tolerance), (q, ratio, tolerance)


def test_the_unbiasedness_check_can_fail(tmp_path):
    """The bound of the test above rejects a variance off by 2x (the estimator without the 1/2 of
    Var(mean) = Var(half) / 2) and the plain 5x5 box that mixes the quadrants at their borders."""
    rng = np.random.default_rng(20261128)
    a, b, true = quadrant_capture(tmp_path, rng)
    tolerance = 5.0 * np.sqrt(2.0 / (QUADRANT * QUADRANT))
    wrong_scale = half_variance(a, b) * 2.0
    low = (slice(QUADRANT, 2 * QUADRANT), slice(0, QUADRANT))  # quadrant 2, sigma 0.01..0.03, beside sigma 3
    assert np.all(np.abs(wrong_scale[low].mean(axis=(0, 1)) / true[low].mean(axis=(0, 1)) - 1.0) > tolerance)
    box = half_variance(a, b)  # no guides: the window crosses into quadrants 0 and 3
    assert np.all(box[low].astype(np.float64).mean(axis=(0, 1)) / true[low].mean(axis=(0, 1)) > 10.0)


def test_the_window_reduces_the_estimates_noise(registry, tmp_path):
    """One pair gives a relative spread of sqrt(2) (Gaussian); the 5x5 window brings it below 0.4."""
    rng = np.random.default_rng(7)
    a, b, true = quadrant_capture(tmp_path, rng)
    _, frame = serve(registry, tmp_path)
    inner = (slice(2, QUADRANT - 2), slice(2, QUADRANT - 2))
    raw = pair_variance(a, b)[inner] / true[inner]
    served = frame["variance"][inner] / true[inner]
    assert 1.2 < raw.std() < 1.6
    assert served.std() < 0.4
    assert abs(served.mean() - 1.0) < 0.1


# ------------------------------------------------------------------------------- the colour
def test_colour_is_the_mean_of_the_halves(registry, tmp_path):
    rng = np.random.default_rng(3)
    a = rng.uniform(0, 4, (8, 12, 3)).astype(np.float32)
    b = rng.uniform(0, 4, (8, 12, 3)).astype(np.float32)
    write(tmp_path / "derived", [{**rgb("half_a", a), **rgb("half_b", b), **guides(8, 12)}])
    _, frame = serve(registry, tmp_path / "derived", channels=frozenset())
    want = ((a.astype(np.float64) + b.astype(np.float64)) / 2.0).astype(np.float32)
    assert frame.channels == {"color"}
    assert frame["color"].tobytes() == want.tobytes()
    assert mean_of_halves(a, b).tobytes() == want.tobytes()
    # a stored colour equal to the mean in float32 arithmetic is accepted and served as stored
    stored = (a + b) / np.float32(2)
    write(tmp_path / "given", [{**rgb("half_a", a), **rgb("half_b", b), **rgb("color", stored), **guides(8, 12)}],
          extra='color = "color"\n')
    _, frame = serve(registry, tmp_path / "given")
    assert frame["color"].tobytes() == stored.tobytes()
    assert frame.channels == {"color", "variance"}


def test_a_preset_colour_gives_way_to_the_halves_and_json_sidecars_name_their_line(registry, tmp_path):
    """With the blender preset, whose colour is ViewLayer.Combined, halves and no ``color`` in the
    sidecar: the colour is the halves' mean (the preset's layer is neither read nor checked)."""
    a, b = _halves()
    write_channels(tmp_path / "0001.exr", {**rgb("ViewLayer.Combined", a * 5), **rgb("half_a", a), **rgb("half_b", b)})
    (tmp_path / "capture.toml").write_text(
        'preset = "blender"\nframes = 1\n[channels]\ncolor_halves = ["half_a", "half_b"]\n')
    _, frame = serve(registry, tmp_path)
    assert frame["color"].tobytes() == mean_of_halves(a, b).tobytes()
    json_folder = tmp_path / "json"
    (json_folder / "frames").mkdir(parents=True)
    write_channels(json_folder / "frames" / "0000.exr", _planes(a, b, **rgb("color", a)))
    (json_folder / "capture.json").write_text(
        '{\n  "frames": 1,\n  "file": "frames/{frame:04d}.exr",\n  "channels": {\n    "color": "color",\n'
        '    "color_halves": ["half_a", "half_b"]\n  }\n}\n')
    with pytest.raises(CaptureError, match=r"capture\.json:6: frame 0: the colour is not the mean"):
        open_capture(json_folder)


def test_halves_follow_the_colour_conventions(registry, tmp_path):
    """ACEScg halves stored bottom row first serve the same colour and variance as the same halves
    converted to linear sRGB and stored top row first (the variance is taken after conversion)."""
    rng = np.random.default_rng(5)
    a = rng.uniform(0, 2, (6, 10, 3)).astype(np.float32)
    b = rng.uniform(0, 2, (6, 10, 3)).astype(np.float32)
    halves = '["half_a", "half_b"]'
    sidecar = 'frames = 1\nfile = "frames/{frame:04d}.exr"\n[channels]\ncolor_halves = ' + halves + "\n"
    srgb = [conv.color(conv.flip_rows(h), "acescg") for h in (a, b)]
    foreign = '[conventions]\ncolor_space = "acescg"\norigin = "bottom_left"\n'
    for name, (first, second), extra in (("aces", (a, b), foreign), ("lin", srgb, "")):
        (tmp_path / name / "frames").mkdir(parents=True)
        write_channels(tmp_path / name / "frames" / "0000.exr", {**rgb("half_a", first), **rgb("half_b", second)})
        (tmp_path / name / "capture.toml").write_text(sidecar + extra)  # no guides: a plain 5x5 window
    _, got = serve(registry, tmp_path / "aces")
    _, want = serve(registry, tmp_path / "lin")
    np.testing.assert_allclose(got["color"], want["color"], rtol=1e-6)
    np.testing.assert_allclose(got["variance"], want["variance"], rtol=1e-5)
    np.testing.assert_allclose(got["variance"], half_variance(*srgb), rtol=1e-6)


def test_halves_are_part_of_the_scene_identity(registry, tmp_path):
    rng = np.random.default_rng(9)
    a, b = (rng.uniform(0, 1, (4, 6, 3)).astype(np.float32) for _ in range(2))
    write(tmp_path, [{**rgb("half_a", a), **rgb("half_b", b), **guides(4, 6)}])
    scene = registry.open_scene(tmp_path)
    assert scene.params["capture"]["color_halves"] == [
        {"file": "frames/{frame:04d}.exr", "layer": "half_a", "components": None},
        {"file": "frames/{frame:04d}.exr", "layer": "half_b", "components": None},
    ]
    first = scene.content_hash()
    write_channels(tmp_path / "frames" / "0000.exr", {**rgb("half_a", a), **rgb("half_b", b * 2), **guides(4, 6)})
    assert registry.open_scene(tmp_path).content_hash() != first


# ------------------------------------------------------------------------------ bad captures
def _halves(h=8, w=12, seed=0):
    rng = np.random.default_rng(seed)
    return [rng.uniform(0, 1, (h, w, 3)).astype(np.float32) for _ in range(2)]


def _planes(a, b, **more):
    return {**rgb("half_a", a), **rgb("half_b", b), **guides(*a.shape[:2]), **more}


def _bad_half_file_missing(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='["half_a", { file = "other/{frame:04d}.exr", layer = "" }]')
    return "open", f"{HALVES_LINE}", "other/0000.exr: missing file for frame 0 (the colour's half-buffer"


def _bad_half_layer_missing(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='["half_a", "half_c"]')
    return "open", f"{HALVES_LINE}", "no layer 'half_c' for channel 'color_halves[1]'"


def _bad_half_in_a_later_frame(folder):
    a, b = _halves()
    write(folder, [_planes(a, b), _planes(a, b)], halves='["half_a", { file = "b/{frame:04d}.exr", layer = "" }]',
          files={"b/0000.exr": rgb("", b)})
    return "open", f"{HALVES_LINE}", "b/0001.exr: missing file for frame 1"


def _bad_one_source(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='["half_a"]')
    return "open", "", "'color_halves' must list two sources of the colour"


def _bad_same_source_twice(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='["half_a", "half_a"]')
    return "open", "", "they must be two independent renders"


def _bad_shapes_differ(folder):
    a, _ = _halves()
    _, b = _halves(6, 10)
    write(folder, [_planes(a, a)], halves='["half_a", { file = "b/{frame:04d}.exr", layer = "" }]',
          files={"b/0000.exr": rgb("", b)})
    return "open", f"{HALVES_LINE}", "b/0000.exr: 10x6 pixels, but the colour of frame 0 is 12x8"


def _bad_colour_is_not_the_mean(folder):
    a, b = _halves()
    colour = mean_of_halves(a, b)
    colour[3, 5, 1] += np.float32(1e-3)
    write(folder, [_planes(a, b, **rgb("color", colour))], extra='color = "color"\n')
    return "open", f"{HALVES_LINE}", "not the mean of the two half-buffers in 1 value(s) (e.g. pixel x=5 y=3"


def _bad_colour_rounded_to_half(folder):
    a, b = _halves()
    colour = mean_of_halves(a, b).astype(np.float16).astype(np.float32)
    write(folder, [_planes(a, b, **rgb("color", colour))], extra='color = "color"\n')
    return "open", f"{HALVES_LINE}", "the colour is not the mean of the two half-buffers"


def _bad_colour_in_a_later_frame(folder):
    a, b = _halves()
    good = _planes(a, b, **rgb("color", mean_of_halves(a, b)))
    bad = _planes(a, b, **rgb("color", mean_of_halves(a, b) + np.float32(0.5)))
    write(folder, [good, bad], extra='color = "color"\n')
    return "render", f"{HALVES_LINE}", "frame 1: the colour is not the mean of the two half-buffers in 288 value(s)"


def _bad_variance_too(folder):
    a, b = _halves()
    write(folder, [_planes(a, b, **rgb("variance", a))], extra='variance = "variance"\n')
    return "open", "", "give either a 'variance' channel or 'color_halves'"


def _bad_outside_the_folder(folder):
    a, b = _halves()
    write_channels(folder.parent / "elsewhere.exr", rgb("", b))
    write(folder, [_planes(a, b)], halves='["half_a", { file = "../elsewhere.exr", layer = "" }]')
    return "open", f"{HALVES_LINE}", "'../elsewhere.exr' of the colour's half-buffer 'color_halves[1]' is outside"


def _bad_pattern(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='["half_a", { file = "{frame.real}.exr", layer = "" }]')
    return "open", "", "may only hold {frame} or an integer format of it"


def _bad_not_a_list(folder):
    a, b = _halves()
    write(folder, [_planes(a, b)], halves='"half_a"')
    return "open", "", "'color_halves' must list two sources"


BAD = {
    "half-file-missing": _bad_half_file_missing,
    "half-layer-missing": _bad_half_layer_missing,
    "half-missing-in-a-later-frame": _bad_half_in_a_later_frame,
    "one-source": _bad_one_source,
    "same-source-twice": _bad_same_source_twice,
    "shapes-differ": _bad_shapes_differ,
    "colour-not-the-mean": _bad_colour_is_not_the_mean,
    "colour-rounded-to-half": _bad_colour_rounded_to_half,
    "colour-not-the-mean-in-frame-1": _bad_colour_in_a_later_frame,
    "variance-and-halves": _bad_variance_too,
    "outside-the-folder": _bad_outside_the_folder,
    "bad-pattern": _bad_pattern,
    "not-a-list": _bad_not_a_list,
}


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_halves_one_line_naming_the_sidecar(registry, tmp_path, case):
    folder = tmp_path / "cap"
    stage, line, expected = BAD[case](folder)
    with pytest.raises(CaptureError) as info:
        scene = open_capture(folder)
        assert stage == "render", "expected opening to fail"
        registry.get("renderer", "captured").factory().render(scene, 1, channels={"variance"})
    message = str(info.value)
    assert "\n" not in message
    assert message.startswith(f"{folder / 'capture.toml'}:{line}" if line else f"{folder / 'capture.toml'}: ")
    assert expected in message


# --------------------------------------------------------------------------------- numerics
def test_variance_guards():
    rng = np.random.default_rng(11)
    # finite extremes: the pair estimate (2e30)^2 / 4 passes float32 max and is clipped, never inf
    a = np.where(rng.random((9, 7, 3)) < 0.5, 1e30, -1e30).astype(np.float32)
    b = -a
    out = half_variance(a, b)
    assert out.dtype == np.float32 and np.isfinite(out).all() and (out > 0).all()
    # float32 max and subnormals
    a = np.full((5, 5, 3), np.finfo(np.float32).max, np.float32)
    assert np.isfinite(half_variance(a, -a)).all()
    tiny = np.full((5, 5, 3), 1e-45, np.float32)
    assert np.isfinite(half_variance(tiny, -tiny)).all()
    # zero noise: zero variance; constant halves: zero
    c = np.full((4, 4, 3), 0.25, np.float32)
    assert not half_variance(c, c).any()
    # tiny and degenerate frames
    for shape in ((1, 1, 3), (1, 7, 3), (7, 1, 3), (2, 2, 3)):
        a, b = (rng.uniform(0, 1, shape).astype(np.float32) for _ in range(2))
        out = half_variance(a, b)
        assert out.shape == shape and np.isfinite(out).all()
    a, b = (rng.uniform(0, 1, (1, 1, 3)).astype(np.float32) for _ in range(2))
    np.testing.assert_allclose(half_variance(a, b), pair_variance(a, b), rtol=1e-6)


def test_a_non_finite_half_stays_in_its_pixel():
    rng = np.random.default_rng(12)
    a, b = (rng.uniform(0, 1, (9, 9, 3)).astype(np.float32) for _ in range(2))
    broken = a.copy()
    broken[4, 4, 0] = np.nan
    out = half_variance(broken, b)
    assert np.isnan(out[4, 4, 0])
    finite = np.ones((9, 9), bool)
    finite[4, 4] = False
    assert np.isfinite(out[finite]).all()
    # the neighbours average their finite estimates only: as if the pixel were not there
    apart = a.copy()
    apart[4, 4] = b[4, 4]  # a zero estimate there, but still counted: different from leaving it out
    assert not np.allclose(out[3, 3], half_variance(apart, b)[3, 3])
    inf_half = a.copy()
    inf_half[0, 0] = np.inf
    assert np.isfinite(half_variance(inf_half, b)[1:, 1:]).all()


def test_broken_guides_keep_the_variance_finite():
    rng = np.random.default_rng(13)
    a, b = (rng.uniform(0, 1, (8, 8, 3)).astype(np.float32) for _ in range(2))
    normal = np.zeros((8, 8, 3), np.float32)
    normal[..., 2] = 1
    normal[2, 2] = np.nan
    normal[5, 5] = np.inf
    normal[6, 6] = 0.0  # zero-length
    normal[1, 6] = (1e30, 0, 0)  # not unit: the weight is capped at 1
    albedo = np.full((8, 8, 3), 0.5, np.float32)
    albedo[3, 3] = np.nan
    depth = np.ones((8, 8), np.float32)
    depth[0, :] = np.inf  # background
    depth[4, 4] = np.nan
    depth[7, 7] = 0.0
    depth[7, 0] = -np.inf
    out = half_variance(a, b, {"normal": normal, "albedo": albedo, "depth": depth})
    assert out.dtype == np.float32 and np.isfinite(out).all() and (out >= 0).all()
    # weights are at most 1 and at the pixel itself exactly 1: the result is a weighted mean
    raw = pair_variance(a, b)
    assert (out <= raw.max(axis=(0, 1)) * (1 + 1e-6)).all() and (out >= raw.min(axis=(0, 1)) * (1 - 1e-6)).all()


# ------------------------------------------------------------------------------ measurement
def _example():
    path = ROOT / "examples" / "capture" / "halves_capture.py"
    spec = importlib.util.spec_from_file_location("halves_capture", path)
    module = importlib.util.module_from_spec(spec)
    sys.modules.setdefault("halves_capture", module)
    spec.loader.exec_module(module)
    return module


@pytest.mark.slow
def test_sbf_and_lbf_denoise_better_with_the_half_buffer_variance(registry, tmp_path):
    """A capture of the path tracer's Cornell box (64x64, two halves of 4 spp: an 8-spp colour,
    seeds 1 to 3, reference 512 spp): SBF and LBF given the served variance have a lower relMSE,
    summed over the seeds, than the same filters estimating the variance from the image."""
    pytest.importorskip("pyvista")
    if "pathtracer" not in registry.renderers:
        pytest.skip("the pathtracer renderer is not registered")
    example = _example()
    reference = example.render_reference(registry, "cornell", (64, 64), 512)
    total = {}
    for seed in (1, 2, 3):
        folder = tmp_path / f"seed{seed}"
        example.write_halves_capture(folder, registry, "cornell", (64, 64), 8, seed, reference)
        for key, values in example.score(folder, registry).items():
            total[key] = total.get(key, 0.0) + values["relmse"]
    for name in ("sbf", "lbf"):
        assert total[(name, "halves")] < total[(name, "spatial")], (name, total)
    assert total[("sbf", "halves")] < total[("input", "-")]
