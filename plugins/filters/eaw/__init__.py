"""The ``eaw`` filter: edge-avoiding à-trous wavelets (Dammertz et al., HPG 2010).

Five (by default) à-trous iterations of a 5x5 B3-spline kernel with hole spacing ``2**i``,
each tap weighted by edge-stopping functions of colour, normal and world position.
Without ``position`` (a capture of colour, albedo and normal) the position stop runs on the
albedo instead (an albedo edge stop), or on a pinhole position from ``depth`` where there is no
albedo (:func:`.filter.position_stand_in`). See ``README.md`` beside this file for the
parameters and the choices made.
"""

from harness import FilterSpec, hookimpl

from .filter import EAWFilter
from .params import DECLARED, PRESETS

VERSION = "1.0"


def make_filter(backend: str = "cpu", **params) -> EAWFilter:
    """Factory of the ``eaw`` filter (see :class:`.filter.EAWFilter`)."""
    return EAWFilter(backend=backend, **params)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="eaw",
            version=VERSION,
            factory=make_filter,
            requires={"color", "normal"},
            optional={"position", "albedo", "depth"},
            full_guides={"normal", "position"},
            temporal=False,
            convex=True,  # renormalised non-negative weights (checked by the stress battery)
            backends=("cpu", "cuda"),
            params=DECLARED,
            stage_timing=True,
            presets=PRESETS,
            description="edge-avoiding à-trous wavelets (Dammertz 2010): 5x5 B3 taps, colour/normal/position stops",
        )
    ]
