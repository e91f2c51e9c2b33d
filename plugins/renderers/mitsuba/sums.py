"""Per-pixel float64 sums of a frame's samples, and the lanes (pixel, sample index) they are taken in."""

from __future__ import annotations

import numpy as np


class PixelSums:
    """Running float64 sums of a frame's samples (and of an independent set for the variance)."""

    def __init__(self, n: int):
        self.acc = np.zeros((n, 3))
        self.acc_sq = np.zeros((n, 3))
        self.spp = np.zeros(n, np.int64)
        self.spread: np.ndarray | None = None  # per-sample variance from the independent set

    def add(self, pixels: np.ndarray, values: np.ndarray, squares: bool) -> None:
        n = self.spp.shape[0]
        values = values.astype(np.float64)
        for c in range(3):
            self.acc[:, c] += np.bincount(pixels, weights=values[:, c], minlength=n)
            if squares:
                self.acc_sq[:, c] += np.bincount(pixels, weights=values[:, c] * values[:, c], minlength=n)


def lane_batches(start: np.ndarray, counts: np.ndarray, max_lanes: int):
    """Lanes (pixels, sample indices) taking ``counts[p]`` samples from ``start[p]`` on, in batches.

    Lanes go sample slot by sample slot (slot ``j`` holds every pixel with ``counts > j``, row
    order), so neighbouring lanes are neighbouring pixels; at most ``max_lanes`` per batch.
    """
    counts = np.asarray(counts, np.int64)
    n = counts.shape[0]
    everyone = np.arange(n, dtype=np.int64)
    order = np.argsort(-counts, kind="stable")
    ascending = -counts[order]
    pixels, samples, size = [], [], 0
    for j in range(int(counts.max(initial=0))):
        taking = int(np.searchsorted(ascending, -j, side="left"))  # pixels with counts > j
        slot = everyone if taking == n else np.sort(order[:taking])
        for lo in range(0, slot.shape[0], max_lanes):
            part = slot[lo:lo + max_lanes]
            if size + part.shape[0] > max_lanes and size:
                yield np.concatenate(pixels), np.concatenate(samples)
                pixels, samples, size = [], [], 0
            pixels.append(part)
            samples.append(start[part] + j)
            size += part.shape[0]
    if size:
        yield np.concatenate(pixels), np.concatenate(samples)
