"""The ``sbf`` filter: SURE-based selection among cross-bilateral candidates (Li et al. 2012).

Modules: :mod:`.params` (parameters), :mod:`.features` (guide features), :mod:`.variance`
(where the noise variance is unknown), :mod:`.bank` (candidate filters, their divergence and
SURE), :mod:`.pipeline` (one pass: bank, SURE smoothing, argmin), :mod:`.adaptive` (sample
budget allocation), :mod:`.filter` (the filter object), :mod:`.cpu` / :mod:`.cuda` (kernels).
Degraded modes: without ``variance`` every pixel's variance is estimated spatially (as
``variance_source="spatial"``), without ``depth`` the depth feature is constant. See README.md
beside this file.
"""

from harness import FilterSpec, hookimpl

from .filter import SBFFilter
from .params import DECLARED, PAPER_SCALES

VERSION = "1.0"

PRESETS = {
    "paper": {
        "scales": PAPER_SCALES, "sigma_normal": 0.8, "sigma_albedo": 0.25, "sigma_depth": 0.6,
    },
    "adaptive": {"mode": "adaptive", "extra_spp": 8.0, "passes": 1},
    "small": {"scales": PAPER_SCALES[:7]},
}


@hookimpl
def register_filters():
    return [
        FilterSpec(
            name="sbf",
            version=VERSION,
            factory=SBFFilter,
            requires={"color", "normal", "albedo"},
            optional={"depth", "variance", "spp"},
            full_guides={"normal", "albedo", "depth", "variance"},
            temporal=False,
            backends=("cpu", "cuda"),
            params=DECLARED,
            stage_timing=True,
            adaptive=True,
            presets=PRESETS,
            description="SURE-based per-pixel selection among 9 cross-bilateral filters, "
                        "optional adaptive sampling (Li et al. 2012)",
        )
    ]
