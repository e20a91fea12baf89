"""Random ball subsets on the hashed grid (refinenet.geometry.ball) against scipy's k-d tree ball query: the exact
members when a ball fits, uniform subsets when it does not, any extent, and determinism by seed."""

from __future__ import annotations

import numpy as np
import pytest
from scipy.spatial import cKDTree

from refinenet.geometry.ball import MAX_CELLS_PER_AXIS, ball_grid, random_ball_subsets


@pytest.fixture(scope="module")
def cloud() -> np.ndarray:
    """A noisy unit sphere of 3,000 points, with 20 duplicates (zero distances are members too)."""
    rng = np.random.default_rng(0)
    points = rng.normal(size=(3000, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    points += rng.normal(scale=0.01, size=points.shape)
    points[-20:] = points[:20]
    return points


def members(points: np.ndarray, radius: float, centres: np.ndarray) -> list[set[int]]:
    return [set(ball) for ball in cKDTree(points).query_ball_point(points[centres], radius)]


def test_small_balls_are_returned_whole_and_padded_with_the_centre(cloud):
    centres = np.arange(0, 3000, 7)
    radius = 0.12
    truth = members(cloud, radius, centres)
    largest = max(len(m) for m in truth)
    chosen = random_ball_subsets(ball_grid(cloud, radius), centres, largest + 5, seed=1)
    for row, (centre, expected) in enumerate(zip(centres, truth, strict=True)):
        got = chosen[row]
        assert set(got[:len(expected)]) == expected
        assert (got[len(expected):] == centre).all()


def test_large_balls_give_subsets_of_max_points_without_repeats(cloud):
    centres = np.arange(0, 3000, 13)
    radius, max_points = 0.3, 40
    truth = members(cloud, radius, centres)
    assert min(len(m) for m in truth) > max_points
    chosen = random_ball_subsets(ball_grid(cloud, radius), centres, max_points, seed=2)
    for row, expected in enumerate(truth):
        assert len(set(chosen[row])) == max_points and set(chosen[row]) <= expected


def test_subsets_are_uniform(cloud):
    """Each of a ball's n members is kept with probability m / n: over 2,000 seeds the frequencies stay within
    5 standard deviations of it."""
    radius, max_points, draws = 0.2, 30, 2000
    (expected,) = members(cloud, radius, np.array([5]))
    grid = ball_grid(cloud, radius)
    counts = np.zeros(len(cloud))
    for seed in range(draws):
        np.add.at(counts, random_ball_subsets(grid, np.array([5]), max_points, seed)[0], 1)
    p = max_points / len(expected)
    frequency = counts[sorted(expected)] / draws
    assert np.abs(frequency - p).max() < 5 * np.sqrt(p * (1 - p) / draws)
    assert counts.sum() == draws * max_points and set(np.flatnonzero(counts)) == expected


def test_the_seed_decides_the_subsets(cloud):
    grid = ball_grid(cloud, 0.3)
    centres = np.arange(50)
    draw = lambda seed: random_ball_subsets(grid, centres, 40, seed)  # noqa: E731
    np.testing.assert_array_equal(draw(5), draw(5))
    assert not np.array_equal(draw(5), draw(6))


def test_any_extent(cloud):
    """A cloud a million times wider than its balls: the cells grow (a bounded number per axis) and the members
    stay exact."""
    points = np.concatenate([cloud, cloud[:10] + [1.0e6, 0.0, 0.0]])
    grid = ball_grid(points, 0.12)
    assert grid.dims.max() <= MAX_CELLS_PER_AXIS and grid.cell > 0.12
    centres = np.array([0, 1, 3005])
    chosen = random_ball_subsets(grid, centres, 500, seed=0)
    for row, expected in enumerate(members(points, 0.12, centres)):
        assert set(chosen[row]) == expected


def test_a_radius_must_be_positive(cloud):
    with pytest.raises(ValueError, match="radius"):
        ball_grid(cloud, 0.0)
