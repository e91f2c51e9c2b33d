"""A filter's floor: the least work any filter with its declarations must do on a frame.

The floor of a filter reads every input buffer the filter receives (the channels it declares,
``requires`` and ``optional``, that the frame holds; ``color`` always) once and writes one
float32 RGB output frame, on the same threads (a Numba parallel kernel, rows in bands). A
temporal filter must also read its history: its floor keeps its own previous output and reads
it as one more RGB frame (the least history any temporal filter keeps; a filter that keeps more,
e.g. moments or previous guides, has a floor set a little low). Every output value is the sum
of the pixel's input values (all channels, all components), so the compiler cannot drop a read:
a NaN in any input shows in the output. The output buffer (and the history) is allocated on the
first call of a shape and kept, as a filter that streams would.

Timed with the timing protocol (:func:`harness.timer.time_frame`) on the same frames, in the
same process and at the same thread count as the filter, its time is the machine's streaming
limit for that filter's inputs: ``x_of_floor = filter ms / floor ms``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

#: rows are dealt in at most this many bands (each band allocates its row accumulators once)
BANDS = 64


@njit(parallel=True, cache=True)
def _floor_kernel(planes, n_planes, maps, n_maps, counts, n_counts, out):
    """``out[i, j, c]`` = the sum over ``planes`` of component ``c`` (3-component planes) plus
    the sum of every other value of pixel (i, j): other planes' components, ``maps``, ``counts``.

    ``planes``: tuple of read-only (H, W, C) float32 arrays, the first ``n_planes`` used;
    ``maps``: (H, W) float32, ``counts``: (H, W) int32, likewise. Rows are cut into bands, one
    parallel iteration each; every input value is read once and every output value written once.
    """
    h, w = out.shape[0], out.shape[1]
    bands = min(h, BANDS)
    for b in prange(bands):
        rgb = np.empty((w, 3), np.float32)
        extra = np.empty(w, np.float32)
        for i in range(b * h // bands, (b + 1) * h // bands):
            rgb[:] = 0.0
            extra[:] = 0.0
            for k in range(n_planes):
                a = planes[k]
                comps = a.shape[2]
                if comps == 3:
                    for j in range(w):
                        rgb[j, 0] += a[i, j, 0]
                        rgb[j, 1] += a[i, j, 1]
                        rgb[j, 2] += a[i, j, 2]
                else:
                    for j in range(w):
                        for c in range(comps):
                            extra[j] += a[i, j, c]
            for k in range(n_maps):
                m = maps[k]
                for j in range(w):
                    extra[j] += m[i, j]
            for k in range(n_counts):
                n = counts[k]
                for j in range(w):
                    extra[j] += np.float32(n[i, j])
            for j in range(w):
                e = extra[j]
                out[i, j, 0] = rgb[j, 0] + e
                out[i, j, 1] = rgb[j, 1] + e
                out[i, j, 2] = rgb[j, 2] + e


def _read_only(array: np.ndarray) -> np.ndarray:
    view = np.ascontiguousarray(array).view()
    view.flags.writeable = False
    return view


_EMPTY3 = _read_only(np.zeros((1, 1, 3), np.float32))
_EMPTY2 = _read_only(np.zeros((1, 1), np.float32))
_EMPTY_INT = _read_only(np.zeros((1, 1), np.int32))


def floor_sum(arrays, out: np.ndarray) -> np.ndarray:
    """Write into ``out`` (H, W, 3) float32 the per-pixel sum of ``arrays`` (see the kernel).

    Parameters
    ----------
    arrays : iterable of ndarray
        (H, W, C) float32, (H, W) float32 or (H, W) int32 arrays of ``out``'s height and width.
    out : ndarray
        (H, W, 3) float32, C-contiguous.

    Returns
    -------
    ndarray
        ``out``.
    """
    planes, maps, counts = [], [], []
    for a in arrays:
        if a.ndim == 3 and a.dtype == np.float32:
            planes.append(_read_only(a))
        elif a.ndim == 2 and a.dtype == np.float32:
            maps.append(_read_only(a))
        elif a.ndim == 2 and a.dtype == np.int32:
            counts.append(_read_only(a))
        else:
            raise ValueError(f"the floor reads (H, W[, C]) float32 or (H, W) int32 arrays, got {a.dtype} {a.shape}")
    _floor_kernel(tuple(planes or [_EMPTY3]), len(planes), tuple(maps or [_EMPTY2]), len(maps),
                  tuple(counts or [_EMPTY_INT]), len(counts), out)
    return out


class Floor:
    """The floor as a filter object (same call signature, deep-copyable).

    Parameters
    ----------
    channels : iterable of str
        The channels the measured filter declares (those missing from a frame are not read).
    temporal : bool
        Also read the previous output (history), as the measured filter is temporal.
    """

    def __init__(self, channels, temporal: bool = False):
        self.channels = tuple(sorted(set(channels) | {"color"}))
        self.temporal = bool(temporal)
        self.out: np.ndarray | None = None
        self.history: np.ndarray | None = None

    def reset(self) -> None:
        """Forget the history (a new sequence)."""
        self.history = None

    def __call__(self, frame, sampler=None) -> np.ndarray:
        shape = (frame.height, frame.width, 3)
        if self.out is None or self.out.shape != shape:
            self.out = np.empty(shape, np.float32)
        inputs = [frame[name] for name in self.channels if name in frame]
        if self.temporal and self.history is not None and self.history.shape == shape:
            inputs.append(self.history)
        out = floor_sum(inputs, self.out)
        if self.temporal:  # the output becomes the history; the next call writes the other buffer
            self.out, self.history = self.history, out
        return out


@dataclass(frozen=True)
class FloorSpec:
    """What the timing protocol needs to know of the floor (``temporal``, ``stage_timing``)."""

    name: str
    temporal: bool
    stage_timing: bool = False


def floor_of(spec) -> tuple[Floor, FloorSpec]:
    """The floor of the filter ``spec`` (a :class:`harness.FilterSpec`) and its timing spec."""
    return (Floor(spec.requires | spec.optional, temporal=spec.temporal),
            FloorSpec(f"floor of {spec.name}", spec.temporal))


__all__ = ["Floor", "FloorSpec", "floor_of", "floor_sum"]
