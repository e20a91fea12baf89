"""Atomic output: every file is written under a temporary name in its folder and renamed when complete,
so a killed job never leaves a file that looks finished, and a failed write (a full disk) leaves nothing and
says so in one line."""

from __future__ import annotations

import os
import tempfile
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

from refinenet.errors import OutputError


def _umask() -> int:
    """The process's umask (reading it means setting it, so it is set back at once)."""
    mask = os.umask(0o022)
    os.umask(mask)
    return mask


@contextmanager
def atomic_path(path: str | Path) -> Iterator[Path]:
    """Yield a temporary path beside `path`; on success rename it onto `path`, on failure delete it.

    The temporary name keeps the final suffix, so writers that dispatch on the extension (numpy, open3d)
    behave as they would for the final file.
    """
    path = Path(path)
    try:
        path.parent.mkdir(parents=True, exist_ok=True)
        fd, tmp = tempfile.mkstemp(prefix=f".{path.stem}.", suffix=f".tmp{path.suffix}", dir=path.parent)
    except OSError as err:
        raise OutputError(path, f"cannot be written ({err.strerror})") from None
    os.fchmod(fd, 0o666 & ~_umask())
    os.close(fd)
    tmp_path = Path(tmp)
    try:
        yield tmp_path
        os.replace(tmp_path, path)
    except OSError as err:
        raise OutputError(path, f"cannot be written ({err.strerror})") from None
    finally:
        if tmp_path.exists():
            tmp_path.unlink()


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
