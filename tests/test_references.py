"""References rendered in resumable chunks, and the render/bench commands."""

import numpy as np
import pytest

from harness import load_plugins
from harness.cache import Cache
from harness.plan import make_plan
from harness.runner import Runner, RunOptions
from tests.test_run import bench


class Interrupting:
    """Wraps a renderer and raises KeyboardInterrupt after ``fail_after`` accumulate calls."""

    def __init__(self, inner, fail_after):
        self.inner, self.fail_after, self.calls = inner, fail_after, []

    def settings(self):
        return self.inner.settings()

    def accumulate(self, scene, frame_index, *, first_sample, count, seed, resolution):
        if len(self.calls) == self.fail_after:
            raise KeyboardInterrupt
        self.calls.append((first_sample, count))
        return self.inner.accumulate(scene, frame_index, first_sample=first_sample, count=count, seed=seed,
                                     resolution=resolution)


def _runner(tmp_path):
    reg = load_plugins()
    plan = make_plan(reg, [reg.scenes["synthetic-edges"]], [], [], resolution=(20, 10))
    return Runner(reg, plan, Cache(tmp_path / "cache"), tmp_path / "o", RunOptions(progress=False)), reg


def test_chunked_reference_resumes_where_it_stopped(tmp_path):
    runner, reg = _runner(tmp_path)
    scene = runner.scene("synthetic-edges")
    inner = reg.renderers["synthetic"].factory()
    runner._renderers["synthetic"] = Interrupting(inner, fail_after=2)
    with pytest.raises(KeyboardInterrupt):
        runner.ensure_reference("synthetic", scene, 0, spp=20, chunk=6)
    assert runner._renderers["synthetic"].calls == [(0, 6), (6, 6)]
    resumed = Interrupting(inner, fail_after=99)
    runner._renderers["synthetic"] = resumed
    ref = runner.ensure_reference("synthetic", scene, 0, spp=20, chunk=6)
    assert resumed.calls == [(12, 6), (18, 2)]  # the first 12 samples were not rendered again
    whole = inner.accumulate(scene, 0, first_sample=0, count=20, seed=1_000_003, resolution=(20, 10)) / 20
    np.testing.assert_allclose(ref, whole, rtol=1e-6)
    assert not list((tmp_path / "cache" / "partial").rglob("*.npz"))  # the checkpoint is gone
    again = Interrupting(inner, fail_after=0)
    runner._renderers["synthetic"] = again
    assert np.array_equal(runner.ensure_reference("synthetic", scene, 0, spp=20, chunk=6), ref)  # from the cache


def test_render_command_fills_the_cache_that_run_uses(tmp_path):
    out = bench(["render", "--scenes", "synthetic-static", "--frames", "2", "--spp", "8", "--chunk", "3",
                 "--cache-dir", tmp_path / "c"])
    assert "synthetic-static: 2 reference frame(s) at 8 spp, 128x96, in the cache" in out.stdout
    run = bench(["run", "--scenes", "synthetic-static", "--frames", "2", "--filters", "passthrough",
                 "--reference-spp", "8", "--quiet", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    assert "2 reused from the cache, 2 rendered" in run.stdout  # references reused, noisy frames rendered


def test_bench_command_reports_ratios_to_peers():
    out = bench(["bench", "gaussian", "--peers", "passthrough", "--resolution", "64x48,32x16", "--repeats", "2"])
    lines = out.stdout.splitlines()
    assert any(line.split()[:2] == ["gaussian", "64x48"] for line in lines)
    assert "x_vs_passthrough" in out.stdout and "rmse" in out.stdout
