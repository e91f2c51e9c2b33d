"""Plugins as they were at another git revision, beside the current ones in one process.

``denoise-bench bench --baseline REV`` times a filter against itself at revision ``REV``:
:func:`plugin_path` finds where the filter's plugin package lies in the project's git tree,
:func:`revision_tree` extracts those folders as they were at ``REV`` (``git archive``) into a
temporary folder that is removed afterwards, :func:`import_copy` imports a package from there
under another module name (its relative imports stay inside the copy; it imports the current
``harness``), and :func:`baseline_spec` calls that package's ``register_filters`` hook and
renames the spec ``NAME@REV``. A plugin that imported its own package by absolute name
(``plugins.filters.NAME``) would get the current code there: the built-in plugins import
themselves relatively.
"""

from __future__ import annotations

import dataclasses
import importlib.util
import io
import shutil
import subprocess
import sys
import tarfile
import tempfile
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from pathlib import Path

#: the project's root (the git work tree the revisions are read from)
PROJECT_ROOT = Path(__file__).resolve().parents[1]


def _git(args: Sequence[str], root: Path) -> subprocess.CompletedProcess:
    try:
        return subprocess.run(["git", *args], cwd=root, capture_output=True, check=False)
    except OSError as exc:
        raise ValueError(f"git is not available: {exc}") from None


def resolve_revision(rev: str, root: Path = PROJECT_ROOT) -> str:
    """The commit id that ``rev`` names in the git repository at ``root``.

    Raises
    ------
    ValueError
        When ``root`` is not a git work tree or ``rev`` names no commit there.
    """
    if not rev or rev.startswith("-"):
        raise ValueError(f"--baseline {rev!r}: not a git revision")
    done = _git(["rev-parse", "--verify", "--quiet", f"{rev}^{{commit}}"], root)
    if done.returncode != 0:
        inside = _git(["rev-parse", "--is-inside-work-tree"], root)
        if inside.returncode != 0:
            raise ValueError(f"--baseline {rev}: the project at {root.name!r} is not a git checkout")
        raise ValueError(f"--baseline {rev}: unknown git revision")
    return done.stdout.decode().strip()


def plugin_path(registry, name: str, root: Path = PROJECT_ROOT) -> tuple[str, str]:
    """(module name, folder relative to ``root``) of the package that registers filter ``name``.

    Raises
    ------
    ValueError
        When the plugin is not a package inside the project's tree (a third-party distribution).
    """
    record = registry.record("filter", name)
    module = record.entry_point.split(":")[0]
    found = importlib.util.find_spec(module)
    locations = list(found.submodule_search_locations or []) if found is not None else []
    folder = Path(locations[0]).resolve() if locations else None
    if folder is None or root.resolve() not in folder.parents:
        raise ValueError(f"--baseline: filter {name!r} ({module}) is not a plugin package of this project's git tree")
    return module, folder.relative_to(root.resolve()).as_posix()


@contextmanager
def revision_tree(rev: str, paths: Sequence[str], root: Path = PROJECT_ROOT) -> Iterator[Path]:
    """A temporary folder holding ``paths`` (relative folders) as they were at ``rev``; removed on exit.

    Raises
    ------
    ValueError
        For an unknown revision, or a path that did not exist at that revision.
    """
    commit = resolve_revision(rev, root)
    folder = Path(tempfile.mkdtemp(prefix="denoise-bench-baseline-"))
    try:
        archive = _git(["archive", "--format=tar", commit, "--", *paths], root)
        if archive.returncode != 0:
            reason = archive.stderr.decode(errors="replace").strip().splitlines()
            raise ValueError(f"--baseline {rev}: {', '.join(paths)} not found at that revision"
                             + (f" ({reason[0]})" if reason else ""))
        with tarfile.open(fileobj=io.BytesIO(archive.stdout)) as tar:
            tar.extractall(folder, filter="data")
        yield folder
    finally:
        shutil.rmtree(folder, ignore_errors=True)


def import_copy(folder: Path, name: str):
    """The package in ``folder`` imported as module ``name`` (a stale one of that name is dropped first)."""
    folder = Path(folder)
    held = sys.modules.get(name)
    if held is not None:
        if Path(getattr(held, "__file__", "") or "").parent == folder:
            return held
        for key in [k for k in sys.modules if k == name or k.startswith(name + ".")]:
            del sys.modules[key]
    spec = importlib.util.spec_from_file_location(name, folder / "__init__.py",
                                                  submodule_search_locations=[str(folder)])
    if spec is None or spec.loader is None or not (folder / "__init__.py").is_file():
        raise ImportError(f"no package in {folder}")
    module = importlib.util.module_from_spec(spec)
    sys.modules[name] = module
    try:
        spec.loader.exec_module(module)
    except BaseException:
        del sys.modules[name]
        raise
    return module


def module_name(commit: str, filter_name: str) -> str:
    """The module name a baseline package is imported under (unique per revision and filter)."""
    safe = "".join(c if c.isalnum() else "_" for c in filter_name)
    return f"_baseline_{commit[:12]}_{safe}"


def baseline_spec(folder: Path, module: str, filter_name: str, label: str):
    """The filter spec ``filter_name`` registered by the package copied into ``folder``, renamed ``label``.

    Parameters
    ----------
    folder : Path
        The package's folder (inside a :func:`revision_tree`).
    module : str
        The module name to import it under (:func:`module_name`).
    filter_name : str
        The name the package registers.
    label : str
        The name the returned spec carries (``NAME@REV``).
    """
    package = import_copy(folder, module)
    hook = getattr(package, "register_filters", None)
    if hook is None:
        raise ImportError(f"{label}: the package has no register_filters hook")
    for spec in hook() or []:
        if spec.name == filter_name:
            return dataclasses.replace(spec, name=label)
    raise ImportError(f"{label}: the package registers no filter {filter_name!r} at that revision")


__all__ = ["PROJECT_ROOT", "baseline_spec", "import_copy", "module_name", "plugin_path", "resolve_revision",
           "revision_tree"]
