"""The candidate filter bank: spatial tables of the cross-bilateral filters and their SURE.

Candidate ``k`` with spatial scale ``s_k`` computes, for pixel ``i`` and window ``|dx|, |dy| <=
round(2 s_k)``,

    w_ij = exp(-d_ij^2 / (2 s_k^2)) * exp(-|f_i - f_j|^2),    F_i = sum_j w_ij y_j / W_i,

with the pre-scaled guide features ``f`` of :mod:`.features` and ``W_i = sum_j w_ij`` (the
centre weight is 1). The weights do not depend on the colour ``y``, so the divergence of the
filter is ``dF_i / dy_i = w_ii / W_i = 1 / W_i`` and Stein's unbiased risk estimate per channel is

    SURE_i = (F_i - y_i)^2 + 2 sigma_i^2 / W_i - sigma_i^2,

``sigma_i^2`` the variance of the pixel mean; it is averaged over RGB. Its expectation is the
expected squared error of ``F_i`` for any noise that is independent between pixels and has
variance ``sigma_i^2``. The feature factor does not depend on ``s_k``: the kernels evaluate it
once per tap of the largest window and add the tap to every candidate whose window holds it.
"""

from __future__ import annotations

import numpy as np


def window_radius(scale: float) -> int:
    """Window radius ``round(2 s)`` in pixels (halves round up)."""
    return int(np.floor(2.0 * scale + 0.5))


def spatial_table(scales) -> tuple[np.ndarray, np.ndarray]:
    """Spatial weights of every candidate and the first candidate reaching each ring.

    Parameters
    ----------
    scales : sequence of float
        Increasing spatial standard deviations in pixels; 0 is the identity.

    Returns
    -------
    table : ndarray (K, 2R+1, 2R+1) float64
        ``exp(-(dx^2 + dy^2) / (2 s_k^2))`` inside candidate k's window, 0 outside;
        ``R`` is the largest window radius.
    first : ndarray (R+1,) int64
        ``first[m]``: index of the first candidate whose window holds the ring
        ``max(|dx|, |dy|) = m`` (radii increase with ``k``).
    """
    radii = [window_radius(s) for s in scales]
    big = max(radii)
    d = np.arange(-big, big + 1, dtype=np.float64)
    dist2 = d[:, None] ** 2 + d[None, :] ** 2
    ring = np.maximum(np.abs(d)[:, None], np.abs(d)[None, :])
    table = np.zeros((len(scales), 2 * big + 1, 2 * big + 1))
    for k, (s, r) in enumerate(zip(scales, radii, strict=True)):
        if s > 0:
            table[k] = np.where(ring <= r, np.exp(-dist2 / (2.0 * s * s)), 0.0)
        else:
            table[k, big, big] = 1.0
    first = [next(k for k, r in enumerate(radii) if r >= m) for m in range(big + 1)]
    return table, np.array(first, np.int64)


def smoothing_table(scale: float) -> np.ndarray:
    """Spatial weights (2r+1, 2r+1) float64 of the SURE-smoothing filter, ``r = round(2 s)``."""
    table, _ = spatial_table((scale,))
    return table[0]
