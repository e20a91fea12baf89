"""Scratch copies of the repository for end-to-end runs: the working tree (tracked and untracked, not ignored
files) in a fresh git repository, with the smoke profile selected."""

import os
import shutil
import subprocess
import sys
from pathlib import Path

from refinenet.pipeline.layout import TIMED_FILES

REPO = Path(__file__).resolve().parents[1]


def isolated(cwd: Path, **extra: str) -> dict[str, str]:
    """The environment for a command in a scratch copy: its own library first, not the checkout's (which the
    editable install points at), so the copy runs the code it was made from."""
    return {**os.environ, **extra,
            "PYTHONPATH": os.pathsep.join([str(cwd / "src"), os.environ.get("PYTHONPATH", "")])}


def sh(cwd: Path, *cmd: str, env: dict[str, str] | None = None) -> subprocess.CompletedProcess:
    """Run a command in a scratch copy (with `env` added to the environment); fail with its output's tail when it
    exits non-zero."""
    run = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True, env=isolated(cwd, **(env or {})))
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    return run


def snakemake(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return sh(cwd, sys.executable, "-m", "snakemake", *args)


def path_without(programs: set[str], shadows: Path) -> str:
    """The PATH with `programs` not found on it, as on a machine where they are not installed: each folder of the
    PATH that holds one of them is replaced by a folder under `shadows` of links to its other entries."""
    folders = []
    for i, folder in enumerate(os.environ["PATH"].split(os.pathsep)):
        entries = sorted(Path(folder).iterdir()) if Path(folder).is_dir() else []
        if any(entry.name in programs for entry in entries):
            shadow = shadows / str(i)
            shadow.mkdir(parents=True)
            for entry in entries:
                if entry.name not in programs:
                    (shadow / entry.name).symlink_to(entry)
            folder = str(shadow)
        folders.append(folder)
    return os.pathsep.join(folders)


def set_param(repo: Path, old: str, new: str) -> None:
    """Replace the first occurrence of `old` in the copy's params.yaml (which must hold it)."""
    params = repo / "params.yaml"
    text = params.read_text()
    assert old in text
    params.write_text(text.replace(old, new, 1))


def smoke_copy(tmp: Path) -> Path:
    """The working tree in a fresh git repository at `tmp`, profile smoke, without the record of the committed
    run (dvc.lock): a smoke run starts with none."""
    files = sh(REPO, "git", "ls-files", "-co", "--exclude-standard").stdout.split()
    for f in files:
        if (REPO / f).is_file() and f != "dvc.lock":
            (tmp / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / f, tmp / f)
    set_param(tmp, "profile: cpu", "profile: smoke")
    sh(tmp, "git", "init", "-q")
    return tmp


def report_files(repo: Path) -> dict[str, bytes]:
    """Every file under the copy's reports/, by path, with its bytes (table_time's files only as present: their
    timings differ from run to run)."""
    timed = set(TIMED_FILES)
    files = {str(p.relative_to(repo)): p for p in sorted((repo / "reports").rglob("*")) if p.is_file()}
    return {name: b"timings" if name in timed else path.read_bytes() for name, path in files.items()}


def different_files(expected: dict[str, bytes], got: dict[str, bytes]) -> list[str]:
    """Names present in only one of two `report_files` results, or with other bytes."""
    return sorted(name for name in expected.keys() | got.keys() if expected.get(name) != got.get(name))
