"""References with known noise: rendered to a target error, with their per-pixel variance of the mean.

A Monte Carlo reference is not the true image: each pixel is a mean of ``N`` samples and has a
variance of the mean ``sigma^2 / N``. :func:`reference_record` renders a reference in fixed
**batches** of samples through the renderer's ``accumulate`` (the chunked-renderer protocol)
and estimates that variance by batch means: with batch sums ``S_k`` of ``n_k`` samples
(``N = sum n_k``, ``K`` batches),

    mean = sum S_k / N,
    var_of_mean = (sum S_k^2 / n_k - (sum S_k)^2 / N) / ((K - 1) N),

which is unbiased for independent batches whatever their sizes (each ``S_k / n_k`` has
variance ``sigma^2 / n_k``). The batch size depends only on the sample cap and the renderer's
``sample_block`` (``max(1, cap // BATCHES_AT_CAP)`` rounded up to whole blocks: samples
stratified together are correlated, and a batch holding part of a block would not be
independent of the batch holding the rest; the path tracer's pixel-area references stratify
blocks of four, and batches of one sample overstated their variance 1.5x), never on how the
work is chunked or distributed, so the same inputs give the same image and variance bit for bit.

With a ``target`` the reference stops as soon as its **median relative standard error**
(:func:`relative_error`) is at or below the target, or at the cap: the first check comes after
``MIN_BATCHES`` batches, the next at the sample count that the measured error predicts
(``N (error / target)^2``, rounded up to whole batches), and so on. The achieved error and
samples are part of the record and of every result row.

Renderers that are not chunked give a reference of unknown noise (``variance`` None), unless
they declare ``reference_noise`` and state it themselves (stored captures); analytic references
(``spp`` 0) have zero variance.
"""

from __future__ import annotations

import math
import warnings
from collections.abc import Callable
from dataclasses import dataclass

import numpy as np

from harness.cache import array_hash
from harness.renders import DEFAULT_CHUNK, REFERENCE_SEED

#: batches of a reference rendered up to its sample cap (the batch size is cap // this)
BATCHES_AT_CAP = 64
#: batches before the first check of the error against a target
MIN_BATCHES = 16
#: pixels darker than this (mean over channels) are left out of the relative error
RELATIVE_ERROR_FLOOR = 1e-3


@dataclass
class ReferenceRecord:
    """A reference image with what is known about its noise.

    Attributes
    ----------
    image : ndarray (H, W, 3) float32
        The reference.
    variance : ndarray (H, W, 3) float32 or None
        Per-pixel variance of the mean (0 for analytic references; None when the renderer
        cannot say, i.e. it is not chunked).
    spp : int
        Samples per pixel actually rendered (0: analytic).
    error : float
        Median relative standard error achieved (:func:`relative_error`; 0 analytic, NaN unknown).
    target : float
        The target it was rendered to (0: a fixed sample count).
    """

    image: np.ndarray
    variance: np.ndarray | None
    spp: int
    error: float
    target: float = 0.0

    @property
    def hash(self) -> str:
        return array_hash(self.image)


def batch_size(cap: int, block: int = 1) -> int:
    """Samples per batch of a reference capped at ``cap`` samples per pixel: ``cap // BATCHES_AT_CAP``
    rounded up to whole blocks of ``block`` samples (the renderer's ``sample_block``)."""
    block = max(1, int(block))
    return -(-max(1, int(cap) // BATCHES_AT_CAP) // block) * block


class BatchMoments:
    """Running sums of a reference's batches: ``sum S_k``, ``sum S_k^2 / n_k``, samples and batches.

    Parameters
    ----------
    shape : tuple
        (H, W, 3).
    """

    def __init__(self, shape):
        self.total = np.zeros(shape, np.float64)
        self.squares = np.zeros(shape, np.float64)
        self.samples = 0
        self.batches = 0

    def add(self, batch_sum: np.ndarray, count: int) -> None:
        """Add the float64 sum of one batch of ``count`` samples (batches in sample order)."""
        part = np.asarray(batch_sum, np.float64)
        self.total = self.total + part
        self.squares = self.squares + part * part / count
        self.samples += int(count)
        self.batches += 1

    def mean(self) -> np.ndarray:
        return self.total / max(self.samples, 1)

    def variance_of_mean(self) -> np.ndarray:
        """The batch-means estimate of the per-pixel variance of the mean (zeros below 2 batches)."""
        if self.batches < 2:
            return np.zeros_like(self.total)
        n = float(self.samples)
        spread = np.maximum(self.squares - self.total * self.total / n, 0.0)
        return spread / ((self.batches - 1) * n)

    def state(self) -> dict:
        return {"sum": self.total, "squares": self.squares, "done": np.asarray(self.samples),
                "batches": np.asarray(self.batches)}

    @classmethod
    def from_state(cls, state: dict, shape) -> BatchMoments | None:
        """Rebuild from :meth:`state` arrays, or None when they do not fit ``shape``."""
        out = cls(shape)
        total, squares = state.get("sum"), state.get("squares")
        if not all(isinstance(a, np.ndarray) and a.shape == tuple(shape) and a.dtype == np.float64
                   for a in (total, squares)):
            return None
        out.total, out.squares = total, squares
        out.samples, out.batches = int(np.asarray(state.get("done", -1))), int(np.asarray(state.get("batches", -1)))
        if out.samples < 1 or out.batches < 1:
            return None
        return out


def relative_error(mean: np.ndarray, variance: np.ndarray) -> float:
    """Median over pixels of the relative standard error of the mean.

    Per pixel, ``sqrt(mean_c variance) / mean_c mean`` over the three channels; pixels whose mean
    is below :data:`RELATIVE_ERROR_FLOOR` (black background, deep shadow) are left out. 0 when
    no pixel is left.
    """
    level = np.asarray(mean, np.float64).mean(axis=-1)
    spread = np.sqrt(np.maximum(np.asarray(variance, np.float64).mean(axis=-1), 0.0))
    lit = level > RELATIVE_ERROR_FLOOR
    if not lit.any():
        return 0.0
    return float(np.median(spread[lit] / level[lit]))


def reference_record(
    store,
    scene,
    renderer: str,
    frame_index: int,
    *,
    spp: int,
    target: float = 0.0,
    seed: int = REFERENCE_SEED,
    chunk: int = DEFAULT_CHUNK,
    progress: Callable[[int], None] | None = None,
    map_chunks: Callable | None = None,
) -> ReferenceRecord:
    """Load or render a reference of ``frame_index`` with its variance of the mean.

    Parameters
    ----------
    store : harness.renders.RenderStore
    scene : Scene or str
    renderer : str
    frame_index : int
    spp : int
        Samples per pixel, or the cap when ``target`` is set (0: analytic, where allowed).
    target : float
        Median relative standard error to stop at (0: render exactly ``spp``).
    seed : int
        Seed of the reference's samples (independent of every noisy frame's seed).
    chunk : int
        Samples between checkpoints (a killed render resumes from the last one).
    progress : callable, optional
        Called with the number of samples just added.
    map_chunks : callable, optional
        ``map_chunks(ranges) -> iterable of float64 sums in the same order`` (an executor).

    Returns
    -------
    ReferenceRecord
    """
    if not (isinstance(target, (int, float)) and math.isfinite(target) and target >= 0):
        raise ValueError(f"reference target must be a finite number >= 0, got {target!r}")
    if map_chunks is not None and seed != REFERENCE_SEED:
        raise ValueError("map_chunks renders with the store's reference seed; give no other seed with it")
    spec = store.registry.get("renderer", renderer)
    scene = store.scene(scene) if isinstance(scene, str) else scene
    if spp == 0 or not spec.chunked:
        image = store.reference(scene, renderer, frame_index, spp=spp, chunk=chunk, progress=progress,
                                map_chunks=map_chunks)
        if spec.reference_noise:  # stored references say their own noise (None: unknown)
            variance = store.renderer(renderer).reference_variance(scene, frame_index)
            error = relative_error(image, variance) if variance is not None else math.nan
            return ReferenceRecord(image, variance, int(spp), error, float(target))
        if spp == 0:
            return ReferenceRecord(image, np.zeros_like(image), 0, 0.0, float(target))
        return ReferenceRecord(image, None, int(spp), math.nan, float(target))
    if isinstance(spp, bool) or not isinstance(spp, int) or spp < 1:
        raise ValueError(f"reference spp of renderer {renderer!r} must be an integer >= 1, got {spp!r}")
    batch = batch_size(spp, spec.sample_block)
    key = store.key("reference-moments", scene, renderer, frame_index, spp=spp, seed=seed,
                    target=float(target), batch=batch)
    w, h = store.resolution(scene)
    stored = store.cache.load("references", key)
    if stored is not None and _valid(stored, (h, w, 3)):
        if progress is not None:
            progress(int(stored["spp"]))
        return ReferenceRecord(stored["reference"], stored["variance"], int(stored["spp"]), float(stored["error"]),
                               float(target))
    moments, goal = _resume(store, key, (h, w, 3), spp, batch, target)
    if progress is not None and moments.samples:
        progress(moments.samples)
    while True:
        ranges = [(first, min(batch, goal - first)) for first in range(moments.samples, goal, batch)]
        if map_chunks is not None:
            sums = map_chunks(ranges)
        else:
            sums = (_accumulate(store, scene, renderer, frame_index, first, count, seed) for first, count in ranges)
        last_saved = moments.samples
        for (_, count), part in zip(ranges, sums):
            moments.add(part, count)
            if progress is not None:
                progress(count)
            if moments.samples - last_saved >= chunk and moments.samples < spp:
                store.cache.store("partial", key, {**moments.state(), "goal": np.asarray(goal)})
                last_saved = moments.samples
        mean, variance = moments.mean(), moments.variance_of_mean()
        error = relative_error(mean, variance)
        goal = _next_goal(moments.samples, error, spp, batch, target)
        if goal <= moments.samples:
            break
        store.cache.store("partial", key, {**moments.state(), "goal": np.asarray(goal)})
    record = ReferenceRecord(mean.astype(np.float32), variance.astype(np.float32), moments.samples, error,
                             float(target))
    store.cache.store("references", key, {"reference": record.image, "variance": record.variance,
                                          "spp": np.asarray(record.spp), "error": np.asarray(record.error)})
    store.cache.discard("partial", key)
    return record


def _next_goal(done: int, error: float, cap: int, batch: int, target: float) -> int:
    """The sample count of the next check (``done`` when the reference is finished)."""
    if target <= 0 or done >= cap or error <= target:
        return done
    predicted = done * (error / target) ** 2
    return min(cap, max(done + batch, int(math.ceil(predicted / batch)) * batch))


def _resume(store, key, shape, cap, batch, target):
    """The moments of a checkpoint and the sample count it was heading to; fresh ones without."""
    first_goal = cap if target <= 0 else min(cap, MIN_BATCHES * batch)
    partial = store.cache.load("partial", key)
    if partial is None:
        return BatchMoments(shape), first_goal
    moments = BatchMoments.from_state(partial, shape)
    goal = int(np.asarray(partial.get("goal", -1)))
    if moments is None or not (moments.samples < goal <= cap):
        store.cache.discard("partial", key)
        warnings.warn(f"reference checkpoint {store.cache.path('partial', key)} is invalid; rendering the "
                      "reference again", stacklevel=3)
        return BatchMoments(shape), first_goal
    return moments, goal


def _accumulate(store, scene, renderer, frame_index, first, count, seed) -> np.ndarray:
    total = store.renderer(renderer).accumulate(scene, frame_index, first_sample=first, count=count, seed=seed,
                                                resolution=store.resolution(scene))
    return np.asarray(total, np.float64)


def _valid(stored: dict, shape) -> bool:
    image, variance = stored.get("reference"), stored.get("variance")
    return (isinstance(image, np.ndarray) and image.shape == shape and image.dtype == np.float32
            and isinstance(variance, np.ndarray) and variance.shape == shape and "spp" in stored
            and "error" in stored)


def noise_floor(variance: np.ndarray | None, mask: np.ndarray | None = None) -> float:
    """RMS standard error of a reference over the scored pixels: the RMSE a perfect output would show.

    Parameters
    ----------
    variance : ndarray (H, W, 3) or None
        Per-pixel variance of the mean (None: unknown, NaN returned).
    mask : ndarray (H, W) bool, optional
        Pixels scored (default all).
    """
    if variance is None:
        return math.nan
    var = np.asarray(variance, np.float64)
    if mask is not None:
        var = var[np.asarray(mask, bool)]
    return float(np.sqrt(np.mean(var))) if var.size else math.nan


__all__ = ["BATCHES_AT_CAP", "MIN_BATCHES", "BatchMoments", "ReferenceRecord", "batch_size", "noise_floor",
           "reference_record", "relative_error"]
