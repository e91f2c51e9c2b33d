"""The unfiltered input under two names: ``passthrough`` (the no-filter baseline of the denoise
task: the noisy colour) and ``noaa`` (the baseline row of the antialias task).

For ``noaa`` each output is a copy of the frame's ``color``: one shading sample per pixel at the
frame's sub-pixel jitter, as the renderer made it. Scoring it against the supersampled reference
measures how much aliasing a scene has before any filter runs.
"""

from __future__ import annotations

import functools

import numpy as np

from harness import FilterSpec, hookimpl


class Passthrough:
    """Returns a copy of ``frame["color"]`` (float32).

    Parameters
    ----------
    backend : {"cpu"}
    name : str
        The filter's name, for messages.
    """

    def __init__(self, backend: str = "cpu", *, name: str = "passthrough"):
        if backend != "cpu":
            raise ValueError(f"{name}: unsupported backend {backend!r}; choose from ('cpu',)")

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        return np.array(frame["color"], dtype=np.float32, copy=True)


@hookimpl
def register_filters():
    return [
        FilterSpec(name="passthrough", version="1.0", factory=Passthrough, description="the noisy input, unfiltered"),
        FilterSpec(
            name="noaa",
            version="1.0",
            factory=functools.partial(Passthrough, name="noaa"),
            requires={"color"},
            temporal=False,
            backends=("cpu",),
            tasks={"antialias"},
            description="no anti-aliasing: the aliased one-sample-per-pixel input (baseline)",
        ),
    ]
