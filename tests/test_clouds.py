"""Data sources: procedural, mesh folders, PCPNet-format folders and generic point folders."""

from dataclasses import replace

import numpy as np
import pytest
from settings import BASE

from refinenet.data.clouds import (
    CloudSpec,
    list_clouds,
    make_cloud,
    read_scan,
    scan_files,
    scored_points,
    surface_sample,
)
from refinenet.data.io import write_ply
from refinenet.data.noise import bbox_diagonal
from refinenet.errors import InputError, ParamsError
from refinenet.evaluation.denoise import surface_distance


def data_block(**overrides):
    return replace(BASE.data, **overrides)


def test_procedural_clouds_follow_the_paper_noise_levels():
    specs = list_clouds(data_block(), BASE.noise)
    levels = {(s.split, s.category): set() for s in specs}
    for s in specs:
        levels[(s.split, s.category)].add(s.noise)
    assert levels[("test", "SharpFeature")] == {0.05, 0.10, 0.15}
    assert levels[("test", "RichFeature")] == {0.05, 0.10, 0.15, 0.20}
    assert levels[("test", "BigNoise")] == {0.2, 0.3, 0.4, 0.5}
    assert levels[("train", "SmoothSurface")] == {0.1, 0.2, 0.3}
    assert ("train", "BigNoise") not in levels
    train = {s.origin for s in specs if s.split == "train"}
    test = {s.origin for s in specs if s.split == "test"}
    assert not train & test


def test_procedural_cloud_records_its_seeds_and_noise():
    spec = CloudSpec("test", "SharpFeature", "lblock_a_n0.10", "lblock_a", 0.10)
    cloud = make_cloud(spec, 5000, seed=3)
    again = make_cloud(spec, 5000, seed=3)
    np.testing.assert_array_equal(cloud.points, again.points)
    assert cloud.meta["noise_percent"] == 0.10 and cloud.meta["noise_seed"] != cloud.meta["sample_seed"]
    assert cloud.meta["noise_sigma"] == pytest.approx(0.001 * cloud.meta["l_d"])
    other_level = make_cloud(CloudSpec("test", "SharpFeature", "lblock_a_n0.15", "lblock_a", 0.15), 5000, seed=3)
    displacement = np.linalg.norm(other_level.points - cloud.points, axis=1).mean()
    assert displacement < 0.01 * cloud.meta["l_d"]  # the same clean sample under both noise levels


def test_a_scored_subset_is_seeded_by_the_cloud_alone_and_nests():
    """A test cloud's scored subset of `inference.points`: distinct sorted indices, the same under any run seed
    (every row of a table scores the same points), a smaller one inside a larger; drawn from a PCPNet .pidx where
    there is one; none on a training cloud, or where it would cover every point."""
    spec = CloudSpec("test", "SharpFeature", "lblock_a_n0.10", "lblock_a", 0.10)
    cloud, reseeded = make_cloud(spec, 1000, seed=3), make_cloud(spec, 1000, seed=2024)
    small, large = scored_points(cloud, 100), scored_points(cloud, 400)
    assert len(np.unique(small)) == 100 and np.all(np.diff(small) > 0) and small.max() < 1000
    np.testing.assert_array_equal(small, scored_points(reseeded, 100))
    assert set(small) <= set(large) and scored_points(cloud, 1000) is None and scored_points(cloud) is None
    other = make_cloud(CloudSpec("test", "SharpFeature", "lblock_b_n0.10", "lblock_b", 0.10), 1000, seed=3)
    assert not np.array_equal(scored_points(other, 100), small)
    pidx = np.arange(0, 1000, 4)
    pcpnet = replace(cloud, meta={**cloud.meta, "pidx": pidx.tolist()})
    np.testing.assert_array_equal(scored_points(pcpnet), pidx)
    assert set(scored_points(pcpnet, 50)) <= set(pidx) and len(scored_points(pcpnet, 50)) == 50
    train = make_cloud(CloudSpec("train", "SharpFeature", "lblock_a_n0.10", "lblock_a", 0.10), 1000, seed=3)
    assert scored_points(train, 100) is None


def test_mesh_folder(shared_data):
    folders = {"train": "train", "test": "dev"}
    data = data_block(source="meshes", path=str(shared_data / "meshes"), split_folders=folders)
    specs = list_clouds(data, BASE.noise)
    test_cats = {s.category for s in specs if s.split == "test"}
    assert test_cats == {"SharpFeature", "SmoothSurface", "RichFeature"}
    assert sum(s.split == "test" and s.category == "SharpFeature" for s in specs) == 3 * 3
    spec = next(s for s in specs if s.name.startswith("pyramid"))
    cloud = make_cloud(spec, 3000, seed=1)
    assert cloud.points.shape == (3000, 3) and np.allclose(np.linalg.norm(cloud.normals, axis=1), 1)
    assert cloud.meta["noise_sigma"] == pytest.approx(spec.noise / 100 * cloud.meta["l_d"])


def test_pcpnet_folder(shared_data, tmp_path):
    for name in ("fandisk100k", "cube100k"):
        for suffix in (".xyz", ".normals"):
            (tmp_path / f"{name}{suffix}").symlink_to(shared_data / "pcpnet_format" / f"{name}{suffix}")
    np.savetxt(tmp_path / "cube100k.pidx", np.arange(0, 100000, 20), fmt="%d")
    (tmp_path / "train.txt").write_text("fandisk100k\n")
    (tmp_path / "test.txt").write_text("cube100k\n")
    data = data_block(source="pcpnet", path=str(tmp_path), pcpnet={"train_list": "train.txt",
                                                                    "test_lists": {"None": "test.txt"}})
    specs = list_clouds(data, BASE.noise)
    assert [(s.split, s.category, s.name) for s in specs] == [("train", "train", "fandisk100k"),
                                                               ("test", "None", "cube100k")]
    cloud = make_cloud(specs[1], 0, seed=0)
    assert len(cloud) == 100000 and len(cloud.meta["pidx"]) == 5000 and cloud.meta["noise_percent"] is None
    (tmp_path / "test.txt").write_text("missing_shape\n")
    with pytest.raises(InputError, match="missing_shape.xyz"):
        make_cloud(list_clouds(data, BASE.noise)[1], 0, seed=0)


def test_points_folder(tmp_path):
    rng = np.random.default_rng(0)
    points = rng.normal(size=(500, 3))
    normals = points / np.linalg.norm(points, axis=1, keepdims=True)
    (tmp_path / "test" / "smooth").mkdir(parents=True)
    write_ply(tmp_path / "test" / "smooth" / "ball.ply", points, normals)
    np.save(tmp_path / "test" / "smooth" / "ball2.npy", np.hstack([points, normals]))
    np.savetxt(tmp_path / "test" / "smooth" / "bare.xyz", points)  # no normals: refused when made
    specs = list_clouds(data_block(source="points", path=str(tmp_path)), BASE.noise)
    assert [s.name for s in specs] == ["ball", "ball2", "bare"] and {s.category for s in specs} == {"SmoothSurface"}
    cloud = make_cloud(specs[0], 0, seed=0)
    np.testing.assert_allclose(cloud.normals, normals, atol=1e-12)
    assert cloud.meta["l_d"] == pytest.approx(bbox_diagonal(points))
    with pytest.raises(InputError, match="no normals"):
        make_cloud(specs[2], 0, seed=0)


CUBE_OFF = """OFF
8 12 0
0 0 0
1 0 0
1 1 0
0 1 0
0 0 1
1 0 1
1 1 1
0 1 1
3 0 2 1
3 0 3 2
3 4 5 6
3 4 6 7
3 0 1 5
3 0 5 4
3 2 3 7
3 2 7 6
3 1 2 6
3 1 6 5
3 0 4 7
3 0 7 3
"""


def test_training_meshes_join_the_training_clouds_of_any_source(tmp_path):
    """data.train_meshes adds its train split (never its test split) at the training levels, after the source's
    own clouds, which stay as they were; a mesh's clouds do not depend on where its folder lies."""
    for folder in ("meshes", "moved"):
        for split, name in (("train", "box"), ("test", "held_out")):
            (tmp_path / folder / split / "sharp").mkdir(parents=True)
            (tmp_path / folder / split / "sharp" / f"{name}.off").write_text(CUBE_OFF)
    procedural = list_clouds(data_block(), BASE.noise)
    specs = list_clouds(data_block(train_meshes=str(tmp_path / "meshes")), BASE.noise)
    assert specs[:len(procedural)] == procedural
    assert [s.key for s in specs[len(procedural):]] == [f"train/SharpFeature/box_n{level:.2f}"
                                                        for level in BASE.noise.train]
    cloud = make_cloud(specs[-1], 3000, seed=1)
    moved = make_cloud(list_clouds(data_block(train_meshes=str(tmp_path / "moved")), BASE.noise)[-1], 3000, seed=1)
    np.testing.assert_array_equal(moved.points, cloud.points)
    assert (cloud.points.min() > -0.05) and (cloud.points.max() < 1.05)
    axis = np.abs(cloud.normals).argmax(axis=1)  # a cube's face normals are the coordinate axes
    assert np.allclose(np.abs(cloud.normals[np.arange(3000), axis]), 1)


def test_bad_training_meshes(tmp_path):
    with pytest.raises(ParamsError, match="data.train_meshes: '.*nowhere' is not a folder"):
        list_clouds(data_block(train_meshes=str(tmp_path / "nowhere")), BASE.noise)
    with pytest.raises(ParamsError, match="data.train_meshes: no meshes in"):
        list_clouds(data_block(train_meshes=str(tmp_path)), BASE.noise)
    (tmp_path / "train" / "sharp").mkdir(parents=True)
    (tmp_path / "train" / "sharp" / "fandisk_b.off").write_text(CUBE_OFF)  # a procedural training shape's name
    with pytest.raises(ParamsError, match="a mesh named as a cloud of data.source: train/SharpFeature/fandisk_b_n"):
        list_clouds(data_block(train_meshes=str(tmp_path)), BASE.noise)


def test_bad_source_settings(tmp_path):
    with pytest.raises(ParamsError, match="data.path"):
        list_clouds(data_block(source="meshes", path=str(tmp_path / "nowhere")), BASE.noise)
    with pytest.raises(ParamsError, match="no test clouds"):
        list_clouds(data_block(source="points", path=str(tmp_path)), BASE.noise)


def test_the_true_surface_of_a_noisy_cloud_lies_one_noise_sigma_away():
    """Gaussian noise of sigma s moves a point off a (locally flat) surface by |N(0, s)|: mean s sqrt(2/pi). The
    clean cloud lies on the dense sample's tangent planes, and a given cloud has no surface to measure against."""
    spec = CloudSpec("test", "SharpFeature", "lblock_a_n0.20", "lblock_a", 0.20)
    cloud = make_cloud(spec, 5000, seed=3)
    surface, normals = surface_sample("c.npz", cloud.meta, 50_000)
    assert surface.shape == (50_000, 3) and np.allclose(np.linalg.norm(normals, axis=1), 1)
    sigma = cloud.meta["noise_sigma"]
    assert surface_distance(cloud.points, surface, normals).mean() == pytest.approx(sigma * np.sqrt(2 / np.pi),
                                                                                  rel=0.05)
    clean = make_cloud(CloudSpec("test", "SharpFeature", "lblock_a_n0", "lblock_a", 0.0), 5000, seed=3)
    on_surface = surface_distance(clean.points, surface, normals)
    # exact on the flat faces; within a sample spacing of an edge the nearest sample may lie on the other face
    spacing = np.sqrt(cloud.meta["l_d"] ** 2 / len(surface))
    assert np.mean(on_surface < 1e-9) > 0.97 and on_surface.max() < 2 * spacing
    with pytest.raises(InputError, match="given.npz: a given cloud has no known clean surface"):
        surface_sample("given.npz", {"noise_percent": None}, 100)


def test_a_scans_folder_reads_point_files_and_mesh_vertices_and_subsets_by_seed(tmp_path):
    rng = np.random.default_rng(6)
    points = rng.normal(size=(500, 3))
    np.savetxt(tmp_path / "b_tile.xyz", points)
    (tmp_path / "a_mesh.obj").write_text("v 0 0 0\nv 1 0 0\nv 0 1 0\nv 0 0 1\nf 1 2 3\nf 1 2 4\n")
    (tmp_path / "notes.md").write_text("not a scan")
    files = scan_files(tmp_path)
    assert [f.name for f in files] == ["a_mesh.obj", "b_tile.xyz"]
    assert np.array_equal(read_scan(files[0], None, 1), [[0, 0, 0], [1, 0, 0], [0, 1, 0], [0, 0, 1]])
    subset = read_scan(files[1], 300, 1)
    assert len(subset) == 300 and np.array_equal(subset, read_scan(files[1], 300, 1))
    assert {tuple(p) for p in subset} <= {tuple(p) for p in np.loadtxt(tmp_path / "b_tile.xyz")}
    assert not np.array_equal(subset, read_scan(files[1], 300, 2))
    with pytest.raises(InputError, match="fewer than the 10"):
        read_scan(files[0], None, 1, min_points=10)
    (tmp_path / "empty").mkdir()
    with pytest.raises(InputError, match="no scans here"):
        scan_files(tmp_path / "empty")
    with pytest.raises(InputError, match="not a folder of scans"):
        scan_files(tmp_path / "missing")
