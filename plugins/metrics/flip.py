"""``flip``: NVIDIA's FLIP difference through the ``flip-evaluator`` package (LDR mode).

Inputs are clamped to [0, 1] and sRGB-encoded like SSIM's, then compared with
``flip_evaluator.evaluate(reference, output, "LDR")``; the score is the mean FLIP error
(0 = identical, lower is better). The package version is recorded in the run manifest.
With a ``mask`` (emitter pixels left out by default) the score is the mean of FLIP's error map
over the scored pixels (NaN when none is left).
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, encode_srgb, hookimpl


def flip(output: np.ndarray, reference: np.ndarray, mask: np.ndarray | None = None) -> float:
    """Mean LDR-FLIP error in [0, 1], over the pixels of ``mask`` when given."""
    import flip_evaluator

    ref = np.ascontiguousarray(encode_srgb(reference), np.float32)
    out = np.ascontiguousarray(encode_srgb(output), np.float32)
    error_map, mean, _ = flip_evaluator.evaluate(ref, out, "LDR", inputsRGB=True, applyMagma=False)
    if mask is None:
        return float(mean)
    scored = np.asarray(error_map, np.float64).reshape(ref.shape[:2])[np.asarray(mask, bool)]
    return float(scored.mean()) if scored.size else float("nan")


def flip_version() -> str:
    from importlib.metadata import version

    return version("flip-evaluator")


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="flip",
            version=f"1.1+flip-evaluator-{flip_version()}",
            factory=lambda: flip,
            higher_is_better=False,
            description="mean LDR-FLIP (flip-evaluator) on clamped sRGB images, emitters excluded",
            accepts={"mask"},
        )
    ]
