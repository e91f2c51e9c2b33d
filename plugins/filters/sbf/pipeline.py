"""One SBF pass over a frame: pack (features, variance), candidate bank + SURE, smoothing, argmin."""

from __future__ import annotations

import time
from dataclasses import dataclass, field

import numba
import numpy as np

from .bank import smoothing_table, spatial_table, window_radius
from .layout import mark_noisy, pack
from .params import SBFParams
from .variance import samples_per_pixel, unknown_variance

#: taps of a row summed together by the kernels (tables get this many - 1 zero columns)
GROUP = 4
#: rows of candidates computed per chunk by the streaming kernels (ring = CHUNK + 2 R_s rows)
CHUNK = 16


@dataclass
class SBFResult:
    """What one pass computed.

    ``variance``, ``best`` and ``min_sure`` live in the caller's scratch (``work``): the next pass
    with the same ``work`` overwrites them.

    Attributes
    ----------
    output : ndarray (H, W, 3) float32
        The per-pixel selected candidate.
    variance : ndarray (H, W, 3) float32
        The variance of the pixel mean that SURE used (given or estimated).
    best : ndarray (H, W) int32
        Selected candidate index (0 where the pixel is noise-free).
    min_sure : ndarray (H, W) float64
        Smoothed SURE of the selected candidate (0 where noise-free).
    candidates : ndarray (K, 3, H, W) float32 or None
        Every candidate's filtered colour (planar); only with ``keep=True``.
    sure : ndarray (K, H, W) float64 or None
        Per-pixel SURE of every candidate, before smoothing; only with ``keep=True``.
    stage_ms : dict
        Milliseconds per stage.
    """

    output: np.ndarray
    variance: np.ndarray
    best: np.ndarray
    min_sure: np.ndarray
    candidates: np.ndarray | None = None
    sure: np.ndarray | None = None
    stage_ms: dict = field(default_factory=dict)


def _padded_table(table: np.ndarray) -> np.ndarray:
    """``table`` with GROUP - 1 zero columns appended to its last axis (float64, contiguous)."""
    extra = [(0, 0)] * (table.ndim - 1) + [(0, GROUP - 1)]
    return np.ascontiguousarray(np.pad(table, extra), dtype=np.float64)


def _ring(work: dict, name: str, shape: tuple, dtype) -> np.ndarray:
    a = work.get(name)
    if a is None or a.shape != shape:
        a = work[name] = np.zeros(shape, dtype)
    return a


def run_sbf(frame, params: SBFParams, kernels, work: dict | None = None,
            keep: bool = False) -> SBFResult:
    """Filter ``frame`` with the SBF candidate bank and per-pixel SURE selection.

    Parameters
    ----------
    frame : Frame
        With ``color``, ``variance``, ``normal``, ``albedo`` and ``depth``; ``spp`` is used
        when present (:mod:`.variance`).
    params : SBFParams
    kernels : module
        The backend's kernels (:mod:`.cpu` or :mod:`.cuda`).
    work : dict, optional
        Scratch buffers kept between calls (reused while the frame size is unchanged).
    keep : bool
        Also return every candidate and per-pixel SURE map (full-frame buffers: for tests and
        analysis; the default streams them through ring buffers of a few rows).

    Returns
    -------
    SBFResult

    References
    ----------
    T.-M. Li, Y.-T. Wu, Y.-Y. Chuang, "SURE-based optimization for adaptive sampling and
    reconstruction", ACM TOG 31(6) (SIGGRAPH Asia 2012).
    """
    work = {} if work is None else work
    t0 = time.perf_counter_ns()
    h, w = frame.shape
    table, first = spatial_table(params.scales)
    radius = np.array([window_radius(s) for s in params.scales], np.int64)
    stable = smoothing_table(params.sure_scale)
    rad = (stable.shape[0] - 1) // 2
    big = (table.shape[1] - 1) // 2
    pad = max(big, rad, params.variance_radius) + GROUP - 1
    slots = numba.get_num_threads()
    sigmas = (params.sigma_normal, params.sigma_albedo, params.sigma_depth)
    planes = pack(frame, sigmas, params.feature_var_floor, pad, work)
    var = planes["var"]
    unknown = unknown_variance(frame, var, planes["any_variance"], params.variance_source)
    if unknown.any():
        kernels.spatial_variance(planes["cpad"], planes["fpad"], planes["inside"], unknown,
                                 params.variance_radius, pad, var, slots)
        np.divide(var, samples_per_pixel(frame)[..., None], out=var, where=unknown[..., None] > 0)
    mark_noisy(var, pad, planes["valid"])
    n_k = len(params.scales)
    rows = h + 2 * rad if keep else min(CHUNK + 2 * rad, h + 2 * rad)
    cand = _ring(work, "cand", (n_k, 3, rows, w), np.float32)
    sure = _ring(work, "sure", (n_k, rows, w + 2 * pad), np.float64)
    out = np.empty((h, w, 3), np.float32)
    best = _ring(work, "best", (h, w), np.int32)
    min_sure = _ring(work, "min_sure", (h, w), np.float64)
    t1 = time.perf_counter_ns()
    kernels.sbf_pass(planes["cpad"], planes["fpad"], planes["inside"], planes["valid"], var,
                     _padded_table(table), first, radius, _padded_table(stable), pad, out, best,
                     min_sure, cand, sure, slots)
    t2 = time.perf_counter_ns()
    scale = planes["scale"]
    if scale != 1.0:
        out /= np.float32(scale)
        var /= np.float32(scale * scale)
        min_sure /= scale * scale
    result = SBFResult(out, var, best, min_sure)
    if keep:
        result.candidates = cand[:, :, :h].copy() / (np.float32(scale) if scale != 1.0 else 1)
        result.sure = sure[:, :h, pad:pad + w].copy() / (scale * scale)
    t3 = time.perf_counter_ns()
    result.stage_ms = {"features": (t1 - t0) / 1e6, "filter": (t2 - t1) / 1e6,
                       "output": (t3 - t2) / 1e6}
    return result
