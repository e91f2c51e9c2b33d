"""The Blender preset against a real Cycles render (examples/capture/blender_capture.py --demo).

Runs where Blender is at hand: the ``bpy`` module in this interpreter, a Python with ``bpy``
named by ``DENOISE_BLENDER_PYTHON``, or ``blender`` on the PATH; skips otherwise. The check is
geometric: each pixel's captured motion must land on where its world position projects through
the previous frame's camera, and its depth must be the view-space z of that position.
"""

from __future__ import annotations

import importlib.util
import os
import shutil
import subprocess
import sys

import numpy as np
import pytest

from harness import CHANNELS, load_plugins
from tests.conftest import ROOT

SCRIPT = ROOT / "examples" / "capture" / "blender_capture.py"


def _blender_command(out):
    args = [str(out), "--demo", "--width", "48", "--height", "27", "--spp", "2", "--reference-spp", "8"]
    python = os.environ.get("DENOISE_BLENDER_PYTHON")
    if python:
        return [python, str(SCRIPT), *args]
    if importlib.util.find_spec("bpy") is not None:
        return [sys.executable, str(SCRIPT), *args]
    blender = shutil.which("blender")
    if blender:
        return [blender, "-b", "--factory-startup", "-P", str(SCRIPT), "--", *args]
    return None


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    out = tmp_path_factory.mktemp("blender-capture")
    command = _blender_command(out)
    if command is None:
        pytest.skip("no Blender: install bpy, put blender on the PATH or set DENOISE_BLENDER_PYTHON")
    subprocess.run(command, check=True, capture_output=True, timeout=600)
    return out


def _project(points, view_proj, width, height):
    clip = points @ view_proj[:3, :3].T + view_proj[:3, 3]
    w = points @ view_proj[3, :3] + view_proj[3, 3]
    x = (clip[..., 0] / w + 1.0) * 0.5 * width - 0.5
    y = (1.0 - clip[..., 1] / w) * 0.5 * height - 0.5
    return np.stack([x, y], axis=-1), w


def test_cycles_capture_follows_the_harness_conventions(capture):
    registry = load_plugins()
    scene = registry.open_scene(capture)
    assert scene.params["channels"] == ["albedo", "color", "depth", "emission", "motion", "normal", "position"]
    assert scene.params["references"]
    renderer = registry.get("renderer", "captured").factory()
    frame = renderer.render(scene, 2, spp=2, channels=frozenset(CHANNELS))
    h, w = frame.shape
    position = frame["position"].astype(np.float64)
    hit = np.isfinite(frame["depth"])
    assert hit.all()  # the ground plane fills the view
    previous, _ = _project(position, frame.meta.prev_view_proj, w, h)
    jj, ii = np.meshgrid(np.arange(w), np.arange(h))
    expected = previous - np.stack([jj, ii], axis=-1)
    error = np.abs(frame["motion"] - expected).max(axis=-1)
    assert np.abs(expected).max() > 2.0  # the camera did move
    assert np.percentile(error, 95) < 0.05  # pixels (edge pixels mix two surfaces)
    _, view_z = _project(position, frame.meta.view_proj, w, h)
    np.testing.assert_allclose(frame["depth"], view_z, rtol=1e-4)
    length = np.linalg.norm(frame["normal"], axis=-1)
    assert np.median(length) == pytest.approx(1.0, abs=1e-4)  # edge pixels average two faces' normals
    assert renderer.reference(scene, 2).shape == (h, w, 3)
