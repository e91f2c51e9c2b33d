"""End-to-end runs: results, manifest, cache reuse, resume after a kill, fault isolation, skips."""

import json
import os
import signal
import subprocess
import sys
import time
import types

import numpy as np
import pandas as pd
import pytest

from harness import FilterSpec, RendererSpec, hookimpl, load_plugins
from harness.benchmark import run_benchmark
from harness.cache import Cache
from harness.plan import make_plan
from harness.renders import RenderStore
from harness.rows import TIMING_COLUMNS
from tests.conftest import bench_env, cli

BASE = [
    "--scenes",
    "synthetic-edges,synthetic-moving",
    "--frames",
    "3",
    "--filters",
    "passthrough,gaussian,median3",
    "--repeats",
    "2",
    "--seeds",
    "0",
    "--timing-at",
    "none",
    "--quiet",
]


bench = cli  # the command, in this process unless an environment is given


def without_timing(df):
    return df.drop(columns=[*TIMING_COLUMNS, "machine"]).sort_values(["job_id", "frame"]).reset_index(drop=True)


def run_api(reg, tmp_path, scenes, filters, metrics, executor="inline", **options):
    """Plan and run through the library (no CLI); returns the results table."""
    return run_benchmark(out=tmp_path / "o", registry=reg, scenes=scenes, filters=filters, metrics=metrics,
                         executor=executor, cache_dir=tmp_path / "c", seeds=options.pop("seeds", [0]),
                         timing_at=options.pop("timing_at", ()), **options).table


@pytest.mark.slow
def test_run_writes_results_and_manifest_and_reuses_the_cache(tmp_path):
    cache = tmp_path / "cache"
    first = bench(["run", *BASE, "--out", tmp_path / "a", "--cache-dir", cache, "--csv"])
    assert "Summary" in first.stdout and "Leaderboard" in first.stdout
    assert "0 reused from the cache" in first.stdout
    df = pd.read_parquet(tmp_path / "a" / "results.parquet")
    assert (tmp_path / "a" / "results.csv").exists()
    assert set(df.status) == {"ok"} and len(df) == 3 * (1 + 3)
    for col in ["rmse", "psnr", "relmse", "ssim", "flip", "temporal_error", "ms_median", "compile_ms", "samples_used"]:
        assert col in df.columns
    moving = df[(df.scene == "synthetic-moving") & (df["filter"] == "gaussian")]
    assert moving.temporal_error.notna().sum() == 1 and moving.frame.iloc[-1] == 2
    edges = df[df.scene == "synthetic-edges"]
    assert (
        edges.temporal_error.isna().all()
        and edges.notes.str.contains("temporal_error skipped: needs >= 2 frames").all()
    )
    noisy = df[df["filter"] == "passthrough"].rmse.mean()
    assert df[df["filter"] == "gaussian"].rmse.mean() < noisy
    assert (df.samples_used == df.width * df.height).all()
    manifest = json.loads((tmp_path / "a" / "manifest.json").read_text())
    assert manifest["seeds"] == [0] and set(manifest["scenes"]) == {"synthetic-edges", "synthetic-moving"}
    assert len(manifest["references"]) == 4
    names = {(p["kind"], p["name"]): p for p in manifest["plugins"]}
    assert names[("filter", "median3")]["distribution"] == "denoise-median-example"
    assert manifest["packages"]["numba"] and manifest["machine"]["numba_threads"] >= 1

    second = bench(["run", *BASE, "--out", tmp_path / "b", "--cache-dir", cache])
    assert "8 reused from the cache, 0 rendered" in second.stdout
    again = pd.read_parquet(tmp_path / "b" / "results.parquet")
    pd.testing.assert_frame_equal(without_timing(df), without_timing(again))

    shown = bench(["show", tmp_path / "b"])
    assert "gaussian" in shown.stdout and "harness 0.1.0" in shown.stdout


@pytest.mark.slow
def test_a_killed_run_resumes_without_recomputing_stored_jobs(tmp_path):
    args = [
        "run",
        "--scenes",
        "synthetic-moving",
        "--filters",
        "passthrough,gaussian,median3",
        "--spp",
        "1,2",
        "--repeats",
        "3",
        "--seeds",
        "0",
        "--timing-at",
        "none",
        "--quiet",
        "--cache-dir",
        tmp_path / "cache",
    ]
    proc = subprocess.Popen(
        [sys.executable, "-m", "harness.cli", *map(str, args), "--out", str(tmp_path / "k")],
        env=bench_env(),
        stdout=subprocess.DEVNULL,
        stderr=subprocess.DEVNULL,
    )
    jobs = tmp_path / "k" / "jobs"
    deadline = time.time() + 240
    while time.time() < deadline and len(list(jobs.glob("*.parquet"))) < 2 and proc.poll() is None:
        time.sleep(0.05)
    proc.send_signal(signal.SIGKILL)
    proc.wait()
    stored = sorted(p.name for p in jobs.glob("*.parquet"))
    assert 2 <= len(stored) < 6, f"the kill came too late to test resuming ({len(stored)} jobs stored)"
    before = {p: (jobs / p).stat().st_mtime_ns for p in stored}
    resumed = bench([*args, "--out", tmp_path / "k", "--resume"])
    assert f"{len(stored)} stored jobs reused (--resume)" in resumed.stdout
    assert all((jobs / p).stat().st_mtime_ns == t for p, t in before.items())  # not recomputed
    clean = bench([*args, "--out", tmp_path / "clean"])
    assert clean.returncode == 0
    pd.testing.assert_frame_equal(
        without_timing(pd.read_parquet(tmp_path / "k" / "results.parquet")),
        without_timing(pd.read_parquet(tmp_path / "clean" / "results.parquet")),
    )


class _Bad:
    def __init__(self, backend="cpu", mode="raise"):
        self.mode = mode

    def reset(self):
        pass

    def __call__(self, frame, sampler=None):
        if self.mode == "raise":
            raise RuntimeError("kernel exploded")
        if self.mode == "shape":
            return np.zeros((2, 2, 3), np.float32)
        out = np.array(frame["color"], copy=True)
        out[0, 0, 0] = np.nan
        return out


def _bad_plugin():
    mod = types.ModuleType("bad_filters")

    @hookimpl
    def register_filters():
        return [
            FilterSpec(name=f"bad_{m}", version="0", factory=lambda backend="cpu", m=m: _Bad(backend, m))
            for m in ("raise", "shape", "nan")
        ]

    mod.register_filters = register_filters
    return mod


def test_broken_filters_give_error_rows_and_the_run_goes_on(tmp_path):
    reg = load_plugins(extra=[_bad_plugin()])
    df = run_api(reg, tmp_path, ["synthetic-moving"], ["bad_raise", "bad_shape", "bad_nan", "passthrough"], ["rmse"],
                 frames=2, repeats=1)
    status = df.groupby("filter").status.agg(lambda s: ",".join(sorted(set(s))))
    assert status.to_dict() == {"bad_nan": "error", "bad_raise": "error", "bad_shape": "error", "passthrough": "ok"}
    msg = df.set_index("filter").message
    assert "RuntimeError: kernel exploded" in msg["bad_raise"]
    assert "output expected shape (96, 128, 3)" in msg["bad_shape"] and "got shape (2, 2, 3)" in msg["bad_shape"]
    assert "non-finite" in msg["bad_nan"]
    assert (df[df["filter"] == "passthrough"].frame.tolist()) == [0, 1]


@pytest.mark.slow
def test_strict_makes_errors_fail_the_command(tmp_path, fake_distribution):
    path = fake_distribution(
        "bad-dist",
        {"bad": "bad_mod"},
        {
            "bad_mod": """
        import numpy as np
        from harness import FilterSpec, hookimpl
        class Bad:
            def __init__(self, backend="cpu"): pass
            def reset(self): pass
            def __call__(self, frame, sampler=None): raise ValueError("nope")
        @hookimpl
        def register_filters():
            return [FilterSpec(name="bad", version="0", factory=Bad)]
    """
        },
    )
    args = [
        "run",
        "--scenes",
        "synthetic-edges",
        "--filters",
        "bad,passthrough",
        "--quiet",
        "--out",
        tmp_path / "o",
        "--cache-dir",
        tmp_path / "c",
    ]
    lenient = bench(args, env=bench_env(path))
    assert "bad/cpu on synthetic-edges frame 0: ValueError: nope" in lenient.stdout
    strict = bench([*args, "--strict"], env=bench_env(path), check=False)
    assert strict.returncode == 1


def test_planner_skips_with_reasons_and_renders_only_needed_channels():
    colour_only = types.ModuleType("colour_only")

    class Flat:
        def settings(self):
            return {}

        def render(self, scene, frame_index, *, spp, seed, channels, resolution):
            raise NotImplementedError

        def reference(self, scene, frame_index, *, spp, seed, resolution):
            raise NotImplementedError

    @hookimpl
    def register_renderers():
        return [RendererSpec(name="flat", version="0", factory=Flat, provides={"color"}, scene_kinds={"procedural"})]

    @hookimpl
    def register_filters():
        return [FilterSpec(name="gpu_only", version="0", factory=lambda backend="cpu": None, backends=("cuda",))]

    colour_only.register_renderers = register_renderers
    colour_only.register_filters = register_filters
    reg = load_plugins(extra=[colour_only])
    scene = reg.scenes["synthetic-edges"]
    store = RenderStore(reg)
    plan = make_plan(
        reg,
        store,
        [scene],
        ["opencv_jbf", "passthrough", "gpu_only"],
        ["temporal_error", "rmse"],
        renderer="flat",
        backends=["cpu", "cuda"],
    )
    reasons = {(j.filter, j.backend): r for j, r in plan.skipped}
    assert "needs channel(s) ['normal'] that renderer 'flat' does not provide" in reasons[("opencv_jbf", "cpu")]
    assert "has no 'cuda' backend" in reasons[("passthrough", "cuda")]
    assert "has no 'cpu' backend" in reasons[("gpu_only", "cpu")]
    from harness import cuda_available

    if not cuda_available():
        assert "no GPU" in reasons[("gpu_only", "cuda")]
    assert [j.filter for j in plan.jobs] == ["passthrough"]
    assert plan.groups[0].metrics.skipped == {"temporal_error": "needs >= 2 frames, scene has 1"}
    plan = make_plan(reg, store, [scene], ["opencv_jbf", "passthrough"], [])
    assert plan.groups[0].channels == {"color", "normal", "spp"}


def test_unknown_names_and_params_are_clear_errors(tmp_path):
    out = bench(["run", "--filters", "nosuch", "--out", tmp_path / "o"], check=False)
    assert out.returncode == 2 and "no filter named 'nosuch'" in out.stderr
    out = bench(["run", "--filters", "gaussian", "--param", "gaussian.sigmaa=2", "--out", tmp_path / "o"], check=False)
    assert out.returncode == 2 and "has no parameter(s) ['sigmaa']" in out.stderr
    out = bench(["run", "--filters", "eaw", "--param", "eaw.iterations=-3", "--out", tmp_path / "o"], check=False)
    assert out.returncode == 2 and "parameter 'iterations' must be int in [1, 10], got -3" in out.stderr


def test_cache_key_misses_when_the_scene_changes(tmp_path):
    reg = load_plugins()
    store = RenderStore(reg, Cache(tmp_path), resolution=(16, 12))
    scene = reg.scenes["synthetic-edges"].factory()
    store.frame(scene, "synthetic", 0, spp=1, seed=0, channels={"normal"})
    store.frame(scene, "synthetic", 0, spp=1, seed=0, channels={"normal"})
    assert store.cache.hits == {"frames": 1} and store.cache.misses == {"frames": 1}
    changed = reg.scenes["synthetic-edges"].factory()
    changed.params = {**changed.params, "checker": 4}
    changed._hash = None
    store.frame(changed, "synthetic", 0, spp=1, seed=0, channels={"normal"})
    assert store.cache.misses == {"frames": 2}


@pytest.mark.slow
@pytest.mark.skipif(os.name != "posix", reason="uses POSIX signals")
def test_pictures_are_written(tmp_path):
    bench(
        [
            "run",
            "--scenes",
            "synthetic-edges",
            "--filters",
            "gaussian",
            "--pictures",
            "--quiet",
            "--out",
            tmp_path / "o",
            "--cache-dir",
            tmp_path / "c",
        ]
    )
    images = sorted(p.name for p in (tmp_path / "o" / "images" / "synthetic-edges").glob("*.png"))
    assert images == ["gaussian-cpu-spp1.png", "input-spp1.png", "reference.png"]


@pytest.mark.slow
def test_mesh_scenes_run_end_to_end_with_the_path_tracer(tmp_path):
    out = bench(["run", "--scenes", "cornell,street", "--frames", "2", "--resolution", "32x24", "--reference-spp", "16",
                 "--filters", "eaw,svgf,sbf,lbf,passthrough", "--strict", "--quiet", "--repeats", "1",
                 "--seeds", "0", "--timing-at", "none", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert set(df.status) == {"ok"}, out.stdout
    assert set(df.renderer) == {"pathtracer"} and len(df) == 5 * (2 + 2)
    assert np.isfinite(df[["rmse", "ssim", "flip", "relmse"]].to_numpy()).all()
    street = df[df.scene == "street"]
    assert street.groupby("filter").temporal_error.count().eq(1).all()


def test_manifest_records_the_code_at_the_start_of_the_run(tmp_path, monkeypatch):
    """A checkout that changes while a run goes on (a commit, a pull) is not what ran: the
    manifest keeps the commit read when the run started."""
    import harness.manifest
    import harness.run

    def at(commit):
        return lambda: {"git_commit": commit, "dirty": False, "version": "0"}

    monkeypatch.setattr(harness.run, "provenance", at("a" * 40))  # read at the start
    monkeypatch.setattr(harness.manifest, "provenance", at("b" * 40))  # what the checkout holds later
    run_api(load_plugins(), tmp_path, ["synthetic-static"], ["passthrough"], ["rmse"], frames=1, repeats=1)
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["git_commit"] == "a" * 40
