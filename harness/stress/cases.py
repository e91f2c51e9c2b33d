"""The stress battery as data: each case names its frames, whom it applies to and what it checks.

A :class:`StressCase` builds a :class:`Sequence` of frames for a filter (only the channels the
filter reads) and says which properties of :mod:`harness.stress.properties` hold on it:

* every case: the output is finite wherever the input radiance is finite, and its magnitude
  stays within a bound (within [min, max] of the input colour for filters that declare
  ``convex``, else within ``GAIN_MAX`` times the largest input magnitude), and within the
  filter's declared gain of its input's local range (``local_range``);
* ``flat`` cases (constant colour over constant guides): the output's mean equals the input's;
* ``energy`` cases (a long static sequence): the output's mean stays near the clean image's
  and does not drift;
* ``fresh`` cases: after ``reset()`` the output equals a fresh instance's;
* ``rejects`` cases (invalid radiance): a ``ValueError`` naming the problem is an answer too;
* ``memory`` cases (4K): no call grows the process by more than
  :data:`harness.stress.check.MEMORY_PER_PIXEL` bytes per pixel; a call's time is bounded by
  the run's ``--timeout`` (seconds without a finished frame).

Groups: ``colour`` (extreme radiance), ``guide`` (extreme or degenerate values in every guide
channel), ``shape`` (1x1 to 4K), ``sequence`` (1,000 static frames, camera cuts, resolution
changes with ``reset()``) and ``policy`` (frames repaired by ``--nonfinite repair``). A guide case
applies to filters that read its channel; ``temporal`` cases to filters that keep history.
Single-frame cases run on three frames for temporal filters (the history path is exercised).
``heavy`` cases (4K, 1,000 frames) are left out of the pytest battery unless asked for.
"""

from __future__ import annotations

import difflib
import fnmatch
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.buffers import Frame
from harness.nonfinite import apply_nonfinite_policy
from harness.stress.frames import (
    FLAT_RGB,
    flat_frame,
    scattered,
    scene_frame,
    set_pixels,
    with_background,
    with_color,
)

F32_MAX = float(np.finfo(np.float32).max)
#: side of the frames of single-frame cases (height, width)
SIZE = (24, 20)
#: frames of the long static sequence and its size
STATIC_FRAMES, STATIC_SIZE = 1000, (40, 48)
#: 4K UHD (height, width)
UHD = (2160, 3840)
#: the albedo of ``guide-albedo-dark-highlight``'s pixels: a near-black diffuse reflectance, just
#: above the 0.01 below which a filter may leave a pixel un-demodulated (the living room's dark
#: wood, where a glossy highlight is 100-1000 times its albedo times the light)
DARK_TINT = (0.012, 0.011, 0.0105)


@dataclass(frozen=True)
class Sequence:
    """The frames of a case, built lazily (``make(t)``), and where ``reset()`` is called.

    Attributes
    ----------
    count : int
        Number of frames.
    make : callable
        ``make(t) -> Frame``.
    resets : frozenset of int
        Frame indices before which the filter's ``reset()`` is called (besides the start).
    clean_mean : ndarray (3,), optional
        Mean RGB of the noise-free image (``energy`` cases).
    """

    count: int
    make: Callable[[int], Frame]
    resets: frozenset = frozenset()
    clean_mean: np.ndarray | None = None

    def __iter__(self):
        return (self.make(t) for t in range(self.count))

    def __len__(self) -> int:
        return self.count

    @classmethod
    def of(cls, frames, resets=()) -> Sequence:
        """A sequence of given frames."""
        frames = list(frames)
        return cls(len(frames), frames.__getitem__, frozenset(resets))


@dataclass(frozen=True)
class StressCase:
    """One case of the battery.

    Attributes
    ----------
    name : str
        Unique, used by ``--cases`` and ``stress_exempt``.
    group : str
        ``colour``, ``guide``, ``shape``, ``sequence`` or ``policy``.
    doc : str
        One line: what the input is.
    build : callable
        ``build(channels, temporal) -> Sequence`` with exactly ``channels`` (plus ``color``).
    channel : str, optional
        A guide case applies only to filters that read this channel.
    temporal_only, flat, energy, fresh, rejects, memory, heavy : bool
        See the module docstring.
    """

    name: str
    group: str
    doc: str
    build: Callable[[frozenset, bool], Sequence]
    channel: str | None = None
    temporal_only: bool = False
    flat: bool = False
    energy: bool = False
    fresh: bool = False
    rejects: bool = False
    memory: bool = False
    heavy: bool = False

    def skip_reason(self, spec) -> str | None:
        """Why the case does not apply to the filter ``spec`` (None when it applies)."""
        if self.channel is not None and self.channel not in spec.requires | spec.optional:
            return f"the filter does not read {self.channel!r}"
        if self.temporal_only and not spec.temporal:
            return "the filter keeps no history"
        return None

    def sequence(self, spec) -> Sequence:
        """The case's frames for the filter ``spec`` (its declared channels only)."""
        return self.build(frozenset(spec.requires | spec.optional), spec.temporal)


def exemption(spec, case_name: str) -> str | None:
    """The reason ``spec`` declares for not passing ``case_name`` (``stress_exempt``), or None."""
    declared = getattr(spec, "stress_exempt", {}) or {}
    if case_name in declared:
        return declared[case_name]
    for pattern, reason in declared.items():
        if fnmatch.fnmatchcase(case_name, pattern):
            return reason
    return None


# ------------------------------------------------------------------ builders
def _frames(temporal: bool) -> int:
    return 3 if temporal else 1


def _each(make_frame: Callable[[frozenset, int], Frame]):
    """A builder of single-frame cases: the frame, three times (noise seed = index) for temporal filters."""

    def build(channels, temporal) -> Sequence:
        return Sequence(_frames(temporal), lambda t: make_frame(channels, t))

    return build


def _scene(channels, t, size=SIZE, noise=True) -> Frame:
    return scene_frame(*size, channels, seed=t, index=t, noise=noise)


def _colour(edit: Callable[[np.ndarray, int], np.ndarray], noise: bool = False):
    def make(channels, t):
        frame = _scene(channels, t, noise=noise)
        return with_color(frame, edit(np.array(frame["color"], copy=True), t).astype(np.float32))

    return _each(make)


def _fireflies(value: float):
    def edit(color, t):
        color[scattered(*color.shape[:2], 0.02, seed=t)] = value
        return color

    return _colour(edit)


def _one_pixel(value: float):
    def edit(color, t):
        color[color.shape[0] // 2, color.shape[1] // 2] = value
        return color

    return _colour(edit)


def _dynamic_range(color, t):
    ii, jj = np.indices(color.shape[:2])
    return np.where(((ii + jj + t) % 2 == 0)[..., None], np.float32(1e30), np.float32(1e-30)) * np.ones(3, np.float32)


def _negative(color, t):
    color[scattered(*color.shape[:2], 0.1, seed=t)] = -0.5
    return color


def _flat(level):
    return _each(lambda channels, t: flat_frame(*SIZE, channels, level=level, index=t))


def _guide(name: str, value, where: str = "scattered"):
    def make(channels, t):
        frame = _scene(channels, t)
        mask = scattered(*frame.shape, 0.05, seed=t) if where == "scattered" else np.ones(frame.shape, bool)
        return set_pixels(frame, name, mask, value)

    return _each(make)


def _conductor(channels, t):
    frame = _scene(channels, t)
    if "albedo" not in frame:
        return frame
    albedo = np.array(frame["albedo"], copy=True)
    albedo[:, frame.width // 2:] = 0.0
    return frame.replace(albedo=albedo)


def _dark_highlights(channels, t):
    frame = _scene(channels, t)
    if "albedo" not in frame:
        return frame
    mask = scattered(*frame.shape, 0.1, seed=t)
    albedo = np.array(frame["albedo"], copy=True)
    albedo[mask] = DARK_TINT
    color = np.array(frame["color"], copy=True)
    color[mask] = np.abs(color).max()
    return with_color(frame.replace(albedo=albedo), color)


def _all_background(channels, t):
    frame = _scene(channels, t, noise=False)
    frame = with_background(frame, np.ones(frame.shape, bool))
    sky = np.array(frame["color"], copy=True)
    sky[...] = np.linspace(0.2, 1.0, frame.height, dtype=np.float32)[:, None, None] * np.float32([0.4, 0.6, 1.0])
    return with_color(frame, sky)


def _shape(height: int, width: int, frames: int | None = None):
    def build(channels, temporal):
        n = frames if (frames is not None and temporal) else _frames(temporal)
        return Sequence(n, lambda t: scene_frame(height, width, channels, seed=t, index=t))

    return build


def _static(channels, temporal) -> Sequence:
    clean = scene_frame(*STATIC_SIZE, {"color"}, noise=False)["color"]
    return Sequence(
        STATIC_FRAMES,
        lambda t: scene_frame(*STATIC_SIZE, channels, seed=t, index=t),
        clean_mean=clean.astype(np.float64).mean(axis=(0, 1)),
    )


#: the flat level of each segment of the camera-cut sequence (times FLAT_RGB)
CUT_LEVELS = (1.0, 100.0, 0.01)


def _camera_cuts(channels, temporal) -> Sequence:
    per = 3

    def make(t):
        segment = t // per
        return flat_frame(*SIZE, channels, level=FLAT_RGB * np.float32(CUT_LEVELS[segment]), index=t,
                          camera_cut=t % per == 0)

    return Sequence(per * len(CUT_LEVELS), make)


#: (height, width) of the resolution sequence: reset() before each change
RESOLUTIONS = ((24, 20), (9, 7), (24, 20), (1, 5), (24, 20))


def _resolutions(channels, temporal) -> Sequence:
    per = 2 if temporal else 1

    def make(t):
        return scene_frame(*RESOLUTIONS[t // per], channels, seed=t, index=t, camera_cut=t % per == 0)

    return Sequence(per * len(RESOLUTIONS), make, resets=frozenset(range(per, per * len(RESOLUTIONS), per)))


#: radiance channels: the repair keeps their sign, so their garbage is never negative (invalid radiance
#: has a case of its own)
RADIANCE = ("color", "direct", "indirect", "emission")
#: values that ``--nonfinite repair`` must turn into something every filter survives
GARBAGE = {
    "radiance": (np.nan, np.inf, -np.inf, F32_MAX, 1e35),
    "f": (np.nan, np.inf, -np.inf, F32_MAX, -F32_MAX, 1e35, -1.0),
    "i": (-7, np.iinfo(np.int32).min, -1, np.iinfo(np.int32).max),
}


def _repaired(fraction: float | None):
    def make(channels, t):
        frame = _scene(channels, t)
        rng = np.random.default_rng(100 + t)
        mask = np.ones(frame.shape, bool) if fraction is None else scattered(*frame.shape, fraction, seed=t)
        arrays = {}
        for name in sorted(frame.channels):
            array = np.array(frame[name], copy=True)
            bad = GARBAGE["radiance" if name in RADIANCE else array.dtype.kind]
            picks = np.asarray(bad, np.float64)[rng.integers(0, len(bad), size=array.shape)]
            array[mask] = picks[mask].astype(array.dtype)
            arrays[name] = array
        repaired, _ = apply_nonfinite_policy(Frame(arrays, frame.meta), "repair")
        return repaired

    return _each(make)


# ------------------------------------------------------------------ the battery
def _battery() -> list[StressCase]:
    cases = [
        StressCase(f"fireflies-1e{k}", "colour", f"smooth image, 2% of pixels at 1e{k}", _fireflies(10.0 ** k))
        for k in range(3, 9)
    ]
    cases += [
        StressCase("color-float-max", "colour", "smooth image, one pixel at 3.4e38 (float32 max)",
                   _one_pixel(F32_MAX)),
        StressCase("color-negative-zero", "colour", "every colour value -0.0 over flat guides", _flat(-0.0),
                   flat=True),
        StressCase("color-dynamic-range", "colour", "checkerboard of 1e-30 and 1e30", _colour(_dynamic_range)),
        StressCase("color-denormal", "colour", "smooth image scaled to subnormal floats (~1e-39)",
                   _colour(lambda c, t: c * np.float32(1e-39))),
        StressCase("color-zero", "colour", "all zero over flat guides", _flat(0.0), flat=True),
        StressCase("color-constant", "colour", "constant (0.25, 0.5, 0.75) over flat guides", _flat(FLAT_RGB),
                   flat=True),
        StressCase("color-flat-huge", "colour", "constant 1e30 over flat guides", _flat(1e30), flat=True),
        StressCase("color-negative", "colour", "10% of pixels at -0.5 (invalid radiance: a clear error or a "
                   "documented clamp)", _colour(_negative), rejects=True),
    ]
    values = {"nan": (np.nan, "NaN"), "inf": (np.inf, "+Inf"), "neginf": (-np.inf, "-Inf"),
              "max": (F32_MAX, "3.4e38 (float32 max)")}
    for channel in ("albedo", "normal", "position", "depth", "variance", "visibility", "motion"):
        for label, (value, text) in values.items():
            cases.append(StressCase(f"guide-{channel}-{label}", "guide", f"5% of pixels with {channel} {text}",
                                    _guide(channel, value), channel=channel))
    for channel in ("albedo", "normal", "position", "depth", "variance", "visibility", "motion"):
        cases.append(StressCase(f"guide-{channel}-nan-all", "guide", f"every pixel's {channel} NaN (a channel the "
                                "renderer could not make)", _guide(channel, np.nan, "all"), channel=channel))
    cases += [
        StressCase("guide-normal-zero", "guide", "5% of pixels with zero-length normals", _guide("normal", 0.0),
                   channel="normal"),
        StressCase("guide-depth-zero", "guide", "5% of pixels at depth 0", _guide("depth", 0.0), channel="depth"),
        StressCase("guide-albedo-zero", "guide", "albedo 0 everywhere (demodulation divides by it)",
                   _guide("albedo", 0.0, "all"), channel="albedo"),
        StressCase("guide-albedo-conductor", "guide", "albedo 0 on one surface whose colour is not (a renderer's "
                   "albedo on conductors)", _each(_conductor), channel="albedo"),
        StressCase("guide-albedo-dark-highlight", "guide", "10% of pixels with a near-black albedo "
                   f"{DARK_TINT} and the frame's brightest colour (a highlight the albedo does not explain)",
                   _each(_dark_highlights), channel="albedo"),
        StressCase("guide-variance-negative", "guide", "5% of pixels with variance -1",
                   _guide("variance", -1.0), channel="variance"),
        StressCase("guide-motion-outside", "guide", "every motion vector (1e6, -1e6) pixels, far outside the image",
                   _guide("motion", (1e6, -1e6), "all"), channel="motion"),
        StressCase("guide-variance-zero", "guide", "variance 0 everywhere (a renderer that claims no noise)",
                   _guide("variance", 0.0, "all"), channel="variance"),
        StressCase("guide-object_id-minus-one", "guide", "object id -1 everywhere", _guide("object_id", -1, "all"),
                   channel="object_id"),
        StressCase("guide-object_id-max", "guide", "object id 2**31 - 1 everywhere",
                   _guide("object_id", np.iinfo(np.int32).max, "all"), channel="object_id"),
        StressCase("guide-spp-zero", "guide", "0 samples everywhere", _guide("spp", 0, "all"), channel="spp"),
        StressCase("guide-all-background", "guide", "every pixel background (zero normal/position/albedo, depth "
                   "inf, id -1) under a sky gradient", _each(_all_background)),
    ]
    cases += [
        StressCase("shape-1x1", "shape", "1x1 pixel", _shape(1, 1)),
        StressCase("shape-1x33", "shape", "one row of 33 pixels", _shape(1, 33)),
        StressCase("shape-33x1", "shape", "one column of 33 pixels", _shape(33, 1)),
        StressCase("shape-7x5", "shape", "7 rows of 5 pixels (odd sizes)", _shape(7, 5)),
        StressCase("shape-13x11", "shape", "13 rows of 11 pixels (odd sizes)", _shape(13, 11)),
        StressCase("shape-4k", "shape", "3840x2160 (4K UHD): memory and time", _shape(*UHD, frames=2), memory=True,
                   heavy=True),
    ]
    cases += [
        StressCase("sequence-static-1000", "sequence", f"{STATIC_FRAMES} frames of a static noisy scene "
                   f"({STATIC_SIZE[1]}x{STATIC_SIZE[0]}): history converges, energy bounded", _static,
                   temporal_only=True, energy=True, heavy=True),
        StressCase("sequence-camera-cuts", "sequence", "three flat segments at 1x, 100x, 0.01x with camera cuts "
                   "between them: no history leaks across a cut", _camera_cuts, flat=True),
        StressCase("sequence-resolutions", "sequence", "resolutions alternating 20x24, 7x9, 5x1 with reset(): "
                   "each reset gives a fresh instance's output", _resolutions, fresh=True),
    ]
    cases += [
        StressCase("repair-scattered", "policy", "10% of pixels of every channel NaN/Inf/3.4e38/negative, then "
                   "--nonfinite repair", _repaired(0.1)),
        StressCase("repair-everything", "policy", "every value of every channel NaN/Inf/3.4e38/negative, then "
                   "--nonfinite repair", _repaired(None)),
    ]
    return cases


#: every case of the battery, by name, in order
CASES: dict[str, StressCase] = {case.name: case for case in _battery()}
GROUPS = ("colour", "guide", "shape", "sequence", "policy")


def select_cases(patterns=None, *, heavy: bool = True) -> list[StressCase]:
    """Cases matching any of ``patterns``, in battery order.

    Parameters
    ----------
    patterns : iterable of str, optional
        Case names, ``fnmatch`` patterns (``"guide-normal-*"``), group names (:data:`GROUPS`),
        ``light`` (every case but the heavy ones) or ``all``. None selects every case (the
        heavy ones with ``heavy``).
    heavy : bool
        Include the heavy cases (4K, 1,000 frames) when ``patterns`` is None.

    Raises
    ------
    ValueError
        A pattern that matches no case (one line: the groups, and the closest case names).
    """
    if patterns is None:
        return [c for c in CASES.values() if heavy or not c.heavy]
    chosen = set()
    for pattern in patterns:
        hits = {n for n, c in CASES.items() if fnmatch.fnmatchcase(n, pattern) or c.group == pattern
                or pattern == "all" or (pattern == "light" and not c.heavy)}
        if not hits:
            close = difflib.get_close_matches(pattern, list(CASES), n=3, cutoff=0.5)
            hint = f"; did you mean {', '.join(close)}?" if close else ""
            raise ValueError(f"no stress case matches {pattern!r} (give case names, fnmatch patterns such as "
                             f"'guide-normal-*', a group: {', '.join(GROUPS)}, 'light' or 'all'){hint}")
        chosen |= hits
    return [c for n, c in CASES.items() if n in chosen]
