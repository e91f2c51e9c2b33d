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


def test_path_tracer_benchmark_compares_against_mitsubas_fastest_cpu_variant(monkeypatch, capsys):
    """``bench_pathtracer.py``'s default Mitsuba variant: ``llvm_ad_rgb`` where the variant probe
    accepts it, else ``scalar_rgb`` with the reason printed; a named variant is used as named.
    Mutation check: a default of ``scalar_rgb`` (as before issue 34) fails the first assertion."""
    from types import SimpleNamespace

    from plugins.renderers.mitsuba import variants

    monkeypatch.setattr(sys, "path", [str(FOLDER), *sys.path])
    bench = runpy.run_path(str(FOLDER / "bench_pathtracer.py"), run_name="bench_pathtracer")
    default = bench["arguments"]([])
    assert default.mitsuba_variant == "fastest"

    monkeypatch.setattr(variants, "choose", lambda requested: {"llvm": "llvm_ad_rgb"}[requested])
    assert bench["mitsuba_variant"](default) == "llvm_ad_rgb"
    assert "llvm_ad_rgb (the fastest CPU variant)" in capsys.readouterr().out

    def broken(requested):
        raise variants.VariantError("renderer 'mitsuba': llvm_ad_rgb does not work here: install libllvm19")

    monkeypatch.setattr(variants, "choose", broken)
    default = SimpleNamespace(mitsuba_variant="fastest")
    assert bench["mitsuba_variant"](default) == "scalar_rgb"
    assert "scalar_rgb (llvm_ad_rgb does not work here: install libllvm19)" in capsys.readouterr().out
    assert bench["mitsuba_variant"](SimpleNamespace(mitsuba_variant="scalar_rgb")) == "scalar_rgb"
