"""The ``passthrough`` filter: returns the noisy colour (the no-filter baseline)."""

import numpy as np

from harness import FilterSpec, hookimpl


class Passthrough:
    """Returns a copy of ``frame["color"]``."""

    def __init__(self, backend: str = "cpu"):
        if backend != "cpu":
            raise ValueError(f"passthrough: unsupported backend {backend!r}")

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        return np.array(frame["color"], dtype=np.float32, copy=True)


@hookimpl
def register_filters():
    return [
        FilterSpec(name="passthrough", version="1.0", factory=Passthrough, description="the noisy input, unfiltered")
    ]
