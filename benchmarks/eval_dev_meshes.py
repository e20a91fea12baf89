"""PCA, Jet, MFPS, simple MFPS and Refine-Net (the shipped networks, as `refinenet normals` runs them) on the
shared development meshes, per mesh and per category.

Answers the project requirement: "On the shared development meshes (../shared/data/meshes/dev, sampled with
100k points at 0.1% noise) MFPS must have a lower mean angular error than PCA and Jet on the sharp category;
report all categories."

Every mesh of ../shared/data/meshes/dev/<sharp|smooth|rich>/ is sampled area-uniformly (ground truth: the
normal of the face a point lies on) and perturbed with Gaussian noise of 0.1% of the bounding-box diagonal;
both seeds come from `derive_seed(2022, ...)` and the mesh's category/file name. Methods: `pca_normals`
(k = 100), `jet_normals` (k = 100, degree 2), full MFPS (`params.yaml `mfps`, no profile: K = {50, 100, 150}, R = 150,
theta_t = 60, eta = code) and simple MFPS (the same with `simple`); Refine-Net is `cli.estimate.estimate_normals`
with the shipped release (src/refinenet/shipped: its own MFPS settings, l_d from the point spacing), which never saw
these meshes. Errors are unoriented angles;
categories follow the synthetic protocol (`refinenet.evaluation.table.aggregate`: pooled mean and PGP, point-weighted
RMSE, unweighted Average). "Near edges" are the points whose 10 nearest clean-sample neighbours include a
ground-truth normal more than 30 degrees away.

    python benchmarks/eval_dev_meshes.py [--points 100000] [--noise 0.1] [--threads 2]

Writes benchmarks/results/dev_meshes.json and dev_meshes.md. The CPU is shared with other jobs: wall and
CPU seconds are recorded for every run (one run each), with the load average at start and end.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from dataclasses import replace
from pathlib import Path

import numpy as np
import pandas as pd
from bench_mfps import machine, near_edges

from refinenet import config as params_lib
from refinenet.atomic import write_text
from refinenet.cli.estimate import estimate_normals
from refinenet.data.meshes import MESH_SUFFIXES, read_mesh, sample_mesh
from refinenet.data.noise import add_gaussian_noise, derive_seed
from refinenet.estimators.baselines import jet_normals, pca_normals
from refinenet.estimators.mfps import mfps_normals
from refinenet.evaluation.metrics import ErrorStats, unoriented_angles
from refinenet.evaluation.table import METHOD_NAMES, aggregate, stats_row, to_csv_frame
from refinenet.network.release import load_release

#: MFPS as params.yaml sets it (its own values, no profile): the paper's synthetic settings.
MFPS = params_lib.load(Path(__file__).resolve().parents[1] / "params.yaml", apply_profile=False).mfps

RESULTS = Path(__file__).parent / "results"
DEV = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "meshes" / "dev"
CATEGORIES = ("sharp", "smooth", "rich")
GLOBAL_SEED = 2022
METRICS = ("mean", "rmse", "pgp5", "pgp10")
CONFIGS = {"mfps": MFPS, "simple_mfps": replace(MFPS, simple=True)}


def dev_meshes(root: Path) -> list[tuple[str, Path]]:
    """(category, path) of every dev mesh, categories in the order of CATEGORIES, files sorted by name."""
    if not root.is_dir():
        sys.exit(f"eval_dev_meshes: the development meshes are missing: {root.resolve()} does not exist "
                 "(expected ../shared/data/meshes/dev/<sharp|smooth|rich>/ relative to the repository root)")
    meshes = [(c, p) for c in CATEGORIES for p in sorted((root / c).glob("*")) if p.suffix.lower() in MESH_SUFFIXES]
    if not meshes:
        sys.exit(f"eval_dev_meshes: no .off/.obj/.ply meshes under {root.resolve()}/<sharp|smooth|rich>/")
    return meshes


def timed(fn: Callable[[], np.ndarray]) -> tuple[np.ndarray, float, float]:
    """Result, wall seconds and CPU seconds (all threads of this process) of one call."""
    start, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return result, time.perf_counter() - start, time.process_time() - cpu


def evaluate_mesh(category: str, path: Path, n_points: int, noise: float, threads: int, release) -> list[dict]:
    """One per-cloud statistics row per method, with timings, near-edge errors and MFPS step statistics."""
    key = f"{category}/{path.name}"
    sample_seed = derive_seed(GLOBAL_SEED, "sample", "dev", key)
    noise_seed = derive_seed(GLOBAL_SEED, "noise", "dev", key, noise)
    clean, truth = sample_mesh(*read_mesh(path), n_points, np.random.default_rng(sample_seed))
    points = add_gaussian_noise(clean, noise, noise_seed)
    near = near_edges(clean, truth)
    methods: dict[str, Callable[[], np.ndarray]] = {
        "pca": lambda: pca_normals(points, 100),
        "jet": lambda: jet_normals(points, 100, 2),
    }
    mfps_stats: dict[str, dict] = {name: {} for name in CONFIGS}
    for name, config in CONFIGS.items():
        methods[name] = lambda c=config, s=mfps_stats[name]: mfps_normals(points, c, workers=threads, stats=s)
    methods["refinenet"] = lambda: estimate_normals(points, release, "refinenet", workers=threads)
    rows = []
    for method, fn in methods.items():
        normals, wall, cpu = timed(fn)
        angles = unoriented_angles(normals, truth)
        row = stats_row(method, category, path.stem, ErrorStats.from_angles(angles))
        row.update(seconds=wall, cpu_seconds=cpu, near_edge_points=int(near.sum()),
                   near_edge_sum_deg=float(angles[near].sum()),
                   mean_near_edges=float(angles[near].mean()) if near.any() else float("nan"),
                   mean_away_from_edges=float(angles[~near].mean()) if (~near).any() else float("nan"),
                   sample_seed=sample_seed, noise_seed=noise_seed)
        if method in mfps_stats:
            row["candidates"] = mfps_stats[method]["candidates"]
        rows.append(row)
        print(f"{key:28s} {METHOD_NAMES[method]:12s} mean {row['mean']:6.2f}  near edges {row['mean_near_edges']:6.2f}"
              f"  {wall:6.1f} s", flush=True)
    return rows


def near_edge_means(per_cloud: pd.DataFrame, category: str) -> dict[str, float]:
    """Pooled mean error over the near-edge points of one category, per method."""
    group = per_cloud[per_cloud["category"] == category].groupby("method", sort=False)
    return {m: float(g["near_edge_sum_deg"].sum() / g["near_edge_points"].sum()) for m, g in group}


def markdown_table(frame: pd.DataFrame, formats: dict[str, str]) -> list[str]:
    """A GitHub table of a DataFrame (index as the first column); `formats` maps columns to format specs."""
    cols = [frame.index.name or "", *frame.columns]
    lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "---|" * len(cols)]
    for index, row in frame.iterrows():
        cells = ["" if isinstance(row[c], float) and np.isnan(row[c]) else format(row[c], formats.get(c, ""))
                 for c in frame.columns]
        lines.append("| " + " | ".join([str(index), *cells]) + " |")
    return lines


def verdict(category_table: pd.DataFrame) -> tuple[str, bool]:
    mean = category_table[("sharp", "mean")]
    met = bool(mean["mfps"] < mean["pca"] and mean["mfps"] < mean["jet"])
    return (f"MFPS mean error on sharp: {mean['mfps']:.2f} vs PCA {mean['pca']:.2f}, Jet {mean['jet']:.2f}: "
            f"{'met' if met else 'not met'}"), met


def markdown(record: dict, per_cloud: pd.DataFrame, category_table: pd.DataFrame) -> str:
    info = record["machine"]
    lines = [
        "# Normal estimation on the shared development meshes",
        "",
        f"Requirement: {record['requirement']}",
        "",
        f"**{record['verdict']}**",
        "",
        f"Every mesh of `../shared/data/meshes/dev` is sampled with {record['points']:,} area-uniform points "
        f"(ground truth: face normals) and perturbed with Gaussian noise of {record['noise_percent']}% of the "
        f"bounding-box diagonal; seeds from `derive_seed({GLOBAL_SEED}, ...)` (recorded in dev_meshes.json). "
        "PCA: k = 100; Jet: k = 100, degree 2; MFPS: K = {50, 100, 150}, R = 150, theta_t = 60 deg, |A| <= 2, "
        "eta = code; simple MFPS: the same without the anisotropic selection; Refine-Net: the networks shipped "
        f"with the package (profile {record['release']['profile']}, trained on the procedural shapes only), run as "
        "`refinenet normals` runs them. Errors are unoriented angles in degrees. Generated by "
        "`benchmarks/eval_dev_meshes.py`.",
        "",
        "## Per category",
        "",
        "Synthetic protocol: mean and PGP pooled over all points of a category, RMSE the point-weighted mean of "
        "per-mesh RMSE; Average is the unweighted mean of the categories.",
        "",
    ]
    flat = to_csv_frame(category_table)
    lines += markdown_table(flat, {c: ".3f" if c.endswith("pgp5") or c.endswith("pgp10") else ".2f"
                                   for c in flat.columns})
    near = record["sharp_near_edges"]
    lines += [
        "",
        f"Sharp category near edges ({near['points']:,} of {near['total_points']:,} points, "
        f"{near['points'] / near['total_points']:.1%}; points whose 10 nearest clean-sample neighbours include "
        "a ground-truth normal more than 30 degrees away), pooled mean error: "
        + ", ".join(f"{METHOD_NAMES[m]} {v:.2f}" for m, v in near["mean"].items()) + ".",
        "",
        "## Per mesh",
        "",
        "Seconds are the wall time of one run (CPU seconds in dev_meshes.json); *mean near edges* is blank where a "
        "mesh has no near-edge points; *candidates* is the fraction of points MFPS classified as near-feature by "
        "the surface-variation knee rule (the others keep PCA k = 50).",
        "",
    ]
    table = per_cloud.assign(method=per_cloud["method"].map(METHOD_NAMES),
                             candidates=per_cloud["candidates"] / per_cloud["n"]).set_index("cloud")
    table.index.name = "mesh"
    columns = ["category", "method", *METRICS, "seconds", "mean_near_edges", "candidates"]
    formats = {"mean": ".2f", "rmse": ".2f", "pgp5": ".3f", "pgp10": ".3f", "seconds": ".1f",
               "mean_near_edges": ".2f", "candidates": ".3f"}
    lines += markdown_table(table[columns].rename(columns={"mean_near_edges": "mean near edges"}),
                            {**formats, "mean near edges": formats["mean_near_edges"]})
    load = record["load_average_1min"]
    total = per_cloud.groupby("method", sort=False)["seconds"].sum()
    lines += [
        "",
        "Total wall seconds per method: " + ", ".join(f"{METHOD_NAMES[m]} {s:.1f}" for m, s in total.items())
        + f"; whole run {record['wall_s']:.0f} s.",
        "",
        "## Machine",
        "",
        f"{info['cpu']}, {info['cores']} cores ({info['threads']} MFPS threads), {info['memory_gb']:.0f} GB, "
        f"{info['platform']}, Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. "
        f"Load average (1 min) at start {load[0]:.2f}, at end {load[1]:.2f}: the CPU is shared with other jobs, "
        f"so a load above {info['cores']} means this run did not have every core to itself.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--noise", type=float, default=0.1, help="percent of the bounding-box diagonal")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--meshes", type=Path, default=DEV)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    meshes = dev_meshes(args.meshes)
    release = load_release()
    load_start, start = os.getloadavg()[0], time.perf_counter()
    rows = [row for category, path in meshes
            for row in evaluate_mesh(category, path, args.points, args.noise, args.threads, release)]
    per_cloud = pd.DataFrame(rows)
    category_table = aggregate(per_cloud, "synthetic", METRICS)
    line, met = verdict(category_table)
    sharp = per_cloud[(per_cloud["category"] == "sharp") & (per_cloud["method"] == "pca")]
    record = {
        "requirement": " ".join(__doc__.split('"')[1].split()),
        "verdict": line, "met": met,
        "points": args.points, "noise_percent": args.noise, "global_seed": GLOBAL_SEED,
        "meshes_dir": str(args.meshes.resolve()),
        "configs": {name: {"scales": list(c.scales), "trials": c.trials, "theta_t": c.theta_t, "a_max": c.a_max,
                           "eta": c.eta, "simple": c.simple, "seed": c.seed} for name, c in CONFIGS.items()},
        "per_category": {METHOD_NAMES[m]: {f"{c}/{k}": float(v) for (c, k), v in row.items()}
                         for m, row in category_table.iterrows()},
        "sharp_near_edges": {"points": int(sharp["near_edge_points"].sum()), "total_points": int(sharp["n"].sum()),
                             "mean": near_edge_means(per_cloud, "sharp")},
        "per_mesh": json.loads(per_cloud.to_json(orient="records")),
        "release": {k: release.card[k] for k in ("profile", "params_fingerprint")},
        "wall_s": time.perf_counter() - start,
        "load_average_1min": [load_start, os.getloadavg()[0]],
        "machine": machine(args.threads),
    }
    args.out.mkdir(parents=True, exist_ok=True)
    write_text(args.out / "dev_meshes.json", json.dumps(record, indent=2) + "\n")
    write_text(args.out / "dev_meshes.md", markdown(record, per_cloud, category_table))
    print(to_csv_frame(category_table).round(3).to_string())
    print(line)


if __name__ == "__main__":
    main()
