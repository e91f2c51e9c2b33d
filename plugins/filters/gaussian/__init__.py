"""The ``gaussian`` filter: a separable Gaussian blur that ignores edges (a lower baseline)."""

from harness import FilterSpec, hookimpl

from .blur import GaussianBlur

PARAMS = {"sigma": 1.5}


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="gaussian",
            version="1.0",
            factory=GaussianBlur,
            params=PARAMS,
            description="separable Gaussian blur, not edge-aware (baseline)",
        )
    ]
