"""Fuzzing: Hypothesis generates frames, finds one a filter fails on, and shrinks it to a minimal one.

A generated example is the ordinary two-surface scene (:func:`harness.stress.frames.scene_frame`)
at a drawn size (1..``MAX_SIDE`` pixels a side; 1..3 frames for temporal filters), its colour
scaled by a drawn factor, with a few drawn pixel edits: a channel the filter reads, a pixel, a
component (or all) and a value. Radiance values are finite and non-negative (anything a
renderer may legally produce, subnormals and float32 max included); guide values are any
float32 (NaN and infinities included) or any int32. A filter fails an example when a property
of :mod:`harness.stress.properties` does not hold, when it raises, crashes or hangs.

Hypothesis shrinks a failure (smaller frames, fewer edits, simpler values) and the minimal
example is saved as a reproducer (:mod:`harness.stress.reproducer`). Every call runs through
``evaluate`` (the CLI's executor: a worker process), so a crash during the search or the
shrinking is one more failing example, not the end of the run.
"""

from __future__ import annotations

import random
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.buffers import CHANNELS, Frame
from harness.stress.check import CaseResult
from harness.stress.frames import scene_frame, with_color
from harness.stress.properties import PASSING

MAX_SIDE = 8
MAX_EDITS = 6
F32_MAX = float(np.finfo(np.float32).max)
#: factors the whole colour is scaled by (the first is where shrinking goes)
SCALES = (1.0, 0.0, 1e-39, 1e-30, 1e8, 1e19, 1e30, F32_MAX)
RADIANCE_VALUES = (0.0, -0.0, 1e-45, 1e-39, 1e-30, 1.0, 1e3, 1e8, 1e19, 1e30, F32_MAX)
GUIDE_VALUES = (np.nan, np.inf, -np.inf, 0.0, -0.0, 1e-45, -1.0, 1e30, -1e30, F32_MAX, -F32_MAX)
INT_VALUES = (-1, 0, 1, int(np.iinfo(np.int32).min), int(np.iinfo(np.int32).max))
RADIANCE = ("color", "direct", "indirect", "emission")


@dataclass(frozen=True)
class Edit:
    """One drawn change: ``channel`` of frame ``t`` at flat pixel index ``pixel``, ``component`` (-1: all)."""

    t: int
    channel: str
    pixel: int
    component: int
    value: float


@dataclass(frozen=True)
class Example:
    """A generated input: size, frames, colour scale and edits (the repr Hypothesis reports)."""

    height: int
    width: int
    count: int
    scale: float
    edits: tuple

    def frames(self, channels) -> list[Frame]:
        """The example's frames with exactly ``channels`` (plus ``color``)."""
        out = []
        for t in range(self.count):
            frame = scene_frame(self.height, self.width, channels, seed=t, index=t)
            if self.scale != 1.0:
                with np.errstate(over="ignore"):
                    scaled = np.minimum(frame["color"].astype(np.float64) * self.scale, F32_MAX)
                frame = with_color(frame, scaled.astype(np.float32))
            for edit in self.edits:
                if edit.t == t:
                    frame = _apply(frame, edit)
            out.append(frame)
        return out


def _apply(frame: Frame, edit: Edit) -> Frame:
    array = np.array(frame[edit.channel], copy=True)
    flat = array.reshape(frame.height * frame.width, -1)
    row = flat[edit.pixel]
    if edit.component < 0 or edit.component >= row.shape[0]:
        row[:] = edit.value
    else:
        row[edit.component] = edit.value
    if edit.channel == "color":
        return with_color(frame, array)
    return frame.replace(**{edit.channel: array})


def examples(channels, temporal: bool):
    """The Hypothesis strategy of :class:`Example` for a filter reading ``channels``."""
    from hypothesis import strategies as st

    names = sorted(set(channels) | {"color"})
    editable = [n for n in names if n not in RADIANCE or n == "color"]

    def values(name):
        if name in RADIANCE:
            return st.one_of(st.sampled_from(RADIANCE_VALUES),
                             st.floats(min_value=0.0, max_value=F32_MAX, width=32, allow_nan=False))
        if np.dtype(CHANNELS[name][1]).kind == "i":
            return st.one_of(st.sampled_from(INT_VALUES), st.integers(INT_VALUES[3], INT_VALUES[4]))
        return st.one_of(st.sampled_from(GUIDE_VALUES), st.floats(width=32))

    @st.composite
    def example(draw):
        height = draw(st.integers(1, MAX_SIDE))
        width = draw(st.integers(1, MAX_SIDE))
        count = draw(st.integers(1, 3)) if temporal else 1
        scale = draw(st.sampled_from(SCALES))

        @st.composite
        def edit(draw_edit):
            name = draw_edit(st.sampled_from(editable))
            return Edit(draw_edit(st.integers(0, count - 1)), name, draw_edit(st.integers(0, height * width - 1)),
                        draw_edit(st.integers(-1, CHANNELS[name][0] - 1)), draw_edit(values(name)))

        edits = draw(st.lists(edit(), max_size=MAX_EDITS))
        return Example(height, width, count, scale, tuple(edits))

    return example()


@dataclass
class FuzzOutcome:
    """What a fuzzing search found.

    Attributes
    ----------
    tried : int
        Examples evaluated (the search and the shrinking).
    example : Example or None
        The minimal failing example (None: no failure found).
    frames : list of Frame
        Its frames.
    result : CaseResult or None
        The filter's result on it.
    """

    tried: int
    example: Example | None = None
    frames: list | None = None
    result: CaseResult | None = None


def fuzz(channels, temporal: bool, evaluate: Callable[[list], CaseResult], *, examples_count: int,
         seed: int = 0) -> FuzzOutcome:
    """Search for a failing example and shrink it.

    Parameters
    ----------
    channels : iterable of str
        What the filter reads (the example's frames hold exactly these).
    temporal : bool
        Whether the filter keeps history (examples of 1..3 frames).
    evaluate : callable
        ``evaluate(frames) -> CaseResult``; a status outside ``pass``/``rejected`` is a failure.
    examples_count : int
        Examples to generate before giving up (shrinking adds more evaluations).
    seed : int
        Seed of the search (the same seed explores the same examples).
    """
    from hypothesis import HealthCheck, find, settings
    from hypothesis.errors import NoSuchExample

    channels = frozenset(channels)
    tried = 0

    def fails(example: Example) -> bool:
        nonlocal tried
        tried += 1
        return evaluate(example.frames(channels)).status not in PASSING

    config = settings(max_examples=examples_count, database=None, deadline=None,
                      suppress_health_check=list(HealthCheck))
    try:
        found = find(examples(channels, temporal), fails, settings=config, random=random.Random(seed))
    except NoSuchExample:
        return FuzzOutcome(tried)
    frames = found.frames(channels)
    return FuzzOutcome(tried + 1, found, frames, evaluate(frames))
