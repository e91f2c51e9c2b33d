"""Shared fixtures of the project's test suite."""

from __future__ import annotations

import contextlib
import io
import os
import subprocess
import sys
import textwrap
import warnings
from pathlib import Path

import pytest

ROOT = Path(__file__).resolve().parents[1]

os.environ.setdefault("VTK_DEFAULT_OPENGL_WINDOW", "vtkEGLRenderWindow")


@pytest.fixture
def fake_distribution(tmp_path, monkeypatch):
    """Install a throw-away distribution with ``denoise_harness`` entry points on ``sys.path``.

    Returns a function ``make(dist_name, entry_points: dict, modules: dict)`` that writes the
    modules and a ``.dist-info`` folder (real entry points, as pip would make them) and returns
    the folder to put on ``PYTHONPATH`` for subprocesses.
    """
    monkeypatch.syspath_prepend(str(tmp_path))

    def make(dist_name: str, entry_points: dict, modules: dict | None = None) -> Path:
        for name, source in (modules or {}).items():
            (tmp_path / f"{name}.py").write_text(textwrap.dedent(source))
        info = tmp_path / f"{dist_name.replace('-', '_')}-0.1.dist-info"
        info.mkdir()
        (info / "METADATA").write_text(f"Metadata-Version: 2.1\nName: {dist_name}\nVersion: 0.1\n")
        lines = "\n".join(f"{k} = {v}" for k, v in entry_points.items())
        (info / "entry_points.txt").write_text(f"[denoise_harness]\n{lines}\n")
        for mod in list(sys.modules):
            if mod in (modules or {}):
                del sys.modules[mod]
        return tmp_path

    return make


def bench_env(extra_path: Path | None = None) -> dict:
    """Environment for running ``denoise-bench`` in a subprocess (optionally with extra modules)."""
    env = dict(os.environ)
    if extra_path is not None:
        env["PYTHONPATH"] = os.pathsep.join(filter(None, [str(extra_path), env.get("PYTHONPATH", "")]))
    env["DENOISE_HARNESS_DISABLE"] = ""
    return env


def cli(args, env=None, check=True):
    """Run ``denoise-bench ARGS``; returns a ``subprocess.CompletedProcess`` (``returncode``, ``stdout``, ``stderr``).

    In this process (no interpreter start, no second import of the plugins: the fast tier's way)
    unless ``env`` is given, which needs a process of its own (extra modules on its path). Where
    the command starts workers, they are processes of their own either way.
    """
    args = [str(a) for a in args]
    if env is not None:
        out = subprocess.run([sys.executable, "-m", "harness.cli", *args], capture_output=True, text=True, env=env)
    else:
        from harness.cli import main

        stdout, stderr = io.StringIO(), io.StringIO()
        shown = warnings.showwarning
        with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), warnings.catch_warnings():
            try:
                code = main(args)
            except SystemExit as exc:  # argparse's usage errors
                code = exc.code if isinstance(exc.code, int) else 1
            finally:
                warnings.showwarning = shown
        out = subprocess.CompletedProcess(["denoise-bench", *args], code, stdout.getvalue(), stderr.getvalue())
    if check and out.returncode != 0:
        raise AssertionError(f"exit {out.returncode}\n{out.stdout}\n{out.stderr}")
    return out
