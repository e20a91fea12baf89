"""The paper's result tables: per-cloud error statistics, category aggregation, CSV and booktabs LaTeX."""

from __future__ import annotations

from collections.abc import Sequence

import numpy as np
import pandas as pd

from refinenet.metrics import STAT_FIELDS, ErrorStats, average_over_categories, pcpnet_category, synthetic_category

#: Column order of the paper's synthetic tables (table:synthetic_result).
SYNTHETIC_ORDER = ("BigNoise", "SharpFeature", "RichFeature", "SmoothSurface")
#: Display names of the methods, in the paper's row order.
METHOD_NAMES = {"pca": "PCA", "jet": "Jet", "mfps": "MFPS", "simple_mfps": "simple MFPS", "refinenet": "Refine-Net"}
METRIC_NAMES = {"mean": "mean", "rmse": "rmse", "pgp5": "PGP5", "pgp10": "PGP10"}
HIGHER_IS_BETTER = {"pgp5", "pgp10"}


def stats_row(method: str, category: str, name: str, stats: ErrorStats) -> dict[str, object]:
    """One row of the per-cloud statistics table."""
    return {"method": method, "category": category, "cloud": name, **stats.to_dict(), **stats.summary()}


def category_order(categories: Sequence[str]) -> list[str]:
    """The paper's column order for known categories, then any others in the order given."""
    known = [c for c in SYNTHETIC_ORDER if c in categories]
    return known + [c for c in dict.fromkeys(categories) if c not in SYNTHETIC_ORDER]


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


def to_csv_frame(table: pd.DataFrame) -> pd.DataFrame:
    """Flat columns `category/metric` and display method names, rounded as in the paper."""
    flat = table.copy()
    flat.columns = [f"{c}/{m}" for c, m in table.columns]
    flat.index = [METHOD_NAMES.get(m, m) for m in table.index]
    flat.index.name = "method"
    return flat


def _fmt(metric: str, value: float) -> str:
    return f"{value:.3f}".lstrip("0") if metric in HIGHER_IS_BETTER else f"{value:.2f}"


def to_latex(table: pd.DataFrame, caption: str, label: str) -> str:
    """A booktabs table like the paper's: two-level header, best value per column in bold."""
    categories = list(dict.fromkeys(c for c, _ in table.columns))
    metrics = list(dict.fromkeys(m for _, m in table.columns))
    best = {col: (table[col].max() if col[1] in HIGHER_IS_BETTER else table[col].min()) for col in table.columns}
    width = len(metrics)
    spec = "l" + "c" * width * len(categories)
    rules = " ".join(f"\\cmidrule(lr){{{2 + i * width}-{1 + (i + 1) * width}}}" for i in range(len(categories)))
    lines = [
        "\\begin{table}[t]", "\\centering", f"\\caption{{{_escape(caption)}}}", f"\\label{{{label}}}",
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
        lines.append(" & ".join([_escape(METHOD_NAMES.get(method, method))] + cells) + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    return "\n".join(lines)


def _escape(text: str) -> str:
    for char in "&%$#_{}":
        text = text.replace(char, "\\" + char)
    return text


def caption(title: str, params: dict, methods: Sequence[str]) -> str:
    """A caption naming the profile, the data and the settings of every method in the table."""
    d, b, m = params["data"], params["baselines"], params.get("mfps", {})
    parts = [
        f"{title}, {params['evaluation']['protocol']} protocol.",
        f"Profile {params['profile']}; data: {d['source']}" + (f" ({d['path']})" if d["path"] else "")
        + f", {d['n_points']} points per cloud.",
    ]
    if {"pca", "jet"} & set(methods):
        parts.append(f"PCA/Jet K = {b['pca_k']}/{b['jet_k']} ({b['big_noise_k']} for BigNoise), jet degree "
                     f"{b['jet_degree']}.")
    if {"mfps", "simple_mfps"} & set(methods):
        parts.append(f"MFPS K = {{{', '.join(map(str, m['scales']))}}}, R = {m['trials']}, "
                     f"theta_t = {m['theta_t']} deg, |A| <= {m['a_max']}, eta = {m['eta']}.")
    if "refinenet" in methods:
        f, n, t, pa = params["features"], params["network"], params["training"], params["patches"]
        n_normals = len(f["sigma_s"]) * len(f["sigma_r"]) + f["include_initial"]
        parts.append(
            f"Refine-Net: {n['preset']} network, features {n['features']}, connection {n['connection']}, "
            f"Kc = {params['clustering']['n_clusters']}, X = {n_normals}"
            f", r_f = {f['r_f']}, {f['frame_mode']} frames, {pa['mode']} patches; {t['optimizer']} lr {t['lr']}, "
            f"batch {t['batch_size']}, <= {t['max_epochs']} epochs (patience {t['patience']}), {t['loss']} loss"
            + (f", at most {t['max_train_points_per_cloud']} training points per cloud"
               if t["max_train_points_per_cloud"] else "") + ".")
    return " ".join(parts)
