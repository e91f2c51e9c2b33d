"""References rendered in resumable chunks, and the render/bench commands."""

import numpy as np
import pytest

from harness import load_plugins
from harness.cache import Cache
from harness.renders import REFERENCE_SEED, RenderStore
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


def _store(tmp_path):
    reg = load_plugins()
    return RenderStore(reg, Cache(tmp_path / "cache"), resolution=(20, 10)), reg


def test_chunked_reference_resumes_where_it_stopped(tmp_path):
    store, reg = _store(tmp_path)
    scene = store.scene("synthetic-edges")
    inner = reg.renderers["synthetic"].factory()
    store._renderers["synthetic"] = Interrupting(inner, fail_after=2)
    with pytest.raises(KeyboardInterrupt):
        store.reference(scene, "synthetic", 0, spp=20, chunk=6)
    assert store._renderers["synthetic"].calls == [(0, 6), (6, 6)]
    resumed = Interrupting(inner, fail_after=99)
    store._renderers["synthetic"] = resumed
    ref = store.reference(scene, "synthetic", 0, spp=20, chunk=6)
    assert resumed.calls == [(12, 6), (18, 2)]  # the first 12 samples were not rendered again
    whole = inner.accumulate(scene, 0, first_sample=0, count=20, seed=REFERENCE_SEED, resolution=(20, 10)) / 20
    np.testing.assert_allclose(ref, whole, rtol=1e-6)
    assert not list((tmp_path / "cache" / "partial").rglob("*.npz"))  # the checkpoint is gone
    again = Interrupting(inner, fail_after=0)
    store._renderers["synthetic"] = again
    assert np.array_equal(store.reference(scene, "synthetic", 0, spp=20, chunk=6), ref)  # from the cache


def test_chunking_does_not_change_a_reference(tmp_path):
    """Sums of consecutive chunks added in order give the same reference bit for bit."""
    store, _ = _store(tmp_path)
    a = store.reference("synthetic-moving", "synthetic", 1, spp=12, chunk=5)
    b = RenderStore(store.registry, Cache(tmp_path / "other"), resolution=(20, 10)).reference(
        "synthetic-moving", "synthetic", 1, spp=12, chunk=12)
    assert np.array_equal(a, b)


def test_chunk_and_spp_must_be_positive(tmp_path):
    store, _ = _store(tmp_path)
    for bad in (0, -5, 2.5):
        with pytest.raises(ValueError, match="chunk must be an integer >= 1"):
            store.reference("synthetic-edges", "synthetic", 0, spp=8, chunk=bad)
    with pytest.raises(ValueError, match="reference spp"):
        store.reference("synthetic-edges", "synthetic", 0, spp=-1)


def test_an_invalid_checkpoint_is_discarded_with_a_warning(tmp_path):
    """A checkpoint claiming a negative sample count (what --chunk -5 used to store) is not trusted."""
    store, _ = _store(tmp_path)
    scene = store.scene("synthetic-edges")
    key = store.key("reference", scene, "synthetic", 0, spp=8, seed=REFERENCE_SEED)
    store.cache.store("partial", key, {"sum": np.zeros((10, 20, 3)), "done": np.asarray(-5)})
    with pytest.warns(UserWarning, match="checkpoint .* is invalid"):
        ref = store.reference(scene, "synthetic", 0, spp=8, chunk=3)
    fresh = RenderStore(store.registry, resolution=(20, 10)).reference(scene, "synthetic", 0, spp=8, chunk=3)
    assert np.array_equal(ref, fresh)


@pytest.mark.slow
def test_render_command_fills_the_cache_that_run_uses(tmp_path):
    out = bench(["render", "--scenes", "synthetic-static", "--frames", "2", "--spp", "8", "--chunk", "3",
                 "--cache-dir", tmp_path / "c"])
    assert "synthetic-static: 2 reference frame(s) at 8 spp, 128x96, in the cache" in out.stdout
    run = bench(["run", "--scenes", "synthetic-static", "--frames", "2", "--filters", "passthrough",
                 "--reference-spp", "8", "--quiet", "--seeds", "0", "--timing-at", "none", "--out", tmp_path / "o",
                 "--cache-dir", tmp_path / "c"])
    assert "2 reused from the cache, 2 rendered" in run.stdout  # references reused, noisy frames rendered


@pytest.mark.slow
def test_bench_command_reports_ratios_to_peers():
    out = bench(["bench", "gaussian", "--peers", "passthrough", "--resolution", "64x48,32x16", "--repeats", "2"])
    lines = out.stdout.splitlines()
    assert any(line.split()[:2] == ["gaussian", "64x48"] for line in lines)
    assert "x_vs_passthrough" in out.stdout and "rmse" in out.stdout


@pytest.mark.slow
def test_bench_without_error_renders_no_reference(tmp_path):
    out = bench(["bench", "noaa", "--peers", "taa", "--task", "antialias", "--scene", "aa-fence", "--resolution",
                 "32x18", "--repeats", "2", "--no-error", "--cache-dir", tmp_path / "c"])
    assert "x_vs_taa" in out.stdout and "rmse" not in out.stdout
    stored = [p for p in (tmp_path / "c").rglob("*") if p.is_file()]
    assert len(stored) == 2, stored  # the two frames taa needs; no reference
