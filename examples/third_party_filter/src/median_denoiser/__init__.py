"""An example third-party filter plugin: the per-channel 3x3 median.

It uses only ``harness``'s public API, and is registered in this distribution's own
``pyproject.toml`` under the ``denoise_harness`` entry-point group, exactly as the built-ins are.
"""

import numpy as np

from harness import FilterSpec, hookimpl


class Median3:
    """Per-channel median over the 3x3 neighbourhood (edges replicated)."""

    def __init__(self, backend="cpu"):
        if backend != "cpu":
            raise ValueError(f"median3: unsupported backend {backend!r}")

    def reset(self):
        """Stateless."""

    def __call__(self, frame, sampler=None):
        color = frame["color"]
        h, w, _ = color.shape
        padded = np.pad(color, ((1, 1), (1, 1), (0, 0)), mode="edge")
        stack = np.stack([padded[i : i + h, j : j + w] for i in range(3) for j in range(3)])
        return np.median(stack, axis=0).astype(np.float32)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="median3",
            version="0.1.0",
            factory=Median3,
            description="3x3 per-channel median (third-party example)",
            # each output value is one of the input values: `denoise-bench stress` and the pytest
            # stress cases then check the tight bound (within [min, max] of the input colour)
            convex=True,
        )
    ]
