"""Every hostile command line of `bad_commands.corpus()`, run as a user runs it (a subprocess), and the precision
of every output format.

For every case, whatever its outcome: each file the case wrote (its inputs, and any file in the way of an output)
keeps its bytes, inode and modification time, unless it is an output a success replaces with --force; the exit
status is the expected one and there is no traceback. A failure is one line `error: ...` holding the case's
substrings, an interruption one line saying so, and neither leaves anything new in the folder (no temporary
`.NAME.*.tmp*` either); a success leaves exactly the named outputs.
"""

from __future__ import annotations

import ctypes
import hashlib
import os
import select
import stat
import subprocess
import sys
import time
from collections.abc import Iterator
from concurrent.futures import Future, ThreadPoolExecutor
from dataclasses import dataclass
from pathlib import Path

import numpy as np
import pytest
from bad_commands import OK, CommandCase, case_id, corpus
from bad_inputs import sphere

from refinenet.data.io import OUTPUT_SUFFIXES, read_cloud, read_normals, write_points

REPO = Path(__file__).resolve().parents[1]
CASES = corpus()
#: The folder of a case: a space and a non-ASCII letter, so every path given is a hostile one.
FOLDER = "case folder ü"
#: Seconds a command may run; seconds to wait for a signal case to open its input, then to work before the signal,
#: and then to stop.
RUN_TIMEOUT, OPEN_TIMEOUT, WORK_S, STOP_TIMEOUT = 300, 120, 2.0, 120
#: inotify's event of a file being opened (linux/inotify.h).
IN_OPEN = 0x20


@dataclass(frozen=True)
class Entry:
    """What a path under a case's folder is: its kind, link target, inode, size, modification time, and digest
    (None: a folder, a link, or a file this process may not read)."""

    kind: str
    target: str | None
    inode: int
    size: int
    mtime_ns: int
    digest: str | None


def _entry(path: Path) -> Entry:
    info = path.lstat()
    if path.is_symlink():
        return Entry("link", os.readlink(path), info.st_ino, 0, info.st_mtime_ns, None)
    if path.is_dir():  # a folder's time changes with its entries: those are compared one by one
        return Entry("folder", None, info.st_ino, 0, 0, None)
    if stat.S_ISFIFO(info.st_mode):  # reading a pipe would wait for a writer
        return Entry("pipe", None, info.st_ino, 0, info.st_mtime_ns, None)
    try:
        digest = hashlib.sha256(path.read_bytes()).hexdigest()
    except PermissionError:
        digest = None
    return Entry("file", None, info.st_ino, info.st_size, info.st_mtime_ns, digest)


def snapshot(folder: Path) -> dict[str, Entry]:
    """Every path under `folder` (links not followed), by its path relative to it."""
    paths = {}
    for top, folders, names in os.walk(folder):
        for name in [*folders, *names]:
            path = Path(top) / name
            paths[str(path.relative_to(folder))] = _entry(path)
    return paths


@dataclass
class Outcome:
    """A case's run: its folder before and after, and what the command did (status None: it had to be killed)."""

    folder: Path
    before: dict[str, Entry]
    after: dict[str, Entry]
    status: int | None
    stdout: str
    stderr: str


class OpenWatch:
    """Linux inotify on one file: an opening is queued, so none is missed as a poll could miss a short read."""

    def __init__(self, path: Path):
        self.libc = ctypes.CDLL(None, use_errno=True)
        self.fd = self.libc.inotify_init1(os.O_CLOEXEC)
        if self.fd < 0 or self.libc.inotify_add_watch(self.fd, os.fsencode(path), IN_OPEN) < 0:
            raise OSError(ctypes.get_errno(), f"inotify on {path}")

    def wait(self, process: subprocess.Popen, timeout: float) -> bool:
        """Whether the file was opened before `process` ended or `timeout` passed."""
        deadline = time.monotonic() + timeout
        while process.poll() is None and time.monotonic() < deadline:
            if select.select([self.fd], [], [], 0.2)[0]:
                return True
        return False

    def close(self) -> None:
        os.close(self.fd)


def run_case(case: CommandCase, tmp: Path) -> Outcome:
    """Build the case in a fresh folder under `tmp`, run it (sending its signal once it works), and take the
    folder's snapshots around it."""
    folder = tmp / FOLDER
    folder.mkdir()
    case.build(folder)
    before = snapshot(folder)
    args = case.args(folder)
    command = [sys.executable, "-m", "refinenet.cli.main", case.entry, *args]
    watch = OpenWatch(Path(args[0])) if case.force else None
    process = subprocess.Popen(command, cwd=REPO, stdout=subprocess.PIPE, stderr=subprocess.PIPE, text=True,
                               encoding="utf-8", errors="replace", preexec_fn=case.preexec)
    try:
        if watch is not None and watch.wait(process, OPEN_TIMEOUT):
            time.sleep(WORK_S)  # past reading the input: estimating or denoising
            if process.poll() is None:
                process.send_signal(case.force)
        stdout, stderr = process.communicate(timeout=STOP_TIMEOUT if case.force else RUN_TIMEOUT)
        status = process.returncode
    except subprocess.TimeoutExpired:
        process.kill()
        stdout, stderr = process.communicate()
        status = None
    finally:
        if watch is not None:
            watch.close()
    return Outcome(folder, before, snapshot(folder), status, stdout, stderr)


def running_as_root() -> bool:
    return hasattr(os, "geteuid") and os.geteuid() == 0


@pytest.fixture(scope="module")
def command_runs(request, tmp_path_factory) -> Iterator[dict[str, Future]]:
    """Every selected case, started ahead of its test and two at a time: a command spends its 2-3 s mostly
    importing, so the file takes half the time on two cores."""
    pool = ThreadPoolExecutor(max_workers=2)
    runs = {}
    for item in request.session.items:
        if getattr(item, "originalname", "") == "test_command":
            case = item.callspec.params["case"]
            if not (case.root_skip and running_as_root()):
                runs[case_id(case)] = pool.submit(run_case, case, tmp_path_factory.mktemp("command"))
    yield runs
    pool.shutdown(cancel_futures=True)


@pytest.mark.parametrize("case", CASES, ids=[case_id(c).encode("ascii", "replace").decode() for c in CASES])
def test_command(case: CommandCase, command_runs) -> None:
    if case.root_skip and running_as_root():
        pytest.skip(f"{case.name}: running as root, which reads and writes files whatever their permissions")
    run = command_runs[case_id(case)].result()
    replaced = set(case.outputs) if case.status == OK else set()
    for path, entry in run.before.items():
        if path not in replaced:
            assert run.after.get(path) == entry, f"{path} was changed: {entry} -> {run.after.get(path)}"
    assert run.status is not None, f"still running after {STOP_TIMEOUT if case.force else RUN_TIMEOUT} s"
    assert run.status == case.status, f"exit status {run.status}, expected {case.status}:\n{run.stderr}"
    assert "Traceback" not in run.stderr, run.stderr
    new = sorted(set(run.after) - set(run.before))
    lines = run.stderr.splitlines()
    if case.status == OK:
        assert not any(line.startswith("error:") for line in lines), run.stderr
        assert new == sorted(set(case.outputs) - set(run.before)), f"new files: {new}, expected {case.outputs}"
        for path in case.outputs:
            output = run.after.get(path)
            assert output is not None and output.kind == "file" and output.size > 0, f"{path}: {output}"
            assert output != run.before.get(path), f"{path} was not replaced"
        return
    assert len(lines) == 1, f"not one line:\n{run.stderr}"
    assert case.force or lines[0].startswith("error: "), f"not an error line: {lines[0]}"
    for problem in case.problems(run.folder):
        assert problem in lines[0], f"expected {problem!r} in {lines[0]!r}"
    for problem in case.absent:
        assert problem not in lines[0], f"{problem!r} in {lines[0]!r}"
    assert not new, f"new files left: {new}"
    assert run.stdout == "", f"output on stdout besides the error:\n{run.stdout}"


# ------------------------------------------------------------------------------------------------------- precision


def utm_cloud(n: int = 2000) -> np.ndarray:
    """A 1 m patch of a survey in UTM coordinates (x ~ 500 km, y ~ 5000 km) with sub-millimetre noise: float64
    keeps ~1e-9 m of such coordinates, float32 only ~0.5 m."""
    rng = np.random.default_rng(11)
    xy = rng.random((n, 2))
    z = 0.05 * np.sin(3 * xy[:, 0]) + rng.normal(scale=2e-4, size=n)
    return np.c_[xy, z] + [500_123.25, 5_001_234.75, 312.5]


#: The clouds whose points every format must give back bit for bit, with unit normals.
PRECISION = {
    "utm": utm_cloud(),
    "1e-9": sphere(2000, "nano")[0] * 1e-9,
    "float32": sphere(2000, "single")[0].astype(np.float32).astype(np.float64) * 3,
}
PRECISION_SUFFIXES = (*(s for s in OUTPUT_SUFFIXES if s != ".normals"), ".XYZ", ".PLY")


def read_back(path: Path, n: int) -> tuple[np.ndarray, np.ndarray]:
    """The points and normals of an output: an `.xyz`'s normals are in the `.normals` beside it."""
    cloud = read_cloud(path)
    normals = cloud.normals if cloud.normals is not None else read_normals(path.with_suffix(".normals"), n)
    return cloud.points, normals


@pytest.mark.parametrize("suffix", PRECISION_SUFFIXES)
@pytest.mark.parametrize("kind", PRECISION)
def test_points_come_back_bit_for_bit(tmp_path: Path, kind: str, suffix: str) -> None:
    points = PRECISION[kind]
    normals = sphere(len(points), "precision")[1]
    path = tmp_path / f"cloud{suffix}"
    write_points(path, points, normals)
    back, back_normals = read_back(path, len(points))
    assert back.dtype == np.float64 and np.array_equal(back, points), \
        f"{path.name}: points moved by up to {np.abs(back - points).max():.3g}"
    np.testing.assert_allclose(back_normals, normals, atol=1e-6)


@pytest.mark.parametrize("suffix", [".txt", ".pcd"])
def test_command_keeps_utm_coordinates(tmp_path: Path, suffix: str) -> None:
    points = PRECISION["utm"]
    source, out = tmp_path / "survey.xyz", tmp_path / f"survey{suffix}"
    np.savetxt(source, points, fmt="%.17g")  # 17 digits: every float64 exactly
    run = subprocess.run([sys.executable, "-m", "refinenet.cli.main", "normals", str(source), "-o", str(out),
                          "--method", "pca"], cwd=REPO, capture_output=True, text=True, timeout=RUN_TIMEOUT)
    assert run.returncode == 0, run.stderr
    back, normals = read_back(out, len(points))
    assert np.array_equal(back, points), f"points moved by up to {np.abs(back - points).max():.3g} m"
    assert np.isfinite(normals).all()
    np.testing.assert_allclose(np.linalg.norm(normals, axis=1), 1, atol=1e-6)
