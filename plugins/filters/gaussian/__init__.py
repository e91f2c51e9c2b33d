"""The ``gaussian`` filter: a separable Gaussian blur that ignores edges (a lower baseline)."""

from harness import FilterSpec, Param, hookimpl

from .blur import GaussianBlur

PARAMS = {"sigma": Param(1.5, min=0, max=64, doc="standard deviation in pixels")}


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
