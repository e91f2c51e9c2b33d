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
    assert _run_child(root, tmp_path / "cache") == {"a": [1, 0], "b": [1, 0]}  # both from the cache
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
    assert line.startswith("compiling the Numba kernels of filters.eaw, filters.svgf on first use")
    eaw = registry.get("filter", "eaw").factory
    folder = empty_cache_home / os.path.basename(numba_cache._unit_folder(*compile_unit(
        sys.modules[eaw.__module__].__file__))[0])
    folder.mkdir(parents=True, exist_ok=True)
    (folder / "cpu.kernel-12.py311.nbi").write_bytes(b"")
    assert numba_cache.uncompiled_units([eaw, registry.get("filter", "svgf").factory]) == ["filters.svgf"]
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(empty_cache_home))
    assert numba_cache.compile_notice(registry, plan) is None  # the user's own cache: not tracked
