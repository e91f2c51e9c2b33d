"""``denoise-bench bench``'s instrument: the floor, thread counts, peak memory, the table's columns.

No timings are asserted (timings are not tests); what is tested is that every number is there,
typed, measured where it should be and sane.
"""

import ctypes
import math

import numpy as np
import pytest

from harness import CHANNELS, FilterSpec, Frame, load_plugins
from harness.bench import COLUMNS, bench_filters
from harness.bench_markdown import bench_markdown
from harness.cache import Cache
from harness.cli.parser import build_parser
from harness.executors import InlineExecutor, LocalExecutor
from harness.executors.base import PluginOptions
from harness.floor import Floor, floor_of
from harness.memory import peak_memory
from harness.renders import RenderStore
from harness.threads import compute_threads, max_threads, using_threads
from tests import bench_plugins
from tests.test_run import bench as cli


def random_frame(h=6, w=5, seed=0) -> dict:
    rng = np.random.default_rng(seed)
    arrays = {}
    for name, (comps, dtype, _) in CHANNELS.items():
        shape = (h, w) if comps == 1 else (h, w, comps)
        arrays[name] = (rng.integers(0, 9, shape) if dtype == np.int32 else rng.random(shape)).astype(dtype)
    return arrays


def pixel_sum(arrays: dict, names) -> np.ndarray:
    """What the floor must write: per-pixel sum of every value (RGB planes component-wise)."""
    h, w = arrays["color"].shape[:2]
    rgb, extra = np.zeros((h, w, 3)), np.zeros((h, w))
    for name in names:
        a = arrays[name].astype(np.float64)
        if a.ndim == 3 and a.shape[2] == 3:
            rgb += a
        else:
            extra += a.reshape(h, w, -1).sum(axis=-1)
    return rgb + extra[..., None]


def test_floor_reads_every_declared_input_and_nothing_else():
    arrays = random_frame()
    declared = {"normal", "depth", "object_id", "motion", "spp", "variance"}
    floor = Floor(declared)
    out = floor(Frame(arrays))
    assert out.dtype == np.float32 and out.shape == (6, 5, 3)
    np.testing.assert_allclose(out, pixel_sum(arrays, declared | {"color"}), rtol=1e-6)
    for name in sorted(declared | {"color"}):
        changed = dict(arrays)
        changed[name] = arrays[name].copy()
        if changed[name].dtype == np.float32:
            changed[name][2, 3] = np.nan  # every component of pixel (2, 3) must turn NaN
            got = Floor(declared)(Frame(changed))
            assert np.isnan(got[2, 3]).all(), name
            assert np.isfinite(np.delete(got.reshape(-1, 3), 2 * 5 + 3, axis=0)).all(), name
        else:
            changed[name][2, 3] += 1000
            got = Floor(declared)(Frame(changed))
            np.testing.assert_allclose(got[2, 3] - out[2, 3], 1000, rtol=1e-5, err_msg=name)
    undeclared = dict(arrays)
    undeclared["albedo"] = np.full_like(arrays["albedo"], np.nan)
    assert np.isfinite(Floor(declared)(Frame(undeclared))).all()


def test_temporal_floor_also_reads_its_history():
    arrays = random_frame()
    spec = FilterSpec(name="t", version="0", factory=lambda backend="cpu": None, requires={"color", "normal"},
                      temporal=True)
    floor, fspec = floor_of(spec)
    assert fspec.temporal and floor.channels == ("color", "normal")
    first = floor(Frame(arrays)).copy()
    kept = (floor.out, floor.history)  # both buffers exist after a sequence's first call
    assert kept[0] is not None and kept[1] is not None and kept[0] is not kept[1]
    second = floor(Frame(arrays))
    assert second is kept[0] and floor.history is kept[0] and floor.out is kept[1]  # used in turn
    np.testing.assert_allclose(second, first * 2, rtol=1e-6)  # inputs + the previous output
    floor.reset()
    np.testing.assert_allclose(floor(Frame(arrays)), first, rtol=1e-6)


def test_using_threads_sets_and_restores_the_count():
    before = compute_threads()
    with using_threads(1) as n:
        assert n == 1 and compute_threads() == 1
    assert compute_threads() == before
    with pytest.raises(ValueError, match="threads must be an integer in"):
        with using_threads(max_threads() + 1):
            pass


def test_threads_option_parsing():
    parse = build_parser().parse_args
    limit = max_threads()
    assert parse(["bench", "eaw", "--threads", "1,all"]).threads == list(dict.fromkeys([1, limit]))
    assert parse(["bench", "eaw", "--threads", "1,1"]).threads == [1]
    assert parse(["bench", "eaw"]).threads is None


@pytest.mark.parametrize("value, message", [
    ("0", "--threads: must be in [1, "), ("two", "--threads: must be thread counts"), ("", "must be thread counts"),
    ("1,-2", "--threads: must be in [1, "), ("big", "must be thread counts"),
])
def test_bad_threads_is_one_line_and_exit_2(value, message, capsys):
    with pytest.raises(SystemExit) as stop:
        build_parser().parse_args(["bench", "eaw", "--threads", value])
    assert stop.value.code == 2
    lines = [line for line in capsys.readouterr().err.splitlines() if line.strip()]
    assert len(lines) == 1 and message in lines[0], lines


def test_too_many_threads_from_the_command_line():
    out = cli(["bench", "passthrough", "--threads", str(max_threads() + 1)], check=False)
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert out.returncode == 2 and len(lines) == 1 and f"must be in [1, {max_threads()}]" in lines[0], out.stderr


def test_peak_memory_counts_native_allocations_in_rss():
    libc = ctypes.CDLL(None)
    libc.malloc.restype = ctypes.c_void_p
    size = 32 * 2**20

    def work():
        pointer = libc.malloc(size)
        ctypes.memset(pointer, 1, size)
        libc.free(ctypes.c_void_p(pointer))

    peak = peak_memory(work)[1]
    if math.isnan(peak.rss):
        pytest.skip("the resident set's high-water mark cannot be reset here (/proc/self/clear_refs)")
    assert peak.traced < 2**20 and 0.95 * size <= peak.rss < 1.5 * size and peak.peak == peak.rss


@pytest.fixture(scope="module")
def local_table(tmp_path_factory):
    """One bench in the local executor's worker: two filters, two resolutions, 1 and all threads."""
    registry = load_plugins(extra=[bench_plugins])
    store = RenderStore(registry, Cache(tmp_path_factory.mktemp("cache")))
    threads = list(dict.fromkeys([1, max_threads()]))
    with LocalExecutor(plugins=PluginOptions(modules=["tests.bench_plugins"])) as executor:
        result = bench_filters(registry, store, executor, ["alloc_frames", "threads_probe"], peers=["passthrough"],
                               scene="synthetic-edges", resolutions=[(256, 192), (128, 96)], threads=threads,
                               repeats=2, error=False)
    return result, threads


@pytest.mark.slow
def test_table_columns_are_present_and_typed(local_table):
    result, threads = local_table
    table = result.table
    assert list(table.columns[:len(COLUMNS) - 1]) == [c for c in COLUMNS if c != "rmse"]
    for name, dtype in COLUMNS.items():
        if name != "rmse":
            assert str(table[name].dtype) == dtype or (dtype == "str" and table[name].map(type).eq(str).all()), name
    assert (table["status"] == "ok").all(), table[["filter", "status"]]
    assert len(table) == 3 * 2 * len(threads)
    for column in ("ms_median", "cpu_ms", "floor_ms", "floor_cpu_ms", "x_of_floor", "peak_mb", "peak_frames",
                   "x_vs_passthrough", "x_of_256x192"):
        assert table[column].dtype == np.float64 and (table[column] > 0).all(), column
    base = table[table["resolution"] == "256x192"]
    assert (base["x_of_256x192"] == 1).all()
    if len(threads) > 1:
        assert f"speedup_vs_{threads[0]}t" in table
    markdown = bench_markdown(result, "denoise-bench bench alloc_frames")
    assert "Command: `denoise-bench bench alloc_frames`" in markdown and "Machine: " in markdown
    assert "| x_of_floor | x_of_floor_cpu | peak_mb |" in markdown


@pytest.mark.slow
def test_a_stage_named_like_a_key_column_keeps_the_key(local_table):
    stages = local_table[0].stages
    assert set(stages["filter"]) == {"threads_probe"}
    assert (stages["filter (stage)"] == 1.5).all() and (stages["copy"] == 0.5).all()


@pytest.mark.slow
def test_threads_reach_the_worker(local_table):
    """The ``threads`` column is ``numba.get_num_threads()`` read in the worker during the job."""
    result, threads = local_table
    table = result.table
    for name in ("alloc_frames", "threads_probe", "passthrough"):
        assert list(table[table["filter"] == name]["threads"]) == [n for _ in range(2) for n in threads]


@pytest.mark.slow
def test_peak_memory_of_a_filter_that_allocates_ten_frames(local_table):
    table = local_table[0].table
    big = table[(table["filter"] == "alloc_frames") & (table["resolution"] == "256x192")]
    # ten held frames and the output; allocator and interpreter overhead on top
    frames = big["peak_frames"]
    assert ((frames >= bench_plugins.FRAMES + 0.9) & (frames < bench_plugins.FRAMES + 3)).all(), big
    assert (big["traced_mb"] >= (bench_plugins.FRAMES + 0.9) * 256 * 192 * 12 / 1e6).all()
    copy = table[(table["filter"] == "passthrough") & (table["resolution"] == "256x192")]
    assert (copy["peak_frames"] < 3).all(), copy


def test_inline_bench_keeps_the_thread_count_of_the_caller(tmp_path):
    registry = load_plugins(extra=[bench_plugins])
    store = RenderStore(registry, Cache(tmp_path / "c"))
    before = compute_threads()
    result = bench_filters(registry, store, InlineExecutor(registry), ["threads_probe"], resolutions=[(32, 24)],
                           threads=[1], repeats=1, error=False)
    assert list(result.table["threads"]) == [1] and compute_threads() == before


def test_temporal_floor_is_warmed_up_on_its_history_layout_before_it_is_timed(monkeypatch):
    """From the second frame a temporal floor reads one more buffer (its history): a kernel of
    another layout, compiled by a warm-up call, never inside the timed calls."""
    import harness.bench
    import harness.floor

    monkeypatch.setattr(harness.floor, "_KERNELS", {})  # nothing compiled yet in this process
    compiled_during_timed_calls = []
    real_time_frame = harness.bench.time_frame

    def time_frame(filt, spec, backend, frame, first, repeats, *args, **kwargs):
        if not first:
            before = len(harness.floor._KERNELS)
            result = real_time_frame(filt, spec, backend, frame, first, repeats, *args, **kwargs)
            compiled_during_timed_calls.append(len(harness.floor._KERNELS) - before)
            return result
        return real_time_frame(filt, spec, backend, frame, first, repeats, *args, **kwargs)

    monkeypatch.setattr(harness.bench, "time_frame", time_frame)
    spec = FilterSpec(name="t", version="0", factory=lambda backend="cpu": None, requires={"color", "normal"},
                      temporal=True)
    frames = [Frame(random_frame(seed=s)) for s in range(3)]
    timing = harness.bench.time_floor(spec, frames, repeats=1)
    assert timing["repeats"] == 1 and math.isfinite(timing["ms_median"])
    assert len(harness.floor._KERNELS) == 2  # without and with the history
    assert sum(compiled_during_timed_calls) == 0


def test_peers_without_the_benchs_backend_are_timed_on_their_own():
    """``--backend cuda`` with CPU-only peers: the peers run on the CPU and their rows say so."""
    from harness.bench import BenchSetup, backend_note

    registry = load_plugins()
    setup = BenchSetup.of(registry, ["eaw"], ["opencv_jbf"], scene="synthetic-edges", renderer=None,
                          task="denoise", params=None, presets=None, steady=0, error=False)
    eaw, jbf = registry.filters["eaw"], registry.filters["opencv_jbf"]
    assert "cuda" in eaw.backends and "cuda" not in jbf.backends
    assert setup.backend_of(eaw, "cuda") == "cuda" and setup.backend_of(jbf, "cuda") == "cpu"
    assert setup.backend_of(jbf, "cpu") == "cpu"
    assert backend_note("cpu", "cuda") == "timed on cpu: no cuda backend" and backend_note("cpu", "cpu") == ""


@pytest.mark.slow
def test_bench_on_the_cuda_simulator_times_cpu_only_peers_on_the_cpu(tmp_path):
    import os
    import subprocess
    import sys

    env = {**os.environ, "NUMBA_ENABLE_CUDASIM": "1"}
    out = subprocess.run([sys.executable, "-m", "harness.cli", "bench", "eaw", "--backend", "cuda", "--peers",
                          "opencv_jbf", "--resolution", "8x8", "--repeats", "1", "--no-error", "--quiet",
                          "--cache-dir", str(tmp_path / "cache")], env=env, capture_output=True, text=True,
                         timeout=900)
    assert out.returncode == 0, out.stderr
    table = out.stdout.split("Per-stage")[0]
    rows = [line for line in table.splitlines() if line.strip().startswith(("eaw", "opencv_jbf"))]
    assert len(rows) == 2 and all(" ok " in r for r in rows), out.stdout
    assert "timed on cpu: no cuda backend" in next(r for r in rows if r.strip().startswith("opencv_jbf"))
