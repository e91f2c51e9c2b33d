"""``temporal_error``: how much a filter's flicker differs from the reference's.

For outputs o_t and references r_t, the score is the RMSE of (o_t - o_{t-1}) against
(r_t - r_{t-1}) over all consecutive pairs: zero for an output that changes exactly as the
reference does, large for flicker or lag.
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, hookimpl


def temporal_error(outputs, references) -> float:
    """RMSE of frame-to-frame differences against the reference's; needs >= 2 frames."""
    if len(outputs) != len(references) or len(outputs) < 2:
        raise ValueError(
            f"temporal_error needs >= 2 frames of outputs and references, got {len(outputs)} and {len(references)}"
        )
    total = 0.0
    count = 0
    for t in range(1, len(outputs)):
        d_out = np.asarray(outputs[t], np.float64) - np.asarray(outputs[t - 1], np.float64)
        d_ref = np.asarray(references[t], np.float64) - np.asarray(references[t - 1], np.float64)
        total += float(np.sum((d_out - d_ref) ** 2))
        count += d_out.size
    return float(np.sqrt(total / count))


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="temporal_error",
            version="1.0",
            factory=lambda: temporal_error,
            higher_is_better=False,
            kind="sequence",
            min_frames=2,
            description="RMSE of frame differences vs. the reference's",
        )
    ]
