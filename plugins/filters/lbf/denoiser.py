"""The LBF filter object: features -> network -> cross-bilateral filter."""

from __future__ import annotations

import time

import numpy as np

from .features import extract_features, gather_inputs
from .filter_cpu import cross_bilateral
from .mlp import predict_bandwidths
from .weights import load_weights

BACKENDS = ("cpu", "cuda")


class LBFFilter:
    """Learned bilateral filter (Kalantari, Bako and Sen 2015), real-time variant.

    Parameters
    ----------
    backend : {"cpu", "cuda"}
        ``cpu``: Numba; ``cuda``: ``numba.cuda`` kernels (the simulator with
        ``NUMBA_ENABLE_CUDASIM=1``).
    radius : int
        Filter window radius in pixels (window ``2 radius + 1`` square). The shipped weights were
        trained with radius 5.
    weights : str, optional
        Path of a weights file; None uses the shipped ``weights/lbf_v1.npz``.
    visibility : {"auto", "standin"}
        Where the visibility feature comes from (see :func:`.features.gather_inputs`).

    Notes
    -----
    After each call ``stage_ms`` holds the milliseconds of the ``features``, ``network`` and
    ``bilateral`` (filter) stages; the ``cuda`` backend adds ``upload`` and ``download``.
    """

    def __init__(self, backend: str = "cpu", radius: int = 5, weights: str | None = None,
                 visibility: str = "auto"):
        if backend not in BACKENDS:
            raise ValueError(f"lbf: unsupported backend {backend!r}; choose from {BACKENDS}")
        integer = isinstance(radius, (int, np.integer)) and not isinstance(radius, bool)
        if not integer or not 0 <= radius <= 64:
            raise ValueError(f"lbf: radius must be an integer in [0, 64], got {radius!r}")
        if visibility not in ("auto", "standin"):
            raise ValueError(f"lbf: visibility must be 'auto' or 'standin', got {visibility!r}")
        self.backend = backend
        self.radius = int(radius)
        self.visibility = visibility
        self.model = load_weights(weights)
        self.stage_ms: dict[str, float] = {}
        self._work: dict = {}
        self._cuda = None
        if backend == "cuda":
            from .cuda import CudaLBF

            self._cuda = CudaLBF(self.model)

    def reset(self) -> None:
        """LBF keeps no history."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        inputs = gather_inputs(frame, self.visibility)
        if self._cuda is not None:
            out, self.stage_ms = self._cuda.run(inputs, self.radius)
            return out
        t0 = time.perf_counter_ns()
        variance, sig, feat = extract_features(inputs, self._work)
        t1 = time.perf_counter_ns()
        params = predict_bandwidths(feat, self.model)
        t2 = time.perf_counter_ns()
        out = cross_bilateral(inputs.color, variance, sig, params, self.radius)
        t3 = time.perf_counter_ns()
        self.stage_ms = {
            "features": (t1 - t0) / 1e6,
            "network": (t2 - t1) / 1e6,
            "bilateral": (t3 - t2) / 1e6,
        }
        return out
