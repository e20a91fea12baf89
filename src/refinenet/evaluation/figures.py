"""The paper's figures: normals and error maps (fig:syn, fig:insight), normals on real scans (fig:real_boy),
clusters beside the Kc curve (fig:cluster) and the training curves. Rendered headless (`render.splat`,
matplotlib's Agg) and deterministically: no timestamp
or software version is written, so the same inputs give the same PNG and PDF bytes."""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path

import matplotlib
import numpy as np
import pandas as pd

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
from matplotlib.ticker import MaxNLocator  # noqa: E402

from refinenet.atomic import atomic_path  # noqa: E402
from refinenet.data.meshes import sample_mesh  # noqa: E402
from refinenet.evaluation.metrics import unoriented_angles  # noqa: E402
from refinenet.evaluation.render import normal_colours, scan_view, splat, view_rotation  # noqa: E402

#: The heat map's range in degrees: errors above it saturate.
MAX_ERROR = 30.0
COLORMAP = "jet"
#: fig:loss2's colours of `better`'s -1 (the first method, L1), 0 (equal) and 1 (the second, L2).
WINNER_COLOURS = np.array([[0.1, 0.3, 0.9], [0.7, 0.7, 0.7], [0.9, 0.15, 0.1]])
#: Points drawn per reconstructed surface: dense enough to close every gap at 300 pixels.
SURFACE_SPLATS = 100_000
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
    """Per panel a row of normals as RGB and a row of angular-error heat maps, one column per method and the ground
    truth last, the mean error over the panel's points in each title. Written to `paths` (kind -> file: png,
    pdf); `footer` names the profile and the data, as in every figure."""
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
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    _save(fig, footer, paths)


@dataclass(frozen=True)
class Scan:
    """One real scan of the real-scan figure: its points and each method's normals (by display name)."""

    name: str
    points: np.ndarray
    estimates: Mapping[str, np.ndarray]


def real_figure(scans: Sequence[Scan], footer: str, paths: Mapping[str, str | Path], size: int = 300) -> None:
    """[P] fig:real_boy / fig:outdoor: one row per scan, its normals as RGB under each method (no ground truth to
    measure against), each seen along its depth axis (`render.scan_view`)."""
    methods = list(scans[0].estimates)
    fig, axes = plt.subplots(len(scans), len(methods), figsize=(1.9 * len(methods), 1.9 * len(scans) + 0.4),
                             dpi=150, squeeze=False)
    for row, scan in zip(axes, scans, strict=True):
        rotation = scan_view(scan.points)
        for ax, (name, normals) in zip(row, scan.estimates.items(), strict=True):
            ax.imshow(splat(scan.points, normal_colours(normals, rotation), rotation, size))
            ax.set_title(name, fontsize=7)
        row[0].set_ylabel(f"{scan.name}\n{len(scan.points):,} points", fontsize=6)
    for ax in axes.ravel():
        ax.set_xticks([])
        ax.set_yticks([])
        ax.set_frame_on(False)
    fig.tight_layout(rect=(0, 0.03, 1, 1))
    _save(fig, footer, paths)


def _save(fig: plt.Figure, footer: str, paths: Mapping[str, str | Path]) -> None:
    fig.text(0.01, 0.005, footer, fontsize=5, color="0.35", wrap=True)
    for kind, path in paths.items():
        with atomic_path(path) as tmp:
            fig.savefig(tmp, format=kind, metadata=STABLE[kind])
    plt.close(fig)


def clusters_figure(points: np.ndarray, labels: Mapping[str, np.ndarray], sweep: tuple[Sequence[float],
                    Sequence[float]], footer: str, paths: Mapping[str, str | Path], size: int = 300) -> None:
    """[P] fig:cluster: the points of one cloud coloured by cluster under each clustering in `labels` (title ->
    cluster id per point), beside the Kc curve `sweep` (Kc values, Average mean error)."""
    rotation = view_rotation()
    fig, axes = plt.subplots(1, len(labels) + 1, figsize=(2.6 * (len(labels) + 1), 3.1), dpi=150, squeeze=False)
    palette = plt.get_cmap("tab10")
    for ax, (title, ids) in zip(axes[0], labels.items(), strict=False):
        ax.imshow(splat(points, palette(ids % 10)[:, :3], rotation, size))
        ax.set_title(f"{title}: {len(np.unique(ids))} clusters used", fontsize=7)
        ax.set_axis_off()
    curve = axes[0, -1]
    curve.plot(*sweep, marker="o", color="tab:blue")
    curve.set_xlabel("Kc", fontsize=7)
    curve.set_ylabel("Average mean error (deg)", fontsize=7)
    curve.set_xticks(list(sweep[0]))
    curve.tick_params(labelsize=6)
    curve.grid(alpha=0.3)
    fig.tight_layout(rect=(0, 0.05, 1, 0.95))
    _save(fig, footer, paths)


def training_figure(histories: Mapping[int, pd.DataFrame], title: str, footer: str,
                    paths: Mapping[str, str | Path]) -> None:
    """Training loss and validation mean error per epoch, one line per cluster (`training.train_cluster`'s
    history: epoch, train_loss, val_mean_deg)."""
    fig, (loss, error) = plt.subplots(1, 2, figsize=(7.6, 2.8), dpi=150)
    for c, history in histories.items():
        loss.plot(history["epoch"], history["train_loss"], marker=".", label=f"cluster {c}")
        error.plot(history["epoch"], history["val_mean_deg"], marker=".", label=f"cluster {c}")
    for ax, label in ((loss, "training loss"), (error, "validation mean error (deg)")):
        ax.set_xlabel("epoch", fontsize=7)
        ax.set_ylabel(label, fontsize=7)
        ax.xaxis.set_major_locator(MaxNLocator(integer=True))
        ax.tick_params(labelsize=6)
        ax.grid(alpha=0.3)
    error.legend(fontsize=6, loc="center left", bbox_to_anchor=(1.02, 0.5))
    fig.suptitle(title, fontsize=8)
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    _save(fig, footer, paths)


@dataclass(frozen=True)
class DenoisedColumn:
    """One column of the denoising figure: points with their distances to the true surface (in l_d), and the
    surface reconstructed from them (vertices, triangles)."""

    title: str
    points: np.ndarray
    distance: np.ndarray
    surface: tuple[np.ndarray, np.ndarray]


def denoising_figure(columns: Sequence[DenoisedColumn], clip: float, footer: str, paths: Mapping[str, str | Path],
                     size: int = 300) -> None:
    """[P] fig:block: per column, the points coloured by their distance to the true surface (heat map clipped at
    `clip`, in l_d) with the mean in the title, and below them the reconstructed surface, shaded."""
    rotation = view_rotation()
    colormap = plt.get_cmap(COLORMAP)
    fig, axes = plt.subplots(2, len(columns), figsize=(1.9 * len(columns), 4.2), dpi=150, squeeze=False)
    for (top, bottom), column in zip(axes.T, columns, strict=True):
        top.imshow(splat(column.points, colormap(np.clip(column.distance / clip, 0.0, 1.0))[:, :3], rotation, size))
        top.set_title(f"{column.title}\nmean {1e3 * column.distance.mean():.3f} x 1e-3 l_d", fontsize=6)
        vertices, triangles = column.surface
        if len(triangles):
            bottom.imshow(splat(*shaded_surface(vertices, triangles, rotation), rotation, size))
        bottom.set_title(f"surface: {len(triangles)} triangles", fontsize=6)
    for ax in axes.ravel():
        ax.set_axis_off()
    fig.tight_layout(rect=(0, 0.04, 1, 1))
    _save(fig, footer, paths)


def shaded_surface(vertices: np.ndarray, triangles: np.ndarray, rotation: np.ndarray,
                   n_points: int = SURFACE_SPLATS) -> tuple[np.ndarray, np.ndarray]:
    """A mesh as dense splats: points uniform by area on its triangles (a fixed seed) and their grey levels, lit from
    the viewer (two-sided Lambert on the face normal), so a coarse mesh still reads as a closed surface."""
    points, normals = sample_mesh(vertices, triangles, n_points, np.random.default_rng(0))
    grey = 0.25 + 0.7 * np.abs(normals @ rotation[2])
    return points, np.repeat(grey[:, None], 3, axis=1)


def loss_figure(panels: Sequence[Panel], footer: str, paths: Mapping[str, str | Path], size: int = 300) -> None:
    """[P] fig:loss2: per panel (a cloud, with the estimates of two methods by name, the first L1's), the points blue
    where the first method's error is lower and red where the second's is (grey where equal), and the share of each
    in the title."""
    rotation = view_rotation()
    fig, axes = plt.subplots(1, len(panels), figsize=(2.4 * len(panels), 2.9), dpi=150, squeeze=False)
    for ax, panel in zip(axes[0], panels, strict=True):
        winner = better(*(unoriented_angles(n, panel.truth) for n in panel.estimates.values()))
        ax.imshow(splat(panel.points, WINNER_COLOURS[winner + 1], rotation, size))
        first, second = panel.estimates
        ax.set_title(f"{panel.title}\n{first} better at {100 * np.mean(winner < 0):.1f}% (blue), "
                     f"{second} at {100 * np.mean(winner > 0):.1f}% (red)", fontsize=6)
        ax.set_axis_off()
    fig.tight_layout(rect=(0, 0.05, 1, 1))
    _save(fig, footer, paths)


def better(first: np.ndarray, second: np.ndarray) -> np.ndarray:
    """Per point: -1 where the first error is the lower, 1 where the second is, 0 where they are equal."""
    return np.sign(first - second).astype(np.int64)
