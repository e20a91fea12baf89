"""The paper's result tables (docs/algorithm.md §12): per-cloud error statistics, category aggregation, CSV,
booktabs LaTeX and the metrics records that `dvc metrics` reads."""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import numpy as np
import pandas as pd

from refinenet.atomic import atomic_path, write_text
from refinenet.data.clouds import scored_points
from refinenet.data.io import read_cloud, read_normals
from refinenet.data.shapes import TABLE_ORDER
from refinenet.errors import InputError
from refinenet.evaluation.metrics import (
    STAT_FIELDS,
    ErrorStats,
    average_over_categories,
    pcpnet_category,
    synthetic_category,
    unoriented_angles,
)

#: Display names of the methods, in the paper's row order.
METHOD_NAMES = {"pca": "PCA", "jet": "Jet", "mfps": "MFPS", "simple_mfps": "simple MFPS", "refinenet": "Refine-Net"}
METRIC_NAMES = {"mean": "mean", "rmse": "rmse", "pgp5": "PGP5", "pgp10": "PGP10"}
HIGHER_IS_BETTER = {"pgp5", "pgp10"}


def evaluate(methods: Sequence[str], clouds: Sequence[str | Path], normals: dict[str, Sequence[str | Path]],
             points: int | None = None) -> pd.DataFrame:
    """Error statistics of every (method, cloud) on the cloud's scored points (`scored_points`: the `.pidx`
    subset where there is one, and a seeded subset of `points` of them where given): `normals[method][i]` holds the
    estimate for `clouds[i]`."""
    for method in methods:
        if len(normals[method]) != len(clouds):
            raise InputError(method, f"{len(normals[method])} normals files for {len(clouds)} clouds")
    rows = []
    for i, cloud_path in enumerate(clouds):
        cloud = read_cloud(cloud_path)
        subset = scored_points(cloud, points)
        truth = cloud.normals if subset is None else cloud.normals[subset]
        for method in methods:
            estimated = read_normals(normals[method][i], len(cloud), subset)
            stats = ErrorStats.from_angles(unoriented_angles(estimated, truth))
            rows.append(stats_row(method, cloud.meta["category"], cloud.meta["name"], stats))
    return pd.DataFrame(rows)


def write_table(per_cloud: pd.DataFrame, protocol: str, metrics: Sequence[str], caption: str, label: str,
                paths: dict[str, str | Path], names: dict[str, str] | None = None) -> pd.DataFrame:
    """The table's four files (`paths` keys csv, tex, per_cloud, metrics), each written atomically; `names`: row
    names where they differ from `METHOD_NAMES`. Returns the table as written to the CSV."""
    names = {**METHOD_NAMES, **(names or {})}
    table = aggregate(per_cloud, protocol, metrics)
    csv = to_csv_frame(table, names)
    with atomic_path(paths["per_cloud"]) as tmp:
        per_cloud.to_csv(tmp, index=False, float_format="%.6g")
    with atomic_path(paths["csv"]) as tmp:
        csv.to_csv(tmp, float_format="%.4f")
    write_text(paths["tex"], to_latex(table, caption, label, names))
    write_text(paths["metrics"], json.dumps(metrics_record(csv), indent=2) + "\n")
    return csv


def metrics_record(csv: pd.DataFrame) -> dict[str, dict[str, float]]:
    """What `dvc metrics show` and `dvc metrics diff` display for a table: the Average columns per method (the
    per-category numbers are in the CSV)."""
    average = [c for c in csv.columns if c.startswith("Average/")]
    return {method: {c.removeprefix("Average/"): round(float(row[c]), 4) for c in average}
            for method, row in csv.iterrows()}


def stats_row(method: str, category: str, name: str, stats: ErrorStats) -> dict[str, object]:
    """One row of the per-cloud statistics table."""
    return {"method": method, "category": category, "cloud": name, **stats.to_dict(), **stats.summary()}


def category_order(categories: Sequence[str]) -> list[str]:
    """The paper's column order for known categories, then any others in the order given."""
    known = [c for c in TABLE_ORDER if c in categories]
    return known + [c for c in dict.fromkeys(categories) if c not in TABLE_ORDER]


def aggregate(per_cloud: pd.DataFrame, protocol: str, metrics: Sequence[str]) -> pd.DataFrame:
    """Rows: methods (in order of appearance); columns: (category, metric) plus ("Average", metric)."""
    combine = synthetic_category if protocol == "synthetic" else pcpnet_category
    categories = category_order(list(per_cloud["category"]))
    rows = {}
    for method, group in per_cloud.groupby("method", sort=False):
        per_cat = {}
        for category in categories:
            clouds = group[group["category"] == category]
            if len(clouds):
                stats = [ErrorStats(*(r[f] for f in STAT_FIELDS)) for r in clouds.to_dict("records")]
                per_cat[category] = combine(stats)
        per_cat["Average"] = average_over_categories(per_cat)
        rows[method] = {(c, m): v[m] for c, v in per_cat.items() for m in metrics}
    table = pd.DataFrame.from_dict(rows, orient="index")
    table.columns = pd.MultiIndex.from_tuples(table.columns, names=["category", "metric"])
    return table


def to_csv_frame(table: pd.DataFrame, names: dict[str, str] = METHOD_NAMES) -> pd.DataFrame:
    """Flat columns `category/metric` and display method names."""
    flat = table.copy()
    flat.columns = [f"{c}/{m}" for c, m in table.columns]
    flat.index = [names.get(m, m) for m in table.index]
    flat.index.name = "method"
    return flat


def _fmt(metric: str, value: float) -> str:
    return f"{value:.3f}".lstrip("0") if metric in HIGHER_IS_BETTER else f"{value:.2f}"


def to_latex(table: pd.DataFrame, caption: str, label: str, names: dict[str, str] = METHOD_NAMES) -> str:
    """A booktabs table like the paper's: two-level header, best value per column in bold."""
    categories = list(dict.fromkeys(c for c, _ in table.columns))
    metrics = list(dict.fromkeys(m for _, m in table.columns))
    best = {col: (table[col].max() if col[1] in HIGHER_IS_BETTER else table[col].min()) for col in table.columns}
    width = len(metrics)
    spec = "l" + "c" * width * len(categories)
    rules = " ".join(f"\\cmidrule(lr){{{2 + i * width}-{1 + (i + 1) * width}}}" for i in range(len(categories)))
    lines = [
        "\\begin{table}[t]", "\\centering", f"\\caption{{{latex_escape(caption)}}}", f"\\label{{{label}}}",
        f"\\begin{{tabular}}{{{spec}}}", "\\toprule",
        " & ".join(["Category"] + [f"\\multicolumn{{{width}}}{{c}}{{{c}}}" for c in categories]) + " \\\\",
        rules,
        " & ".join(["Method"] + [METRIC_NAMES[m] for _ in categories for m in metrics]) + " \\\\",
        "\\midrule",
    ]
    for method, row in table.iterrows():
        cells = []
        for col in table.columns:
            text = _fmt(col[1], row[col])
            cells.append(f"\\textbf{{{text}}}" if np.isclose(row[col], best[col]) else text)
        lines.append(" & ".join([latex_escape(names.get(method, method))] + cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


def latex_escape(text: str) -> str:
    for char in "&%$#_{}":
        text = text.replace(char, "\\" + char)
    return text.replace("^", "\\^{}")
