"""Flicker over the frames: a ``per_frame`` sequence metric scored on each pair of frames."""

import math

import numpy as np
import pytest

from harness import Frame, FrameMeta, MetricSpec
from harness.jobs import GroupInputs, run_job
from harness.plan import Job, MetricPlan
from harness.rows import make_table, per_frame_column
from harness.testing import registry

H, W, N = 6, 8, 7


def _sequence(jump_at: int | None, step: float = 0.2):
    """References moving linearly; outputs (the noisy colour, which passthrough returns) follow them
    exactly but for a jump of ``step`` between frames ``jump_at - 1`` and ``jump_at`` that stays."""
    refs = [np.full((H, W, 3), 0.3 + 0.05 * t, np.float32) for t in range(N)]
    colours = [r + (step if jump_at is not None and t >= jump_at else 0.0) for t, r in enumerate(refs)]
    frames = [Frame({"color": c.astype(np.float32)}, FrameMeta(index=t)) for t, c in enumerate(colours)]
    return frames, refs


def _run(frames, refs, variances=None):
    inputs = GroupInputs(frames, refs, ["x"] * N, [0] * N, reference_variances=variances or [],
                         reference_quality=[(64, 0.1)] * N)
    job = Job("denoise", "s", "synthetic", "passthrough", "cpu", "{}", "", 1, 0, width=W, height=H, frames=N,
              repeats=1, reference_spp=64)
    plan = MetricPlan(frame=["rmse"], sequence=["temporal_error"], per_frame=["temporal_error"])
    return make_table(run_job(registry(), job, inputs, plan).rows, plan.names)


def test_a_jump_between_frames_3_and_4_is_a_spike_at_frame_4():
    table = _run(*_sequence(jump_at=4))
    flicker = table[per_frame_column("temporal_error")].to_numpy()
    assert math.isnan(flicker[0])
    assert flicker[4] == pytest.approx(0.2, rel=1e-5)
    assert np.allclose(np.delete(flicker, [0, 4]), 0.0, atol=1e-6)
    # the sequence value is unchanged and derivable: the RMS of the per-frame values (equal pixel counts)
    sequence = table.temporal_error.to_numpy()
    assert np.isnan(sequence[:-1]).all()
    assert sequence[-1] == pytest.approx(math.sqrt(0.2 ** 2 / (N - 1)), rel=1e-5)
    assert sequence[-1] == pytest.approx(math.sqrt(np.nanmean(flicker ** 2)), rel=1e-6)
    steady = _run(*_sequence(jump_at=None))[per_frame_column("temporal_error")].to_numpy()
    assert np.allclose(steady[1:], 0.0, atol=1e-6)


def test_per_frame_values_are_bias_corrected_with_the_pair_of_variances():
    frames, refs = _sequence(jump_at=2)
    variances = [np.full((H, W, 3), 0.001 * (t + 1), np.float32) for t in range(N)]
    flicker = _run(frames, refs, variances)[per_frame_column("temporal_error")].to_numpy()
    # pair (1, 2): 0.2^2 - v_1 - v_2; pair (t-1, t) elsewhere: nothing left, clamped at 0
    assert flicker[2] == pytest.approx(math.sqrt(0.04 - 0.002 - 0.003), rel=1e-5)
    assert np.allclose(np.delete(flicker, [0, 2]), 0.0)


def test_the_plan_names_the_per_frame_column_and_the_spec_is_checked():
    spec = registry().metrics["temporal_error"]
    assert spec.per_frame and spec.declarations()["per_frame"] is True
    assert MetricPlan(sequence=["temporal_error"], per_frame=["temporal_error"]).names == [
        "temporal_error", "temporal_error_per_frame"]
    with pytest.raises(ValueError, match="per_frame needs kind 'sequence'"):
        MetricSpec("m", "1", factory=lambda: None, per_frame=True)


def test_a_per_frame_column_takes_its_sequence_metrics_direction():
    from harness.results import column_spec

    specs = registry().metrics
    assert column_spec(specs, "temporal_error_per_frame") is specs["temporal_error"]
    assert column_spec(specs, "ssim") is specs["ssim"] and column_spec(specs, "nothing_per_frame") is None
