"""``flip``: NVIDIA's FLIP difference through the ``flip-evaluator`` package (LDR mode).

Inputs are clamped to [0, 1] and sRGB-encoded like SSIM's, then compared with
``flip_evaluator.evaluate(reference, output, "LDR")``; the score is the mean FLIP error
(0 = identical, lower is better). The package version is recorded in the run manifest.
"""

from __future__ import annotations

import numpy as np

from harness import MetricSpec, encode_srgb, hookimpl


def flip(output: np.ndarray, reference: np.ndarray) -> float:
    """Mean LDR-FLIP error in [0, 1]."""
    import flip_evaluator

    ref = np.ascontiguousarray(encode_srgb(reference), np.float32)
    out = np.ascontiguousarray(encode_srgb(output), np.float32)
    result = flip_evaluator.evaluate(ref, out, "LDR", inputsRGB=True, applyMagma=False)
    return float(result[1])


def flip_version() -> str:
    from importlib.metadata import version

    return version("flip-evaluator")


@hookimpl
def register_metrics():
    return [
        MetricSpec(
            name="flip",
            version=f"1.0+flip-evaluator-{flip_version()}",
            factory=lambda: flip,
            higher_is_better=False,
            description="mean LDR-FLIP (flip-evaluator) on clamped sRGB images",
        )
    ]
