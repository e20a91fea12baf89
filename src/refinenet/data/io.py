"""Reading and writing point clouds with normals, with validation that names the file and the problem.

Formats: PCPNet text (`NAME.xyz` + optional `NAME.normals`, also 6-column `.xyz`), `.ply` and `.pcd`
(via Open3D), `.npy` (N x 3 or N x 6), and the pipeline's own `.npz` cloud records (points, normals and
the metadata that produced them, seed included).
"""

from __future__ import annotations

import ctypes
import io
import json
import os
import re
import sys
import tempfile
import warnings
from collections.abc import Iterator
from contextlib import contextmanager, redirect_stderr, redirect_stdout
from dataclasses import dataclass, field
from pathlib import Path
from typing import Any

import numpy as np

from refinenet.atomic import atomic_path
from refinenet.errors import InputError, OutputError

#: Point files a user or a data source gives, and (with .npz) the pipeline's own cloud records.
POINT_FILE_SUFFIXES = (".xyz", ".txt", ".ply", ".pcd", ".npy")
POINT_SUFFIXES = (*POINT_FILE_SUFFIXES, ".npz")
#: Files `write_points` makes: a cloud with its normals, or (.normals) the normals alone.
OUTPUT_SUFFIXES = (".ply", ".pcd", ".xyz", ".txt", ".npy", ".normals")
#: Coordinates the estimators handle: MFPS and the feature filter square distances in float32, which overflows
#: near 1e19 and underflows near 1e-19 (a unit sphere scaled by 1e-16 to 1e18 gives the same normals; by 1e30
#: it gives NaN or a traceback). A cloud or mesh must lie within +-MAX_COORDINATE and span at least MIN_EXTENT
#: (its largest side), which leaves a margin of 1e4 or more for the spacing of points; otherwise rescale it.
MAX_COORDINATE = 1e12
MIN_EXTENT = 1e-12
#: A normal component beyond this would overflow when squared; such rows are rescaled before normalising.
HUGE_COMPONENT = 1e150


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
        with warnings.catch_warnings():  # an all-comment file is reported below, not as a warning on stderr
            warnings.simplefilter("ignore", UserWarning)
            table = np.loadtxt(path, dtype=np.float64, ndmin=2, comments="#", encoding="utf-8-sig")
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


def check_extent(path: str | Path, coordinates: np.ndarray, what: str) -> None:
    """Refuse finite coordinates the estimators cannot handle: beyond +-MAX_COORDINATE, or (two or more points)
    all coinciding or spanning less than MIN_EXTENT."""
    if len(coordinates) == 0:
        return
    big = np.abs(coordinates).max(axis=1) > MAX_COORDINATE
    if big.any():
        row = int(np.argmax(big))
        raise InputError(path, f"{what} coordinate {np.abs(coordinates[row]).max():.3g} at row {row + 1} is beyond "
                               f"+-{MAX_COORDINATE:.0e}, the range the estimators support (rescale the data)")
    extent = float((coordinates.max(axis=0) - coordinates.min(axis=0)).max())
    if len(coordinates) > 1 and extent == 0:
        raise InputError(path, f"all {len(coordinates)} {what} coincide: there is no surface")
    if len(coordinates) > 1 and extent < MIN_EXTENT:
        raise InputError(path, f"the {what} span only {extent:.3g}, below the {MIN_EXTENT:.0e} the estimators "
                               f"support (rescale the data)")


def _check_normals(path: Path, normals: np.ndarray, n_points: int) -> np.ndarray:
    check_array(path, normals, "normals")
    if len(normals) != n_points:
        raise InputError(path, f"{len(normals)} normals for {n_points} points")
    # Rows whose squares would overflow (components beyond 1e150) are first scaled to a largest component of 1;
    # every other row is normalised as it is, so ordinary files give bit-identical unit normals.
    largest = np.abs(normals).max(axis=1, keepdims=True)
    normals = np.where(largest > HUGE_COMPONENT, normals / np.maximum(largest, 1.0), normals)
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
    if Path(path).is_dir():
        raise InputError(path, f"is a folder, not a {what}")
    if not Path(path).is_file():
        raise InputError(path, f"{what} not found")
    return suffix


def read_cloud(path: str | Path, min_points: int = 1) -> Cloud:
    """Read a point cloud (and its normals when present) from any supported format."""
    path = Path(path)
    suffix = check_file(path, POINT_SUFFIXES, "point file")
    meta: dict[str, Any] = {}
    if suffix in (".xyz", ".txt"):
        points, normals = _split_columns(path, _read_table(path, "point"), "point file")
        sibling = path.with_suffix(".normals")
        if normals is None and sibling.exists():
            normals = _check_normals(sibling, _read_table(sibling, "normals"), len(points))
    elif suffix == ".npy":
        table = _load_npy(path)
        if table.ndim != 2:
            raise InputError(path, f"expected an N x 3 or N x 6 array, found shape {table.shape}")
        points, normals = _split_columns(path, table, ".npy array")
    elif suffix == ".npz":
        points, normals, meta = _read_npz(path)
    else:
        points, normals = _read_open3d(path)
    check_array(path, points, "points", min_points)
    check_extent(path, points, "points")
    if normals is not None:
        normals = _check_normals(path, normals, len(points))
    return Cloud(points, normals, meta)


def _load_npy(path: Path) -> np.ndarray:
    """A numeric `.npy` array as float64. Never unpickles (object arrays are refused), and maps the file before
    copying it, so a header that declares more data than the file holds is an error, not a huge allocation."""
    try:
        array = np.load(path, mmap_mode="r", allow_pickle=False)
        if not isinstance(array, np.ndarray):
            raise ValueError("not a single array")
        if array.dtype.kind not in "iuf":
            raise InputError(path, f"expected an array of numbers, found dtype {array.dtype}")
        return np.array(array, dtype=np.float64)
    except (ValueError, OSError, EOFError) as err:
        first = str(err).strip().splitlines()[0] if str(err).strip() else type(err).__name__
        raise InputError(path, f"unreadable .npy file ({first})") from None


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


@contextmanager
def native_output_captured() -> Iterator[list[str]]:
    """Run a native reader with its output sent to a buffer: Open3D prints its warnings through Python's
    `sys.stdout`, and the RPly library inside it straight to the C stderr, which would add lines to a stage's
    one-line error. The list yielded receives the captured lines (colour codes removed) when the block ends."""
    captured: list[str] = []
    python_output = io.StringIO()
    for stream in (sys.stdout, sys.stderr):
        if stream is not None:
            stream.flush()
    try:
        saved = os.dup(1), os.dup(2)
    except OSError:  # no standard streams to redirect
        saved = None
    with tempfile.TemporaryFile() as sink, redirect_stdout(python_output), redirect_stderr(python_output):
        try:
            if saved:
                os.dup2(sink.fileno(), 1)
                os.dup2(sink.fileno(), 2)
            yield captured
        finally:
            if saved:
                try:
                    ctypes.CDLL(None).fflush(None)  # C stdio buffers, before the streams are given back
                except (OSError, AttributeError, TypeError):
                    pass
                for fd, original in zip((1, 2), saved, strict=True):
                    os.dup2(original, fd)
                    os.close(original)
            sink.seek(0)
            text = python_output.getvalue() + sink.read().decode("utf-8", "replace")
            text = re.sub(r"\x1b\[[0-9;]*m", "", text)
            captured.extend(line.strip() for line in text.splitlines() if line.strip())


def reader_failure(path: Path, messages: list[str]) -> str | None:
    """The first captured message of a native reader that reports a failure, without Open3D's level prefix and
    with the file named by its name only (the error names its path)."""
    bad = [m for m in messages if re.search(r"fail|error|unable|unexpected", m, flags=re.IGNORECASE)]
    return re.sub(r"^\[Open3D \w+\]\s*", "", bad[0]).replace(str(path), path.name) if bad else None


def _header(path: Path, end: bytes) -> list[list[str]]:
    """The words of each header line of a PLY or PCD file, up to the line starting with `end`."""
    with open(path, "rb") as fh:
        head = fh.read(65536)
    lines = [line.split() for line in head.decode("ascii", "replace").splitlines()]
    ends = [i for i, words in enumerate(lines) if words[:1] == [end.decode()]]
    return lines[:ends[0] + 1] if ends else []


def _expected_points(path: Path, suffix: str) -> int:
    """The point count a PLY or PCD header declares, after checking it declares x, y and z in a known type."""
    if suffix == ".ply":
        header = _header(path, b"end_header")
        if not header or header[0][:1] != ["ply"]:
            raise InputError(path, "not a PLY file (no 'ply' ... 'end_header' header)")
        element, count, properties = None, -1, []
        for words in header:
            if words[:1] == ["element"] and len(words) == 3:
                element = words[1]
                if element == "vertex":
                    count = int(words[2]) if words[2].isdigit() else -1
            elif words[:1] == ["property"] and element == "vertex":
                properties.append(words[-1])
        if count < 0 or not {"x", "y", "z"} <= set(properties):
            raise InputError(path, f"PLY header declares no vertex element with x, y and z (found {properties})")
        return count
    header = {words[0]: words[1:] for words in _header(path, b"DATA") if words and not words[0].startswith("#")}
    fields, types = header.get("FIELDS", []), header.get("TYPE", [])
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(path, f"PCD header declares no x, y and z fields (found {fields})")
    if len(types) != len(fields) or not set(types) <= {"F", "I", "U"}:
        raise InputError(path, f"PCD header declares unsupported field types {types} (F, I or U)")
    points = header.get("POINTS", [""])[0]
    if not points.isdigit():
        raise InputError(path, "PCD header declares no POINTS count")
    rows = _pcd_rows(path, header)
    if rows is not None and rows < int(points):
        raise InputError(path, f"truncated PCD file (header declares {points} points, the data holds {rows})")
    return int(points)


def _pcd_rows(path: Path, header: dict[str, list[str]]) -> int | None:
    """Rows of point data a PCD file holds (Open3D pads a short file with zeros); None: compressed data."""
    data = header.get("DATA", [""])[0]
    sizes, counts = header.get("SIZE", []), header.get("COUNT", ["1"] * len(header.get("SIZE", [])))
    with open(path, "rb") as fh:
        for line in fh:
            if line.split()[:1] == [b"DATA"]:
                break
        if data == "ascii":
            return sum(1 for line in fh if line.strip())
        if data == "binary" and all(w.isdigit() for w in (*sizes, *counts)) and len(sizes) == len(counts):
            row_bytes = sum(int(a) * int(b) for a, b in zip(sizes, counts, strict=True))
            return (path.stat().st_size - fh.tell()) // row_bytes if row_bytes else None
    return None


def _read_open3d(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    import open3d as o3d

    if path.stat().st_size == 0:
        raise InputError(path, "empty point file")
    suffix = path.suffix.lower()
    expected = _expected_points(path, suffix)
    with native_output_captured() as messages:
        pcd = o3d.io.read_point_cloud(str(path), print_progress=False)
    points = np.asarray(pcd.points, dtype=np.float64)
    problem = reader_failure(path, messages)
    if problem or len(points) == 0 or len(points) != expected:
        raise InputError(path, f"truncated or malformed {suffix[1:].upper()} file (header declares {expected} "
                               f"points, read {len(points)}{'; ' + problem if problem else ''})")
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


def read_normals(path: str | Path, n_points: int, rows: np.ndarray | None = None) -> np.ndarray:
    """Normals written by `write_normals`, checked against the expected point count. With `rows`, only those rows
    are returned and checked: the others may be NaN, points no estimator computed (`data.clouds.scored_points`)."""
    path = Path(path)
    if path.suffix == ".npy":
        if not path.is_file():
            raise InputError(path, "normals file not found")
        normals = _load_npy(path)
    else:
        normals = _read_table(path, "normals")
    if rows is None:
        return _check_normals(path, normals, n_points)
    if normals.ndim != 2 or len(normals) != n_points:
        raise InputError(path, f"{len(normals)} normals for {n_points} points")
    return _check_normals(path, normals[rows], len(rows))


def write_points(path: str | Path, points: np.ndarray, normals: np.ndarray) -> None:
    """A cloud and its normals in the format of the path's suffix (OUTPUT_SUFFIXES): binary `.ply` or `.pcd`;
    `.xyz` with a `.normals` file beside it (PCPNet); `.txt` with 6 columns; `.npy` as an N x 6 float64 array;
    or `.normals`, the normals alone."""
    suffix = check_output_type(path)
    if suffix in (".ply", ".pcd"):
        write_ply(path, points, normals)
    elif suffix == ".xyz":
        write_xyz_normals(path, points, normals)
    elif suffix == ".normals":
        write_normals(path, normals)
    else:
        table = np.concatenate([points, normals], axis=1)
        with atomic_path(path) as tmp:
            if suffix == ".npy":
                with open(tmp, "wb") as fh:
                    np.save(fh, table)
            else:
                np.savetxt(tmp, table, fmt="%.8f")


def check_output_type(path: str | Path) -> str:
    """The lower-case suffix of an output path `write_points` can write; otherwise an OutputError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise OutputError(path, f"unsupported output type '{suffix}' (use one of {', '.join(OUTPUT_SUFFIXES)})")
    return suffix


def write_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None) -> None:
    """A binary `.ply` (or `.pcd`, by the suffix) with optional per-point normals, readable by Open3D, MeshLab
    and CloudCompare."""
    import open3d as o3d

    pcd = o3d.geometry.PointCloud(o3d.utility.Vector3dVector(np.asarray(points, dtype=np.float64)))
    if normals is not None:
        pcd.normals = o3d.utility.Vector3dVector(np.asarray(normals, dtype=np.float64))
    with atomic_path(path) as tmp:
        if not o3d.io.write_point_cloud(str(tmp), pcd, write_ascii=False):
            raise OutputError(path, "Open3D could not write the file")
