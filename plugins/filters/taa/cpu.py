"""TAA on the CPU: :func:`.kernels.resolve_px` compiled by Numba, rows in parallel."""

from __future__ import annotations

import numpy as np
from numba import njit, prange

from . import kernels as K

_resolve_px = njit(cache=True)(K.resolve_px)


@njit(cache=True, parallel=True)
def _resolve(color, depth, object_id, motion, jx, jy, hist, hist_depth, hist_id, has_history, alpha, gamma,
             clip_mode, weighted, reconstruct, fetch, dilate, depth_tolerance, out):
    for row in prange(color.shape[0]):
        i = np.int64(row)  # prange's index may be unsigned; the body mixes it with signed offsets
        for j in range(color.shape[1]):
            _resolve_px(i, j, color, depth, object_id, motion, jx, jy, hist, hist_depth, hist_id, has_history,
                        alpha, gamma, clip_mode, weighted, reconstruct, fetch, dilate, depth_tolerance, out)


class History:
    """The previous output and the previous frame's depth and object ids (host arrays)."""

    def __init__(self, color: np.ndarray, depth: np.ndarray, object_id: np.ndarray):
        self.color, self.depth, self.object_id = color, depth, object_id

    @property
    def shape(self) -> tuple[int, int]:
        return self.depth.shape


def resolve(color, depth, object_id, motion, jitter, history: History | None, settings: dict):
    """One TAA frame.

    Parameters
    ----------
    color, depth, object_id, motion : ndarray
        The frame's channels (float32, float32, int32, float32).
    jitter : (float, float)
        The frame's sub-pixel jitter in pixels.
    history : History or None
        The state of the previous frame (None: no history).
    settings : dict
        :func:`.params.resolve_settings`.

    Returns
    -------
    out : ndarray (H, W, 3) float32
    history : History
        The state for the next frame.
    """
    out = np.empty(color.shape, np.float32)
    has = history is not None
    hist = history if has else History(out, depth, object_id)  # never read without history
    _resolve(color, depth, object_id, motion, float(jitter[0]), float(jitter[1]), hist.color, hist.depth,
             hist.object_id, has, settings["alpha"], settings["gamma"], settings["clip_mode"], settings["weighted"],
             settings["reconstruct"], settings["fetch"], settings["dilate"], settings["depth_tolerance"], out)
    return out, History(out.copy(), depth.copy(), object_id.copy())
