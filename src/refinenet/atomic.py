"""Atomic output: every file is written under a temporary name in its folder and renamed when complete,
so a killed job never leaves a file that looks finished, and a failed write (a full disk) leaves nothing and
says so in one line. Inside `atomic_group` the renames wait for the whole group: the outputs of one command
appear together or not at all."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Callable, Iterator
from contextlib import contextmanager
from contextvars import ContextVar
from pathlib import Path

from refinenet.errors import OutputError
from refinenet.interrupts import held


def _umask() -> int:
    """The process's umask (reading it means setting it, so it is set back at once)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


#: The (temporary, final) paths of the open `atomic_group`, renamed when it ends; None outside a group.
_GROUP: ContextVar[list[tuple[Path, Path]] | None] = ContextVar("atomic_group", default=None)
#: Every temporary of this process not yet renamed or deleted, and the folders made for outputs not yet in place
#: (`remove_temporaries`).
_LIVE: set[Path] = set()
_MADE: list[Path] = []
#: Characters of an output's name kept in its temporary's name, so that a long legal name stays legal.
STEM_CHARS = 64


def _failed(path: Path, err: OSError) -> OutputError:
    return OutputError(path, f"cannot be written ({err.strerror or type(err).__name__})")


@contextmanager
def atomic_group(committed: Callable[[], None] | None = None) -> Iterator[None]:
    """Defer the renames of every `atomic_path` in the block to its successful end, then make them all in one
    `interrupts.held` block, and call `committed` before it ends (a command then stops treating a signal as
    "nothing was written"). On any failure every temporary is deleted and no output of the block appears; a file
    an output replaced (with --force) is put back from a hard link made before the renames."""
    pending: list[tuple[Path, Path]] = []
    token = _GROUP.set(pending)
    try:
        yield
    except BaseException:
        _undo(tmp for tmp, _ in pending)
        raise
    finally:
        _GROUP.reset(token)
    with held():
        backups: dict[Path, Path] = {}
        done: list[Path] = []
        try:
            for tmp, path in pending:
                if path.is_file() and not path.is_symlink():
                    backup = tmp.with_name(tmp.name + ".old")
                    try:
                        os.link(path, backup)
                    except OSError:  # a file system without hard links: that file cannot be put back
                        continue
                    backups[path] = backup
                    _LIVE.add(backup)
            for tmp, path in pending:
                os.replace(tmp, path)
                _LIVE.discard(tmp)
                done.append(path)
        except OSError as err:
            for path in done:
                if path in backups:
                    os.replace(backups[path], path)
                else:
                    path.unlink(missing_ok=True)
            _undo([tmp for tmp, _ in pending] + list(backups.values()))
            raise _failed(pending[len(done)][1], err) from None
        for backup in backups.values():
            _remove(backup)
        _MADE.clear()
        if committed is not None:
            committed()


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it onto `path` (at the end of the enclosing
    `atomic_group`, if any), on failure delete it (and any folder made for it).

    The temporary name keeps the final suffix, so writers that dispatch on the extension (numpy, open3d)
    behave as they would for the final file.
    """
    path = Path(path)
    group, tmp_path = _GROUP.get(), None
    try:
        _make_folders(path.parent)
        with held():  # a temporary exists only once it is known to remove_temporaries
            fd, tmp = tempfile.mkstemp(prefix=f".{path.stem[:STEM_CHARS]}.", suffix=f".tmp{path.suffix.lower()}",
                                       dir=path.parent)
            tmp_path = Path(tmp)
            _LIVE.add(tmp_path)
        try:
            os.fchmod(fd, 0o666 & ~_umask())
        finally:
            os.close(fd)
    except OSError as err:
        _undo([tmp_path] if tmp_path else [])
        raise _failed(path, err) from None
    try:
        yield tmp_path
        if group is None:
            os.replace(tmp_path, path)
            _LIVE.discard(tmp_path)
            _MADE.clear()
        else:
            group.append((tmp_path, path))
    except OSError as err:
        raise _failed(path, err) from None
    finally:
        if tmp_path in _LIVE and (group is None or (tmp_path, path) not in group):
            _undo([tmp_path])


def _make_folders(folder: Path) -> None:
    """Create `folder` and the missing folders above it, remembering each for `_undo`."""
    missing = []
    while not folder.exists() and folder != folder.parent:
        missing.append(folder)
        folder = folder.parent
    for made in reversed(missing):
        made.mkdir(exist_ok=True)
        _MADE.append(made)


def _remove(tmp: Path) -> None:
    tmp.unlink(missing_ok=True)
    _LIVE.discard(tmp)


def _undo(temporaries) -> None:
    """Delete the temporaries, then the folders made for outputs, deepest first, while they are empty."""
    for tmp in list(temporaries):
        _remove(tmp)
    if not _LIVE:
        for folder in reversed(_MADE):
            try:
                folder.rmdir()
            except OSError:
                pass
        _MADE.clear()


def remove_temporaries() -> None:
    """Delete every temporary this process still has, and the folders made for them: for a command that stops
    on a signal at once, without unwinding (which would leave the threads of a pool running into the
    interpreter's shutdown)."""
    _undo(list(_LIVE))


def write_text(path: str | Path, text: str) -> None:
    """Write a text file atomically."""
    with atomic_path(path) as tmp:
        tmp.write_text(text)


def write_torch(path: str | Path, obj: object) -> None:
    """Save a torch object atomically, through an open file: given a path, torch names the records inside its
    archive after that (temporary, random) file name, so two runs saving the same networks wrote different bytes."""
    import torch  # here, not at the top: most users of this module never load torch

    with atomic_path(path) as tmp, open(tmp, "wb") as fh:
        torch.save(obj, fh)
