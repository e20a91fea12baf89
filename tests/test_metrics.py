"""Angular metrics and aggregation, on hand-computed cases."""

import numpy as np
import pytest

from refinenet.evaluation.metrics import (
    ErrorStats,
    average_over_categories,
    pcpnet_category,
    pooled,
    synthetic_category,
    unoriented_angles,
)


def test_unoriented_angles():
    g = np.array([[0, 0, 1.0], [0, 0, 1.0], [0, 0, 1.0], [1.0, 0, 0]])
    n = np.array([[0, 0, -1.0], [0, 1.0, 1.0], [0, 2.0, 0], [1.0, 0, 0]])  # flipped, 45 deg, 90 deg (unnormalised)
    np.testing.assert_allclose(unoriented_angles(n, g), [0, 45, 90, 0], atol=1e-9)


def test_stats_by_hand():
    s = ErrorStats.from_angles(np.array([1.0, 3.0, 6.0, 12.0]))
    assert s.mean == pytest.approx(5.5)
    assert s.rmse == pytest.approx(np.sqrt((1 + 9 + 36 + 144) / 4))
    assert (s.pgp5, s.pgp10) == (0.5, 0.75)


def test_synthetic_pooling_and_weighted_rmse():
    a = ErrorStats.from_angles(np.array([2.0, 2.0]))  # rmse 2
    b = ErrorStats.from_angles(np.array([4.0, 4.0, 4.0, 4.0, 4.0, 4.0]))  # rmse 4
    cat = synthetic_category([a, b])
    assert cat["mean"] == pytest.approx((4 + 24) / 8)
    assert cat["rmse"] == pytest.approx((2 * 2 + 6 * 4) / 8)  # point-weighted per-cloud RMSE
    assert cat["rmse_pooled"] == pytest.approx(np.sqrt((8 + 96) / 8))
    assert pooled([a, b]).n == 8


def test_pcpnet_is_unweighted_over_shapes():
    a = ErrorStats.from_angles(np.array([2.0, 2.0]))
    b = ErrorStats.from_angles(np.full(100, 4.0))
    assert pcpnet_category([a, b])["rmse"] == pytest.approx(3.0)


def test_average_is_unweighted_over_categories():
    # the paper's own check (docs/algorithm.md §10): MFPS (5.72 + 4.36 + 4.82 + 4.10) / 4 = 4.75
    cats = {c: {"mean": v, "n": 10 ** i} for i, (c, v) in enumerate(zip("ABCD", [5.72, 4.36, 4.82, 4.10], strict=True))}
    assert average_over_categories(cats)["mean"] == pytest.approx(4.75)
