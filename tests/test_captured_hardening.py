"""Captured data as untrusted input (issue 29, item 11; issue 32, captured-data friction): file patterns,
files outside the capture folder, normals that are not unit length, a missing reference location."""

from __future__ import annotations

import json
import shutil

import numpy as np
import pytest

from harness import CHANNELS, load_plugins, read_channels, write_capture, write_channels
from plugins.renderers.captured import CaptureError, open_capture

#: the variable that lets a capture name files outside its folder (docs/captured.md)
ALLOW_ENV = "DENOISE_HARNESS_ALLOW_OUTSIDE_FILES"

ALL = frozenset(CHANNELS)
SIZE = (24, 16)


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def capture(registry, tmp_path_factory):
    """A two-frame capture of ``synthetic-moving`` (every channel, references); tests copy it."""
    scene = registry.get("scene", "synthetic-moving").factory()
    renderer = registry.get("renderer", "synthetic").factory()
    frames = [renderer.render(scene, t, spp=2, seed=3, channels=ALL, resolution=SIZE) for t in range(2)]
    refs = [renderer.reference(scene, t, resolution=SIZE) for t in range(2)]
    folder = tmp_path_factory.mktemp("capture") / "cap"
    write_capture(folder, frames, refs, spp=2)
    return folder, frames


def edited(capture, tmp_path, change) -> object:
    folder = tmp_path / "cap"
    shutil.copytree(capture[0], folder)
    data = json.loads((folder / "capture.json").read_text())
    change(data, folder)
    (folder / "capture.json").write_text(json.dumps(data, indent=1))
    return folder


def test_file_patterns_take_the_frame_number_only(capture, tmp_path):
    patterns = {"{frame.__class__.__mro__}": "{frame.__class__.__mro__}", "{frame!r}.exr": "{frame!r}",
                "{0}.exr": "{0}", "{frame[0]}.exr": "{frame[0]}", "{frame:>{width}}": "{frame:>{width}}"}
    for k, (pattern, bad) in enumerate(patterns.items()):
        folder = edited(capture, tmp_path / str(k), lambda d, f, p=pattern: d.update(file=p))
        with pytest.raises(CaptureError, match="may only hold {frame} or an integer format") as info:
            open_capture(folder)
        assert bad in str(info.value) and "\n" not in str(info.value)
    ok = edited(capture, tmp_path / "ok", lambda d, f: None)
    assert json.loads((ok / "capture.json").read_text())["file"] == "frames/{frame:04d}.exr"
    assert open_capture(ok).frame_count == 2


def _outside(data, folder):
    moved = folder.parent / "elsewhere"
    shutil.move(str(folder / "reference"), str(moved))
    data["reference"]["file"] = "../elsewhere/{frame:04d}.exr"


def test_files_outside_the_capture_folder_are_refused_unless_allowed(capture, tmp_path, monkeypatch):
    folder = edited(capture, tmp_path, _outside)
    with pytest.raises(CaptureError) as info:
        open_capture(folder)
    message = str(info.value)
    assert "\n" not in message and f"{folder / 'capture.json'}:" in message
    assert "'../elsewhere/0000.exr' of the reference is outside the capture folder" in message
    assert f"set {ALLOW_ENV}=1" in message
    monkeypatch.setenv(ALLOW_ENV, "1")
    assert open_capture(folder).params["references"]


def _encode_normals(data, folder):
    for path in sorted((folder / "frames").glob("*.exr")):
        channels, _ = read_channels(path)
        names = [f"normal.{c}" for c in "XYZ"]
        background = np.all([channels[n] == 0 for n in names], axis=0)
        for n in names:
            channels[n] = np.where(background, 0.0, 0.5 * channels[n] + 0.5).astype(np.float32)
        write_channels(path, channels)


def test_normals_must_be_unit_length_and_half_offset_files_are_decoded(capture, registry, tmp_path):
    folder = edited(capture, tmp_path, _encode_normals)
    with pytest.raises(CaptureError, match=r"normals are not unit length .*normal_encoding = \"unsigned\""):
        open_capture(folder)
    data = json.loads((folder / "capture.json").read_text())
    data["conventions"] = {**data.get("conventions", {}), "normal_encoding": "unsigned"}
    (folder / "capture.json").write_text(json.dumps(data))
    scene = open_capture(folder)
    frame = registry.get("renderer", "captured").factory().render(scene, 1, spp=2, channels={"normal"})
    want = capture[1][1]["normal"]
    np.testing.assert_allclose(frame["normal"], want, atol=1e-6)


def _reference_layer(data, folder):
    data["reference"]["layer"] = "beauty"


def _reference_folder(data, folder):
    shutil.rmtree(folder / "reference")


def test_a_missing_reference_fails_at_open_naming_the_sidecar_line(capture, tmp_path):
    for change, expected in ((_reference_layer, "no layer 'beauty' for the reference"),
                             (_reference_folder, "reference/0000.exr: missing file for frame 0 (the reference)")):
        folder = edited(capture, tmp_path / change.__name__, change)
        lines = (folder / "capture.json").read_text().splitlines()
        line = next(k for k, text in enumerate(lines, 1) if text.strip().startswith('"reference"'))
        with pytest.raises(CaptureError) as info:
            open_capture(folder)
        message = str(info.value)
        assert message.startswith(f"{folder / 'capture.json'}:{line}: ") and expected in message, message
