"""Hardening (issue 29) as a user meets it: each repro of the issue is one line on standard error and
exit status 2 (or the documented safe behaviour), and nothing outside ``--out`` is written or removed.
Each test fails before the fix (docs/hardening.md lists them by defect)."""

from __future__ import annotations

import subprocess
import sys
import time
from pathlib import Path

import pandas as pd
import pytest

from tests.conftest import bench_env

QUICK = ["--scenes", "synthetic-edges", "--filters", "passthrough", "--seeds", "0", "--timing-at", "none", "--quiet",
         "--no-render-cost"]


def cli(args, cwd, env=None, timeout=300):
    """``denoise-bench`` (the installed console script, as a user runs it) in ``cwd``."""
    script = Path(sys.executable).parent / "denoise-bench"
    command = [str(script)] if script.exists() else [sys.executable, "-m", "harness.cli"]
    return subprocess.run([*command, *map(str, args)], capture_output=True, text=True, cwd=cwd,
                          env=env or bench_env(), timeout=timeout)


def snapshot(folder: Path) -> dict:
    """Every file under ``folder`` with its bytes (to prove nothing was written or removed)."""
    return {p.relative_to(folder): p.read_bytes() for p in folder.rglob("*") if p.is_file()}


def one_line_exit_2(out, expected: str) -> str:
    lines = [line for line in out.stderr.splitlines() if line.strip()]
    assert out.returncode == 2, f"exit {out.returncode}\n{out.stdout}\n{out.stderr}"
    assert len(lines) == 1 and "Traceback" not in out.stderr, out.stderr
    assert expected in lines[0], lines[0]
    return lines[0]


@pytest.fixture
def workdir(tmp_path):
    """A user's folder: a file of theirs, and a render cache beside it."""
    home = tmp_path / "work"
    home.mkdir()
    (home / "important.txt").write_text("keep me")
    return home


@pytest.fixture(scope="module")
def stored_run(tmp_path_factory):
    root = tmp_path_factory.mktemp("stored")
    out = cli(["run", *QUICK, "--executor", "inline", "--out", root / "run", "--cache-dir", root / "c"], cwd=root)
    assert out.returncode == 0, out.stderr
    return root / "run"


# ------------------------------------------------------------------ 1. report and show
@pytest.mark.slow
def test_report_and_show_write_only_what_they_own(stored_run, workdir):
    (workdir / "v").mkdir()
    (workdir / "v" / "important.txt").write_text("x")
    before = snapshot(workdir)
    one_line_exit_2(cli(["report", stored_run, "--out", "v"], cwd=workdir), "is no report folder")
    one_line_exit_2(cli(["report", stored_run, "--out", "."], cwd=workdir), "is the current directory")
    one_line_exit_2(cli(["report", stored_run, "--out", ""], cwd=workdir), "must name a folder")
    run_files = snapshot(stored_run)
    one_line_exit_2(cli(["show", stored_run, "--markdown", stored_run / "results.parquet"], cwd=workdir),
                    "the run's own files are never overwritten")
    assert snapshot(workdir) == before and snapshot(stored_run) == run_files


@pytest.mark.slow
def test_refused_runs_leave_nothing_behind(workdir):
    before = snapshot(workdir)
    cases = {
        "--out ''": (["--out", ""], "--out: must name a folder"),
        "bad parameter": (["--out", "o", "--param", "passthrough.nope=1"], "has no parameter(s) ['nope']"),
        "rank-by": (["--out", "o", "--rank-by", "nope"], "--rank-by 'nope'"),
        "disable": (["--out", "o", "--disable", "nope"], "--disable: unknown plugin name(s) ['nope']"),
        "seed": (["--out", "o", "--seeds", str(2**63)], "--seeds: must be integers in [0, 2**63 - 1]"),
        "cache dir is a file": (["--out", "o", "--cache-dir", "important.txt"], "is a file, not a folder"),
        "cache dir empty": (["--out", "o", "--cache-dir", ""], "--cache-dir: must name a folder"),
        "foreign --out": (["--out", "."], "holds other files and is no denoise-bench output folder"),
        "memory": (["--out", "o", "--resolution", "32768x32768"], "of memory"),
    }
    for case, (extra, expected) in cases.items():
        args = ["run", *QUICK, "--cache-dir", "cache", *extra]
        one_line_exit_2(cli(args, cwd=workdir), expected)
        assert snapshot(workdir) == before and sorted(p.name for p in workdir.iterdir()) == ["important.txt"], case


# ------------------------------------------------------------------ 2. the worker runs the installed code
@pytest.mark.slow
def test_a_harness_package_in_the_current_directory_does_not_replace_the_installed_one(workdir, tmp_path):
    shadow = workdir / "harness"
    shadow.mkdir()
    (shadow / "__init__.py").write_text("raise RuntimeError('not the installed harness')\n")
    out = cli(["run", *QUICK, "--strict", "--out", "o", "--cache-dir", tmp_path / "c"], cwd=workdir)
    assert out.returncode == 0, out.stdout + out.stderr
    df = pd.read_parquet(workdir / "o" / "results.parquet")
    assert (df.status == "ok").all(), df.message.tolist()


# ------------------------------------------------------------------ 3. huge work up front
@pytest.mark.slow
def test_a_billion_samples_per_pixel_is_estimated_before_any_work(workdir, tmp_path):
    out = cli(["run", *QUICK, "--spp", "1000000000", "--max-hours", "1", "--out", "o", "--cache-dir", tmp_path / "c"],
              cwd=workdir)
    line = one_line_exit_2(out, "estimated work: ")
    assert "samples to render" in line and "more than --max-hours 1" in line
    assert not (workdir / "o").exists() and not (tmp_path / "c").exists()


# ------------------------------------------------------------------ 10. options checked before any work
@pytest.mark.slow
def test_an_unreachable_scheduler_is_refused_in_one_line(workdir):
    pytest.importorskip("distributed")
    started = time.monotonic()
    out = cli(["run", *QUICK, "--executor", "dask", "--scheduler", "nope.invalid:1", "--out", "o"], cwd=workdir,
              timeout=120)
    one_line_exit_2(out, "--scheduler nope.invalid:1: cannot reach the dask scheduler: unknown host")
    assert time.monotonic() - started < 60 and not (workdir / "o").exists()


FLAG = """
from pathlib import Path
import os
Path(os.environ["IMPORTED_FLAG"]).write_text("imported")
from harness import FilterSpec, hookimpl

@hookimpl
def register_filters():
    return []
"""


@pytest.mark.slow
def test_a_bad_plugin_name_is_refused_before_any_plugin_is_imported(fake_distribution, tmp_path, workdir):
    path = fake_distribution("flag-dist", {"flag": "flag_plugin"}, {"flag_plugin": FLAG})
    env = bench_env(path)
    env["IMPORTED_FLAG"] = str(tmp_path / "imported")
    env["DENOISE_HARNESS_NAME_INDEX"] = str(tmp_path / "index.json")
    assert cli(["plugins"], cwd=workdir, env=env).returncode == 0  # a full load records the names
    (tmp_path / "imported").unlink()
    for args, expected in ((["run", "--filters", "nosuch"], "no filter named 'nosuch'"),
                           (["run", "--scenes", "nosuch"], "no scene named 'nosuch'"),
                           (["stress", "--filters", "passthrough,nosuch"], "no filter named 'nosuch'"),
                           (["run", "--disable", "nope"], "--disable: unknown plugin name(s) ['nope']")):
        one_line_exit_2(cli(args, cwd=workdir, env=env), expected)
        assert not (tmp_path / "imported").exists(), f"{args}: a plugin was imported before the name was refused"

