"""The dask executor on a real ``distributed.LocalCluster`` of 2 worker processes.

References chunked over workers are bit-identical to local ones, a run's metric columns equal
the local executor's, a worker killed while it holds tasks is replaced and the run completes
with the same table, and a task that kills every worker it runs on becomes a named error row.
"""

import importlib.util
import json
import os
import signal
import subprocess
import sys
import threading
import time

import numpy as np
import pandas as pd
import pytest

from harness import load_plugins
from harness.benchmark import run_benchmark
from harness.cache import Cache
from harness.executors import make_executor
from harness.executors.base import PluginOptions
from harness.remote_renders import RemoteRenders
from harness.renders import RenderStore
from harness.rows import TIMING_COLUMNS
from tests import dask_plugins
from tests.conftest import bench_env
from tests.test_run import bench

needs_dask = pytest.mark.skipif(importlib.util.find_spec("distributed") is None,
                                reason='the dask executor needs the optional extra: pip install -e ".[dask]"')

PLUGINS = PluginOptions(modules=["tests.dask_plugins"])
SCENES = ["synthetic-edges", "synthetic-moving"]
METRICS = ["rmse", "psnr", "ssim", "temporal_error"]


@pytest.fixture(scope="module")
def registry():
    return load_plugins(extra=[dask_plugins])


@pytest.fixture(scope="module")
def cluster(registry):
    """A local cluster of 2 worker processes; a task may see 1 worker die under it and still run."""
    with make_executor("dask", registry=registry, plugins=PLUGINS, workers=2, allowed_failures=1,
                       dashboard_address=":0") as executor:
        yield executor


def comparable(df):
    """The table without what differs between machines and runs (times, machine, threads)."""
    return df.drop(columns=[*TIMING_COLUMNS, "machine", "threads"]).sort_values(["job_id", "frame"]).reset_index(
        drop=True)


def run(registry, executor, tmp_path, filters, scenes=SCENES, name="o", seeds=(0,)):
    return run_benchmark(out=tmp_path / name, registry=registry, executor=executor, scenes=scenes, filters=filters,
                         metrics=METRICS, frames=3, repeats=1, reference_spp=24, seeds=seeds, timing_at=(),
                         resolution=(40, 30), cache_dir=tmp_path / f"cache-{name}").table


@pytest.mark.slow
@needs_dask
def test_the_cluster_has_two_worker_processes(cluster):
    pids = cluster.client.run(os.getpid)
    assert len(pids) == 2 and len(set(pids.values())) == 2 and os.getpid() not in pids.values()
    assert cluster.describe()["workers"] == 2 and cluster.allowed_failures == 1


@pytest.mark.slow
@needs_dask
@pytest.mark.parametrize(("scene", "renderer", "frames", "spp", "chunk"),
                         [("synthetic-moving", "synthetic", 3, 23, 5), ("cornell", "pathtracer", 1, 10, 3)])
def test_a_chunked_reference_is_bit_identical_to_the_local_one(registry, cluster, tmp_path, scene, renderer, frames,
                                                               spp, chunk):
    local = RenderStore(registry, resolution=(24, 16))
    expected = [local.reference(scene, renderer, t, spp=spp, chunk=spp) for t in range(frames)]  # one chunk
    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(24, 16))
    added = []
    with RemoteRenders(store, cluster, chunk=chunk) as renders:
        futures = [renders.reference(scene, renderer, t, spp=spp, progress=added.append) for t in range(frames)]
        got = [f.result() for f in futures]
    for want, have in zip(expected, got):
        assert have.dtype == np.float32 and np.array_equal(want, have)
    assert sum(added) == frames * spp
    assert store.cache.misses["references"] == frames and not list((tmp_path / "c" / "partial").rglob("*.npz"))


@pytest.mark.slow
@needs_dask
def test_a_reference_resumes_from_its_stored_chunks(registry, cluster, tmp_path):
    """A checkpoint left by an interrupted render is used: only the remaining chunks are tasks."""
    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(24, 16))
    scene = store.scene("synthetic-static")
    part = store.accumulate(scene, "synthetic", 0, 0, 4) + store.accumulate(scene, "synthetic", 0, 4, 4)
    key = store.key("reference", scene, "synthetic", 0, spp=20, seed=1_000_003)
    store.cache.store("partial", key, {"sum": part, "done": np.asarray(8)})
    added = []
    with RemoteRenders(store, cluster, chunk=4) as renders:
        ref = renders.reference(scene, "synthetic", 0, spp=20, progress=added.append).result()
    assert added == [8, 4, 4, 4]  # the stored 8 samples, then three chunk tasks
    assert np.array_equal(ref, RenderStore(registry, resolution=(24, 16)).reference(scene, "synthetic", 0, spp=20))


def kill_a_worker_running(client, prefix: str, while_alive, timeout: float = 120) -> list:
    """Kill (SIGKILL, by pid) the first worker seen running a task whose key starts with ``prefix``."""
    deadline = time.time() + timeout
    while time.time() < deadline and while_alive():
        for address, keys in client.processing().items():
            if any(str(k).startswith(prefix) for k in keys):
                pid = client.run(os.getpid, workers=[address])[address]
                os.kill(pid, signal.SIGKILL)
                return [pid]
        time.sleep(0.02)
    return []


@pytest.mark.slow
@needs_dask
def test_a_worker_killed_while_it_renders_a_chunk_loses_and_repeats_no_samples(registry, cluster, tmp_path):
    """The killed chunk runs again elsewhere; the reference is the local one and each sample counts once."""
    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(24, 16))
    added, result = [], {}
    with RemoteRenders(store, cluster, chunk=2) as renders:
        future = renders.reference("synthetic-moving", "slow-synthetic", 1, spp=16, progress=added.append)
        killed = kill_a_worker_running(cluster.client, "ChunkUnit", lambda: not future.done())
        result["ref"] = future.result(timeout=120)
    assert killed, "no chunk was seen running on a worker"
    local = RenderStore(registry, resolution=(24, 16)).reference("synthetic-moving", "synthetic", 1, spp=16, chunk=16)
    assert np.array_equal(result["ref"], local)
    assert sum(added) == 16 and len(added) == 8  # every chunk once
    cluster.client.wait_for_workers(2, timeout=60)
    assert killed[0] not in cluster.client.run(os.getpid).values()


@pytest.mark.slow
@needs_dask
def test_frames_rendered_on_workers_equal_local_ones(registry, cluster, tmp_path):
    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(24, 16))
    channels = {"albedo", "normal", "motion", "spp"}
    with RemoteRenders(store, cluster) as renders:
        frame = renders.frame("synthetic-moving", "synthetic", 2, spp=2, seed=7, channels=channels).result()
    local = RenderStore(registry, resolution=(24, 16)).frame("synthetic-moving", "synthetic", 2, spp=2, seed=7,
                                                              channels=channels)
    assert frame.channels == local.channels
    for name in local.channels:
        assert np.array_equal(frame[name], local[name]), name


@pytest.mark.slow
@needs_dask
def test_a_run_has_the_metric_columns_of_the_local_run(registry, cluster, tmp_path):
    filters = ["passthrough", "gaussian", "median3", "slow"]
    on_cluster = run(registry, cluster, tmp_path, filters, name="dask")
    with make_executor("local", registry=registry, plugins=PLUGINS) as local:
        here = run(registry, local, tmp_path, filters, name="local")
    assert set(on_cluster.status) == {"ok"} and len(on_cluster) == len(filters) * (1 + 3)
    pd.testing.assert_frame_equal(comparable(on_cluster), comparable(here))
    assert on_cluster.ms_median.notna().all() and (on_cluster.machine != "").all()
    stored = sorted(p.stem for p in (tmp_path / "dask" / "jobs").glob("*.parquet"))
    assert stored == sorted(on_cluster.job_id.unique())


@pytest.mark.slow
@needs_dask
def test_a_worker_killed_while_it_holds_tasks_is_replaced_and_the_run_completes(registry, cluster, tmp_path):
    filters = ["slow", "passthrough", "gaussian"]
    expected = run(registry, make_executor("inline", registry=registry), tmp_path, filters, name="inline", seeds=[0, 1])
    client = cluster.client
    result = {}

    def background():
        result["table"] = run(registry, cluster, tmp_path, filters, name="dask", seeds=[0, 1])

    thread = threading.Thread(target=background)
    thread.start()
    killed = kill_a_worker_running(client, "JobUnit", thread.is_alive)
    thread.join(300)
    assert killed, "no job was seen running on a worker"
    assert not thread.is_alive() and "table" in result
    table = result["table"]
    assert set(table.status) == {"ok"}, table[table.status != "ok"].message.tolist()
    pd.testing.assert_frame_equal(comparable(table), comparable(expected))
    client.wait_for_workers(2, timeout=60)  # the nanny started a new worker process
    assert killed[0] not in client.run(os.getpid).values()


@pytest.mark.slow
@needs_dask
def test_a_task_that_kills_its_workers_becomes_a_named_error_row(registry, cluster, tmp_path):
    table = run(registry, cluster, tmp_path, ["exits", "gaussian"], scenes=["synthetic-edges"], name="exits")
    bad = table[table["filter"] == "exits"]
    assert list(bad.status) == ["error"]
    message = bad.message.iloc[0]
    assert message.startswith("exits/cpu on synthetic-edges: 2 workers died running it") and "1 retries" in message
    # a job that ran beside it on a dying worker is a suspect too (Dask's allowed-failures count
    # every task the worker was running): it is ok, or an error naming the deaths, never lost
    good = table[table["filter"] == "gaussian"]
    assert len(good) and all(s == "ok" or "workers died" in m for s, m in zip(good.status, good.message))
    cluster.client.wait_for_workers(2, timeout=60)
    again = run(registry, cluster, tmp_path, ["gaussian"], scenes=["synthetic-edges"], name="again")
    assert set(again.status) == {"ok"}  # the cluster is whole again


@pytest.mark.slow
@needs_dask
def test_cli_render_then_run_on_a_local_cluster(tmp_path):
    cache = tmp_path / "cache"
    render = bench(["render", "--scenes", "synthetic-static", "--frames", "2", "--spp", "9", "--chunk", "4",
                    "--resolution", "32x24", "--executor", "dask", "--workers", "2", "--cache-dir", cache])
    assert "dask: a local cluster, 2 worker(s) on 1 machine(s); dashboard" in render.stderr
    assert "synthetic-static: 2 reference frame(s) at 9 spp, 32x24, in the cache" in render.stdout
    out = bench(["run", "--scenes", "synthetic-static", "--frames", "2", "--resolution", "32x24", "--reference-spp",
                 "9", "--filters", "passthrough,gaussian", "--repeats", "1", "--seeds", "0", "--timing-at", "none",
                 "--executor", "dask", "--quiet",
                 "--out", tmp_path / "o", "--cache-dir", cache])
    assert "2 reused from the cache, 2 rendered" in out.stdout  # the references, then the noisy frames
    table = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert set(table.status) == {"ok"} and len(table) == 4
    assert json.loads((tmp_path / "o" / "manifest.json").read_text())["executor"]["executor"] == "dask"


@pytest.mark.slow
@needs_dask
def test_an_interrupted_cluster_run_resumes_like_a_local_one(tmp_path):
    def args(executor, out):
        extra = ["--executor", "dask", "--workers", "2"] if executor == "dask" else []
        return ["run", "--scenes", "synthetic-moving", "--filters", "passthrough,gaussian,median3", "--spp", "1,2,4,8",
                "--frames", "4", "--resolution", "160x120", "--repeats", "30", "--seeds", "0", "--timing-at", "none",
                "--quiet", "--cache-dir",
                tmp_path / f"cache-{executor}", "--out", tmp_path / out, *extra]

    # the local run first: every kernel the runs use is compiled (Numba's cache) before the interrupted run
    bench(args("local", "clean"))
    # SIGINT as a terminal gives it: a process inherits an ignored SIGINT (something in a full test session
    # leaves the test process ignoring it), and an ignored SIGINT stays ignored in the run
    proc = subprocess.Popen([sys.executable, "-m", "harness.cli", *map(str, args("dask", "k"))], env=bench_env(),
                            stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                            preexec_fn=lambda: signal.signal(signal.SIGINT, signal.SIG_DFL))
    jobs = tmp_path / "k" / "jobs"
    deadline = time.time() + 240
    while time.time() < deadline and len(list(jobs.glob("*.parquet"))) < 2 and proc.poll() is None:
        time.sleep(0.02)
    proc.send_signal(signal.SIGINT)
    _, err = proc.communicate(timeout=120)
    stored = sorted(p.name for p in jobs.glob("*.parquet"))
    assert proc.returncode == 130 and "interrupted; stored results are kept" in err, err
    # 12 jobs, each long enough (30 timed calls per frame) that the interrupt lands mid-run: with 6 short
    # ones a loaded machine sometimes saw the run end before the signal came
    assert 2 <= len(stored) < 12, f"the interrupt came too late to test resuming ({len(stored)} jobs stored)"
    before = {p: (jobs / p).stat().st_mtime_ns for p in stored}
    resumed = bench([*args("dask", "k"), "--resume"])
    assert f"{len(stored)} stored jobs reused (--resume)" in resumed.stdout
    assert all((jobs / p).stat().st_mtime_ns == t for p, t in before.items())  # not recomputed
    pd.testing.assert_frame_equal(comparable(pd.read_parquet(tmp_path / "k" / "results.parquet")),
                                  comparable(pd.read_parquet(tmp_path / "clean" / "results.parquet")))


def test_without_distributed_the_cli_says_how_to_install_it():
    code = ("import sys; sys.modules['distributed'] = None; "
            "from harness.cli import main; sys.exit(main(['run', '--executor', 'dask']))")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=bench_env())
    assert out.returncode == 2
    assert 'pip install -e ".[dask]"' in out.stderr, out.stderr


@needs_dask
def test_a_timed_task_waits_for_renders_and_new_renders_wait_for_it(tmp_path):
    """The host slot: shared for renders, exclusive for timing, and no starving of the timed task."""
    from harness.executors.dask import host_slot

    events, release = [], threading.Event()

    def render(name, hold=None):
        with host_slot(False, tmp_path):
            events.append(f"{name} in")
            if hold is not None:
                hold.wait(10)
            events.append(f"{name} out")

    def timed():
        with host_slot(True, tmp_path):
            events.append("timed in")
            time.sleep(0.3)
            events.append("timed out")

    first = threading.Thread(target=render, args=("first", release))
    first.start()
    while "first in" not in events:
        time.sleep(0.01)
    waiting = threading.Thread(target=timed)
    waiting.start()
    time.sleep(0.3)
    late = threading.Thread(target=render, args=("late",))
    late.start()
    time.sleep(0.3)
    assert events == ["first in"]  # the timed task waits for the render; the late render waits behind it
    release.set()
    for t in (first, waiting, late):
        t.join(10)
    assert events == ["first in", "first out", "timed in", "timed out", "late in", "late out"]


def test_the_leaderboard_names_the_machines_when_rows_were_timed_on_several():
    from harness.results import leaderboard, timing_setups
    from harness.rows import Row, make_table

    def row(f, scene, machine, threads, rmse):
        return Row(job_id=f + scene, task="denoise", scene=scene, filter=f, backend="cpu", status="ok", frame=0,
                   ms_median=1.0, machine=machine, threads=threads, metrics={"rmse": rmse})

    one = make_table([row("a", "x", "CPU A", 2, 1.0), row("b", "x", "CPU A", 2, 2.0)])
    assert timing_setups(one) == ["CPU A (2 threads)"] and "timed_on" not in leaderboard(one, {})
    mixed = make_table([row("a", "x", "CPU A", 2, 1.0), row("b", "x", "CPU A", 2, 2.0), row("a", "y", "CPU B", 8, 1.0)])
    board = leaderboard(mixed, {}).set_index("entry")
    assert timing_setups(mixed) == ["CPU A (2 threads)", "CPU B (8 threads)"]
    assert board.loc["a/cpu", "timed_on"] == "CPU A (2 threads); CPU B (8 threads)"
    assert board.loc["b/cpu", "timed_on"] == "CPU A (2 threads)"
