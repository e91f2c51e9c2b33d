"""Conformance testing for plugins, usable by third parties with pytest.

Example, in a third party's test file::

    from harness.testing import parametrize_with_checks

    @parametrize_with_checks(filters=["my_filter"])
    def test_my_filter(plugin_check):
        plugin_check()

Every check of :mod:`harness.testing.checks` for that kind becomes one test, with an id like
``filter:my_filter[cpu]-check_constant_image``. Filters of the ``antialias`` task also get the
checks of :mod:`harness.testing.antialias_checks`. With no arguments every registered plugin of
every kind is checked (the project's own suite does this). The ``cuda`` backend is checked where
``numba.cuda`` can run (a GPU, or ``NUMBA_ENABLE_CUDASIM=1``) and ``cuda_checks`` is true.
"""

from __future__ import annotations

import functools

from harness.backends import cuda_available
from harness.plugins import load_plugins
from harness.testing.antialias_checks import ANTIALIAS_CHECKS
from harness.testing.checks import FILTER_CHECKS, METRIC_CHECKS, RENDERER_CHECKS, SCENE_CHECKS
from harness.testing.frames import make_frame

_CHECKS = {"filter": FILTER_CHECKS, "metric": METRIC_CHECKS, "renderer": RENDERER_CHECKS, "scene": SCENE_CHECKS}


@functools.lru_cache(maxsize=1)
def registry():
    """The registry of installed plugins, loaded once per process."""
    return load_plugins()


class PluginCheck:
    """One check bound to one plugin (and backend); call it to run the check."""

    def __init__(self, kind: str, name: str, backend: str | None, check):
        self.kind, self.name, self.backend, self.check = kind, name, backend, check

    @property
    def id(self) -> str:
        backend = f"[{self.backend}]" if self.backend else ""
        return f"{self.kind}:{self.name}{backend}-{self.check.__name__}"

    def __call__(self) -> None:
        import pytest

        reg = registry()
        spec = reg.get(self.kind, self.name)
        kwargs = {"registry": reg} if self.kind == "renderer" else {}
        try:
            self.check(spec, self.backend, **kwargs)
        except FileNotFoundError as exc:  # scenes whose third-party files are absent
            pytest.skip(f"{self.kind} {self.name!r}: {exc}")

    def __repr__(self) -> str:
        return self.id


def plugin_checks(
    filters=None, metrics=None, renderers=None, scenes=None, cuda_checks: bool = True
) -> list[PluginCheck]:
    """Every (plugin, backend, check) to run; ``None`` for a kind means all registered of that kind.

    Passing only some kinds (e.g. ``filters=["mine"]``) checks only those.
    """
    reg = registry()
    chosen = {"filter": filters, "metric": metrics, "renderer": renderers, "scene": scenes}
    if any(v is not None for v in chosen.values()):
        chosen = {k: (v or []) for k, v in chosen.items()}
    else:
        chosen = {k: sorted(reg.by_kind(k)) for k in chosen}
    items = []
    for kind, names in chosen.items():
        for name in names:
            spec = reg.get(kind, name)
            backends = [None]
            if kind == "filter":
                backends = [b for b in spec.backends if b == "cpu" or (cuda_checks and cuda_available())]
            checks = _CHECKS[kind]
            if kind == "filter" and "antialias" in spec.tasks:
                checks = checks + ANTIALIAS_CHECKS  # the anti-aliasing task's own checks
            for backend in backends:
                for check in checks:
                    items.append(PluginCheck(kind, name, backend, check))
    return items


def parametrize_with_checks(filters=None, metrics=None, renderers=None, scenes=None, cuda_checks: bool = True):
    """A ``pytest.mark.parametrize`` over :func:`plugin_checks`, as the argument ``plugin_check``."""
    import pytest

    reg = registry()
    params = []
    for item in plugin_checks(filters, metrics, renderers, scenes, cuda_checks):
        reason = getattr(reg.get(item.kind, item.name), "xfail_checks", {}).get(item.check.__name__)
        marks = [pytest.mark.xfail(reason=reason, strict=True)] if reason else []
        params.append(pytest.param(item, id=item.id, marks=marks))
    return pytest.mark.parametrize("plugin_check", params)


__all__ = ["PluginCheck", "make_frame", "parametrize_with_checks", "plugin_checks", "registry"]
