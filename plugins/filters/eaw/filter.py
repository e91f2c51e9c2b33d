"""The EAW filter object: per-frame preparation shared by the backends, then the backend's passes.

Dammertz, Sewtz, Hanika, Lensch, "Edge-Avoiding À-Trous Wavelet Transform for fast Global
Illumination Filtering", HPG 2010.
"""

from __future__ import annotations

import numpy as np

from harness import kernels, load_backend, pinhole_position

from .layout import Buffers
from .params import EAWParams, b3_kernel

#: the backends, each a module of this package with ``run(frame, params, coefficients, taps, buffers)``
BACKENDS = ("cpu", "cuda")


def position_stand_in(frame) -> np.ndarray:
    """What the position stop reads where the frame has no ``position``: the albedo (an albedo
    edge stop, normalised like positions), else a pinhole position from ``depth`` (or from the
    pixel grid at unit depth: then only the spatial extent of the à-trous kernel)."""
    if "albedo" in frame:
        albedo = np.nan_to_num(np.asarray(frame["albedo"], np.float32), nan=0.0, posinf=0.0, neginf=0.0)
        return np.ascontiguousarray(albedo)
    return pinhole_position(frame.shape, frame["depth"] if "depth" in frame else None)


class EAWFilter:
    """Edge-avoiding à-trous wavelet filter (spatial, stateless).

    Parameters
    ----------
    backend : {"cpu", "cuda"}
    **params
        See :class:`.params.EAWParams`.

    Notes
    -----
    ``filter(frame)`` returns the filtered colour (H, W, 3) float32; ``stage_ms`` holds the
    milliseconds of the last call's stages: ``prepare`` (pixel classes, colour and position
    scales, padded planar buffers), ``atrous`` (all iterations, the last one writing the output
    on the CPU), and for ``cuda`` ``unpack``. The buffers are kept between frames of one size.
    """

    def __init__(self, backend: str = "cpu", **params):
        self.params = EAWParams.from_kwargs(**params)
        self.backend = backend
        self._kernels = load_backend(__package__, backend, BACKENDS, owner="eaw")
        self._coefficients = self.params.coefficients()
        self._taps = b3_kernel()
        self._buffers = None
        self.stage_ms: dict[str, float] = {}

    def reset(self) -> None:
        """Nothing to forget: the filter keeps no history (buffers are only scratch space)."""

    def __call__(self, frame, sampler=None):
        # below kernels.SERIAL_MAX_PIXELS the CPU backend runs on one thread (see the README)
        if "position" not in frame:
            frame = frame.replace(position=position_stand_in(frame))
        with kernels.serial_below(frame.height * frame.width, enabled=self.backend == "cpu"):
            h, w, halo = frame.height, frame.width, self.params.halo()
            if self._buffers is None or not self._buffers.fits(h, w, halo):
                self._buffers = Buffers(h, w, halo)
            out, self.stage_ms = self._kernels.run(frame, self.params, self._coefficients, self._taps,
                                                   self._buffers)
            return out
