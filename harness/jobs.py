"""One job: the timing protocol, validation of the outputs, metrics, and the job's rows.

No I/O and no scheduling: a job gets its rendered inputs and returns rows (and, on request,
outputs); an executor decides where it runs.

Timing protocol (DESIGN.md): the first call of a filter on a new shape is its compile/warm-up,
recorded as ``compile_ms`` and checked like every other call; then ``repeats`` calls are timed
with ``time.perf_counter_ns`` and reported as median, min and max. CUDA work is synchronised
before the clock stops. Validation, metrics and any I/O happen outside the timed region. A
temporal filter is deep-copied before each timed call so that every repeat starts from the same
history; the state after the last repeat carries on to the next frame. An adaptive filter's
timed call includes the extra samples it asks for (a fresh sampler per call).

Fault handling: a filter that fails to build, raises (``sys.exit`` included), returns a wrong
shape or dtype, or non-finite values gives an ``error`` row with a short message.

Metrics receive what their spec ``accepts``: the reference's variance of the mean (for the
bias correction) and the mask of scored pixels (emitters left out unless the job includes
them). A job whose ``timing`` names real resolutions also times its filter on the group's
frames of those sizes (:func:`time_real_resolutions`), after its quality frames.
"""

from __future__ import annotations

import copy
import json
import math
import time
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harness.buffers import Frame, check_filter_output
from harness.errors import short_error
from harness.images import display_variance
from harness.machine import machine_label
from harness.plan import Job, MetricPlan
from harness.references import noise_floor
from harness.rows import Row, timing_column


@dataclass
class GroupInputs:
    """What every job of a group shares (sent once to a worker).

    Attributes
    ----------
    frames : list of Frame
        The noisy frames, after the non-finite policy.
    references : list of ndarray or None
        The converged reference of each frame (None where the renderer makes none).
    reference_hashes : list of str
    repaired : list of int
        Values the non-finite policy replaced in each frame.
    channels : frozenset
        Channels rendered (what an adaptive sampler renders too).
    scene : Scene, optional
        The scene, for adaptive filters (their sampler renders more samples of it).
    renderer_settings : dict
        Factory settings of the group's renderer (for the sampler).
    reference_variances : list of ndarray or None
        Each reference's per-pixel variance of the mean (None where unknown).
    reference_quality : list of (int, float)
        Each reference's samples per pixel and median relative standard error.
    timing_frames : dict
        (width, height) -> frames at that real resolution, for jobs that time there
        (:func:`harness.timing.timing_frames`).
    """

    frames: list
    references: list
    reference_hashes: list
    repaired: list
    channels: frozenset = frozenset()
    scene: Any = None
    renderer_settings: dict = field(default_factory=dict)
    reference_variances: list = field(default_factory=list)
    reference_quality: list = field(default_factory=list)
    timing_frames: dict = field(default_factory=dict)


@dataclass
class JobResult:
    """The rows of a job and the outputs that were asked for (frame index -> image)."""

    rows: list
    outputs: dict = field(default_factory=dict)


def run_job(
    registry,
    job: Job,
    inputs: GroupInputs,
    metrics: MetricPlan,
    *,
    renderer=None,
    keep_outputs: str = "none",
    progress: Callable[[int], None] | None = None,
) -> JobResult:
    """Run one job over every frame of its group.

    Parameters
    ----------
    registry : harness.Registry
        Where the filter's and metrics' specs come from.
    job : harness.plan.Job
    inputs : GroupInputs
    metrics : harness.plan.MetricPlan
        Metric names to score (frame and sequence) and those skipped with their reason.
    renderer : object, optional
        The group's renderer, for filters that declare ``adaptive`` (its ``sampler``).
    keep_outputs : {"none", "first", "all"}
        Which outputs to return with the rows.
    progress : callable, optional
        Called with 1 after each frame (and with the remaining count when the job ends early).

    Returns
    -------
    JobResult
    """
    spec = registry.get("filter", job.filter)
    tick = progress or (lambda n: None)
    n = len(inputs.frames)
    try:
        filt = spec.factory(backend=job.backend, **job.param_dict)
        filt.reset()
    except (Exception, SystemExit) as exc:
        tick(n)
        first = inputs.frames[0] if n else None
        return JobResult([_row(job, inputs, -1, first, "error", f"filter could not be built: {_why(exc)}")])
    visible = spec.requires | spec.optional
    use_sampler = spec.adaptive and renderer is not None
    frame_metrics = {name: registry.get("metric", name) for name in metrics.frame}
    frame_metrics = {name: (m, m.factory()) for name, m in frame_metrics.items()}
    skipped_notes = [f"{name} skipped: {reason}" for name, reason in metrics.skipped.items()]
    rows, outputs, kept, masks = [], [], {}, []
    for t, frame in enumerate(inputs.frames):
        shown = frame.subset(visible & frame.channels)
        timing: dict = {}
        sampler_factory = _sampler_factory(renderer, inputs, job, t) if use_sampler else None
        try:
            filt, out, timing, samples = time_frame(filt, spec, job.backend, shown, t == 0, job.repeats,
                                                    sampler_factory, check=f"filter {job.filter!r}")
        except (Exception, SystemExit) as exc:
            rows.append(_row(job, inputs, t, frame, "error", _why(exc), timing=timing))
            tick(n - t)
            return JobResult(rows, kept)
        notes = list(skipped_notes)
        if inputs.repaired[t]:
            notes.append(f"{inputs.repaired[t]} non-finite input values repaired")
        scores = {}
        reference = inputs.references[t]
        variance = _variance(inputs, t)
        mask = emitter_mask(frame) if job.emitters == "exclude" else None
        masks.append(mask)
        if mask is not None and not mask.any():
            notes.append("every pixel sees an emitter: nothing to score with emitters excluded")
        if reference is not None:
            for name, (mspec, metric) in frame_metrics.items():
                try:
                    scores[name] = float(metric(out, reference, **_metric_inputs(mspec, variance, mask)))
                except Exception as exc:
                    notes.append(f"{name} failed: {short_error(exc, 120)}")
        outputs.append(out)
        if keep_outputs == "all" or (keep_outputs == "first" and t == 0):
            kept[t] = out
        row = _row(job, inputs, t, frame, "ok", "", scores=scores, timing=timing, samples=samples,
                   notes="; ".join(notes))
        if reference is not None:
            row.reference_noise = noise_floor(variance, mask)
            display = None if variance is None else display_variance(reference, variance)
            row.reference_noise_display = noise_floor(display, mask)
        rows.append(row)
        tick(1)
    for name in metrics.sequence:
        mspec = registry.get("metric", name)
        extra = {}
        if "reference_variance" in mspec.accepts:
            extra["reference_variance"] = [_variance(inputs, t) for t in range(n)]
        if "mask" in mspec.accepts:
            extra["mask"] = masks
        try:
            rows[-1].metrics[name] = float(mspec.factory()(outputs, inputs.references, **extra))
        except Exception as exc:
            rows[-1].notes = "; ".join(filter(None, [rows[-1].notes, f"{name} failed: {short_error(exc, 120)}"]))
    if job.timing and inputs.timing_frames:
        times, failures = time_real_resolutions(spec, job, inputs, renderer)
        for row in rows:
            for (w, h), ms in times.items():
                setattr(row, timing_column(w, h), ms)
        if failures:
            rows[-1].notes = "; ".join(filter(None, [rows[-1].notes, *failures]))
    return JobResult(rows, kept)


def emitter_mask(frame: Frame) -> np.ndarray | None:
    """Pixels to score: True where the first hit is not an emitter (None without ``emission``)."""
    if "emission" not in frame:
        return None
    return ~(np.asarray(frame["emission"]) > 0.0).any(axis=-1)


def _variance(inputs: GroupInputs, t: int):
    variances = inputs.reference_variances
    return variances[t] if t < len(variances) else None


def _metric_inputs(mspec, variance, mask) -> dict:
    extra = {}
    if "reference_variance" in mspec.accepts:
        extra["reference_variance"] = variance
    if "mask" in mspec.accepts:
        extra["mask"] = mask
    return extra


def time_real_resolutions(spec, job: Job, inputs: GroupInputs, renderer=None) -> tuple[dict, list]:
    """Per-frame time of the job's filter on the group's frames at real resolutions.

    For each (width, height) of ``inputs.timing_frames``: a fresh filter is built and called
    once on the first frame (compilation and, for a temporal filter, history), then timed on
    the last one with the timing protocol (:func:`time_frame`, ``job.repeats`` calls; an
    adaptive filter renders its extra samples at that resolution inside the timed calls).

    Returns
    -------
    times : dict
        (width, height) -> median milliseconds per frame.
    failures : list of str
        Notes for the resolutions that failed.
    """
    times, failures = {}, []
    visible = spec.requires | spec.optional
    for (w, h), frames in inputs.timing_frames.items():
        try:
            filt = spec.factory(backend=job.backend, **job.param_dict)
            filt.reset()
            for k, frame in enumerate(frames):
                make = None
                if spec.adaptive and renderer is not None and inputs.scene is not None:
                    make = _sampler_at(renderer, inputs, job, frame.meta.index, (w, h))
                shown = frame.subset(visible & frame.channels)
                repeats = job.repeats if k == len(frames) - 1 else 1
                filt, _, timing, _ = time_frame(filt, spec, job.backend, shown, False, repeats, make,
                                                check=f"filter {job.filter!r}")
            times[(w, h)] = timing["ms_median"]
        except (Exception, SystemExit) as exc:
            failures.append(f"timing at {w}x{h} failed: {_why(exc)}")
    return times, failures


def _sampler_at(renderer, inputs: GroupInputs, job: Job, t: int, resolution):
    def make():
        return renderer.sampler(inputs.scene, t, spp=job.spp, seed=job.seed, channels=inputs.channels,
                                resolution=resolution)

    return make


def time_frame(filt, spec, backend: str, frame: Frame, first: bool, repeats: int, sampler_factory=None,
               check: str | None = None):
    """The timing protocol for one frame.

    Parameters
    ----------
    filt : filter object
    spec : FilterSpec
    backend : str
    frame : Frame
        What the filter sees (its declared channels only).
    first : bool
        Whether this is the first frame (the compile/warm-up call is made and recorded).
    repeats : int
        Timed calls (>= 1).
    sampler_factory : callable, optional
        Returns a fresh sampler for each call of an adaptive filter.
    check : str, optional
        When given, every output (the warm-up's too) is validated, naming this owner.

    Returns
    -------
    filt : filter object
        The state to continue the sequence with.
    out : ndarray
        The output of the last timed call.
    timing : dict
        ``compile_ms`` (first frame), ``ms_median``, ``ms_min``, ``ms_max``, ``repeats`` and
        ``stage_ms`` (JSON) where the filter declares ``stage_timing``.
    samples : int
        Samples the output is made of (the sampler's count for adaptive filters).
    """
    new_sampler = sampler_factory or (lambda: None)

    def call(instance, sampler):
        start = time.perf_counter_ns()
        out = instance(frame, sampler=sampler)
        if backend == "cuda":
            from numba import cuda

            cuda.synchronize()
        ms = (time.perf_counter_ns() - start) / 1e6
        if check is not None:
            check_filter_output(out, frame, owner=check)
        return out, ms

    stateful = spec.temporal
    timing: dict = {"repeats": repeats}
    if first:
        warm = copy.deepcopy(filt) if stateful else filt
        _, timing["compile_ms"] = call(warm, new_sampler())
    times = []
    state = filt
    out = sampler = None
    for _ in range(repeats):
        instance = copy.deepcopy(filt) if stateful else filt
        sampler = new_sampler()
        out, ms = call(instance, sampler)
        times.append(ms)
        state = instance
    timing.update(ms_median=float(np.median(times)), ms_min=float(min(times)), ms_max=float(max(times)))
    stages = getattr(state, "stage_ms", None) if spec.stage_timing else None
    if stages:
        timing["stage_ms"] = json.dumps({k: round(float(v), 4) for k, v in stages.items()})
    if sampler is not None:
        samples = sampler.samples_used
    elif "spp" in frame:
        samples = int(frame["spp"].astype(np.int64).sum())
    else:
        samples = -1
    return state, out, timing, samples


def _sampler_factory(renderer, inputs: GroupInputs, job: Job, t: int):
    def make():
        return renderer.sampler(inputs.scene, t, spp=job.spp, seed=job.seed, channels=inputs.channels,
                                resolution=job.resolution)

    return make


def _why(exc: BaseException) -> str:
    if isinstance(exc, SystemExit):
        return f"SystemExit: the filter called sys.exit({exc.code!r})"
    return short_error(exc)


def _row(job: Job, inputs: GroupInputs, t: int, frame, status: str, message: str, *, scores=None, timing=None,
         samples=-1, notes="") -> Row:
    import numba

    timing = timing or {}
    quality = inputs.reference_quality[t] if 0 <= t < len(inputs.reference_quality) else None
    h, w = (frame.height, frame.width) if frame is not None else (-1, -1)
    if samples == -1 and frame is not None and status == "ok":
        samples = job.spp * h * w
    return Row(
        job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash, renderer=job.renderer,
        filter=job.filter, preset=job.preset, params=job.params, backend=job.backend, spp=job.spp, seed=job.seed,
        frame=t, width=w, height=h, status=status, message=message, notes=notes, samples_used=samples,
        compile_ms=timing.get("compile_ms", math.nan), ms_median=timing.get("ms_median", math.nan),
        ms_min=timing.get("ms_min", math.nan), ms_max=timing.get("ms_max", math.nan),
        repeats=timing.get("repeats", 0), stage_ms=timing.get("stage_ms", ""), threads=numba.get_num_threads(),
        machine=machine_label(), nonfinite_repaired=inputs.repaired[t] if 0 <= t < len(inputs.repaired) else 0,
        reference_spp=quality[0] if quality else job.reference_spp,
        reference_error=quality[1] if quality else math.nan,
        reference_hash=inputs.reference_hashes[t] if 0 <= t < len(inputs.reference_hashes) else "",
        metrics=dict(scores or {}),
    )


def job_error_rows(job: Job, message: str, frame: int = -1) -> list[Row]:
    """The one ``error`` row of a job that could not run (render failure, crash, timeout)."""
    return [Row(job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash,
                renderer=job.renderer, filter=job.filter, preset=job.preset, params=job.params,
                backend=job.backend, spp=job.spp, seed=job.seed, frame=frame, width=job.width, height=job.height,
                status="error", message=message, reference_spp=job.reference_spp)]


def skipped_row(job: Job, reason: str) -> Row:
    """The ``skipped`` row of a job the planner could not pair."""
    return Row(job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash,
               renderer=job.renderer, filter=job.filter, preset=job.preset, params=job.params,
               backend=job.backend, spp=job.spp, seed=job.seed, status="skipped", message=reason,
               reference_spp=job.reference_spp)
