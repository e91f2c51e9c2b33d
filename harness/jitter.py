"""Sub-pixel jitter of real-time renderers: the Halton (2, 3) cycle engines use with TAA.

Shared by the renderers that jitter their frames (``raster``, ``pathtracer`` with ``jitter``) and
by the anti-aliasing checks, so every jittered frame of the harness follows one sequence.
"""

from __future__ import annotations

#: length of the jitter cycle: frame t uses the Halton point of index (t mod 16) + 1, as engines
#: do (UE4 and most TAA implementations cycle 8 or 16 points of the (2, 3) sequence)
JITTER_CYCLE = 16


def radical_inverse(index: int, base: int) -> float:
    """The van der Corput radical inverse of ``index`` in ``base`` (in [0, 1))."""
    result, scale = 0.0, 1.0 / base
    while index > 0:
        index, digit = divmod(index, base)
        result += digit * scale
        scale /= base
    return result


def halton_jitter(frame: int, cycle: int = JITTER_CYCLE) -> tuple[float, float]:
    """Halton (2, 3) offset of ``frame`` in pixels, centred on the pixel: each in [-0.5, 0.5).

    Point ``(frame mod cycle) + 1`` of the sequence is used: index 0 would be the degenerate
    (0, 0) point, and the cycle repeats the same well-spread ``cycle`` positions forever.
    """
    index = frame % cycle + 1
    return radical_inverse(index, 2) - 0.5, radical_inverse(index, 3) - 0.5


__all__ = ["JITTER_CYCLE", "halton_jitter", "radical_inverse"]
