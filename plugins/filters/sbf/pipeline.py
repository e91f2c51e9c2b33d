"""One SBF pass over a frame: features, candidate bank + SURE, smoothing, argmin selection."""

from __future__ import annotations

import importlib
import time
from dataclasses import dataclass, field

import numpy as np

from .bank import smoothing_table, spatial_table
from .features import guide_features, noisy_mask
from .params import SBFParams
from .variance import samples_per_pixel, unknown_variance


@dataclass
class SBFResult:
    """What one pass computed.

    Attributes
    ----------
    output : ndarray (H, W, 3) float32
        The per-pixel selected candidate.
    candidates : ndarray (K, 3, H, W) float32
        Every candidate's filtered colour (planar).
    sure : ndarray (K, H, W) float64
        Per-pixel SURE of every candidate, before smoothing.
    variance : ndarray (3, H, W) float32
        The variance of the pixel mean that SURE used (given or estimated).
    best : ndarray (H, W) int32
        Selected candidate index (0 where the pixel is noise-free).
    min_sure : ndarray (H, W) float64
        Smoothed SURE of the selected candidate (0 where noise-free).
    stage_ms : dict
        Milliseconds per stage.
    """

    output: np.ndarray
    candidates: np.ndarray
    sure: np.ndarray
    variance: np.ndarray
    best: np.ndarray
    min_sure: np.ndarray
    stage_ms: dict = field(default_factory=dict)


def kernels(backend: str):
    """The kernel module of ``backend`` (``cpu`` or ``cuda``), imported on first use."""
    if backend not in ("cpu", "cuda"):
        raise ValueError(f"sbf: unsupported backend {backend!r}; use 'cpu' or 'cuda'")
    return importlib.import_module(f"{__package__}.{backend}")


def run_sbf(frame, params: SBFParams, backend: str = "cpu") -> SBFResult:
    """Filter ``frame`` with the SBF candidate bank and per-pixel SURE selection.

    Parameters
    ----------
    frame : Frame
        With ``color``, ``variance``, ``normal``, ``albedo`` and ``depth``; ``spp`` is used
        when present (:mod:`.variance`).
    params : SBFParams
    backend : {"cpu", "cuda"}

    Returns
    -------
    SBFResult

    References
    ----------
    T.-M. Li, Y.-T. Wu, Y.-Y. Chuang, "SURE-based optimization for adaptive sampling and
    reconstruction", ACM TOG 31(6) (SIGGRAPH Asia 2012).
    """
    k = kernels(backend)
    t0 = time.perf_counter_ns()
    h, w = frame.shape
    color = np.ascontiguousarray(np.moveaxis(frame["color"], -1, 0), dtype=np.float32)
    var = np.maximum(np.moveaxis(frame["variance"], -1, 0), 0)
    var = np.ascontiguousarray(var, dtype=np.float32)
    feat = guide_features(frame, params.sigma_normal, params.sigma_albedo, params.sigma_depth,
                          params.feature_var_floor)
    unknown = unknown_variance(frame, params.variance_source)
    if unknown.any():
        k.spatial_variance(color, feat, params.variance_radius, unknown, var)
        var = np.where(unknown[None] > 0, var / samples_per_pixel(frame)[None], var)
        var = np.ascontiguousarray(var, dtype=np.float32)
    noisy = noisy_mask(var)
    table, first = spatial_table(params.scales)
    n_k = len(params.scales)
    candidates = np.empty((n_k, 3, h, w), np.float32)
    sure = np.empty((n_k, h, w), np.float64)
    t1 = time.perf_counter_ns()
    k.candidate_bank(color, var, feat, noisy, table, first, candidates, sure)
    t2 = time.perf_counter_ns()
    out = np.empty((3, h, w), np.float32)
    best = np.empty((h, w), np.int32)
    min_sure = np.empty((h, w), np.float64)
    k.smooth_and_select(color, feat, noisy, smoothing_table(params.sure_scale), candidates, sure,
                        out, best, min_sure)
    output = np.ascontiguousarray(np.moveaxis(out, 0, -1))
    t3 = time.perf_counter_ns()
    stages = {"features": (t1 - t0) / 1e6, "bank_sure": (t2 - t1) / 1e6,
              "smooth_select": (t3 - t2) / 1e6}
    return SBFResult(output, candidates, sure, var, best, min_sure, stages)
