"""TAA on the GPU (``numba.cuda``): :func:`.kernels.resolve_px` as a device function, a thread a pixel.

The history stays on the device between frames. Runs under Numba's CUDA simulator
(``NUMBA_ENABLE_CUDASIM=1``) for tests.
"""

from __future__ import annotations

import numpy as np
from numba import cuda

from . import kernels as K

_resolve_px = cuda.jit(device=True)(K.resolve_px)
BLOCK = (16, 16)


@cuda.jit
def _resolve(color, depth, object_id, motion, jx, jy, hist, hist_depth, hist_id, has_history, alpha, gamma,
             clip_mode, weighted, reconstruct, fetch, dilate, depth_tolerance, out):
    j, i = cuda.grid(2)
    if i < color.shape[0] and j < color.shape[1]:
        _resolve_px(i, j, color, depth, object_id, motion, jx, jy, hist, hist_depth, hist_id, has_history,
                    alpha, gamma, clip_mode, weighted, reconstruct, fetch, dilate, depth_tolerance, out)


class History:
    """The previous output and the previous frame's depth and object ids, on the device.

    A deep copy copies the device arrays (the harness deep-copies temporal filters).
    """

    def __init__(self, color, depth, object_id):
        self.color, self.depth, self.object_id = color, depth, object_id

    @property
    def shape(self) -> tuple[int, int]:
        return tuple(self.depth.shape)

    def __deepcopy__(self, memo):
        return History(*(cuda.to_device(a.copy_to_host()) for a in (self.color, self.depth, self.object_id)))


def resolve(color, depth, object_id, motion, jitter, history: History | None, settings: dict):
    """One TAA frame on the GPU; the same contract as :func:`.cpu.resolve`."""
    h, w = depth.shape
    d_color, d_depth, d_id, d_motion = (cuda.to_device(np.ascontiguousarray(a))
                                        for a in (color, depth, object_id, motion))
    d_out = cuda.device_array((h, w, 3), np.float32)
    has = history is not None
    hist = history if has else History(d_out, d_depth, d_id)  # never read without history
    grid = ((w + BLOCK[0] - 1) // BLOCK[0], (h + BLOCK[1] - 1) // BLOCK[1])
    _resolve[grid, BLOCK](d_color, d_depth, d_id, d_motion, float(jitter[0]), float(jitter[1]), hist.color,
                          hist.depth, hist.object_id, has, settings["alpha"], settings["gamma"],
                          settings["clip_mode"], settings["weighted"], settings["reconstruct"], settings["fetch"],
                          settings["dilate"], settings["depth_tolerance"], d_out)
    out = d_out.copy_to_host()
    cuda.synchronize()
    return out, History(d_out, d_depth, d_id)
