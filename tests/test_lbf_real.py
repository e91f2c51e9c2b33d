"""LBF's training on real (third-party) scenes: the data split, the cameras, the missing-scene paths.

The test that renders the real scenes needs ``../shared/scenes`` and skips with a message where
it is absent; the others run anywhere.
"""

from __future__ import annotations

import dataclasses
import math
import os
import re
import subprocess
import sys
import types
from pathlib import Path

import numpy as np
import pytest

from harness import CameraPath, load_plugins
from plugins.filters.lbf.weights import DEFAULT_WEIGHTS, load_weights

pytest.importorskip("torch")
T = pytest.importorskip("plugins.filters.lbf.train")
RS = pytest.importorskip("plugins.filters.lbf.real_scenes")

ROOT = Path(__file__).resolve().parents[1]


def test_held_out_scenes_are_never_trained_on():
    assert set(RS.TRAIN_SCENES) == {"classroom", "living-room"}
    assert RS.HELDOUT_SCENES == ("sponza",)
    assert T.FULL.real_train > 0 and T.FULL.real_test > 0
    assert T.QUICK.real_train == T.QUICK.real_val == T.QUICK.real_test == 0


def test_shipped_weights_state_their_data():
    meta = load_weights().meta
    real = meta["real_scenes"]
    assert real["used"] is True and meta["quick"] is False and meta["seed"] == 0
    assert real["train"] == list(RS.TRAIN_SCENES) and real["heldout"] == list(RS.HELDOUT_SCENES)
    assert set(real["scene_sha256"]) == set(RS.TRAIN_SCENES + RS.HELDOUT_SCENES)
    assert "classroom" in meta["training_data"] and "sponza" in meta["training_data"]
    assert set(meta["split_relmse"]) == {"procedural", "real", "heldout_scenes"}
    for name, scores in meta["split_relmse"].items():
        assert scores["final"] < scores["noisy"], name
    assert re.fullmatch("[0-9a-f]{64}", meta["training_data_hash"])


def test_docs_quote_the_shipped_weights():
    meta = load_weights().meta
    for doc in (ROOT / "plugins" / "filters" / "lbf" / "README.md", ROOT / "docs" / "lbf.md"):
        text = doc.read_text()
        assert meta["arrays_sha256"] in text, doc
        assert meta["training_data_hash"] in text, doc
        assert DEFAULT_WEIGHTS.name in text, doc


def test_variant_cameras_crop_the_original_view():
    eye, target = np.array([1.0, 2.0, 3.0]), np.array([1.0, 2.0, -2.0])
    camera = CameraPath(positions=[eye, eye + 0.1], targets=[target, target], up=(0, 1, 0), fov=40.0)
    variants = [{"frame": 0, "zoom": 1.0, "pan": [0.7, -0.3]}, {"frame": 1, "zoom": 0.5, "pan": [1.0, 1.0]},
                {"frame": 0, "zoom": 0.4, "pan": [-1.0, 0.2]}]
    cams = RS.variant_cameras(camera, variants)
    # zoom 1: the original camera
    np.testing.assert_allclose(cams.targets[0], target, atol=1e-12)
    assert cams.fov_at(0) == pytest.approx(40.0)
    np.testing.assert_allclose(cams.eye(1), camera.eye(1))
    half = math.tan(math.radians(40.0) / 2)
    for k, v in enumerate(variants):
        assert math.tan(math.radians(cams.fov_at(k)) / 2) == pytest.approx(v["zoom"] * half)
        # every corner of the new view (16:9) lies inside the original view
        right, up, forward = cams.basis(k)
        r0, u0, f0 = camera.basis(v["frame"])
        h = v["zoom"] * half
        for sx in (-1, 1):
            for sy in (-1, 1):
                ray = forward + sx * h * RS.FILM_ASPECT * right + sy * h * up
                x, y = ray @ r0 / (ray @ f0), ray @ u0 / (ray @ f0)
                assert abs(x) <= half * RS.FILM_ASPECT * (1 + 1e-9) and abs(y) <= half * (1 + 1e-9)


def _fake_registry():
    def missing():
        raise FileNotFoundError("scene 'classroom': no Mitsuba scene folder found; tried X, Y")

    spec = types.SimpleNamespace(factory=missing)
    return types.SimpleNamespace(scenes={"classroom": spec}, renderers={"pathtracer": object()})


def test_missing_real_scenes_stop_training_before_rendering(monkeypatch):
    with pytest.raises(RS.RealScenesMissing) as info:
        RS.load(_fake_registry(), RS.TRAIN_SCENES)
    message = str(info.value)
    assert "\n" not in message and isinstance(info.value, FileNotFoundError)
    assert "classroom" in message and "living-room (no scene plugin registers it)" in message
    assert "-o real=false" in message
    no_tracer = types.SimpleNamespace(scenes={}, renderers={})
    with pytest.raises(RS.RealScenesMissing, match="pathtracer"):
        RS.load(no_tracer, RS.TRAIN_SCENES)

    def must_not_render(*args, **kwargs):
        raise AssertionError("rendered before checking the real scenes")

    monkeypatch.setattr(T, "load_plugins", _fake_registry)
    monkeypatch.setattr(T, "make_dataset", must_not_render)
    with pytest.raises(RS.RealScenesMissing):
        T.fit(0, T.FULL)


def test_procedural_only_training_is_recorded():
    train, val, test, info = T._real_data(_fake_registry(), 0, T.FULL, real=False)
    assert train == val == test == []
    assert info == {"used": False, "reason": "real=False: procedural data only"}
    assert "no real scene (real=False" in T._description(info)
    assert T._real_data(_fake_registry(), 0, T.QUICK, real=True)[3]["used"] is False


def test_trainer_options_are_checked():
    trainer = load_plugins().filters["lbf"].trainer
    with pytest.raises(ValueError, match="bogus"):
        trainer(seed=0, output=None, quick=True, bogus=1)
    with pytest.raises(ValueError, match="real must be true or false"):
        T.train(seed=0, output="unused.npz", quick=True, real="yes")


@pytest.mark.slow
def test_cli_without_the_real_scenes_exits_2_in_one_line(tmp_path):
    env = {**os.environ, "DENOISE_HARNESS_DISABLE": ",".join(RS.TRAIN_SCENES + RS.HELDOUT_SCENES)}
    proc = subprocess.run([sys.executable, "-m", "harness.cli", "train", "lbf", "--output", str(tmp_path / "w.npz")],
                          cwd=ROOT, env=env, capture_output=True, text=True, timeout=300)
    assert proc.returncode == 2, proc.stderr[-2000:]
    lines = [line for line in proc.stderr.splitlines() if "real scenes" in line]
    assert len(lines) == 1 and "-o real=false" in lines[0] and "Traceback" not in proc.stderr
    assert not (tmp_path / "w.npz").exists()


@pytest.mark.slow
def test_training_data_includes_the_real_scenes(monkeypatch):
    reg = load_plugins()
    try:
        scenes = RS.load(reg, RS.TRAIN_SCENES + RS.HELDOUT_SCENES)
    except RS.RealScenesMissing as exc:
        pytest.skip(f"the real scenes are absent: {exc}")
    monkeypatch.setattr(RS, "load", lambda reg, names: {n: scenes[n] for n in names})
    monkeypatch.setattr(RS, "REFERENCE_SPP", 8)
    monkeypatch.setattr(RS, "RESOLUTIONS", ((24, 16),))
    config = dataclasses.replace(T.FULL, real_train=1, real_val=1, real_test=1)
    train, val, test, info = T._real_data(reg, 0, config, real=True)
    assert info["used"] and info["train"] == list(RS.TRAIN_SCENES) and info["heldout"] == ["sponza"]
    assert len(train) == len(val) == 2 and len(test) == 1
    for sample in train + val + test:
        a = sample["arrays"]
        assert a["color"].shape == a["ref"].shape == (16, 24, 3)
        assert all(np.all(np.isfinite(x)) for x in a.values())
        assert (a["normal"] != 0).any() and a["ref"].mean() > 0
    # the first training frame is the classroom's crop (rendered again: deterministic), the
    # held-out frame sponza's
    classroom = RS.dataset(reg, {"classroom": scenes["classroom"]}, 3, 1)[0]
    for key, value in classroom.items():
        np.testing.assert_array_equal(train[0]["arrays"][key], value)
    sponza = RS.dataset(reg, {"sponza": scenes["sponza"]}, 5, 1)[0]
    np.testing.assert_array_equal(test[0]["arrays"]["ref"], sponza["ref"])
