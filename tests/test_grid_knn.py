"""The uniform-grid kNN kernels against the k-d tree (the reference) on clouds of every awkward kind."""

import numpy as np
import pytest
from scipy.spatial import cKDTree

from refinenet.estimators.baselines import pca_normals
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.geometry import grid_knn, neighbors

RNG = np.random.default_rng(7)


def _sphere(n: int, noise: float = 0.0) -> np.ndarray:
    d = RNG.normal(size=(n, 3))
    d /= np.linalg.norm(d, axis=1, keepdims=True)
    return d + noise * RNG.normal(size=(n, 3))


CLOUDS = {
    "noisy sphere": _sphere(6000, 0.002),
    "uniform cube": RNG.random((6000, 3)),
    "plane (flat axis)": np.c_[RNG.random((6000, 2)), np.zeros(6000)],
    "line": np.c_[np.linspace(0, 1, 3000), np.zeros(3000), np.zeros(3000)] + 1e-4 * RNG.random((3000, 3)),
    "far outliers": np.concatenate([_sphere(5900, 0.002), RNG.normal(0, 100, (100, 3))]),
    "far from origin": _sphere(5000, 0.002) * 0.01 + 1e4,
}


def _grid_answer(points: np.ndarray, k: int, query: np.ndarray | None = None):
    tree = cKDTree(points)
    grid = grid_knn.build_grid(points, k, tree)
    assert grid is not None
    return grid_knn.grid_knn(grid, points if query is None else query, k)


@pytest.mark.parametrize("name", list(CLOUDS))
@pytest.mark.parametrize("k", [1, 16, 100])
def test_grid_knn_equals_the_tree(name, k):
    points = CLOUDS[name]
    dist, idx, done = _grid_answer(points, k)
    ref_dist, ref_idx = cKDTree(points).query(points, k=k)
    ref_dist, ref_idx = ref_dist.reshape(len(points), k), ref_idx.reshape(len(points), k)
    assert done.mean() > 0.5, "the grid should answer most queries itself"
    np.testing.assert_array_equal(dist[done], ref_dist[done])  # bit-identical distances, sorted ascending
    np.testing.assert_array_equal(idx[done], ref_idx[done])
    assert np.all(idx[done, 0] == np.flatnonzero(done))  # the query point comes first


def test_grid_answers_nearly_every_query_on_a_surface():
    _, _, done = _grid_answer(CLOUDS["noisy sphere"], 50)
    assert done.mean() > 0.9


def test_queries_off_the_cloud_and_beyond_the_grid():
    points = CLOUDS["noisy sphere"]
    query = np.concatenate([_sphere(2000) * 1.01, [[50.0, 0, 0], [0, -1e3, 2]]])
    dist, idx, done = _grid_answer(points, 30, query)
    ref_dist, ref_idx = cKDTree(points).query(query, k=30)
    np.testing.assert_array_equal(idx[done], ref_idx[done])
    np.testing.assert_array_equal(dist[done], ref_dist[done])
    assert done[:2000].mean() > 0.9


def test_duplicate_points_give_the_same_distances():
    points = np.repeat(RNG.random((2000, 3)), 4, axis=0)
    dist, idx, done = _grid_answer(points, 20)
    ref_dist, _ = cKDTree(points).query(points, k=20)
    assert done.mean() > 0.9
    np.testing.assert_array_equal(dist[done], ref_dist[done])  # ties may come in another order
    rows = np.flatnonzero(done)
    np.testing.assert_allclose(np.linalg.norm(points[idx[rows]] - points[rows, None], axis=2), dist[rows])


def test_no_grid_where_it_would_not_pay():
    clusters = np.concatenate([RNG.normal(0, 0.001, (3000, 3)), RNG.normal(10, 1.0, (3000, 3))])
    assert grid_knn.build_grid(clusters, 20, cKDTree(clusters)) is None
    same = np.zeros((500, 3))
    assert grid_knn.build_grid(same, 20, cKDTree(same)) is None


@pytest.mark.parametrize("name", ["noisy sphere", "far outliers", "far from origin"])
def test_grid_covariances_equal_the_reference(name):
    points = CLOUDS[name]
    tree = cKDTree(points)
    grid = grid_knn.build_grid(points, 40, tree)
    covs, done = grid_knn.grid_covariances(grid, 40)  # in the grid's order
    ref = neighbors.covariances(points, tree.query(points, k=40)[1])[1][grid.order]
    assert done.mean() > 0.9
    scale = np.abs(ref).max(axis=(1, 2))[done, None, None]
    np.testing.assert_allclose(covs[done] / scale, ref[done] / scale, atol=1e-9)


@pytest.fixture
def grid_everywhere(monkeypatch):
    """Send even small query sets through the grid, so the public functions take the grid path here."""
    monkeypatch.setattr(neighbors, "GRID_MIN_QUERIES", 0)


@pytest.mark.parametrize("name", list(CLOUDS))
def test_knn_is_exact_for_every_query(grid_everywhere, name):
    points = CLOUDS[name]
    dist, idx = neighbors.knn(points, 25)
    ref_dist, ref_idx = cKDTree(points).query(points, k=25)
    np.testing.assert_array_equal(dist, ref_dist)
    np.testing.assert_array_equal(idx, ref_idx)
    assert idx.dtype == np.int64


def test_knn_int32_lists_without_distances(grid_everywhere):
    points = CLOUDS["noisy sphere"]
    dist, idx = neighbors.knn(points, 25, with_distances=False, index_dtype=np.int32)
    assert dist is None and idx.dtype == np.int32
    np.testing.assert_array_equal(idx, cKDTree(points).query(points, k=25)[1])


@pytest.mark.parametrize("name", list(CLOUDS))
def test_pca_normals_equal_those_of_the_tree_lists(grid_everywhere, monkeypatch, name):
    monkeypatch.setattr(neighbors, "BLOCK_POINTS", 1000)  # several blocks, grid and tree rows in each
    points = CLOUDS[name]
    normals = neighbors.pca_normals(points, 30)
    ref = neighbors.smallest_eigenvectors(neighbors.covariances(points, cKDTree(points).query(points, k=30)[1])[1])[1]
    np.testing.assert_allclose(np.abs(np.einsum("ij,ij->i", normals, ref)), 1.0, atol=1e-9)


def test_grid_covariances_of_a_block_equal_those_of_the_whole_cloud():
    points = CLOUDS["noisy sphere"]
    grid = grid_knn.build_grid(points, 40, cKDTree(points))
    covs, done = grid_knn.grid_covariances(grid, 40)
    block = slice(500, 1700)
    part, part_done = grid_knn.grid_covariances(grid, 40, block)
    np.testing.assert_array_equal(part_done, done[block])
    np.testing.assert_array_equal(part[part_done], covs[block][done[block]])


def test_pca_on_the_grid_recovers_known_normals(grid_everywhere):
    uv = RNG.random((20000, 2))
    axis_u, axis_v = np.array([1.0, 2.0, 0.5]), np.array([-2.0, 1.0, 0.0])
    normal = np.cross(axis_u, axis_v) / np.linalg.norm(np.cross(axis_u, axis_v))
    plane = uv[:, :1] * axis_u + uv[:, 1:] * axis_v + 3.0
    assert unoriented_angles(pca_normals(plane, 30), normal[None]).max() < 1e-5
    sphere = _sphere(20000)
    angles = unoriented_angles(pca_normals(sphere, 30), sphere)
    assert angles.mean() < 0.5 and angles.max() < 2.0


@pytest.mark.parametrize("name", list(CLOUDS))
def test_shared_lists_give_each_narrower_knn_and_its_last_distance(grid_everywhere, name):
    """The first k columns of one wide list are kNN_k itself, and the distance to the last of them is `knn`'s, to
    the bit: the stages that share a tile's lists get what their own queries would give."""
    points = CLOUDS[name]
    lists = neighbors.neighbour_lists(points, 40)
    assert lists.dtype == np.int32
    for k in (10, 25, 40):
        dist, idx = neighbors.knn(points, k)
        np.testing.assert_array_equal(neighbors.first_neighbours(lists, k), idx)
        last, first = neighbors.nearest_at(points, k, np.arange(len(points)), neighbours=lists)
        np.testing.assert_array_equal(first, idx)
        np.testing.assert_array_equal(last, dist[:, -1])
    with pytest.raises(ValueError, match="lists of 40 neighbours, 41 needed"):
        neighbors.first_neighbours(lists, 41)
