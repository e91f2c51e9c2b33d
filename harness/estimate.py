"""How much a run will render and how much memory it holds, estimated before any work.

Work is counted in **samples**: pixels x samples per pixel of every noisy frame and every
reference that is not in the render cache yet (pixels x frames x spp x seeds for the inputs,
pixels x frames x reference spp for the references, which all seeds share; analytic references
cost none). Time is that work over the renderer's rate in samples per second, measured on
this machine on a small image (:func:`measure_rate`) only when the run could be long at all
(:data:`FAST_RATE`, faster than any renderer measured here, would take over
:data:`LONG_S`); a reference rendered to a target error may stop earlier, so its count is an
upper bound.

Memory is the largest group's inputs as a run holds them: each frame is its channels (float32
or int32 components), each reference its image and its variance (24 bytes per pixel), held by
the run and, with a worker process, once more while sent and once in the worker
(``copies = 3``); plus the real-resolution frames its filters are timed on; plus the renderer's
working set while it renders (:data:`RENDER_BYTES_PER_PIXEL`: float64 sums and squares of a
reference). The filters' own working memory is not counted, so the estimate is a lower bound;
a run whose estimate exceeds this machine's memory (:func:`memory_limit`) cannot succeed.
"""

from __future__ import annotations

import math
import os
import time
from dataclasses import dataclass, field
from pathlib import Path

from harness.buffers import CHANNELS
from harness.real_resolutions import TIMING_FRAMES
from harness.references import batch_size
from harness.renders import REFERENCE_SEED

#: bytes per pixel of a reference held by a run: the image and its variance of the mean, float32 RGB
REFERENCE_BYTES_PER_PIXEL = 24
#: bytes per pixel a renderer needs while it renders a reference: float64 running sum, sum of
#: squares and one batch (3 x 24)
RENDER_BYTES_PER_PIXEL = 72
#: samples per second no renderer here reaches (the synthetic renderer: about 2e7 on one core)
FAST_RATE = 1e8
#: a run estimated to take longer than this (seconds) is announced with its estimated time
LONG_S = 600.0
#: environment variable that lowers the memory limit (bytes, or a number with K, M, G or T)
MEMORY_ENV = "DENOISE_HARNESS_MEMORY_LIMIT"
#: the side of the square image a renderer's rate is measured on, and the spp of the two timed calls
RATE_SIDE = 128
RATE_SPP = (1, 17)


@dataclass
class Work:
    """What a run will render and hold.

    Attributes
    ----------
    samples : dict
        Renderer -> samples (pixels x spp) still to render, inputs and references.
    input_samples, reference_samples : int
        The same split by kind.
    peak_bytes : int
        Estimated peak memory (a lower bound).
    peak_what : str
        What that peak holds (the group, its frames and sizes).
    groups : dict
        Renderer -> a group it renders (where its rate is measured).
    """

    samples: dict = field(default_factory=dict)
    input_samples: int = 0
    reference_samples: int = 0
    peak_bytes: int = 0
    peak_what: str = ""
    groups: dict = field(default_factory=dict)

    @property
    def total(self) -> int:
        return self.input_samples + self.reference_samples

    def add(self, renderer: str, samples: int, reference: bool) -> None:
        self.samples[renderer] = self.samples.get(renderer, 0) + int(samples)
        if reference:
            self.reference_samples += int(samples)
        else:
            self.input_samples += int(samples)


def frame_bytes(channels, pixels: int) -> int:
    """Bytes of one frame of ``channels`` (``color`` always) at ``pixels`` pixels."""
    names = set(channels) | {"color"}
    return pixels * sum(CHANNELS[c][0] * 4 for c in names if c in CHANNELS)


def plan_work(plan, store, *, copies: int = 3) -> Work:
    """The work and peak memory of a planned run (renders in the store's cache are not counted).

    Parameters
    ----------
    plan : harness.plan.Plan
    store : harness.renders.RenderStore
        The store the plan was made with (its cache, scenes and renderers).
    copies : int
        How many times a group's inputs are held at once (1 in-process, 3 with a worker process).
    """
    work = Work()
    references = set()
    for group in plan.groups:
        width, height = group.resolution
        pixels = width * height
        spec = store.registry.renderers[group.renderer]
        work.groups.setdefault(group.renderer, group)
        for t in range(group.frames):
            if not _cached_frame(store, group, t):
                work.add(group.renderer, pixels * group.spp, reference=False)
            key = (group.scene, group.renderer, t, group.reference_spp, group.reference_target, (width, height))
            if spec.references and group.reference_spp > 0 and key not in references:
                references.add(key)
                if not _cached_reference(store, group, t):
                    work.add(group.renderer, pixels * group.reference_spp, reference=True)
        timed = 0
        for w, h in group.timing:
            count = min(TIMING_FRAMES, group.frames)
            work.add(group.renderer, count * w * h * group.spp, reference=False)
            timed += count * frame_bytes(group.channels, w * h)
        held = group.frames * (frame_bytes(group.channels, pixels)
                               + (REFERENCE_BYTES_PER_PIXEL * pixels if spec.references else 0))
        peak = copies * (held + timed) + RENDER_BYTES_PER_PIXEL * pixels
        if peak > work.peak_bytes:
            work.peak_bytes = peak
            work.peak_what = (f"{group.scene} ({group.task}): {group.frames} frame(s) of {width}x{height}, "
                              f"{_size(frame_bytes(group.channels, pixels))} per frame"
                              + (f" and {_size(REFERENCE_BYTES_PER_PIXEL * pixels)} per reference"
                                 if spec.references else "")
                              + f", held {copies}x")
    return work


def reference_work(store, items, target: float = 0.0) -> Work:
    """The work and peak memory of rendering references: ``items`` are (scene spec, renderer, spp, frames)."""
    work = Work()
    for spec, renderer, spp, frames in items:
        width, height = store.resolution_of(spec)
        pixels = width * height
        group = _ReferenceGroup(spec.name, renderer, spp, target, frames, (width, height))
        work.groups.setdefault(renderer, group)
        for t in range(frames):
            if spp > 0 and not _cached_reference(store, group, t):
                work.add(renderer, pixels * spp, reference=True)
        peak = (REFERENCE_BYTES_PER_PIXEL + RENDER_BYTES_PER_PIXEL) * pixels
        if peak > work.peak_bytes:
            work.peak_bytes = peak
            work.peak_what = f"{spec.name}: a reference of {width}x{height}"
    return work


@dataclass
class _ReferenceGroup:
    """The parts of a plan group the estimate reads, for ``denoise-bench render``."""

    scene: str
    renderer: str
    reference_spp: int
    reference_target: float
    frames: int
    resolution: tuple
    spp: int = 1
    seed: int = 0
    channels: frozenset = frozenset()


def _cached_frame(store, group, t: int) -> bool:
    if not store.cache.enabled:
        return False
    try:
        scene = store.scene(group.scene)
        key = store.key("frame", scene, group.renderer, t, spp=group.spp, seed=group.seed,
                        channels=sorted(group.channels))
    except Exception:  # the render itself will report what is wrong
        return False
    return store.cache.path("frames", key).is_file()


def _cached_reference(store, group, t: int) -> bool:
    """Whether the reference of frame ``t`` is stored (the keys of :mod:`harness.references`)."""
    if not store.cache.enabled:
        return False
    spp = group.reference_spp
    try:
        scene = store.scene(group.scene)
        spec = store.registry.renderers[group.renderer]
        if spec.chunked:
            key = store.key("reference-moments", scene, group.renderer, t, spp=spp, seed=REFERENCE_SEED,
                            target=float(group.reference_target), batch=batch_size(spp, spec.sample_block))
        else:
            key = store.key("reference", scene, group.renderer, t, spp=spp, seed=REFERENCE_SEED)
    except Exception:
        return False
    return store.cache.path("references", key).is_file()


def memory_limit() -> tuple[int, str]:
    """The memory a run may use here (bytes) and where that limit comes from.

    The smallest of the machine's physical memory, the process's cgroup limit and
    ``$DENOISE_HARNESS_MEMORY_LIMIT``.
    """
    limits = []
    try:
        limits.append((os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES"), "this machine's memory"))
    except (ValueError, OSError, AttributeError):
        pass
    for path in ("/sys/fs/cgroup/memory.max", "/sys/fs/cgroup/memory/memory.limit_in_bytes"):
        try:
            text = Path(path).read_text().strip()
        except OSError:
            continue
        if text.isdigit() and int(text) < 2**60:
            limits.append((int(text), f"the memory limit of this process's cgroup ({path})"))
    given = os.environ.get(MEMORY_ENV, "").strip()
    if given:
        limits.append((parse_bytes(given), f"${MEMORY_ENV}"))
    if not limits:
        return 2**63 - 1, "no known limit"
    return min(limits)


def parse_bytes(text: str) -> int:
    """``"8G"``, ``"512M"``, ``"1.5T"`` or a number of bytes; a one-line ``ValueError`` otherwise."""
    units = {"": 1, "K": 2**10, "M": 2**20, "G": 2**30, "T": 2**40}
    raw = text.strip().upper().removesuffix("B").removesuffix("I")
    unit = raw[-1] if raw and raw[-1] in units else ""
    try:
        value = float(raw[: len(raw) - len(unit)])
    except ValueError:
        raise ValueError(f"${MEMORY_ENV} must be bytes or a number with K, M, G or T, got {text!r}") from None
    if not 0 < value < math.inf:
        raise ValueError(f"${MEMORY_ENV} must be > 0, got {text!r}")
    return int(value * units[unit])


def check_memory(work: Work) -> None:
    """A one-line ``ValueError`` naming the estimate and the limit when the work cannot fit in memory."""
    limit, source = memory_limit()
    if work.peak_bytes > limit:
        raise ValueError(f"needs at least {_size(work.peak_bytes)} of memory ({work.peak_what}), more than "
                         f"{source} ({_size(limit)}); lower the resolution or the frames")


def measure_rate(store, group) -> float | None:
    """Samples per second of the group's renderer on this machine, or None where it cannot be measured.

    The renderer renders frame 0 of the group's scene at :data:`RATE_SIDE` pixels square with
    the group's channels: once (compilation), then twice at each spp of :data:`RATE_SPP` (the
    faster of the two kept); the rate is the extra samples over the extra time, which leaves out
    the per-frame cost, unless the two times are too close to tell (a loaded machine), where it is
    the samples of the larger call over its time.
    """
    try:
        scene = store.scene(group.scene)
        renderer = store.renderer(group.renderer)
        size = (RATE_SIDE, RATE_SIDE)

        def render(spp: int) -> float:
            start = time.perf_counter()
            renderer.render(scene, 0, spp=spp, seed=0, channels=frozenset(group.channels), resolution=size)
            return time.perf_counter() - start

        render(RATE_SPP[0])
        low = min(render(RATE_SPP[0]), render(RATE_SPP[0]))
        high = min(render(RATE_SPP[1]), render(RATE_SPP[1]))
    except Exception:  # a renderer that serves one size only (captures) has no rate here
        return None
    pixels = RATE_SIDE * RATE_SIDE
    if high > 1.5 * low:
        return pixels * (RATE_SPP[1] - RATE_SPP[0]) / (high - low)
    return pixels * RATE_SPP[1] / high if high > 0 else None


def estimated_seconds(work: Work, store) -> tuple[float | None, str]:
    """The work's time on this machine (None when it is short or unknown) and one line saying so.

    Rates are measured (:func:`measure_rate`) only when the work would take over
    :data:`LONG_S` at :data:`FAST_RATE` (a renderer's first call compiles it where its compiled
    code is not cached yet: work the run needs anyway).
    """
    if work.total / FAST_RATE <= LONG_S:
        return None, ""
    seconds, parts, unknown = 0.0, [], []
    for renderer, samples in sorted(work.samples.items()):
        if not samples:
            continue
        rate = measure_rate(store, work.groups[renderer])
        if rate is None:
            unknown.append(renderer)
            continue
        seconds += samples / rate
        parts.append(f"{renderer} {samples:.3g} samples at {rate:.3g}/s")
    line = (f"estimated work: {work.total:.3g} samples to render ({work.input_samples:.3g} for inputs, "
            f"{work.reference_samples:.3g} for references; {', '.join(parts) or 'no rate measured'}, rates "
            f"measured here on {RATE_SIDE}x{RATE_SIDE}): about {duration(seconds)} of rendering")
    if unknown:
        line += f" plus what {', '.join(unknown)} take(s) (no rate)"
    return seconds, line


def check_plan(plan, store, *, copies: int = 3, max_hours: float | None = None) -> dict:
    """Refuse a planned run that cannot fit in memory or takes longer than ``max_hours``; its estimate.

    See :func:`check_work`; ``copies`` as in :func:`plan_work`.
    """
    return check_work(plan_work(plan, store, copies=copies), store, max_hours)


def check_work(work: Work, store, max_hours: float | None = None) -> dict:
    """Refuse work that cannot fit in memory or takes longer than ``max_hours``; return its estimate.

    Returns
    -------
    dict
        ``samples`` (still to render), ``input_samples``, ``reference_samples``, ``peak_bytes``,
        ``seconds`` (None: short or unknown) and ``announcement`` (one line for work estimated
        over :data:`LONG_S`, else ``""``).

    Raises
    ------
    ValueError
        One line naming the estimate and the limit.
    """
    check_memory(work)
    seconds, line = estimated_seconds(work, store)
    if seconds is not None and max_hours is not None and seconds > max_hours * 3600:
        raise ValueError(f"{line}; more than --max-hours {max_hours:g}")
    return {"samples": work.total, "input_samples": work.input_samples, "reference_samples": work.reference_samples,
            "peak_bytes": work.peak_bytes, "seconds": seconds, "announcement": line}


def duration(seconds: float) -> str:
    """``"42 s"``, ``"12 min"``, ``"3.4 h"`` or ``"2.1 days"``."""
    if seconds < 120:
        return f"{seconds:.0f} s"
    if seconds < 7200:
        return f"{seconds / 60:.0f} min"
    if seconds < 172800:
        return f"{seconds / 3600:.1f} h"
    return f"{seconds / 86400:.1f} days"


def _size(count: float) -> str:
    for unit, scale in (("TiB", 2**40), ("GiB", 2**30), ("MiB", 2**20), ("KiB", 2**10)):
        if count >= scale:
            return f"{count / scale:.3g} {unit}"
    return f"{count:.0f} bytes"


__all__ = ["FAST_RATE", "LONG_S", "MEMORY_ENV", "Work", "check_memory", "check_plan", "check_work", "duration",
           "estimated_seconds", "frame_bytes", "measure_rate", "memory_limit", "parse_bytes", "plan_work",
           "reference_work"]
