"""``benchmarks/aa_rnn_curve.py``: weights file names and the report's rows (runs of one size and
seed but other lengths stay apart)."""

from __future__ import annotations

import contextlib
import io
import json
import runpy
import sys
from pathlib import Path

import pytest

BENCHMARKS = Path(__file__).resolve().parents[1] / "benchmarks"


def _curve(monkeypatch, *args) -> str:
    monkeypatch.setattr(sys, "argv", [str(BENCHMARKS / "aa_rnn_curve.py"), *args])
    monkeypatch.setattr(sys, "path", [str(BENCHMARKS), *sys.path])
    stdout = io.StringIO()
    with contextlib.redirect_stdout(stdout), pytest.raises(SystemExit) as done:
        runpy.run_path(str(BENCHMARKS / "aa_rnn_curve.py"), run_name="__main__")
    assert done.value.code == 0
    return stdout.getvalue()


def _scores(ssim: float, epochs: int | None = None, steps: int | None = None) -> dict:
    value = {"test": {"ssim": ssim, "temporal_error": 0.05, "ghost": 0.02, "sequences": 2},
             "bench": {s: {"ssim": ssim, "temporal_error": 0.1, "ghost": 0.06} for s in ("a", "b")}}
    if epochs is not None:
        value["training"] = {"epochs_run": epochs, "steps_run": steps, "train_cpu_s": 60.0 * epochs,
                             "best_epoch": epochs, "seed": 0, "train_sequences": 16}
    return value


def test_runs_of_other_lengths_get_their_own_rows_in_order_of_steps(monkeypatch, tmp_path):
    scores = {"noaa": _scores(0.5), "taa": _scores(0.6), "aa_rnn": _scores(0.7),
              # the same size and seed: 12 epochs (unnamed length), 24 epochs and its quarter snapshot
              "n16-s0.npz": _scores(0.80, 12, 24), "n16-s0-r24.npz": _scores(0.90, 24, 48),
              "n16-s0-r24-e6.npz": _scores(0.70, 6, 12), "n16-s0-e3.npz": _scores(0.60, 3, 6),
              "not-a-run.npz": _scores(0.1, 1, 1)}
    (tmp_path / "scores.json").write_text(json.dumps(scores))
    rows = [line for line in _curve(monkeypatch, "report", "--out", str(tmp_path)).splitlines()
            if line.startswith("| 16 |")]
    assert [r.split(" | ")[1] for r in rows] == ["3 (6)", "6 (12)", "12 (24)", "24 (48)"]
    assert [r.split(" | ")[3] for r in rows] == ["0.6000", "0.7000", "0.8000", "0.9000"]
    assert all(r.split(" | ")[2] == "1" for r in rows)  # one seed each: no run was merged into another


def test_weights_names():
    sys.path.insert(0, str(BENCHMARKS))
    try:
        from aa_rnn_curve import NAME
    finally:
        sys.path.remove(str(BENCHMARKS))
    assert NAME.match("n826-s2.npz").groups() == ("826", "2", None, None)
    assert NAME.match("n826-s0-e3.npz").groups() == ("826", "0", None, "3")
    assert NAME.match("n1140-s0-r24-e6.npz").groups() == ("1140", "0", "24", "6")
    assert NAME.match("n1140-s0-r24.npz").groups() == ("1140", "0", "24", None)
    assert NAME.match("n1140-s0.npz.ckpt") is None and NAME.match("scores.npz") is None
