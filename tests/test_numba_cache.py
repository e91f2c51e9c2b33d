"""Numba's cache folder is keyed by the source, so an edited helper module never runs stale code."""

import os
import subprocess
import sys

from harness.numba_cache import configure_numba_cache, source_digest


def test_digest_changes_with_any_source_file(tmp_path):
    pkg = tmp_path / "plugins" / "f"
    pkg.mkdir(parents=True)
    (pkg / "cpu.py").write_text("def kernel(): return 1\n")
    (pkg / "helpers.py").write_text("X = 1\n")
    before = source_digest(tmp_path / "plugins")
    assert source_digest(tmp_path / "plugins") == before
    (pkg / "helpers.py").write_text("X = 2\n")  # only the helper changes, not the kernel's file
    assert source_digest(tmp_path / "plugins") != before


def test_harness_import_points_numba_at_the_keyed_folder(tmp_path):
    env = {**os.environ, "XDG_CACHE_HOME": str(tmp_path)}
    env.pop("NUMBA_CACHE_DIR", None)
    code = "import harness, numba; print(numba.config.CACHE_DIR)"
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip().startswith(str(tmp_path / "denoise-harness" / "numba"))
    env["NUMBA_CACHE_DIR"] = str(tmp_path / "mine")
    out = subprocess.run([sys.executable, "-c", code], capture_output=True, text=True, env=env, check=True).stdout
    assert out.strip() == str(tmp_path / "mine")


def test_a_user_setting_is_left_alone(monkeypatch, tmp_path):
    monkeypatch.setenv("NUMBA_CACHE_DIR", str(tmp_path))
    assert configure_numba_cache() is None
