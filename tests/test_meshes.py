"""Mesh reading (format variants, one-line errors naming the file) and area-uniform sampling with face normals."""

from pathlib import Path

import numpy as np
import pytest

from refinenet.data.meshes import MESH_SUFFIXES, mesh_area, read_mesh, sample_mesh
from refinenet.errors import InputError

# unit cube, vertex index 4x + 2y + z, triangles wound outward: -x, +x, -y, +y, -z, +z
CUBE_VERTICES = np.array([[x, y, z] for x in (0.0, 1.0) for y in (0.0, 1.0) for z in (0.0, 1.0)])
CUBE_FACES = np.array([[0, 1, 3], [0, 3, 2], [4, 6, 7], [4, 7, 5], [0, 4, 5], [0, 5, 1],
                       [2, 3, 7], [2, 7, 6], [0, 2, 6], [0, 6, 4], [1, 5, 7], [1, 7, 3]])
CHI2_5DOF_P001 = 20.52  # chi-square quantile at p = 0.001, 5 degrees of freedom


def test_cube_faces_are_wound_outward():
    a, b, c = (CUBE_VERTICES[CUBE_FACES[:, k]] for k in range(3))
    outward = (a + b + c) / 3 - 0.5
    assert (np.sum(np.cross(b - a, c - a) * outward, axis=1) > 0).all()
    assert mesh_area(CUBE_VERTICES, CUBE_FACES) == pytest.approx(6.0, abs=1e-12)


def test_cube_samples_lie_on_their_face_with_its_axis_normal():
    n = 60_000
    points, normals = sample_mesh(CUBE_VERTICES, CUBE_FACES, n, np.random.default_rng(0))
    assert points.shape == normals.shape == (n, 3)
    axis = np.argmax(np.abs(normals), axis=1)
    sign = normals[np.arange(n), axis]
    assert np.isin(sign, (-1.0, 1.0)).all() and (np.abs(normals).sum(axis=1) == 1.0).all()
    # exactly on the face plane: x == 0 on the -x face, x == 1 on the +x face, inside [0, 1] elsewhere
    assert (points[np.arange(n), axis] == (sign > 0)).all()
    assert ((points >= 0) & (points <= 1)).all()
    counts = np.bincount(2 * axis + (sign > 0), minlength=6)
    assert np.sum((counts - n / 6) ** 2 / (n / 6)) < CHI2_5DOF_P001


def test_points_are_uniform_inside_a_triangle():
    n = 40_000
    points, normals = sample_mesh(np.array([[0.0, 0, 0], [1, 0, 0], [0, 1, 0]]), np.array([[0, 1, 2]]), n,
                                  np.random.default_rng(1))
    assert (normals == [0.0, 0.0, 1.0]).all() and (points[:, 2] == 0).all()
    assert (points[:, :2] >= 0).all() and (points[:, 0] + points[:, 1] <= 1 + 1e-15).all()
    # the corner region x > 1/2 holds a quarter of the area; so does y > 1/2
    for coordinate in (0, 1):
        share = np.mean(points[:, coordinate] > 0.5)
        assert abs(share - 0.25) < 4 * np.sqrt(0.25 * 0.75 / n)


def test_zero_area_faces_are_never_sampled():
    vertices = np.concatenate([CUBE_VERTICES, [[5.0, 5, 5], [6, 6, 6], [7, 7, 7]]])  # a collinear triple
    faces = np.concatenate([CUBE_FACES, [[8, 9, 10], [8, 8, 9]]])
    points, _ = sample_mesh(vertices, faces, 20_000, np.random.default_rng(2))
    assert points.max() <= 1.0
    with pytest.raises(ValueError, match="non-zero area"):
        sample_mesh(vertices, np.array([[8, 9, 10]]), 10, np.random.default_rng(2))


def test_sampling_is_deterministic_per_seed():
    first = sample_mesh(CUBE_VERTICES, CUBE_FACES, 500, np.random.default_rng(7))
    second = sample_mesh(CUBE_VERTICES, CUBE_FACES, 500, np.random.default_rng(7))
    other = sample_mesh(CUBE_VERTICES, CUBE_FACES, 500, np.random.default_rng(8))
    assert all(np.array_equal(a, b) for a, b in zip(first, second, strict=True))
    assert not np.array_equal(first[0], other[0])


def _write(path: Path, text: str) -> Path:
    path.write_text(text)
    return path


def test_off_header_variants_comments_colours_and_polygons(tmp_path):
    plain = _write(tmp_path / "plain.off", "OFF\n# a comment\n\n4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
    one_line = _write(tmp_path / "one_line.off", "OFF 4 2 0\n0 0 0\n1 0 0\n1 1 0\n0 1 0\n3 0 1 2\n3 0 2 3\n")
    coloured = _write(tmp_path / "coloured.off",
                      "COFF\n4 1 0\n0 0 0 9 9 9 1\n1 0 0 9 9 9 1\n1 1 0 9 9 9 1\n0 1 0 9 9 9 1\n4 0 1 2 3 255 0 0\n")
    expected = np.array([[0, 1, 2], [0, 2, 3]])
    for path in (plain, one_line, coloured):
        vertices, faces = read_mesh(path)
        assert vertices.dtype == np.float64 and faces.dtype == np.int64
        np.testing.assert_array_equal(vertices, [[0, 0, 0], [1, 0, 0], [1, 1, 0], [0, 1, 0]])
        np.testing.assert_array_equal(faces, expected)


def test_ply_round_trip_and_truncated_ply(tmp_path):
    import open3d as o3d

    mesh = o3d.geometry.TriangleMesh(o3d.utility.Vector3dVector(CUBE_VERTICES),
                                     o3d.utility.Vector3iVector(CUBE_FACES.astype(np.int32)))
    path = tmp_path / "cube.ply"
    assert o3d.io.write_triangle_mesh(str(path), mesh, write_ascii=False)
    vertices, faces = read_mesh(path)
    np.testing.assert_array_equal(vertices, CUBE_VERTICES)
    np.testing.assert_array_equal(faces, CUBE_FACES)
    truncated = tmp_path / "truncated.ply"
    truncated.write_bytes(path.read_bytes()[:-7])
    with pytest.raises(InputError, match="truncated") as err:
        read_mesh(truncated)
    assert str(truncated) in str(err.value)


BAD_FILES = {
    "empty.off": ("", "empty"),
    "truncated.off": ("OFF\n4 4 0\n0 0 0\n1 0 0\n0 1 0\n0 0 1\n3 0 2 1\n3 0 1 3\n", "truncated"),
    "short_face.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1\n", "truncated"),
    "nan.off": ("OFF\n3 1 0\n0 0 0\nnan 0 0\n0 1 0\n3 0 1 2\n", "NaN"),
    "nan.obj": ("v 0 0 0\nv 1 0 0\nv 0 inf 0\nf 1 2 3\n", "NaN"),
    "no_faces.off": ("OFF\n3 0 0\n0 0 0\n1 0 0\n0 1 0\n", "no triangles"),
    "bad_index.off": ("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n", "outside 0..2"),
    "text.off": ("OFF\n3 1 0\n0 0 0\n1 x 0\n0 1 0\n3 0 1 2\n", "non-numeric"),
    "header.off": ("PLY\n3 1 0\n", "not an OFF file"),
    "cloud.obj": ("v 0 0 0\nv 1 0 0\nv 0 1 0\n", "no triangles"),
    "mesh.stl": ("solid x\n", "unsupported mesh type"),
}


@pytest.mark.parametrize("name", BAD_FILES)
def test_bad_files_raise_one_line_errors_naming_the_file(tmp_path, name):
    text, problem = BAD_FILES[name]
    path = _write(tmp_path / name, text)
    with pytest.raises(InputError, match=problem) as err:
        read_mesh(path)
    assert str(path) in str(err.value) and "\n" not in str(err.value)


def test_missing_file(tmp_path):
    with pytest.raises(InputError, match="not found") as err:
        read_mesh(tmp_path / "absent.off")
    assert str(tmp_path / "absent.off") in str(err.value)


def test_shared_meshes_read_finite_and_agree_with_open3d(shared_data):
    import open3d as o3d

    files = sorted(p for p in (shared_data / "meshes").glob("*/*/*") if p.suffix.lower() in MESH_SUFFIXES)
    if not files:
        pytest.skip(f"no mesh files under {shared_data / 'meshes'}")
    for path in files:
        vertices, faces = read_mesh(path)
        assert np.isfinite(vertices).all() and len(faces) > 0 and faces.max() < len(vertices), path
        if path.suffix == ".off":  # Open3D reads OFF coordinates as float32
            reference = o3d.io.read_triangle_mesh(str(path))
            np.testing.assert_array_equal(faces, np.asarray(reference.triangles), err_msg=str(path))
            np.testing.assert_allclose(vertices, np.asarray(reference.vertices), rtol=1e-6, atol=1e-6,
                                       err_msg=str(path))
