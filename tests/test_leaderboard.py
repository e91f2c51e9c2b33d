"""The leaderboard: ranked by one stated metric, intervals, paired tests, noise floors, real-resolution times."""

import numpy as np
import pandas as pd
import pytest

from harness import MetricSpec
from harness.results import board_table, entry_labels, leaderboard, rank_metric
from harness.rows import make_table

SPECS = {
    "display_rmse": MetricSpec(name="display_rmse", version="1", factory=lambda: None,
                               noise_floor="reference_noise_display"),
    "ssim": MetricSpec(name="ssim", version="1", factory=lambda: None, higher_is_better=True),
}


def rows(filter_name, level, *, spread=0.01, floor=0.001, seed=0, scenes=("a", "b"), seeds=(0, 1, 2), frames=4,
         ms=None, task="denoise"):
    """Result rows of one filter whose display_rmse is ``level`` plus per-(seed, frame) noise."""
    rng = np.random.default_rng(seed)
    out = []
    for scene in scenes:
        for s in seeds:
            shared = np.random.default_rng(1000 * s + len(scene)).normal(0, 0.05)  # the same input for every filter
            for t in range(frames):
                value = level + shared + rng.normal(0, spread)
                out.append({"job_id": f"{filter_name}{scene}{s}", "task": task, "scene": scene, "filter": filter_name,
                            "backend": "cpu", "params": "{}", "spp": 1, "seed": s, "frame": t, "status": "ok",
                            "display_rmse": value, "ssim": 1.0 - value, "reference_noise_display": floor,
                            "ms_1280x720": ms if (ms is not None and scene == "a" and s == 0) else np.nan})
    return out


def board(*parts, rank_by=None):
    return leaderboard(make_table([r for part in parts for r in part]), SPECS, rank_by)


def test_ranked_by_display_rmse_with_intervals_and_paired_tests():
    b = board(rows("good", 0.10, ms=50.0), rows("close", 0.101, seed=1, ms=20.0), rows("bad", 0.20, seed=2, ms=5.0))
    assert b.attrs["rank_by"] == "display_rmse" and not b.attrs["higher_is_better"]
    assert list(b.entry) == ["good/cpu", "close/cpu", "bad/cpu"] and list(b["rank"]) == [1, 2, 3]
    assert (b.display_rmse_lo <= b.display_rmse).all() and (b.display_rmse <= b.display_rmse_hi).all()
    assert b.vs_next[0].startswith("not significant")  # 0.100 vs 0.101 with a spread of 0.01
    assert b.vs_next[1].startswith("better") and b.p_next[1] < 0.01
    assert b.vs_next[2] == ""
    assert list(b.ms_1280x720) == [50.0, 20.0, 5.0]
    assert list(b.cells) == [24, 24, 24] and list(b.scenes) == [2, 2, 2]
    # the shared per-seed offsets are the same for every filter: the paired test sees through them
    assert b.display_rmse_hi[0] - b.display_rmse_lo[0] > 0.02


def test_a_difference_below_the_reference_noise_is_marked_not_resolved():
    clean = board(rows("a", 0.10, spread=0.0005), rows("b", 0.105, spread=0.0005, seed=1))
    assert clean.vs_next[0].startswith("better") and "not resolved" not in clean.vs_next[0]
    noisy = board(rows("a", 0.10, spread=0.0005, floor=0.02), rows("b", 0.105, spread=0.0005, seed=1, floor=0.02))
    assert "not resolved" in noisy.vs_next[0] and noisy.vs_next[0].startswith("better")


def test_rank_by_another_metric_and_direction():
    b = board(rows("x", 0.3), rows("y", 0.1, seed=1), rank_by="ssim")
    assert b.attrs["rank_by"] == "ssim" and b.attrs["higher_is_better"]
    assert list(b.entry) == ["y/cpu", "x/cpu"]
    with pytest.raises(ValueError, match="cannot rank by 'flip'"):
        board(rows("x", 0.3), rank_by="flip")
    assert rank_metric(["ssim", "rmse"]) == "rmse" and rank_metric(["ssim", "display_rmse"]) == "display_rmse"


def test_boards_are_per_task_and_entries_name_their_configuration():
    b = board(rows("x", 0.3), rows("x", 0.2, task="antialias"), rows("y", 0.1, task="antialias"))
    assert set(b.task) == {"denoise", "antialias"}
    assert list(b[b.task == "antialias"].entry) == ["y/cpu", "x/cpu"]
    df = make_table(rows("x", 0.3) + [dict(r, params='{"k": 2}', spp=4) for r in rows("x", 0.2)])
    labels = set(entry_labels(df[df.status == "ok"]))
    assert labels == {"x/cpu k=null @1spp", "x/cpu k=2 @4spp"}  # only the parameters that differ
    sweep = make_table([dict(r, params=f'{{"a": {a}, "b": "s", "c": 1}}', job_id=f"j{a}") for a in (1, 2)
                        for r in rows("x", 0.3)])
    assert set(entry_labels(sweep[sweep.status == "ok"])) == {"x/cpu a=1", "x/cpu a=2"}


def test_board_table_shows_intervals_and_the_verdict_next_to_the_ranking_metric():
    b = board(rows("good", 0.10, ms=50.0), rows("bad", 0.20, seed=2))
    b.attrs.update(rank_by="display_rmse")
    table = board_table(b.drop(columns="task"), intervals="rank")
    assert list(table.columns[:4]) == ["rank", "entry", "display_rmse", "vs next"]
    assert table.display_rmse[0].count("[") == 1 and "[" not in table.ssim[0]
    assert table.ms_1280x720[0] == "50" and table.ms_1920x1080[0] == "-"
    full = board_table(b.drop(columns="task"))
    assert "[" in full.ssim[0]


def test_single_seed_single_frame_gives_points_not_intervals():
    b = board(rows("x", 0.3, seeds=(0,), frames=1, scenes=("a",)), rows("y", 0.1, seeds=(0,), frames=1, scenes=("a",)))
    assert (b.display_rmse_lo == b.display_rmse).all() and (b.display_rmse_hi == b.display_rmse).all()
    assert b.vs_next[0] == "one input: no test"
    assert isinstance(b, pd.DataFrame)


def test_one_input_is_written_as_such_not_as_an_interval():
    """A captured frame run once (one scene, seed and frame): the table says there is nothing to
    resample instead of showing a zero-width interval."""
    b = board(rows("x", 0.3, seeds=(0,), frames=1, scenes=("a",)), rows("y", 0.1, seeds=(0,), frames=1, scenes=("a",)))
    b.attrs.update(rank_by="display_rmse")
    table = board_table(b.drop(columns="task"))
    assert table.display_rmse[0].endswith(" (one input: no interval)") and "[" not in table.display_rmse[0]
    assert table["vs next"][0] == "one input: no test"
    several = board(rows("x", 0.3, seeds=(0,), frames=3, scenes=("a",)))
    several.attrs.update(rank_by="display_rmse")
    assert "no interval" not in board_table(several.drop(columns="task")).display_rmse[0]


def test_degraded_entries_are_marked_with_the_guides_they_lacked():
    full = rows("svgf", 0.1)
    degraded = [dict(r, guides="albedo,normal; without depth,motion,object_id", scene="c") for r in rows("svgf", 0.2)]
    for r in full:
        r["guides"] = "albedo,depth,motion,normal,object_id"
    labels = entry_labels(make_table(full + degraded))
    assert set(labels) == {"svgf/cpu", "svgf/cpu [without depth,motion,object_id]"}
