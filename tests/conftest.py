"""Shared fixtures: paths to the repository and to the shared development data (skipped when absent)."""

import subprocess
from pathlib import Path

import numpy as np
import pandas as pd
import pytest

from refinenet.evaluation.metrics import ErrorStats
from refinenet.evaluation.table import stats_row
from refinenet.threads import thread_independent_products

# The tests compare in-process runs with the commands' (a tile job here against `refinenet normals` there): they run
# in the commands' MKL mode, and so do the processes they start.
thread_independent_products()

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


@pytest.fixture
def per_cloud() -> pd.DataFrame:
    """Per-cloud errors of two methods on three categories, two clouds each, with known aggregates: every angle of
    a cloud is equal (pca's twice jet's)."""
    rows = []
    for method, scale in (("pca", 2.0), ("jet", 1.0)):
        for category, base in (("SmoothSurface", 1.0), ("BigNoise", 3.0), ("SharpFeature", 2.0)):
            for i, n in enumerate((10, 30)):
                angles = np.full(n, scale * base * (i + 1))
                rows.append(stats_row(method, category, f"{category}_{i}", ErrorStats.from_angles(angles)))
    return pd.DataFrame(rows)
