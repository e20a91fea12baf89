"""The report page's entries (`evaluation.report` renders them): every table and figure the run makes, the files
each links and what each figure shows. The report step depends on exactly these files."""

from __future__ import annotations

import os
from dataclasses import dataclass
from typing import TYPE_CHECKING, Any

from refinenet.evaluation.table import METHOD_NAMES
from refinenet.pipeline import layout
from refinenet.pipeline.catalogue import (
    CLUSTER_FIGURE_VARIANTS,
    DENOISE_METHODS,
    DENOISE_TABLE,
    FIGURE_CATEGORIES,
    FIGURE_METHODS,
    REAL_VARIANT,
    SCAN_TABLE,
    TABLES,
    Table,
)
from refinenet.pipeline.methods import figure_name

if TYPE_CHECKING:
    from refinenet.pipeline.workflow import Pipeline


@dataclass(frozen=True)
class TableEntry:
    """A table of the page: its CSV (rendered), its LaTeX (whose caption it shows) and every file to link."""

    name: str
    csv: str
    tex: str | None
    links: dict[str, str]


@dataclass(frozen=True)
class FigureEntry:
    """A figure of the page: the PNG shown, what it shows, and every file to link (e.g. the PDF)."""

    name: str
    png: str
    caption: str
    links: dict[str, str]


def _figure(files: dict[str, str]) -> dict[str, Any]:
    """A figure's PNG and its links (every format it is written in)."""
    return {"png": files["png"], "links": files}


def _rel(paths: dict[str, str]) -> dict[str, str]:
    return {kind: os.path.relpath(path, layout.REPORT_DIR) for kind, path in paths.items()}


def reported(pipe: Pipeline) -> tuple[list[TableEntry], list[FigureEntry]]:
    """Every table and figure of the report page, paths relative to the page's folder."""
    denoise = bool(pipe.denoise_keys())
    tables = [TableEntry(name, files["csv"], files["tex"], files)
              for name, files in [*((n, _rel(Table.files(n))) for n in TABLES),
                                  *([(DENOISE_TABLE, _rel(Table.files(DENOISE_TABLE)))] if denoise else []),
                                  (SCAN_TABLE, _rel(Table.files(SCAN_TABLE))),
                                  ("table_time", _rel(layout.TIME_FILES)),
                                  ("table_architecture", _rel(layout.ARCHITECTURE_FILES))]]
    figures = [
        FigureEntry("normals_and_errors", **_figure(_rel(layout.FIGURE_NORMALS)), caption=(
            "[P] fig:syn / fig:insight: normals as RGB and unoriented angular-error heat maps of "
            f"{', '.join(map(figure_name, pipe.figure_methods()))} on the first test cloud of "
            f"{' and '.join(FIGURE_CATEGORIES)}; each panel's mean error in its title.")),
        FigureEntry("real_scans", **_figure(_rel(layout.FIGURE_REAL)), caption=(
            "[P] fig:real_boy / fig:outdoor: normals as RGB of "
            f"{', '.join(METHOD_NAMES[m] for m in FIGURE_METHODS)} (X = 8, variant {REAL_VARIANT}) on "
            + (f"the real scans of {pipe.full.figures.scans} (no ground truth)" if pipe.full.figures.scans else
               "the simulated scans of table_scans")
            + ", radii from the point spacing.")),
        FigureEntry("clusters", **_figure(_rel(layout.FIGURE_CLUSTERS)), caption=(
            "[P] fig:cluster: a test cloud coloured by cluster for "
            f"{' and '.join(f'variant {v}' for v in CLUSTER_FIGURE_VARIANTS)}, beside the Kc curve.")),
        *([FigureEntry("denoising", **_figure(_rel(layout.FIGURE_DENOISE)), caption=(
            "[P] fig:block: a test cloud denoised with the normals of "
            f"{', '.join(METHOD_NAMES[m] for m in DENOISE_METHODS)} (top: points coloured by their distance to "
            "the true surface; bottom: screened Poisson surfaces), beside the noisy input and the true surface."))]
          if denoise else []),
        FigureEntry("l1_against_l2", **_figure(_rel(layout.FIGURE_LOSS)), caption=(
            "[P] fig:loss2: one test shape at increasing noise, each point blue where Refine-Net trained with L1 "
            "has the lower error and red where the L2 (mse) network has; the share of blue points in each title.")),
        *(FigureEntry(name, **_figure(_rel({"png": Table.files(name, table)["plot"]})),
                      caption=f"The {table.sweep[1]} sweep: Average mean error against {table.sweep[1]} ({name}).")
          for name, table in TABLES.items() if table.sweep),
        *(FigureEntry(f"training_{v}", **_figure(_rel({"png": layout.FIGURE_TRAINING.format(variant=v)})),
                      caption=f"Training loss and validation error per epoch of every cluster of variant {v}.")
          for v in pipe.trained),
    ]
    return tables, figures


def reported_files(pipe: Pipeline) -> list[str]:
    """The files the report page renders or links, as paths from the repository root."""
    tables, figures = reported(pipe)
    files = [os.path.join(layout.REPORT_DIR, p) for entry in (*tables, *figures) for p in entry.links.values()]
    return list(dict.fromkeys([*files, layout.COMPARISON_FILES["md"]]))
