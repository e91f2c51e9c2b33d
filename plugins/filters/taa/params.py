"""Parameters of the ``taa`` filter, declared once for the spec and for direct construction."""

from __future__ import annotations

from harness import Param

from . import kernels as K

#: the declarations in the FilterSpec; defaults follow Karis 2014 and Salvi 2016
DECLARED = {
    "alpha": Param(0.1, min=0.0, min_exclusive=True, max=1.0,
                   doc="weight of the current frame in the exponential blend (history 1 - alpha)"),
    "clipping": Param("variance", choices=("variance", "minmax", "none"),
                      doc="history rectification: Salvi's variance box, the 3x3 min/max box, or none"),
    "gamma": Param(1.0, min=0.0, min_exclusive=True, max=10.0,
                   doc="half-width of the variance box in standard deviations"),
    "luminance_weighting": Param(True, doc="blend colours compressed by 1 / (1 + luma) (Karis 2014)"),
    "reconstruct": Param(True, doc="Blackman-Harris reconstruction of the current colour from 3x3 jittered samples"),
    "history_filter": Param("catmull_rom", choices=("catmull_rom", "bilinear"), doc="history fetch"),
    "dilate_motion": Param(True, doc="motion of the closest depth in 3x3"),
    "depth_tolerance": Param(0.1, min=0.0, max=1e30, doc="relative depth change accepted as the same surface"),
}

_CLIP = {"none": K.CLIP_NONE, "minmax": K.CLIP_MINMAX, "variance": K.CLIP_VARIANCE}
_FETCH = {"bilinear": K.FETCH_BILINEAR, "catmull_rom": K.FETCH_CATMULL_ROM}


def resolve_settings(params: dict) -> dict:
    """Validated parameters (defaults filled in) with the kernel's codes for the string choices.

    Raises ``TypeError`` for an unknown name and ``ValueError`` for a value out of its declaration.
    """
    unknown = sorted(set(params) - set(DECLARED))
    if unknown:
        raise TypeError(f"taa: unknown parameter(s) {unknown}; known: {sorted(DECLARED)}")
    values = {name: p.default for name, p in DECLARED.items()}
    values.update({k: DECLARED[k].check(v, owner=f"taa: parameter {k!r}") for k, v in params.items()})
    return {
        "alpha": float(values["alpha"]),
        "gamma": float(values["gamma"]),
        "clip_mode": _CLIP[values["clipping"]],
        "weighted": bool(values["luminance_weighting"]),
        "reconstruct": bool(values["reconstruct"]),
        "fetch": _FETCH[values["history_filter"]],
        "dilate": bool(values["dilate_motion"]),
        "depth_tolerance": float(values["depth_tolerance"]),
    }
