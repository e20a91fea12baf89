"""A corpus of hostile command lines for `refinenet normals`, `refinenet denoise` and `refinenet tiles`, generated
on the fly (no binaries are kept): the sibling of `bad_inputs.py`, whose cases are bad input files, for bad commands.

Each `CommandCase` is a small record: the files it writes into a folder (its inputs, and any existing file in the
way of an output), the arguments, and the outcome the contract promises a user, who must never lose a file:

* every input is left as it was, byte for byte and with its modification time (an input is never written, even
  with `--force`);
* a failure is one line `error: ... PROBLEM` with exit status 2, and nothing new in the folder (no temporary
  `.NAME.*.tmp*` file either); SIGINT or SIGTERM while the command works is one line saying it was interrupted,
  the status 130 or 143, and nothing new either;
* a success writes exactly the named outputs (an `.xyz` with its `.normals` beside it) and nothing else.

The prefix of a case's name, up to the `/`, is the class of the issue it covers (`CLASSES`).
`python tests/bad_commands.py` prints the corpus and the counts per entry point and per class; the tests in
`tests/test_bad_commands.py` run them.
"""

from __future__ import annotations

import io
import os
import resource
import signal
import subprocess
import sys
from collections import Counter
from collections.abc import Callable
from dataclasses import dataclass
from functools import cache
from pathlib import Path

import numpy as np
from bad_inputs import _directory, _ply_builder, _rows, _six, _unreadable, _xyz, sphere, write_content

from refinenet.network.release import BUNDLE, CARD_JSON, CARD_MD, SHIPPED

NORMALS, DENOISE, TILES = "normals", "denoise", "tiles"
ENTRIES = (NORMALS, DENOISE, TILES)
OK, BAD = 0, 2
#: Exit statuses of a command stopped by SIGINT or SIGTERM: 128 + the signal, as a shell reports it.
INTERRUPTED = {signal.SIGINT: 128 + signal.SIGINT, signal.SIGTERM: 128 + signal.SIGTERM}
#: What the error line says when an output is one of the inputs (`error: OUT: is the input ...`).
INPUT = "input"
CLASSES = {
    "same-file": "an output is a file the command reads: the same path, a hard link, a symbolic link, or the "
                 ".normals beside an .xyz output; refused even with --force",
    "twice": "two outputs are the same file, or one tiles piece named twice",
    "exists": "an output exists: refused without --force, replaced with it",
    "partial": "one of several outputs cannot be written: none is",
    "folder": "a folder (or a pipe) where a file is read or written",
    "permission": "an unreadable input or a read-only output folder (meaningless as root)",
    "disk-full": "the disk fills while an output is written (RLIMIT_FSIZE)",
    "signal": "SIGTERM or SIGINT while the command works",
    "release": "a corrupt --release folder",
    "option": "a malformed option value or an unknown option: one line, no argparse usage",
    "naming": "output names in upper case, and a format that cannot hold the result",
    "side-file": "a file beside the input that the user did not name is not read",
    "ply": "PLY inputs: placeholder normals, a vertex count the data does not hold",
    "stale": "a tiles job or merge whose cloud changed since its plan was made",
}
#: Points of the ordinary clouds (on the unit sphere), of the full-disk ones, and of the clouds large enough that a
#: command is surely still working seconds after it has opened them (Refine-Net: minutes; denoise: 15 s and more).
N_CLOUD, N_FULL, N_BIG = 1000, 3000, 200_000
#: The size files may grow to in a full-disk case: far below any of its outputs (3000 points: 100 kB and more).
FULL_DISK_BYTES = 64 * 1024
#: The content of an existing output that a case puts in the way.
EARLIER = "an earlier result that must survive a failed command\n"

Content = bytes | str | Callable[[Path], None]


@dataclass(frozen=True)
class CommandCase:
    name: str
    """`CLASS/what`: unique; CLASS is a key of CLASSES."""
    entry: str
    """normals | denoise | tiles: the subcommand."""
    build: Callable[[Path], None]
    """Writes the case's files into a folder: its inputs, and any existing file in the way of an output."""
    argv: str
    """The arguments after the subcommand, split at spaces; `{dir}` is the case's folder."""
    status: int
    """The expected exit status: OK, BAD, or INTERRUPTED[force]."""
    problem: tuple[str, ...] = ()
    """Substrings of the one stderr line of a failure (`{dir}` is the folder)."""
    absent: tuple[str, ...] = ()
    """Substrings that line must not contain."""
    outputs: tuple[str, ...] = ()
    """The files a success must leave, relative to the folder (an existing one is replaced)."""
    force: signal.Signals | None = None
    """A signal sent once the command has opened its input (the first argument) and worked for a while."""
    preexec: Callable[[], None] | None = None
    """Run in the child before the command (a full disk)."""
    root_skip: bool = False
    """Meaningless as root (file permissions do not stop root): skipped there."""
    note: str = ""

    @property
    def issue(self) -> str:
        """The class of the issue the case covers."""
        return self.name.split("/", 1)[0]

    def args(self, folder: Path) -> list[str]:
        return [arg.format(dir=folder) for arg in self.argv.split()]

    def problems(self, folder: Path) -> list[str]:
        return [p.format(dir=folder) for p in self.problem]


def files(contents: dict[str, Content]) -> Callable[[Path], None]:
    """A builder writing each name (relative to the folder, parents created, in order) with bytes, text, or a
    writer of the path."""
    def build(folder: Path) -> None:
        for name, content in contents.items():
            path = folder / name
            path.parent.mkdir(parents=True, exist_ok=True)
            write_content(path, content)
    return build


def full_disk() -> None:
    """In the child: files may grow to FULL_DISK_BYTES only, and a write beyond fails with EFBIG (SIGXFSZ, which
    would kill the process instead, is ignored), as on a full disk; the limit binds root too."""
    signal.signal(signal.SIGXFSZ, signal.SIG_IGN)
    resource.setrlimit(resource.RLIMIT_FSIZE, (FULL_DISK_BYTES, FULL_DISK_BYTES))


# ----------------------------------------------------------------------------------------------------------- data

POINTS, OUTWARD = sphere(N_CLOUD, "commands")
CLOUD = _xyz(POINTS)
ORIENTED = _xyz(_six(POINTS, OUTWARD))
NORMALS_FILE = _xyz(OUTWARD)
PLY = _ply_builder(["x", "y", "z"], POINTS, binary=True)
ORIENTED_PLY = _ply_builder(["x", "y", "z", "nx", "ny", "nz"], _six(POINTS, OUTWARD), binary=True)
FULL_CLOUD = _xyz(sphere(N_FULL, "full")[0])
FULL_ORIENTED = _xyz(_six(*sphere(N_FULL, "full")))
#: A `.normals` file of another, older cloud: the wrong length and a malformed line.
STALE_NORMALS = "0 0 1\n0 1\nstale\n"


def symlink(target: str) -> Callable[[Path], None]:
    """A symbolic link to `target`, a name in the same folder."""
    return lambda path: path.symlink_to(target)


def hardlink(target: str) -> Callable[[Path], None]:
    return lambda path: path.hardlink_to(path.parent / target)


def fifo(path: Path) -> None:
    os.mkfifo(path)


def folder_mode(mode: int) -> Callable[[Path], None]:
    def build(path: Path) -> None:
        path.mkdir()
        path.chmod(mode)
    return build


@cache
def big_table(columns: int) -> bytes:
    """N_BIG noisy points on the unit sphere as text, with (6 columns) or without (3) their normals."""
    points, normals = sphere(N_BIG, "big")
    noisy = points + np.random.default_rng(7).normal(scale=0.003, size=points.shape)
    buffer = io.BytesIO()
    np.savetxt(buffer, np.c_[noisy, normals][:, :columns], fmt="%.9g")
    return buffer.getvalue()


def big(columns: int) -> Callable[[Path], None]:
    return lambda path: path.write_bytes(big_table(columns))


def release(bundle: Content) -> dict[str, Content]:
    """A release folder `rel` with the shipped model card and `bundle` as its networks.pt."""
    return {f"rel/{CARD_MD}": (SHIPPED / CARD_MD).read_bytes(), f"rel/{CARD_JSON}": (SHIPPED / CARD_JSON).read_bytes(),
            f"rel/{BUNDLE}": bundle}


def foreign_bundle(path: Path) -> None:
    """A valid torch archive (zip + pickle) of a dictionary that is no release."""
    import torch

    torch.save({"a": 1}, path)


GARBAGE = bytes(range(256)) * 16
NOT_A_RELEASE = (BUNDLE, "not a Refine-Net release")


# ---------------------------------------------------------------------------------------------------------- corpus


def _same_file() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    initial = files({"in.xyz": CLOUD, "init.normals": NORMALS_FILE})
    return [
        CommandCase("same-file/initial as output", n, initial,
                    "{dir}/in.xyz -o {dir}/init.normals --initial {dir}/init.normals", BAD,
                    (INPUT, "{dir}/init.normals")),
        CommandCase("same-file/initial as output --force", n, initial,
                    "{dir}/in.xyz -o {dir}/init.normals --initial {dir}/init.normals --force", BAD,
                    (INPUT, "{dir}/init.normals")),
        CommandCase("same-file/initial as the .normals of an .xyz output", n,
                    files({"in.xyz": CLOUD, "res.normals": NORMALS_FILE}),
                    "{dir}/in.xyz -o {dir}/res.xyz --initial {dir}/res.normals --force", BAD,
                    (INPUT, "{dir}/res.normals")),
        CommandCase("same-file/initial as the .normals of an .XYZ output", n,
                    files({"in.xyz": CLOUD, "RES.normals": NORMALS_FILE}),
                    "{dir}/in.xyz -o {dir}/RES.XYZ --initial {dir}/RES.normals --force", BAD,
                    (INPUT, "{dir}/RES.normals")),
        CommandCase("same-file/input as output", d, files({"wn.txt": ORIENTED}), "{dir}/wn.txt -o {dir}/wn.txt", BAD,
                    (INPUT, "{dir}/wn.txt")),
        CommandCase("same-file/input as output --force", d, files({"wn.txt": ORIENTED}),
                    "{dir}/wn.txt -o {dir}/wn.txt --force", BAD, (INPUT, "{dir}/wn.txt")),
        CommandCase("same-file/input as surface", d, files({"scan.ply": ORIENTED_PLY}),
                    "{dir}/scan.ply -o {dir}/dn.npy --surface {dir}/scan.ply", BAD,
                    (INPUT, "{dir}/scan.ply")),
        CommandCase("same-file/input spelled otherwise", n, files({"in.ply": PLY}),
                    "{dir}/in.ply -o {dir}/./in.ply --method pca --force", BAD, (INPUT, "in.ply")),
        CommandCase("same-file/hard link of the input", n, files({"in.ply": PLY, "alias.ply": hardlink("in.ply")}),
                    "{dir}/in.ply -o {dir}/alias.ply --method pca --force", BAD, (INPUT, "{dir}/alias.ply")),
        CommandCase("same-file/symbolic link to the input", n,
                    files({"in.xyz": CLOUD, "alias.xyz": symlink("in.xyz")}),
                    "{dir}/in.xyz -o {dir}/alias.xyz --method pca --force", BAD, (INPUT, "{dir}/alias.xyz")),
        CommandCase("same-file/hard link of the input as surface", d,
                    files({"scan.ply": ORIENTED_PLY, "mesh.ply": hardlink("scan.ply")}),
                    "{dir}/scan.ply -o {dir}/dn.npy --surface {dir}/mesh.ply --force", BAD,
                    (INPUT, "{dir}/mesh.ply")),
        CommandCase("same-file/--normals as output", d, files({"c.xyz": CLOUD, "n.normals": NORMALS_FILE}),
                    "{dir}/c.xyz --normals {dir}/n.normals -o {dir}/n.normals --force", BAD,
                    (INPUT, "{dir}/n.normals")),
        CommandCase("same-file/--normals as the .normals of an .xyz output", d,
                    files({"scan.ply": PLY, "scan.normals": NORMALS_FILE}),
                    "{dir}/scan.ply --normals {dir}/scan.normals -o {dir}/scan.xyz --force", BAD,
                    (INPUT, "{dir}/scan.normals")),
        CommandCase("same-file/symbolic link to --normals beside an .xyz output", d,
                    files({"c.xyz": CLOUD, "n.normals": NORMALS_FILE, "out.normals": symlink("n.normals")}),
                    "{dir}/c.xyz --normals {dir}/n.normals -o {dir}/out.xyz --force", BAD,
                    (INPUT, "{dir}/out.normals")),
    ]


def _twice() -> list[CommandCase]:
    d = DENOISE
    return [
        CommandCase("twice/surface is the output", d, files({"wn.txt": ORIENTED}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/dn.ply", BAD, ("dn.ply",)),
        CommandCase("twice/surface is the output spelled otherwise", d, files({"wn.txt": ORIENTED}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/./dn.ply", BAD, ("dn.ply",)),
        CommandCase("twice/surface is a symbolic link to the output", d,
                    files({"wn.txt": ORIENTED, "dn.ply": EARLIER, "alias.ply": symlink("dn.ply")}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/alias.ply --force", BAD, ("{dir}/",)),
    ]


def _exists() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    refused = ("exists", "--force")
    return [
        CommandCase("exists/output", n, files({"in.xyz": CLOUD, "out.ply": EARLIER}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca", BAD, (*refused, "{dir}/out.ply")),
        CommandCase("exists/a dangling symbolic link as output", n,
                    files({"in.xyz": CLOUD, "out.ply": symlink("nowhere.ply")}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca", BAD, ("exists", "--force", "{dir}/out.ply")),
        CommandCase("exists/output --force", n, files({"in.xyz": CLOUD, "out.ply": EARLIER}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca --force", OK, outputs=("out.ply",)),
        CommandCase("exists/the .normals of an .xyz output", n, files({"in.xyz": CLOUD, "res.normals": EARLIER}),
                    "{dir}/in.xyz -o {dir}/res.xyz --method pca", BAD, (*refused, "{dir}/res.normals"),
                    note="res.xyz must not be written either"),
        CommandCase("exists/the .normals of an .xyz output --force", n,
                    files({"in.xyz": CLOUD, "res.normals": EARLIER}),
                    "{dir}/in.xyz -o {dir}/res.xyz --method pca --force", OK, outputs=("res.xyz", "res.normals")),
        CommandCase("exists/output", d, files({"wn.txt": ORIENTED, "dn.npy": EARLIER}),
                    "{dir}/wn.txt -o {dir}/dn.npy", BAD, (*refused, "{dir}/dn.npy")),
        CommandCase("exists/surface", d, files({"wn.txt": ORIENTED, "mesh.ply": EARLIER}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/mesh.ply", BAD, (*refused, "{dir}/mesh.ply"),
                    note="dn.ply must not be written either"),
        CommandCase("exists/surface --force", d, files({"wn.txt": ORIENTED, "mesh.ply": EARLIER}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/mesh.ply --force", OK,
                    outputs=("dn.ply", "mesh.ply")),
    ]


def _partial() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    return [
        CommandCase("partial/the .normals of an .xyz output is a folder", n,
                    files({"in.xyz": CLOUD, "res.normals": _directory}),
                    "{dir}/in.xyz -o {dir}/res.xyz --method pca", BAD, ("res.normals",)),
        CommandCase("partial/the .normals of an .xyz output is a folder --force", n,
                    files({"in.xyz": CLOUD, "res.normals": _directory}),
                    "{dir}/in.xyz -o {dir}/res.xyz --method pca --force", BAD, ("res.normals",)),
        CommandCase("partial/the .normals of an .xyz output is a folder", d,
                    files({"wn.txt": ORIENTED, "res.normals": _directory}),
                    "{dir}/wn.txt -o {dir}/res.xyz --force", BAD, ("res.normals",)),
        CommandCase("partial/the surface's folder is a file", d, files({"wn.txt": ORIENTED, "sub": EARLIER}),
                    "{dir}/wn.txt -o {dir}/dn.ply --surface {dir}/sub/x.ply", BAD, ("{dir}/sub",),
                    note="the folder cannot be made: dn.ply must not be written"),
        CommandCase("partial/the output's folder is a file", n, files({"in.xyz": CLOUD, "sub": EARLIER}),
                    "{dir}/in.xyz -o {dir}/sub/out.ply --method pca", BAD, ("{dir}/sub",)),
    ]


def _folder() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    return [
        CommandCase("folder/output", n, files({"in.xyz": CLOUD, "out.ply": _directory}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca", BAD, ("{dir}/out.ply",)),
        CommandCase("folder/output --force", n, files({"in.xyz": CLOUD, "out.ply": _directory}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca --force", BAD, ("{dir}/out.ply",)),
        CommandCase("folder/input", n, files({"cloud.xyz": _directory}), "{dir}/cloud.xyz -o {dir}/out.ply "
                    "--method pca", BAD, ("{dir}/cloud.xyz",)),
        CommandCase("folder/a named pipe as output --force", n, files({"in.xyz": CLOUD, "out.ply": fifo}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca --force", BAD, ("{dir}/out.ply", "not a regular file")),
        CommandCase("folder/output", d, files({"wn.txt": ORIENTED, "dn.ply": _directory}),
                    "{dir}/wn.txt -o {dir}/dn.ply --force", BAD, ("{dir}/dn.ply",)),
        CommandCase("folder/input", d, files({"wn.txt": _directory}), "{dir}/wn.txt -o {dir}/dn.ply", BAD,
                    ("{dir}/wn.txt",)),
    ]


def _permission() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    return [
        CommandCase("permission/read-only output folder", n, files({"in.xyz": CLOUD, "ro": folder_mode(0o555)}),
                    "{dir}/in.xyz -o {dir}/ro/out.ply --method pca", BAD, ("{dir}/ro/out.ply",), root_skip=True),
        CommandCase("permission/read-only output folder", d, files({"wn.txt": ORIENTED, "ro": folder_mode(0o555)}),
                    "{dir}/wn.txt -o {dir}/ro/dn.ply", BAD, ("{dir}/ro/dn.ply",), root_skip=True),
        CommandCase("permission/unreadable input", n, files({"in.xyz": _unreadable(_rows(POINTS))}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca", BAD, ("{dir}/in.xyz",), root_skip=True),
        CommandCase("permission/unreadable input", d, files({"wn.txt": _unreadable(_rows(_six(POINTS, OUTWARD)))}),
                    "{dir}/wn.txt -o {dir}/dn.ply", BAD, ("{dir}/wn.txt",), root_skip=True),
    ]


def _disk_full() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    return [
        CommandCase("disk-full/.txt output", n, files({"in.xyz": FULL_CLOUD}),
                    "{dir}/in.xyz -o {dir}/out.txt --method pca", BAD, ("{dir}/out.txt",), preexec=full_disk),
        CommandCase("disk-full/.xyz output", n, files({"in.xyz": FULL_CLOUD}),
                    "{dir}/in.xyz -o {dir}/out.xyz --method pca", BAD, ("{dir}/out.",), preexec=full_disk),
        CommandCase("disk-full/.ply output", d, files({"wn.txt": FULL_ORIENTED}), "{dir}/wn.txt -o {dir}/dn.ply",
                    BAD, ("{dir}/dn.ply",), preexec=full_disk),
        CommandCase("disk-full/output over an existing one", n, files({"in.xyz": FULL_CLOUD, "out.npy": EARLIER}),
                    "{dir}/in.xyz -o {dir}/out.npy --method pca --force", BAD, ("{dir}/out.npy",),
                    preexec=full_disk, note="the earlier out.npy must survive"),
    ]


def _signal() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    term, stop = signal.SIGTERM, signal.SIGINT
    line = ("interrupted",)
    return [
        CommandCase("signal/SIGTERM", n, files({"big.xyz": big(3)}), "{dir}/big.xyz -o {dir}/big.ply",
                    INTERRUPTED[term], line, force=term),
        CommandCase("signal/SIGINT", n, files({"big.xyz": big(3)}), "{dir}/big.xyz -o {dir}/out.ply",
                    INTERRUPTED[stop], line, force=stop),
        CommandCase("signal/SIGINT over existing outputs --force", n,
                    files({"big.xyz": big(3), "out.xyz": EARLIER, "out.normals": EARLIER}),
                    "{dir}/big.xyz -o {dir}/out.xyz --force", INTERRUPTED[stop], line, force=stop,
                    note="the earlier out.xyz and out.normals must survive"),
        CommandCase("signal/SIGTERM", d, files({"big.txt": big(6)}),
                    "{dir}/big.txt -o {dir}/dn.ply --surface {dir}/mesh.ply", INTERRUPTED[term], line, force=term),
    ]


def _release() -> list[CommandCase]:
    n, d = NORMALS, DENOISE
    return [
        CommandCase("release/garbage networks.pt", n, files({"in.xyz": CLOUD, **release(GARBAGE)}),
                    "{dir}/in.xyz -o {dir}/out.ply --release {dir}/rel", BAD, NOT_A_RELEASE),
        CommandCase("release/foreign torch archive", n, files({"in.xyz": CLOUD, **release(foreign_bundle)}),
                    "{dir}/in.xyz -o {dir}/out.ply --method pca --release {dir}/rel", BAD, NOT_A_RELEASE),
        CommandCase("release/garbage networks.pt", d, files({"wn.txt": ORIENTED, **release(GARBAGE)}),
                    "{dir}/wn.txt -o {dir}/dn.ply --release {dir}/rel", BAD, NOT_A_RELEASE),
        CommandCase("release/foreign torch archive", d, files({"wn.txt": ORIENTED, **release(foreign_bundle)}),
                    "{dir}/wn.txt -o {dir}/dn.ply --release {dir}/rel", BAD, NOT_A_RELEASE),
    ]


def _option() -> list[CommandCase]:
    normal = [("--strata=²", "--strata"), ("--strata=-1", "--strata"), ("--threads=0", "--threads"),
              ("--threads=100000", "--threads"),
              ("--threads=x", "--threads"), ("--tile-points=abc", "--tile-points"), ("--bogus", "--bogus"),
              ("--viewpoint 1 2", "--viewpoint")]
    denoise = [("--radius=nan", "radius"), ("--iterations=x", "--iterations"), ("--bogus", "--bogus")]
    cases = [CommandCase(f"option/{option}", NORMALS, files({"in.xyz": CLOUD}),
                         f"{{dir}}/in.xyz -o {{dir}}/out.ply --method pca {option}", BAD, (named,))
             for option, named in normal]
    return cases + [CommandCase(f"option/{option}", DENOISE, files({"wn.txt": ORIENTED}),
                                f"{{dir}}/wn.txt -o {{dir}}/dn.ply {option}", BAD, (named,))
                    for option, named in denoise]


def _naming() -> list[CommandCase]:
    return [
        CommandCase("naming/.XYZ output", NORMALS, files({"in.xyz": CLOUD}), "{dir}/in.xyz -o {dir}/OUT.XYZ "
                    "--method pca", OK, outputs=("OUT.XYZ", "OUT.normals"), note="not OUT.XYZ.xyz"),
        CommandCase("naming/.PLY output", NORMALS, files({"in.xyz": CLOUD}), "{dir}/in.xyz -o {dir}/OUT.PLY "
                    "--method pca", OK, outputs=("OUT.PLY",)),
        CommandCase("naming/.XYZ output", DENOISE, files({"wn.txt": ORIENTED}), "{dir}/wn.txt -o {dir}/OUT.XYZ", OK,
                    outputs=("OUT.XYZ", "OUT.normals")),
        CommandCase("naming/.normals output", DENOISE, files({"wn.txt": ORIENTED}), "{dir}/wn.txt -o {dir}/dn.normals",
                    BAD, ("{dir}/dn.normals", "normals only"), note="the denoised points would be lost"),
    ]


def _side_file() -> list[CommandCase]:
    return [
        CommandCase("side-file/stale .normals beside the input", NORMALS,
                    files({"scan.xyz": CLOUD, "scan.normals": STALE_NORMALS}),
                    "{dir}/scan.xyz -o {dir}/out.ply --method pca", OK, outputs=("out.ply",)),
        CommandCase("side-file/stale .normals beside the input", DENOISE,
                    files({"scan.xyz": CLOUD, "scan.normals": STALE_NORMALS, "given.normals": NORMALS_FILE}),
                    "{dir}/scan.xyz --normals {dir}/given.normals -o {dir}/dn.ply", OK, outputs=("dn.ply",)),
    ]


def _ply() -> list[CommandCase]:
    placeholders = _ply_builder(["x", "y", "z", "nx", "ny", "nz"], _six(POINTS, np.zeros_like(POINTS)), binary=True)
    held = sphere(2000, "lying")[0]
    counts, read = ("2,000", "2,100"), ("read 2,100",)
    return [
        CommandCase("ply/zero normals (placeholders)", NORMALS, files({"scan.ply": placeholders}),
                    "{dir}/scan.ply -o {dir}/out.ply --method pca", OK, outputs=("out.ply",)),
        CommandCase("ply/declares 2100 vertices, holds 2000 (binary)", NORMALS,
                    files({"scan.ply": _ply_builder(["x", "y", "z"], held, declared=2100, binary=True)}),
                    "{dir}/scan.ply -o {dir}/out.ply --method pca", BAD, counts, read),
        CommandCase("ply/declares 2100 vertices, holds 2000 (ascii)", NORMALS,
                    files({"scan.ply": _ply_builder(["x", "y", "z"], held, declared=2100)}),
                    "{dir}/scan.ply -o {dir}/out.ply --method pca", BAD, counts, read),
    ]


def tiles_work(stale: bool = False, earlier: tuple[str, ...] = ()) -> Callable[[Path], None]:
    """The cloud in.xyz, its tiles plan plan.json and its one job's piece 0.npz, made by the command itself (PCA,
    so in seconds); `stale`: the cloud then replaced by another; each name in `earlier` then holds EARLIER."""
    def build(folder: Path) -> None:
        write_content(folder / "in.xyz", CLOUD)
        for step in (["plan", "in.xyz", "-o", "plan.json", "--method", "pca"],
                     ["run", "plan.json", "--job", "0", "-o", "0.npz"]):
            subprocess.run([sys.executable, "-m", "refinenet.cli.main", TILES, *step], cwd=folder, check=True,
                           capture_output=True)
        if stale:
            write_content(folder / "in.xyz", FULL_CLOUD)
        for name in earlier:
            write_content(folder / name, EARLIER)
    return build


def _tiles() -> list[CommandCase]:
    t, cloud = TILES, files({"in.xyz": CLOUD})
    merge = "merge {dir}/plan.json {dir}/0.npz -o"
    return [
        CommandCase("same-file/tiles merge into the cloud", t, tiles_work(), f"{merge} {{dir}}/in.xyz --force", BAD,
                    (INPUT, "{dir}/in.xyz")),
        CommandCase("twice/tiles merge a piece named twice", t, tiles_work(),
                    "merge {dir}/plan.json {dir}/0.npz {dir}/0.npz -o {dir}/out.ply", BAD, ("0.npz", "already")),
        CommandCase("exists/tiles plan", t, files({"in.xyz": CLOUD, "plan.json": EARLIER}),
                    "plan {dir}/in.xyz -o {dir}/plan.json --method pca", BAD, ("plan.json", "--force")),
        CommandCase("exists/tiles plan --force", t, files({"in.xyz": CLOUD, "plan.json": EARLIER}),
                    "plan {dir}/in.xyz -o {dir}/plan.json --method pca --force", OK, outputs=("plan.json",)),
        CommandCase("exists/tiles merge", t, tiles_work(earlier=("out.ply",)), f"{merge} {{dir}}/out.ply", BAD,
                    ("out.ply", "--force")),
        CommandCase("exists/tiles merge --force", t, tiles_work(earlier=("out.ply",)),
                    f"{merge} {{dir}}/out.ply --force", OK, outputs=("out.ply",)),
        CommandCase("option/tiles run --job beyond the plan", t, tiles_work(),
                    "run {dir}/plan.json --job 5 -o {dir}/5.npz", BAD, ("--job", "1 jobs")),
        CommandCase("naming/tiles plan not .json", t, cloud, "plan {dir}/in.xyz -o {dir}/plan.txt --method pca", BAD,
                    ("plan.txt", "JSON")),
        CommandCase("naming/tiles run piece not .npz", t, tiles_work(), "run {dir}/plan.json --job 0 -o {dir}/0.ply",
                    BAD, ("0.ply", ".npz")),
        CommandCase("stale/tiles run", t, tiles_work(stale=True), "run {dir}/plan.json --job 0 -o {dir}/1.npz", BAD,
                    ("{dir}/in.xyz", "changed")),
        CommandCase("stale/tiles merge", t, tiles_work(stale=True), f"{merge} {{dir}}/out.ply", BAD,
                    ("{dir}/in.xyz", "changed")),
    ]


def corpus() -> list[CommandCase]:
    """Every case, in a fixed order; names are unique per entry point."""
    cases = [*_same_file(), *_twice(), *_exists(), *_partial(), *_folder(), *_permission(), *_disk_full(),
             *_signal(), *_release(), *_option(), *_naming(), *_side_file(), *_ply(), *_tiles()]
    seen = Counter(case_id(c) for c in cases)
    assert all(n == 1 for n in seen.values()), f"duplicate cases: {[k for k, n in seen.items() if n > 1]}"
    assert all(c.issue in CLASSES and c.entry in ENTRIES for c in cases)
    assert all((c.status == OK) == bool(c.outputs) for c in cases), "a success names its outputs, a failure none"
    return cases


def case_id(case: CommandCase) -> str:
    return f"{case.entry}:{case.name}"


def table() -> str:
    """The corpus as a Markdown table, with the counts per entry point and per class."""
    cases = corpus()
    lines = ["| entry | case | arguments | expected |", "|---|---|---|---|"]
    for c in cases:
        outcome = f"{c.status}" + (f" after {c.force.name}" if c.force else "")
        outcome += f", writes {', '.join(c.outputs)}" if c.outputs else f", '{' / '.join(c.problem)}'"
        outcome += (", disk full" if c.preexec else "") + (", not as root" if c.root_skip else "")
        lines.append(f"| {c.entry} | `{c.name}` | `{c.argv}` | {outcome} |".replace("{dir}/", ""))
    entries, classes = Counter(c.entry for c in cases), Counter(c.issue for c in cases)
    lines += ["", f"**{len(cases)}** command lines: " + ", ".join(f"{entries[e]} {e}" for e in ENTRIES) + ".", "",
              "| class | cases | covers |", "|---|---|---|"]
    lines += [f"| {k} | {classes[k]} | {what} |" for k, what in CLASSES.items()]
    return "\n".join(lines)


if __name__ == "__main__":
    print(table())
