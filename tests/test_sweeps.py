"""Parameter sweeps (--grid): configurations, their jobs, and the front of a real sweep."""

import json

import numpy as np
import pytest

from harness import load_plugins
from harness.benchmark import run_benchmark
from harness.cache import Cache
from harness.cli.parser import build_parser
from harness.pareto import configuration_points, pareto_front, time_resolution
from harness.plan import make_plan
from harness.render_cost import measure_render_cost
from harness.renders import RenderStore
from harness.sweeps import MAX_CONFIGURATIONS, grid_points


@pytest.fixture(scope="module")
def reg():
    return load_plugins(disable=[])


def test_grid_points_are_the_cartesian_product_in_the_given_order():
    points = grid_points("f", {"a": 1}, {"b": [1, 2], "c": ["x", "y", "z"]})
    assert points[:3] == [{"a": 1, "b": 1, "c": "x"}, {"a": 1, "b": 1, "c": "y"}, {"a": 1, "b": 1, "c": "z"}]
    assert len(points) == 6 and points[-1] == {"a": 1, "b": 2, "c": "z"}
    assert grid_points("f", {"a": 1}) == [{"a": 1}]


@pytest.mark.parametrize("overrides, grid, message", [
    ({"b": 1}, {"b": [1, 2]}, "both by --param and --grid"),
    ({}, {"b": []}, "at least one value"),
    ({}, {"b": list(range(40)), "c": list(range(40))}, f"more than {MAX_CONFIGURATIONS}"),
])
def test_grid_points_refuse_bad_grids(overrides, grid, message):
    with pytest.raises(ValueError, match=message):
        grid_points("f", overrides, grid)


@pytest.mark.slow
def test_every_grid_point_is_a_job_with_its_params_in_its_identity(reg, tmp_path):
    store = RenderStore(reg, Cache(tmp_path / "c"))
    plan = make_plan(reg, store, [reg.scenes["synthetic-edges"]], ["eaw", "gaussian"], ["rmse"], spp=[1, 2],
                     seeds=[0], frames=1, grid={"eaw": {"iterations": [1, 3, 5]}})
    eaw = [j for j in plan.jobs if j.filter == "eaw"]
    assert len(eaw) == 6 and len({j.job_id for j in eaw}) == 6
    assert sorted({json.loads(j.params)["iterations"] for j in eaw}) == [1, 3, 5]
    assert len([j for j in plan.jobs if j.filter == "gaussian"]) == 2
    assert plan.settings["grid"] == {"eaw": {"iterations": [1, 3, 5]}}
    with pytest.raises(ValueError, match="iterations"):
        make_plan(reg, store, [reg.scenes["synthetic-edges"]], ["eaw"], ["rmse"], grid={"eaw": {"iterations": [0, 2]}})
    with pytest.raises(ValueError, match="not selected"):
        make_plan(reg, store, [reg.scenes["synthetic-edges"]], ["eaw"], ["rmse"], grid={"svgf": {"alpha": [0.1]}})


def test_cli_parses_grids_and_budgets():
    args = build_parser().parse_args(["run", "--grid", "eaw.iterations=1,2", "--grid", "eaw.color_scale=linear,log",
                                      "--budget", "33,16", "--report"])
    assert args.grid == [("eaw", "iterations", [1, 2]), ("eaw", "color_scale", ["linear", "log"])]
    assert args.budget == [16.0, 33.0] and args.report
    for bad in (["--grid", "eaw.iterations=1,,2"], ["--grid", "iterations=1"], ["--budget", "0"],
                ["--budget", "x"]):
        with pytest.raises(SystemExit):
            build_parser().parse_args(["run", *bad])


@pytest.mark.slow
def test_a_sweep_over_filters_and_spp_gives_a_monotone_front(reg, tmp_path):
    """The issue's sweep on a synthetic scene: every configuration a point, the renderer's cost per spp added.

    Timed at the scene's own (small) resolution to stay quick; the same functions use 1280x720
    where a run is timed there.
    """
    run = run_benchmark(out=tmp_path / "o", registry=reg, executor="inline", cache_dir=tmp_path / "c",
                        resolution=(48, 32), scenes=["synthetic-moving"], filters=["eaw", "svgf"],
                        metrics=["display_rmse"], spp=[1, 2, 4], seeds=[0], frames=2, repeats=1, reference_spp=16,
                        timing_at=(), grid={"eaw": {"iterations": [1, 2, 3, 4, 5]}, "svgf": {"iterations": [1, 3, 5]}})
    df = run.table
    assert (df.status == "ok").all()
    cost = measure_render_cost(run.store, run.plan, resolutions=[(48, 32)], repeats=1)
    assert sorted(cost.spp) == [1, 2, 4] and (cost.render_ms > 0).all()
    assert time_resolution(df) is None
    points = configuration_points(df, "display_rmse", "denoise", resolution=None, render_cost=cost)
    assert len(points) == (5 + 3) * 3
    assert points.render_ms.notna().all() and (points.time_ms > points.filter_ms).all()
    assert points.error.notna().all() and np.isfinite(points.time_ms).all()
    front = pareto_front(points, "time_ms", "error")
    assert len(front) >= 1
    assert front.time_ms.is_monotonic_increasing and (np.diff(front.error) < 0).all()
    for r in points.itertuples():  # every configuration off the front is dominated by one on it
        assert ((front.time_ms <= r.time_ms) & (front.error <= r.error)).any()
    assert {"eaw/cpu iterations=1 @1spp", "svgf/cpu iterations=5 @4spp"} <= set(points.entry)


@pytest.mark.slow
def test_each_configuration_is_timed_at_each_spp_and_the_front_uses_its_own(reg, tmp_path):
    """``--spp 1,2`` on a synthetic scene timed at 1280x720: every configuration has a real-resolution
    time at both spp, and each point's filter time is the one measured at its own spp."""
    run = run_benchmark(out=tmp_path / "o", registry=reg, executor="inline", cache_dir=tmp_path / "c",
                        resolution=(48, 32), scenes=["synthetic-moving"], filters=["passthrough", "gaussian"],
                        metrics=["display_rmse"], spp=[1, 2], seeds=[0, 1], frames=2, repeats=1, reference_spp=16,
                        grid={"gaussian": {"sigma": [1.0, 2.0]}}, timing_at=((1280, 720),),
                        timing_scene="synthetic-moving")
    assert sorted({(j.spp, j.seed) for j in run.plan.jobs if j.timing}) == [(1, 0), (2, 0)]
    df = run.table
    assert (df.status == "ok").all()
    timed = df.dropna(subset=["ms_1280x720"])
    assert set(timed.seed) == {0} and (timed.ms_1280x720 > 0).all()
    assert timed.groupby(["filter", "params"]).spp.unique().map(sorted).map(list).tolist() == [[1, 2]] * 3
    points = configuration_points(df, "display_rmse", "denoise")
    assert len(points) == 3 * 2 and (points.filter_ms_spp == points.spp).all()
    for r in points.itertuples():
        own = timed[(timed["filter"] == r.filter) & (timed.params == r.params) & (timed.spp == r.spp)]
        assert r.filter_ms == own.ms_1280x720.median()
