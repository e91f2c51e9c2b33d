"""A filter's floor: the least work any filter with its declarations must do on a frame.

The floor of a filter reads every input buffer the filter receives (the channels it declares,
``requires`` and ``optional``, that the frame holds; ``color`` always) once and writes one
float32 RGB output frame, on the same threads (a Numba parallel kernel over rows). A
temporal filter must also read its history: its floor keeps its own previous output and reads
it as one more RGB frame (the least history any temporal filter keeps; a filter that keeps more,
e.g. moments or previous guides, has a floor set a little low). Every output value is the sum
of the pixel's input values (all channels, all components), so the compiler cannot drop a read:
a NaN in any input shows in the output. The output buffer (two, used in turn, for a temporal
floor: one holds the history) is allocated on the first call of a shape or sequence and kept, as
a filter that streams would, so a timed call that continues a sequence allocates nothing.

Timed with the timing protocol (:func:`harness.timer.time_frame`) on the same frames, in the
same process and at the same thread count as the filter, its time is the machine's streaming
limit for that filter's inputs: ``x_of_floor = filter ms / floor ms``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np
from numba import njit, prange

#: compiled kernels by input layout (see :func:`floor_kernel`)
_KERNELS: dict = {}


def floor_kernel(layout: tuple):
    """The compiled floor kernel for inputs of ``layout``: one ``(ndim, components, is_int)`` per array.

    The kernel takes the arrays in that order and the (H, W, 3) float32 output, and writes
    ``out[i, j, c]`` = the sum of component ``c`` of every 3-component input plus the sum of
    every other input value of pixel (i, j) (one-component maps, int32 counts cast to float32,
    each component of other planes). Its source is written for the layout (one named argument
    and one term per input), as a hand-written kernel for those buffers would be: a loop over
    a tuple of arrays indexed at run time compiled to about half the speed (measured on 1280x720
    inputs, one thread). Rows are split between the threads by ``prange``; every input value is
    read once and every output value written once. Compiled once per layout and process.
    """
    if layout in _KERNELS:
        return _KERNELS[layout]
    names = [f"a{k}" for k in range(len(layout))]
    rgb, extra = [], []
    for name, (ndim, comps, is_int) in zip(names, layout):
        if ndim == 3 and comps == 3:
            rgb.append(f"{name}[i, j, c]")
        elif ndim == 3:
            extra += [f"{name}[i, j, {c}]" for c in range(comps)]
        else:
            extra.append(f"float32({name}[i, j])" if is_int else f"{name}[i, j]")
    source = "\n".join([
        f"def kernel({', '.join([*names, 'out'])}):",
        "    h, w = out.shape[0], out.shape[1]",
        "    for i in prange(h):",
        "        for j in range(w):",
        f"            e = float32(0.0){''.join(' + ' + t for t in extra)}",
        "            for c in range(3):",
        f"                out[i, j, c] = e{''.join(' + ' + t for t in rgb)}",
    ])
    namespace = {"prange": prange, "float32": np.float32}
    exec(compile(source, f"<floor kernel {layout}>", "exec"), namespace)
    _KERNELS[layout] = njit(parallel=True)(namespace["kernel"])
    return _KERNELS[layout]


def floor_sum(arrays, out: np.ndarray) -> np.ndarray:
    """Write into ``out`` (H, W, 3) float32 the per-pixel sum of ``arrays`` (see :func:`floor_kernel`).

    Parameters
    ----------
    arrays : sequence of ndarray
        (H, W, C) float32, (H, W) float32 or (H, W) int32 arrays of ``out``'s height and width.
    out : ndarray
        (H, W, 3) float32.

    Returns
    -------
    ndarray
        ``out``.
    """
    layout = []
    for a in arrays:
        if not (a.dtype == np.float32 and a.ndim in (2, 3) or a.dtype == np.int32 and a.ndim == 2):
            raise ValueError(f"the floor reads (H, W[, C]) float32 or (H, W) int32 arrays, got {a.dtype} {a.shape}")
        if a.shape[:2] != out.shape[:2]:
            raise ValueError(f"the floor's inputs must be {out.shape[:2]} pixels, got {a.shape}")
        layout.append((a.ndim, a.shape[2] if a.ndim == 3 else 1, a.dtype == np.int32))
    floor_kernel(tuple(layout))(*arrays, out)
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
            if self.history is None or self.history.shape != shape:
                self.history = np.empty(shape, np.float32)  # first call of a sequence: the second buffer
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
