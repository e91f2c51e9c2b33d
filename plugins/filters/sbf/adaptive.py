"""Adaptive sampling of SBF: where to spend an exact extra sample budget."""

from __future__ import annotations

import numpy as np

#: added to luminance^2 in the sampling weight (relative error)
LUMINANCE_EPS = 1e-3
_LUMA = np.array([0.2126, 0.7152, 0.0722])


def sampling_weight(min_sure: np.ndarray, output: np.ndarray) -> np.ndarray:
    """``max(minSURE, 0) / (luminance(F)^2 + 1e-3)`` per pixel, float64 (H, W), finite.

    Parameters
    ----------
    min_sure : ndarray (H, W)
        Smoothed SURE of the selected candidate.
    output : ndarray (H, W, 3)
        The filtered image.
    """
    lum = output.astype(np.float64) @ _LUMA
    weight = np.maximum(min_sure, 0.0) / (lum * lum + LUMINANCE_EPS)
    return np.nan_to_num(weight, nan=0.0, posinf=np.finfo(np.float64).max)


def split_budget(total: int, parts: int) -> list[int]:
    """Split ``total`` samples over ``parts`` passes; the first ``total % parts`` get one more."""
    base, rest = divmod(int(total), int(parts))
    return [base + (1 if p < rest else 0) for p in range(parts)]


def allocate(weight: np.ndarray, budget: int, room: np.ndarray, minimum: int = 0) -> np.ndarray:
    """Integer samples per pixel in proportion to ``weight``, summing to ``budget`` exactly.

    Parameters
    ----------
    weight : ndarray (H, W)
        Non-negative sampling weights (negative and NaN count as 0). Where every pixel with room
        has weight 0, the budget is spread evenly.
    budget : int
        Samples to hand out.
    room : ndarray (H, W), integer
        Most samples each pixel may receive (0 excludes a pixel).
    minimum : int
        Samples every pixel with room gets first (up to its room), when the budget covers it.

    Returns
    -------
    ndarray (H, W) int64
        Sums to ``min(budget, room.sum())``, never exceeds ``room``.

    Notes
    -----
    The real-valued share ``budget_left * w_i / sum(w)`` is water-filled against ``room``
    (a pixel whose share exceeds its room gets its room and the rest is re-shared), then
    floored; the remaining samples go one each to the pixels with the largest fractional part,
    ties to the lower flat index, so the result is deterministic.
    """
    room = np.maximum(np.asarray(room, np.int64), 0).ravel()
    w = np.asarray(weight, np.float64).ravel()
    w = np.maximum(np.nan_to_num(w, nan=0.0, posinf=np.finfo(np.float64).max), 0.0)
    if w.size and w.max() > 0:
        w = w / w.max()  # keeps sums finite
    budget = int(min(max(int(budget), 0), room.sum()))
    give = np.zeros(room.size, np.int64)
    base = np.minimum(room, int(minimum))
    if minimum > 0 and base.sum() <= budget:
        give += base
    left = budget - int(give.sum())
    free = room - give
    share = np.zeros(room.size)
    open_ = free > 0
    remaining = float(left)
    while remaining > 0 and open_.any():
        ww = np.where(open_, w, 0.0)
        total = ww.sum()
        if not (total > 0 and np.isfinite(total)):
            ww = open_.astype(np.float64)
            total = ww.sum()
        part = remaining * (ww / total)
        over = open_ & (part >= free)
        if not over.any():
            share[open_] = part[open_]
            break
        share[over] = free[over]
        remaining -= float(free[over].sum())
        open_ &= ~over
    share = np.minimum(share, free)
    whole = np.floor(share).astype(np.int64)
    rest = left - int(whole.sum())
    frac = share - whole
    order = np.lexsort((np.arange(room.size), -frac))
    while rest > 0:
        has_room = whole[order] < free[order]
        take = order[has_room][:rest]
        if take.size == 0:
            break
        whole[take] += 1
        rest -= take.size
    give += whole
    return give.reshape(np.shape(weight))
