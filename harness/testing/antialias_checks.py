"""Conformance checks for filters of the ``antialias`` task (run in addition to the filter checks).

An anti-aliasing filter sees one shading sample per pixel at the frame's sub-pixel jitter
(``FrameMeta.jitter``, pixels in [-0.5, 0.5)), and motion in the harness's convention: from the
pixel centre to where the surface seen at the pixel's (jittered) sample was in the previous
frame's unjittered image, so a static surface has ``motion == jitter``; the background (depth
``inf``) has the camera's motion. Each check is ``check(spec, backend)`` and raises
``AssertionError`` naming the filter.
"""

from __future__ import annotations

import numpy as np

from harness.buffers import FrameMeta, check_filter_output
from harness.jitter import JITTER_CYCLE, halton_jitter
from harness.testing.frames import make_frame

#: the first 16 points of the Halton (2, 3) sequence (index 1..16), centred on the pixel
_JITTER = [halton_jitter(t) for t in range(JITTER_CYCLE)]


def _channels(spec) -> frozenset:
    return frozenset(spec.requires | spec.optional)


def _jittered_frame(spec, t: int, color: np.ndarray, motion: np.ndarray | None = None, cut: bool | None = None):
    """A frame of a static flat surface (constant G-buffer) with Halton jitter ``t`` and ``color``."""
    h, w = color.shape[:2]
    base = make_frame(h, w, _channels(spec), index=t, color=0.5, constant_features=True)
    jitter = _JITTER[t % 16]
    arrays = {"color": np.ascontiguousarray(color, np.float32)}
    if "motion" in base:
        arrays["motion"] = (np.broadcast_to(np.float32(jitter), (h, w, 2)) if motion is None else motion).astype(
            np.float32)
    meta = FrameMeta(index=t, scene="conformance-aa", jitter=jitter, camera_cut=(t == 0) if cut is None else cut)
    return base.replace(meta=meta, **arrays)


def _run(spec, backend, frames) -> list[np.ndarray]:
    f = spec.factory(backend=backend, **dict(spec.params))
    f.reset()
    outs = []
    for frame in frames:
        out = f(frame, sampler=None)
        check_filter_output(out, frame, owner=f"filter {spec.name!r}")
        outs.append(np.array(out, copy=True))
    return outs


def check_aa_constant_under_jitter_and_motion(spec, backend):
    """A constant image stays constant across jittered frames, static or under any motion."""
    value = np.array([0.25, 0.5, 0.75], np.float32)
    h, w = 12, 16
    color = np.broadcast_to(value, (h, w, 3))
    rng = np.random.default_rng(7)
    static = [_jittered_frame(spec, t, color) for t in range(6)]
    moving = [_jittered_frame(spec, t, color, motion=rng.normal(0.0, 3.0, (h, w, 2))) for t in range(6)]
    for label, frames in (("static", static), ("moving", moving)):
        for t, out in enumerate(_run(spec, backend, frames)):
            err = float(np.abs(out - value).max())
            assert err <= 1e-4 * 0.75 + 1e-6, (
                f"filter {spec.name!r} changed a constant image by {err} (frame {t}, {label}, jitter {_JITTER[t]})"
            )


def check_aa_camera_cut_drops_history(spec, backend):
    """On a frame marked ``camera_cut`` the output does not depend on the frames before it."""
    rng = np.random.default_rng(8)
    h, w = 10, 14
    frames = [_jittered_frame(spec, t, rng.uniform(0.0, 1.0, (h, w, 3))) for t in range(4)]
    cut = _jittered_frame(spec, 4, rng.uniform(0.0, 1.0, (h, w, 3)), cut=True)
    after = _run(spec, backend, frames + [cut])[-1]
    fresh = _run(spec, backend, [cut])[0]
    assert np.array_equal(after, fresh), (
        f"filter {spec.name!r}: output on a camera cut depends on earlier frames "
        f"(max diff {np.abs(after - fresh).max()})"
    )


def _edges(x: np.ndarray, y: np.ndarray) -> np.ndarray:
    """A test pattern of the unit square grid: a slanted edge and a thin slanted line (values 0.1-0.9)."""
    edge = (y - 0.37 * x - 3.1) > 0.0
    line = np.abs(x - 0.6 * y - 9.3) < 0.35
    value = np.where(edge, 0.8, 0.15)
    value = np.where(line, 0.05, value)
    return np.stack([value, 0.6 * value + 0.1, 0.9 - 0.5 * value], axis=-1)


def check_aa_static_sequence_converges(spec, backend):
    """A temporal AA filter, on a static jittered sequence, ends closer to the box-filtered image
    than a single aliased frame is (after 16 frames, at most 0.8 of the aliased frame's error)."""
    if not spec.temporal:
        return
    h, w = 18, 24
    jj, ii = np.meshgrid(np.arange(w, dtype=np.float64), np.arange(h, dtype=np.float64))
    s = 16  # reference: 16 x 16 box-filtered samples per pixel
    offsets = (np.arange(s) + 0.5) / s - 0.5
    ref = np.zeros((h, w, 3))
    for oy in offsets:
        for ox in offsets:
            ref += _edges(jj + ox, ii + oy)
    ref /= s * s
    frames = [_jittered_frame(spec, t, _edges(jj + _JITTER[t % 16][0], ii + _JITTER[t % 16][1])) for t in range(17)]
    outs = _run(spec, backend, frames)

    def rmse(a):
        return float(np.sqrt(np.mean((a - ref) ** 2)))

    aliased = max(rmse(frames[0]["color"]), rmse(frames[16]["color"]))
    final = rmse(outs[16])
    assert final <= 0.8 * aliased, (
        f"filter {spec.name!r}: after 16 static jittered frames the error to the box-filtered image is "
        f"{final:.4f}, the aliased input's {aliased:.4f}"
    )


ANTIALIAS_CHECKS = [
    check_aa_constant_under_jitter_and_motion,
    check_aa_camera_cut_drops_history,
    check_aa_static_sequence_converges,
]

__all__ = ["ANTIALIAS_CHECKS"]
