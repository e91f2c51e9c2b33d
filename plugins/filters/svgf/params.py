"""Parameters of the ``svgf`` filter: the paper's defaults and the widely used variant.

Schied et al., "Spatiotemporal Variance-Guided Filtering: Real-Time Reconstruction for
Path-Traced Global Illumination", HPG 2017.
"""

from __future__ import annotations

import math
from dataclasses import dataclass, fields

from harness import Param

#: rows per task of the ``cpu`` backend's balanced loops (:func:`harness.kernels.take_range`;
#: 720 rows: 180 tasks)
TASK_ROWS = 4

#: The paper's values. Reprojection tolerances and epsilons are not given in the paper; the
#: values here are this implementation's choices (see README.md).
PAPER = {
    "separate_lighting": True,
    "iterations": 5,
    "feedback_iteration": 0,
    "alpha_color": 0.2,
    "alpha_moments": 0.2,
    "history_average": False,
    "max_history": 32.0,
    "variance_frames": 4.0,
    "sigma_z": 1.0,
    "sigma_n": 128.0,
    "sigma_l": 4.0,
    "albedo_epsilon": 0.1,
    "depth_tolerance": 0.05,
    "normal_tolerance": 0.9,
    "depth_epsilon": 1e-3,
    "luminance_epsilon": 1e-10,
}

#: The widely used variant (4 iterations, history from the 2nd, colour alpha 0.05, sigma_l 10,
#: blend max(alpha, 1/history_length) with history capped at 32, demodulation floor 0.001).
FALCOR = {
    "iterations": 4,
    "feedback_iteration": 1,
    "alpha_color": 0.05,
    "alpha_moments": 0.2,
    "history_average": True,
    "max_history": 32.0,
    "sigma_l": 10.0,
    "albedo_epsilon": 1e-3,
}

PRESETS = {"paper": dict(PAPER), "falcor": {**PAPER, **FALCOR}}

_RANGES = {
    "iterations": {"min": 0, "max": 10},
    "feedback_iteration": {"min": -1, "max": 9},
    "alpha_color": {"min": 0, "min_exclusive": True, "max": 1},
    "alpha_moments": {"min": 0, "min_exclusive": True, "max": 1},
    "max_history": {"min": 1, "max": 1e30},
    "variance_frames": {"min": 0, "max": 1e30},
    "sigma_z": {"min": 0, "max": 1e30},
    "sigma_n": {"min": 0, "max": 1e30},
    "sigma_l": {"min": 0, "max": 1e30},
    "albedo_epsilon": {"min": 0, "min_exclusive": True, "max": 1e30},
    "depth_epsilon": {"min": 0, "min_exclusive": True, "max": 1e30},
    "luminance_epsilon": {"min": 0, "min_exclusive": True, "max": 1e30},
    "depth_tolerance": {"min": 0, "max": 1e30},
    "normal_tolerance": {"min": -1, "max": 1},
}

#: the declarations in the FilterSpec (types and ranges, checked before a run; the cross-parameter
#: rule ``feedback_iteration < iterations`` is checked when the filter is built)
DECLARED = {name: Param(value, **_RANGES.get(name, {})) for name, value in PAPER.items()}


@dataclass(frozen=True)
class SVGFParams:
    """Validated parameters of :class:`plugins.filters.svgf.pipeline.SVGF`.

    Attributes
    ----------
    separate_lighting : bool
        Filter ``direct`` and ``indirect`` as two signals when the frame has them (the paper);
        False filters ``color`` as one signal (about half the à-trous work).
    iterations : int
        Number of à-trous iterations (step sizes 1, 2, 4, ...).
    feedback_iteration : int
        Index of the à-trous iteration whose output becomes the colour history; ``-1`` feeds
        back the temporally accumulated colour (before any spatial filtering).
    alpha_color, alpha_moments : float
        Weights of the current frame in the exponential moving averages, in (0, 1].
    history_average : bool
        Blend with ``max(alpha, 1 / history_length)`` (a plain mean while history is short).
    max_history : float
        Cap of the history length counter, >= 1.
    variance_frames : float
        Below this history length the variance is estimated spatially (7x7).
    sigma_z, sigma_n, sigma_l : float
        Edge-stopping parameters of depth, normal and luminance.
    albedo_epsilon : float
        Demodulation divides by ``max(albedo, albedo_epsilon)`` (the paper gives no floor; 0.1 bounds
        what a highlight on a near-black texel, which the albedo does not explain, brings to its
        neighbours: at most ``1 / albedo_epsilon`` times its colour; see the README).
    depth_tolerance : float
        Relative depth difference allowed between a pixel and a reprojected tap.
    normal_tolerance : float
        Smallest dot product of normals allowed between a pixel and a reprojected tap.
    depth_epsilon : float
        Relative epsilon of the depth weight's denominator (times the pixel's depth).
    luminance_epsilon : float
        Epsilon of the luminance weight's denominator.
    """

    separate_lighting: bool = PAPER["separate_lighting"]
    iterations: int = PAPER["iterations"]
    feedback_iteration: int = PAPER["feedback_iteration"]
    alpha_color: float = PAPER["alpha_color"]
    alpha_moments: float = PAPER["alpha_moments"]
    history_average: bool = PAPER["history_average"]
    max_history: float = PAPER["max_history"]
    variance_frames: float = PAPER["variance_frames"]
    sigma_z: float = PAPER["sigma_z"]
    sigma_n: float = PAPER["sigma_n"]
    sigma_l: float = PAPER["sigma_l"]
    albedo_epsilon: float = PAPER["albedo_epsilon"]
    depth_tolerance: float = PAPER["depth_tolerance"]
    normal_tolerance: float = PAPER["normal_tolerance"]
    depth_epsilon: float = PAPER["depth_epsilon"]
    luminance_epsilon: float = PAPER["luminance_epsilon"]

    @classmethod
    def from_kwargs(cls, **kwargs) -> SVGFParams:
        """Build and validate; an unknown name raises ``TypeError`` naming it."""
        known = {f.name for f in fields(cls)}
        unknown = sorted(set(kwargs) - known)
        if unknown:
            raise TypeError(f"svgf: unknown parameter(s) {unknown}; known: {sorted(known)}")
        params = cls(**kwargs)
        params.validate()
        return params

    def validate(self) -> None:
        """Raise ``ValueError`` naming the first parameter out of range."""
        def bad(name, why):
            raise ValueError(f"svgf: parameter {name}={getattr(self, name)!r} {why}")

        for name in ("history_average", "separate_lighting"):
            if not isinstance(getattr(self, name), bool):
                bad(name, "must be True or False")
        for name in ("iterations", "feedback_iteration"):
            if isinstance(getattr(self, name), bool) or int(getattr(self, name)) != getattr(self, name):
                bad(name, "must be an integer")
        if not 0 <= self.iterations <= 10:
            bad("iterations", "must be in [0, 10]")
        if self.feedback_iteration != -1 and not 0 <= self.feedback_iteration < self.iterations:
            bad("feedback_iteration", f"must be -1 or in [0, iterations={self.iterations})")
        for name in fields(self):
            value = getattr(self, name.name)
            if name.name in ("iterations", "feedback_iteration", "history_average", "separate_lighting"):
                continue
            if not isinstance(value, (int, float)) or isinstance(value, bool) or not math.isfinite(value):
                bad(name.name, "must be a finite number")
        for name in ("alpha_color", "alpha_moments"):
            if not 0.0 < getattr(self, name) <= 1.0:
                bad(name, "must be in (0, 1]")
        if self.max_history < 1.0:
            bad("max_history", "must be >= 1")
        for name in ("variance_frames", "sigma_z", "sigma_n", "sigma_l"):
            if getattr(self, name) < 0.0:
                bad(name, "must be >= 0")
        for name in ("albedo_epsilon", "depth_epsilon", "luminance_epsilon"):
            if getattr(self, name) <= 0.0:
                bad(name, "must be > 0")
        if self.depth_tolerance < 0.0:
            bad("depth_tolerance", "must be >= 0")
        if not -1.0 <= self.normal_tolerance <= 1.0:
            bad("normal_tolerance", "must be in [-1, 1]")
