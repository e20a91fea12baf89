"""Refine-Net (the shipped networks, as `refinenet normals` runs them) against PCA (best of k = 30, 50, 100), Jet
and MFPS on the shared development meshes, at the synthetic benchmark's test noise levels.

Answers the accuracy requirement: "Evaluate the trained networks on the shared development meshes (100k points,
the paper's test noise levels per category) against PCA (best of k = 30, 50, 100), Jet and MFPS"; the networks
must be below all three in every category. It also keeps the older check that MFPS beats PCA and Jet on the sharp
meshes.

Every mesh of ../shared/data/meshes/dev/<sharp|smooth|rich>/ is sampled area-uniformly (ground truth: the normal
of the face a point lies on) and perturbed with Gaussian noise in percent of the bounding-box diagonal. The
categories are the synthetic benchmark's: a sharp mesh at SharpFeature's levels, a smooth one at SmoothSurface's,
a rich one at RichFeature's (params.yaml `noise.test`), and every mesh at BigNoise's. Seeds come from
`derive_seed(2022, ...)`, the mesh and the level. Methods: `pca_normals` with k = 30, 50 and 100, and per category
the k of lowest mean error ("PCA (best k)"); `jet_normals` with params.yaml's `baselines` (k = 100, 200 on
BigNoise, degree 2); MFPS with params.yaml's `mfps` (no profile: the paper's synthetic settings); Refine-Net is
`cli.estimate.estimate_normals` with the shipped release (its own MFPS, l_d from the point spacing, the default
`--precision auto`), which never saw these meshes. Errors are unoriented angles; categories follow the synthetic
protocol (`refinenet.evaluation.table.aggregate`: pooled mean and PGP, point-weighted RMSE, unweighted Average).
"Near edges" are the points whose 10 nearest clean-sample neighbours include a ground-truth normal more than 30
degrees away.

    python benchmarks/eval_dev_meshes.py [--points 100000] [--threads 2] [--methods refinenet]
                                         [--release FOLDER --out DIR]

`--methods` reruns only some methods (after a change to Refine-Net, say) and keeps the other methods' rows from
the committed run (`--reuse`), whose clouds are the same: every cloud's seeds derive from the mesh and the level.

`--release` evaluates another run's exported networks (its `src/refinenet/shipped` after `snakemake -j2 release`,
e.g. a candidate setting's) in place of the shipped ones; its results go under `--out`, a folder outside
benchmarks/results, which holds the shipped networks' evaluation only.

Writes benchmarks/results/dev_meshes.json and dev_meshes.md (or under `--out`). Wall and CPU seconds are recorded
for every run (one run each), with the load average at start and end. Each finished cloud's rows are appended to
dev_meshes.partial.jsonl beside them, so that a killed run (the whole takes hours on 2 cores) resumes where it
stopped when started again with the same settings; the file is removed once the results are written.
"""

from __future__ import annotations

import argparse
import json
import os
import sys
import time
from collections.abc import Callable
from pathlib import Path

import numpy as np
import pandas as pd
from bench_mfps import machine, near_edges
from machine import shipped_networks, write_results

from refinenet import config as params_lib
from refinenet.cli.estimate import estimate_normals
from refinenet.data.meshes import MESH_SUFFIXES, read_mesh, sample_mesh
from refinenet.data.noise import add_gaussian_noise, derive_seed
from refinenet.estimators.baselines import jet_normals, pca_normals
from refinenet.estimators.mfps import mfps_normals
from refinenet.evaluation.metrics import ErrorStats, unoriented_angles
from refinenet.evaluation.table import METHOD_NAMES, aggregate, stats_row, to_csv_frame
from refinenet.network.devices import resolve_device, resolve_precision
from refinenet.network.release import SHIPPED, load_release

#: params.yaml as written (no profile): the paper's synthetic settings of the baselines, MFPS and the noise.
PARAMS = params_lib.load(Path(__file__).resolve().parents[1] / "params.yaml", apply_profile=False)

RESULTS = Path(__file__).parent / "results"
#: The results' file names: STEM.json and STEM.md.
STEM = "dev_meshes"
#: FeatureConfig's inputs beyond the paper, named in the report when a release uses them.
BEYOND_PAPER_INPUTS = ("pca_k", "jet_k", "smooth_jet")
DEV = Path(__file__).resolve().parents[1] / ".." / "shared" / "data" / "meshes" / "dev"
#: Development mesh folder -> the synthetic category whose noise levels it gets (every mesh also gets BigNoise's).
FOLDERS = {"sharp": "SharpFeature", "smooth": "SmoothSurface", "rich": "RichFeature"}
BIG_NOISE = "BigNoise"
GLOBAL_SEED = 2022
METRICS = ("mean", "rmse", "pgp5", "pgp10")
PCA_KS = (30, 50, 100)
PCA_BEST = "pca_best"
NAMES = {**METHOD_NAMES, **{f"pca{k}": f"PCA k = {k}" for k in PCA_KS}, PCA_BEST: "PCA (best k)"}
#: The methods Refine-Net must beat in every category.
RIVALS = (PCA_BEST, "jet", "mfps")
#: Every method run on each cloud.
METHODS = (*(f"pca{k}" for k in PCA_KS), "jet", "mfps", "refinenet")


def dev_meshes(root: Path) -> list[tuple[str, Path]]:
    """(folder, path) of every dev mesh, folders in the order of FOLDERS, files sorted by name."""
    if not root.is_dir():
        sys.exit(f"eval_dev_meshes: the development meshes are missing: {root.resolve()} does not exist "
                 "(expected ../shared/data/meshes/dev/<sharp|smooth|rich>/ relative to the repository root)")
    meshes = [(f, p) for f in FOLDERS for p in sorted((root / f).glob("*")) if p.suffix.lower() in MESH_SUFFIXES]
    if not meshes:
        sys.exit(f"eval_dev_meshes: no .off/.obj/.ply meshes under {root.resolve()}/<sharp|smooth|rich>/")
    return meshes


def clouds(meshes: list[tuple[str, Path]]) -> list[tuple[str, str, Path, float]]:
    """(category, mesh key, path, noise percent) of every test cloud: each mesh at its folder's category's levels,
    then every mesh at BigNoise's."""
    test = PARAMS.noise.test
    own = [(FOLDERS[f], f"{f}/{p.name}", p, level) for f, p in meshes for level in test[FOLDERS[f]]]
    return own + [(BIG_NOISE, f"{f}/{p.name}", p, level) for f, p in meshes for level in test[BIG_NOISE]]


def timed(fn: Callable[[], np.ndarray]) -> tuple[np.ndarray, float, float]:
    """Result, wall seconds and CPU seconds (all threads of this process) of one call."""
    start, cpu = time.perf_counter(), time.process_time()
    result = fn()
    return result, time.perf_counter() - start, time.process_time() - cpu


def noisy_sample(key: str, path: Path, noise: float, n_points: int) -> tuple[np.ndarray, ...]:
    """Clean points, their true normals, the noisy points, and both seeds of one test cloud of mesh `key`."""
    sample_seed = derive_seed(GLOBAL_SEED, "sample", "dev", key)
    noise_seed = derive_seed(GLOBAL_SEED, "noise", "dev", key, noise)
    clean, truth = sample_mesh(*read_mesh(path), n_points, np.random.default_rng(sample_seed))
    return clean, truth, add_gaussian_noise(clean, noise, noise_seed), sample_seed, noise_seed


def evaluate_cloud(category: str, key: str, path: Path, noise: float, n_points: int, threads: int,
                   release, only: tuple[str, ...] = METHODS) -> list[dict]:
    """One per-cloud statistics row per method of `only`, with timings and near-edge errors."""
    clean, truth, points, sample_seed, noise_seed = noisy_sample(key, path, noise, n_points)
    near = near_edges(clean, truth)
    b = PARAMS.baselines
    jet_k = b.big_noise_k if category == BIG_NOISE else b.jet_k
    methods: dict[str, Callable[[], np.ndarray]] = {
        **{f"pca{k}": lambda k=k: pca_normals(points, k) for k in PCA_KS},
        "jet": lambda: jet_normals(points, jet_k, b.jet_degree),
        "mfps": lambda: mfps_normals(points, PARAMS.mfps, workers=threads),
        "refinenet": lambda: estimate_normals(points, release, "refinenet", workers=threads),
    }
    rows = []
    for method in only:
        normals, wall, cpu = timed(methods[method])
        angles = unoriented_angles(normals, truth)
        row = stats_row(method, category, f"{Path(key).stem}_n{noise}", ErrorStats.from_angles(angles))
        row.update(mesh=Path(key).stem, noise=noise, seconds=wall, cpu_seconds=cpu,
                   near_edge_points=int(near.sum()), near_edge_sum_deg=float(angles[near].sum()),
                   sample_seed=sample_seed, noise_seed=noise_seed)
        rows.append(row)
        print(f"{category:13s} {key:24s} {noise:4.2f}% {NAMES[method]:12s} mean {row['mean']:6.2f}  {wall:6.1f} s",
              flush=True)
    return rows


def finished_clouds(path: Path, settings: dict) -> dict[tuple, list[dict]]:
    """The rows of every cloud that an interrupted run with the same `settings` finished (`path`, one JSON line per
    cloud; a line cut off by the kill is ignored)."""
    done = {}
    for line in path.read_text().splitlines() if path.is_file() else ():
        try:
            entry = json.loads(line)
        except json.JSONDecodeError:
            continue
        if entry["settings"] == settings:
            done[tuple(entry["cloud"])] = entry["rows"]
    return done


def keep_finished(path: Path, settings: dict, cloud: tuple, rows: list[dict]) -> None:
    """Append one finished cloud's rows to `path`, on disk before the next cloud starts. Each entry starts on a
    line of its own, also after a line that a kill cut off."""
    with path.open("a") as file:
        file.write("\n" + json.dumps({"settings": settings, "cloud": cloud, "rows": rows},
                                     default=lambda value: value.item()) + "\n")
        file.flush()
        os.fsync(file.fileno())


def table_categories(table: pd.DataFrame) -> list[str]:
    """The categories of a category table (`aggregate`), in its column order, without the Average."""
    return [c for c in dict.fromkeys(table.columns.get_level_values(0)) if c != "Average"]


def with_best_pca(table: pd.DataFrame) -> tuple[pd.DataFrame, dict[str, int]]:
    """The category table with a "PCA (best k)" row: per category the k of lowest mean error (all its metrics),
    the Average the mean over the categories; and the k chosen per category."""
    categories = table_categories(table)
    best = {c: min(PCA_KS, key=lambda k: table.loc[f"pca{k}", (c, "mean")]) for c in categories}
    row = {(c, m): table.loc[f"pca{best[c]}", (c, m)] for c in categories for m in METRICS}
    row |= {("Average", m): float(np.mean([row[(c, m)] for c in categories])) for m in METRICS}
    table = pd.concat([table, pd.DataFrame([row], index=[PCA_BEST], columns=table.columns)])
    return table, best


def verdicts(table: pd.DataFrame) -> dict[str, dict[str, object]]:
    """Per category: Refine-Net's mean error, each rival's, and whether Refine-Net is below all of them."""
    categories = table_categories(table)
    out = {}
    for c in categories:
        ours, rivals = table.loc["refinenet", (c, "mean")], {r: table.loc[r, (c, "mean")] for r in RIVALS}
        out[c] = {"refinenet": float(ours), **{r: float(v) for r, v in rivals.items()},
                  "met": bool(all(ours < v for v in rivals.values()))}
    return out


def markdown_table(frame: pd.DataFrame, formats: dict[str, str]) -> list[str]:
    """A GitHub table of a DataFrame (index as the first column); `formats` maps columns to format specs."""
    cols = [frame.index.name or "", *frame.columns]
    lines = ["| " + " | ".join(map(str, cols)) + " |", "|" + "---|" * len(cols)]
    for index, row in frame.iterrows():
        cells = ["" if isinstance(row[c], float) and np.isnan(row[c]) else format(row[c], formats.get(c, ""))
                 for c in frame.columns]
        lines.append("| " + " | ".join([str(index), *cells]) + " |")
    return lines


def markdown(record: dict, per_cloud: pd.DataFrame, category_table: pd.DataFrame) -> str:
    info, levels = record["machine"], PARAMS.noise.test
    per_category = record["verdicts"]
    met = [c for c, v in per_category.items() if v["met"]]
    lines = [
        "# Normal estimation on the shared development meshes",
        "",
        f"Requirement: {record['requirement']}",
        "",
        f"**Refine-Net below PCA (best k), Jet and MFPS in {len(met)} of {len(per_category)} categories"
        + (f" ({', '.join(met)})" if met else "") + ".** " + record["mfps_verdict"],
        "",
        f"Every mesh of `../shared/data/meshes/dev` is sampled with {record['points']:,} area-uniform points "
        "(ground truth: face normals) and perturbed with Gaussian noise in percent of the bounding-box diagonal: "
        + "; ".join(f"the {folder} meshes at {category}'s levels {', '.join(map(str, levels[category]))}"
                    for folder, category in FOLDERS.items())
        + f"; and every mesh at {BIG_NOISE}'s levels {', '.join(map(str, levels[BIG_NOISE]))}. Seeds from "
        f"`derive_seed({GLOBAL_SEED}, ...)` (in {STEM}.json). PCA: k = {', '.join(map(str, PCA_KS))} and per "
        "category the k of lowest mean error (chosen: "
        + ", ".join(f"{c} {k}" for c, k in record["pca_best_k"].items())
        + f"); Jet: k = {PARAMS.baselines.jet_k} ({PARAMS.baselines.big_noise_k} on BigNoise), degree "
        f"{PARAMS.baselines.jet_degree}; MFPS: params.yaml's (K = {{{', '.join(map(str, PARAMS.mfps.scales))}}}, "
        f"R = {PARAMS.mfps.trials}, theta_t = {PARAMS.mfps.theta_t} deg, eta = {PARAMS.mfps.eta}); Refine-Net: "
        + ("the networks shipped with the package" if record["release_shipped"] else
           "another run's exported networks (`--release`; not the shipped ones)")
        + f" (profile {record['release']['profile']}, networks {record['release']['fingerprint']}, inputs beyond "
        f"the paper: {', '.join(f'{k} = {v}' for k, v in record['release_inputs'].items()) or 'none'}, trained on "
        f"the procedural shapes only, {record['precision']}), "
        "run as `refinenet normals` runs them (`--strata auto`: on strata of a cloud noisier than the networks know, "
        "`studies/results/strata.md`). Errors are unoriented angles in degrees. Generated by "
        "`benchmarks/eval_dev_meshes.py`"
        + (f"; this run computed {', '.join(NAMES[m] for m in record['methods_run'])} and kept the other methods' "
           f"rows (and their timings) from the run before it (`{Path(record['reused_from']).name}`, the same clouds)"
           if record.get("reused_from") else "") + ".",
        "",
        "## Per category",
        "",
        "Synthetic protocol: mean and PGP pooled over all points of a category, RMSE the point-weighted mean of "
        "per-cloud RMSE; Average is the unweighted mean of the categories.",
        "",
    ]
    flat = to_csv_frame(category_table, NAMES)
    lines += markdown_table(flat, {c: ".3f" if c.endswith(("pgp5", "pgp10")) else ".2f" for c in flat.columns})
    near = record["sharp_near_edges"]
    lines += [
        "",
        "Mean error per category, Refine-Net against the best of the others: "
        + "; ".join(f"{c} {v['refinenet']:.2f} against " + ", ".join(f"{NAMES[r]} {v[r]:.2f}" for r in RIVALS)
                    + (" (met)" if v["met"] else " (**not met**)") for c, v in per_category.items()) + ".",
        "",
        f"SharpFeature near edges ({near['points']:,} of {near['total_points']:,} points, "
        f"{near['points'] / near['total_points']:.1%}), pooled mean error: "
        + ", ".join(f"{NAMES[m]} {v:.2f}" for m, v in near["mean"].items()) + ".",
        "",
        "## Per cloud",
        "",
        "Mean error in degrees per test cloud and method (every statistic, and each run's wall and CPU seconds, "
        f"in {STEM}.json).",
        "",
    ]
    wide = per_cloud.pivot_table(index=["category", "mesh", "noise"], columns="method", values="mean", sort=False)
    wide = wide.rename(columns=NAMES).reset_index()
    wide.index = wide.pop("category")
    wide.index.name = "category"
    lines += markdown_table(wide, {**{NAMES[m]: ".2f" for m in per_cloud["method"].unique()}, "noise": ".2f"})
    load = record["load_average_1min"]
    total = per_cloud.groupby("method", sort=False)["seconds"].sum()
    lines += [
        "",
        "Total wall seconds per method: " + ", ".join(f"{NAMES[m]} {s:.0f}" for m, s in total.items())
        + f"; whole run {record['wall_s']:.0f} s.",
        "",
        "## Machine",
        "",
        f"{info['cpu']}, {info['cores']} cores ({info['threads']} threads), {info['memory_gb']:.0f} GB, "
        f"{info['platform']}, Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}. "
        f"Load average (1 min) at start {load[0]:.2f}, at end {load[1]:.2f}: a load above {info['cores']} means "
        "this run did not have every core to itself.",
        "",
    ]
    return "\n".join(lines)


def reused_rows(path: Path, methods: list[str], n_points: int) -> pd.DataFrame:
    """The per-cloud rows of `methods` from an earlier run of the same clouds (same seeds and point count)."""
    if not methods:
        return pd.DataFrame()
    record = json.loads(path.read_text())
    if record["points"] != n_points or record["global_seed"] != GLOBAL_SEED:
        raise SystemExit(f"{path}: a run of {record['points']} points, seed {record['global_seed']}; cannot reuse")
    rows = pd.DataFrame(record["per_cloud"])
    return rows[rows["method"].isin(methods)]


def in_run_order(fresh: pd.DataFrame, kept: pd.DataFrame) -> pd.DataFrame:
    """The rows of both, cloud by cloud as `fresh` ran them, and within a cloud in METHODS' order."""
    cloud = ["category", "mesh", "noise"]
    both = pd.concat([fresh, kept], ignore_index=True)
    seen = {c: i for i, c in enumerate(dict.fromkeys(fresh[cloud].itertuples(index=False, name=None)))}
    key = [(seen[tuple(row[:3])], METHODS.index(row[3])) for row in both[[*cloud, "method"]].itertuples(index=False)]
    return both.iloc[sorted(range(len(both)), key=key.__getitem__)].reset_index(drop=True)


def near_edge_means(per_cloud: pd.DataFrame, category: str) -> dict[str, float]:
    """Pooled mean error over the near-edge points of one category, per method."""
    group = per_cloud[per_cloud["category"] == category].groupby("method", sort=False)
    return {m: float(g["near_edge_sum_deg"].sum() / g["near_edge_points"].sum()) for m, g in group}


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points", type=int, default=100_000)
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--meshes", type=Path, default=DEV)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                        help="run only these; the other methods' rows come from --reuse")
    parser.add_argument("--reuse", type=Path, default=RESULTS / "dev_meshes.json",
                        help="an earlier run's dev_meshes.json whose rows of the methods not run are kept (the same "
                             "clouds: checked by their seeds and sizes)")
    parser.add_argument("--release", type=Path, default=SHIPPED,
                        help="a release folder to evaluate in place of the shipped networks")
    args = parser.parse_args()
    if args.release.resolve() != SHIPPED and args.out.resolve() == RESULTS.resolve():
        sys.exit(f"eval_dev_meshes: --release {args.release}: give --out a folder outside {RESULTS} (it holds the "
                 "shipped networks' evaluation only)")
    test_clouds = clouds(dev_meshes(args.meshes))
    precision = resolve_precision("auto", resolve_device("cpu"))
    release = load_release(args.release, precision=precision)
    kept = reused_rows(args.reuse, [m for m in METHODS if m not in args.methods], args.points)
    load_start, start = os.getloadavg()[0], time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    partial = args.out / f"{STEM}.partial.jsonl"
    settings = {"points": args.points, "threads": args.threads, "methods": list(args.methods),
                "precision": precision, "release": shipped_networks(release)["fingerprint"]}
    finished = finished_clouds(partial, settings)
    rows, resumed = [], 0
    for category, key, path, noise in test_clouds:
        cloud = (category, key, noise)
        resumed += cloud in finished
        if cloud not in finished:
            finished[cloud] = evaluate_cloud(category, key, path, noise, args.points, args.threads, release,
                                             tuple(args.methods))
            keep_finished(partial, settings, cloud, finished[cloud])
        rows += finished[cloud]
    per_cloud = in_run_order(pd.DataFrame(rows), kept)
    if len(per_cloud) != len(test_clouds) * len(METHODS):
        raise SystemExit(f"{args.reuse}: its rows do not cover every cloud of the methods not run")
    category_table, best_k = with_best_pca(aggregate(per_cloud, "synthetic", METRICS))
    sharp = category_table[("SharpFeature", "mean")]
    mfps_met = bool(sharp["mfps"] < sharp[PCA_BEST] and sharp["mfps"] < sharp["jet"])
    sharp_rows = per_cloud[(per_cloud["category"] == "SharpFeature") & (per_cloud["method"] == "mfps")]
    record = {
        "requirement": " ".join(__doc__.split('"')[1].split()),
        "verdicts": verdicts(category_table),
        "mfps_verdict": f"MFPS on SharpFeature: {sharp['mfps']:.2f} against PCA (best k) {sharp[PCA_BEST]:.2f} and "
                        f"Jet {sharp['jet']:.2f} ({'met' if mfps_met else 'not met'}).",
        "points": args.points, "noise_percent": {c: list(v) for c, v in PARAMS.noise.test.items()},
        "global_seed": GLOBAL_SEED, "meshes_dir": str(args.meshes.resolve()), "pca_best_k": best_k,
        "precision": precision, "methods_run": list(args.methods),
        "reused_from": str(args.reuse) if len(args.methods) < len(METHODS) else None,
        "per_category": {NAMES[m]: {f"{c}/{k}": float(v) for (c, k), v in row.items()}
                         for m, row in category_table.iterrows()},
        "sharp_near_edges": {"points": int(sharp_rows["near_edge_points"].sum()),
                             "total_points": int(sharp_rows["n"].sum()),
                             "mean": near_edge_means(per_cloud, "SharpFeature")},
        "per_cloud": json.loads(per_cloud.to_json(orient="records")),
        "release": shipped_networks(release),
        "release_shipped": args.release.resolve() == SHIPPED,
        "release_folder": str(args.release),
        "release_inputs": {k: v for k in BEYOND_PAPER_INPUTS if (v := getattr(release.params.features, k))},
        "clouds_resumed": resumed,
        "wall_s": time.perf_counter() - start,
        "load_average_1min": [load_start, os.getloadavg()[0]],
        "machine": machine(args.threads),
    }
    write_results(args.out, STEM, record, markdown(record, per_cloud, category_table))
    partial.unlink()
    print(to_csv_frame(category_table, NAMES).round(3).to_string())


if __name__ == "__main__":
    main()
