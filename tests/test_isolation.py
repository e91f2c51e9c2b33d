"""Jobs run in a worker process: hangs, exits, segfaults and memory errors become error rows."""

import json

import pandas as pd
import pytest

from harness import load_plugins
from harness.executors import LocalExecutor
from harness.executors.base import Outcome, PluginOptions, WorkUnit
from tests.conftest import bench_env
from tests.test_run import bench


class Probe(WorkUnit):
    """A task that returns its worker's pid, or makes the worker exit."""

    label = "probe"

    def __init__(self, action="pid"):
        self.action = action

    def run(self, context, shared):
        import os

        if self.action == "die":
            os._exit(1)
        return os.getpid()

FAULTY = """
import ctypes, os, sys, time
import numpy as np
from harness import FilterSpec, hookimpl

class Faulty:
    def __init__(self, backend="cpu", how="hang"):
        self.how = how
    def reset(self):
        pass
    def __call__(self, frame, sampler=None):
        if self.how == "hang":
            time.sleep(10_000)
        if self.how == "exit":
            sys.exit(3)
        if self.how == "segv":
            ctypes.string_at(0)
        if self.how == "oom":
            raise MemoryError("cannot allocate 64 GiB")
        if self.how == "osexit":
            os._exit(7)
        if self.how == "print":
            print("noise on stdout from a filter")
        return np.array(frame["color"], copy=True)

@hookimpl
def register_filters():
    return [FilterSpec(name=how, version="0", factory=lambda backend="cpu", how=how: Faulty(backend, how))
            for how in ("hang", "exit", "segv", "oom", "osexit", "print")]
"""


@pytest.fixture
def faulty(fake_distribution):
    return fake_distribution("faulty-dist", {"faulty": "faulty_filters"}, {"faulty_filters": FAULTY})


@pytest.mark.slow
def test_each_crash_is_one_error_row_and_the_run_completes(tmp_path, faulty):
    args = ["run", "--scenes", "synthetic-edges,synthetic-moving", "--frames", "2", "--quiet", "--repeats", "1",
            "--seeds", "0", "--timing-at", "none",
            "--filters", "hang,exit,segv,oom,osexit,print,passthrough", "--timeout", "4",
            "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"]
    out = bench([*args, "--strict"], env=bench_env(faulty), check=False)
    assert out.returncode == 1, out.stderr
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    errors = df[df.status == "error"]
    assert errors.groupby(["filter", "scene"]).size().eq(1).all()  # one row per failed job
    msg = {f: g.message.iloc[0] for f, g in errors.groupby("filter")}
    assert set(msg) == {"hang", "exit", "segv", "oom", "osexit"}
    assert "timed out: no progress for 4 s" in msg["hang"] and "worker killed" in msg["hang"]
    assert "SystemExit: the filter called sys.exit(3)" in msg["exit"]
    assert "SIGSEGV (segmentation fault)" in msg["segv"]
    assert "MemoryError: cannot allocate 64 GiB" in msg["oom"]
    assert "exited with code 7" in msg["osexit"]
    ok = df[df.status == "ok"]
    assert set(ok["filter"]) == {"passthrough", "print"} and len(ok) == 2 * (1 + 2)
    assert ok.rmse.notna().all()
    manifest = json.loads((tmp_path / "o" / "manifest.json").read_text())
    assert manifest["error_jobs"] == 10 and manifest["executor"]["workers_started"] >= 4
    assert "noise on stdout" not in out.stdout  # a plugin's prints go to stderr, not into the report
    lenient = bench(args, env=bench_env(faulty), check=False)
    assert lenient.returncode == 0


@pytest.mark.slow
def test_inline_executor_turns_sys_exit_into_an_error_row(tmp_path, faulty):
    out = bench(["run", "--scenes", "synthetic-edges", "--filters", "exit,passthrough", "--quiet", "--executor",
                 "inline", "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"], env=bench_env(faulty))
    df = pd.read_parquet(tmp_path / "o" / "results.parquet")
    assert df.set_index("filter").status.to_dict() == {"exit": "error", "passthrough": "ok"}, out.stdout


@pytest.mark.slow
def test_the_worker_stays_warm_and_restarts_after_a_crash(faulty):
    """One worker serves job after job; after it dies, the next task gets a new one."""
    with LocalExecutor(plugins=PluginOptions(), timeout=60) as ex:
        outcomes = [o for _, o in ex.run([Probe("pid"), Probe("pid"), Probe("die"), Probe("pid")])]
    assert [o.ok for o in outcomes] == [True, True, False, True]
    assert outcomes[0].value == outcomes[1].value != outcomes[3].value
    assert isinstance(outcomes[2], Outcome) and "exited with code 1" in outcomes[2].error
    assert ex.started == 2


def test_a_worker_that_cannot_load_the_plugins_is_an_error_outcome():
    with LocalExecutor(plugins=PluginOptions(modules=["no_such_plugin_module"]), timeout=60) as ex:
        (_, outcome), = list(ex.run([Probe()]))
    assert not outcome.ok
    assert "the worker could not start: loading plugins: ModuleNotFoundError" in outcome.error


def test_load_plugins_is_unaffected(faulty):
    assert {"hang", "segv"} <= set(load_plugins().filters)


def test_a_unit_whose_shared_input_the_worker_does_not_hold_is_an_error_outcome():
    """The executors refuse it in one place (``WorkUnit.run_held``): no work unit checks it itself."""
    from harness.executors import InlineExecutor
    from harness.executors.base import Shared

    probe = Probe()
    probe.shared = Shared("frames", None)
    with InlineExecutor(load_plugins()) as ex:
        (_, outcome), = list(ex.run([probe]))
    assert not outcome.ok and "the worker does not hold the shared input of probe" in outcome.error
    probe.shared = Shared("frames", [1, 2])
    with InlineExecutor(load_plugins()) as ex:
        (_, outcome), = list(ex.run([probe]))
    assert outcome.ok
