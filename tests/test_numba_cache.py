"""Numba's cache is kept per compile unit, keyed by its source: an edit recompiles its own unit only."""

import json
import os
import subprocess
import sys
import textwrap

import pytest

from harness import numba_cache
from harness.numba_cache import compile_unit, configure_numba_cache, source_digest


def test_digest_changes_with_any_source_file(tmp_path):
    pkg = tmp_path / "plugins" / "f"
    pkg.mkdir(parents=True)
    (pkg / "cpu.py").write_text("def kernel(): return 1\n")
    (pkg / "helpers.py").write_text("X = 1\n")
    before = source_digest(tmp_path / "plugins")
    assert source_digest(tmp_path / "plugins") == before
    (pkg / "helpers.py").write_text("X = 2\n")  # only the helper changes, not the kernel's file
    assert source_digest(tmp_path / "plugins") != before


def test_compile_units():
    name, paths = compile_unit(numba_cache.PLUGINS / "filters" / "eaw" / "cpu.py")
    assert name == "filters.eaw"
    assert paths[0] == numba_cache.PLUGINS / "filters" / "eaw"
    assert numba_cache.HARNESS / "kernels.py" in paths or numba_cache.HARNESS / "kernels" in paths
    assert compile_unit(numba_cache.PLUGINS / "metrics" / "errors.py")[0] == "metrics.errors"
    assert compile_unit(numba_cache.HARNESS / "floor.py") == ("harness", (numba_cache.HARNESS,))
    assert compile_unit(numba_cache.HARNESS.parent / "tests" / "x.py") is None


# a child process: two plugin units under a temporary plugins folder, each with a cached kernel
CHILD = textwrap.dedent("""
    import json, sys
    from pathlib import Path
    from harness import numba_cache
    numba_cache.PLUGINS = Path(sys.argv[1])
    numba_cache.configure_numba_cache()
    sys.path.insert(0, str(Path(sys.argv[1]).parent))
    from tplugins.filters.a.k import kernel as ka
    from tplugins.filters.b.k import kernel as kb
    ka(1.0), kb(1.0)
    print(json.dumps({n: [k.stats.cache_hits.total(), k.stats.cache_misses.total()] for n, k in
                      (("a", ka), ("b", kb))}))
""")


def _run_child(root, cache_home):
    env = {**os.environ, "XDG_CACHE_HOME": str(cache_home)}
    env.pop("NUMBA_CACHE_DIR", None)
    out = subprocess.run([sys.executable, "-c", CHILD, str(root / "tplugins")], capture_output=True, text=True,
                         env=env, check=True).stdout
    return json.loads(out.strip().splitlines()[-1])


@pytest.mark.slow
def test_an_edit_recompiles_its_own_plugin_only(tmp_path):
    root = tmp_path / "src"
    for name in ("a", "b"):
        pkg = root / "tplugins" / "filters" / name
        pkg.mkdir(parents=True)
        (pkg / "__init__.py").write_text("")
        (pkg / "k.py").write_text("import numba\n\n@numba.njit(cache=True)\ndef kernel(x):\n    return x + 1.0\n")
    for folder in (root / "tplugins", root / "tplugins" / "filters"):
        (folder / "__init__.py").write_text("")
    first = _run_child(root, tmp_path / "cache")
    assert first == {"a": [0, 1], "b": [0, 1]}  # both compiled
    records = sorted((tmp_path / "cache" / "denoise-harness" / "numba").glob(f"*/{numba_cache.RECORD}"))
    assert [p.parent.name.split("-")[0] for p in records] == ["filters.a", "filters.b"]
    assert all(json.loads(p.read_text())["cpu_s"] > 0 for p in records)  # each compile's time recorded
    stamps = [p.stat().st_mtime_ns for p in records]
    assert _run_child(root, tmp_path / "cache") == {"a": [1, 0], "b": [1, 0]}  # both from the cache
    assert [p.stat().st_mtime_ns for p in records] == stamps  # a cache hit records no compile
    helper = root / "tplugins" / "filters" / "a" / "helpers.py"
    helper.write_text("# a one-line edit of another module of plugin a\n")
    assert _run_child(root, tmp_path / "cache") == {"a": [0, 1], "b": [1, 0]}  # a recompiled, b not
    folders = sorted(p.name.split("-")[0] for p in (tmp_path / "cache" / "denoise-harness" / "numba").iterdir())
    assert folders == ["filters.a", "filters.a", "filters.b"]


def test_a_user_setting_is_left_alone(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert configure_numba_cache() is None


@pytest.fixture
def empty_cache_home(monkeypatch, tmp_path):
    """A cache home with no compiled kernel (the unit folders' paths are recomputed for it)."""
    monkeypatch.delenv("NUMBA_CACHE_DIR", raising=False)
    monkeypatch.setenv("XDG_CACHE_HOME", str(tmp_path))
    numba_cache._unit_folder.cache_clear()
    yield tmp_path / "denoise-harness" / "numba"
    numba_cache._unit_folder.cache_clear()


def test_a_run_names_the_units_it_will_compile(empty_cache_home, monkeypatch):
    """A fresh install (or an edit) is announced by the units whose kernels are not cached yet:
    only units with cached kernels (passthrough has none), and none once their folder holds one."""
    from types import SimpleNamespace

    from harness import load_plugins

    registry = load_plugins()
    plan = SimpleNamespace(jobs=[SimpleNamespace(filter=f, renderer="synthetic") for f in ("eaw", "passthrough")]
                           + [SimpleNamespace(filter="svgf", renderer="")])
    line = numba_cache.compile_notice(registry, plan)
    assert line.startswith("compiling kernels of filters.eaw, filters.svgf (first use")
    eaw = registry.get("filter", "eaw").factory
    folder = empty_cache_home / os.path.basename(numba_cache._unit_folder(*compile_unit(
        sys.modules[eaw.__module__].__file__))[0])
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cpu.kernel-12.py311.nbi").write_bytes(b"")
    assert numba_cache.uncompiled_units([eaw, registry.get("filter", "svgf").factory]) == ["filters.svgf"]
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(empty_cache_home))
    assert numba_cache.compile_notice(registry, plan) is None  # the user's own cache: not tracked


def _record(home, unit, digest, seconds):
    folder = home / f"{unit}-{digest}"
    folder.mkdir(parents=True, exist_ok=True)
    (folder / numba_cache.RECORD).write_text(json.dumps({"cpu_s": seconds}))
    return folder


def _plan(*filters):
    from types import SimpleNamespace

    return SimpleNamespace(jobs=[SimpleNamespace(filter=f, renderer="synthetic") for f in filters])


def test_the_notice_estimates_from_the_recorded_compile_times(empty_cache_home, monkeypatch):
    """The estimate is the sum of each unit's last recorded compile (an older source's folder counts),
    else the shipped table, said so; a unit known to neither leaves no figure."""
    from harness import load_plugins

    registry = load_plugins()
    monkeypatch.setattr(numba_cache, "MEASURED_CPU_S", {"filters.eaw": 50.0, "filters.svgf": 40.0})
    line = numba_cache.compile_notice(registry, _plan("eaw", "svgf"))
    assert line == (f"compiling kernels of filters.eaw, filters.svgf (first use, about 90 s: "
                    f"{numba_cache.MEASURED_ON}, this machine's last compile where recorded)")
    _record(empty_cache_home, "filters.eaw", "0123456789abcdef", 95.4)  # an edit ago: another digest
    _record(empty_cache_home, "filters.svgf", "fedcba9876543210", 61.0)
    line = numba_cache.compile_notice(registry, _plan("eaw", "svgf"))
    assert line == ("compiling kernels of filters.eaw, filters.svgf (first use, about 2.6 min: their last compile "
                    "on this machine)")
    assert numba_cache.recorded_seconds("filters.eaw") == 95.4
    monkeypatch.setattr(numba_cache, "MEASURED_CPU_S", {})
    line = numba_cache.compile_notice(registry, _plan("eaw", "gaussian"))
    assert line.startswith("compiling kernels of filters.eaw, filters.gaussian (first use, about 95 s plus "
                           "filters.gaussian: ")
    line = numba_cache.compile_notice(registry, _plan("gaussian"))
    assert line == "compiling kernels of filters.gaussian (first use, minutes on 2 cores, once)"


def test_progress_names_each_unit_once_when_its_record_lands(empty_cache_home):
    from harness import load_plugins

    registry = load_plugins()
    progress = numba_cache.CompileProgress(registry, ["filters.eaw"])
    assert progress("filter", "eaw") is None  # nothing compiled yet
    name, paths = compile_unit(sys.modules[registry.get("filter", "eaw").factory.__module__].__file__)
    folder = numba_cache._unit_folder(name, paths)[0]
    _record(empty_cache_home, "filters.eaw", folder.rsplit("-", 1)[1], 95.4)
    assert progress("filter", "svgf") is None  # not announced
    assert progress("filter", "eaw") == "compiled kernels of filters.eaw in 95 s (CPU)"
    assert progress("filter", "eaw") is None  # said once


@pytest.mark.slow
def test_a_run_of_one_filter_compiles_no_other_plugin(tmp_path):
    """Nothing compiles at import or registration: a run of one filter on an analytic scene fills the
    cache of that filter only, and says when it is compiled."""
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path / "home")}
    env.pop("NUMBA_CACHE_DIR", None)
    run = subprocess.run([sys.executable, "-m", "harness.cli", "run", "--filters", "gaussian", "--scenes",
                          "synthetic-moving", "--timing-at", "none", "--seeds", "0", "--frames", "2", "--no-cache",
                          "--quiet", "--out", str(tmp_path / "out")], capture_output=True, text=True, env=env)
    assert run.returncode == 0, run.stderr
    home = tmp_path / "home" / "denoise-harness" / "numba"
    compiled = {p.name.rsplit("-", 1)[0] for p in home.iterdir() if any(p.glob("*.nbi"))}
    assert compiled - {"harness"} == {"filters.gaussian"}
    assert "compiling kernels of filters.gaussian (first use" in run.stderr
    assert "compiled kernels of filters.gaussian in" in run.stderr
