"""Sub-pixel jitter sequences for temporal anti-aliasing."""

from __future__ import annotations


def radical_inverse(index: int, base: int) -> float:
    """The van der Corput radical inverse of ``index`` in ``base`` (in [0, 1))."""
    result, scale = 0.0, 1.0 / base
    while index > 0:
        index, digit = divmod(index, base)
        result += digit * scale
        scale /= base
    return result


def halton_jitter(frame: int) -> tuple[float, float]:
    """Halton (2, 3) offset of ``frame`` in pixels, centred on the pixel: each in [-0.5, 0.5).

    Index ``frame + 1`` is used so that frame 0 is not the degenerate (0, 0) point.
    """
    return radical_inverse(frame + 1, 2) - 0.5, radical_inverse(frame + 1, 3) - 0.5
