"""Run time against error: Pareto fronts, best within a budget, configuration points of a table."""

import numpy as np
import pandas as pd
import pytest

from harness.pareto import best_within, configuration_points, pareto_front
from harness.rows import make_table


def points(rows):
    return pd.DataFrame(rows, columns=["entry", "time_ms", "error"])


def test_front_keeps_only_non_dominated_points_and_is_monotone():
    p = points([("a", 1, 0.5), ("b", 2, 0.6), ("c", 3, 0.3), ("d", 3, 0.35), ("e", 10, 0.3), ("f", 20, 0.1),
                ("g", 5, np.nan)])
    front = pareto_front(p, "time_ms", "error")
    assert list(front.entry) == ["a", "c", "f"]
    assert front.time_ms.is_monotonic_increasing and front.error.is_monotonic_decreasing
    higher = pareto_front(p.assign(error=-p.error), "time_ms", "error", higher_is_better=True)
    assert list(higher.entry) == ["a", "c", "f"]


def test_front_property_on_random_clouds():
    rng = np.random.default_rng(0)
    for _ in range(50):
        p = points([(str(k), t, e) for k, (t, e) in enumerate(rng.uniform(0, 1, size=(30, 2)))])
        front = pareto_front(p, "time_ms", "error")
        assert front.time_ms.is_monotonic_increasing and (np.diff(front.error) < 0).all()
        for r in p.itertuples():  # every point off the front is dominated by a front point
            if r.entry not in set(front.entry):
                assert ((front.time_ms <= r.time_ms) & (front.error <= r.error)).any()


def test_best_within_budget_on_a_constructed_table():
    p = points([("fast", 2.0, 0.30), ("mid", 15.0, 0.12), ("mid-bad", 12.0, 0.20), ("slow", 30.0, 0.05),
                ("slower", 40.0, 0.01)])
    best = best_within(p, (1.0, 16.0, 33.0, 100.0), "time_ms", "error")
    assert list(best.budget_ms) == [1.0, 16.0, 33.0, 100.0]
    assert pd.isna(best.entry[0])
    assert list(best.entry[1:]) == ["mid", "slow", "slower"]


def test_configuration_points_add_render_time_per_spp():
    rows = []
    for spp in (1, 4):
        for scene, err in (("a", 0.2), ("b", 0.4)):
            for t in range(2):
                rows.append({"job_id": f"{spp}{scene}", "task": "denoise", "scene": scene, "filter": "f",
                             "backend": "cpu", "params": "{}", "spp": spp, "seed": 0, "frame": t, "status": "ok",
                             "display_rmse": err / spp,
                             "ms_1280x720": 5.0 if (scene == "a" and spp == 1) else np.nan})
    df = make_table(rows)
    cost = pd.DataFrame({"task": ["denoise", "denoise", "antialias"], "spp": [1, 4, 1], "width": 1280,
                         "height": 720, "render_ms": [10.0, 40.0, 99.0]})
    p = configuration_points(df, "display_rmse", "denoise", render_cost=cost)
    assert list(p.spp) == [1, 4]
    assert list(p.time_ms) == [15.0, 45.0] and list(p.render_ms) == [10.0, 40.0]
    assert list(p.filter_ms_spp) == [1, 1]  # timed at 1 spp only: that time stands for 4 spp
    assert p.error[0] == pytest.approx(0.3) and p.error[1] == pytest.approx(0.075)
    assert list(configuration_points(df, "display_rmse", "denoise", scene="b").error) == pytest.approx([0.4, 0.1])
    alone = configuration_points(df, "display_rmse", "denoise")
    assert list(alone.time_ms) == [5.0, 5.0] and alone.render_ms.isna().all()
    assert configuration_points(df, "display_rmse", "antialias").empty
