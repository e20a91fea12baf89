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
#: Every temporary of this process not yet renamed or deleted (`remove_temporaries`).
_LIVE: set[Path] = set()


@contextmanager
def atomic_group(committed: Callable[[], None] | None = None) -> Iterator[None]:
    """Defer the renames of every `atomic_path` in the block to its successful end, then make them all in one
    `interrupts.held` block, and call `committed` before it ends (a command then stops treating a signal as
    "nothing was written"). On any failure every temporary is deleted and no output of the block appears."""
    pending: list[tuple[Path, Path]] = []
    token = _GROUP.set(pending)
    try:
        yield
    except BaseException:
        for tmp, _ in pending:
            _remove(tmp)
        raise
    finally:
        _GROUP.reset(token)
    done: list[Path] = []
    with held():
        try:
            for tmp, path in pending:
                os.replace(tmp, path)
                _LIVE.discard(tmp)
                done.append(path)
        except OSError as err:
            for tmp, _ in pending:
                _remove(tmp)
            for path in done:  # new files only: an output that replaced another (--force) cannot be taken back
                path.unlink(missing_ok=True)
            raise OutputError(pending[len(done)][1], f"cannot be written ({err.strerror})") from None
        if committed is not None:
            committed()


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it onto `path` (at the end of the enclosing
    `atomic_group`, if any), on failure delete it.

    The temporary name keeps the final suffix, so writers that dispatch on the extension (numpy, open3d)
    behave as they would for the final file.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        with held():  # a temporary exists only once it is known to remove_temporaries
            fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix.lower()}",
                                       dir=path.parent)
            _LIVE.add(Path(tmp))
    except OSError as err:
        raise OutputError(path, f"cannot be written ({err.strerror})") from None
    os.fchmod(fd, 0o666 & ~_umask())
    os.close(fd)
    tmp_path, group = Path(tmp), _GROUP.get()
    try:
        yield tmp_path
        if group is None:
            os.replace(tmp_path, path)
            _LIVE.discard(tmp_path)
        else:
            group.append((tmp_path, path))
    except OSError as err:
        raise OutputError(path, f"cannot be written ({err.strerror})") from None
    finally:
        if tmp_path in _LIVE and (group is None or (tmp_path, path) not in group):
            _remove(tmp_path)


def _remove(tmp: Path) -> None:
    tmp.unlink(missing_ok=True)
    _LIVE.discard(tmp)


def remove_temporaries() -> None:
    """Delete every temporary this process still has: for a command that stops on a signal at once, without
    unwinding (which would leave the threads of a pool running into the interpreter's shutdown)."""
    for tmp in list(_LIVE):
        _remove(tmp)


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
