"""Counter-based random numbers: a stateless hash of (seed, frame, pixel, sample, dimension).

Every random number of a path is a pure function of its coordinates, so a render does not
depend on the thread count or on the order in which pixels are processed, and the samples
``[8, 16)`` of a pixel are the same whether they are taken in one call or in a later one.
The mixing function is the 64-bit finaliser of SplitMix64 (Steele, Lea, Flood, OOPSLA 2014).
"""

from __future__ import annotations

import numpy as np
from numba import njit

_GOLDEN = np.uint64(0x9E3779B97F4A7C15)
_M1 = np.uint64(0xBF58476D1CE4E5B9)
_M2 = np.uint64(0x94D049BB133111EB)
_S30 = np.uint64(30)
_S27 = np.uint64(27)
_S31 = np.uint64(31)
_S40 = np.uint64(40)
_INV24 = 1.0 / 16777216.0


@njit(cache=True, error_model="numpy")
def mix64(x):
    """SplitMix64 finaliser: a bijective avalanche mix of a uint64."""
    x = np.uint64(x)
    x = (x ^ (x >> _S30)) * _M1
    x = (x ^ (x >> _S27)) * _M2
    return x ^ (x >> _S31)


@njit(cache=True, error_model="numpy")
def stream_key(seed, frame, pixel, sample):
    """The key of one sample's random stream.

    Parameters
    ----------
    seed, frame, pixel, sample : int
        Non-negative integers; ``pixel`` is the row-major pixel index.

    Returns
    -------
    numpy.uint64
    """
    k = mix64(np.uint64(seed) + _GOLDEN)
    k = mix64(k ^ (np.uint64(frame) * _GOLDEN))
    k = mix64(k ^ (np.uint64(pixel) * _M1))
    return mix64(k ^ (np.uint64(sample) * _M2))


@njit(cache=True, error_model="numpy")
def uniform(key, dim):
    """The ``dim``-th uniform number in [0, 1) of the stream ``key`` (24 bits of resolution)."""
    x = mix64(key ^ (np.uint64(dim) * _GOLDEN + _M2))
    return float(x >> _S40) * _INV24
