"""The ``svgf`` filter: spatiotemporal variance-guided filtering (Schied et al., HPG 2017).

Albedo demodulation, temporal reprojection and accumulation with motion vectors, temporal (or
short-history spatial) luminance variance, and 5 variance-guided à-trous iterations. Degraded
modes (README): without ``motion`` the motion of static geometry from the camera where the frame
has ``view_proj``, ``prev_view_proj`` and ``depth`` (or ``position``), else spatial only (no
history); without ``depth`` no depth stop,
without ``object_id`` one object. Backends:
``cpu`` (Numba, parallel) and ``cuda`` (``numba.cuda``).
"""

from harness import FilterSpec, hookimpl

from .params import DECLARED, PRESETS
from .pipeline import SVGF

VERSION = "1.3"  # 1.1: camera motion without motion vectors; 1.2: demodulated and un-demodulated pixels filtered apart; 1.3: demodulation floor 0.1


def make_filter(backend: str = "cpu", **params) -> SVGF:
    """Build an :class:`SVGF` filter (``backend`` ``"cpu"`` or ``"cuda"``)."""
    return SVGF(backend=backend, **params)


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="svgf",
            version=VERSION,
            factory=make_filter,
            requires={"color", "albedo", "normal"},
            optional={"depth", "object_id", "motion", "indirect", "emission"},
            full_guides={"albedo", "normal", "depth", "object_id", "motion"},
            motion_from_camera=True,
            temporal=True,
            backends=("cpu", "cuda"),
            params=DECLARED,
            stage_timing=True,
            presets=PRESETS,
            description="spatiotemporal variance-guided filtering (Schied et al. 2017)",
        )
    ]
