"""The TAA filter object: history across frames, camera cuts, backend dispatch."""

from __future__ import annotations

import numpy as np

from harness import load_backend

from .params import resolve_settings

BACKENDS = ("cpu", "cuda")


class TAA:
    """Temporal anti-aliasing (Karis 2014; Salvi 2016; Yang et al. 2020).

    Parameters
    ----------
    backend : {"cpu", "cuda"}
    **params
        See :data:`plugins.filters.taa.params.DECLARED`.

    Notes
    -----
    The history (previous output, depth and object ids) is dropped on :meth:`reset`, on a frame
    whose ``meta.camera_cut`` is set and when the image size changes; the first frame after
    that is the reconstructed current colour alone.
    """

    def __init__(self, backend: str = "cpu", **params):
        self.settings = resolve_settings(params)
        self.backend = backend
        self._ops = load_backend(__package__, backend, BACKENDS, owner="taa")
        self._history = None

    def reset(self) -> None:
        """Forget the history (new sequence or camera cut)."""
        self._history = None

    def __call__(self, frame, sampler=None) -> np.ndarray:
        """Anti-alias one frame of a sequence; returns (H, W, 3) float32."""
        if frame.meta.camera_cut or (self._history is not None and self._history.shape != frame.shape):
            self.reset()
        out, self._history = self._ops.resolve(
            frame["color"], frame["depth"], frame["object_id"], frame["motion"], frame.meta.jitter,
            self._history, self.settings)
        return out
