"""Spatial tiles: a partition of the cloud into balanced cells, each with the margin around its own points."""

import numpy as np
import pytest

from refinenet.geometry.tiles import cells, tiles


def test_cells_partition_the_cloud_into_balanced_parts():
    points = np.random.default_rng(0).random((10_001, 3)) * [10, 1, 0.1]
    parts = cells(points, 1000)
    assert np.array_equal(np.sort(np.concatenate(parts)), np.arange(len(points)))
    assert all(len(p) <= 1000 for p in parts) and min(len(p) for p in parts) >= 500
    assert all((np.diff(p) > 0).all() for p in parts)


def test_tile_margins_hold_every_point_near_the_own_points():
    points = np.random.default_rng(1).random((5000, 3))
    for tile in tiles(points, 1200, margin=0.1):
        assert np.array_equal(tile.ids[tile.own_rows], tile.own)
        own = points[tile.own]
        near = np.all((points >= own.min(0) - 0.1) & (points <= own.max(0) + 0.1), axis=1)
        assert np.array_equal(np.flatnonzero(near), tile.ids)


def test_a_small_cloud_is_one_tile_without_margin():
    points = np.random.default_rng(2).random((100, 3))
    (tile,) = tiles(points, 100, margin=5.0)
    assert np.array_equal(tile.own, np.arange(100)) and np.array_equal(tile.ids, tile.own)
    with pytest.raises(ValueError, match="at least 1"):
        cells(points, 0)
