"""The EAW filter object: per-frame preparation shared by the backends, then the backend's passes.

Dammertz, Sewtz, Hanika, Lensch, "Edge-Avoiding À-Trous Wavelet Transform for fast Global
Illumination Filtering", HPG 2010.
"""

from __future__ import annotations

import math
import time

import numpy as np
from numba import get_num_threads, set_num_threads

from harness import cuda_available

from . import cpu
from .params import EAWParams, b3_kernel

#: below this many pixels the CPU backend runs on one thread: waking the thread pool costs more
#: than it saves (milliseconds per parallel region on a loaded 2-core machine, see README)
SERIAL_MAX_PIXELS = 256 * 256

_DUMMY_IDS = np.zeros((1, 1), np.int32)
_DUMMY_DEPTH = np.zeros((1, 1), np.float32)
_DUMMY_VARIANCE = np.zeros((1, 1, 3), np.float32)


def frame_state(frame) -> np.ndarray:
    """Per-pixel class (background / still / active, see :mod:`.cpu`) of a frame, (H, W) int8."""
    state = np.empty((frame.height, frame.width), np.int8)
    has_ids, has_depth, has_var = "object_id" in frame, "depth" in frame, "variance" in frame
    cpu.classify(
        frame["normal"],
        frame["object_id"] if has_ids else _DUMMY_IDS,
        frame["depth"] if has_depth else _DUMMY_DEPTH,
        frame["variance"] if has_var else _DUMMY_VARIANCE,
        has_ids, has_depth, has_var, state,
    )
    return state


def frame_scales(color, position, state, params: EAWParams):
    """Colour scale, position origin and position unit of a frame.

    Returns
    -------
    scale : float
        Log-average luminance of the surface pixels with positive luminance (``logmean``), or 1.
    origin : ndarray (3,) float64
        Lower corner of the surfaces' bounding box (0 when there is no surface).
    pos_unit : float
        Diagonal of that box (``scene`` units) or 1 (``world``).
    """
    log_sum, count, lo, hi = cpu.surface_statistics(color, position, state)
    scale = 1.0
    if params.color_scale == "logmean" and count > 0:
        scale = math.exp(log_sum / count)
        if not (math.isfinite(scale) and scale > 0.0):
            scale = 1.0
    origin = lo if np.all(np.isfinite(lo)) else np.zeros(3)
    pos_unit = 1.0
    if params.position_units == "scene" and np.all(np.isfinite(lo)):
        diag = float(np.linalg.norm(hi - lo))
        if math.isfinite(diag) and diag > 0.0:
            pos_unit = diag
    return scale, np.ascontiguousarray(origin, dtype=np.float64), pos_unit


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
    milliseconds of the last call's stages: ``classify`` (pixel classes, colour and position
    scales), ``pack`` (padded planar buffers), ``atrous`` (all iterations, the last one writing
    the output), and for ``cuda`` ``unpack``.
    """

    def __init__(self, backend: str = "cpu", **params):
        self.params = EAWParams.from_kwargs(**params)
        if backend not in ("cpu", "cuda"):
            raise ValueError(f"eaw: unsupported backend {backend!r}; use 'cpu' or 'cuda'")
        if backend == "cuda" and not cuda_available():
            raise RuntimeError("eaw: backend 'cuda' needs a CUDA GPU or NUMBA_ENABLE_CUDASIM=1")
        self.backend = backend
        self._coefficients = self.params.coefficients()
        self._taps = b3_kernel()
        self._buffers = None
        self.stage_ms: dict[str, float] = {}

    def reset(self) -> None:
        """Nothing to forget: the filter keeps no history (buffers are only scratch space)."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        threads = get_num_threads()
        serial = self.backend == "cpu" and frame.height * frame.width < SERIAL_MAX_PIXELS and threads > 1
        if serial:
            set_num_threads(1)
        try:
            return self._filter(frame)
        finally:
            if serial:
                set_num_threads(threads)

    def _filter(self, frame) -> np.ndarray:
        t0 = time.perf_counter()
        color = np.ascontiguousarray(frame["color"], dtype=np.float32)
        normal = np.ascontiguousarray(frame["normal"], dtype=np.float32)
        position = np.ascontiguousarray(frame["position"], dtype=np.float32)
        state = frame_state(frame)
        scale, origin, pos_unit = frame_scales(color, position, state, self.params)
        t1 = time.perf_counter()
        if self.backend == "cpu":
            h, w = state.shape
            halo = self.params.halo()
            if self._buffers is None or not self._buffers.fits(h, w, halo):
                self._buffers = cpu.Buffers(h, w, halo)
            out, stages = cpu.run(color, normal, position, state, self._coefficients, self._taps,
                                  scale, origin, pos_unit, self._buffers)
        else:
            from . import cuda as cuda_backend

            out, stages = cuda_backend.run(color, normal, position, state, self._coefficients, self._taps,
                                           scale, origin, pos_unit, self.params.halo())
        self.stage_ms = {"classify": (t1 - t0) * 1e3, **stages}
        return out
