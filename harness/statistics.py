"""Confidence intervals and paired tests for the leaderboard (method in docs/statistics.md).

The data of one leaderboard entry for one metric are **cells**: one value per (scene, seed,
frame). An entry's score is the mean over scenes of its per-scene means, so every scene counts
the same however many frames or seeds it has.

**Interval.** A hierarchical (two-stage) bootstrap, stratified by scene: in each resample and
each scene, the seeds are drawn with replacement, then, within each drawn seed, its frames are
drawn with replacement; the scene means of the resample are averaged. Resampling seeds as
clusters keeps the frames of one sequence together (a temporal filter's errors on consecutive
frames are correlated); resampling frames inside them adds the variation over the sequence.
The 95% interval is the 2.5 and 97.5 percentiles of ``RESAMPLES`` resampled scores
(percentile bootstrap, a fixed random seed, so the same table gives the same interval).

**Paired test.** Two entries are compared on the cells both have (same scenes, seeds and
frames, hence the same noisy inputs and references): the per-cell differences go through the
same bootstrap, which gives an interval for the difference of scores and a two-sided p-value
``2 min(P*(d <= 0), P*(d >= 0))``. The difference is significant at 5% when the interval
excludes 0.

With one seed the interval reflects the frames only; with one seed and one frame it is a
point (the table says so with ``cells``).

**Rank agreement.** How far two rankings of the same entries agree (the ``procedural`` and
``real`` tiers' leaderboards): Kendall's tau-b of their scores, ``(C - D) / sqrt((C + D + T_x)
(C + D + T_y))`` over the pairs of entries, with ``C`` concordant and ``D`` discordant pairs and
``T_x``, ``T_y`` the pairs tied in one ranking only (Kendall 1945); 1 is the same order, -1 the
reverse, 0 no relation.
"""

from __future__ import annotations

import math
from dataclasses import dataclass

import numpy as np
import pandas as pd

#: bootstrap resamples per interval or test
RESAMPLES = 2000
#: two-sided level of the intervals and tests
CONFIDENCE = 0.95
#: seed of the resampling (intervals are reproducible)
BOOTSTRAP_SEED = 20_240_601
#: columns identifying a cell of an entry
CELL_KEYS = ["scene", "seed", "frame"]


@dataclass
class Interval:
    """A score and its bootstrap interval."""

    mean: float
    low: float
    high: float
    cells: int


@dataclass
class Comparison:
    """The paired comparison of two entries (first minus second)."""

    difference: float
    low: float
    high: float
    p_value: float
    cells: int

    @property
    def significant(self) -> bool:
        """The 95% interval excludes 0 (never with fewer than 2 cells: nothing to resample)."""
        return self.cells > 1 and not (self.low <= 0.0 <= self.high)


def score(cells: pd.DataFrame, column: str = "value") -> float:
    """Mean over scenes of the per-scene mean of ``column`` (NaN without cells)."""
    if cells.empty:
        return math.nan
    return float(cells.groupby("scene")[column].mean().mean())


def _layout(cells: pd.DataFrame, column: str):
    """Per scene: a list (one per seed) of arrays of values over frames."""
    out = []
    for _, scene in cells.groupby("scene", sort=True):
        out.append([g[column].to_numpy(np.float64) for _, g in scene.groupby("seed", sort=True)])
    return out


def bootstrap_scores(cells: pd.DataFrame, column: str = "value", resamples: int = RESAMPLES,
                     seed: int = BOOTSTRAP_SEED) -> np.ndarray:
    """Resampled scores (``resamples``,) of the two-stage bootstrap described in the module docstring."""
    rng = np.random.default_rng(seed)
    totals = np.zeros(resamples)
    layout = _layout(cells, column)
    for seeds in layout:
        k = len(seeds)
        chosen = rng.integers(0, k, size=(resamples, k))
        sums = np.zeros(resamples)
        counts = np.zeros(resamples)
        for s, values in enumerate(seeds):
            n = len(values)
            draws = values[rng.integers(0, n, size=(resamples, k, n))].sum(axis=2)  # frames of every copy
            drawn = chosen == s
            sums += (draws * drawn).sum(axis=1)
            counts += drawn.sum(axis=1) * n
        totals += sums / counts
    return totals / max(len(layout), 1)


def interval(cells: pd.DataFrame, column: str = "value") -> Interval:
    """Score of ``cells`` with its 95% bootstrap interval."""
    mean = score(cells, column)
    if cells.empty:
        return Interval(math.nan, math.nan, math.nan, 0)
    boot = bootstrap_scores(cells, column)
    tail = (1.0 - CONFIDENCE) / 2.0 * 100.0
    low, high = np.percentile(boot, [tail, 100.0 - tail])
    return Interval(mean, float(low), float(high), len(cells))


def paired(first: pd.DataFrame, second: pd.DataFrame) -> Comparison:
    """Paired bootstrap comparison of two entries' cells (``value`` columns) on their common cells."""
    both = first.merge(second, on=CELL_KEYS, suffixes=("_a", "_b"))
    if both.empty:
        return Comparison(math.nan, math.nan, math.nan, math.nan, 0)
    both["diff"] = both["value_a"] - both["value_b"]
    boot = bootstrap_scores(both, "diff")
    tail = (1.0 - CONFIDENCE) / 2.0 * 100.0
    low, high = np.percentile(boot, [tail, 100.0 - tail])
    p = 2.0 * min(float(np.mean(boot <= 0.0)), float(np.mean(boot >= 0.0)))
    return Comparison(score(both, "diff"), float(low), float(high), min(p, 1.0), len(both))


def kendall_tau(x, y) -> float:
    """Kendall's tau-b of two paired sequences of scores (NaN pairs dropped; NaN with fewer than two
    pairs, or where one sequence is constant)."""
    x = np.asarray(x, np.float64)
    y = np.asarray(y, np.float64)
    if x.shape != y.shape or x.ndim != 1:
        raise ValueError(f"kendall_tau needs two sequences of the same length, got shapes {x.shape} and {y.shape}")
    keep = np.isfinite(x) & np.isfinite(y)
    x, y = x[keep], y[keep]
    if len(x) < 2:
        return math.nan
    i, j = np.triu_indices(len(x), k=1)
    dx, dy = np.sign(x[i] - x[j]), np.sign(y[i] - y[j])
    both = float(np.sum(dx * dy))  # concordant minus discordant
    untied_x, untied_y = float(np.sum(dx != 0)), float(np.sum(dy != 0))
    if untied_x == 0.0 or untied_y == 0.0:
        return math.nan
    return both / math.sqrt(untied_x * untied_y)


__all__ = ["BOOTSTRAP_SEED", "CELL_KEYS", "CONFIDENCE", "RESAMPLES", "Comparison", "Interval", "bootstrap_scores",
           "interval", "kendall_tau", "paired", "score"]
