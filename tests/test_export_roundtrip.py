"""Export then ingest: a captured folder and the built-in scene score every filter the same, bit for bit."""

import numpy as np
import pandas as pd
import pytest

from tests.test_run import bench

# every metric, the bias-corrected ones included: the capture carries each reference's variance
METRICS = ["flip", "psnr", "relmse", "rmse", "display_rmse", "display_psnr", "ssim", "temporal_error",
           "reference_noise"]
FILTERS = "eaw,svgf,sbf,lbf,passthrough,gaussian,opencv_jbf"


def _run(args, out):
    bench(["run", *args, "--filters", FILTERS, "--quiet", "--repeats", "1", "--executor", "inline", "--out", out])
    df = pd.read_parquet(out / "results.parquet")
    assert set(df.status) == {"ok"}, df[df.status != "ok"].message.tolist()
    return df.sort_values(["filter", "frame"]).reset_index(drop=True)


@pytest.mark.slow
@pytest.mark.parametrize("scene,frames", [("street", 3), ("cornell", 1)])
def test_exported_scene_scores_like_the_builtin(tmp_path, scene, frames):
    common = ["--resolution", "32x24", "--frames", str(frames), "--cache-dir", tmp_path / "c"]
    one_seed = ["--seeds", "0", "--timing-at", "none"]  # the export holds seed 0's frames
    builtin = _run(["--scenes", scene, "--reference-spp", "16", *common, *one_seed], tmp_path / "builtin")
    bench(["export", "--scenes", scene, "--reference-spp", "16", *common, "--out", tmp_path / "x"])
    captured = _run(["--scene-dir", tmp_path / "x" / scene, *common, *one_seed], tmp_path / "captured")
    assert set(captured.renderer) == {"captured"} and len(captured) == len(builtin)
    for m in METRICS:
        a, b = builtin[m].to_numpy(), captured[m].to_numpy()
        assert np.array_equal(a, b, equal_nan=True), f"{scene}: {m} differs"
    assert (builtin.reference_hash == captured.reference_hash).all()


def test_a_capture_without_reference_variance_has_unknown_not_zero_noise(tmp_path):
    import json

    common = ["--resolution", "32x24", "--frames", "1", "--cache-dir", tmp_path / "c"]
    bench(["export", "--scenes", "cornell", "--reference-spp", "16", *common, "--out", tmp_path / "x"])
    sidecar = tmp_path / "x" / "cornell" / "capture.json"
    data = json.loads(sidecar.read_text())
    assert data["reference"].pop("variance") == "variance"
    sidecar.write_text(json.dumps(data))
    captured = _run(["--scene-dir", tmp_path / "x" / "cornell", *common, "--seeds", "0", "--timing-at", "none"],
                    tmp_path / "captured")
    assert captured.reference_noise.isna().all() and captured.rmse.notna().all()


@pytest.mark.slow
def test_save_outputs_writes_exr_per_frame(tmp_path):
    from harness.exr import read_channels

    bench(["run", "--scenes", "synthetic-moving", "--frames", "2", "--seeds", "0", "--filters", "gaussian", "--quiet",
           "--save-outputs", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    files = sorted((tmp_path / "o" / "outputs" / "synthetic-moving").rglob("*.exr"))
    assert [f.name for f in files] == ["0000.exr", "0001.exr"] and files[0].parent.name == "gaussian-cpu-spp1-seed0"
    channels, size = read_channels(files[0])
    assert size == (128, 96) and set(channels) == {"R", "G", "B"}
