"""Triangle meshes: reading `.off`/`.obj`/`.ply` with validation, and area-uniform sampling with face normals.

Sampling follows PCPNet: a point's ground truth is the normal of the face it lies on, so planar faces give
their exact plane normal. OFF is parsed here rather than by Open3D, whose reader rounds vertices to float32,
rejects the one-line header variant (`OFF V F E`) and silently returns a partial mesh from a truncated file;
OBJ and PLY go through Open3D.
"""

from __future__ import annotations

import re
from pathlib import Path

import numpy as np

from refinenet.data.io import check_extent, check_file, native_failure, native_output_captured
from refinenet.errors import InputError

MESH_SUFFIXES = (".off", ".obj", ".ply")


def read_mesh(path: str | Path) -> tuple[np.ndarray, np.ndarray]:
    """Vertices (V, 3) float64 and triangles (F, 3) int64; polygons are fan-triangulated."""
    path = Path(path)
    suffix = check_file(path, MESH_SUFFIXES, "mesh")
    if path.stat().st_size == 0:
        raise InputError(path, "empty mesh file")
    vertices, faces = _read_off(path) if suffix == ".off" else _read_open3d(path)
    return _checked(path, vertices, faces)


def _checked(path: Path, vertices: np.ndarray, faces: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    if len(faces) == 0:
        raise InputError(path, "no triangles in mesh (empty, truncated or a point cloud)")
    bad = ~np.isfinite(vertices).all(axis=1)
    if bad.any():
        raise InputError(path, f"NaN or inf in vertex coordinates (first at vertex {int(np.argmax(bad))})")
    if faces.min() < 0 or faces.max() >= len(vertices):
        row = int(np.argmax((faces < 0).any(axis=1) | (faces >= len(vertices)).any(axis=1)))
        raise InputError(path, f"triangle {row} refers to a vertex outside 0..{len(vertices) - 1}")
    check_extent(path, vertices[np.unique(faces)], "vertices")
    if not (np.linalg.norm(_face_cross(vertices, faces), axis=1) > 0).any():
        raise InputError(path, f"all {len(faces)} triangles have zero area (repeated or collinear vertices)")
    return vertices, faces


def _fan(polygons: list[list[str]]) -> list[tuple[str, str, str]]:
    return [(p[0], p[j], p[j + 1]) for p in polygons for j in range(1, len(p) - 1)]


def _read_off(path: Path) -> tuple[np.ndarray, np.ndarray]:
    """OFF, COFF, NOFF...: counts on the keyword line or the next one, `#` comments, extra columns ignored."""
    try:
        text = path.read_text(encoding="utf-8-sig")
    except UnicodeDecodeError:
        raise InputError(path, "not a text OFF file (binary OFF is not supported)") from None
    rows = [r for r in (line.split("#", 1)[0].split() for line in text.splitlines()) if r]
    if not rows or not re.fullmatch(r"[A-Z]*OFF", rows[0][0]):
        raise InputError(path, "not an OFF file (the first word must be OFF, COFF, NOFF, ...)")
    start = 1 if len(rows[0]) > 1 else 2
    counts = rows[0][1:] if len(rows[0]) > 1 else (rows[1] if len(rows) > 1 else [])
    try:
        n_vertices, n_faces = int(counts[0]), int(counts[1])
    except (IndexError, ValueError):
        raise InputError(path, "malformed OFF header (expected vertex, face and edge counts)") from None
    vertex_rows = rows[start:start + n_vertices]
    face_rows = rows[start + n_vertices:start + n_vertices + n_faces]
    polygons = [r[1:1 + int(r[0])] for r in face_rows if r[0].isdigit() and 3 <= int(r[0]) <= len(r) - 1]
    if len(vertex_rows) < n_vertices or len(polygons) < n_faces or any(len(r) < 3 for r in vertex_rows):
        raise InputError(path, f"truncated or malformed OFF file (header declares {n_vertices} vertices and "
                               f"{n_faces} faces)")
    try:
        vertices = np.array([r[:3] for r in vertex_rows], dtype=np.float64)
        faces = np.array(_fan(polygons), dtype=np.int64).reshape(-1, 3)
    except ValueError as err:
        raise InputError(path, f"non-numeric value in OFF file ({err})") from None
    return vertices, faces


def _ply_counts(path: Path) -> tuple[int, int]:
    """Vertex and face counts declared by a PLY header (-1 when not declared)."""
    with open(path, "rb") as fh:
        header = fh.read(65536).split(b"end_header", 1)[0].decode("ascii", "replace")
    counts = dict(re.findall(r"^element\s+(\w+)\s+(\d+)", header, flags=re.MULTILINE))
    return int(counts.get("vertex", -1)), int(counts.get("face", -1))


def _read_open3d(path: Path) -> tuple[np.ndarray, np.ndarray]:
    import open3d as o3d

    if path.suffix.lower() == ".obj":
        _check_obj_vertices(path)
    with native_output_captured() as messages:  # Open3D's and RPly's warnings, kept off the stage's stderr
        mesh = o3d.io.read_triangle_mesh(str(path), print_progress=False)
    vertices = np.asarray(mesh.vertices, dtype=np.float64)
    faces = np.asarray(mesh.triangles, dtype=np.int64)
    problem = native_failure(path, messages)
    if problem and len(faces) == 0:
        raise InputError(path, f"unreadable mesh ({problem})")
    if path.suffix.lower() == ".ply":
        n_vertices, n_faces = _ply_counts(path)
        if len(vertices) != n_vertices or len(faces) < n_faces:
            raise InputError(path, f"truncated or unreadable PLY file (header declares {n_vertices} vertices "
                                   f"and {n_faces} faces, read {len(vertices)} and {len(faces)} triangles)")
    return vertices, faces


def _check_obj_vertices(path: Path) -> None:
    """Every `v` line of an OBJ file has three numbers (Open3D's reader silently drops the rest of the mesh), and
    there is an `f` line."""
    faces = 0
    with open(path, "rb") as fh:
        for number, line in enumerate(fh, 1):
            words = line.split()
            if words[:1] == [b"v"] and not _numbers(words[1:4], 3):
                text = line.decode("utf-8", "replace").strip()
                raise InputError(path, f"vertex on line {number} is not three numbers ({text[:60]!r})")
            faces += words[:1] == [b"f"]
    if not faces:
        raise InputError(path, "no triangles in mesh (no 'f' lines: a point cloud?)")


def _numbers(words: list[bytes], count: int) -> bool:
    try:
        return len([float(w) for w in words]) == count
    except ValueError:
        return False


def _face_cross(vertices: np.ndarray, faces: np.ndarray) -> np.ndarray:
    """(b - a) x (c - a) per face: twice the area times the unit normal given by the winding."""
    a, b, c = (vertices[faces[:, k]] for k in range(3))
    return np.cross(b - a, c - a)


def mesh_area(vertices: np.ndarray, faces: np.ndarray) -> float:
    """Total surface area."""
    return 0.5 * float(np.linalg.norm(_face_cross(vertices, faces), axis=1).sum())


def sample_mesh(vertices: np.ndarray, faces: np.ndarray, n_points: int,
                rng: np.random.Generator) -> tuple[np.ndarray, np.ndarray]:
    """`n_points` points uniform by area and the unit normal of the face each lies on (faces wound outward).

    A face is drawn with probability proportional to its area, so zero-area faces are never drawn; the point
    is `a + sqrt(r1) (b - a) + sqrt(r1) r2 (c - b)`, uniform on the triangle and exactly in the plane of
    an axis-aligned face.
    """
    if n_points < 0:
        raise ValueError(f"n_points must be >= 0, got {n_points}")
    cross = _face_cross(vertices, faces)
    twice_area = np.linalg.norm(cross, axis=1)
    usable = np.flatnonzero(twice_area > 0)
    if len(usable) == 0:
        raise ValueError("the mesh has no triangle of non-zero area")
    chosen = usable[rng.choice(len(usable), size=n_points, p=twice_area[usable] / twice_area[usable].sum())]
    a, b, c = (vertices[faces[chosen, k]] for k in range(3))
    s = np.sqrt(rng.random((n_points, 1)))
    t = rng.random((n_points, 1))
    points = a + s * (b - a) + (s * t) * (c - b)
    return points, cross[chosen] / twice_area[chosen, None]
