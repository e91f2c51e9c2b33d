"""Hardening (issue 29), through the library: no data loss, the installed code runs in the worker,
huge work refused up front, scene files confined, inputs read-only. Each test fails before the fix
(docs/hardening.md lists them by defect)."""

from __future__ import annotations

import json
import os
import shutil
import sys
import time
import types
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from harness import FilterSpec, hookimpl, load_plugins
from harness.cache import Cache
from harness.executors import LocalExecutor, make_executor
from harness.executors.base import PluginOptions, WorkUnit
from harness.plan import check_choices, make_plan
from harness.renders import RenderStore
from harness.report import write_report
from harness.run import run_plan

ROOT = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def registry():
    return load_plugins()


@pytest.fixture(scope="module")
def stored_run(registry, tmp_path_factory):
    """A small stored run (inline, synthetic-edges, passthrough); tests copy it before changing it."""
    root = tmp_path_factory.mktemp("run")
    store = RenderStore(registry, Cache(root / "c"))
    plan = make_plan(registry, store, [registry.scenes["synthetic-edges"]], ["passthrough"], ["rmse"], seeds=[0],
                     repeats=1)
    with make_executor("inline", registry=registry) as executor:
        run_plan(registry, plan, store, executor, root / "o", progress=False)
    return root / "o"


def copy_run(stored_run, tmp_path) -> Path:
    run = tmp_path / "run"
    shutil.copytree(stored_run, run)
    return run


# ------------------------------------------------------------------ 1. report and run folders
def test_report_never_empties_a_folder_it_does_not_own(registry, stored_run, tmp_path):
    run = copy_run(stored_run, tmp_path)
    mine = tmp_path / "v"
    mine.mkdir()
    (mine / "important.txt").write_text("x")
    with pytest.raises(ValueError, match="is no report folder"):
        write_report(run, registry, out=mine)
    assert (mine / "important.txt").read_text() == "x"
    for where in (run, tmp_path, run / "jobs"):  # the run itself, a folder holding it, one of its parts
        with pytest.raises(ValueError):
            write_report(run, registry, out=where)
    assert (run / "results.parquet").is_file() and any((run / "jobs").iterdir())


@pytest.mark.slow
def test_report_replaces_only_the_files_it_wrote(registry, stored_run, tmp_path):
    run = copy_run(stored_run, tmp_path)
    out = tmp_path / "r"
    write_report(run, registry, out=out)
    (out / "notes.txt").write_text("mine")
    marker = out / ".denoise-bench-report.json"
    listed = json.loads(marker.read_text())
    assert "index.html" in listed["files"] and "notes.txt" not in listed["files"]
    (out / "img" / "stale.png").write_bytes(b"old picture")  # as if an earlier report had written it
    marker.write_text(json.dumps({"files": [*listed["files"], "img/stale.png", "../outside.txt"]}))
    (tmp_path / "outside.txt").write_text("keep")
    write_report(run, registry, out=out)
    assert (out / "notes.txt").read_text() == "mine" and (out / "index.html").is_file()
    assert not (out / "img" / "stale.png").exists() and (tmp_path / "outside.txt").read_text() == "keep"
    write_report(run, registry)  # the default folder, run/report, is the run's own
    assert (run / "report" / "index.html").is_file()


def test_run_never_starts_in_a_folder_of_other_files(registry, stored_run, tmp_path):
    mine = tmp_path / "mine"
    (mine / "jobs").mkdir(parents=True)
    (mine / "jobs" / "precious.parquet").write_bytes(b"user data")
    (mine / "results.parquet").write_bytes(b"user table")
    store = RenderStore(registry, Cache(tmp_path / "c"))
    plan = make_plan(registry, store, [registry.scenes["synthetic-edges"]], ["passthrough"], ["rmse"], seeds=[0])
    with make_executor("inline", registry=registry) as executor, pytest.raises(ValueError, match="no denoise-bench"):
        run_plan(registry, plan, store, executor, mine, progress=False)
    assert (mine / "jobs" / "precious.parquet").read_bytes() == b"user data"
    assert (mine / "results.parquet").read_bytes() == b"user table"


# ------------------------------------------------------------------ 2 and 7. the worker
class WhereAmI(WorkUnit):
    """Returns the harness folder the worker imported; optionally starts a child process that sleeps."""

    label = "where am I"

    def __init__(self, child: bool = False):
        self.child = child

    def run(self, context, shared):
        import subprocess

        import harness

        pid = subprocess.Popen(["sleep", "300"]).pid if self.child else 0
        return str(Path(harness.__file__).resolve().parent), pid


@pytest.mark.slow
def test_the_worker_runs_the_installed_harness_not_the_current_directory(tmp_path, monkeypatch):
    shadow = tmp_path / "harness"
    shadow.mkdir()
    (shadow / "__init__.py").write_text("raise RuntimeError('the harness of the current directory')\n")
    monkeypatch.chdir(tmp_path)
    with LocalExecutor() as executor:
        (_, outcome), = list(executor.run([WhereAmI()]))
        assert outcome.ok, outcome.error
        assert outcome.value[0] == str((ROOT / "harness").resolve())
        assert executor.describe()["worker_code"]["same_harness"]


@pytest.mark.slow
def test_a_worker_with_other_plugin_source_is_refused(registry):
    mismatched = load_plugins()
    record = next(r for r in mismatched.records if r.kind == "filter" and r.name == "passthrough")
    record.source_hash = "0" * 64  # as if the parent had loaded other source than the worker
    with LocalExecutor(registry=mismatched) as executor:
        (_, outcome), = list(executor.run([WhereAmI()]))
    assert not outcome.ok and "other source of plugin(s) ['filter:passthrough']" in outcome.error


def _gone(pid: int) -> bool:
    try:
        state = Path(f"/proc/{pid}/stat").read_text().rsplit(")", 1)[1].split()[0]
    except OSError:
        return True
    return state in ("Z", "X")


@pytest.mark.slow
def test_a_filters_child_processes_end_with_the_worker():
    with LocalExecutor() as executor:
        (_, outcome), = list(executor.run([WhereAmI(child=True)]))
    assert outcome.ok, outcome.error
    child = outcome.value[1]
    deadline = time.monotonic() + 10
    while not _gone(child) and time.monotonic() < deadline:
        time.sleep(0.1)
    alive = not _gone(child)
    if alive:
        os.kill(child, 9)
    assert not alive, "the worker's child process outlived it"


# ------------------------------------------------------------------ 3. work and memory up front
def test_memory_beyond_this_machine_is_refused_before_any_work(registry, tmp_path):
    from harness.estimate import check_memory, memory_limit, plan_work

    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(32768, 32768))
    plan = make_plan(registry, store, [registry.scenes["synthetic-edges"]], ["passthrough"], ["rmse"], seeds=[0])
    work = plan_work(plan, store)
    limit, _ = memory_limit()
    assert work.peak_bytes > 32768 * 32768 * 36 * 3 > 0  # colour + reference and variance, three copies
    if work.peak_bytes > limit:
        with pytest.raises(ValueError, match=r"needs at least .* GiB of memory .* 32768x32768.*more than"):
            check_memory(work)
    assert not (tmp_path / "c").exists()  # nothing rendered


def test_work_counts_pixels_frames_spp_and_seeds_not_in_the_cache(registry, tmp_path):
    from harness.estimate import plan_work

    store = RenderStore(registry, Cache(tmp_path / "c"), resolution=(40, 30))
    spec = registry.scenes["synthetic-moving"]
    plan = make_plan(registry, store, [spec], ["passthrough"], ["rmse"], seeds=[0, 1], spp=[1, 4], frames=3)
    work = plan_work(plan, store)
    assert work.input_samples == 40 * 30 * 3 * (1 + 4) * 2 and work.reference_samples == 0  # analytic references
    group = plan.groups[0]
    store.frame(group.scene, group.renderer, 0, spp=group.spp, seed=group.seed, channels=group.channels)
    assert plan_work(plan, store).input_samples == work.input_samples - 40 * 30 * group.spp


def test_a_long_run_is_announced_with_its_time(registry, tmp_path, monkeypatch):
    from harness import estimate

    store = RenderStore(registry, Cache(tmp_path / "c"))
    plan = make_plan(registry, store, [registry.scenes["synthetic-edges"]], ["passthrough"], ["rmse"], seeds=[0],
                     spp=[1_000_000_000])
    work = estimate.plan_work(plan, store)
    seconds, line = estimate.estimated_seconds(work, store)
    assert seconds > 3600 and "about" in line and "synthetic" in line
    monkeypatch.setenv(estimate.MEMORY_ENV, "1M")
    assert estimate.memory_limit() == (2**20, f"${estimate.MEMORY_ENV}")
    with pytest.raises(ValueError, match=r"more than \$DENOISE_HARNESS_MEMORY_LIMIT \(1 MiB\)"):
        estimate.check_memory(work)


# ------------------------------------------------------------------ 4. cache locations
def test_a_cache_entry_replaced_by_a_directory_is_removed_and_rendered_again(tmp_path):
    cache = Cache(tmp_path / "c")
    path = cache.path("frames", "ab" * 32)
    (path / "inside").mkdir(parents=True)
    with pytest.warns(UserWarning, match="removed, rendering it again"):
        assert cache.load("frames", "ab" * 32) is None
    assert not path.exists()
    cache.store("frames", "ab" * 32, {"x": np.zeros(3)})
    assert cache.load("frames", "ab" * 32)["x"].shape == (3,)


def test_a_cache_folder_that_is_a_file_or_unwritable_is_refused_without_a_trace(tmp_path):
    afile = tmp_path / "file"
    afile.write_text("x")
    for bad in (afile, afile / "sub"):
        with pytest.raises(ValueError, match="is a file, not a folder"):
            Cache(bad).check()
    with pytest.raises(ValueError, match="not writable"):
        Cache("/proc/denoise-harness-cache").check()
    fresh = tmp_path / "a" / "b"
    Cache(fresh).check()
    assert not (tmp_path / "a").exists()  # checked, nothing left behind


# ------------------------------------------------------------------ 5. compile warm-up outside stress timeouts
SLOW_START = """
import time
import numpy as np
from harness import FilterSpec, hookimpl

FIRST = [True]

class SlowStart:
    '''Its first call in a process takes 4 s (a cold compile), the others none.'''
    def __init__(self, backend="cpu"):
        pass
    def reset(self):
        pass
    def __call__(self, frame, sampler=None):
        if FIRST[0]:
            FIRST[0] = False
            time.sleep(4)
        return np.array(frame["color"], copy=True)

@hookimpl
def register_filters():
    return [FilterSpec(name="slowstart", version="0", factory=SlowStart)]
"""


@pytest.mark.slow
def test_stress_cases_do_not_count_the_warm_up_against_their_timeout(tmp_path, monkeypatch):
    from harness.stress import make_targets, run_stress, select_cases

    (tmp_path / "slow_start_plugin.py").write_text(SLOW_START)
    monkeypatch.syspath_prepend(str(tmp_path))
    module = __import__("slow_start_plugin")
    reg = load_plugins(extra=[module])
    targets = make_targets(reg, ["slowstart"], ["cpu"])
    executor = LocalExecutor(registry=reg, plugins=PluginOptions(modules=["slow_start_plugin"]), timeout=2)
    with executor:
        outcome = run_stress(reg, executor, tmp_path / "s", targets, cases=select_cases(["shape-1x1"]))
    row = outcome.table.iloc[0]
    assert row.status == "pass", row.message


# ------------------------------------------------------------------ 6. seeds
def test_seeds_are_limited_to_int64(registry, tmp_path):
    for bad in (2**63, 2**64 + 5):
        with pytest.raises(ValueError, match=r"seeds must be integers in \[0, 2\*\*63 - 1\]"):
            check_choices(seeds=[bad])
    store = RenderStore(registry, Cache(tmp_path / "c"))
    plan = make_plan(registry, store, [registry.scenes["synthetic-edges"]], ["passthrough"], ["rmse"],
                     seeds=[2**63 - 1], repeats=1)
    with make_executor("inline", registry=registry) as executor:
        table = run_plan(registry, plan, store, executor, tmp_path / "o", progress=False).table
    stored = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert set(table.seed) == set(stored.seed) == {2**63 - 1} and (stored.status == "ok").all()


# ------------------------------------------------------------------ 8. Mitsuba file references
SCENE = """<?xml version="1.0"?>
<scene version="0.6.0">
  <sensor type="perspective"><float name="fov" value="60"/>
    <film type="hdrfilm"><integer name="width" value="16"/><integer name="height" value="12"/></film></sensor>
  {shape}
</scene>
"""
OBJ = "v 0 0 -3\nv 1 0 -3\nv 0 1 -3\nf 1 2 3\n"


def mitsuba_folder(tmp_path, shape: str) -> Path:
    folder = tmp_path / "scene"
    folder.mkdir(exist_ok=True)
    (folder / "scene.xml").write_text(SCENE.format(shape=shape))
    return folder


def obj_shape(name: str) -> str:
    return f'<shape type="obj" id="mesh"><string name="filename" value="{name}"/></shape>'


def test_mitsuba_files_outside_the_scene_folder_are_refused(registry, tmp_path, monkeypatch):
    from plugins.scenes.mitsuba.files import ALLOW_ENV

    (tmp_path / "elsewhere.obj").write_text(OBJ)
    for name in ("../../../../../../../../etc/passwd", "/etc/passwd", "../elsewhere.obj"):
        folder = mitsuba_folder(tmp_path, obj_shape(name))
        with pytest.raises(ValueError, match=f"names '{name}', which is outside the scene folder .*{ALLOW_ENV}=1"):
            registry.open_scene(folder)
    folder = mitsuba_folder(tmp_path, '<emitter type="envmap"><string name="filename" value="../sky.exr"/></emitter>')
    with pytest.raises(ValueError, match="outside the scene folder"):
        registry.open_scene(folder)
    monkeypatch.setenv(ALLOW_ENV, "1")
    assert len(registry.open_scene(mitsuba_folder(tmp_path, obj_shape("../elsewhere.obj"))).objects) == 1
    with pytest.raises(ValueError, match="obj mesh passwd holds no triangle"):  # allowed, and still not a mesh
        registry.open_scene(mitsuba_folder(tmp_path, obj_shape("/etc/passwd")))


def test_empty_or_unparseable_meshes_are_errors(registry, tmp_path):
    folder = mitsuba_folder(tmp_path, obj_shape("mesh.obj"))
    (folder / "mesh.obj").write_text("# nothing but a comment\n")
    with pytest.raises(ValueError, match="shape 'mesh': obj mesh mesh.obj holds no triangle"):
        registry.open_scene(folder)
    (folder / "mesh.obj").write_text("v 0 0 x\nf 1 1 1\n")
    with pytest.raises(ValueError, match="cannot read obj mesh mesh.obj"):
        registry.open_scene(folder)
    (folder / "mesh.obj").write_text(OBJ)
    assert len(registry.open_scene(folder).objects) == 1


# ------------------------------------------------------------------ 9. filters that write into their inputs
def _scribbler():
    class Scribbler:
        def __init__(self, backend="cpu"):
            pass

        def reset(self):
            pass

        def __call__(self, frame, sampler=None):
            color = frame["color"]
            color.setflags(write=True)  # allowed on an array that owns its memory
            color[...] = 0.0
            return np.array(color, copy=True)

    plugin = types.ModuleType("scribbler_plugin")
    plugin.register_filters = hookimpl(lambda: [FilterSpec(name="scribbler", version="0", factory=Scribbler)])
    return plugin


def test_a_filter_writing_into_its_input_is_an_error_row_and_harms_no_other_job(tmp_path):
    reg = load_plugins(extra=[_scribbler()])

    def run(filters, name):
        store = RenderStore(reg, Cache(tmp_path / "c"))
        plan = make_plan(reg, store, [reg.scenes["synthetic-edges"]], filters, ["rmse"], seeds=[0], repeats=1)
        with make_executor("inline", registry=reg) as executor:
            return run_plan(reg, plan, store, executor, tmp_path / name, progress=False).table

    alone = run(["passthrough"], "alone")
    both = run(["scribbler", "passthrough"], "both").set_index("filter")
    assert both.loc["scribbler", "status"] == "error"
    assert "wrote into its input channel(s) ['color']: inputs are read-only" in both.loc["scribbler", "message"]
    assert both.loc["passthrough", "status"] == "ok"
    assert both.loc["passthrough", "rmse"] == alone.set_index("filter").loc["passthrough", "rmse"]


# ------------------------------------------------------------------ 10. options checked before any work
def test_an_unreachable_scheduler_is_one_line_within_the_probe_time():
    import socket

    from harness.cli.checks import check_scheduler

    with socket.socket() as server:
        server.bind(("127.0.0.1", 0))
        server.listen()
        port = server.getsockname()[1]
        check_scheduler(f"tcp://127.0.0.1:{port}")  # something listens: fine
    started = time.monotonic()
    with pytest.raises(ValueError, match=f"--scheduler tcp://127.0.0.1:{port}: cannot reach the dask scheduler"):
        check_scheduler(f"tcp://127.0.0.1:{port}", timeout=2)
    with pytest.raises(ValueError, match="unknown host 'nope.invalid'"):
        check_scheduler("nope.invalid:1", timeout=2)
    assert time.monotonic() - started < 10


def test_plugin_names_are_known_without_importing_plugins(tmp_path, monkeypatch):
    """The name index answers from what the last full load registered; a stale index is not used."""
    from harness.cli import names

    monkeypatch.setenv(names.INDEX_ENV, str(tmp_path / "index.json"))
    digest = names.fingerprint()
    assert digest is not None and names.known_names(digest) is None
    names.write_index(load_plugins(), digest)
    known = names.known_names(digest)
    assert {"passthrough", "eaw"} <= known["filter"] and "rmse" in known["metric"]
    args = types.SimpleNamespace(filters=["eaw", "nosuch"], disable=[])
    assert names.refusal(args, known).startswith("no filter named 'nosuch'; registered: [")
    assert names.refusal(types.SimpleNamespace(filters=["eaw"], disable=["nope"]), known).startswith(
        "--disable: unknown plugin name(s) ['nope']")
    assert names.refusal(types.SimpleNamespace(rank_by="temporal_error_per_frame"), known) is None
    assert names.known_names("another fingerprint") is None


# ------------------------------------------------------------------ fixture modules must not leak
@pytest.fixture(autouse=True)
def _forget_plugin_modules():
    yield
    for name in ("slow_start_plugin",):
        sys.modules.pop(name, None)


def test_docs_table_names_every_test_of_this_file():
    """docs/hardening.md lists each defect with its test; every test named there exists."""
    table = (ROOT / "docs" / "hardening.md").read_text()
    here = {n for n in globals() if n.startswith("test_")}
    from tests import test_captured_hardening, test_hardening_cli

    there = {n for m in (test_hardening_cli, test_captured_hardening) for n in vars(m) if n.startswith("test_")}
    named = set(__import__("re").findall(r"`(test_[a-z0-9_]+)`", table))
    assert named and named <= here | there, sorted(named - here - there)
    assert here - {"test_docs_table_names_every_test_of_this_file"} <= named

