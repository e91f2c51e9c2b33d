"""The ``noaa`` filter: no anti-aliasing, the aliased input itself (the baseline row of the AA task).

Each output is a copy of the frame's ``color``: one shading sample per pixel at the frame's
sub-pixel jitter, as the renderer made it. Scoring it against the supersampled reference
measures how much aliasing a scene has before any filter runs.
"""

from __future__ import annotations

import numpy as np

from harness import FilterSpec, hookimpl

VERSION = "1.0"


class NoAA:
    """Returns the input colour unchanged (a float32 copy)."""

    def __init__(self, backend: str = "cpu"):
        if backend != "cpu":
            raise ValueError(f"noaa: unsupported backend {backend!r}; choose from ('cpu',)")

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        return np.array(frame["color"], dtype=np.float32, copy=True)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="noaa",
            version=VERSION,
            factory=NoAA,
            requires={"color"},
            temporal=False,
            backends=("cpu",),
            tasks={"antialias"},
            description="no anti-aliasing: the aliased one-sample-per-pixel input (baseline)",
        )
    ]
