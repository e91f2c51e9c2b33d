"""The plugin manager: loads plugins from entry points, validates and lists their specs.

Built-in and third-party plugins take the same path: modules registered under the
``denoise_harness`` entry-point group, implementing hooks of :mod:`harness.hookspecs`.
"""

from __future__ import annotations

import hashlib
import importlib.metadata as importlib_metadata
import os
import sys
from collections.abc import Iterable
from dataclasses import dataclass, field
from pathlib import Path
from types import ModuleType
from typing import Any

import pluggy

from harness import hookspecs
from harness.errors import short_error
from harness.specs import FilterSpec, MetricSpec, RendererSpec, SceneSpec

ENTRY_POINT_GROUP = "denoise_harness"
DISABLE_ENV = "DENOISE_HARNESS_DISABLE"

_HOOKS = {
    "filter": ("register_filters", FilterSpec),
    "renderer": ("register_renderers", RendererSpec),
    "metric": ("register_metrics", MetricSpec),
    "scene": ("register_scenes", SceneSpec),
}


class PluginConflictError(RuntimeError):
    """Two plugins registered the same name for the same kind."""


@dataclass
class PluginRecord:
    """One line of ``denoise-bench plugins``: a spec, or a plugin module that failed to load.

    Attributes
    ----------
    kind : str
        ``filter``, ``renderer``, ``metric``, ``scene``, or ``module`` for a module that failed
        before declaring anything.
    name : str
    version : str
    distribution : str
        The installed distribution that registered the entry point (``<local>`` for objects
        registered in-process).
    entry_point : str
    status : {"ok", "broken", "disabled"}
    error : str
    spec : spec dataclass or None
    source_hash : str
        SHA-256 of the plugin module's source files.
    """

    kind: str
    name: str
    version: str = ""
    distribution: str = ""
    entry_point: str = ""
    status: str = "ok"
    error: str = ""
    spec: Any = None
    source_hash: str = ""

    def as_dict(self) -> dict:
        return {
            "kind": self.kind,
            "name": self.name,
            "version": self.version,
            "distribution": self.distribution,
            "entry_point": self.entry_point,
            "status": self.status,
            "error": self.error,
            "source_hash": self.source_hash,
            "declarations": self.spec.declarations() if self.spec is not None else {},
        }


@dataclass
class Registry:
    """Every loaded plugin spec by kind and name, and a record of every plugin (broken too)."""

    filters: dict = field(default_factory=dict)
    renderers: dict = field(default_factory=dict)
    metrics: dict = field(default_factory=dict)
    scenes: dict = field(default_factory=dict)
    records: list = field(default_factory=list)
    manager: Any = None

    def open_scene(self, path) -> Any:
        """Open a scene folder or file through the plugins' ``open_scene`` hook (first result wins).

        Raises
        ------
        FileNotFoundError
            When ``path`` does not exist.
        ValueError
            When no plugin recognises it, or the one that does fails (the message says why).
        """
        path = Path(path)
        if not path.exists():
            raise FileNotFoundError(f"scene path {path} does not exist")
        if self.manager is None:
            raise ValueError(f"cannot open scene {path}: no plugins are loaded")
        try:
            scene = self.manager.hook.open_scene(path=path)
        except Exception as exc:
            raise ValueError(f"cannot open scene {path}: {short_error(exc)}") from None
        if scene is None:
            raise ValueError(f"cannot open scene {path}: no scene plugin recognises it")
        return scene

    def by_kind(self, kind: str) -> dict:
        return {"filter": self.filters, "renderer": self.renderers, "metric": self.metrics, "scene": self.scenes}[kind]

    def get(self, kind: str, name: str):
        """The spec of ``kind`` named ``name``; a ``KeyError`` lists the known names and broken plugins."""
        table = self.by_kind(kind)
        if name in table:
            return table[name]
        broken = [r for r in self.records if r.name == name and r.status != "ok"]
        if broken:
            raise KeyError(f"{kind} {name!r} is {broken[0].status}: {broken[0].error or 'disabled by name'}")
        raise KeyError(f"no {kind} named {name!r}; registered: {sorted(table)}")

    def record(self, kind: str, name: str) -> PluginRecord:
        for r in self.records:
            if r.kind == kind and r.name == name:
                return r
        raise KeyError(f"no {kind} record named {name!r}")

    @property
    def broken(self) -> list:
        return [r for r in self.records if r.status == "broken"]


def source_hash(module: Any) -> str:
    """SHA-256 over the source files of a plugin module (its whole package folder for a package)."""
    if not isinstance(module, ModuleType):
        module = sys.modules.get(getattr(module, "__module__", ""), None)
        if module is None:
            return ""
    path = getattr(module, "__file__", None)
    if not path:
        return ""
    path = Path(path)
    files = sorted(path.parent.rglob("*.py")) if path.name == "__init__.py" else [path]
    h = hashlib.sha256()
    for f in files:
        h.update(f.relative_to(path.parent).as_posix().encode())
        h.update(f.read_bytes())
    return h.hexdigest()


def disabled_names(extra: Iterable[str] = ()) -> set[str]:
    """Plugin names disabled by ``$DENOISE_HARNESS_DISABLE`` (comma-separated) and ``extra``."""
    names = {n.strip() for n in os.environ.get(DISABLE_ENV, "").split(",") if n.strip()}
    return names | set(extra)


def _reject_unknown_hooks(pm, registry, origin) -> None:
    """Unregister every plugin that implements a hook the harness does not specify.

    A misspelled hook (``register_filter``) would otherwise be ignored silently: the plugin is
    listed as broken, with the unknown name and the hooks that exist.
    """
    known = sorted(name for name in dir(hookspecs) if name.startswith(("register_", "open_")))
    while True:
        try:
            pm.check_pending()
            return
        except pluggy.PluginValidationError as exc:
            plugin = exc.plugin
            name = pm.get_name(plugin)
            unknown = sorted(
                hook for hook, caller in vars(pm.hook).items()
                if not caller.has_spec() and any(impl.plugin is plugin for impl in caller.get_hookimpls())
            )
            pm.unregister(plugin)
            dist, ep_value = origin.pop(name, ("<unknown>", name))
            registry.records.append(
                PluginRecord("module", name, distribution=dist, entry_point=ep_value, status="broken",
                             error=f"unknown hook(s) {unknown}; the hooks are {known}")
            )


def load_plugins(disable: Iterable[str] = (), extra: Iterable[Any] = (), entry_points: bool = True) -> Registry:
    """Load every plugin and collect its specs.

    Parameters
    ----------
    disable : iterable of str
        Plugin names (spec names or entry-point names) to disable, on top of
        ``$DENOISE_HARNESS_DISABLE``.
    extra : iterable
        Plugin objects or modules registered in-process (tests, notebooks).
    entry_points : bool
        Load the ``denoise_harness`` entry-point group (the default).

    Returns
    -------
    Registry

    Raises
    ------
    PluginConflictError
        When two plugins register the same name for the same kind; the message names both
        distributions.
    """
    off = disabled_names(disable)
    pm = pluggy.PluginManager(hookspecs.PROJECT_NAME)
    pm.add_hookspecs(hookspecs)
    registry = Registry(manager=pm)
    origin: dict[str, tuple[str, str]] = {}  # plugin name in pm -> (distribution, entry point)

    if entry_points:
        for ep in sorted(importlib_metadata.entry_points(group=ENTRY_POINT_GROUP), key=lambda e: e.name):
            dist = ep.dist.name if ep.dist is not None else "<unknown>"
            if ep.name in off:
                registry.records.append(
                    PluginRecord("module", ep.name, distribution=dist, entry_point=ep.value, status="disabled")
                )
                continue
            try:
                module = ep.load()
                pm.register(module, name=ep.name)
            except Exception as exc:  # a broken plugin must not take down the others
                registry.records.append(
                    PluginRecord(
                        "module",
                        ep.name,
                        distribution=dist,
                        entry_point=ep.value,
                        status="broken",
                        error=short_error(exc),
                    )
                )
                continue
            origin[ep.name] = (dist, ep.value)
    for i, obj in enumerate(extra):
        name = getattr(obj, "__name__", None) or f"extra-{i}-{type(obj).__name__}"
        pm.register(obj, name=name)
        origin[name] = ("<local>", name)
    _reject_unknown_hooks(pm, registry, origin)

    for kind, (hook_name, spec_type) in _HOOKS.items():
        table = registry.by_kind(kind)
        for impl in getattr(pm.hook, hook_name).get_hookimpls():
            dist, ep_value = origin.get(impl.plugin_name, ("<unknown>", impl.plugin_name))
            digest = source_hash(impl.plugin)
            others = [p for name, p in pm.list_name_plugin() if name != impl.plugin_name]
            try:
                results = pm.subset_hook_caller(hook_name, remove_plugins=others)()
                specs = [spec for result in results for spec in (result or [])]
                for spec in specs:
                    if not isinstance(spec, spec_type):
                        raise TypeError(f"{hook_name} returned {type(spec).__name__}, expected {spec_type.__name__}")
            except Exception as exc:
                registry.records.append(
                    PluginRecord(
                        kind,
                        impl.plugin_name,
                        distribution=dist,
                        entry_point=ep_value,
                        status="broken",
                        error=short_error(exc),
                    )
                )
                continue
            for spec in specs:
                record = PluginRecord(kind, spec.name, spec.version, dist, ep_value, spec=spec, source_hash=digest)
                if spec.name in off:
                    record.status = "disabled"
                    registry.records.append(record)
                    continue
                if spec.name in table:
                    other = registry.record(kind, spec.name)
                    raise PluginConflictError(
                        f"two {kind} plugins are named {spec.name!r}: one from distribution "
                        f"{other.distribution!r} ({other.entry_point}), one from {dist!r} ({ep_value}); "
                        f"uninstall one or disable it with {DISABLE_ENV}"
                    )
                table[spec.name] = spec
                registry.records.append(record)
    return registry
