"""The repository is ruff clean under pyproject.toml's [tool.ruff] settings (the environment's ruff, of the dev
extra), so the test command checks what CI checks. `snakemake --lint` is checked in test_workflow."""

import subprocess
import sys
from pathlib import Path

REPO = Path(__file__).resolve().parents[1]


def test_ruff_finds_nothing():
    run = subprocess.run([sys.executable, "-m", "ruff", "check", "--no-cache", "."], cwd=REPO, capture_output=True,
                         text=True)
    assert run.returncode == 0, run.stdout[-3000:] + run.stderr[-3000:]
