"""The report's pictures: displayed images, crops where filters disagree most, per-pixel error maps."""

from __future__ import annotations

from pathlib import Path

import numpy as np

from harness.images import encode_srgb, write_png

#: crops per scene
CROPS = 3
#: relMSE's regulariser (the same as the ``relmse`` metric's)
RELMSE_EPS = 0.01


def disagreement_crops(images: list[np.ndarray], count: int = CROPS, size: int | None = None) -> list[tuple]:
    """Square windows ``(top, left, size)`` where the displayed images differ most, not overlapping.

    The score of a window is the sum over its pixels of the standard deviation across
    ``images`` of the displayed values (mean over channels); windows are picked greedily.
    """
    if not images:
        return []
    stack = np.stack([encode_srgb(i).mean(axis=-1) for i in images])
    spread = stack.std(axis=0)
    h, w = spread.shape
    size = int(size or max(8, min(h, w) // 4))
    size = min(size, h, w)
    integral = np.pad(spread.cumsum(0).cumsum(1), ((1, 0), (1, 0)))
    sums = integral[size:, size:] - integral[:-size, size:] - integral[size:, :-size] + integral[:-size, :-size]
    picked = []
    taken = np.zeros_like(sums, dtype=bool)
    for _ in range(count):
        masked = np.where(taken, -np.inf, sums)
        if not np.isfinite(masked).any():
            break
        top, left = np.unravel_index(int(np.argmax(masked)), masked.shape)
        picked.append((int(top), int(left), size))
        taken[max(0, top - size + 1):top + size, max(0, left - size + 1):left + size] = True
    return picked


def crop(image: np.ndarray, window: tuple, scale: int = 4) -> np.ndarray:
    """The window of an image, enlarged ``scale`` times (nearest neighbour)."""
    top, left, size = window
    part = image[top:top + size, left:left + size]
    return np.repeat(np.repeat(part, scale, axis=0), scale, axis=1)


def outline(image: np.ndarray, windows: list[tuple]) -> np.ndarray:
    """A copy of a linear image with the windows framed in bright colours (for the overview)."""
    out = np.array(image, np.float32, copy=True)
    colours = [(4.0, 0.2, 0.2), (0.2, 4.0, 0.2), (0.2, 0.4, 4.0)]
    for k, (top, left, size) in enumerate(windows):
        c = colours[k % len(colours)]
        bottom, right = top + size - 1, left + size - 1
        out[top, left:right + 1] = c
        out[bottom, left:right + 1] = c
        out[top:bottom + 1, left] = c
        out[top:bottom + 1, right] = c
    return out


def relmse_map(output: np.ndarray, reference: np.ndarray) -> np.ndarray:
    """Per-pixel relMSE, ``(x - r)^2 / (r^2 + 0.01)`` averaged over channels."""
    x, r = np.asarray(output, np.float64), np.asarray(reference, np.float64)
    return ((x - r) ** 2 / (r * r + RELMSE_EPS)).mean(axis=-1)


def flip_map(output: np.ndarray, reference: np.ndarray) -> np.ndarray | None:
    """FLIP's per-pixel error map (magma colours, 8-bit-ready floats in [0, 1]), or None without flip-evaluator."""
    try:
        import flip_evaluator
    except ImportError:
        return None
    ref = np.ascontiguousarray(encode_srgb(reference), np.float32)
    out = np.ascontiguousarray(encode_srgb(output), np.float32)
    error_map, _, _ = flip_evaluator.evaluate(ref, out, "LDR", inputsRGB=True, applyMagma=True)
    return np.asarray(error_map, np.float32)


def write_display(path: Path, image: np.ndarray) -> Path:
    """A linear image as a displayed PNG (the harness's display mapping)."""
    return write_png(path, image)


def write_encoded(path: Path, image: np.ndarray) -> Path:
    """An image already in display values [0, 1] (e.g. FLIP's magma map) as a PNG."""
    from harness.scene import srgb_to_linear

    return write_png(path, srgb_to_linear(np.clip(image, 0.0, 1.0)))


__all__ = ["CROPS", "crop", "disagreement_crops", "flip_map", "outline", "relmse_map", "write_display",
           "write_encoded"]
