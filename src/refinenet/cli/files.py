"""The files of one command, checked before any work: no output may be one of its inputs (by identity: the same
path, a hard link or a symbolic link), none may be written twice, and none may replace an existing file unless
the user says `--force`, which never extends to an input."""

from __future__ import annotations

import os
import stat
from collections.abc import Mapping, Sequence
from pathlib import Path

from refinenet.errors import OutputError


def release_files(folder: str | Path) -> list[Path]:
    """Every file of a release folder: all of them are read, and none may be overwritten."""
    folder = Path(folder)
    return sorted(p for p in folder.iterdir() if p.is_file()) if folder.is_dir() else []


def check_outputs(reads: Mapping[str, Sequence[str | Path]], writes: Sequence[str | Path], force: bool) -> None:
    """Refuse, in one line naming the output, a write onto an input (`reads`: the files by what they are, e.g.
    "the input"), the same file written twice, an existing file without `force`, or a folder that cannot take
    it."""
    inputs = {}
    for what, paths in reads.items():
        for path in paths:
            try:
                info = os.stat(path)
            except OSError:
                continue  # a missing or unreadable input is its reader's error
            inputs[info.st_dev, info.st_ino] = what, Path(path)
    written: dict[str, Path] = {}
    for path in map(Path, writes):
        key = os.path.realpath(path)
        if key in written:
            raise OutputError(path, f"is written twice (also as {written[key]}); choose another output")
        written[key] = path
        try:
            info = os.stat(path) if os.path.lexists(path) else None
        except FileNotFoundError:  # a dangling symbolic link: an existing name all the same
            info = os.lstat(path)
        except OSError as err:
            raise OutputError(path, f"cannot be written ({err.strerror})") from None
        if info is not None and (info.st_dev, info.st_ino) in inputs:
            what, source = inputs[info.st_dev, info.st_ino]
            same = "" if source == path else f" {source} (the same file)"
            raise OutputError(path, f"is {what}{same}; choose another output (an input is never written, even "
                                    f"with --force)")
        if info is not None and stat.S_ISDIR(info.st_mode):
            raise OutputError(path, "is a folder")
        if info is not None and not (stat.S_ISREG(info.st_mode) or stat.S_ISLNK(info.st_mode)):
            raise OutputError(path, "exists and is not a regular file (a device, a pipe or a socket)")
        if info is not None and not force:
            raise OutputError(path, "exists; pass --force to replace it")
        _check_folder(path)


def _check_folder(path: Path) -> None:
    """The nearest existing folder above `path` must be a folder this process may create files in."""
    folder = path.absolute().parent
    while not os.path.lexists(folder) and folder != folder.parent:
        folder = folder.parent
    if not folder.is_dir():
        raise OutputError(path, f"cannot be written ({folder} is not a folder)")
    if not os.access(folder, os.W_OK | os.X_OK):
        raise OutputError(path, f"cannot be written (the folder {folder} is not writable)")
