"""The ``fxaa`` filter: a single-frame, FXAA-style edge blend (Lottes, NVIDIA 2009-2011).

The non-temporal baseline of the anti-aliasing task: it finds luma edges in the one frame and
blends along them, so it softens stair-steps of edges wider than a pixel but cannot restore what
the single sample per pixel missed (broken thin wires, texture moire). See ``docs/antialias.md``.
"""

from __future__ import annotations

import numpy as np

from harness import FilterSpec, Param, hookimpl, load_backend

VERSION = "1.0"
BACKENDS = ("cpu",)
PARAMS = {
    "edge_threshold": Param(0.125, min=0.0, max=1.0,
                            doc="local contrast, relative to the local max luma, below which a pixel is kept"),
    "edge_threshold_min": Param(0.0312, min=0.0, max=1.0,
                                doc="absolute contrast below which a pixel is kept (dark areas)"),
    "span_max": Param(8.0, min=0.0, min_exclusive=True, max=64.0, doc="longest blend along the edge, pixels"),
}


class FXAA:
    """FXAA-style anti-aliasing of single frames (no history)."""

    def __init__(self, backend: str = "cpu", **params):
        unknown = sorted(set(params) - set(PARAMS))
        if unknown:
            raise TypeError(f"fxaa: unknown parameter(s) {unknown}; known: {sorted(PARAMS)}")
        values = {k: p.default for k, p in PARAMS.items()}
        values.update({k: PARAMS[k].check(v, owner=f"fxaa: parameter {k!r}") for k, v in params.items()})
        self.params = values
        self._ops = load_backend(__package__, backend, BACKENDS, owner="fxaa")

    def reset(self) -> None:
        """Nothing to forget."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        p = self.params
        return self._ops.fxaa(frame["color"], p["edge_threshold"], p["edge_threshold_min"], p["span_max"])


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="fxaa",
            version=VERSION,
            factory=FXAA,
            requires={"color"},
            temporal=False,
            backends=BACKENDS,
            params=PARAMS,
            tasks={"antialias"},
            description="single-frame FXAA-style edge blend (non-temporal AA baseline)",
        )
    ]
