"""The scripts in ``benchmarks/``: each answers ``--help`` (its imports and its parser work) and
takes its options through the shared helper ``benchmarks/common.py``.

``--help`` runs in this process (``runpy``, as ``python benchmarks/NAME.py --help`` would: the
script's folder first on the path), so that the plugins are imported once for all scripts.
"""

import contextlib
import io
import runpy
import sys
from pathlib import Path

import pytest

FOLDER = Path(__file__).resolve().parents[1] / "benchmarks"
SCRIPTS = sorted(p.name for p in FOLDER.glob("*.py") if p.name != "common.py")


def test_there_are_scripts():
    assert SCRIPTS and (FOLDER / "common.py").is_file()


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_answers_help(script, monkeypatch):
    monkeypatch.setattr(sys, "argv", [str(FOLDER / script), "--help"])
    monkeypatch.setattr(sys, "path", [str(FOLDER), *sys.path])
    stdout, stderr = io.StringIO(), io.StringIO()
    with contextlib.redirect_stdout(stdout), contextlib.redirect_stderr(stderr), pytest.raises(SystemExit) as done:
        runpy.run_path(str(FOLDER / script), run_name="__main__")
    assert done.value.code == 0, stderr.getvalue()
    assert stdout.getvalue().startswith("usage: ") and stderr.getvalue() == ""


@pytest.mark.parametrize("script", SCRIPTS)
def test_script_uses_the_shared_clocks_and_parser(script):
    source = (FOLDER / script).read_text()
    assert "from common import" in source
    for own in ("perf_counter", "argparse.ArgumentParser", "clear_refs", "getrusage"):
        assert own not in source, f"{script} measures with {own} of its own"


def test_a_bad_option_value_is_an_error_line_and_exit_2(monkeypatch):
    monkeypatch.setattr(sys, "argv", [str(FOLDER / "bench_raster.py"), "--resolution", "big"])
    monkeypatch.setattr(sys, "path", [str(FOLDER), *sys.path])
    stderr = io.StringIO()
    with contextlib.redirect_stderr(stderr), pytest.raises(SystemExit) as done:
        runpy.run_path(str(FOLDER / "bench_raster.py"), run_name="__main__")
    lines = [line for line in stderr.getvalue().splitlines() if line.strip()]
    assert done.value.code == 2 and lines[-1].startswith("bench_raster.py: error: argument --resolution"), lines
