"""The LBF filter object: features -> network -> cross-bilateral filter, on the chosen backend."""

from __future__ import annotations

import numpy as np

from harness import load_backend

from .features import gather_inputs
from .weights import load_weights

BACKENDS = ("cpu", "cuda")


class LBFFilter:
    """Learned bilateral filter (Kalantari, Bako and Sen 2015), real-time variant.

    Parameters
    ----------
    backend : {"cpu", "cuda"}
        ``cpu``: Numba (:mod:`.cpu`); ``cuda``: ``numba.cuda`` kernels (:mod:`.cuda`; the
        simulator with ``NUMBA_ENABLE_CUDASIM=1``). Both modules expose a ``Denoiser``.
    radius : int
        Filter window radius in pixels (window ``2 radius + 1`` square). The shipped weights were
        trained with radius 5.
    weights : str, optional
        Path of a weights file; None uses the shipped ``weights/lbf_v2.npz``.
    visibility : {"auto", "standin"}
        Where the visibility feature comes from (see :func:`.features.gather_inputs`).

    Notes
    -----
    After each call ``stage_ms`` holds the milliseconds of the ``signals``, ``network`` and
    ``bilateral`` (filter) stages; the ``cuda`` backend adds ``upload`` and ``download``.
    """

    def __init__(self, backend: str = "cpu", radius: int = 5, weights: str | None = None,
                 visibility: str = "auto"):
        kernels = load_backend(__package__, backend, BACKENDS, owner="lbf")
        integer = isinstance(radius, (int, np.integer)) and not isinstance(radius, bool)
        if not integer or not 0 <= radius <= 64:
            raise ValueError(f"lbf: radius must be an integer in [0, 64], got {radius!r}")
        if visibility not in ("auto", "standin"):
            raise ValueError(f"lbf: visibility must be 'auto' or 'standin', got {visibility!r}")
        self.backend = backend
        self.radius = int(radius)
        self.visibility = visibility
        self.model = load_weights(weights)
        self.denoiser = kernels.Denoiser(self.model)
        self.stage_ms: dict[str, float] = {}

    def reset(self) -> None:
        """LBF keeps no history."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        out, self.stage_ms = self.denoiser(gather_inputs(frame, self.visibility), self.radius)
        return out
