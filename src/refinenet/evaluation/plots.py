"""Line plots of the sweep tables (e.g. the Kc curve of the paper's fig:cluster), rendered headless and
deterministically: the same table gives the same PNG bytes (no timestamp or software version is written)."""

from __future__ import annotations

from collections.abc import Sequence
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from refinenet.atomic import atomic_path  # noqa: E402


def sweep_plot(values: Sequence[float], errors: Sequence[float], symbol: str, ylabel: str, footer: str,
               path: str | Path) -> None:
    """The error against the swept value, one marker per row of the table; `footer` names profile and data."""
    fig, ax = plt.subplots(figsize=(4.5, 3.4), dpi=150)
    ax.plot(values, errors, marker="o", color="tab:blue")
    ax.set_xlabel(symbol)
    ax.set_ylabel(ylabel)
    ax.set_xticks(list(values))
    ax.grid(alpha=0.3)
    fig.text(0.01, 0.01, footer, fontsize=6, color="0.35")
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    plt.close(fig)
