"""Where Numba keeps its compiled-function cache: one folder per plugin, keyed by that plugin's source.

Numba's on-disk cache (``cache=True``) checks only the timestamp of the file that defines a
function, not of the files whose functions it inlined or called, so after an edit to a helper
module a stale cached kernel could run with the old code. The harness therefore installs a cache
locator that puts the kernels of each *compile unit* in a folder named by a digest of that
unit's source:

* a built-in plugin, ``plugins/<kind>/<name>`` (a package or a single module): its own ``.py``
  files plus the harness's shared kernels (:mod:`harness.kernels`, the only harness code a
  plugin's compiled code may call);
* the ``harness`` package itself (its own kernels, such as :mod:`harness.floor`).

An edit to one plugin therefore recompiles that plugin's kernels only; an edit to
:mod:`harness.kernels` recompiles every plugin; an edit elsewhere in the harness recompiles the
harness's own few kernels. The folders live in ``<cache home>/denoise-harness/numba/`` and are
named ``<unit>-<digest>``, so checkouts with the same source share them. Source stamps are the
digest, not the file's modification time, so a fresh clone of the same code finds its kernels.

A ``NUMBA_CACHE_DIR`` set by the user is left alone (Numba then caches everything there, keyed
by timestamps as usual). Third-party plugins keep Numba's default locators.
"""

from __future__ import annotations

import hashlib
import os
import sys
from collections.abc import Iterable
from functools import cache
from pathlib import Path

HARNESS = Path(__file__).resolve().parent
PLUGINS = HARNESS.parent / "plugins"
#: harness modules a plugin's compiled code may call: part of every plugin's digest
SHARED_KERNELS = ("kernels.py", "kernels")


def source_digest(*paths: Path) -> str:
    """SHA-256 (first 16 hex digits) over the relative names and bytes of every ``.py`` file.

    Parameters
    ----------
    *paths : pathlib.Path
        Folders (searched recursively) or single files; missing paths are skipped.
    """
    h = hashlib.sha256()
    for root in paths:
        files = sorted(root.rglob("*.py")) if root.is_dir() else [root] if root.is_file() else []
        for path in files:
            h.update(path.relative_to(root.parent).as_posix().encode())
            h.update(path.read_bytes())
    return h.hexdigest()[:16]


def compile_unit(py_file: str | Path) -> tuple[str, tuple[Path, ...]] | None:
    """The compile unit a source file belongs to: (name, the paths its digest covers), or None.

    Parameters
    ----------
    py_file : path
        The file that defines a compiled function.

    Returns
    -------
    tuple or None
        ``("harness", (harness folder,))`` for the harness, ``("<kind>.<name>", (plugin path,
        shared kernels...))`` for a built-in plugin, None for any other file.
    """
    path = Path(py_file).resolve()
    if path.is_relative_to(HARNESS):
        return "harness", (HARNESS,)
    if not path.is_relative_to(PLUGINS):
        return None
    parts = path.relative_to(PLUGINS).parts
    if len(parts) < 2:
        return None
    unit = PLUGINS / parts[0] / parts[1]
    name = f"{parts[0]}.{Path(parts[1]).stem}"
    return name, (unit, *(HARNESS / s for s in SHARED_KERNELS))


@cache
def _unit_folder(name: str, paths: tuple[Path, ...]) -> tuple[str, str]:
    """(folder, digest) of a compile unit (computed once per process)."""
    digest = source_digest(*paths)
    return str(cache_home() / f"{name}-{digest}"), digest


def cache_home() -> Path:
    """``$XDG_CACHE_HOME/denoise-harness/numba`` (``~/.cache`` when unset)."""
    home = Path(os.environ.get("XDG_CACHE_HOME") or Path.home() / ".cache")
    return home / "denoise-harness" / "numba"


def _locator_class():
    """A Numba cache locator for the compile units (built on first use: Numba imports lazily)."""
    from numba.core import caching

    class UnitCacheLocator(caching._SourceFileBackedLocatorMixin, caching._CacheLocator):
        """Caches a function of the harness or a built-in plugin in its compile unit's folder."""

        def __init__(self, py_func, py_file):
            self._py_file = py_file
            self._lineno = py_func.__code__.co_firstlineno
            self._cache_path, self._digest = _unit_folder(*compile_unit(py_file))

        def get_cache_path(self):
            return self._cache_path

        def get_source_stamp(self):
            return self._digest

        @classmethod
        def from_function(cls, py_func, py_file):
            if os.environ.get("NUMBA_CACHE_DIR") or compile_unit(py_file) is None:
                return None
            return super().from_function(py_func, py_file)

    return UnitCacheLocator


def _asks_for_cache(paths: tuple[Path, ...]) -> bool:
    """Whether the unit's own source (its first path) defines a kernel cached on disk."""
    root = paths[0]
    files = sorted(root.rglob("*.py")) if root.is_dir() else [root] if root.is_file() else []
    return any("cache=True" in f.read_text(errors="replace") for f in files)


def uncompiled_units(objects: Iterable[object]) -> list[str]:
    """Compile units that will compile Numba kernels when ``objects`` are first used.

    Parameters
    ----------
    objects : iterable
        Plugin objects (classes or functions, e.g. the specs' factories); each names the compile
        unit of the module that defines it.

    Returns
    -------
    list of str
        Sorted names of the units (``filters.eaw``, ``renderers.pathtracer``, ...) whose source
        caches kernels on disk and whose cache folder for the current source holds no compiled
        kernel yet: a fresh install, or an edit of that unit. Empty when the user set
        ``NUMBA_CACHE_DIR`` (Numba's own cache, which this module does not track).
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return []
    missing = set()
    for obj in objects:
        module = sys.modules.get(getattr(obj, "__module__", "") or "")
        unit = compile_unit(module.__file__) if getattr(module, "__file__", None) else None
        if unit is None or unit[0] in missing or not _asks_for_cache(unit[1]):
            continue
        folder = Path(_unit_folder(*unit)[0])
        if not folder.is_dir() or not any(folder.glob("*.nbi")):
            missing.add(unit[0])
    return sorted(missing)


def compile_notice(registry, plan) -> str | None:
    """One line naming the compile units a planned run will compile on first use, or None.

    Parameters
    ----------
    registry : harness.plugins.Registry
    plan : harness.plan.Plan
        Its jobs' filters and renderers are looked up in ``registry``.
    """
    objects = []
    for kind, names in (("filter", {j.filter for j in plan.jobs}), ("renderer", {j.renderer for j in plan.jobs})):
        for name in sorted(n for n in names if n):
            try:
                objects.append(registry.get(kind, name).factory)
            except KeyError:
                continue
    units = uncompiled_units(objects)
    if not units:
        return None
    return (f"compiling the Numba kernels of {', '.join(units)} on first use (a fresh install or an edit "
            f"of their source: minutes on 2 cores, once; later runs load them from the cache)")


def configure_numba_cache() -> Path | None:
    """Install the per-unit cache locator ahead of Numba's own (once per process).

    Returns the folder holding the units' caches, or None when the user set
    ``NUMBA_CACHE_DIR`` themselves.
    """
    if os.environ.get("NUMBA_CACHE_DIR"):
        return None
    from numba.core import caching

    locators = caching.CacheImpl._locator_classes
    if not any(cls.__name__ == "UnitCacheLocator" for cls in locators):
        locators.insert(0, _locator_class())
    return cache_home()
