"""Parameters of the SBF filter, their paper defaults and their validation."""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from harness import Param

#: Candidate spatial scales (pixels) of Li, Wu & Chuang (2012); 0 is the identity filter.
PAPER_SCALES = (0.0, 0.7071, 1.0, 1.4142, 2.0, 2.8284, 4.0, 5.6569, 8.0)

MODES = ("fixed", "adaptive")
VARIANCE_SOURCES = ("auto", "given", "spatial")


@dataclass(frozen=True)
class SBFParams:
    """Validated parameters of :class:`plugins.filters.sbf.filter.SBFFilter`.

    Parameters
    ----------
    mode : {"fixed", "adaptive"}
        ``fixed`` filters the frame it is given (equal-sample comparisons); ``adaptive`` spends
        ``extra_spp`` more samples per pixel on average through the renderer's sampler.
    scales : tuple of float
        Spatial standard deviations (pixels) of the candidate filters; 0 is the identity. The
        window radius of scale ``s`` is ``round(2 s)``.
    sigma_normal, sigma_albedo, sigma_depth : float
        Feature bandwidths of the cross-bilateral weights (depth is divided by the scene's
        maximum depth first).
    feature_var_floor : float
        Lower bound of ``var_i + var_j`` in the feature term. The G-buffer features are
        noise-free, so the bound is the whole denominator (paper: 0.01).
    sure_scale : float
        Spatial standard deviation (pixels) of the feature-only cross-bilateral filter that
        smooths the SURE maps before the per-pixel argmin; 0 disables smoothing.
    extra_spp : float
        Adaptive mode: average extra samples per pixel, all passes together.
    passes : int
        Adaptive mode: number of sample-allocation passes.
    max_spp_per_pixel : int
        Adaptive mode: cap of the total samples of one pixel (0 = no cap).
    variance_source : {"auto", "given", "spatial"}
        Where the noise variance of the pixel mean comes from (:mod:`.variance`): ``auto`` uses
        the ``variance`` channel and estimates it spatially only where it is unknown (pixels
        with fewer than 2 samples); ``given`` always trusts the channel; ``spatial`` always
        estimates.
    variance_radius : int
        Radius (pixels) of the window of the spatial variance estimate (3: 7x7).
    """

    mode: str = "fixed"
    scales: tuple = PAPER_SCALES
    sigma_normal: float = 0.8
    sigma_albedo: float = 0.25
    sigma_depth: float = 0.6
    feature_var_floor: float = 0.01
    sure_scale: float = 4.0
    extra_spp: float = 8.0
    passes: int = 1
    max_spp_per_pixel: int = 64
    variance_source: str = "auto"
    variance_radius: int = 3

    def __post_init__(self):
        if self.mode not in MODES:
            raise ValueError(f"sbf: mode must be one of {MODES}, got {self.mode!r}")
        scales = tuple(float(s) for s in self.scales)
        if not scales or len(scales) > 16:
            raise ValueError(f"sbf: scales must hold 1 to 16 values, got {len(scales)}")
        if any(not math.isfinite(s) or s < 0 or s > 32 for s in scales):
            raise ValueError(f"sbf: scales must be finite numbers in [0, 32], got {scales}")
        if sorted(scales) != list(scales) or len(set(scales)) != len(scales):
            raise ValueError(f"sbf: scales must be strictly increasing, got {scales}")
        object.__setattr__(self, "scales", scales)
        for name in ("sigma_normal", "sigma_albedo", "sigma_depth", "feature_var_floor"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value <= 0:
                raise ValueError(f"sbf: {name} must be a finite number > 0, got {value!r}")
        for name in ("sure_scale", "extra_spp"):
            value = getattr(self, name)
            if not isinstance(value, (int, float)) or not math.isfinite(value) or value < 0:
                raise ValueError(f"sbf: {name} must be a finite number >= 0, got {value!r}")
        if self.sure_scale > 32:
            raise ValueError(f"sbf: sure_scale must be <= 32, got {self.sure_scale}")
        if self.variance_source not in VARIANCE_SOURCES:
            raise ValueError(
                f"sbf: variance_source must be one of {VARIANCE_SOURCES}, got {self.variance_source!r}"
            )
        for name, low in (("passes", 1), ("max_spp_per_pixel", 0), ("variance_radius", 1)):
            value = getattr(self, name)
            if not isinstance(value, int) or isinstance(value, bool) or value < low:
                raise ValueError(f"sbf: {name} must be an integer >= {low}, got {value!r}")


#: Parameter names and defaults.
DEFAULTS = {f.name: f.default for f in fields(SBFParams)}

_RANGES = {
    "mode": {"choices": MODES},
    "scales": {"min": 0, "max": 32},
    "sigma_normal": {"min": 0, "min_exclusive": True, "max": 1e30},
    "sigma_albedo": {"min": 0, "min_exclusive": True, "max": 1e30},
    "sigma_depth": {"min": 0, "min_exclusive": True, "max": 1e30},
    "feature_var_floor": {"min": 0, "min_exclusive": True, "max": 1e30},
    "sure_scale": {"min": 0, "max": 32},
    "extra_spp": {"min": 0, "max": 1e6},
    "passes": {"min": 1, "max": 64},
    "max_spp_per_pixel": {"min": 0},
    "variance_source": {"choices": VARIANCE_SOURCES},
    "variance_radius": {"min": 1, "max": 32},
}

#: The declarations in the FilterSpec (types and ranges, checked before a run; ``scales`` must
#: also be strictly increasing, which the filter checks when it is built).
DECLARED = {name: Param(value, **_RANGES.get(name, {})) for name, value in DEFAULTS.items()}
