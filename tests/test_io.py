"""Readers and writers: round trips, and one clear error per kind of bad file."""

import os

import numpy as np
import pytest

from refinenet.data.io import (
    Cloud,
    read_cloud,
    read_normals,
    write_cloud,
    write_normals,
    write_ply,
    write_points,
)
from refinenet.errors import InputError


@pytest.fixture
def cloud():
    rng = np.random.default_rng(0)
    points = rng.normal(size=(50, 3))
    normals = rng.normal(size=(50, 3))
    return points, normals / np.linalg.norm(normals, axis=1, keepdims=True)


def test_xyz_normals_round_trip(tmp_path, cloud):
    """PCPNet's pair of files: the `.normals` beside an `.xyz` is read only when asked for (a data source)."""
    points, normals = cloud
    write_points(tmp_path / "shape.xyz", points, normals)
    assert read_cloud(tmp_path / "shape.xyz").normals is None
    back = read_cloud(tmp_path / "shape.xyz", sibling_normals=True)
    np.testing.assert_array_equal(back.points, points)
    np.testing.assert_allclose(back.normals, normals, atol=1e-7)


def test_six_column_xyz_and_npy(tmp_path, cloud):
    points, normals = cloud
    np.savetxt(tmp_path / "six.xyz", np.hstack([points, normals]))
    np.save(tmp_path / "six.npy", np.hstack([points, normals]))
    for name in ("six.xyz", "six.npy"):
        back = read_cloud(tmp_path / name)
        np.testing.assert_allclose(back.normals, normals, atol=1e-12)


def test_ply_and_pcd_round_trip(tmp_path, cloud):
    points, normals = cloud
    write_ply(tmp_path / "c.ply", points, normals)
    back = read_cloud(tmp_path / "c.ply")
    np.testing.assert_allclose(back.points, points, atol=1e-12)
    np.testing.assert_allclose(back.normals, normals, atol=1e-12)
    import open3d as o3d

    o3d.io.write_point_cloud(str(tmp_path / "c.pcd"), o3d.io.read_point_cloud(str(tmp_path / "c.ply")))
    np.testing.assert_allclose(read_cloud(tmp_path / "c.pcd").points, points, atol=1e-12)


def test_npz_record_keeps_metadata(tmp_path, cloud):
    points, normals = cloud
    write_cloud(tmp_path / "r.npz", Cloud(points, normals, {"seed": 7, "noise_percent": 0.1}))
    back = read_cloud(tmp_path / "r.npz")
    assert back.meta == {"seed": 7, "noise_percent": 0.1}
    np.testing.assert_array_equal(back.points, points)


def test_normals_files(tmp_path, cloud):
    _, normals = cloud
    for name in ("n.npy", "n.normals"):
        write_normals(tmp_path / name, normals)
        np.testing.assert_allclose(read_normals(tmp_path / name, 50), normals, atol=1e-6)
    with pytest.raises(InputError, match="49 points"):
        read_normals(tmp_path / "n.npy", 49)


def test_normals_of_some_rows_leave_the_others_unchecked(tmp_path, cloud):
    """Points no estimator computed (outside a PCPNet .pidx) are NaN; reading the scored rows ignores them and
    still refuses a NaN among the scored."""
    _, normals = cloud
    partial = np.where(np.arange(50)[:, None] % 2 == 0, normals, np.nan)
    for name in ("n.npy", "n.normals"):
        write_normals(tmp_path / name, partial)
        np.testing.assert_allclose(read_normals(tmp_path / name, 50, np.arange(0, 50, 2)), normals[::2], atol=1e-6)
        with pytest.raises(InputError, match="NaN"):
            read_normals(tmp_path / name, 50, np.array([0, 1]))
        with pytest.raises(InputError, match="NaN"):
            read_normals(tmp_path / name, 50)
        with pytest.raises(InputError, match="50 normals for 51 points"):
            read_normals(tmp_path / name, 51, np.array([0]))


@pytest.mark.parametrize(
    ("content", "problem"),
    [
        ("", "empty"),
        ("1 2 3\n4 5 6\n7 8\n", "malformed"),  # truncated last line
        ("1 2 3\n4 five 6\n", "malformed"),  # non-numeric
        ("1 2 3\nnan 5 6\n", "NaN or inf"),
        ("1 2 3\ninf 5 6\n", "NaN or inf"),
        ("1 2 3 4\n5 6 7 8\n", "4 columns"),
    ],
)
def test_bad_xyz_files(tmp_path, content, problem):
    path = tmp_path / "bad.xyz"
    path.write_text(content)
    with pytest.raises(InputError, match=problem) as info:
        read_cloud(path)
    message = str(info.value)
    assert str(path) in message and "\n" not in message


def test_too_few_points(tmp_path):
    path = tmp_path / "few.xyz"
    path.write_text("0 0 0\n1 0 0\n0 1 0\n")
    with pytest.raises(InputError, match="3 points, fewer than the 100"):
        read_cloud(path, min_points=100)


def test_mismatched_normals_file(tmp_path):
    (tmp_path / "a.xyz").write_text("0 0 0\n1 0 0\n0 1 0\n")
    (tmp_path / "a.normals").write_text("0 0 1\n0 0 1\n")
    with pytest.raises(InputError, match="2 normals for 3 points"):
        read_cloud(tmp_path / "a.xyz", sibling_normals=True)
    assert read_cloud(tmp_path / "a.xyz").normals is None  # a file the user did not name is not read


def test_bad_binary_files(tmp_path):
    (tmp_path / "e.ply").write_bytes(b"")
    (tmp_path / "t.ply").write_bytes(b"ply\nformat ascii 1.0\nelement vertex 5\nproperty float x\n")
    (tmp_path / "b.npy").write_bytes(b"not numpy")
    for name in ("e.ply", "t.ply", "b.npy"):
        with pytest.raises(InputError, match=name):
            read_cloud(tmp_path / name)
    with pytest.raises(InputError, match="unsupported"):
        read_cloud(tmp_path / "x.las")


def test_failed_write_leaves_nothing(tmp_path):
    class Boom(RuntimeError):
        pass

    from refinenet.atomic import atomic_path

    with pytest.raises(Boom), atomic_path(tmp_path / "out.npy") as tmp:
        tmp.write_text("partial")
        raise Boom
    assert list(tmp_path.iterdir()) == []


def test_a_group_of_outputs_appears_together_or_not_at_all(tmp_path, cloud):
    """An `.xyz` and its `.normals` are written, then the group fails: neither appears, no temporary is left.
    Without the failure both appear at the group's end, not before."""
    from refinenet.atomic import atomic_group, write_text
    from refinenet.errors import OutputError

    points, normals = cloud
    out, blocker = tmp_path / "out", tmp_path / "blocker"
    out.mkdir()
    blocker.write_text("a file, where a folder would have to be made")
    with pytest.raises(OutputError, match="blocker"), atomic_group():
        write_points(out / "a.xyz", points, normals)
        write_text(blocker / "report.txt", "")
    assert list(out.iterdir()) == []
    with atomic_group():
        write_points(out / "a.xyz", points, normals)
        assert [p.name for p in out.iterdir() if not p.name.startswith(".")] == []
    assert sorted(p.name for p in out.iterdir()) == ["a.normals", "a.xyz"]


def test_a_signal_during_the_renames_waits_for_their_end(tmp_path, cloud):
    """A handler that finds the renames `held` defers its signal; it is raised again once both files are there."""
    import signal

    from refinenet import interrupts
    from refinenet.atomic import atomic_group

    seen = []

    def handler(signum, _frame):
        if interrupts.is_held():
            interrupts.defer(signum)
            return
        seen.append(sorted(p.name for p in tmp_path.iterdir()))

    previous = signal.signal(signal.SIGUSR1, handler)
    try:
        with atomic_group(committed=lambda: signal.raise_signal(signal.SIGUSR1)):
            write_points(tmp_path / "a.xyz", *cloud)
    finally:
        signal.signal(signal.SIGUSR1, previous)
    assert seen == [["a.normals", "a.xyz"]]


@pytest.mark.parametrize("umask, mode", [(0o022, 0o644), (0o077, 0o600), (0o002, 0o664)])
def test_written_files_get_the_mode_the_umask_gives(tmp_path, umask, mode):
    """An atomic write must not leave the owner-only mode of its temporary file: a report shared with a group
    (reports/index.html) would be unreadable to it."""
    from refinenet.atomic import write_text

    previous = os.umask(umask)
    try:
        write_text(tmp_path / "index.html", "<html></html>")
    finally:
        os.umask(previous)
    assert (tmp_path / "index.html").stat().st_mode & 0o777 == mode


def test_a_saved_torch_object_has_the_same_bytes_every_time(tmp_path):
    """Saved twice (each time under another temporary name), the same networks give the same file: the shipped
    networks of two runs, and DVC's cache of them, are bit-identical."""
    import torch

    from refinenet.atomic import write_torch

    state = {"weight": torch.arange(6.0).reshape(2, 3)}
    write_torch(tmp_path / "a.pt", state)
    first = (tmp_path / "a.pt").read_bytes()
    write_torch(tmp_path / "a.pt", state)
    assert (tmp_path / "a.pt").read_bytes() == first
    assert torch.equal(torch.load(tmp_path / "a.pt", weights_only=True)["weight"], state["weight"])
    assert [p.name for p in tmp_path.iterdir()] == ["a.pt"]


def _ply_bytes(rows: np.ndarray, declared: int, props: str = "x y z", binary: bool = True) -> bytes:
    header = (f"ply\nformat {'binary_little_endian' if binary else 'ascii'} 1.0\nelement vertex {declared}\n"
              + "".join(f"property float {p}\n" for p in props.split()) + "end_header\n")
    body = rows.astype("<f4").tobytes() if binary else "".join(" ".join(map(str, r)) + "\n" for r in rows).encode()
    return header.encode() + body


@pytest.mark.parametrize("binary", [True, False])
def test_a_short_ply_reports_the_rows_it_holds(tmp_path, binary):
    path = tmp_path / "short.ply"
    path.write_bytes(_ply_bytes(np.random.default_rng(1).random((2000, 3)), 2100, binary=binary))
    with pytest.raises(InputError, match="header declares 2,100 points, the data holds 2,000"):
        read_cloud(path)


def test_placeholder_zero_normals_count_as_absent(tmp_path, cloud):
    """Many scanners write nx ny nz = 0 for every point; one zero normal among real ones is still an error."""
    points, normals = cloud
    (tmp_path / "zeros.ply").write_bytes(_ply_bytes(np.c_[points, np.zeros_like(points)], len(points),
                                                    "x y z nx ny nz"))
    back = read_cloud(tmp_path / "zeros.ply")
    assert back.normals is None and len(back) == len(points)
    one_zero = normals.copy()
    one_zero[3] = 0
    np.save(tmp_path / "one.npy", np.c_[points, one_zero])
    with pytest.raises(InputError, match="zero-length normal at row 4"):
        read_cloud(tmp_path / "one.npy")


@pytest.mark.parametrize("fmt, order", [("binary_little_endian", "<"), ("binary_big_endian", ">")])
def test_binary_ply_is_read_as_open3d_reads_it(tmp_path, cloud, fmt, order):
    """Binary PLY vertices are read by numpy, in any byte order and among other properties of any type (here a
    colour, an int and a double), with the values Open3D gives."""
    import open3d as o3d

    points, normals = cloud
    rgb = np.random.default_rng(2).integers(0, 256, size=(len(points), 3))
    fields = [("red", "u1", rgb[:, 0]), ("x", "f8", points[:, 0]), ("y", "f8", points[:, 1]),
              ("label", "i4", np.arange(len(points))), ("z", "f8", points[:, 2]), ("nx", "f4", normals[:, 0]),
              ("ny", "f4", normals[:, 1]), ("nz", "f4", normals[:, 2]), ("green", "u1", rgb[:, 1]),
              ("blue", "u1", rgb[:, 2])]
    types = {"u1": "uchar", "i4": "int", "f4": "float", "f8": "double"}
    rows = np.empty(len(points), dtype=[(name, order + kind) for name, kind, _ in fields])
    for name, _, values in fields:
        rows[name] = values
    header = (f"ply\nformat {fmt} 1.0\ncomment made by a test\nelement vertex {len(points)}\n"
              + "".join(f"property {types[kind]} {name}\n" for name, kind, _ in fields) + "end_header\n")
    path = tmp_path / "scan.ply"
    path.write_bytes(header.encode() + rows.tobytes())
    back, theirs = read_cloud(path), o3d.io.read_point_cloud(str(path))
    np.testing.assert_array_equal(back.points, points)
    np.testing.assert_array_equal(back.points, np.asarray(theirs.points))
    given = np.asarray(theirs.normals)  # float32 in the file; read_cloud rescales each to unit length
    np.testing.assert_allclose(back.normals, given / np.linalg.norm(given, axis=1, keepdims=True), rtol=0, atol=1e-15)


def test_binary_float64_pcd_is_read_exactly(tmp_path, cloud):
    """As PCL writes it; Open3D's reader would return zeros."""
    points, normals = cloud
    points = points + [500_000.0, 5_000_000.0, 0.0]
    header = ("VERSION 0.7\nFIELDS x y z normal_x normal_y normal_z\nSIZE 8 8 8 8 8 8\nTYPE F F F F F F\n"
              f"COUNT 1 1 1 1 1 1\nWIDTH {len(points)}\nHEIGHT 1\nVIEWPOINT 0 0 0 1 0 0 0\nPOINTS {len(points)}\n"
              "DATA binary\n")
    (tmp_path / "pcl.pcd").write_bytes(header.encode() + np.c_[points, normals].astype("<f8").tobytes())
    back = read_cloud(tmp_path / "pcl.pcd")
    np.testing.assert_array_equal(back.points, points)
    np.testing.assert_allclose(back.normals, normals, atol=1e-12)
    (tmp_path / "short.pcd").write_bytes((tmp_path / "pcl.pcd").read_bytes()[:-100])
    with pytest.raises(InputError, match=f"declares {len(points)} points, the data holds {len(points) - 3}"):
        read_cloud(tmp_path / "short.pcd")


def test_a_failed_rename_puts_back_the_outputs_it_replaced(tmp_path, cloud, monkeypatch):
    """With --force over an .xyz and its .normals, the second rename fails: the first output is put back."""
    from refinenet import atomic
    from refinenet.errors import OutputError

    for name in ("a.xyz", "a.normals"):
        (tmp_path / name).write_text(f"the earlier {name}\n")
    replace, calls = os.replace, []

    def second_fails(src, dst):
        calls.append(dst)
        if len(calls) == 2:
            raise OSError(28, "No space left on device")
        replace(src, dst)

    monkeypatch.setattr(atomic.os, "replace", second_fails)
    with pytest.raises(OutputError, match="No space left"), atomic.atomic_group():
        write_points(tmp_path / "a.xyz", *cloud)
    assert {p.name: p.read_text() for p in tmp_path.iterdir()} == {n: f"the earlier {n}\n" for n in ("a.xyz",
                                                                                                       "a.normals")}


def test_a_failed_output_removes_the_folders_made_for_it(tmp_path, cloud):
    from refinenet.atomic import atomic_group
    from refinenet.errors import OutputError

    (tmp_path / "blocker").write_text("")
    with pytest.raises(OutputError), atomic_group():
        write_points(tmp_path / "new" / "deep" / "a.xyz", *cloud)
        write_points(tmp_path / "blocker" / "b.ply", *cloud)
    assert [p.name for p in tmp_path.iterdir()] == ["blocker"]
