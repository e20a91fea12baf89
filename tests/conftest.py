"""Shared fixtures: paths to the repository and to the shared development data (skipped when absent)."""

import subprocess
from pathlib import Path

import pytest

# The suite starts its subprocesses from worker threads while torch's own threads run; a CI run once saw such a
# vfork()ed child fail its exec with EFAULT ("[Errno 14] Bad address"). fork() copies the address space instead of
# sharing it, so no other thread can disturb the child between the two calls.
subprocess._USE_VFORK = False

REPO = Path(__file__).resolve().parents[1]
SHARED_DATA = REPO.parent / "shared" / "data"


@pytest.fixture
def shared_data() -> Path:
    if not SHARED_DATA.is_dir():
        pytest.skip(f"shared development data not found at {SHARED_DATA}")
    return SHARED_DATA
