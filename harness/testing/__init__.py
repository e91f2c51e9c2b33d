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

Filters also get the stress battery (:mod:`harness.stress.cases`): one test per case that
applies, with an id like ``filter:my_filter[cpu]-stress:guide-normal-nan``, each run in a worker
process so a crash fails the test rather than the session (``stress="all"`` adds the heavy
4K and 1,000-frame cases; ``stress=None`` leaves the battery out). All but one case per group of
the battery (colour, guide, shape, sequence, policy) carry the ``slow`` marker, so that
``pytest -m "not slow"`` is a fast tier that still runs each group for each filter (which case
stands for its group depends on the filter's name: together the filters cover more of it). A check the filter declares
in ``xfail_checks`` (by check name) or a case in ``stress_exempt`` runs as a strict expected
failure with the declared reason; ``xfail`` adds expected failures by test id (for plugins
whose spec you do not own).
"""

from __future__ import annotations

import functools
import zlib

from harness.backends import cuda_available
from harness.plugins import load_plugins
from harness.stress.cases import exemption
from harness.testing.antialias_checks import ANTIALIAS_CHECKS
from harness.testing.checks import FILTER_CHECKS, METRIC_CHECKS, RENDERER_CHECKS, SCENE_CHECKS
from harness.testing.frames import make_frame
from harness.testing.stress import StressCheck, stress_checks

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

    def xfail_reason(self, spec) -> str | None:
        """The reason the plugin declares for failing this check (None: it must pass)."""
        reason = (getattr(spec, "xfail_checks", None) or {}).get(self.check.__name__)
        if reason is None and isinstance(self.check, StressCheck):
            reason = exemption(spec, self.check.case.name)
        return reason


def plugin_checks(
    filters=None, metrics=None, renderers=None, scenes=None, cuda_checks: bool = True, stress="light"
) -> list[PluginCheck]:
    """Every (plugin, backend, check) to run; ``None`` for a kind means all registered of that kind.

    Passing only some kinds (e.g. ``filters=["mine"]``) checks only those. ``stress`` chooses
    the stress cases of filters: ``"light"`` (default), ``"all"`` or None.
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
            checks = list(_CHECKS[kind])
            if kind == "filter" and "antialias" in spec.tasks:
                checks += ANTIALIAS_CHECKS  # the anti-aliasing task's own checks
            if kind == "filter":
                checks += stress_checks(spec, stress)
            for backend in backends:
                for check in checks:
                    items.append(PluginCheck(kind, name, backend, check))
    return items


def fast_stress_cases(items) -> dict[str, set[str]]:
    """The stress cases of the fast tier: for each filter, one case per group of the battery.

    Parameters
    ----------
    items : list of PluginCheck

    Returns
    -------
    dict
        Filter name to the names of its cases that stay in the fast tier; the case standing for
        a group is chosen by a hash of the filter's name among the group's cases that apply to it.
    """
    groups: dict[tuple[str, str], list[str]] = {}
    for item in items:
        if isinstance(item.check, StressCheck):
            names = groups.setdefault((item.name, item.check.case.group), [])
            if item.check.case.name not in names:
                names.append(item.check.case.name)
    fast: dict[str, set[str]] = {}
    for (name, _), names in groups.items():
        fast.setdefault(name, set()).add(names[zlib.crc32(name.encode()) % len(names)])
    return fast


def _loads_scene_files(item, reg) -> bool:
    """Whether a check opens third-party scene files (a ``real``-tier scene, or a renderer of that
    tier alone): seconds to tens of seconds each, so the full tier's."""
    spec = reg.get(item.kind, item.name)
    if item.kind == "scene":
        return spec.tier == "real"
    return item.kind == "renderer" and set(spec.scene_tiers) <= {"real"}


def parametrize_with_checks(filters=None, metrics=None, renderers=None, scenes=None, cuda_checks: bool = True,
                            stress="light", xfail=None):
    """A ``pytest.mark.parametrize`` over :func:`plugin_checks`, as the argument ``plugin_check``.

    Parameters
    ----------
    filters, metrics, renderers, scenes : list of str, optional
        Plugins to check (see :func:`plugin_checks`).
    cuda_checks : bool
        Check the ``cuda`` backend where ``numba.cuda`` can run.
    stress : {"light", "all", None}
        Which stress cases filters get (one per group of the battery per filter in the fast tier,
        the others marked ``slow``; the checks that open third-party scene files are ``slow`` too).
    xfail : mapping of str to str, optional
        Test ids (``filter:NAME[cpu]-stress:CASE``) expected to fail, with the reason, on top
        of what the plugins declare (ids of plugins that are not installed are ignored; a
        misspelt id of a checked plugin is an error). Every expected failure is strict: one
        that passes fails.
    """
    import pytest

    reg = registry()
    extra = dict(xfail or {})
    items = plugin_checks(filters, metrics, renderers, scenes, cuda_checks, stress)
    fast = fast_stress_cases(items)
    params = []
    for item in items:
        reason = item.xfail_reason(reg.get(item.kind, item.name)) or extra.pop(item.id, None)
        marks = [pytest.mark.xfail(reason=reason, strict=True)] if reason else []
        if isinstance(item.check, StressCheck) and item.check.case.name not in fast.get(item.name, ()):
            marks.append(pytest.mark.slow)
        elif _loads_scene_files(item, reg):
            marks.append(pytest.mark.slow)
        params.append(pytest.param(item, id=item.id, marks=marks))
    checked = {item.id[: -len(item.check.__name__)] for item in items}  # "kind:name[backend]-" of each plugin
    unknown = sorted(i for i in extra if any(i.startswith(prefix) for prefix in checked))
    if unknown:  # a checked plugin has no such test: a misspelt id (absent plugins are not an error)
        raise ValueError(f"xfail names tests that do not exist: {unknown}")
    return pytest.mark.parametrize("plugin_check", params)


__all__ = ["PluginCheck", "StressCheck", "fast_stress_cases", "make_frame", "parametrize_with_checks",
           "plugin_checks", "registry", "stress_checks"]
