"""One job: the timing protocol, validation of the outputs, metrics, and the job's rows.

No I/O and no scheduling: a job gets its rendered inputs and returns rows (and, on request,
outputs); an executor decides where it runs.

Each frame goes through the timing protocol (:mod:`harness.timer`); validation, metrics and
any I/O happen outside the timed region.

Fault handling: a filter that fails to build, raises (``sys.exit`` included), returns a wrong
shape or dtype, or non-finite values gives an ``error`` row with a short message.

Inputs are read-only: a filter sees read-only copies of its channels (made outside the timed
region), so one that writes into them anyway (after ``setflags(write=True)``) changes neither the
group's shared frames nor another job's input; the write is detected (its copies no longer equal
the frame) and the job ends with an ``error`` row naming the channels written.

Metrics receive what their spec ``accepts``: the reference's variance of the mean (for the
bias correction) and the mask of scored pixels (emitters left out unless the job includes
them). A sequence metric is scored once, on the last frame's row; one that declares
``per_frame`` is also scored on each pair of frames (t - 1, t), on frame t's row
(:func:`harness.rows.per_frame_column`).

A job whose ``timing`` names real resolutions also times its filter on the group's frames of
those sizes (:func:`harness.timer.time_real_resolutions`), after its quality frames.
"""

from __future__ import annotations

import math
from collections.abc import Callable
from dataclasses import dataclass, field
from typing import Any

import numpy as np

from harness.buffers import Frame
from harness.errors import filter_error, short_error
from harness.images import display_variance
from harness.machine import machine_label
from harness.plan import Job, MetricPlan
from harness.references import noise_floor
from harness.rows import Row, per_frame_column, timing_column
from harness.timer import sampler_factory, time_frame, time_real_resolutions


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
        (:func:`harness.real_resolutions.timing_frames`).
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


def run_job(registry, job: Job, inputs: GroupInputs, metrics: MetricPlan, **options) -> JobResult:
    """Run one job over every frame of its group (:func:`_run_job`), its rows naming the guides
    the filter had (``guides``)."""
    result = _run_job(registry, job, inputs, metrics, **options)
    if inputs.frames:
        spec = registry.get("filter", job.filter)
        guides = spec.guides_used(inputs.frames[0].channels, [f.meta for f in inputs.frames])
        for row in result.rows:
            row.guides = guides
    return result


def _run_job(
    registry,
    job: Job,
    inputs: GroupInputs,
    metrics: MetricPlan,
    *,
    renderer=None,
    keep_outputs: str | frozenset = "none",
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
    keep_outputs : {"none", "first", "all"} or collection of int
        Which outputs to return with the rows (a collection: those frame indices).
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
        return JobResult([_row(job, inputs, -1, first, "error", f"filter could not be built: {filter_error(exc)}")])
    visible = spec.requires | spec.optional
    use_sampler = spec.adaptive and renderer is not None
    frame_metrics = {name: registry.get("metric", name) for name in metrics.frame}
    frame_metrics = {name: (m, m.factory()) for name, m in frame_metrics.items()}
    skipped_notes = [f"{name} skipped: {reason}" for name, reason in metrics.skipped.items()]
    rows, outputs, kept, masks = [], [], {}, []
    for t, frame in enumerate(inputs.frames):
        shown = read_only_copy(frame, visible & frame.channels)
        timing: dict = {}
        make = sampler_factory(renderer, inputs, job, t, job.resolution) if use_sampler else None
        try:
            filt, out, timing, samples = time_frame(filt, spec, job.backend, shown, t == 0, job.repeats,
                                                    make, check=f"filter {job.filter!r}")
        except (Exception, SystemExit) as exc:
            rows.append(_row(job, inputs, t, frame, "error", filter_error(exc), timing=timing))
            tick(n - t)
            return JobResult(rows, kept)
        written = changed_channels(shown, frame)
        if written:
            rows.append(_row(job, inputs, t, frame, "error", f"filter {job.filter!r} wrote into its input channel(s) "
                             f"{written}: inputs are read-only; copy an array before changing it", timing=timing))
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
        if keep_outputs == "all" or (keep_outputs == "first" and t == 0) or (
                not isinstance(keep_outputs, str) and t in keep_outputs):
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
        if name in metrics.per_frame:
            _score_per_frame(rows, name, mspec.factory(), outputs, inputs.references, extra)
    if job.timing and inputs.timing_frames:
        times, failures = time_real_resolutions(spec, job, inputs, renderer)
        for row in rows:
            for (w, h), ms in times.items():
                setattr(row, timing_column(w, h), ms)
        if failures:
            rows[-1].notes = "; ".join(filter(None, [rows[-1].notes, *failures]))
    return JobResult(rows, kept)


def _score_per_frame(rows: list, name: str, metric, outputs: list, references: list, extra: dict) -> None:
    """A ``per_frame`` sequence metric on each pair of frames (t - 1, t), on row t (:func:`per_frame_column`)."""
    column = per_frame_column(name)
    for t in range(1, len(outputs)):
        if references[t - 1] is None or references[t] is None:
            continue
        pair = {key: values[t - 1:t + 1] for key, values in extra.items()}
        try:
            rows[t].metrics[column] = float(metric(outputs[t - 1:t + 1], references[t - 1:t + 1], **pair))
        except Exception as exc:
            rows[t].notes = "; ".join(filter(None, [rows[t].notes, f"{column} failed: {short_error(exc, 120)}"]))


def read_only_copy(frame: Frame, names) -> Frame:
    """A frame of read-only copies of ``names`` (and ``color``) of ``frame``: what a filter is handed."""
    arrays = {}
    for name in sorted(set(names) | {"color"}):
        array = np.array(frame[name], copy=True)
        array.flags.writeable = False
        arrays[name] = array
    return Frame(arrays, frame.meta)


def changed_channels(seen: Frame, frame: Frame) -> list[str]:
    """The channels of ``seen`` (a :func:`read_only_copy`) whose values no longer equal ``frame``'s."""
    changed = []
    for name in sorted(seen.channels):
        a, b = seen[name], frame[name]
        same = np.array_equal(a, b, equal_nan=True) if a.dtype.kind == "f" else np.array_equal(a, b)
        if not same:
            changed.append(name)
    return changed


def emitter_mask(frame: Frame) -> np.ndarray | None:
    """Pixels to score: True where neither the pixel's first hit nor that of any of its eight
    neighbours is an emitter (None without ``emission``).

    The ring of neighbours goes too because a pixel-area reference is box-filtered over the
    pixel: an edge pixel of a lamp holds part of the lamp's HDR radiance, which a frame traced
    through the pixel centre does not see, and whose noise in a 64-spp Cornell reference held
    93% of the reference's variance over the scored pixels.
    """
    if "emission" not in frame:
        return None
    lit = np.pad((np.asarray(frame["emission"]) > 0.0).any(axis=-1), 1)
    h, w = lit.shape[0] - 2, lit.shape[1] - 2
    near = np.zeros((h, w), bool)
    for dy in range(3):
        for dx in range(3):
            near |= lit[dy:dy + h, dx:dx + w]
    return ~near


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


def _row(job: Job, inputs: GroupInputs, t: int, frame, status: str, message: str, *, scores=None, timing=None,
         samples=-1, notes="") -> Row:
    import numba

    timing = timing or {}
    quality = inputs.reference_quality[t] if 0 <= t < len(inputs.reference_quality) else None
    h, w = (frame.height, frame.width) if frame is not None else (-1, -1)
    if samples == -1 and frame is not None and status == "ok":
        samples = job.spp * h * w
    return Row(
        job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash, tier=job.tier,
        renderer=job.renderer, filter=job.filter, preset=job.preset, params=job.params, backend=job.backend,
        spp=job.spp, seed=job.seed,
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
    return [Row(job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash, tier=job.tier,
                renderer=job.renderer, filter=job.filter, preset=job.preset, params=job.params,
                backend=job.backend, spp=job.spp, seed=job.seed, frame=frame, width=job.width, height=job.height,
                status="error", message=message, reference_spp=job.reference_spp)]


def skipped_row(job: Job, reason: str) -> Row:
    """The ``skipped`` row of a job the planner could not pair."""
    return Row(job_id=job.job_id, task=job.task, scene=job.scene, scene_hash=job.scene_hash, tier=job.tier,
               renderer=job.renderer, filter=job.filter, preset=job.preset, params=job.params,
               backend=job.backend, spp=job.spp, seed=job.seed, status="skipped", message=reason,
               reference_spp=job.reference_spp)
