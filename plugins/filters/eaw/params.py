"""Parameters of the ``eaw`` filter: defaults, presets, validation, per-iteration coefficients."""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np

from harness import Param

#: parameter name -> default (see :data:`DECLARED` for types and ranges)
DEFAULTS = {
    "iterations": 5,
    "sigma_rt": 32.0,
    "sigma_n": 0.3,
    "sigma_x": 0.015,
    "sigma_rt_schedule": 0.5,
    "color_scale": "logmean",
    "position_units": "scene",
}

COLOR_SCALES = ("logmean", "none")
POSITION_UNITS = ("scene", "world")

#: the declarations in the FilterSpec: what ``--param`` accepts, checked before a run
DECLARED = {
    "iterations": Param(DEFAULTS["iterations"], min=1, max=10, doc="a-trous iterations (hole spacing 2**i)"),
    "sigma_rt": Param(DEFAULTS["sigma_rt"], min=0, min_exclusive=True, doc="colour sigma of iteration 0; inf disables"),
    "sigma_n": Param(DEFAULTS["sigma_n"], min=0, min_exclusive=True, doc="normal sigma; inf disables"),
    "sigma_x": Param(DEFAULTS["sigma_x"], min=0, min_exclusive=True, doc="position sigma; inf disables"),
    "sigma_rt_schedule": Param(DEFAULTS["sigma_rt_schedule"], type="any",
                               doc="factor per iteration (float r: r**i) or a list of factors"),
    "color_scale": Param(DEFAULTS["color_scale"], choices=COLOR_SCALES),
    "position_units": Param(DEFAULTS["position_units"], choices=POSITION_UNITS),
}

#: named parameter sets
PRESETS = {
    # as close to the paper's listing as the harness allows: raw colour, world-unit positions
    "paper": {"color_scale": "none", "position_units": "world", "sigma_rt_schedule": 0.5},
    # a lighter, faster variant
    "fast": {"iterations": 3},
}

#: the largest per-iteration coefficient 1/sigma^2 (keeps every product finite in float32)
COEF_MAX = 1e12

# B3-spline taps per axis
B3 = (1.0 / 16.0, 1.0 / 4.0, 3.0 / 8.0, 1.0 / 4.0, 1.0 / 16.0)


def b3_kernel() -> np.ndarray:
    """The 25 taps of the 5x5 B3-spline kernel, row-major, float32 (they sum to 1)."""
    b = np.asarray(B3, dtype=np.float64)
    return np.outer(b, b).ravel().astype(np.float32)


def _positive(name: str, value) -> float:
    try:
        value = float(value)
    except (TypeError, ValueError):
        raise ValueError(f"eaw: parameter {name!r} must be a number, got {value!r}") from None
    if not value > 0:  # also rejects NaN
        raise ValueError(f"eaw: parameter {name!r} must be > 0 (inf disables the term), got {value}")
    return value


def _coef(sigma: float) -> float:
    """1 / sigma^2, clamped to [0, COEF_MAX] (0 for an infinite sigma)."""
    return min(1.0 / (sigma * sigma), COEF_MAX) if math.isfinite(sigma) else 0.0


@dataclass(frozen=True)
class EAWParams:
    """Validated parameters of the EAW filter (see the plugin's README for their meaning).

    Parameters
    ----------
    iterations : int
        Number of à-trous iterations N (1..10); iteration i uses hole spacing 2**i pixels.
    sigma_rt : float
        Colour edge-stopping sigma of iteration 0 (in units of the colour scale, see
        ``color_scale``); ``inf`` switches the colour term off.
    sigma_n : float
        Normal edge-stopping sigma (unit normals); ``inf`` switches the term off.
    sigma_x : float
        Position edge-stopping sigma (in units of ``position_units``); ``inf`` switches it off.
    sigma_rt_schedule : float or sequence of float
        A float ``r`` gives ``sigma_rt_i = sigma_rt * r**i``; a sequence gives the factor of
        each iteration explicitly (its length must equal ``iterations``).
    color_scale : {"logmean", "none"}
        ``logmean`` measures colour differences relative to the log-average luminance of the
        frame's surfaces (the filter is then exposure invariant); ``none`` uses raw radiance as
        the paper does.
    position_units : {"scene", "world"}
        ``scene`` measures positions relative to the diagonal of the bounding box of the visible
        surfaces; ``world`` uses world units as the paper does.
    """

    iterations: int = DEFAULTS["iterations"]
    sigma_rt: float = DEFAULTS["sigma_rt"]
    sigma_n: float = DEFAULTS["sigma_n"]
    sigma_x: float = DEFAULTS["sigma_x"]
    sigma_rt_schedule: object = DEFAULTS["sigma_rt_schedule"]
    color_scale: str = DEFAULTS["color_scale"]
    position_units: str = DEFAULTS["position_units"]

    def __post_init__(self):
        it = self.iterations
        if isinstance(it, bool) or not isinstance(it, (int, np.integer)) or not 1 <= it <= 10:
            raise ValueError(f"eaw: parameter 'iterations' must be an integer in 1..10, got {it!r}")
        object.__setattr__(self, "iterations", int(it))
        for name in ("sigma_rt", "sigma_n", "sigma_x"):
            object.__setattr__(self, name, _positive(name, getattr(self, name)))
        sched = self.sigma_rt_schedule
        if isinstance(sched, (list, tuple, np.ndarray)):
            factors = tuple(_positive("sigma_rt_schedule", v) for v in sched)
            if len(factors) != self.iterations:
                raise ValueError(
                    f"eaw: parameter 'sigma_rt_schedule' lists {len(factors)} factors but "
                    f"'iterations' is {self.iterations}"
                )
            object.__setattr__(self, "sigma_rt_schedule", factors)
        else:
            object.__setattr__(self, "sigma_rt_schedule", _positive("sigma_rt_schedule", sched))
        if self.color_scale not in COLOR_SCALES:
            raise ValueError(f"eaw: parameter 'color_scale' must be one of {COLOR_SCALES}, got {self.color_scale!r}")
        if self.position_units not in POSITION_UNITS:
            raise ValueError(
                f"eaw: parameter 'position_units' must be one of {POSITION_UNITS}, got {self.position_units!r}"
            )

    @classmethod
    def from_kwargs(cls, **params) -> EAWParams:
        """Build from keyword arguments; an unknown name raises ``TypeError`` naming it."""
        unknown = sorted(set(params) - set(DEFAULTS))
        if unknown:
            raise TypeError(f"eaw: unknown parameter(s) {unknown}; known: {sorted(DEFAULTS)}")
        return cls(**params)

    def rt_factors(self) -> tuple[float, ...]:
        """The factor multiplying ``sigma_rt`` in each iteration."""
        if isinstance(self.sigma_rt_schedule, tuple):
            return self.sigma_rt_schedule
        return tuple(self.sigma_rt_schedule**i for i in range(self.iterations))

    def coefficients(self) -> np.ndarray:
        """Per-iteration weights of the squared distances, shape (iterations, 3) float32.

        Row ``i`` holds ``(1/sigma_rt_i^2, 1/(4**i sigma_n^2), 1/sigma_x^2)``: the exponent of
        the edge-stopping weight is ``-(a_c |dc|^2 + a_n |dn|^2 + a_x |dx|^2)``. The normal
        term is divided by the squared step width ``(2**i)^2`` as in the paper's listing.
        """
        rows = []
        for i, f in enumerate(self.rt_factors()):
            step = float(2**i)
            rows.append((_coef(self.sigma_rt * f), _coef(self.sigma_n * step), _coef(self.sigma_x)))
        return np.asarray(rows, dtype=np.float32)

    def halo(self) -> int:
        """Largest tap offset in pixels, ``2 * 2**(iterations-1)``."""
        return 2**self.iterations
