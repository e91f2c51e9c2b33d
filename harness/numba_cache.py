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
import json
import os
import sys
import time
from collections.abc import Iterable
from functools import cache
from pathlib import Path

HARNESS = Path(__file__).resolve().parent
PLUGINS = HARNESS.parent / "plugins"
#: harness modules a plugin's compiled code may call: part of every plugin's digest
SHARED_KERNELS = ("kernels.py", "kernels")
#: the file in a unit's cache folder holding the thread CPU seconds its kernels took to compile
RECORD = "compile-time.json"
#: where :data:`MEASURED_CPU_S` was measured
MEASURED_ON = "CPU seconds measured on a 2-core AMD EPYC"
#: compile CPU seconds per unit (:data:`RECORD`, thread CPU time) on a first ``denoise-bench run`` on a
#: 2-core AMD EPYC shared with other work (load average 4-6): the filters in one run of
#: ``--scenes synthetic-moving --seeds 0 --frames 2 --timing-at none``, the path tracer in one of
#: ``--filters gaussian --scenes cornell``; the estimate where this machine has recorded none
MEASURED_CPU_S: dict[str, float] = {
    "filters.eaw": 78.7, "filters.gaussian": 2.4, "filters.lbf": 35.1, "filters.sbf": 30.2, "filters.svgf": 113.0,
    "renderers.pathtracer": 308.0,
}


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


def _unit_of(obj) -> tuple[str, tuple[Path, ...]] | None:
    """The compile unit of the module that defines ``obj`` (:func:`compile_unit`), or None."""
    module = sys.modules.get(getattr(obj, "__module__", "") or "")
    return compile_unit(module.__file__) if getattr(module, "__file__", None) else None


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
        unit = _unit_of(obj)
        if unit is None or unit[0] in missing or not _asks_for_cache(unit[1]):
            continue
        folder = Path(_unit_folder(*unit)[0])
        if not folder.is_dir() or not any(folder.glob("*.nbi")):
            missing.add(unit[0])
    return sorted(missing)


def plan_units(registry, plan) -> list[str]:
    """The compile units of a planned run's filters and renderers that hold no compiled kernel yet.

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
    return uncompiled_units(objects)


def compile_notice(registry, plan) -> str | None:
    """One line naming the compile units a planned run will compile on first use and how long it takes, or None.

    The estimate is each unit's compile time recorded on this machine (:func:`recorded_seconds`),
    else the CPU seconds of :data:`MEASURED_CPU_S`; the line says which.

    Parameters
    ----------
    registry : harness.plugins.Registry
    plan : harness.plan.Plan
        Its jobs' filters and renderers are looked up in ``registry``.
    """
    units = plan_units(registry, plan)
    if not units:
        return None
    recorded = {u: recorded_seconds(u) for u in units}
    line = f"compiling kernels of {', '.join(units)} (first use"
    if all(s is not None for s in recorded.values()):
        return line + f", about {_seconds(sum(recorded.values()))}: their last compile on this machine)"
    known = {u: recorded[u] if recorded[u] is not None else MEASURED_CPU_S.get(u) for u in units}
    unknown = [u for u, s in known.items() if s is None]
    if len(unknown) == len(units):
        return line + ", minutes on 2 cores, once)"
    more = f" plus {', '.join(unknown)}" if unknown else ""
    return line + (f", about {_seconds(sum(s for s in known.values() if s is not None))}{more}: {MEASURED_ON}, "
                   f"this machine's last compile where recorded)")


def _seconds(seconds: float) -> str:
    return f"{seconds:.0f} s" if seconds < 120 else f"{seconds / 60:.1f} min"


def recorded_seconds(unit: str) -> float | None:
    """The thread CPU seconds of the last compile of a unit's kernels recorded on this machine, or None.

    The newest :data:`RECORD` among the unit's cache folders (any source digest: the last compile
    before an edit tells how long the next one takes).
    """
    records = sorted(cache_home().glob(f"{unit}-*/{RECORD}"), key=lambda p: p.stat().st_mtime)
    for path in reversed(records):
        try:
            return float(json.loads(path.read_text())["cpu_s"])
        except (OSError, ValueError, KeyError, TypeError):
            continue
    return None


def compiled_line(name: str, paths: tuple[Path, ...]) -> str | None:
    """``compiled kernels of NAME in N s`` once the unit's current cache folder holds its record, else None.

    Parameters
    ----------
    name, paths : str, tuple of pathlib.Path
        The unit, as :func:`compile_unit` gives it.
    """
    path = Path(_unit_folder(name, paths)[0]) / RECORD
    try:
        seconds = float(json.loads(path.read_text())["cpu_s"])
    except (OSError, ValueError, KeyError, TypeError):
        return None
    return f"compiled kernels of {name} in {_seconds(seconds)} (CPU)"


class CompileProgress:
    """Says, once per unit, that a unit announced by :func:`compile_notice` has compiled its kernels.

    Parameters
    ----------
    registry : harness.plugins.Registry
    units : iterable of str
        The units still to compile (:func:`plan_units`).
    """

    def __init__(self, registry, units: Iterable[str]):
        self.registry, self.pending = registry, set(units)

    def __call__(self, kind: str, name: str) -> str | None:
        """The line for a plugin just used (``kind`` ``filter`` or ``renderer``), or None.

        None when its unit was not pending or recorded no compile time (e.g. compiled on another
        machine of a cluster).
        """
        if not self.pending:
            return None
        try:
            unit = _unit_of(self.registry.get(kind, name).factory)
        except KeyError:
            return None
        if unit is None or unit[0] not in self.pending:
            return None
        line = compiled_line(*unit)
        if line is not None:
            self.pending.discard(unit[0])
        return line


class _CompileClock:
    """A Numba ``numba:compile`` listener: each unit's compile CPU time, written to its cache folder.

    The thread CPU time of each outermost compile (callees compiled inside it included) goes to
    the unit of the function compiled; the unit's total in this process is written to
    :data:`RECORD` in its current folder after each one. Numba raises the event only for a real
    compile, not for a kernel loaded from the cache.
    """

    def __init__(self):
        self.depth, self.start, self.totals = 0, 0.0, {}

    def on_start(self, event) -> None:
        if self.depth == 0:
            self.start = time.thread_time()
        self.depth += 1

    def on_end(self, event) -> None:
        self.depth -= 1
        if self.depth:
            return
        func = getattr(event.data.get("dispatcher"), "py_func", None)
        unit = compile_unit(func.__code__.co_filename) if func is not None else None
        if unit is None:
            return
        folder = Path(_unit_folder(*unit)[0])
        self.totals[unit[0]] = self.totals.get(unit[0], 0.0) + time.thread_time() - self.start
        try:
            folder.mkdir(parents=True, exist_ok=True)
            (folder / RECORD).write_text(json.dumps({"cpu_s": round(self.totals[unit[0]], 2)}))
        except OSError:
            pass


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
        _install_clock()
    return cache_home()


def _install_clock() -> None:
    """Register :class:`_CompileClock` for Numba's compile events (once per process)."""
    from numba.core import event

    clock = _CompileClock()
    listener = type("UnitCompileClock", (event.Listener,), {"on_start": lambda self, e: clock.on_start(e),
                                                            "on_end": lambda self, e: clock.on_end(e)})
    event.register("numba:compile", listener())
