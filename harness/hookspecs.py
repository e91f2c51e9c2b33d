"""The plugin contract: pluggy hook specifications.

A plugin is any module registered under the ``denoise_harness`` entry-point group that
implements one or more of these hooks with :data:`harness.hookimpl`. Each hook returns a
list of specs (see :mod:`harness.specs`).
"""

from __future__ import annotations

import pluggy

PROJECT_NAME = "denoise_harness"

hookspec = pluggy.HookspecMarker(PROJECT_NAME)
hookimpl = pluggy.HookimplMarker(PROJECT_NAME)


@hookspec
def register_filters():
    """Return a list of :class:`harness.FilterSpec` this plugin provides."""


@hookspec
def register_renderers():
    """Return a list of :class:`harness.RendererSpec` this plugin provides."""


@hookspec
def register_metrics():
    """Return a list of :class:`harness.MetricSpec` this plugin provides."""


@hookspec
def register_scenes():
    """Return a list of :class:`harness.SceneSpec` this plugin provides."""


@hookspec(firstresult=True)
def open_scene(path):
    """Open a scene stored at ``path`` (a folder or file), or return None if not recognised.

    Used by ``denoise-bench run --scene-dir PATH``; the first plugin returning a
    :class:`harness.Scene` wins.
    """
