"""The point splat renderer and the normals figure: a nearer surface hides a farther one whatever the point order,
normals colour by their axis whatever their sign, and the figure's files are the same bytes on every run."""

import numpy as np
import pandas as pd
import pytest

from refinenet.evaluation.figures import (
    DenoisedColumn,
    Panel,
    Scan,
    better,
    clusters_figure,
    denoising_figure,
    loss_figure,
    normals_figure,
    real_figure,
    shaded_surface,
    training_figure,
)
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.evaluation.render import normal_colours, scan_view, splat, splat_radius, view_rotation

RED, BLUE = np.array([1.0, 0.0, 0.0]), np.array([0.0, 0.0, 1.0])


def grid_square(half: float, z: float, n: int = 60) -> np.ndarray:
    u = np.linspace(-half, half, n)
    x, y = np.meshgrid(u, u)
    return np.column_stack([x.ravel(), y.ravel(), np.full(x.size, z)])


def test_a_nearer_square_hides_the_one_behind_it():
    """A red square at z = 1 in front of a smaller blue one at z = 0, seen along -z: no blue pixel, whichever
    square's points come first; seen from behind, the blue square shows in the middle."""
    front, back = grid_square(1.0, 1.0), grid_square(0.5, 0.0)
    colours = np.vstack([np.tile(RED, (len(front), 1)), np.tile(BLUE, (len(back), 1))])
    for order in (np.arange(len(colours)), np.arange(len(colours))[::-1]):
        image = splat(np.vstack([front, back])[order], colours[order], np.eye(3), size=120)
        assert not (image == BLUE).all(axis=2).any()
        assert (image == RED).all(axis=2).sum() > 0.6 * 120 * 120  # the front square fills the view
    behind = np.diag([-1.0, 1.0, -1.0])  # looking along +z: the blue square is nearer
    image = splat(np.vstack([front, back]), colours, behind, size=120)
    assert (image[60, 60] == BLUE).all() and (image[5 + 4, 60] == RED).all()


def test_normal_colours_ignore_the_sign_and_follow_the_axis():
    rotation = view_rotation()
    up = np.array([[0.0, 0.0, 1.0], [0.0, 0.0, -1.0]])
    np.testing.assert_array_equal(normal_colours(up, rotation), [[0.5, 0.5, 1.0], [0.5, 0.5, 1.0]])
    assert splat_radius(100_000, 300) == 1 and splat_radius(1_000, 300) == 5 and splat_radius(3, 300) == 6


def drawn_twice(tmp_path, draw) -> list[list[bytes]]:
    """The bytes of the PNG and the PDF that `draw(paths)` writes, on each of two runs."""
    files = []
    for run in range(2):
        paths = {"png": tmp_path / f"{run}.png", "pdf": tmp_path / f"{run}.pdf"}
        draw(paths)
        files.append([p.read_bytes() for p in paths.values()])
    return files


def test_the_figure_is_the_same_bytes_on_every_run(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    truth = points / np.linalg.norm(points, axis=1, keepdims=True)
    noisy = truth + rng.normal(0.0, 0.1, truth.shape)
    panel = Panel("test/sphere", points, truth, {"exact": truth, "noisy": noisy})
    files = drawn_twice(tmp_path, lambda paths: normals_figure([panel], "profile test", paths, size=80))
    assert files[0] == files[1] and files[0][0].startswith(b"\x89PNG") and files[0][1].startswith(b"%PDF")


def test_the_cluster_and_training_figures_are_the_same_bytes_on_every_run(tmp_path):
    rng = np.random.default_rng(1)
    points = rng.normal(size=(300, 3))
    labels = {"Kc = 2": (points[:, 0] > 0).astype(int), "Kc = 4": rng.integers(4, size=300)}
    history = pd.DataFrame({"epoch": [1, 2, 3], "train_loss": [0.5, 0.3, 0.2], "val_mean_deg": [20.0, 15.0, 14.0]})
    files = []
    for run in range(2):
        clusters = {"png": tmp_path / f"c{run}.png", "pdf": tmp_path / f"c{run}.pdf"}
        clusters_figure(points, labels, ([1, 2, 4], [6.0, 5.0, 4.5]), "profile test", clusters, size=80)
        training = {"png": tmp_path / f"t{run}.png"}
        training_figure({0: history, 1: history.iloc[:0]}, "variant full", "profile test", training)
        files.append([p.read_bytes() for p in (*clusters.values(), *training.values())])
    assert files[0] == files[1]


def test_the_denoising_figure_is_the_same_bytes_on_every_run_and_shades_by_facing(tmp_path):
    vertices = np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    triangles = np.array([[0, 2, 1], [0, 1, 3], [0, 3, 2], [1, 2, 3]])
    rotation = view_rotation()
    points, grey = shaded_surface(vertices, triangles, rotation, n_points=2000)
    assert points.shape == (2000, 3) and np.allclose(grey[:, 0], grey[:, 2])
    assert 0.25 <= grey.min() and grey.max() <= 0.95  # lit between the ambient level and full facing light
    rng = np.random.default_rng(2)
    cloud = rng.normal(size=(300, 3))
    columns = [DenoisedColumn(name, cloud, np.abs(rng.normal(size=300)) * 1e-3, (vertices, triangles))
               for name in ("noisy input", "PCA")]
    files = drawn_twice(tmp_path, lambda paths: denoising_figure(columns, 2e-3, "profile test", paths, size=80))
    assert files[0] == files[1]


def test_the_loss_figure_colours_each_point_by_the_better_network(tmp_path):
    """L1's estimate exact on the first 300 points and 20 deg off on the other 100, L2's 10 deg off everywhere: 75% of
    the points blue (L1 better), 25% red; the same bytes on every run."""
    rng = np.random.default_rng(3)
    points = rng.normal(size=(400, 3))
    truth = np.tile([0.0, 0.0, 1.0], (400, 1))
    tilt = np.radians(np.where(np.arange(400) < 300, 0.0, 20.0))
    l1 = np.c_[np.sin(tilt), np.zeros(400), np.cos(tilt)]
    l2 = np.tile([np.sin(np.radians(10.0)), 0.0, np.cos(np.radians(10.0))], (400, 1))
    panel = Panel("test/plane", points, truth, {"L1": l1, "L2": l2})
    files = drawn_twice(tmp_path, lambda paths: loss_figure([panel], "profile test", paths, size=80))
    assert files[0] == files[1]
    winner = better(unoriented_angles(l1, truth), unoriented_angles(l2, truth))
    assert (winner[:300] == -1).all() and (winner[300:] == 1).all()
    assert np.array_equal(better(np.ones(3), np.ones(3)), np.zeros(3))


def test_a_range_scan_is_seen_along_its_depth_from_the_scanner_with_z_or_y_up():
    """A scan of a tilted wall 10 units in front of a scanner at the origin (depth -z): seen from +z (the scanner's
    side) with y up, as the camera held it; a LiDAR tile of a street (depth along y, z up) keeps z up."""
    rng = np.random.default_rng(4)
    wall = np.c_[rng.uniform(-3, 3, 2000), rng.uniform(-2, 2, 2000), np.zeros(2000)]
    wall[:, 2] = -10.0 + 0.1 * wall[:, 0]
    rotation = scan_view(wall)
    assert np.allclose(rotation @ rotation.T, np.eye(3)) and np.linalg.det(rotation) == pytest.approx(1.0)
    depth = np.array([-0.1, 0.0, 1.0]) / np.linalg.norm([-0.1, 0.0, 1.0])
    assert rotation[2] @ depth == pytest.approx(1.0)
    assert rotation[1] @ [0.0, 1.0, 0.0] == pytest.approx(1.0)
    street = np.c_[rng.uniform(-5, 5, 2000), 100.0 + rng.normal(0, 0.05, 2000), rng.uniform(0, 8, 2000)]
    rotation = scan_view(street)
    assert rotation[2] @ [0.0, -1.0, 0.0] == pytest.approx(1.0, abs=1e-3)  # from the origin's side
    assert rotation[1] @ [0.0, 0.0, 1.0] == pytest.approx(1.0, abs=1e-3)


def test_the_real_scan_figure_is_the_same_bytes_on_every_run(tmp_path):
    rng = np.random.default_rng(5)
    points = rng.normal(size=(400, 3)) * [3.0, 2.0, 0.2] - [0.0, 0.0, 10.0]
    normals = np.tile([0.0, 0.0, 1.0], (400, 1))
    scans = [Scan("wall", points, {"PCA": normals, "Refine-Net (X = 8)": normals + rng.normal(0, 0.1, (400, 3))})]
    files = drawn_twice(tmp_path, lambda paths: real_figure(scans, "profile test", paths, size=80))
    assert files[0] == files[1]
