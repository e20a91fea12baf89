"""Reading and writing point clouds with normals, with validation that names the file and the problem.

Formats: PCPNet text (`NAME.xyz` + optional `NAME.normals`, also 6-column `.xyz`), `.ply` and `.pcd` (binary
ones by numpy, the rest by Open3D; written here), `.npy` (N x 3 or N x 6), and the pipeline's own `.npz` cloud
records (points, normals and the metadata that produced them, seed included).
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
from refinenet.errors import InputError, OutputError, first_line
from refinenet.interrupts import held

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
        raise InputError(path, f"malformed {what} file ({first_line(err)})") from None
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
    check_count(path, len(array), min_points)
    return array


def check_count(path: str | Path, n_points: int, min_points: int) -> None:
    """Refuse fewer than `min_points` points: alone, for a cloud read before its step knew how many it needs."""
    if n_points < min_points:
        raise InputError(path, f"{n_points} points, fewer than the {min_points} this step needs")


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


def read_cloud(path: str | Path, min_points: int = 1, sibling_normals: bool = False) -> Cloud:
    """Read a point cloud (and its normals when present) from any supported format.

    Only the named file is read, unless `sibling_normals` (the PCPNet format of a data source): then the normals
    of a 3-column `NAME.xyz` come from `NAME.normals` beside it. Normals that are all zero, the placeholders many
    scanners write, count as absent.
    """
    path = Path(path)
    suffix = check_file(path, POINT_SUFFIXES, "point file")
    meta: dict[str, Any] = {}
    try:
        if suffix in (".xyz", ".txt"):
            points, normals = _split_columns(path, _read_table(path, "point"), "point file")
            sibling = path.with_suffix(".normals")
            if normals is None and sibling_normals and sibling.exists():
                normals = _check_normals(sibling, _read_table(sibling, "normals"), len(points))
        elif suffix == ".npy":
            table = _load_npy(path)
            if table.ndim != 2:
                raise InputError(path, f"expected an N x 3 or N x 6 array, found shape {table.shape}")
            points, normals = _split_columns(path, table, ".npy array")
        elif suffix == ".npz":
            points, normals, meta = _read_npz(path)
        else:
            points, normals = _read_ply_or_pcd(path)
    except OSError as err:
        raise InputError(path, f"cannot be read ({err.strerror or type(err).__name__})") from None
    check_array(path, points, "points", min_points)
    check_extent(path, points, "points")
    if normals is not None and len(normals) == len(points) and not np.any(normals):
        normals = None
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
        raise InputError(path, f"unreadable .npy file ({first_line(err)})") from None


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
    one-line error. The list yielded receives the captured lines (colour codes removed) when the block ends.
    Signals wait for the end (`interrupts.held`), so that a command's last line reaches the real stderr."""
    with held():
        with _captured() as captured:
            yield captured


@contextmanager
def _captured() -> Iterator[list[str]]:
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


def native_failure(path: Path, messages: list[str]) -> str | None:
    """The first captured message of a native reader or writer that reports a failure, without Open3D's level
    prefix and with the file named by its name only (the error names its path)."""
    bad = [m for m in messages if re.search(r"fail|error|unable|unexpected", m, flags=re.IGNORECASE)]
    return re.sub(r"^\[Open3D \w+\]\s*", "", bad[0]).replace(str(path), path.name) if bad else None


#: The most header a PLY or PCD file may have (comments included) before its data.
MAX_HEADER = 1 << 24


def _header(path: Path, end: bytes) -> list[list[str]]:
    """The words of each header line of a PLY or PCD file, up to the line starting with `end`."""
    head = b""
    with open(path, "rb") as fh:
        while len(head) < MAX_HEADER and not re.search(rb"(^|\n)" + end, head):
            chunk = fh.read(65536)
            if not chunk:
                break
            head += chunk
    lines = [line.split() for line in head.decode("ascii", "replace").splitlines()]
    ends = [i for i, words in enumerate(lines) if words[:1] == [end.decode()]]
    return lines[:ends[0] + 1] if ends else []


#: The numpy type of each PLY scalar type (in the file's byte order) and of each PCD (TYPE, SIZE).
PLY_TYPES = {"char": "i1", "uchar": "u1", "int8": "i1", "uint8": "u1", "short": "i2", "ushort": "u2", "int16": "i2",
             "uint16": "u2", "int": "i4", "uint": "u4", "int32": "i4", "uint32": "u4", "float": "f4",
             "float32": "f4", "double": "f8", "float64": "f8"}
PLY_ORDERS = {"binary_little_endian": "<", "binary_big_endian": ">"}
PCD_TYPES = {("F", "4"): "<f4", ("F", "8"): "<f8", ("I", "1"): "i1", ("I", "2"): "<i2", ("I", "4"): "<i4",
             ("I", "8"): "<i8", ("U", "1"): "u1", ("U", "2"): "<u2", ("U", "4"): "<u4", ("U", "8"): "<u8"}


def _data_start(path: Path, end: bytes) -> int:
    """The byte offset just past the header line starting with `end`."""
    with open(path, "rb") as fh:
        for line in fh:
            if line.split()[:1] == [end]:
                return fh.tell()
    return path.stat().st_size


def _text_lines(path: Path, start: int) -> int:
    """The non-blank lines of a file from byte `start` on: the rows of a text PLY or PCD body."""
    with open(path, "rb") as fh:
        fh.seek(start)
        return sum(1 for line in fh if line.strip())


def _ply_points(path: Path) -> tuple[int, int | None, np.dtype | None]:
    """The point count a PLY header declares, the rows its data holds (None: not countable, as with a face
    element or a list property) and, for a binary file of vertices alone, the numpy type of a row, after checking
    it declares x, y and z."""
    header = _header(path, b"end_header")
    if not header or header[0][:1] != ["ply"]:
        raise InputError(path, "not a PLY file (no 'ply' ... 'end_header' header)")
    element, count, properties, elements, scalar = None, -1, [], 0, True
    fmt = next((words[1] for words in header if words[:1] == ["format"] and len(words) > 1), "")
    for words in header:
        if words[:1] == ["element"] and len(words) == 3:
            element, elements = words[1], elements + 1
            if element == "vertex":
                count = int(words[2]) if words[2].isdigit() else -1
        elif words[:1] == ["property"] and element == "vertex":
            properties.append((words[-1], words[1]))
            scalar = scalar and len(words) == 3 and words[1] in PLY_TYPES
    names = [name for name, _ in properties]
    if count < 0 or not {"x", "y", "z"} <= set(names):
        raise InputError(path, f"PLY header declares no vertex element with x, y and z (found {names})")
    if elements != 1 or not scalar:
        return count, None, None
    start = _data_start(path, b"end_header")
    if fmt == "ascii":
        return count, _text_lines(path, start), None
    if fmt not in PLY_ORDERS:
        return count, None, None
    row = np.dtype([(f"{i}_{name}", PLY_ORDERS[fmt] + PLY_TYPES[kind]) for i, (name, kind) in enumerate(properties)])
    return count, (path.stat().st_size - start) // row.itemsize, row


def _pcd_header(path: Path) -> dict[str, list[str]]:
    """A PCD header by keyword, checked to declare x, y and z of known types and a point count."""
    header = {words[0]: words[1:] for words in _header(path, b"DATA") if words and not words[0].startswith("#")}
    fields, types = header.get("FIELDS", []), header.get("TYPE", [])
    if not {"x", "y", "z"} <= set(fields):
        raise InputError(path, f"PCD header declares no x, y and z fields (found {fields})")
    if len(types) != len(fields) or not set(types) <= {"F", "I", "U"}:
        raise InputError(path, f"PCD header declares unsupported field types {types} (F, I or U)")
    if not header.get("POINTS", [""])[0].isdigit():
        raise InputError(path, "PCD header declares no POINTS count")
    return header


def _read_binary_pcd(path: Path, header: dict[str, list[str]]) -> tuple[np.ndarray, np.ndarray | None]:
    """Uncompressed binary PCD data, read by numpy: Open3D reads a binary float64 field as zeros."""
    fields, n = header["FIELDS"], int(header["POINTS"][0])
    sizes, counts = header.get("SIZE", []), header.get("COUNT", ["1"] * len(fields))
    try:
        if not all(count.isdigit() and int(count) >= 1 for count in counts):
            raise ValueError("a count below 1")
        dtype = np.dtype([(f"{i}_{name}", PCD_TYPES[kind, size], (int(count),))
                          for i, (name, kind, size, count) in enumerate(zip(fields, header["TYPE"], sizes, counts,
                                                                            strict=True))])
    except (KeyError, ValueError):
        raise InputError(path, f"PCD header declares unsupported field sizes {sizes} or counts {counts}") from None
    start = _data_start(path, b"DATA")
    rows = (path.stat().st_size - start) // dtype.itemsize
    if rows < n:
        raise InputError(path, f"truncated PCD file (header declares {n:,} points, the data holds {rows:,})")
    data = np.fromfile(path, dtype=dtype, count=n, offset=start)
    return _columns(data, fields, ("x", "y", "z")), _columns(data, fields, ("normal_x", "normal_y", "normal_z"))


def _columns(data: np.ndarray, fields: list[str], names: tuple[str, ...]) -> np.ndarray | None:
    """Three named fields of structured rows (each field named `INDEX_NAME`, its first value taken) as an
    N x 3 float64 array, or None where the rows lack one of them."""
    keys = [f"{fields.index(name)}_{name}" for name in names if name in fields]
    if len(keys) != 3:
        return None
    return np.stack([data[k].reshape(len(data), -1)[:, 0] for k in keys], axis=1).astype(np.float64)


def _read_ply_or_pcd(path: Path) -> tuple[np.ndarray, np.ndarray | None]:
    """A PLY or PCD point cloud, checked against its header's count. Binary files of points alone are read by
    numpy (Open3D reads a binary float64 PCD field as zeros, and importing it costs most of a second); the rest,
    text or with faces, by Open3D."""
    if path.stat().st_size == 0:
        raise InputError(path, "empty point file")
    kind = path.suffix[1:].upper()
    row = None
    if kind == "PCD":
        header = _pcd_header(path)
        if header.get("DATA", [""])[0] == "binary":
            return _read_binary_pcd(path, header)
        expected, rows = int(header["POINTS"][0]), None
        if header.get("DATA", [""])[0] == "ascii":
            rows = _text_lines(path, _data_start(path, b"DATA"))
    else:
        expected, rows, row = _ply_points(path)
    if rows is not None and rows < expected:
        raise InputError(path, f"truncated {kind} file (header declares {expected:,} points, the data holds "
                               f"{rows:,})")
    if row is not None:
        data = np.fromfile(path, dtype=row, count=expected, offset=_data_start(path, b"end_header"))
        fields = [name.split("_", 1)[1] for name in row.names]
        return _columns(data, fields, ("x", "y", "z")), _columns(data, fields, ("nx", "ny", "nz"))
    return _read_open3d(path, kind, expected)


def _read_open3d(path: Path, kind: str, expected: int) -> tuple[np.ndarray, np.ndarray | None]:
    """A text PLY or PCD, or a PLY with faces, by Open3D, which must find the `expected` points."""
    import open3d as o3d

    with native_output_captured() as messages:
        pcd = o3d.io.read_point_cloud(str(path), print_progress=False)
    points = np.asarray(pcd.points, dtype=np.float64)
    problem = native_failure(path, messages)
    if problem or len(points) == 0 or len(points) != expected:
        found = f"; {problem}" if problem else f", read {len(points):,}"
        raise InputError(path, f"truncated or malformed {kind} file (header declares {expected:,} points{found})")
    normals = np.asarray(pcd.normals, dtype=np.float64) if pcd.has_normals() else None
    return points, normals


def write_cloud(path: str | Path, cloud: Cloud) -> None:
    """Write the pipeline's `.npz` cloud record (float32 is not used: noise at 0.05% needs float64)."""
    arrays = {"points": cloud.points} if cloud.normals is None else {"points": cloud.points, "normals": cloud.normals}
    save_record(path, arrays, cloud.meta)


def write_normals(path: str | Path, normals: np.ndarray) -> None:
    """An N x 3 normal file in the PCPNet `.normals` text format, or binary `.npy`."""
    path = Path(path)
    with atomic_path(path) as tmp:
        if path.suffix.lower() == ".npy":
            with open(tmp, "wb") as fh:
                np.save(fh, np.asarray(normals, dtype=np.float32))
        else:
            np.savetxt(tmp, np.asarray(normals, dtype=np.float64), fmt="%.8f")


def read_normals(path: str | Path, n_points: int, rows: np.ndarray | None = None) -> np.ndarray:
    """Normals written by `write_normals`, checked against the expected point count. With `rows`, only those rows
    are returned and checked: the others may be NaN, points no estimator computed (`data.clouds.scored_points`)."""
    path = Path(path)
    if path.suffix.lower() == ".npy":
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


def output_files(path: str | Path) -> list[Path]:
    """The files `write_points` makes for `path`: the path, and for `.xyz` its `.normals` beside it (PCPNet)."""
    path = Path(path)
    return [path, path.with_suffix(".normals")] if check_output_type(path) == ".xyz" else [path]


def write_points(path: str | Path, points: np.ndarray, normals: np.ndarray) -> None:
    """A cloud and its normals in the format of the path's suffix (OUTPUT_SUFFIXES, any case): binary `.ply`;
    `.pcd`; `.xyz` with a `.normals` file beside it (PCPNet); `.txt` with 6 columns; `.npy` as an N x 6 float64
    array; or `.normals`, the normals alone. The points read back bit for bit from every format: text holds each
    coordinate's shortest exact decimal, `.pcd` is binary float32 where that holds every coordinate exactly and
    text float64 (which Open3D reads) where it does not."""
    suffix = check_output_type(path)
    if suffix == ".ply":
        write_ply(path, points, normals)
    elif suffix == ".pcd":
        _write_pcd(path, points, normals)
    elif suffix == ".normals":
        write_normals(path, normals)
    elif suffix == ".npy":
        with atomic_path(path) as tmp, open(tmp, "wb") as fh:
            np.save(fh, np.concatenate([points, normals], axis=1).astype(np.float64))
    else:
        with atomic_path(path) as tmp, open(tmp, "w") as fh:
            fh.writelines(_text_rows(points, None if suffix == ".xyz" else normals))
        if suffix == ".xyz":
            write_normals(output_files(path)[1], normals)


def _text_rows(points: np.ndarray, normals: np.ndarray | None) -> Iterator[str]:
    """Rows of exact coordinates (Python's shortest round-trip repr) and, if given, normals to 8 decimals."""
    if normals is None:
        for x, y, z in points.tolist():
            yield f"{x!r} {y!r} {z!r}\n"
    else:
        for (x, y, z), (a, b, c) in zip(points.tolist(), normals.tolist(), strict=True):
            yield f"{x!r} {y!r} {z!r} {a:.8f} {b:.8f} {c:.8f}\n"


def _write_pcd(path: str | Path, points: np.ndarray, normals: np.ndarray) -> None:
    """A PCD file with normals, binary float32 when that holds every coordinate exactly, else text float64."""
    exact32 = np.array_equal(points.astype(np.float32).astype(np.float64), points)
    size, data = ("4", "binary") if exact32 else ("8", "ascii")
    header = (f"# .PCD v0.7 - Point Cloud Data file format\nVERSION 0.7\n"
              f"FIELDS x y z normal_x normal_y normal_z\nSIZE {' '.join([size] * 6)}\nTYPE F F F F F F\n"
              f"COUNT 1 1 1 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\n"
              f"POINTS {len(points)}\nDATA {data}\n")
    with atomic_path(path) as tmp, open(tmp, "w" if data == "ascii" else "wb") as fh:
        if exact32:
            fh.write(header.encode())
            _write_rows(fh, [points, normals], "<f4")
        else:
            fh.write(header)
            fh.writelines(_text_rows(points, normals))


def check_output_type(path: str | Path) -> str:
    """The lower-case suffix of an output path `write_points` can write; otherwise an OutputError naming it."""
    suffix = Path(path).suffix.lower()
    if suffix not in OUTPUT_SUFFIXES:
        raise OutputError(path, f"unsupported output type '{suffix}' (use one of {', '.join(OUTPUT_SUFFIXES)})")
    return suffix


def write_ply(path: str | Path, points: np.ndarray, normals: np.ndarray | None = None) -> None:
    """A binary little-endian `.ply` of float64 points, with optional per-point normals, readable by Open3D,
    MeshLab and CloudCompare. Written here rather than by Open3D, whose writer reports success on a full disk."""
    columns = [np.asarray(points, dtype=np.float64)] + ([] if normals is None else [np.asarray(normals, np.float64)])
    names = ["x", "y", "z"] + ([] if normals is None else ["nx", "ny", "nz"])
    header = (f"ply\nformat binary_little_endian 1.0\nelement vertex {len(points)}\n"
              + "".join(f"property double {name}\n" for name in names) + "end_header\n")
    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        fh.write(header.encode("ascii"))
        _write_rows(fh, columns, "<f8")


def _write_rows(fh, columns: list[np.ndarray], dtype: str, chunk: int = 1 << 20) -> None:
    """The columns side by side as binary rows of `dtype`, a chunk of rows at a time (a bounded copy)."""
    for start in range(0, len(columns[0]), chunk):
        fh.write(np.concatenate([c[start:start + chunk] for c in columns], axis=1).astype(dtype).tobytes())
