"""Spatial tiles with a margin, so that a cloud of any size is processed in bounded memory.

Each point belongs to exactly one tile (its `own` points); a tile's working cloud adds every point within
`margin` of its own points' bounding box, so that the neighbourhoods of its own points, and the neighbourhoods of
their neighbours, lie inside it. With a margin as wide as the farthest such chain, a point gets the same result in
its tile as in the whole cloud (`refinenet.cli.estimate` chooses the margin per method).

Tiles come from median splits of the longest side (a k-d tree's cells), so they hold nearly equal point counts
whatever the density.
"""

from __future__ import annotations

from collections.abc import Iterator
from dataclasses import dataclass

import numpy as np


@dataclass(frozen=True)
class Tile:
    """One tile: ids are positions in the whole cloud, both sorted, `own` a subset of `ids`."""

    own: np.ndarray
    """The points this tile answers for."""
    ids: np.ndarray
    """Its working cloud: own points and the margin around them."""

    @property
    def own_rows(self) -> np.ndarray:
        """Positions of the own points within the working cloud."""
        return np.searchsorted(self.ids, self.own)


def cells(points: np.ndarray, max_points: int) -> list[np.ndarray]:
    """Sorted id arrays of at most `max_points` points each, partitioning the cloud by median splits."""
    if max_points < 1:
        raise ValueError(f"max_points must be at least 1, got {max_points}")
    pending, done = [np.arange(len(points))], []
    while pending:
        ids = pending.pop()
        if len(ids) <= max_points:
            done.append(ids)
            continue
        coords = points[ids]
        axis = int(np.argmax(coords.max(axis=0) - coords.min(axis=0)))
        half = len(ids) // 2
        order = np.argpartition(coords[:, axis], half)
        pending += [np.sort(ids[order[:half]]), np.sort(ids[order[half:]])]
    return sorted(done, key=lambda ids: int(ids[0]))


def tiles(points: np.ndarray, max_points: int, margin: float) -> Iterator[Tile]:
    """The tiles of a cloud, in a fixed order; a cloud of at most `max_points` points is one tile, no margin."""
    if len(points) <= max_points:
        everything = np.arange(len(points))
        yield Tile(everything, everything)
        return
    for own in cells(points, max_points):
        coords = points[own]
        low, high = coords.min(axis=0) - margin, coords.max(axis=0) + margin
        inside = np.all((points >= low) & (points <= high), axis=1)
        inside[own] = True
        yield Tile(own, np.flatnonzero(inside))
