"""Filters for the Dask executor's tests, loaded by the workers by module name.

``slow`` sleeps in every call (so a worker can be killed while it holds the job); ``exits`` ends
its worker process (``os._exit``) on every call. The renderer ``slow-synthetic`` is the
``synthetic`` renderer whose ``accumulate`` sleeps (so a worker can be killed while it holds a
reference chunk).
"""

import os
import time

import numpy as np

from harness import CHANNELS, FilterSpec, RendererSpec, hookimpl
from plugins.renderers.synthetic.renderer import SyntheticRenderer


class Slow:
    def __init__(self, backend="cpu", how="slow"):
        self.how = how

    def reset(self):
        pass

    def __call__(self, frame, sampler=None):
        if self.how == "exits":
            os._exit(9)
        time.sleep(0.15)
        return np.ascontiguousarray(frame["color"] * np.float32(0.5) + np.float32(0.25))


@hookimpl
def register_filters():
    return [FilterSpec(name=how, version="0", factory=lambda backend="cpu", how=how: Slow(backend, how))
            for how in ("slow", "exits")]


class SlowSynthetic:
    """The synthetic renderer; ``accumulate`` sleeps 0.1 s per sample before its sum."""

    def __init__(self, **settings):
        self.inner = SyntheticRenderer(**settings)

    def settings(self) -> dict:
        return self.inner.settings()

    def render(self, *args, **kwargs):
        return self.inner.render(*args, **kwargs)

    def reference(self, *args, **kwargs):
        return self.inner.reference(*args, **kwargs)

    def accumulate(self, scene, frame_index, *, first_sample, count, seed=0, resolution=None):
        time.sleep(0.1 * count)
        return self.inner.accumulate(scene, frame_index, first_sample=first_sample, count=count, seed=seed,
                                     resolution=resolution)


@hookimpl
def register_renderers():
    return [RendererSpec(name="slow-synthetic", version="0", factory=SlowSynthetic, provides=frozenset(CHANNELS),
                         references=True, scene_kinds=frozenset({"procedural"}), reference_spp=0, chunked=True,
                         tasks={"denoise"}, description="the synthetic renderer, slow reference chunks (tests)")]
