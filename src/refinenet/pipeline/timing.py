"""[P] Table time: seconds per 1k points of MFPS, the feature cache and the network, from the run's own job
benchmark files, and the network's parameters from the model definition.

Snakemake writes one benchmark file per job (`JOB_BENCHMARK`; DVC runs the same rules through the bridge). A job's
seconds are its whole wall time, the process start (Python, numpy, torch imports: about 1-2 s) included, so small
clouds overstate the cost per point; the paper's 100k-point clouds make the start negligible. Timings differ from
run to run: this table is the one report two runs do not reproduce bit for bit.
"""

from __future__ import annotations

import json
from collections.abc import Sequence
from pathlib import Path

import pandas as pd

from refinenet.atomic import atomic_path, write_text
from refinenet.config import FULL
from refinenet.errors import InputError
from refinenet.evaluation.table import latex_escape

#: The timed steps, in the order a cloud passes them: row name -> the step of its jobs' benchmark files
#: (`JOB_BENCHMARK`: MFPS, and full's instances of the per-variant steps).
TIMED = {"MFPS": "mfps", "feature cache": f"features/{FULL}", "network": f"inference/{FULL}"}
TOTAL = "Refine-Net in total"
#: The rows that the network's parameters belong to.
NETWORK_ROWS = ("network", TOTAL)
PER_1K = "s per 1k points"


def read_benchmark(path: str | Path) -> dict[str, float]:
    """A job's wall seconds and peak memory (MB) from its Snakemake benchmark file."""
    path = Path(path)
    if not path.is_file():
        raise InputError(path, "job benchmark file not found (outputs restored by dvc checkout or pull carry no "
                               "timings: rerun the steps to time them)")
    try:
        bench = pd.read_csv(path, sep="\t")
        return {"seconds": float(bench["s"].iloc[0]), "rss_mb": float(bench["max_rss"].iloc[0])}
    except (KeyError, IndexError, ValueError, pd.errors.ParserError) as err:
        raise InputError(path, f"not a Snakemake benchmark file ({err})") from None


def time_table(jobs: pd.DataFrame, per_cluster: int, n_clusters: int) -> pd.DataFrame:
    """One row per timed step and the total: seconds per 1k points (all jobs' seconds over all their points, so
    large clouds weigh by their size), jobs, and the network's parameters per cluster and for all clusters."""
    rows = []
    for name in TIMED:
        own = jobs[jobs["step"] == name]
        rows.append({"step": name, PER_1K: 1000 * own["seconds"].sum() / own["points"].sum(), "jobs": len(own)})
    table = pd.DataFrame(rows).set_index("step")
    table.loc[TOTAL] = [table[PER_1K].sum(), table["jobs"].sum()]
    table["jobs"] = table["jobs"].astype(int)
    for column, count in (("parameters per cluster", per_cluster), ("parameters", per_cluster * n_clusters)):
        table[column] = pd.array([count if step in NETWORK_ROWS else None for step in table.index], dtype="Int64")
    return table


def write_time_table(jobs: pd.DataFrame, table: pd.DataFrame, caption: str, label: str,
                     paths: dict[str, str]) -> None:
    """paths: csv, tex (booktabs), per_cloud (every timed job), metrics (the seconds per 1k points and the total
    parameters, for `dvc metrics show`)."""
    with atomic_path(paths["per_cloud"]) as tmp:
        jobs.to_csv(tmp, index=False, float_format="%.6g")
    with atomic_path(paths["csv"]) as tmp:
        table.to_csv(tmp, float_format="%.4f")
    record = {PER_1K: {step: round(float(v), 4) for step, v in table[PER_1K].items()},
              "parameters": int(table.loc[TOTAL, "parameters"])}
    write_text(paths["metrics"], json.dumps(record, indent=2) + "\n")
    header = ["Step", PER_1K, "jobs", "parameters per cluster", "parameters"]
    lines = ["\\begin{table}[t]", "\\centering", f"\\caption{{{latex_escape(caption)}}}", f"\\label{{{label}}}",
             "\\begin{tabular}{lrrrr}", "\\toprule", " & ".join(header) + " \\\\", "\\midrule"]
    for step, row in table.iterrows():
        if step == TOTAL:
            lines.append("\\midrule")
        counts = ["" if pd.isna(row[c]) else f"{int(row[c]):,}" for c in ("parameters per cluster", "parameters")]
        lines.append(" & ".join([latex_escape(str(step)), f"{row[PER_1K]:.3f}", str(int(row['jobs'])), *counts])
                     + " \\\\")
    lines += ["\\bottomrule", "\\end{tabular}", "\\end{table}", ""]
    write_text(paths["tex"], "\n".join(lines))


def job_rows(clouds: Sequence[tuple[str, int, int, int]], pattern: str) -> pd.DataFrame:
    """Every timed job of the given (cloud key, points, featured points, refined points) tuples, from the benchmark
    files `pattern` names (`{step}` and `{cloud}` open: `JOB_BENCHMARK`). MFPS runs on every point, the feature
    cache on a PCPNet shape's `.pidx` points, the network on `inference.points` of those
    (`data.clouds.scored_points`)."""
    rows = [{"cloud": key, "step": name, "points": points, **read_benchmark(pattern.format(step=step, cloud=key))}
            for key, *sizes in clouds for (name, step), points in zip(TIMED.items(), sizes, strict=True)]
    return pd.DataFrame(rows)
