"""Counter-based random numbers: a value depends only on (seed, frame, pixel, sample, stream)."""

from __future__ import annotations

import numpy as np

_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)


def _mix(x: np.ndarray) -> np.ndarray:
    """The splitmix64 finaliser, elementwise on uint64 (wrapping arithmetic)."""
    x = x ^ (x >> np.uint64(30))
    x = x * _M1
    x = x ^ (x >> np.uint64(27))
    x = x * _M2
    return x ^ (x >> np.uint64(31))


def uniform(seed: int, frame: int, pixel: np.ndarray, sample: int, stream: int) -> np.ndarray:
    """Uniform numbers in (0, 1), float64, one per entry of ``pixel`` (flat pixel indices)."""
    with np.errstate(over="ignore"):
        key = _mix(np.uint64(seed & 0xFFFFFFFF) * np.uint64(0x9E3779B97F4A7C15) + np.uint64(frame))
        key = _mix(key ^ (np.uint64(sample) << np.uint64(8)) ^ np.uint64(stream))
        x = _mix(pixel.astype(np.uint64) ^ key)
    return ((x >> np.uint64(11)).astype(np.float64) + 0.5) / float(1 << 53)
