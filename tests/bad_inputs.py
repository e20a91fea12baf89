"""A corpus of malformed, hostile and degenerate input files, generated on the fly (no binaries are kept).

Each `Case` is a small record: the file name, how to build it (bytes, text, or a builder that writes the file and
any siblings into a folder), the kind of reader it targets, and the outcome a user should get:

* `ERROR`: every entry point that reads it stops with one line `error: PATH: PROBLEM` (exit status 2 for the stage
  scripts), where PATH is the case's file or its `culprit` and PROBLEM contains `problem`;
* `VALID`: a valid but degenerate input that works: the result is finite and every normal is of unit length.

`needs_k` marks clouds that are only too small for a step with a neighbourhood (the baselines' K, MFPS' scales, the
height maps' k): an error there, valid for the readers and the data sources, which take any size.

`python tests/bad_inputs.py` prints the corpus and the entry points each case goes through (`entry_points`); the
tests in `tests/test_bad_inputs.py` run them.
"""

from __future__ import annotations

import struct
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from refinenet.data.io import POINT_FILE_SUFFIXES

ERROR, VALID = "error", "valid"
#: The user command, as an entry point: `refinenet normals` (a subprocess, like the stage scripts).
CLI = "cli.normals"
KINDS = ("cloud", "normals", "mesh", "pcpnet", "params")
#: Points of every usable cloud: more than the largest neighbourhood of params.yaml (MFPS: 1.5 x 150 = 225).
N_POINTS = 300
#: Points of the clouds that are too small for the neighbourhood steps (K = 100 in params.yaml).
FEW_POINTS = 40
#: Name of the file that a hostile pickle creates if it is ever unpickled.
UNPICKLED = "UNPICKLED"
#: A PCPNet list file of the `pcpnet` cases, and the shape the `normals` and `pcpnet` cases pair with.
LIST_FILE = "test list.txt"

Builder = Callable[[Path], None]


@dataclass(frozen=True)
class Case:
    name: str
    """The file (or folder) name the case writes; for `pcpnet` cases the list file, for `params` the params file."""
    kind: str
    """cloud | normals | mesh | pcpnet | params: which reader it targets."""
    content: bytes | str | Builder | None
    """The file's bytes or text, or a builder writing `folder / name` (and siblings); None: nothing (missing)."""
    expect: str
    """ERROR or VALID."""
    problem: str = ""
    """A substring of the error's PROBLEM part (ERROR cases)."""
    culprit: str | None = None
    """The file the error must name, relative to the folder, when it is not `name`."""
    needs_k: bool = False
    """Too few points only for steps with a neighbourhood: an error there, valid for the readers and sources."""
    all_stages: bool = False
    """Also run through the slower stage scripts (mfps, features), not only the fast one of its kind."""
    root_skip: bool = False
    """Meaningless as root (file permissions do not stop root from reading): skipped there."""
    note: str = ""

    def write(self, folder: Path) -> Path:
        """Write the case into `folder` (created) and return the path an entry point is given."""
        folder.mkdir(parents=True, exist_ok=True)
        path = folder / self.name
        if self.content is not None:
            write_content(path, self.content)
        return path

    @property
    def offender(self) -> str:
        """The file name the one-line error must name."""
        return self.culprit or self.name


# ----------------------------------------------------------------------------------------------------------- data


def write_content(path: Path, content: bytes | str | Builder) -> None:
    """Write a case's file: its bytes, its text (UTF-8, as given: no newline translation), or by its builder."""
    if isinstance(content, bytes):
        path.write_bytes(content)
    elif isinstance(content, str):
        path.write_bytes(content.encode())
    else:
        content(path)


def _rng(tag: str) -> np.random.Generator:
    return np.random.default_rng(sum(tag.encode()))


def sphere(n: int = N_POINTS, tag: str = "sphere") -> tuple[np.ndarray, np.ndarray]:
    """Points on the unit sphere and their outward normals."""
    points = _rng(tag).normal(size=(n, 3))
    points /= np.linalg.norm(points, axis=1, keepdims=True)
    return points, points.copy()


def _rows(array: np.ndarray, sep: str = " ", end: str = "\n", fmt: str = "{:.9g}") -> str:
    return "".join(sep.join(fmt.format(v) for v in row) + end for row in array)


def _six(points: np.ndarray, normals: np.ndarray | None = None) -> np.ndarray:
    if normals is None:
        normals = np.tile([0.0, 0.0, 1.0], (len(points), 1))
    return np.hstack([points, normals])


def good_cloud_text(n: int = N_POINTS) -> str:
    """The companion cloud of the normals cases: N points, 3 columns."""
    return _rows(sphere(n, "companion")[0])


def good_normals_text(n: int = N_POINTS) -> str:
    return _rows(sphere(n, "companion")[1])


def _xyz(table: np.ndarray, **fmt) -> Builder:
    return lambda path: path.write_text(_rows(table, **fmt))


def _npy(array: np.ndarray) -> Builder:
    def build(path: Path) -> None:
        with open(path, "wb") as fh:
            np.save(fh, array, allow_pickle=False)
    return build


class _Trap:
    """Pickled inside an object array: unpickling it would create the file UNPICKLED beside the case."""

    def __init__(self, target: str):
        self.target = target

    def __reduce__(self):
        return (open, (self.target, "w"))


def _pickled(rows: int, cols: int = 3) -> Builder:
    def build(path: Path) -> None:
        array = np.empty((rows, cols), dtype=object)
        array[:] = 0.0
        array[0, 0] = _Trap(str(path.parent / UNPICKLED))
        with open(path, "wb") as fh:
            np.save(fh, array, allow_pickle=True)
    return build


def _npy_lying_header(path: Path) -> None:
    """A valid .npy header declaring 10^12 rows, followed by the data of 10."""
    header = "{'descr': '<f8', 'fortran_order': False, 'shape': (1000000000000, 3), }"
    header += " " * (118 - len(header)) + "\n"
    path.write_bytes(b"\x93NUMPY\x01\x00" + struct.pack("<H", len(header)) + header.encode()
                     + np.zeros((10, 3)).tobytes())


def _npy_truncated(path: Path) -> None:
    _npy(_six(*sphere()))(path)
    data = path.read_bytes()
    path.write_bytes(data[:len(data) - 1000])


def _npz_without_points(path: Path) -> None:
    with open(path, "wb") as fh:
        np.savez(fh, normals=sphere()[1])


def _npz_pickled_points(path: Path) -> None:
    array = np.empty((N_POINTS, 3), dtype=object)
    array[:] = 0.0
    array[0, 0] = _Trap(str(path.parent / UNPICKLED))
    with open(path, "wb") as fh:
        np.savez(fh, points=array)


def _ply(props: list[str], rows: np.ndarray, declared: int | None = None, binary: bool = False,
         faces: list[tuple[int, ...]] | None = None, declared_faces: int | None = None) -> bytes:
    """A PLY file with float vertex `props`, `rows` of data, and a header declaring `declared` vertices."""
    fmt = "binary_little_endian" if binary else "ascii"
    header = ["ply", f"format {fmt} 1.0", f"element vertex {len(rows) if declared is None else declared}"]
    header += [f"property float {p}" for p in props]
    if faces is not None:
        header += [f"element face {len(faces) if declared_faces is None else declared_faces}",
                   "property list uchar int vertex_indices"]
    body = b""
    if binary:
        body = np.asarray(rows, dtype="<f4").tobytes()
        for face in faces or []:
            body += struct.pack(f"<B{len(face)}i", len(face), *face)
    else:
        body = _rows(rows).encode() + "".join(f"{len(f)} {' '.join(map(str, f))}\n" for f in faces or []).encode()
    return ("\n".join(header) + "\nend_header\n").encode() + body


def _ply_builder(*args, **kwargs) -> Builder:
    return lambda path: path.write_bytes(_ply(*args, **kwargs))


def _pcd(fields: str, types: str, rows: np.ndarray, declared: int | None = None, binary: bool = False,
         counts: str | None = None) -> bytes:
    """A PCD file of 4-byte fields, text or binary, with `counts` (one per field; default 1 each)."""
    n = len(rows) if declared is None else declared
    count = counts or " ".join("1" for _ in fields.split())
    size = " ".join("4" for _ in fields.split())
    header = (f"# .PCD v0.7\nVERSION 0.7\nFIELDS {fields}\nSIZE {size}\nTYPE {types}\nCOUNT {count}\n"
              f"WIDTH {n}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {n}\nDATA {'binary' if binary else 'ascii'}\n")
    return header.encode() + (np.asarray(rows, "<f4").tobytes() if binary else _rows(rows).encode())


def _directory(path: Path) -> None:
    path.mkdir()


def _unreadable(content: str) -> Builder:
    def build(path: Path) -> None:
        path.write_text(content)
        path.chmod(0)
    return build


CUBE_V = [(0, 0, 0), (1, 0, 0), (1, 1, 0), (0, 1, 0), (0, 0, 1), (1, 0, 1), (1, 1, 1), (0, 1, 1)]
CUBE_F = [(0, 3, 2, 1), (4, 5, 6, 7), (0, 1, 5, 4), (1, 2, 6, 5), (2, 3, 7, 6), (3, 0, 4, 7)]


def _off(vertices, faces, header: str = "OFF", counts: tuple[int, int] | None = None, end: str = "\n") -> str:
    nv, nf = counts or (len(vertices), len(faces))
    lines = [header, f"{nv} {nf} 0"]
    lines += [" ".join(f"{c:.9g}" if isinstance(c, float) else str(c) for c in v) for v in vertices]
    lines += [f"{len(f)} " + " ".join(map(str, f)) for f in faces]
    return end.join(lines) + end


def _obj(vertices, faces) -> str:
    return "".join(f"v {x} {y} {z}\n" for x, y, z in vertices) + "".join(
        "f " + " ".join(str(i) for i in f) + "\n" for f in faces)


def _pcpnet(list_text: str | bytes, shapes: dict[str, dict[str, str | bytes | Builder]]) -> Builder:
    """A PCPNet folder: the list file, and per shape name its files by suffix (.xyz, .normals, .pidx)."""
    def build(path: Path) -> None:
        (path.write_bytes if isinstance(list_text, bytes) else path.write_text)(list_text)
        for shape, files in shapes.items():
            for suffix, content in files.items():
                write_content(path.parent / f"{shape}{suffix}", content)
    return build


def _shape(pidx: str | bytes | None = None, normals: str | bytes | None = None) -> dict[str, str | bytes]:
    files: dict[str, str | bytes] = {".xyz": good_cloud_text(), ".normals": good_normals_text()}
    if normals is not None:
        files[".normals"] = normals
    if pidx is not None:
        files[".pidx"] = pidx
    return files


def _params(transform: Callable[[str], str]) -> Builder:
    repo_params = Path(__file__).resolve().parents[1] / "params.yaml"
    return lambda path: path.write_text(transform(repo_params.read_text()))


# ---------------------------------------------------------------------------------------------------------- corpus


def _cloud_cases() -> list[Case]:
    pts, nrm = sphere()
    six = _six(pts, nrm)
    flat = _rng("flat").uniform(size=(N_POINTS, 2))
    plane = np.c_[flat, np.zeros(N_POINTS)]
    t = np.linspace(0, 1, N_POINTS)[:, None]
    dup = np.repeat(sphere(N_POINTS // 3, "dup")[0], 3, axis=0)
    few = _six(*sphere(FEW_POINTS, "few"))
    nan_normal, zero_normal = six.copy(), six.copy()
    nan_normal[7, 4] = np.nan
    zero_normal[5, 3:] = 0
    return [
        # --- text clouds: errors
        Case("empty.xyz", "cloud", b"", ERROR, "empty"),
        Case("blank lines.xyz", "cloud", "\n   \n\t\n", ERROR, "empty"),
        Case("comments only.xyz", "cloud", "# x y z\n# no data\n", ERROR, "empty"),
        Case("truncated.xyz", "cloud", _rows(pts[:50]) + "0.5 0.25", ERROR, "malformed"),
        Case("cut number.xyz", "cloud", _rows(pts[:50]) + "0.5 0.25 1.5e", ERROR, "malformed"),
        Case("non numeric.xyz", "cloud", _rows(pts[:50]) + "1 two 3\n", ERROR, "malformed"),
        Case("nan.xyz", "cloud", _rows(pts[:50]) + "nan 0 1\n", ERROR, "NaN or inf"),
        Case("inf.xyz", "cloud", _rows(pts[:50]) + "1 -inf 1\n", ERROR, "NaN or inf"),
        Case("overflow.xyz", "cloud", _rows(pts[:50]) + "1e999 0 0\n", ERROR, "NaN or inf",
             note="1e999 parses as inf"),
        Case("four columns.xyz", "cloud", _rows(np.c_[pts, pts[:, :1]]), ERROR, "4 columns"),
        Case("two columns.xyz", "cloud", _rows(pts[:, :2]), ERROR, "2 columns"),
        Case("ragged.xyz", "cloud", _rows(pts[:50]) + _rows(six[:50]), ERROR, "malformed",
             note="3 then 6 columns"),
        Case("mixed delimiters.xyz", "cloud", _rows(pts[:50]) + _rows(pts[:50], sep=","), ERROR, "malformed"),
        Case("csv.xyz", "cloud", _rows(pts, sep=","), ERROR, "malformed", note="comma-separated: not PCPNet text"),
        Case("header line.xyz", "cloud", "x y z\n" + _rows(pts), ERROR, "malformed",
             note="a header must be a # comment"),
        Case("binary garbage.xyz", "cloud", bytes(range(256)) * 8, ERROR, "malformed"),
        Case("latin1.xyz", "cloud", "0 0 0\n1 0 0\n\xe9 1 0\n".encode("latin-1"), ERROR, "malformed"),
        Case("zero normal.xyz", "cloud", _xyz(zero_normal), ERROR, "zero-length normal"),
        Case("nan normal.xyz", "cloud", _xyz(nan_normal), ERROR, "NaN or inf"),
        Case("few points.xyz", "cloud", _xyz(few), ERROR, "fewer than", needs_k=True, all_stages=True),
        Case("one point.xyz", "cloud", "0 0 0 0 0 1\n", ERROR, "fewer than", needs_k=True),
        Case("folder.xyz", "cloud", _directory, ERROR, "", note="a directory named like a cloud"),
        Case("missing.xyz", "cloud", None, ERROR, "not found"),
        Case("unreadable.xyz", "cloud", _unreadable(_rows(six)), ERROR, "", root_skip=True),
        Case("cloud.las", "cloud", _rows(six), ERROR, "unsupported"),
        Case("no suffix", "cloud", _rows(six), ERROR, "unsupported"),
        # --- text clouds: valid but degenerate
        Case("crlf.xyz", "cloud", _xyz(six, end="\r\n"), VALID, note="Windows line ends", all_stages=True),
        Case("bom.xyz", "cloud", lambda p: p.write_bytes(b"\xef\xbb\xbf" + _rows(six).encode()), VALID,
             note="UTF-8 byte-order mark (Windows editors)", all_stages=True),
        Case("tabs.xyz", "cloud", _xyz(six, sep=" \t "), VALID, note="tabs and spaces mixed"),
        Case("cloud.txt", "cloud", _rows(six), VALID, note="a text table named .txt, as many tools export it"),
        Case("exponents.xyz", "cloud", _xyz(six, fmt="{:.6E}"), VALID),
        Case("UPPER.XYZ", "cloud", _xyz(six), VALID, note="upper-case suffix"),
        Case("my cloud with spaces.xyz", "cloud", _xyz(six), VALID),
        Case("nuage_été_点云.xyz", "cloud", _xyz(six), VALID, note="non-ASCII name"),
        Case("identical.xyz", "cloud", _xyz(_six(np.tile([0.3, -1.0, 2.0], (N_POINTS, 1)))), ERROR, "coincide",
             note="all points identical: no surface", all_stages=True),
        Case("collinear.xyz", "cloud", _xyz(_six(t * [1.0, 2.0, 3.0])), VALID, all_stages=True),
        Case("coplanar.xyz", "cloud", _xyz(_six(plane)), VALID, all_stages=True),
        Case("duplicates.xyz", "cloud", _xyz(_six(dup)), VALID, note="every point three times", all_stages=True),
        Case("huge.xyz", "cloud", _xyz(_six(pts * 1e30, nrm)), ERROR, "beyond",
             note="coordinates ~1e30: squared distances overflow the estimators' float32"),
        Case("overflowing.xyz", "cloud", _xyz(_six(pts * 1e200, nrm)), ERROR, "beyond",
             note="coordinates ~1e200: squares overflow float64"),
        Case("tiny.xyz", "cloud", _xyz(_six(pts * 1e-200, nrm)), ERROR, "span only",
             note="coordinates ~1e-200: squares underflow to 0"),
        Case("big extent.xyz", "cloud", _xyz(_six(pts * 1e10, nrm)), VALID,
             note="a sphere of radius 1e10, near the supported limit", all_stages=True),
        Case("small extent.xyz", "cloud", _xyz(_six(pts * 1e-10, nrm)), VALID,
             note="a sphere of radius 1e-10, near the supported limit", all_stages=True),
        Case("offset.xyz", "cloud", _xyz(_six(pts + 1e9, nrm)), VALID,
             note="a unit sphere 1e9 away from the origin", all_stages=True),
        # --- .npy
        Case("strings.npy", "cloud", _npy(np.full((N_POINTS, 3), "abc")), ERROR, "", note="unicode dtype"),
        Case("complex.npy", "cloud", _npy(six.astype(np.complex128) * 1j), ERROR, ""),
        Case("structured.npy", "cloud", _npy(np.zeros(N_POINTS, dtype=[("x", "f4"), ("y", "f4"), ("z", "f4")])),
             ERROR, ""),
        Case("flat.npy", "cloud", _npy(pts.ravel()), ERROR, "shape"),
        Case("cube.npy", "cloud", _npy(np.zeros((10, 10, 3))), ERROR, "shape"),
        Case("five columns.npy", "cloud", _npy(np.zeros((N_POINTS, 5))), ERROR, "5 columns"),
        Case("nan.npy", "cloud", _npy(np.where(six == six[3, 1], np.nan, six)), ERROR, "NaN or inf"),
        Case("pickled.npy", "cloud", _pickled(N_POINTS, 6), ERROR, "",
             note="object array: must not be unpickled", all_stages=True),
        Case("lying header.npy", "cloud", _npy_lying_header, ERROR, "", note="declares 10^12 rows, holds 10"),
        Case("truncated.npy", "cloud", _npy_truncated, ERROR, ""),
        Case("not numpy.npy", "cloud", b"just text, not an array\n", ERROR, ""),
        Case("int32.npy", "cloud", _npy(np.c_[_rng("int").integers(-50, 50, (N_POINTS, 3)),
                                              np.tile([0, 0, 1], (N_POINTS, 1))].astype(np.int32)), VALID,
             note="integer coordinates"),
        Case("float32.npy", "cloud", _npy(six.astype(np.float32)), VALID),
        # --- .npz cloud records
        Case("no points.npz", "cloud", _npz_without_points, ERROR, "points"),
        Case("pickled.npz", "cloud", _npz_pickled_points, ERROR, "", note="object array: must not be unpickled"),
        # --- PLY point clouds
        Case("no z.ply", "cloud", _ply_builder(["x", "y"], pts[:, :2]), ERROR, ""),
        Case("lying count ascii.ply", "cloud", _ply_builder(["x", "y", "z"], pts, declared=2 * N_POINTS),
             ERROR, "", note="declares twice the vertices it holds", all_stages=True),
        Case("lying count binary.ply", "cloud",
             _ply_builder(["x", "y", "z"], pts, declared=2 * N_POINTS, binary=True), ERROR, ""),
        Case("extra data binary.ply", "cloud", _ply_builder(["x", "y", "z", "nx", "ny", "nz"], six,
                                                            declared=N_POINTS // 2, binary=True), VALID,
             note="declares half the vertices it holds: those are read, the rest ignored, as by any PLY reader"),
        Case("zero vertices.ply", "cloud", _ply_builder(["x", "y", "z"], pts[:0]), ERROR, ""),
        Case("nan.ply", "cloud", _ply_builder(["x", "y", "z"], np.where(pts == pts[9, 2], np.nan, pts)),
             ERROR, "NaN or inf"),
        Case("normals.ply", "cloud", _ply_builder(["x", "y", "z", "nx", "ny", "nz"], six, binary=True), VALID),
        # --- PCD
        Case("no xyz.pcd", "cloud", _pcd("a b c", "F F F", pts), ERROR, "", note="unsupported fields"),
        Case("unknown type.pcd", "cloud", _pcd("x y z", "Q Q Q", pts), ERROR, "", note="TYPE Q does not exist"),
        Case("lying count.pcd", "cloud", _pcd("x y z", "F F F", pts, declared=2 * N_POINTS), ERROR, ""),
        Case("intensity.pcd", "cloud", _pcd("x y z intensity normal_x normal_y normal_z", "F F F F F F F",
                                            np.c_[pts, np.ones(N_POINTS), nrm]), VALID, note="an extra field"),
        Case("binary.pcd", "cloud", _pcd("x y z normal_x normal_y normal_z", "F F F F F F", six, binary=True), VALID,
             note="read by numpy"),
        Case("zero count binary.pcd", "cloud", _pcd("x y z", "F F F", pts, binary=True, counts="0 1 1"), ERROR,
             "counts", note="a field of no values"),
        Case("lying count binary.pcd", "cloud", _pcd("x y z", "F F F", pts, declared=2 * N_POINTS, binary=True),
             ERROR, "truncated"),
    ]


def _normals_cases() -> list[Case]:
    nrm = sphere(N_POINTS, "companion")[1]
    zero, nan = nrm.copy(), nrm.copy()
    zero[11] = 0
    nan[12, 1] = np.nan
    return [
        Case("short.normals", "normals", _xyz(nrm[:-1]), ERROR, "normals for", all_stages=True),
        Case("long.normals", "normals", _xyz(np.r_[nrm, nrm[:1]]), ERROR, "normals for"),
        Case("zero vector.normals", "normals", _xyz(zero), ERROR, "zero-length", all_stages=True),
        Case("nan.normals", "normals", _xyz(nan), ERROR, "NaN or inf"),
        Case("two columns.normals", "normals", _xyz(nrm[:, :2]), ERROR, "3 columns"),
        Case("empty.normals", "normals", b"", ERROR, "empty"),
        Case("text.normals", "normals", "nx ny nz\n" + _rows(nrm), ERROR, "malformed"),
        Case("folder.normals", "normals", _directory, ERROR, ""),
        Case("wrong shape.npy", "normals", _npy(np.zeros((N_POINTS, 4))), ERROR, "3 columns", all_stages=True),
        Case("pickled normals.npy", "normals", _pickled(N_POINTS), ERROR, "",
             note="object array: must not be unpickled", all_stages=True),
        Case("garbage normals.npy", "normals", b"\x00\x01 not an array", ERROR, "", all_stages=True),
        Case("strings normals.npy", "normals", _npy(np.full((N_POINTS, 3), "x")), ERROR, ""),
        Case("huge.normals", "normals", _xyz(nrm * 1e200), VALID,
             note="lengths ~1e200: squares overflow", all_stages=True),
        Case("tiny.normals", "normals", _xyz(nrm * 1e-200), ERROR, "zero-length",
             note="lengths ~1e-200: below the zero-length threshold"),
        Case("unnormalised.normals", "normals", _xyz(nrm * 3.5), VALID),
        Case("crlf.normals", "normals", _xyz(nrm, end="\r\n"), VALID),
        Case("float16.npy", "normals", _npy(nrm.astype(np.float16)), VALID),
    ]


def _mesh_cases() -> list[Case]:
    tri = [(0.0, 0.0, 0.0), (1.0, 0.0, 0.0), (0.0, 1.0, 0.0)]
    return [
        Case("empty.off", "mesh", b"", ERROR, "empty", all_stages=True),
        Case("no keyword.off", "mesh", _off(CUBE_V, CUBE_F).replace("OFF\n", ""), ERROR, "not an OFF"),
        Case("index too large.off", "mesh", _off(CUBE_V, [*CUBE_F[:5], (3, 0, 4, 8)]), ERROR, "outside",
             all_stages=True),
        Case("negative index.off", "mesh", _off(CUBE_V, [*CUBE_F[:5], (3, -1, 4, 7)]), ERROR, ""),
        Case("all degenerate.off", "mesh", _off(tri, [(0, 0, 1), (1, 2, 2)]), ERROR, "area",
             note="every face repeats a vertex", all_stages=True),
        Case("collinear face.off", "mesh", _off([*tri, (2.0, 0.0, 0.0)], [(0, 1, 3)]), ERROR, "area"),
        Case("some degenerate.off", "mesh", _off(CUBE_V, [*CUBE_F, (0, 0, 1), (2, 2, 2)]), VALID,
             note="zero-area faces beside good ones", all_stages=True),
        Case("truncated.off", "mesh", _off(CUBE_V, CUBE_F)[:-30], ERROR, "truncated", all_stages=True),
        Case("missing vertices.off", "mesh", _off(CUBE_V[:6], CUBE_F, counts=(8, 6)), ERROR, "truncated"),
        Case("non numeric.off", "mesh", _off(CUBE_V, CUBE_F).replace("1 1 1", "1 one 1"), ERROR, "non-numeric"),
        Case("nan vertex.off", "mesh", _off(CUBE_V, CUBE_F).replace("1 1 1", "1 nan 1"), ERROR, "NaN"),
        Case("no faces.off", "mesh", _off(CUBE_V, []), ERROR, "no triangles"),
        Case("two-vertex face.off", "mesh", _off(CUBE_V, [*CUBE_F[:5], (0, 1)]), ERROR, ""),
        Case("huge.off", "mesh", _off([tuple(1e30 * c for c in v) for v in CUBE_V], CUBE_F), ERROR, "beyond",
             all_stages=True),
        Case("overflowing.off", "mesh", _off([tuple(1e200 * c for c in v) for v in CUBE_V], CUBE_F), ERROR,
             "beyond", note="face areas overflow float64"),
        Case("far away.off", "mesh", _off([tuple(c + 1e6 for c in v) for v in CUBE_V], CUBE_F), VALID,
             note="a unit cube 1e6 from the origin"),
        Case("crlf.off", "mesh", _off(CUBE_V, CUBE_F, end="\r\n"), VALID, all_stages=True),
        Case("bom.off", "mesh", lambda p: p.write_bytes(b"\xef\xbb\xbf" + _off(CUBE_V, CUBE_F).encode()), VALID,
             note="UTF-8 byte-order mark", all_stages=True),
        Case("binary.off", "mesh", b"OFF\n\xff\xfe\x00\x01" * 20, ERROR, ""),
        Case("cube mesh with spaces é.off", "mesh", _off(CUBE_V, CUBE_F), VALID, all_stages=True),
        Case("index too large.obj", "mesh", _obj(CUBE_V, [(1, 2, 3), (1, 3, 99)]), ERROR, ""),
        Case("points only.obj", "mesh", _obj(CUBE_V, []), ERROR, "no triangles"),
        Case("non numeric.obj", "mesh", _obj(CUBE_V, [(1, 2, 3)]).replace("v 1 1 1", "v 1 one 1"), ERROR,
             "three numbers", all_stages=True),
        Case("degenerate.obj", "mesh", _obj(CUBE_V, [(1, 1, 2), (3, 3, 3)]), ERROR, "area"),
        Case("lying count.ply", "mesh", _ply_builder(["x", "y", "z"], np.array(CUBE_V, float), declared=16,
                                                     faces=[(0, 1, 2), (0, 2, 3)]), ERROR, "", all_stages=True),
        Case("no faces.ply", "mesh", _ply_builder(["x", "y", "z"], np.array(CUBE_V, float)), ERROR, ""),
        Case("truncated binary.ply", "mesh",
             lambda p: p.write_bytes(_ply(["x", "y", "z"], np.array(CUBE_V, float), binary=True,
                                          faces=[(0, 1, 2), (0, 2, 3), (4, 5, 6)])[:-10]), ERROR, ""),
        Case("face index.ply", "mesh", _ply_builder(["x", "y", "z"], np.array(CUBE_V, float),
                                                    faces=[(0, 1, 2), (0, 2, 30)]), ERROR, ""),
        Case("folder.off", "mesh", _directory, ERROR, "", all_stages=True),
        Case("unreadable.off", "mesh", _unreadable(_off(CUBE_V, CUBE_F)), ERROR, "", root_skip=True),
        Case("mesh.stl", "mesh", "solid x\nendsolid x\n", ERROR, "unsupported"),
    ]


def _pcpnet_cases() -> list[Case]:
    good = _shape()
    return [
        Case(LIST_FILE, "pcpnet", _pcpnet("shape\nmissing_shape\n", {"shape": good}), ERROR, "not found",
             culprit="missing_shape.xyz", note="list names a missing file", all_stages=True),
        Case("absent list.txt", "pcpnet", None, ERROR, "not found", all_stages=True),
        Case("list folder.txt", "pcpnet", _directory, ERROR, ""),
        Case("binary list.txt", "pcpnet", _pcpnet(b"\xff\xfe\x00shape\x00\n", {"shape": good}), ERROR, "not a text",
             all_stages=True),
        Case("empty list.txt", "pcpnet", _pcpnet("", {"shape": good}), ERROR, "empty", note="no shape at all",
             all_stages=True),
        Case("pidx out of range.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(pidx=f"0\n5\n{N_POINTS}\n")}),
             ERROR, "0..", culprit="shape.pidx", all_stages=True),
        Case("pidx negative.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(pidx="0\n-1\n")}), ERROR, "0..",
             culprit="shape.pidx"),
        Case("pidx text.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(pidx="0\nfive\n")}), ERROR,
             "malformed", culprit="shape.pidx"),
        Case("pidx float.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(pidx="0\n1.5\n")}), ERROR, "",
             culprit="shape.pidx"),
        Case("pidx empty.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(pidx="")}), ERROR, "empty",
             culprit="shape.pidx", all_stages=True),
        Case("pidx folder.txt", "pcpnet", _pcpnet("shape\n", {"shape": {**_shape(), ".pidx": _directory}}), ERROR,
             "", culprit="shape.pidx", note="shape.pidx is a folder"),
        Case("no normals.txt", "pcpnet", _pcpnet("bare\n", {"bare": {".xyz": good_cloud_text()}}), ERROR,
             "no normals", culprit="bare.xyz", all_stages=True),
        Case("bad normals.txt", "pcpnet", _pcpnet("shape\n", {"shape": _shape(normals=good_normals_text(10))}),
             ERROR, "normals for", culprit="shape.normals"),
        Case("shape folder.txt", "pcpnet", _pcpnet("dir\n", {"dir": {".xyz": _directory}}), ERROR, "",
             culprit="dir.xyz", note="the list names a folder"),
        Case("crlf list.txt", "pcpnet", _pcpnet("shape\r\n\r\n", {"shape": good}), VALID, all_stages=True),
        Case("bom list.txt", "pcpnet", _pcpnet(b"\xef\xbb\xbfshape\n", {"shape": good}), VALID,
             note="UTF-8 byte-order mark", all_stages=True),
        Case("spaces list.txt", "pcpnet", _pcpnet("  my shape é  \n", {"my shape é": _shape(pidx="0\n7\n")}),
             VALID, note="names with spaces and non-ASCII, a valid .pidx", all_stages=True),
    ]


def _params_cases() -> list[Case]:
    return [
        Case("empty params.yaml", "params", b"", ERROR, "(top level)", all_stages=True),
        Case("not yaml.yaml", "params", "data: [unclosed\n", ERROR, "YAML"),
        Case("list.yaml", "params", "- 1\n- 2\n", ERROR, "(top level)"),
        Case("binary params.yaml", "params", b"\xff\xfe\x00\x01garbage", ERROR, "cannot be read as YAML",
             all_stages=True),
        Case("params folder.yaml", "params", _directory, ERROR, ""),
        Case("absent params.yaml", "params", None, ERROR, ""),
        Case("python tag.yaml", "params", f"profile: !!python/object/apply:open ['{UNPICKLED}', 'w']\n", ERROR,
             "", note="a YAML tag that would run code: must be refused, not executed", all_stages=True),
        Case("tabs.yaml", "params", "profile: cpu\n\tseed: 1\n", ERROR, ""),
        Case("unknown profile.yaml", "params", _params(lambda t: t.replace("profile: cpu", "profile: gpu", 1)),
             ERROR, "profile", all_stages=True),
        Case("crlf params.yaml", "params", _params(lambda t: t.replace("\n", "\r\n")), VALID),
        Case("bom params.yaml", "params", lambda p: p.write_bytes(
            b"\xef\xbb\xbf" + (Path(__file__).resolve().parents[1] / "params.yaml").read_bytes()), VALID,
             all_stages=True),
    ]


def corpus() -> list[Case]:
    """Every case, in a fixed order; names are unique within a kind."""
    cases = [*_cloud_cases(), *_normals_cases(), *_mesh_cases(), *_pcpnet_cases(), *_params_cases()]
    seen = Counter((c.kind, c.name) for c in cases)
    duplicated = [key for key, n in seen.items() if n > 1]
    assert not duplicated, f"duplicate cases: {duplicated}"
    return cases


# ----------------------------------------------------------------------------------------------------- entry points

#: Entry points, in-process (library functions) and subprocesses (stage scripts), by kind.
READERS = {
    "cloud": ("io.read_cloud", "points source", "pcpnet source"),
    "normals": ("io.read_normals", "io.read_cloud (sibling)", "pcpnet source"),
    "mesh": ("meshes.read_mesh", "meshes source"),
    "pcpnet": ("pcpnet source",),
    "params": ("config.load",),
}
#: Entry points that need a neighbourhood of k points (a `needs_k` case is an error only there).
NEEDS_K = frozenset({"io.read_cloud", "stages.baselines", "stages.mfps", "stages.features", CLI})
SOURCE_SUFFIXES = {"points source": POINT_FILE_SUFFIXES, "meshes source": (".off", ".obj", ".ply")}


def expected(case: Case, entry: str) -> str:
    """The outcome of `case` at `entry`."""
    if case.needs_k and entry not in NEEDS_K:
        return VALID
    return case.expect


def entry_points(case: Case) -> list[str]:
    """Every entry point that reads the case's kind of file and can be given it."""
    suffix = Path(case.name).suffix.lower()
    entries: list[str] = []
    for entry in READERS[case.kind]:
        if entry.endswith("s source") and (suffix not in SOURCE_SUFFIXES[entry] or case.content is None):
            continue  # a folder source lists only files of its types, and cannot list a missing one
        if entry == "pcpnet source" and case.kind == "cloud" and Path(case.name).suffix != ".xyz":
            continue  # PCPNet shapes are NAME.xyz
        if entry == "pcpnet source" and case.kind == "normals" and suffix != ".normals":
            continue
        if entry == "io.read_cloud (sibling)" and suffix != ".normals":
            continue
        entries.append(entry)
    if case.kind in ("cloud", "normals"):
        entries.append(CLI)  # a cloud as its input; a normals file as --initial
    if case.kind == "cloud":
        entries.append("stages.baselines")
        if case.all_stages:
            entries += ["stages.mfps", "stages.features"]
    elif case.all_stages:  # the stage scripts start in 1-2 s each: a representative subset of the other kinds
        entries.append({"normals": "stages.features", "mesh": "stages.clouds", "pcpnet": "stages.clouds",
                        "params": "stages.baselines"}[case.kind])
    return entries


def table() -> str:
    """The corpus as a Markdown table, with the counts."""
    cases = corpus()
    lines = ["| kind | file | expected | entry points |", "|---|---|---|---|"]
    for c in cases:
        outcome = c.expect + (" (too few points for a neighbourhood)" if c.needs_k else "")
        lines.append(f"| {c.kind} | `{c.name}` | {outcome} | {', '.join(entry_points(c))} |")
    runs = sum(len(entry_points(c)) for c in cases)
    subprocesses = sum(e.startswith("stages.") for c in cases for e in entry_points(c))
    kinds = Counter(c.kind for c in cases)
    outcomes = Counter(c.expect for c in cases)
    lines += ["", f"**{len(cases)}** inputs ({', '.join(f'{kinds[k]} {k}' for k in KINDS)}; "
                  f"{outcomes[ERROR]} errors, {outcomes[VALID]} valid but degenerate), "
                  f"**{runs}** runs through the entry points ({subprocesses} of them stage-script subprocesses)."]
    return "\n".join(lines)


def results(junit: Path) -> str:
    """Outcomes per entry point (test_bad_inputs), per variant (test_params_fuzz) and per command and class
    (test_bad_commands) from a pytest --junitxml file."""
    import xml.etree.ElementTree as ET

    def outcome(case: ET.Element) -> str:
        for child in case:
            if child.tag == "skipped":
                return "xfailed" if child.get("type") == "pytest.xfail" else "skipped"
            if child.tag in ("failure", "error"):
                return "failed"
        return "passed"

    inputs: dict[str, Counter] = {}
    per_case: dict[str, Counter] = {}
    fuzz: dict[str, Counter] = {}
    fuzz_names: list[str] = []
    skips: Counter = Counter()
    commands: dict[tuple[str, str], Counter] = {}
    other: dict[str, Counter] = {}
    for case in ET.parse(junit).iter("testcase"):
        name, result = case.get("name", ""), outcome(case)
        if name.startswith("test_command["):
            entry, command = name[len("test_command["):].split(":", 1)
            commands.setdefault((entry, command.split("/", 1)[0]), Counter())[result] += 1
        elif case.get("classname", "").endswith("test_bad_inputs") and "@" in name:
            inputs.setdefault(name.rsplit("@", 1)[1].rstrip("]"), Counter())[result] += 1
            per_case.setdefault(name.split("[", 1)[1].rsplit("@", 1)[0], Counter())[result] += 1
        elif name.startswith("test_a_broken_key_is_named["):
            fuzz.setdefault(name.rsplit("-", 1)[1].rstrip("]"), Counter())[result] += 1
            fuzz_names.append(name)
            if result == "skipped":
                reason = next(iter(case)).get("message", "")
                skips["no range or choices" if "no range" in reason else "keys are data"] += 1
        else:
            other.setdefault(name.split("[")[0], Counter())[result] += 1
    states = ("passed", "skipped", "xfailed", "failed")
    lines = ["| entry point | runs | " + " | ".join(states) + " |", "|---|---|" + "---|" * len(states)]
    total: Counter = Counter()
    for entry, counts in sorted(inputs.items(), key=lambda item: (item[0].startswith("stages."), item[0])):
        total += counts
        lines.append(f"| {entry} | {sum(counts.values())} | " + " | ".join(str(counts[s]) for s in states) + " |")
    lines.append(f"| **all** | **{sum(total.values())}** | " + " | ".join(f"**{total[s]}**" for s in states) + " |")
    runs = sorted(sum(c.values()) for c in per_case.values())
    clean = sum(set(c) == {"passed"} for c in per_case.values())
    lines += ["", f"**{len(per_case)}** inputs, each through {runs[0]} to {runs[-1]} entry points "
                  f"(mean {sum(runs) / len(runs):.1f}): **{clean}** passed at every one; "
                  + ", ".join(f"{sum(s in c for c in per_case.values())} with {s} runs"
                              for s in states[1:] if any(s in c for c in per_case.values())) + "."]
    keys = sum(fuzz[next(iter(fuzz))].values()) if fuzz else 0
    profile_keys = len({n.split("[", 1)[1].rsplit("-", 1)[0] for n in fuzz_names if "[profiles." in n})
    lines += ["", "| params variant | keys | " + " | ".join(states) + " |", "|---|---|" + "---|" * len(states)]
    for variant, counts in fuzz.items():
        lines.append(f"| {variant} | {sum(counts.values())} | " + " | ".join(str(counts[s]) for s in states) + " |")
    checked = sum(c["passed"] for c in fuzz.values())
    lines += ["", f"**{keys}** keys ({keys - profile_keys} base leaves, {profile_keys} of `profiles`) x "
                  f"**{len(fuzz)}** variants = **{keys * len(fuzz)}** broken params files: "
                  f"**{checked}** reported by their key, {sum(skips.values())} skipped "
                  f"({', '.join(f'{n}: {why}' for why, n in skips.items())})."]
    if commands:
        lines += ["", "| command | class | cases | " + " | ".join(states) + " |",
                  "|---|---|---|" + "---|" * len(states)]
        for (entry, kind), counts in sorted(commands.items()):
            lines.append(f"| {entry} | {kind} | {sum(counts.values())} | "
                         + " | ".join(str(counts[s]) for s in states) + " |")
        total = sum(commands.values(), Counter())
        lines.append(f"| **all** | | **{sum(total.values())}** | " + " | ".join(f"**{total[s]}**" for s in states)
                     + " |")
    for test, counts in other.items():
        lines.append(f"* `{test}`: " + ", ".join(f"{counts[s]} {s}" for s in states if counts[s]))
    return "\n".join(lines)


if __name__ == "__main__":
    import argparse

    parser = argparse.ArgumentParser(description=__doc__.split("\n\n")[0])
    parser.add_argument("--results", type=Path, help="a pytest --junitxml file of test_bad_inputs/test_params_fuzz")
    args = parser.parse_args()
    print(table())
    if args.results:
        print()
        print(results(args.results))
