"""The harness's policy for non-finite and out-of-range renderer output, over every channel.

Renderer output is checked at the harness boundary, before any filter sees it (``--nonfinite``):

``raise`` (the default)
    A NaN or infinity in any float channel (``+inf`` depth excepted: it marks background) fails
    the render with a :class:`harness.NonFiniteError` naming the channel and the count.
``repair``
    Every non-finite or out-of-range value is replaced by a safe value and counted (the count
    is the ``nonfinite_repaired`` column):

    ============================================  ===============================================
    channel                                       repair
    ============================================  ===============================================
    color, direct, indirect, emission, position   NaN/Inf -> 0; magnitudes above 1e30 -> +-1e30
    albedo                                        NaN/Inf -> 0; clamped to [0, 1e30]
    variance                                      NaN/Inf -> 0; clamped to [0, 1e30]
    visibility                                    NaN/Inf -> 0; clamped to [0, 1]
    motion                                        NaN/Inf -> 0; clamped to +-1e6 pixels
    depth                                         NaN, -Inf or negative -> +inf (background)
    normal                                        a pixel with a NaN/Inf component becomes
                                                  background (zero normal, position and albedo,
                                                  depth +inf, object id -1); a finite normal
                                                  longer than 1e3 is renormalised to unit length
    object_id                                     below -1 -> -1
    spp                                           negative -> 0
    ============================================  ===============================================

    The bounds keep every square and product a filter forms finite in float32 (1e30 squared
    overflows float32 but not the float64 sums the built-in filters use; 3.4e38 overflows
    both a square and most sums).
"""

from __future__ import annotations

import numpy as np

from harness.buffers import Frame, NonFiniteError

#: largest magnitude a repaired radiance, position, albedo or variance keeps
SAFE_MAX = np.float32(1e30)
#: largest motion, in pixels, a repaired motion vector keeps
MOTION_MAX = np.float32(1e6)
#: a normal longer than this is out of range (a unit vector with float error is ~1)
NORMAL_MAX = 1e3

_SIGNED = ("color", "direct", "indirect", "emission", "position")
_POSITIVE = {"albedo": SAFE_MAX, "variance": SAFE_MAX, "visibility": np.float32(1.0)}


def apply_nonfinite_policy(frame: Frame, policy: str, *, owner: str = "renderer") -> tuple[Frame, int]:
    """Apply the non-finite policy to a frame (see the module docstring).

    Parameters
    ----------
    frame : Frame
    policy : {"raise", "repair"}
    owner : str
        Plugin named in the error.

    Returns
    -------
    frame : Frame
        The input, or a repaired copy.
    count : int
        Number of values found non-finite or out of range (and repaired).

    Raises
    ------
    NonFiniteError
        Under ``raise``, for any non-finite value; the message names the channels.
    """
    if policy not in ("raise", "repair"):
        raise ValueError(f"non-finite policy must be 'raise' or 'repair', got {policy!r}")
    if policy == "raise":
        counts = {}
        for name in sorted(frame.channels):
            array = frame[name]
            if array.dtype.kind == "f":
                bad = ~np.isfinite(array)
                if name == "depth":
                    bad &= ~np.isposinf(array)
                if bad.any():
                    counts[name] = int(np.count_nonzero(bad))
        if counts:
            detail = ", ".join(f"{n} {c}" for n, c in counts.items())
            raise NonFiniteError(
                f"{owner}: frame {frame.meta.index} of {frame.meta.scene!r} holds {sum(counts.values())} "
                f"non-finite values ({detail}); use --nonfinite repair to replace them"
            )
        return frame, 0
    return _repair(frame)


def _repair(frame: Frame) -> tuple[Frame, int]:
    arrays = {n: np.array(frame[n], copy=True) for n in frame.channels}
    count = 0
    for name in _SIGNED:
        if name in arrays:
            a = arrays[name]
            bad = ~np.isfinite(a) | (np.abs(a) > SAFE_MAX)
            count += int(np.count_nonzero(bad))
            a[~np.isfinite(a)] = 0.0
            np.clip(a, -SAFE_MAX, SAFE_MAX, out=a)
    for name, high in _POSITIVE.items():
        if name in arrays:
            a = arrays[name]
            finite = np.isfinite(a)
            count += int(np.count_nonzero(~finite | (a < 0) | (a > high)))
            a[~finite] = 0.0
            np.clip(a, 0.0, high, out=a)
    if "motion" in arrays:
        a = arrays["motion"]
        count += int(np.count_nonzero(~np.isfinite(a) | (np.abs(a) > MOTION_MAX)))
        a[~np.isfinite(a)] = 0.0
        np.clip(a, -MOTION_MAX, MOTION_MAX, out=a)
    if "depth" in arrays:
        a = arrays["depth"]
        bad = np.isnan(a) | (a < 0)
        count += int(np.count_nonzero(bad))
        a[bad] = np.inf
    if "normal" in arrays:
        count += _repair_normals(arrays)
    if "object_id" in arrays:
        a = arrays["object_id"]
        count += int(np.count_nonzero(a < -1))
        np.maximum(a, -1, out=a)
    if "spp" in arrays:
        a = arrays["spp"]
        count += int(np.count_nonzero(a < 0))
        np.maximum(a, 0, out=a)
    if count == 0:
        return frame, 0
    return Frame(arrays, frame.meta), count


def _repair_normals(arrays: dict) -> int:
    n = arrays["normal"]
    broken = ~np.isfinite(n).all(axis=-1)
    count = int(np.count_nonzero(~np.isfinite(n)))
    n[broken] = 0.0
    for name in ("position", "albedo"):
        if name in arrays:
            arrays[name][broken] = 0.0
    if "depth" in arrays:
        arrays["depth"][broken] = np.inf
    if "object_id" in arrays:
        arrays["object_id"][broken] = -1
    length = np.sqrt(np.sum(n.astype(np.float64) ** 2, axis=-1))
    long = length > NORMAL_MAX
    count += int(np.count_nonzero(long))
    if long.any():
        n[long] = (n[long].astype(np.float64) / length[long][:, None]).astype(np.float32)
    return count
