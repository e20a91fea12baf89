"""The report page's entries (`evaluation.report` renders them): every table and figure of the run, the files each
links, what each figure shows and whether the run that builds the page makes it (the main job makes its own only).
The report step depends on exactly the files of the entries the run makes."""

from __future__ import annotations

import os
from dataclasses import dataclass, replace
from typing import TYPE_CHECKING

from refinenet.evaluation.table import METHOD_NAMES
from refinenet.pipeline import layout
from refinenet.pipeline.catalogue import (
    CLUSTER_FIGURE_VARIANTS,
    DENOISE_METHODS,
    DENOISE_TABLE,
    FIGURE_CATEGORIES,
    REAL_VARIANT,
    SCAN_FIGURE_METHODS,
    SCAN_TABLE,
    TABLES,
    Table,
)
from refinenet.pipeline.methods import FULL, figure_name

if TYPE_CHECKING:
    from refinenet.pipeline.workflow import Pipeline


@dataclass(frozen=True)
class TableEntry:
    """A table of the page: its CSV (rendered), its LaTeX (whose caption it shows) and every file to link."""

    name: str
    csv: str
    tex: str | None
    links: dict[str, str]
    made: bool = True
    """Whether the run that builds the page makes the table (the main job makes only its own): the page shows any
    other as the result of an earlier run or commit, saying so, or names the target that builds it."""
    target: str = ""
    """What to ask Snakemake for to build it."""


@dataclass(frozen=True)
class FigureEntry:
    """A figure of the page: the PNG shown, what it shows, and every file to link (e.g. the PDF)."""

    name: str
    png: str
    caption: str
    links: dict[str, str]
    made: bool = True
    target: str = ""


def _rel(paths: dict[str, str]) -> dict[str, str]:
    return {kind: os.path.relpath(path, layout.REPORT_DIR) for kind, path in paths.items()}


def _figures(pipe: Pipeline) -> list[tuple[str, dict[str, str], str]]:
    """Every figure of the run: (name, its files from the repository root, caption)."""
    denoise = bool(pipe.denoise_keys())
    scans = pipe.full.figures.scans
    return [
        ("normals_and_errors", layout.FIGURE_NORMALS,
         "[P] fig:syn / fig:insight: normals as RGB and unoriented angular-error heat maps of "
         f"{', '.join(map(figure_name, pipe.figure_methods()))} on the first test cloud of "
         f"{' and '.join(FIGURE_CATEGORIES)}; each panel's mean error in its title."),
        ("real_scans", layout.FIGURE_REAL,
         "[P] fig:real_boy / fig:outdoor: normals as RGB of "
         f"{', '.join(map(figure_name, SCAN_FIGURE_METHODS))} (variant {REAL_VARIANT}: no initial normal among its "
         "inputs, the paper's real-data setting) on "
         + (f"the real scans of {scans} (no ground truth)" if scans else "the simulated scans of table_scans")
         + ", radii from the point spacing."),
        ("clusters", layout.FIGURE_CLUSTERS,
         "[P] fig:cluster: a test cloud coloured by cluster for "
         f"{' and '.join(f'variant {v}' for v in CLUSTER_FIGURE_VARIANTS)}, beside the Kc curve."),
        *([("denoising", layout.FIGURE_DENOISE,
            "[P] fig:block: a test cloud denoised with the normals of "
            f"{', '.join(METHOD_NAMES[m] for m in DENOISE_METHODS)} (top: points coloured by their distance to "
            "the true surface; bottom: screened Poisson surfaces), beside the noisy input and the true surface.")]
          if denoise else []),
        ("l1_against_l2", layout.FIGURE_LOSS,
         "[P] fig:loss2: one test shape at increasing noise, each point blue where Refine-Net trained with L1 "
         "has the lower error and red where the L2 (mse) network has; the share of blue points in each title."),
        *((f"{name}_plot", {"png": Table.files(name, table)["plot"]},
           f"The {table.sweep[1]} sweep: Average mean error against {table.sweep[1]} ({name}).")
          for name, table in TABLES.items() if table.sweep),
        *((f"training_{v}", {"png": layout.FIGURE_TRAINING.format(variant=v)},
           f"Training loss and validation error per epoch of every cluster of variant {v}"
           + (" (the release's networks)." if v == FULL else "."))
          for v in pipe.trained),
    ]


def _tables(pipe: Pipeline) -> list[tuple[str, dict[str, str]]]:
    """Every table of the run: (name, its files from the repository root)."""
    return [*((n, Table.files(n)) for n in TABLES),
            *([(DENOISE_TABLE, Table.files(DENOISE_TABLE))] if pipe.denoise_keys() else []),
            (SCAN_TABLE, Table.files(SCAN_TABLE)), ("table_time", layout.TIME_FILES),
            ("table_architecture", layout.ARCHITECTURE_FILES)]


def reported(pipe: Pipeline, main: bool = False) -> tuple[list[TableEntry], list[FigureEntry]]:
    """Every table and figure of the report page, paths relative to the page's folder; with `main`, the main job's
    page, on which only the main job's files (`Pipeline.main_targets`) are made by the run."""
    made = set(pipe.main_targets()) if main else None
    tables = [TableEntry(name, files["csv"], files["tex"], files, made is None or files["csv"] in made, files["csv"])
              for name, files in _tables(pipe)]
    figures = [FigureEntry(name, files["png"], caption, files, made is None or files["png"] in made, files["png"])
               for name, files, caption in _figures(pipe)]
    return ([replace(t, csv=os.path.relpath(t.csv, layout.REPORT_DIR), tex=os.path.relpath(t.tex, layout.REPORT_DIR),
                     links=_rel(t.links)) for t in tables],
            [replace(f, png=os.path.relpath(f.png, layout.REPORT_DIR), links=_rel(f.links)) for f in figures])


#: The notes the page shows as text, by title: (the file from the repository root, whether the main job makes it).
#: The comparison with the paper reads every table: the full run makes it.
NOTES = {"Comparison with the paper": (layout.COMPARISON_FILES["md"], False),
         "Model card of the release": (f"{layout.RELEASE}/MODEL_CARD.md", True)}


def reported_files(pipe: Pipeline, main: bool = False) -> list[str]:
    """What the report page renders or links that the run makes, as paths from the repository root (the release
    as its folder, a step's output): the report step depends on exactly these."""
    tables, figures = reported(pipe, main)
    files = [os.path.join(layout.REPORT_DIR, p) for entry in (*tables, *figures) if entry.made
             for p in entry.links.values()]
    notes = [path for path, by_main in NOTES.values() if by_main or not main]
    return list(dict.fromkeys(layout.RELEASE if p.startswith(f"{layout.RELEASE}/") else p for p in [*files, *notes]))
