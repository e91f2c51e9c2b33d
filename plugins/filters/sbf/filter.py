"""The SBF filter object: fixed mode (filter the given frame) and adaptive mode (spend samples)."""

from __future__ import annotations

import dataclasses
import time

import numpy as np

from harness import constant_depth, load_backend

from .adaptive import allocate, sampling_weight, split_budget
from .params import SBFParams
from .pipeline import run_sbf

BACKENDS = ("cpu", "cuda")


class SBFFilter:
    """SURE-based filter selection (Li, Wu & Chuang 2012) with optional adaptive sampling.

    Parameters
    ----------
    backend : {"cpu", "cuda"}
    **params
        See :class:`.params.SBFParams`; an unknown name raises ``TypeError`` naming it.

    Attributes
    ----------
    stage_ms : dict
        Milliseconds per stage of the last call (summed over passes in adaptive mode).
    samples_added : int
        Extra samples requested from the sampler in the last call (0 in fixed mode).
    last_mode : str
        The mode the last call ran in: ``adaptive`` needs a sampler, and falls back to
        ``fixed`` (filtering the given frame) when called with ``sampler=None``.
    last_result : SBFResult
        The final pass of the last call (selection, variance; every candidate and SURE map
        too when ``keep_candidates`` is set).
    keep_candidates : bool
        Keep every candidate and per-pixel SURE map of the last pass in ``last_result`` (full
        frames: 180 bytes per pixel for the paper's bank; off by default, the kernels then
        stream them through ring buffers of a few rows).
    """

    def __init__(self, backend: str = "cpu", **params):
        unknown = sorted(set(params) - set(SBFParams.__dataclass_fields__))
        if unknown:
            raise TypeError(f"sbf: unknown parameter(s) {unknown}")
        self.kernels = load_backend(__package__, backend, BACKENDS, owner="sbf")
        self.backend = backend
        self.params = SBFParams(**params)
        self.keep_candidates = False
        self._work: dict = {}
        self.stage_ms: dict = {}
        self.samples_added = 0
        self.last_mode = self.params.mode
        self.last_result = None

    def reset(self) -> None:
        """SBF keeps no history."""

    def __call__(self, frame, sampler=None) -> np.ndarray:
        if self.params.mode == "adaptive" and sampler is not None:
            return self._adaptive(frame, sampler)
        self.last_mode = "fixed"
        self.samples_added = 0
        self.last_result = self._pass(frame)
        self.stage_ms = dict(self.last_result.stage_ms)
        return self.last_result.output

    def _adaptive(self, frame, sampler) -> np.ndarray:
        """Filter, add samples where ``minSURE / luminance^2`` is large, repeat; filter again.

        The sampler's frame supplies colour, variance and ``spp``; the guide features are taken
        from ``frame`` when the sampler's frame lacks them.
        """
        p = self.params
        self.last_mode = "adaptive"
        self.samples_added = 0
        current = sampler.frame
        if current.shape != frame.shape:
            raise ValueError(f"sbf: sampler frame is {current.shape}, frame is {frame.shape}")
        guides = {n: frame[n] for n in ("normal", "albedo", "depth") if n not in current}
        current = current.replace(**guides) if guides else current
        totals: dict = {}
        budget = int(round(p.extra_spp * frame.height * frame.width))
        for part in split_budget(budget, p.passes):
            result = self._pass(current)
            _add_stages(totals, result.stage_ms)
            t0 = time.perf_counter_ns()
            spp = current["spp"].astype(np.int64)
            room = (np.maximum(p.max_spp_per_pixel - spp, 0) if p.max_spp_per_pixel > 0
                    else np.full(frame.shape, part, np.int64))
            noisy = (result.variance > 0).any(axis=-1)
            room = room * noisy if noisy.any() else room  # noise-free pixels need no samples
            minimum = 1 if part >= int(np.count_nonzero(room)) else 0
            spp_map = allocate(sampling_weight(result.min_sure, result.output), part, room, minimum)
            _add_stages(totals, {"allocate": (time.perf_counter_ns() - t0) / 1e6})
            t0 = time.perf_counter_ns()
            added = sampler.add_samples(spp_map.astype(np.int32))
            _add_stages(totals, {"add_samples": (time.perf_counter_ns() - t0) / 1e6})
            self.samples_added += int(spp_map.sum())
            guides = {n: current[n] for n in ("normal", "albedo", "depth") if n not in added}
            current = added.replace(**guides) if guides else added
        self.last_result = self._pass(current)
        _add_stages(totals, self.last_result.stage_ms)
        self.stage_ms = totals
        return self.last_result.output


    def _pass(self, frame):
        params = self.params
        if "depth" not in frame:  # no depth feature: every pixel at depth 1 (the depth term is 0)
            frame = frame.replace(depth=constant_depth(frame.shape))
        if "variance" not in frame:  # no variance channel: estimated from the image (variance.py)
            frame = frame.replace(variance=np.zeros((*frame.shape, 3), np.float32))
            params = dataclasses.replace(params, variance_source="spatial")
        return run_sbf(frame, params, self.kernels, self._work, keep=self.keep_candidates)


def _add_stages(totals: dict, stages: dict) -> None:
    for name, ms in stages.items():
        totals[name] = totals.get(name, 0.0) + ms
