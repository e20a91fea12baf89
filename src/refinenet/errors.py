"""User-facing errors: one line naming the file or parameter and what is wrong with it."""

from __future__ import annotations

from pathlib import Path


def first_line(err: BaseException) -> str:
    """The first line of an exception's message (its type's name when it has none): for a one-line error."""
    text = str(err).strip()
    return text.splitlines()[0] if text else type(err).__name__


class RefineNetError(Exception):
    """Base class of the errors a stage reports as a single line and a non-zero exit."""


class InputError(RefineNetError):
    """A data file that cannot be used: missing, empty, truncated, non-numeric, NaN/inf, wrong shape, too small."""

    def __init__(self, path: str | Path, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{self.path}: {problem}")


class OutputError(RefineNetError):
    """An output that cannot be written (no space left, no permission); nothing that looks complete is left."""

    def __init__(self, path: str | Path, problem: str):
        self.path, self.problem = str(path), problem
        super().__init__(f"{self.path}: {problem}")


class ParamsError(RefineNetError):
    """An invalid configuration value, named by its dotted key."""

    def __init__(self, key: str, problem: str, source: str = "params.yaml"):
        self.key, self.problem = key, problem
        super().__init__(f"{source}: {key}: {problem}")
