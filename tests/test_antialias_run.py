"""The anti-aliasing task through the main pipeline: pairing by task, an end-to-end
``denoise-bench run --task antialias`` and the leaderboard per task."""

import pandas as pd
import pytest

from harness import load_plugins
from harness.plan import make_plan
from harness.renders import RenderStore
from tests.test_run import bench

AA_FILTERS = ("noaa", "fxaa", "taa", "aa_rnn")


def test_planner_pairs_filters_scenes_and_renderers_by_task():
    reg = load_plugins()
    store = RenderStore(reg, resolution=(16, 8))
    scenes = [reg.scenes["aa-fence"], reg.scenes["synthetic-edges"]]
    plan = make_plan(reg, store, scenes, ["taa", "noaa", "passthrough"], ["ssim"], frames=2)
    pairs = {(j.task, j.scene, j.renderer, j.filter) for j in plan.jobs}
    assert pairs == {
        ("antialias", "aa-fence", "raster", "taa"),
        ("antialias", "aa-fence", "raster", "noaa"),
        ("denoise", "synthetic-edges", "synthetic", "passthrough"),
    }
    # the antialias group renders the jittered G-buffer the AA filters read, and never "spp"
    aa_group = next(g for g in plan.groups if g.task == "antialias")
    assert {"color", "depth", "motion"} <= aa_group.channels and "spp" not in aa_group.channels
    # an AA filter asked for on the denoise task alone is skipped with the reason
    plan = make_plan(reg, store, scenes, ["taa", "passthrough"], ["ssim"], frames=2, tasks=["denoise"])
    assert [j.filter for j in plan.jobs] == ["passthrough"]
    reasons = {j.filter: r for j, r in plan.skipped}
    assert reasons["taa"] == "filter 'taa' serves ['antialias'], not ['denoise']"
    # a renderer that cannot serve the task gives skipped rows with the reason
    plan = make_plan(reg, store, [reg.scenes["aa-fence"]], ["taa"], ["ssim"], frames=2, renderer="pathtracer",
                     tasks=["antialias"])
    assert not plan.jobs
    assert "not task 'antialias'" in plan.skipped[0][1]


@pytest.mark.slow
def test_run_task_antialias_end_to_end(tmp_path):
    out = bench(["run", "--task", "antialias", "--scenes", "aa-fence,synthetic-edges", "--resolution", "32x18",
                 "--frames", "3", "--seeds", "0", "--reference-spp", "16", "--filters", ",".join(AA_FILTERS),
                 "--repeats", "1",
                 "--executor", "inline", "--strict", "--quiet", "--out", tmp_path / "o", "--cache-dir",
                 tmp_path / "c"])
    assert "Leaderboard, task antialias" in out.stdout and "task denoise" not in out.stdout
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert set(df.status) == {"ok"} and set(df.task) == {"antialias"}
    assert set(df.scene) == {"aa-fence"} and set(df.renderer) == {"raster"}
    assert set(df["filter"]) == set(AA_FILTERS) and len(df) == len(AA_FILTERS) * 3
    assert df[["ssim", "psnr", "flip", "rmse"]].notna().all().all()
    last = df[df.frame == 2].set_index("filter")
    # the temporal filters improve on the aliased input by the last frame
    assert last.loc["taa", "rmse"] < last.loc["noaa", "rmse"]
    assert last.loc["aa_rnn", "rmse"] < last.loc["noaa", "rmse"]
