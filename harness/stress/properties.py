"""The properties a filter's outputs must have on stress input: bounds, not golden numbers.

:class:`Monitor` watches one sequence, call by call:

``finite``
    The output is finite at every pixel whose input radiance (``color`` and, where the filter
    reads them, ``direct``/``indirect``/``emission``) is finite.
``bounds``
    A filter that declares ``convex`` outputs, per channel, values within [min, max] of its input
    radiance since the last ``reset()`` or camera cut (relative tolerance ``RANGE_RTOL``, and an
    absolute one of the smallest normal float32, so flushing subnormals to zero is allowed).
    Where the filter reads ``direct``/``indirect``, the range is that of their sum's bounds. Any
    other filter's output magnitude stays within ``GAIN_MAX`` times the largest input magnitude.
``local_range``
    Every filter: each output pixel's magnitude is at most ``range_gain`` times the largest
    input radiance magnitude within ``range_radius`` pixels of it (the whole frame where the
    radius is None), over the frames since the last ``reset()`` or camera cut, plus the smallest
    normal float32 (both declared by the filter's spec; the default gain is 4). It catches what
    the gain bound lets through: a demodulation that amplified a conductor's colour 200 times.
``flat``
    On flat frames (constant colour over constant guides) the output's mean equals the input's
    within ``FLAT_RTOL`` (relative) plus the smallest normal float32.
``energy``
    Over a long static sequence, each output frame's mean over the clean image's mean stays
    within ``1 +- ENERGY_TOL``, and the mean of that ratio over the last ``WINDOW`` frames
    differs from its mean over frames ``WINDOW``..``2 WINDOW`` by at most ``DRIFT_TOL``.
"""

from __future__ import annotations

from dataclasses import dataclass

import numpy as np

from harness.buffers import Frame

RANGE_RTOL = 1e-5
GAIN_MAX = 1e3
FLAT_RTOL = 1e-3
ENERGY_TOL = 0.2
DRIFT_TOL = 0.02
WINDOW = 100
TINY = float(np.finfo(np.float32).tiny)

#: the statuses of a case that count as passing (the others: :mod:`harness.stress.table`)
PASSING = ("pass", "rejected")


@dataclass
class Failure:
    """A property that did not hold: the status, a one-line message and the frame."""

    status: str
    message: str
    frame: int = -1


def radiance_parts(frame: Frame) -> list[np.ndarray]:
    """The radiance inputs whose sum makes the image: ``direct`` + ``indirect`` (+ ``emission``) or ``color``."""
    if "direct" in frame and "indirect" in frame:
        return [frame[n] for n in ("direct", "indirect", "emission") if n in frame]
    return [frame["color"]]


def window_max(values: np.ndarray, radius: int) -> np.ndarray:
    """The largest value of ``values`` (H, W) within a square of half-width ``radius`` around each pixel."""
    out = values
    for axis in (0, 1):
        n = out.shape[axis]
        pad = [(0, 0), (0, 0)]
        pad[axis] = (radius, radius)
        padded = np.pad(out, pad, mode="constant", constant_values=-np.inf)
        out = np.lib.stride_tricks.sliding_window_view(padded, 2 * radius + 1, axis=axis).max(axis=-1)
        assert out.shape[axis] == n
    return out


class Monitor:
    """Checks the outputs of one filter over one sequence.

    Parameters
    ----------
    convex : bool
        The filter declares ``convex`` (tight bounds) or not (the gain bound).
    flat, energy : bool
        Which of the case's properties hold (see the module docstring).
    clean_mean : ndarray (3,), optional
        Mean RGB of the noise-free image (``energy``).
    """

    def __init__(self, *, convex: bool, flat: bool = False, energy: bool = False, clean_mean=None,
                 range_gain: float = 4.0, range_radius: int | None = None):
        self.convex, self.flat, self.energy = convex, flat, energy
        self.range_gain, self.range_radius = float(range_gain), range_radius
        self.clean_mean = None if clean_mean is None else np.asarray(clean_mean, np.float64)
        self.means: list[np.ndarray] = []
        self.restart()

    def restart(self) -> None:
        """Forget the input range (``reset()`` or a camera cut)."""
        self.low = np.full(3, np.inf)
        self.high = np.full(3, -np.inf)
        self.peak = 0.0
        self.local = None  # largest input magnitude per pixel (over the window), since the restart

    def check(self, t: int, frame: Frame, out: np.ndarray) -> Failure | None:
        """Check output ``out`` of frame ``t``; the first property that fails, or None."""
        if frame.meta.camera_cut and t > 0:
            self.restart()
        color = frame["color"]
        parts = radiance_parts(frame)
        finite = np.isfinite(color).all(axis=-1)
        for part in parts:
            finite &= np.isfinite(part).all(axis=-1)
        bad = ~np.isfinite(out).all(axis=-1) & finite
        if bad.any():
            i, j = np.argwhere(bad)[0]
            return Failure("nonfinite", f"{int(bad.sum())} of {bad.size} pixels non-finite where the input "
                                        f"radiance is finite (first at row {i}, column {j}: {out[i, j].tolist()})", t)
        self._widen(parts, finite)
        failure = self._bounds(out, finite, t)
        if failure is None:
            failure = self._local_range(parts, out, finite, t)
        if failure is None and self.flat:
            failure = self._flat(color, out, t)
        if self.energy:
            self.means.append(out.astype(np.float64).mean(axis=(0, 1)))
        return failure

    def _widen(self, parts, finite) -> None:
        low = np.zeros(3)
        high = np.zeros(3)
        peak = 0.0
        for part in parts:
            values = part[finite].astype(np.float64)
            if values.size:
                low += values.min(axis=0)
                high += values.max(axis=0)
                peak += float(np.abs(values).max())
        if finite.any():
            self.low = np.minimum(self.low, low)
            self.high = np.maximum(self.high, high)
            self.peak = max(self.peak, peak)

    def _bounds(self, out, finite, t) -> Failure | None:
        values = out[finite].astype(np.float64)
        if not values.size:
            return None
        if self.convex:
            scale = np.maximum(np.abs(self.low), np.abs(self.high))
            tol = RANGE_RTOL * scale + TINY
            below = values.min(axis=0) < self.low - tol
            above = values.max(axis=0) > self.high + tol
            if below.any() or above.any():
                c = int(np.argmax(below | above))
                return Failure("out_of_bounds", f"channel {c}: output in [{values[:, c].min():.6g}, "
                                                f"{values[:, c].max():.6g}], outside the input range "
                                                f"[{self.low[c]:.6g}, {self.high[c]:.6g}] of a convex filter", t)
            return None
        peak = float(np.abs(values).max())
        if peak > GAIN_MAX * self.peak + TINY:
            return Failure("out_of_bounds", f"output magnitude {peak:.6g} exceeds {GAIN_MAX:g} x the largest input "
                                            f"magnitude {self.peak:.6g}", t)
        return None

    def _local_range(self, parts, out, finite, t) -> Failure | None:
        magnitude = np.zeros(finite.shape)
        for part in parts:
            magnitude += np.abs(np.where(finite[..., None], part, 0.0).astype(np.float64)).max(axis=-1)
        local = np.full(finite.shape, magnitude.max()) if self.range_radius is None else \
            window_max(magnitude, self.range_radius)
        if self.local is None or self.local.shape != local.shape:
            self.local = local
        else:
            self.local = np.maximum(self.local, local)
        got = np.where(finite, np.abs(out.astype(np.float64)).max(axis=-1), 0.0)
        bound = self.range_gain * self.local + TINY
        over = got > bound
        if not over.any():
            return None
        i, j = np.unravel_index(int(np.argmax(np.where(over, got / bound, 0.0))), got.shape)
        window = "the frame" if self.range_radius is None else f"{self.range_radius} pixels"
        return Failure("out_of_bounds", f"{int(over.sum())} pixels beyond {self.range_gain:g} x the largest input "
                                        f"magnitude within {window} (first at row {i}, column {j}: {got[i, j]:.6g} "
                                        f"against {self.local[i, j]:.6g})", t)

    def _flat(self, color, out, t) -> Failure | None:
        want = color.astype(np.float64).mean(axis=(0, 1))
        got = out.astype(np.float64).mean(axis=(0, 1))
        err = np.abs(got - want)
        tol = FLAT_RTOL * np.abs(want) + TINY
        if (err > tol).any():
            c = int(np.argmax(err - tol))
            return Failure("mean_shift", f"flat input: output mean {got[c]:.6g} instead of {want[c]:.6g} "
                                         f"(channel {c}, relative error {err[c] / max(abs(want[c]), TINY):.3g})", t)
        return None

    def finish(self) -> Failure | None:
        """Sequence-level properties (``energy``), after the last frame."""
        if not self.energy or self.clean_mean is None or not self.means:
            return None
        ratio = np.array([m.sum() for m in self.means]) / self.clean_mean.sum()
        worst = int(np.argmax(np.abs(ratio - 1.0)))
        if abs(ratio[worst] - 1.0) > ENERGY_TOL:
            return Failure("unstable", f"frame {worst}: output energy {ratio[worst]:.4g} x the clean image's "
                                       f"(bound 1 +- {ENERGY_TOL:g})", worst)
        if len(ratio) >= 3 * WINDOW:
            early, late = ratio[WINDOW:2 * WINDOW].mean(), ratio[-WINDOW:].mean()
            if abs(late - early) > DRIFT_TOL:
                return Failure("unstable", f"energy drifts from {early:.4g} (frames {WINDOW}-{2 * WINDOW}) to "
                                           f"{late:.4g} (last {WINDOW}) x the clean image's (bound {DRIFT_TOL:g})",
                               len(ratio) - 1)
        return None

    def energy_summary(self) -> str:
        """Mean and range of the energy ratio (for the row's notes)."""
        if not self.means or self.clean_mean is None:
            return ""
        ratio = np.array([m.sum() for m in self.means]) / self.clean_mean.sum()
        return f"energy ratio {ratio.mean():.4g} (min {ratio.min():.4g}, max {ratio.max():.4g})"
