"""``temporal_error``: how much a filter's flicker differs from the reference's.

For outputs o_t and references r_t, the score is the RMSE of (o_t - o_{t-1}) against
(r_t - r_{t-1}) over all consecutive pairs: zero for an output that changes exactly as the
reference does, large for flicker or lag.

Bias-corrected like the squared-error metrics: with the references' variances of the mean
``v_t`` (independent between frames), ``E[(d_out - d_ref)^2]`` exceeds the error against the
true change by ``v_t + v_{t-1}``, which is subtracted per pixel; with masks, a pair scores the
pixels scored in both frames (emitters are left out by default).

Per frame (the spec declares ``per_frame``): the harness also scores each pair (t - 1, t) on
its own and stores it on frame t's row as ``temporal_error_per_frame``, so flicker is a time
series (a filter that flickers between frames 3 and 4 shows a spike at frame 4). The sequence
value is the root of the pixel-count-weighted mean of the pairs' squared values: where every
pair scores the same pixels and no pair's bias-corrected mean is negative (each pair's is
clamped at zero, the sequence's only once), ``temporal_error == sqrt(mean_t(per_frame_t ** 2))``.
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, hookimpl


def temporal_error(outputs, references, reference_variance=None, mask=None) -> float:
    """RMSE of frame-to-frame differences against the reference's; needs >= 2 frames.

    Parameters
    ----------
    outputs, references : list of ndarray (H, W, 3)
    reference_variance : list of ndarray or None, optional
        Each reference's per-pixel variance of the mean (an entry None: unknown, no correction).
    mask : list of ndarray (H, W) bool or None, optional
        Pixels scored in each frame.
    """
    if len(outputs) != len(references) or len(outputs) < 2:
        raise ValueError(
            f"temporal_error needs >= 2 frames of outputs and references, got {len(outputs)} and {len(references)}"
        )
    variances = reference_variance or [None] * len(outputs)
    masks = mask or [None] * len(outputs)
    total = 0.0
    count = 0
    for t in range(1, len(outputs)):
        d_out = np.asarray(outputs[t], np.float64) - np.asarray(outputs[t - 1], np.float64)
        d_ref = np.asarray(references[t], np.float64) - np.asarray(references[t - 1], np.float64)
        term = (d_out - d_ref) ** 2
        if variances[t] is not None and variances[t - 1] is not None:
            term = term - np.asarray(variances[t], np.float64) - np.asarray(variances[t - 1], np.float64)
        if masks[t] is not None or masks[t - 1] is not None:
            both = np.ones(term.shape[:2], bool)
            for m in (masks[t], masks[t - 1]):
                if m is not None:
                    both &= np.asarray(m, bool)
            term = term[both]
        total += float(np.sum(term))
        count += term.size
    if count == 0:
        return float("nan")
    return float(np.sqrt(max(total / count, 0.0)))


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="temporal_error",
            version="2.1",
            factory=lambda: temporal_error,
            higher_is_better=False,
            kind="sequence",
            min_frames=2,
            description="RMSE of frame differences vs. the reference's, bias-corrected, emitters excluded",
            accepts={"reference_variance", "mask"},
            per_frame=True,
        )
    ]
