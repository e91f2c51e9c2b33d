"""Bad input is a one-line message and exit status 2, checked before any work."""

import os
import subprocess
import sys

import pytest

from harness.lock import FolderLock
from tests.conftest import bench_env

QUICK = ["--scenes", "synthetic-edges", "--filters", "passthrough", "--quiet"]


def cli(args, cwd=None):
    return subprocess.run([sys.executable, "-m", "harness.cli", *map(str, args)], capture_output=True, text=True,
                          env=bench_env(), cwd=cwd)


BAD = {
    "repeats 0": (["run", *QUICK, "--repeats", "0"], "--repeats: must be >= 1, got 0"),
    "spp 0": (["run", *QUICK, "--spp", "0"], "--spp: must be integers >= 1"),
    "negative seed": (["run", *QUICK, "--seeds", "-1"], "--seeds: must be integers >= 0"),
    "frames 0": (["run", *QUICK, "--frames", "0"], "--frames: must be >= 1"),
    "reference spp 0": (["run", *QUICK, "--reference-spp", "0"], "--reference-spp: must be >= 1"),
    "negative param": (["run", "--scenes", "synthetic-edges", "--filters", "eaw", "--param", "eaw.iterations=-3"],
                       "filter 'eaw': parameter 'iterations' must be int in [1, 10], got -3"),
    "param type": (["run", "--scenes", "synthetic-edges", "--filters", "eaw", "--param", "eaw.sigma_n=abc"],
                   "parameter 'sigma_n' must be float in (0, inf], got 'abc'"),
    "param choice": (["run", "--scenes", "synthetic-edges", "--filters", "eaw", "--param",
                      "eaw.color_scale=log"], "parameter 'color_scale' must be one of ('logmean', 'none')"),
    "param syntax": (["run", *QUICK, "--param", "iterations=3"], "--param: must look like FILTER.NAME=VALUE"),
    "unknown param": (["run", "--scenes", "synthetic-edges", "--filters", "gaussian", "--param", "gaussian.sigmaa=2"],
                      "has no parameter(s) ['sigmaa']"),
    "unknown preset": (["run", "--scenes", "synthetic-edges", "--filters", "eaw", "--preset", "eaw=slow"],
                       "filter 'eaw' has no preset 'slow'"),
    "unknown renderer": (["run", *QUICK, "--renderer", "nosuch"], "no renderer named 'nosuch'"),
    "unknown filter": (["run", "--scenes", "synthetic-edges", "--filters", "nosuch"], "no filter named 'nosuch'"),
    "unknown scene": (["run", "--scenes", "nosuch", "--filters", "passthrough"], "no scene named 'nosuch'"),
    "bad backend": (["run", *QUICK, "--backend", "bogus"], "--backend: must be among cpu, cuda, auto, all"),
    "empty filters": (["run", "--scenes", "synthetic-edges", "--filters", ""], "--filters: needs at least one name"),
    "bad timeout": (["run", *QUICK, "--timeout", "0"], "--timeout: must be a finite number of seconds > 0"),
    "bad executor": (["run", *QUICK, "--executor", "cloud"],
                     "--executor: must be one of dask, inline, local, got 'cloud'"),
    "bad resolution": (["run", *QUICK, "--resolution", "0x10"], "resolution sides must be in [1, 32768]"),
    "bench resolution": (["bench", "gaussian", "--resolution", "abc"], "resolution must look like 1280x720"),
    "bench repeats": (["bench", "gaussian", "--repeats", "0"], "--repeats: must be >= 1"),
    "render chunk 0": (["render", "--scenes", "synthetic-edges", "--chunk", "0"], "--chunk: must be >= 1, got 0"),
    "render chunk -5": (["render", "--scenes", "synthetic-edges", "--chunk", "-5"], "--chunk: must be >= 1, got -5"),
    "scene dir missing": (["run", "--scene-dir", "no/such/folder", "--filters", "passthrough"],
                          "scene path no/such/folder does not exist"),
    "train untrainable": (["train", "gaussian"], "filter 'gaussian' is not trainable"),
    "show nothing": (["show", "no/such/run"], "no results in no/such/run"),
}


def _with_folders(args, tmp_path):
    return [*args, "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"] if args[0] == "run" else args


def _one_line(case, returncode, stderr, expected):
    assert returncode == 2, f"{case}: exit {returncode}\n{stderr}"
    lines = [line for line in stderr.splitlines() if line.strip()]
    assert len(lines) == 1, f"{case}: expected one line, got:\n{stderr}"
    assert expected in lines[0], f"{case}: {lines[0]!r} lacks {expected!r}"
    assert "Traceback" not in stderr


@pytest.mark.slow
@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2(case, tmp_path):
    """The console script in its own process (the full tier; the fast tier calls ``main`` in-process)."""
    args, expected = BAD[case]
    out = cli(_with_folders(args, tmp_path))
    _one_line(case, out.returncode, out.stderr, expected)


@pytest.mark.parametrize("case", sorted(BAD))
def test_bad_input_is_one_line_and_exit_2_in_process(case, tmp_path, capsys):
    from harness.cli import main

    args, expected = BAD[case]
    try:
        code = main([str(a) for a in _with_folders(args, tmp_path)])
    except SystemExit as exc:  # argparse's refusals
        code = exc.code
    _one_line(case, code, capsys.readouterr().err, expected)


@pytest.mark.slow
def test_out_pointing_at_a_file_or_a_read_only_folder(tmp_path):
    afile = tmp_path / "file.txt"
    afile.write_text("x")
    out = cli(["run", *QUICK, "--out", afile])
    assert out.returncode == 2 and "is a file, not a folder" in out.stderr and len(out.stderr.splitlines()) == 1
    locked = tmp_path / "ro"
    locked.mkdir()
    locked.chmod(0o500)
    # root writes through permissions: a folder in sysfs is read-only for everyone
    target = locked / "sub" if os.geteuid() != 0 else "/sys/kernel/denoise-harness-test"
    try:
        out = cli(["run", *QUICK, "--out", target])
    finally:
        locked.chmod(0o700)
    assert out.returncode == 2 and "is not writable" in out.stderr and len(out.stderr.splitlines()) == 1


@pytest.mark.slow
def test_a_second_run_into_a_locked_folder_is_refused(tmp_path):
    with FolderLock(tmp_path / "o"):
        out = cli(["run", *QUICK, "--out", tmp_path / "o", "--cache-dir", tmp_path / "c"])
    assert out.returncode == 2
    assert "is in use by another run (pid" in out.stderr and len(out.stderr.splitlines()) == 1
    free = cli(["run", *QUICK, "--out", tmp_path / "o", "--cache-dir", tmp_path / "c", "--executor", "inline"])
    assert free.returncode == 0, free.stderr
