"""The run manifest: what is needed to reproduce and audit a stored results table.

The manifest describes the whole stored table (after ``--resume`` too): the scenes, references
(their hashes, and the samples and median relative standard error each reached) and seeds are
read from the table's rows, the plugins and packages from this process; the run's settings
include its profile with the values actually used.
"""

from __future__ import annotations

import functools
import json
import subprocess
import sys
import time
from importlib import metadata
from pathlib import Path

import pandas as pd

from harness.cache import atomic_write_bytes
from harness.machine import machine_info

PACKAGES = [
    "numpy", "numba", "llvmlite", "pyvista", "vtk", "OpenImageIO", "scikit-image", "pandas", "pyarrow", "torch",
    "pluggy", "flip-evaluator", "tqdm", "opencv-contrib-python-headless", "pyoidn",
]
DISTRIBUTION = "denoise-harness"


def _git(root: Path, *args: str) -> str | None:
    try:
        out = subprocess.run(["git", "-C", str(root), *args], capture_output=True, text=True, timeout=10, check=False)
    except (OSError, subprocess.SubprocessError):
        return None
    return out.stdout.strip() if out.returncode == 0 else None


@functools.lru_cache(maxsize=1)
def provenance() -> dict:
    """The harness's own source: ``git_commit`` and ``dirty`` of its checkout, and its version.

    Taken from the folder the ``harness`` package was imported from (not the current
    directory). Where that folder is not a git checkout (an installed wheel), ``git_commit`` is
    empty and ``version`` names the installed distribution.
    """
    from harness import __version__

    root = Path(__file__).resolve().parent.parent
    top = _git(root, "rev-parse", "--show-toplevel")
    commit, dirty = "", None
    if top and Path(top).resolve() == root:
        commit = _git(root, "rev-parse", "HEAD") or ""
        status = _git(root, "status", "--porcelain", "--untracked-files=no", "--", "harness", "plugins",
                      "pyproject.toml")
        dirty = bool(status) if status is not None else None
    try:
        installed = metadata.version(DISTRIBUTION)
    except metadata.PackageNotFoundError:
        installed = None
    return {"git_commit": commit, "dirty": dirty, "version": installed or __version__}


def package_versions() -> dict:
    out = {}
    for name in PACKAGES:
        try:
            out[name] = metadata.version(name)
        except metadata.PackageNotFoundError:
            out[name] = None
    return out


def make_manifest(registry, table: pd.DataFrame, *, settings: dict, executor: dict | None = None,
                  reused_jobs: int = 0, scene_approximations: dict | None = None,
                  source: dict | None = None) -> dict:
    """The manifest of a stored results table.

    Parameters
    ----------
    registry : harness.Registry
    table : DataFrame
        The whole stored table (every job, reused ones included).
    settings : dict
        The run's settings (what was asked for).
    executor : dict, optional
        Where jobs ran (:meth:`harness.executors.Executor.describe`).
    reused_jobs : int
        Jobs kept from an earlier run (``--resume``).
    scene_approximations : dict, optional
        Scene name -> what its plugin renders approximately
        (:meth:`harness.renders.RenderStore.scene_approximations`); kept for the table's scenes.
    source : dict, optional
        :func:`provenance` as it was when the run started (default: now); a checkout that
        changes during a long run must not be recorded as the code that ran.
    """
    from harness import __version__

    ran = table[table.status != "skipped"] if len(table) else table
    scenes = {r.scene: r.scene_hash for r in ran.drop_duplicates("scene").itertuples() if r.scene_hash}
    refs, quality = {}, {}
    for r in ran[ran.reference_hash != ""].drop_duplicates(["scene", "renderer", "frame"]).itertuples():
        refs[f"{r.scene}/{r.renderer}/{r.frame}"] = r.reference_hash
        error = None if pd.isna(r.reference_error) else float(r.reference_error)
        quality[f"{r.scene}/{r.renderer}/{r.frame}"] = {"spp": int(r.reference_spp), "median_relative_error": error}
    source = source or provenance()
    return {
        "harness_version": __version__,
        "created": time.strftime("%Y-%m-%dT%H:%M:%SZ", time.gmtime()),
        "command": " ".join([Path(sys.argv[0]).name, *sys.argv[1:]]) if sys.argv else "",
        "settings": settings,
        "git_commit": source["git_commit"],
        "git_dirty": source["dirty"],
        "installed_version": source["version"],
        "machine": machine_info(),
        "machines": sorted(set(ran.machine) - {""}) if len(ran) else [],
        "executor": executor or {},
        "python": sys.version.split()[0],
        "packages": package_versions(),
        "plugins": [r.as_dict() for r in registry.records],
        "jobs": int(table.job_id.nunique()) if len(table) else 0,
        "skipped_jobs": int(table[table.status == "skipped"].job_id.nunique()) if len(table) else 0,
        "error_jobs": int(table[table.status == "error"].job_id.nunique()) if len(table) else 0,
        "reused_jobs": reused_jobs,
        "tasks": sorted(set(ran.task)) if len(ran) else [],
        "seeds": sorted(int(s) for s in set(ran.seed)) if len(ran) else [],
        "scenes": scenes,
        "scene_approximations": {name: list(notes) for name, notes in sorted((scene_approximations or {}).items())
                                 if name in set(table.scene)} if len(table) else {},
        "references": refs,
        "reference_quality": quality,
    }


def write_manifest(manifest: dict, path: Path) -> None:
    atomic_write_bytes(Path(path), json.dumps(manifest, indent=2, sort_keys=True, default=str).encode())


def read_manifest(folder: str | Path) -> dict | None:
    path = Path(folder) / "manifest.json"
    return json.loads(path.read_text()) if path.exists() else None
