"""Confidence intervals and paired tests of the leaderboard (harness.statistics): coverage and power."""

import numpy as np
import pandas as pd
import pytest

from harness.statistics import interval, paired, score


def table(values: np.ndarray) -> pd.DataFrame:
    """Cells from an array (scenes, seeds, frames) of values."""
    s, k, f = np.indices(values.shape)
    return pd.DataFrame({"scene": s.ravel().astype(str), "seed": k.ravel(), "frame": f.ravel(),
                         "value": values.ravel()})


def test_score_weights_every_scene_equally():
    cells = pd.concat([table(np.zeros((1, 1, 10))), table(np.ones((1, 1, 2))).assign(scene="b")])
    assert score(cells) == pytest.approx(0.5)


@pytest.mark.slow
def test_interval_covers_the_true_mean_about_95_percent_of_the_time():
    """Seeds are independent replicates; frames of one seed are correlated (a shared offset per seed)."""
    rng = np.random.default_rng(0)
    hits, trials = 0, 200
    for _ in range(trials):
        per_seed = rng.normal(0.0, 1.0, size=(2, 8, 1))  # what a noisy input does to a whole sequence
        per_frame = rng.normal(0.0, 0.5, size=(2, 8, 6))
        iv = interval(table(3.0 + per_seed + per_frame))
        hits += iv.low <= 3.0 <= iv.high
    # the percentile bootstrap is a little narrow with 8 clusters; it must not ignore the clustering
    assert 0.85 <= hits / trials <= 0.99, hits / trials


def test_ignoring_the_seed_clusters_would_be_too_narrow():
    """The same data with every frame an independent seed gives a clearly narrower interval."""
    rng = np.random.default_rng(1)
    values = 3.0 + rng.normal(0, 1.0, size=(1, 6, 1)) + rng.normal(0, 0.2, size=(1, 6, 10))
    clustered = interval(table(values))
    flat = interval(table(values.reshape(1, 60, 1)))
    assert (clustered.high - clustered.low) > 2.0 * (flat.high - flat.low)


def test_paired_test_finds_a_real_difference_and_not_a_spurious_one():
    rng = np.random.default_rng(2)
    shared = rng.normal(0, 1.0, size=(3, 3, 8))  # the same inputs: large shared variation
    a = table(1.0 + shared + rng.normal(0, 0.02, shared.shape))
    b = table(1.05 + shared + rng.normal(0, 0.02, shared.shape))
    test = paired(a, b)
    assert test.significant and test.difference == pytest.approx(-0.05, abs=0.01) and test.p_value < 0.01
    false_positives = 0
    for trial in range(40):
        r = np.random.default_rng(100 + trial)
        base = r.normal(0, 1.0, size=(3, 3, 8))
        x = table(base + r.normal(0, 0.05, base.shape))
        y = table(base + r.normal(0, 0.05, base.shape))
        false_positives += paired(x, y).significant
    assert false_positives <= 6  # about 5% expected, with room for the narrow bootstrap


def test_paired_uses_only_common_cells_and_is_reproducible():
    a = table(np.arange(12.0).reshape(1, 3, 4))
    b = table(np.arange(12.0).reshape(1, 3, 4) + 1.0).iloc[:6]
    first, again = paired(a, b), paired(a, b)
    assert first.cells == 6 and first.difference == pytest.approx(-1.0)
    assert (first.low, first.high, first.p_value) == (again.low, again.high, again.p_value)
    assert paired(a, b.assign(scene="other")).cells == 0


def test_a_single_cell_gives_a_point():
    iv = interval(table(np.full((1, 1, 1), 0.25)))
    assert iv.mean == iv.low == iv.high == 0.25 and iv.cells == 1


def test_kendall_tau_against_hand_counts_and_scipy():
    from scipy.stats import kendalltau

    from harness.statistics import kendall_tau

    # [1..5] against [3, 1, 2, 5, 4]: of the 10 pairs, 7 in the same order, 3 reversed: (7 - 3) / 10
    assert kendall_tau([1, 2, 3, 4, 5], [3, 1, 2, 5, 4]) == pytest.approx(0.4)
    assert kendall_tau([1, 2, 3, 4], [1, 2, 3, 4]) == 1.0 and kendall_tau([1, 2, 3], [3, 2, 1]) == -1.0
    # tau-b with ties: x ties (0, 1), y ties (1, 2); 7 concordant, 1 discordant, 9 untied in each: 6 / 9
    assert kendall_tau([1, 1, 2, 3, 4], [1, 2, 2, 4, 3]) == pytest.approx(2 / 3)
    rng = np.random.default_rng(3)
    for _ in range(20):
        x, y = rng.integers(0, 5, 9).astype(float), rng.normal(size=9)
        assert kendall_tau(x, y) == pytest.approx(kendalltau(x, y)[0], abs=1e-12)
    # pairs with a NaN are dropped; fewer than two pairs or a constant ranking say nothing
    assert kendall_tau([1, np.nan, 3, 2], [1, 5, 2, 3]) == pytest.approx(kendall_tau([1, 3, 2], [1, 2, 3]))
    assert np.isnan(kendall_tau([1.0], [2.0])) and np.isnan(kendall_tau([1, 1, 1], [1, 2, 3]))
    with pytest.raises(ValueError, match="same length"):
        kendall_tau([1, 2], [1, 2, 3])
