"""The paper's normal figures (fig:syn, fig:insight): per test cloud, a row of normals as RGB and a row of angular
error heat maps, one column per method and the ground truth last, the mean error over each panel's points in its
title. Rendered headless (`render.splat`, matplotlib's Agg) and deterministically: no timestamp or software
version is written, so the same normals give the same PNG and PDF bytes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402

from refinenet.atomic import atomic_path  # noqa: E402
from refinenet.evaluation.metrics import unoriented_angles  # noqa: E402
from refinenet.evaluation.render import normal_colours, splat, view_rotation  # noqa: E402

#: The heat map's range in degrees: errors above it saturate.
MAX_ERROR = 30.0
COLORMAP = "jet"
#: Metadata that would change from run to run, left out of every file.
STABLE = {"png": {"Software": None}, "pdf": {"CreationDate": None, "Producer": None, "Creator": None}}


@dataclass(frozen=True)
class Panel:
    """One test cloud of the figure: its points, true normals and each method's estimate (by display name)."""

    title: str
    points: np.ndarray
    truth: np.ndarray
    estimates: Mapping[str, np.ndarray]


def normals_figure(panels: Sequence[Panel], footer: str, paths: Mapping[str, str | Path], size: int = 300) -> None:
    """Write the figure to `paths` (keys png and pdf). `footer` names the profile and the data."""
    rotation = view_rotation()
    methods = list(panels[0].estimates)
    rows, columns = 2 * len(panels), len(methods) + 1
    fig, axes = plt.subplots(rows, columns, figsize=(1.7 * columns, 1.8 * rows + 0.5), dpi=150, squeeze=False)
    colormap = plt.get_cmap(COLORMAP)
    for i, panel in enumerate(panels):
        top, bottom = axes[2 * i], axes[2 * i + 1]
        for j, (name, normals) in enumerate([*panel.estimates.items(), ("ground truth", panel.truth)]):
            top[j].imshow(splat(panel.points, normal_colours(normals, rotation), rotation, size))
            top[j].set_title(name, fontsize=7)
            if name == "ground truth":
                continue
            error = unoriented_angles(normals, panel.truth)
            bottom[j].imshow(splat(panel.points, colormap(np.clip(error / MAX_ERROR, 0.0, 1.0))[:, :3], rotation,
                                   size))
            bottom[j].set_title(f"mean {error.mean():.2f} deg", fontsize=7)
        top[0].set_ylabel(panel.title, fontsize=6)
        bar = fig.colorbar(plt.cm.ScalarMappable(plt.Normalize(0.0, MAX_ERROR), colormap),
                           cax=bottom[-1].inset_axes((0.35, 0.1, 0.12, 0.8)))
        bar.set_label("error (deg)", fontsize=6)
        bar.ax.tick_params(labelsize=6)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_frame_on(False)
    fig.text(0.01, 0.005, footer, fontsize=5, color="0.35", wrap=True)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    for kind, path in paths.items():
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=kind, metadata=STABLE[kind])
    plt.close(fig)
