"""Reading and writing point clouds with normals, with validation that names the file and the problem.

Formats: PCPNet text (`NAME.xyz` + optional `NAME.normals`, also 6-column `.xyz`), `.ply` and `.pcd`
(via Open3D), `.npy` (N x 3 or N x 6), and the pipeline's own `.npz` cloud records (points, normals and
the metadata that produced them, seed included).
"""

from __future__ import annotations

import json
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from refinenet.atomic import atomic_path
from refinenet.errors import InputError, OutputError

#: Point files a user or a data source gives, and (with .npz) the pipeline's own cloud records.
POINT_FILE_SUFFIXES = (".xyz", ".ply", ".pcd", ".npy")
POINT_SUFFIXES = (*POINT_FILE_SUFFIXES, ".npz")


@dataclass
class Cloud:
    """A point cloud, its (ground-truth or estimated) normals if known, and how it was made."""

    points: np.ndarray
    normals: np.ndarray | None = None
    meta: dict[str, Any] = field(default_factory=dict)

    def __len__(self) -> int:
        return len(self.points)


def _read_table(path: Path, what: str) -> np.ndarray:
    """A whitespace-separated numeric table with 3 or 6 columns, every line complete."""
    if not path.is_file():
        raise InputError(path, f"{what} file not found")
    if path.stat().st_size == 0:
        raise InputError(path, f"empty {what} file")
    try:
        table = np.loadtxt(path, dtype=np.float64, ndmin=2, comments="#")
    except ValueError as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else "unreadable"
        raise InputError(path, f"malformed {what} file ({first})") from None
    if table.size == 0:
        raise InputError(path, f"empty {what} file (no numeric rows)")
    return table


def check_array(path: str | Path, array: np.ndarray, what: str, min_points: int = 1) -> np.ndarray:
    """Refuse arrays that are not N x 3, hold NaN/inf, or have fewer than `min_points` rows."""
    if array.ndim != 2 or array.shape[1] != 3:
        raise InputError(path, f"{what} must have 3 columns, found shape {array.shape}")
    bad = ~np.isfinite(array).all(axis=1)
    if bad.any():
        raise InputError(path, f"{what} contain NaN or inf (first at row {int(np.argmax(bad)) + 1})")
    if len(array) < min_points:
        raise InputError(path, f"{len(array)} points, fewer than the {min_points} this step needs")
    return array


def _check_normals(path: Path, normals: np.ndarray, n_points: int) -> np.ndarray:
    check_array(path, normals, "normals")
    if len(normals) != n_points:
        raise InputError(path, f"{len(normals)} normals for {n_points} points")
    length = np.linalg.norm(normals, axis=1)
    if (length < 1e-12).any():
        raise InputError(path, f"zero-length normal at row {int(np.argmax(length < 1e-12)) + 1}")
    return normals / length[:, None]


def _split_columns(path: Path, table: np.ndarray, what: str) -> tuple[np.ndarray, np.ndarray | None]:
    if table.shape[1] == 3:
        return table, None
    if table.shape[1] == 6:
        return table[:, :3], table[:, 3:]
    raise InputError(path, f"{what} has {table.shape[1]} columns; expected 3 (x y z) or 6 (x y z nx ny nz)")


def check_file(path: str | Path, suffixes: tuple[str, ...], what: str) -> str:
    """The lower-case suffix of an existing file of one of the `suffixes`; otherwise an InputError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix not in suffixes:
        raise InputError(path, f"unsupported {what} type '{suffix}' (use one of {', '.join(suffixes)})")
    if not Path(path).is_file():
        raise InputError(path, f"{what} not found")
    return suffix


def read_cloud(path: str | Path, min_points: int = 1) -> Cloud:
    """Read a point cloud (and its normals when present) from any supported format."""
    path = Path(path)
    suffix = check_file(path, POINT_SUFFIXES, "point file")
    meta: dict[str, Any] = {}
    if suffix == ".xyz":
        points, normals = _split_columns(path, _read_table(path, "point"), "point file")
        sibling = path.with_suffix(".normals")
        if normals is None and sibling.exists():
            normals = _check_normals(sibling, _read_table(sibling, "normals"), len(points))
    elif suffix == ".npy":
        try:
            table = np.load(path, allow_pickle=False)
        except (ValueError, OSError, EOFError) as err:
            raise InputError(path, f"unreadable .npy file ({err})") from None
        if table.ndim != 2:
            raise InputError(path, f"expected an N x 3 or N x 6 array, found shape {table.shape}")
        points, normals = _split_columns(path, table.astype(np.float64), ".npy array")
    elif suffix == ".npz":
        points, normals, meta = _read_npz(path)
    else:
        points, normals = _read_open3d(path)
    check_array(path, points, "points", min_points)
    if normals is not None:
        normals = _check_normals(path, normals, len(points))
    return Cloud(points, normals, meta)


def save_record(path: str | Path, arrays: dict[str, np.ndarray], meta: dict[str, Any]) -> None:
    """An uncompressed `.npz` of named arrays plus JSON metadata (seeds, settings), written atomically: the
    pipeline's format for clouds, feature caches and cluster models."""
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        np.savez(fh, **arrays, meta=np.asarray(json.dumps(meta, sort_keys=True)))


def load_record(path: str | Path, required: tuple[str, ...], what: str) -> tuple[dict[str, np.ndarray], dict[str, Any]]:
    """The arrays and metadata of a `save_record` file; every array in `required` must be there and all arrays
    present are returned. A missing or malformed file is an InputError naming `what` it should have been."""
    path = Path(path)
    try:
        data = np.load(path, allow_pickle=False)
        if not isinstance(data, np.lib.npyio.NpzFile):
            raise ValueError("not an .npz archive")
        with data:
            missing = [key for key in required if key not in data]
            if missing:
                raise KeyError(f"no {', '.join(missing)}")
            arrays = {key: data[key] for key in data.files if key != "meta"}
            meta = json.loads(str(data["meta"])) if "meta" in data else {}
    except (ValueError, OSError, EOFError, KeyError) as err:
        raise InputError(path, f"not a {what} ({err})") from None
    return arrays, meta


def _read_npz(path: Path) -> tuple[np.ndarray, np.ndarray | None, dict[str, Any]]:
    arrays, meta = load_record(path, ("points",), "cloud record")
    normals = arrays.get("normals")
    return arrays["points"].astype(np.float64), None if normals is None else normals.astype(np.float64), meta


def _read_open3d(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    import open3d as o3d

    if path.stat().st_size == 0:
        raise InputError(path, "empty point file")
    pcd = o3d.io.read_point_cloud(str(path), print_progress=False)
    points = np.asarray(pcd.points, dtype=np.float64)
    if len(points) == 0:
        raise InputError(path, "no points could be read (empty, truncated or malformed file)")
    normals = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    return points, normals


def write_cloud(path: str | Path, cloud: Cloud) -> None:
    """Write the pipeline's `.npz` cloud record (float32 is not used: noise at 0.05% needs float64)."""
    arrays = {"points": cloud.points} if cloud.normals is None else {"points": cloud.points, "normals": cloud.normals}
    save_record(path, arrays, cloud.meta)


def write_xyz_normals(base: str | Path, points: np.ndarray, normals: np.ndarray | None = None) -> None:
    """PCPNet format: `base.xyz` and, when normals are given, `base.normals` (both atomically)."""
    base = Path(base)
    if base.suffix in (".xyz", ".normals"):
        base = base.with_suffix("")
    outputs = [(base.with_name(base.name + ".xyz"), points)]
    if normals is not None:
        outputs.append((base.with_name(base.name + ".normals"), normals))
    for path, array in outputs:
        with atomic_path(path) as tmp:
            np.savetxt(tmp, np.asarray(array, dtype=np.float64), fmt="%.8f")


def write_normals(path: str | Path, normals: np.ndarray) -> None:
    """An N x 3 normal file in the PCPNet `.normals` text format, or binary `.npy`."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if path.suffix == ".npy":
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(normals, dtype=np.float32))
        else:
            np.savetxt(tmp, np.asarray(normals, dtype=np.float64), fmt="%.8f")


def read_normals(path: str | Path, n_points: int) -> np.ndarray:
    """Normals written by `write_normals`, checked against the expected point count."""
    path = Path(path)
    if path.suffix == ".npy":
        if not path.is_file():
            raise InputError(path, "normals file not found")
        normals = np.load(path, allow_pickle=False).astype(np.float64)
    else:
        normals = _read_table(path, "normals")
    return _check_normals(path, normals, n_points)


def write_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None) -> None:
    """A binary `.ply` with optional per-point normals, readable by Open3D, MeshLab and CloudCompare."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), pcd, write_ascii=False):
            raise OutputError(path, "Open3D could not write the file")
