"""An outside render scored: Mitsuba 3 captures ../shared/scenes/living-room, the harness ingests it.

The capture script is the ``mitsuba`` renderer plugin plus ``denoise-bench export``. Needs the
``mitsuba`` extra and the third-party scene folder; skips otherwise. The rendered files go to a
temporary folder only (they derive from a third-party scene).
"""

from __future__ import annotations

import importlib.util
import sys
import warnings

import numpy as np
import pytest

from harness import load_plugins
from tests.conftest import ROOT

SCENE = ROOT.parent / "shared" / "scenes" / "living-room"
# the capture loads the living-room and renders it (tens of seconds)
pytestmark = pytest.mark.slow


def _load(path):
    """The script at ``path`` as a module, its folder first on the path while it is imported (as when
    run: ``benchmarks/`` scripts import ``common``)."""
    spec = importlib.util.spec_from_file_location(path.stem, path)
    module = importlib.util.module_from_spec(spec)
    sys.path.insert(0, str(path.parent))
    try:
        spec.loader.exec_module(module)
    finally:
        sys.path.remove(str(path.parent))
    return module


@pytest.fixture(scope="module")
def capture(tmp_path_factory):
    pytest.importorskip("mitsuba", reason="mitsuba is not installed (pip install 'denoise-harness[mitsuba]')")
    if not (SCENE / "scene.xml").is_file():
        pytest.skip(f"third-party scene folder {SCENE} is absent")
    script = _load(ROOT / "examples" / "capture" / "mitsuba_capture.py")
    out = tmp_path_factory.mktemp("living-room-capture")
    script.main([str(SCENE), str(out), "--width", "32", "--height", "18", "--frames", "2",
                 "--reference-spp", "8", "--variance-spp", "3", "--max-depth", "4", "--no-cache"])
    return out


@pytest.mark.slow
def test_mitsuba_capture_is_ingested_with_harness_conventions(capture):
    registry = load_plugins()
    scene = registry.open_scene(capture)
    assert scene.kind == "captured" and scene.name == "living-room-mitsuba3"
    with warnings.catch_warnings():
        warnings.simplefilter("ignore")
        source = registry.get("scene", "living-room").factory()
    assert scene.resolution == (32, 18) and scene.frame_count == min(2, source.frame_count)
    assert scene.params["channels"] == ["albedo", "color", "depth", "emission", "motion", "normal", "object_id",
                                        "position", "spp", "variance"]
    renderer = registry.get("renderer", "captured").factory()
    last = scene.frame_count - 1
    frame = renderer.render(scene, last, spp=1, channels=set(scene.params["channels"]))
    ref = renderer.reference(scene, last)
    assert ref.shape == (18, 32, 3) and np.isfinite(ref).all() and ref.mean() > 0
    noise = renderer.reference_variance(scene, last)  # the reference states its noise (bias correction)
    assert noise is not None and noise.shape == ref.shape and (noise >= 0).all() and noise.max() > 0
    hit = frame["object_id"] >= 0
    assert hit.mean() > 0.8  # an indoor view
    assert len(np.unique(frame["object_id"][hit])) > 5  # one id per shape
    assert np.isfinite(frame["motion"]).all()
    if scene.frame_count == 1:
        assert (frame["motion"] == 0).all()
    depth = frame["depth"]
    # Mitsuba's background depth 0 became +inf; hits have positive view-space depth
    assert (depth[np.isfinite(depth)] > 0).all()
    normal_length = np.linalg.norm(frame["normal"], axis=-1)
    np.testing.assert_allclose(normal_length[depth < np.inf], 1.0, atol=1e-3)
    # depth is the view z of the position: z = (position - eye) . forward
    eye = source.camera.eye(last)
    forward = source.camera.basis(last)[2]
    z = (frame["position"].astype(np.float64) - eye) @ forward
    both = np.isfinite(depth) & hit
    np.testing.assert_allclose(depth[both], z[both], rtol=1e-4)
    assert (frame["variance"] >= 0).all()


def test_filters_run_on_the_mitsuba_capture(capture):
    score = _load(ROOT / "benchmarks" / "score_capture.py").score
    table, skipped = score(capture, ["passthrough", "eaw", "svgf"])
    assert set(table.index) == {"passthrough", "eaw", "svgf"} and not skipped
    assert np.isfinite(table.to_numpy()).all()
    assert (table["ssim"] <= 1.0).all()
