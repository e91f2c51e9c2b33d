"""The paper-scale dataset of ``aa_rnn`` and training on it: the split by scene, the writer
(compressed, resumable, deterministic, the same with any executor), the crop camera's geometry,
the benchmark scenes held out, training resumed from a checkpoint to the same weights, and the
``denoise-bench train aa_rnn -o ...`` options."""

from __future__ import annotations

import os
import types

import numpy as np
import pytest

from harness import CameraPath, load_plugins
from harness.cli import main
from plugins.filters.aa_rnn import dataset as DS
from plugins.filters.aa_rnn.cropcam import crop_camera
from plugins.filters.aa_rnn.dataset_training import EpochConfig, checkpoint_path, snapshot_path, train_on_dataset
from plugins.filters.aa_rnn.weights import load_weights

TINY = DS.DatasetConfig(sequences=5, frames=3, size=12, seed=7, mitsuba_share=0.0)


@pytest.fixture(scope="module")
def tiny(tmp_path_factory):
    folder = tmp_path_factory.mktemp("aa_data")
    DS.generate(folder, TINY, executor="inline")
    return folder


def test_plan_splits_3_1_1_by_scene_never_by_frame():
    entries = DS.plan(DS.DatasetConfig(sequences=200, mitsuba_share=0.3, mitsuba=("a", "b", "c")))
    assert [e["index"] for e in entries] == list(range(200))
    units: dict = {}
    for e in entries:
        units.setdefault(e["unit"], set()).add(e["split"])
    assert all(len(splits) == 1 for splits in units.values())  # a scene lies in one split
    assert sum(e["source"] != "procedural" for e in entries) == 60
    assert {e["unit"] for e in entries if e["source"] == "a"} == {"a"}
    counts = {s: sum(e["split"] == s for e in entries) for s in DS.SPLITS}
    assert counts == {"train": 120, "validation": 40, "test": 40}
    procedural = DS.plan(DS.DatasetConfig(sequences=10, mitsuba_share=0.0))
    assert [sum(e["split"] == s for e in procedural) for s in DS.SPLITS] == [6, 2, 2]
    assert DS.plan(DS.DatasetConfig(sequences=200, mitsuba_share=0.3, mitsuba=("a", "b", "c"))) == entries
    other = DS.plan(DS.DatasetConfig(sequences=200, seed=1, mitsuba_share=0.3, mitsuba=("a", "b", "c")))
    assert [e["source"] for e in other] != [e["source"] for e in entries]


def test_benchmark_scenes_are_never_dataset_sources():
    spec = types.SimpleNamespace
    registry = types.SimpleNamespace(scenes={
        "aa-like": spec(tags={"mitsuba"}, kind="mesh", tasks={"antialias"}),
        "not-mitsuba": spec(tags=set(), kind="mesh", tasks={"denoise"}),
    })
    assert DS.mitsuba_scenes(registry) == []
    real = load_plugins()
    aa = {n for n, s in real.scenes.items() if "antialias" in s.tasks}
    assert aa == {"aa-railing", "aa-fence", "aa-garden"}
    entries = DS.plan(DS.DatasetConfig(sequences=20, mitsuba_share=0.5, mitsuba=("classroom",)))
    assert not {e["source"] for e in entries} & aa


def test_crop_camera_keeps_the_large_frames_pixel_size_and_aims_at_the_crop():
    base = CameraPath(positions=[[0.0, 1.0, 5.0]], targets=[[0.3, 0.8, 0.0]], fov=50.0)
    size = 32
    for seed in range(5):
        rng = np.random.default_rng(seed)
        cam, drawn = crop_camera(rng, base, size, frames=3, first=1, speed=0.0, pan=0.0)
        height = drawn["frame_height"]
        width = height * 16 / 9
        cx, cy = drawn["crop_centre"]
        # the point seen at the crop's centre projects to the drawn place of the large frame
        point = cam.eye(1) + 7.0 * (cam.targets[1] - cam.eye(1)) / np.linalg.norm(cam.targets[1] - cam.eye(1))
        big = base.project(point, 0, int(round(width)), height)
        assert np.allclose(big, [int(round(width)) / 2 - 0.5 + cx, height / 2 - 0.5 + cy], atol=0.05)
        assert np.allclose(cam.project(point, 1, size, size), [(size - 1) / 2, (size - 1) / 2], atol=1e-6)
        # a pixel of the crop spans the angle of a pixel at the centre of the large frame
        assert np.tan(np.radians(cam.fov) / 2) == pytest.approx(np.tan(np.radians(base.fov) / 2) * size / height)


@pytest.mark.slow
def test_writer_stores_compressed_sequences_with_gbuffer_motion_and_ssaa(tiny):
    from harness import halton_jitter

    manifest = DS.read_manifest(tiny)
    assert manifest["complete"] and manifest["splits"] == {"train": 3, "validation": 1, "test": 1}
    for e in manifest["plan"]:
        a = DS.read_sequence(DS.sequence_path(tiny, e["index"]))
        assert set(a) == set(DS.ARRAYS)
        assert a["color"].shape == a["reference"].shape == (3, 12, 12, 3) and a["color"].dtype == np.float32
        assert a["motion"].shape == (3, 12, 12, 2) and a["object_id"].dtype == np.int32
        first = a["meta"]["first_frame"]
        assert 0 <= first < 16 and a["meta"]["split"] == e["split"]
        assert np.allclose(a["jitter"], [halton_jitter(first + t) for t in range(3)])
        assert np.isfinite(a["reference"]).all() and not np.array_equal(a["reference"], a["color"])
    # compressed: smaller than the raw arrays
    raw = sum(v.nbytes for k, v in DS.read_sequence(DS.sequence_path(tiny, 0)).items() if k != "meta")
    assert DS.sequence_path(tiny, 0).stat().st_size < raw


def test_writer_resumes_renders_only_what_is_missing_and_refuses_other_settings(tiny, tmp_path, monkeypatch):
    import shutil

    folder = tmp_path / "copy"
    shutil.copytree(tiny, folder)
    before = {p.name: p.stat().st_mtime_ns for p in folder.glob("seq_*.npz")}
    truncated = DS.sequence_path(folder, 2)
    truncated.write_bytes(truncated.read_bytes()[:100])  # a damaged file is rendered again
    DS.sequence_path(folder, 4).unlink()
    # a dataset being made serves the sequences it holds, and names the first one it lacks
    assert len(DS.load_split(folder, "train", 2)[0]) == 2
    with pytest.raises(FileNotFoundError, match="sequence 2 "):
        DS.load_split(folder, "train")
    rendered = []
    real = DS.render_sequence
    monkeypatch.setattr(DS, "render_sequence", lambda c, e, r=None: rendered.append(e["index"]) or real(c, e, r))
    DS.generate(folder, TINY, executor="inline")
    assert sorted(rendered) == [2, 4]
    after = {p.name: p.stat().st_mtime_ns for p in folder.glob("seq_*.npz")}
    assert all(after[n] == before[n] for n in ("seq_00000.npz", "seq_00001.npz", "seq_00003.npz"))
    for k in (2, 4):  # the same bytes of arrays as the first time: a sequence depends on its index only
        a, b = DS.read_sequence(DS.sequence_path(folder, k)), DS.read_sequence(DS.sequence_path(tiny, k))
        for name in DS.ARRAYS[:-1]:
            np.testing.assert_array_equal(a[name], b[name])
    with pytest.raises(ValueError, match="other|made with"):
        DS.generate(folder, DS.DatasetConfig(sequences=6, frames=3, size=12, seed=7, mitsuba_share=0.0),
                    executor="inline")
    assert not list(folder.glob(".*tmp*"))


@pytest.mark.slow
def test_training_resumed_from_its_checkpoint_gives_the_same_weights(tiny, tmp_path):
    config = EpochConfig(epochs=3, batch=2, crop=8, eval_every=1, snapshots=(2,))
    whole = train_on_dataset(tiny, tmp_path / "whole.npz", seed=1, config=config)
    assert train_on_dataset(tiny, tmp_path / "parts.npz", seed=1, config=config, until_epoch=1) is None
    assert checkpoint_path(tmp_path / "parts.npz").is_file() and not (tmp_path / "parts.npz").exists()
    parts = train_on_dataset(tiny, tmp_path / "parts.npz", seed=1, config=config)
    ma, mb = load_weights(whole)[1], load_weights(parts)[1]
    assert ma["arrays_sha256"] == mb["arrays_sha256"] and ma["validation_l1"] == mb["validation_l1"]
    assert ma["epochs_run"] == 3 and ma["steps_per_epoch"] == 1 and ma["threads"] == 1
    assert load_weights(snapshot_path(tmp_path / "whole.npz", 2))[1]["epochs_run"] == 2
    other = train_on_dataset(tiny, tmp_path / "other.npz", seed=2, config=config)
    assert load_weights(other)[1]["arrays_sha256"] != ma["arrays_sha256"]
    with pytest.raises(ValueError, match="other settings"):
        train_on_dataset(tiny, tmp_path / "parts.npz", seed=1, config=EpochConfig(epochs=4, batch=2, crop=8))


def test_cli_options_make_the_dataset_and_train(tiny, tmp_path, capsys):
    out = tmp_path / "w.npz"
    assert main(["train", "aa_rnn", "--seed", "3", "--output", str(out), "-o", f"data={tiny}", "-o", "epochs=1",
                 "-o", "batch=2", "-o", "crop=8"]) == 0
    assert load_weights(out)[1]["seed"] == 3 and load_weights(out)[1]["epochs_run"] == 1
    capsys.readouterr()
    assert main(["train", "aa_rnn", "-o", f"data={tiny}", "-o", "bogus=1"]) == 2
    assert "unknown ['bogus']" in capsys.readouterr().err
    assert main(["train", "aa_rnn", "-o", f"data={tiny}", "-o", "sequences=9", "-o", "stage=dataset"]) == 2
    assert "made with" in capsys.readouterr().err
    assert main(["train", "aa_rnn", "-o", f"data={tmp_path / 'none'}"]) == 2  # training needs --output
    assert "--output" in capsys.readouterr().err and not (tmp_path / "none").exists()


@pytest.mark.slow
def test_train_without_options_runs_the_shipped_recipe(tmp_path, monkeypatch, caplog):
    from plugins.filters.aa_rnn import weights as W

    data = tmp_path / "cache" / "data"
    recipe = {"data": str(data), "train_sequences": 2, "epochs": 2, "val_sequences": 1, "eval_every": 1, "batch": 2,
              "crop": 8, "executor": "inline"}
    monkeypatch.setitem(W.SHIPPED, W.DEFAULT_LAYERS, dict(W.SHIPPED[W.DEFAULT_LAYERS], recipe=recipe,
                                                          dataset=TINY.to_json(), seed=0))
    out = tmp_path / "w.npz"
    caplog.set_level("INFO")
    assert main(["train", "aa_rnn", "--output", str(out)]) == 0
    manifest = DS.read_manifest(data)  # the dataset made first, with the recorded settings
    assert manifest["complete"] and manifest["config"] == TINY.to_json()
    meta = load_weights(out)[1]
    assert meta["recipe"] == "dataset" and meta["seed"] == 0 and meta["epochs_run"] == 2
    assert meta["config"]["train_sequences"] == 2 and meta["config"]["val_sequences"] == 1
    # the checkpoint lies beside the dataset, not beside the (shipped) weights
    assert (data.parent / "w.npz.ckpt").is_file() and not checkpoint_path(out).exists()
    assert "differs from the shipped weights" in caplog.text
    # the same weights as the options spelled out
    again = tmp_path / "again.npz"
    assert main(["train", "aa_rnn", "--output", str(again)] + [a for k, v in recipe.items()
                                                                for a in ("-o", f"{k}={v}")]) == 0
    assert load_weights(again)[1]["arrays_sha256"] == meta["arrays_sha256"]
    # another seed, or a quick run, would replace the shipped file: refused without --output
    assert main(["train", "aa_rnn", "--seed", "1"]) == 2
    assert main(["train", "aa_rnn", "--quick"]) == 2


def test_option_without_equals_is_a_usage_error():
    with pytest.raises(SystemExit) as exc:
        main(["train", "aa_rnn", "-o", "nokey"])
    assert exc.value.code == 2


@pytest.mark.slow
@pytest.mark.parametrize("executor", ["local", "dask"])
def test_workers_write_the_same_files_as_the_calling_process(tiny, tmp_path, executor):
    if executor == "dask":
        pytest.importorskip("dask.distributed")
    DS.generate(tmp_path, TINY, workers=2, executor=executor)
    for e in DS.read_manifest(tmp_path)["plan"]:
        a, b = DS.read_sequence(DS.sequence_path(tmp_path, e["index"])), DS.read_sequence(
            DS.sequence_path(tiny, e["index"]))
        for name in DS.ARRAYS[:-1]:
            np.testing.assert_array_equal(a[name], b[name])


@pytest.mark.slow
def test_mitsuba_crops_are_rendered_where_the_scenes_are_present(tmp_path):
    registry = load_plugins()
    present = DS.mitsuba_scenes(registry)
    if not present:
        pytest.skip("no Mitsuba scene folder under ../shared/scenes")
    config = DS.DatasetConfig(sequences=4, frames=2, size=16, mitsuba_share=1.0)
    DS.generate(tmp_path, config, executor="inline")
    manifest = DS.read_manifest(tmp_path)
    assert set(manifest["config"]["mitsuba"]) == set(present)
    for e in manifest["plan"]:
        a = DS.read_sequence(DS.sequence_path(tmp_path, e["index"]))
        assert a["meta"]["source"] in present and np.isfinite(a["reference"]).all()
        assert a["meta"]["camera"]["exposure"] > 0 and os.path.getsize(DS.sequence_path(tmp_path, e["index"])) > 0
