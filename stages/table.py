"""Evaluate estimated normals against ground truth and write a results table (CSV, LaTeX) and metrics JSON."""

import argparse
import json

import numpy as np
import pandas as pd

from refinenet import stage
from refinenet.atomic import atomic_path, write_text
from refinenet.errors import InputError
from refinenet.io import read_cloud, read_normals
from refinenet.metrics import ErrorStats, unoriented_angles
from refinenet.tables import aggregate, stats_row, to_csv_frame, to_latex


def per_cloud(methods: list[str], clouds: list[str], normals: list[str], protocol: str) -> pd.DataFrame:
    """Error statistics of every (method, cloud), on the `.pidx` subset under the PCPNet protocol."""
    if len(normals) != len(methods) * len(clouds):
        raise InputError(normals[0] if normals else "--normals", "expected one normals file per method and cloud")
    rows = []
    for ci, cloud_path in enumerate(clouds):
        cloud = read_cloud(cloud_path)
        subset = np.asarray(cloud.meta["pidx"]) if protocol == "pcpnet" and "pidx" in cloud.meta else slice(None)
        for mi, method in enumerate(methods):
            estimated = read_normals(normals[mi * len(clouds) + ci], len(cloud))
            stats = ErrorStats.from_angles(unoriented_angles(estimated[subset], cloud.normals[subset]))
            rows.append(stats_row(method, cloud.meta["category"], cloud.meta["name"], stats))
    return pd.DataFrame(rows)


def main(args: argparse.Namespace) -> None:
    stats = per_cloud(args.methods, args.clouds, args.normals, args.protocol)
    table = aggregate(stats, args.protocol, args.metrics)
    csv = to_csv_frame(table)
    with atomic_path(args.per_cloud) as tmp:
        stats.to_csv(tmp, index=False, float_format="%.6g")
    with atomic_path(args.csv) as tmp:
        csv.to_csv(tmp, float_format="%.4f")
    write_text(args.tex, to_latex(table, args.caption, args.label))
    write_text(args.metrics_json, json.dumps(csv.to_dict(orient="index"), indent=2) + "\n")


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--methods", nargs="+", required=True)
    parser.add_argument("--clouds", nargs="+", required=True, help="test cloud records (.npz)")
    parser.add_argument("--normals", nargs="+", required=True, help="estimated normals, method-major order")
    parser.add_argument("--protocol", choices=["synthetic", "pcpnet"], required=True)
    parser.add_argument("--metrics", nargs="+", default=["mean", "rmse"], choices=["mean", "rmse", "pgp5", "pgp10"])
    parser.add_argument("--caption", required=True)
    parser.add_argument("--label", required=True)
    parser.add_argument("--csv", required=True)
    parser.add_argument("--tex", required=True)
    parser.add_argument("--per-cloud", required=True)
    parser.add_argument("--metrics-json", required=True)
    stage.run(parser, main)
