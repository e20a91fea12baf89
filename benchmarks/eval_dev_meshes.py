"""Refine-Net (the shipped networks, as `refinenet normals` runs them) against PCA (best of k = 30, 50, 100), Jet,
MFPS and the other tools (CGAL's jet and VCM, the learned DISNE) on the shared development meshes, at the synthetic
benchmark's test noise levels.

Answers the accuracy requirement: "Evaluate the trained networks on the shared development meshes (100k points,
the paper's test noise levels per category) against PCA (best of k = 30, 50, 100), Jet and MFPS"; the networks
must be below all of them, and below every peer the run has, in mean and RMSE in every category. It also keeps the
older check that MFPS beats PCA and Jet on the sharp meshes.

Every mesh of ../shared/data/meshes/dev/<sharp|smooth|rich>/ is sampled area-uniformly (ground truth: the normal
of the face a point lies on) and perturbed with Gaussian noise in percent of the bounding-box diagonal. The
categories are the synthetic benchmark's: a sharp mesh at SharpFeature's levels, a smooth one at SmoothSurface's,
a rich one at RichFeature's (params.yaml `noise.test`), and every mesh at BigNoise's. Seeds come from
`derive_seed(2022, ...)`, the mesh and the level. Methods: `pca_normals` with k = 30, 50 and 100, and per category
the k of lowest mean error ("PCA (best k)"); `jet_normals` with params.yaml's `baselines` (k = 100, 200 on
BigNoise, degree 2); MFPS with params.yaml's `mfps` (no profile: the paper's synthetic settings); Refine-Net is
`cli.estimate.estimate_normals` with the shipped release (its own MFPS, l_d from the point spacing, the default
`--precision auto`), which never saw these meshes. The peers run as whole processes on the same noisy cloud
(`peers.py`: CGAL's `jet_estimate_normals` at k = 18, 50, 100 and `vcm_estimate_normals`, one thread each, from the
`peers` extra; DISNE from a folder made by ../shared/peers/disne/prepare.sh, one thread); one not installed is left
out, with the reason in the report. Open3D's PCA is not run: `pca_normals` gives its normals (benchmarks/results/
pca.md), so the PCA rows stand for it. Errors are unoriented angles; categories follow the synthetic
protocol (`refinenet.evaluation.table.aggregate`: pooled mean and PGP, point-weighted RMSE, unweighted Average).
"Near edges" are the points whose 10 nearest clean-sample neighbours include a ground-truth normal more than 30
degrees away.

    python benchmarks/eval_dev_meshes.py [--points 50000 100000] [--threads 2] [--methods refinenet]
                                         [--disne DISNE_FOLDER] [--release FOLDER --out DIR]

Each cloud size (`--points`, by default 50,000 and 100,000) is a run of its own, with its own record in
dev_meshes.json (keyed by the size): a run replaces its size's record and keeps the others'. The report has, per
size, the tables per category, per noise level and per cloud and each method's wall seconds per 100,000 points, and
a plot of the mean error against the noise level per method and category, one row of panels per size
(dev_meshes.png).

`--methods` reruns only some methods (after a change to Refine-Net, say) and keeps the other methods' rows from
the committed run of the same size (`--reuse`), whose clouds are the same: every cloud's seeds derive from the mesh
and the level.

`--release` evaluates another run's exported networks (its `results/release` after `snakemake -j2 release`,
e.g. a candidate setting's) in place of the shipped ones; its results go under `--out`, a folder outside
benchmarks/results, which holds the shipped networks' evaluation only.

Writes benchmarks/results/dev_meshes.json, dev_meshes.md and dev_meshes.png (or under `--out`). Wall and CPU
seconds are recorded for every run (one run each), with the load average at start and end. Each finished cloud's
rows are appended to dev_meshes.partial.jsonl beside them, so that a killed run (the whole takes hours on 2 cores)
resumes where it stopped when started again with the same settings; the file is removed once the results are
written.
"""

from __future__ import annotations

import argparse
import datetime
import json
import os
import sys
import tempfile
import time
from collections.abc import Callable
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import numpy as np  # noqa: E402
import pandas as pd  # noqa: E402
from bench_mfps import machine, near_edges  # noqa: E402
from machine import shipped_networks, write_results  # noqa: E402
from peers import PEERS, cgal_missing, cloud_files, disne_missing, peers, timed_process  # noqa: E402

from refinenet import config as params_lib  # noqa: E402
from refinenet.atomic import atomic_path  # noqa: E402
from refinenet.cli.estimate import estimate_normals  # noqa: E402
from refinenet.data.meshes import MESH_SUFFIXES, read_mesh, sample_mesh  # noqa: E402
from refinenet.data.noise import add_gaussian_noise, bbox_diagonal, derive_seed  # noqa: E402
from refinenet.estimators.baselines import jet_normals, pca_normals  # noqa: E402
from refinenet.estimators.mfps import mfps_normals  # noqa: E402
from refinenet.evaluation.metrics import ErrorStats, unoriented_angles  # noqa: E402
from refinenet.evaluation.table import METHOD_NAMES, aggregate, stats_row, to_csv_frame  # noqa: E402
from refinenet.network.devices import resolve_device, resolve_precision  # noqa: E402
from refinenet.network.release import SHIPPED, load_release  # noqa: E402
from refinenet.threads import thread_independent_products  # noqa: E402

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
#: The cloud sizes of a default run (points per cloud).
SIZES = (50_000, 100_000)
METRICS = ("mean", "rmse", "pgp5", "pgp10")
PCA_KS = (30, 50, 100)
PCA_BEST = "pca_best"
#: The other tools, run as whole processes by `peers.py` (Open3D's PCA is not among them: `pca_normals` gives its
#: normals within 1.2e-6 deg, benchmarks/results/pca.md, so the PCA rows stand for it at each k).
PEER_METHODS = tuple(p for p in PEERS if p != "open3d")
NAMES = {**METHOD_NAMES, **{f"pca{k}": f"PCA k = {k}" for k in PCA_KS}, PCA_BEST: "PCA (best k)",
         **{f"cgal_jet{k}": f"CGAL jet k = {k}" for k in (18, 50, 100)}, "cgal_vcm": "CGAL VCM", "disne": "DISNE"}
#: The methods Refine-Net must beat in every category (of those the run has).
RIVALS = (PCA_BEST, "jet", "mfps", *PEER_METHODS)
#: Every method, in the order of the tables.
METHODS = (*(f"pca{k}" for k in PCA_KS), "jet", "mfps", *PEER_METHODS, "refinenet")
#: Methods drawn in the plot of mean error against noise (the PCA of each category's best k stands for PCA).
PLOTTED = (PCA_BEST, "jet", "mfps", *PEER_METHODS, "refinenet")


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
                   release, only: tuple[str, ...] = METHODS, disne: Path | None = None) -> list[dict]:
    """One per-cloud statistics row per method of `only`, with timings and near-edge errors; a peer that is not
    installed gives no row."""
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
    runs = {name: lambda method=method: timed(method) for name, method in methods.items()}
    rows = []
    with tempfile.TemporaryDirectory() as folder:
        if any(m in PEER_METHODS for m in only):
            runs |= peer_methods(points, Path(folder), disne, [m for m in only if m in PEER_METHODS])
        for method in (m for m in only if m in runs):
            normals, wall, cpu = runs[method]()
            rows.append(cloud_row(method, category, key, noise, normals, truth, near, wall, cpu, sample_seed,
                                  noise_seed))
    return rows


def peer_methods(points: np.ndarray, folder: Path, disne: Path | None,
                 chosen: list[str]) -> dict[str, Callable[[], tuple[np.ndarray, float, float]]]:
    """The installed peers of `chosen` on the cloud (written to `folder` by `cloud_files`), each a call that
    gives its normals and the wall and CPU seconds of its whole process."""
    runs, _ = peers(*cloud_files(points, folder), bbox_diagonal(points), folder, disne)

    def run(peer) -> tuple[np.ndarray, float, float]:
        timing = timed_process(peer.command, peer.env)
        return peer.normals(len(points)), timing["wall_s"], timing["cpu_s"]

    return {peer.name: lambda peer=peer: run(peer) for peer in runs if peer.name in chosen}


def cloud_row(method: str, category: str, key: str, noise: float, normals: np.ndarray, truth: np.ndarray,
              near: np.ndarray, wall: float, cpu: float, sample_seed: int, noise_seed: int) -> dict:
    """The per-cloud statistics row of one method's normals."""
    angles = unoriented_angles(normals, truth)
    row = stats_row(method, category, f"{Path(key).stem}_n{noise}", ErrorStats.from_angles(angles))
    row.update(mesh=Path(key).stem, noise=noise, seconds=wall, cpu_seconds=cpu,
               near_edge_points=int(near.sum()), near_edge_sum_deg=float(angles[near].sum()),
               sample_seed=sample_seed, noise_seed=noise_seed)
    print(f"{category:13s} {key:24s} {noise:4.2f}% {NAMES[method]:16s} mean {row['mean']:6.2f}  {wall:6.1f} s",
          flush=True)
    return row


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
    """Per category: Refine-Net's mean and RMSE, each rival's (of those in the table), and whether Refine-Net is
    below all of them in both."""
    out = {}
    for c in table_categories(table):
        ours = {m: float(table.loc["refinenet", (c, m)]) for m in ("mean", "rmse")}
        rivals = {r: {m: float(table.loc[r, (c, m)]) for m in ("mean", "rmse")} for r in RIVALS if r in table.index}
        out[c] = {"refinenet": ours, **rivals,
                  "met": all(ours[m] < v[m] for v in rivals.values() for m in ("mean", "rmse"))}
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


def markdown(runs: list[tuple[dict, pd.DataFrame, pd.DataFrame]]) -> str:
    """The report of every size's run (its record, per-cloud rows and category table; smallest size first): the
    verdicts first, then one section per size."""
    levels = PARAMS.noise.test
    lines = [
        "# Normal estimation on the shared development meshes",
        "",
        f"Requirement: {runs[0][0]['requirement']}",
        "",
    ]
    for record, _, _ in runs:
        met = [c for c, v in record["verdicts"].items() if v["met"]]
        lines += [
            f"**At {record['points']:,} points: Refine-Net below {', '.join(NAMES[r] for r in record['rivals'])} in "
            f"mean and RMSE in {len(met)} of {len(record['verdicts'])} categories"
            + (f" ({', '.join(met)})" if met else "") + ".** " + record["mfps_verdict"]
            + (f" Not run: {'; '.join(f'{NAMES[m]} ({why})' for m, why in record['not_run'].items())}."
               if record["not_run"] else ""),
            "",
        ]
    sizes = " and ".join(f"{record['points']:,}" for record, _, _ in runs)
    lines += [
        f"Every mesh of `../shared/data/meshes/dev` is sampled with {sizes} area-uniform points (ground truth: "
        "face normals; each size a run of its own) and perturbed with Gaussian "
        "noise in percent of the bounding-box diagonal: "
        + "; ".join(f"the {folder} meshes at {category}'s levels {', '.join(map(str, levels[category]))}"
                    for folder, category in FOLDERS.items())
        + f"; and every mesh at {BIG_NOISE}'s levels {', '.join(map(str, levels[BIG_NOISE]))}. Seeds from "
        f"`derive_seed({GLOBAL_SEED}, ...)` (in {STEM}.json). PCA: k = {', '.join(map(str, PCA_KS))} and per "
        f"category the k of lowest mean error; Jet: k = {PARAMS.baselines.jet_k} ({PARAMS.baselines.big_noise_k} on "
        f"BigNoise), degree {PARAMS.baselines.jet_degree}; MFPS: params.yaml's (K = "
        f"{{{', '.join(map(str, PARAMS.mfps.scales))}}}, R = {PARAMS.mfps.trials}, theta_t = {PARAMS.mfps.theta_t} "
        f"deg, eta = {PARAMS.mfps.eta}); Refine-Net: networks trained on the procedural shapes only, run as "
        "`refinenet normals` runs them (`--strata auto`: on strata of a cloud noisier than the networks know, "
        "`studies/results/strata.md`). Errors are unoriented angles in degrees. Mean and PGP are pooled over all "
        "points of a category, RMSE is the point-weighted mean of per-cloud RMSE, and the Average the unweighted "
        "mean of the categories (the synthetic protocol). Generated by `benchmarks/eval_dev_meshes.py`; the plot of "
        f"mean error against noise is `{STEM}.png`.",
        "",
    ]
    for run in runs:
        lines += size_section(*run)
    return "\n".join(lines)


def size_section(record: dict, per_cloud: pd.DataFrame, category_table: pd.DataFrame) -> list[str]:
    """One size's run: its networks and machine, and its tables per category, per noise level and per cloud."""
    info, near, load = record["machine"], record["sharp_near_edges"], record["load_average_1min"]
    flat = to_csv_frame(category_table, NAMES)
    n = f"{record['points']:,}"
    lines = [
        f"## {n} points",
        "",
        "Refine-Net: " + ("the networks shipped with the package" if record["release_shipped"] else
                          "another run's exported networks (`--release`; not the shipped ones)")
        + f" (profile {record['release']['profile']}, networks {record['release']['fingerprint']}, inputs beyond "
        f"the paper: {', '.join(f'{k} = {v}' for k, v in record['release_inputs'].items()) or 'none'}, "
        f"{record['precision']}). PCA's best k per category: "
        + ", ".join(f"{c} {k}" for c, k in record["pca_best_k"].items()) + ". "
        f"{info['cpu']}, {info['cores']} cores ({info['threads']} threads), {info['memory_gb']:.0f} GB, "
        f"{info['platform']}, Python {info['python']}, numpy {info['numpy']}, scipy {info['scipy']}, "
        + (f"{record['date']}; " if "date" in record else "")
        + f"load average (1 min) at start {load[0]:.2f}, at end {load[1]:.2f} (above {info['cores']}: this run did "
        "not have every core to itself)"
        + (f"; this run computed {', '.join(NAMES[m] for m in record['methods_run'])} and kept the other methods' "
           f"rows (and their timings) from the run before it (`{Path(record['reused_from']).name}`, the same clouds)"
           if record.get("reused_from") else "") + ".",
        "",
        f"### Per category, {n} points",
        "",
        *markdown_table(flat, {c: ".3f" if c.endswith(("pgp5", "pgp10")) else ".2f" for c in flat.columns}),
        "",
        "Mean / RMSE per category, Refine-Net against the others: "
        + "; ".join(f"{c} {_pair(v['refinenet'])} against "
                    + ", ".join(f"{NAMES[r]} {_pair(v[r])}" for r in record["rivals"])
                    + (" (met)" if v["met"] else " (**not met**)") for c, v in record["verdicts"].items()) + ".",
        "",
        f"### Per noise level, {n} points",
        "",
        "Mean error in degrees pooled over the clouds of each category and noise level (percent of the diagonal).",
        "",
        *markdown_table(per_level(per_cloud).rename(columns=NAMES), {NAMES[m]: ".2f" for m in METHODS}),
        "",
        f"### Time, {n} points",
        "",
        "Wall seconds per 100,000 points, summed over every cloud of the run (each method on the threads it was "
        f"given: ours and PCA, Jet and MFPS on {info['threads']}, the CGAL and DISNE peers on one, each a whole "
        "process with its start-up): "
        + ", ".join(f"{NAMES[m]} {v:.1f}" for m, v in seconds_per_100k(per_cloud).items()) + ".",
        "",
        f"SharpFeature near edges ({near['points']:,} of {near['total_points']:,} points, "
        f"{near['points'] / near['total_points']:.1%}), pooled mean error: "
        + ", ".join(f"{NAMES[m]} {v:.2f}" for m, v in near["mean"].items()) + ".",
        "",
        f"### Per cloud, {n} points",
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
    total = per_cloud.groupby("method", sort=False)["seconds"].sum()
    return [
        *lines,
        "",
        "Total wall seconds per method: " + ", ".join(f"{NAMES[m]} {s:.0f}" for m, s in total.items())
        + f"; whole run {record['wall_s']:.0f} s.",
        "",
    ]


def absent(method: str, methods: list[str], reuse: Path, disne: Path | None) -> str:
    """Why a peer has no rows: not installed, or neither run nor in the reused record."""
    missing = disne_missing(disne) if method == "disne" else cgal_missing()
    if method in methods and missing:
        return missing
    return f"not asked for (--methods) and not in {reuse.name}"


def _pair(v: dict[str, float]) -> str:
    return f"{v['mean']:.2f} / {v['rmse']:.2f}"


def pooled_means(per_cloud: pd.DataFrame, by: list[str]) -> pd.DataFrame:
    """Mean error per group of the `by` columns, one column per method, pooled over the groups' points (the sums of
    their clouds' errors over the sums of their counts, so that a larger cloud weighs more)."""
    sums = per_cloud.groupby([*by, "method"], sort=False)[["sum_deg", "n"]].sum()
    return (sums["sum_deg"] / sums["n"]).unstack("method")


def per_level(per_cloud: pd.DataFrame) -> pd.DataFrame:
    """Pooled mean error per (category, noise) and method, methods in METHODS' order."""
    table = pooled_means(per_cloud, ["category", "noise"])
    table = table[[m for m in METHODS if m in table.columns]]
    table.index = [f"{c} {noise:.2f}" for c, noise in table.index]
    table.index.name = "category, noise"
    return table


def seconds_per_100k(per_cloud: pd.DataFrame) -> dict[str, float]:
    """Wall seconds per 100,000 points of each method over the whole run."""
    sums = per_cloud.groupby("method")[["seconds", "n"]].sum()
    return {m: float(1e5 * sums.loc[m, "seconds"] / sums.loc[m, "n"]) for m in METHODS if m in sums.index}


def noise_plot(runs: list[tuple[dict, pd.DataFrame, pd.DataFrame]], path: Path) -> None:
    """Mean error against the noise level per method, one panel per category and one row per size's run (its record
    and per-cloud rows; PCA at the category's best k)."""
    categories = list(dict.fromkeys(runs[0][1]["category"]))
    fig, axes = plt.subplots(len(runs), len(categories), figsize=(3.2 * len(categories), 3.2 * len(runs)), dpi=120,
                             squeeze=False)
    for row, (record, per_cloud, _) in zip(axes, runs, strict=True):
        levels = per_level(per_cloud)
        for ax, category in zip(row, categories, strict=True):
            rows = levels[levels.index.str.startswith(category + " ")]
            noise = [float(label.split()[-1]) for label in rows.index]
            for method in PLOTTED:
                column = f"pca{record['pca_best_k'][category]}" if method == PCA_BEST else method
                if column in rows.columns:
                    ax.plot(noise, rows[column], marker="o", ms=3, label=NAMES[method],
                            lw=2.2 if method == "refinenet" else 1.2)
            ax.set_title(f"{category}, {record['points']:,} points", fontsize=9)
            ax.set_xlabel("noise (% of the diagonal)", fontsize=8)
            ax.set_xticks(noise)
            ax.grid(alpha=0.3)
        row[0].set_ylabel("mean error (deg)", fontsize=8)
    axes[0][-1].legend(fontsize=7, loc="upper left", bbox_to_anchor=(1.02, 1))
    footer = "; ".join(f"{r['points']:,} points: networks {r['release']['fingerprint']}, {r['machine']['cpu']}"
                       + (f", {r['date']}" if "date" in r else "") for r, _, _ in runs)
    fig.text(0.01, 0.01, f"{STEM}: {footer}", fontsize=6, color="0.35")
    fig.tight_layout(rect=(0, 0.05 / len(runs), 1, 1))
    with atomic_path(path) as tmp:
        fig.savefig(tmp, format="png", metadata={"Software": None})
    plt.close(fig)


def reused_rows(path: Path, methods: list[str], n_points: int) -> pd.DataFrame:
    """The per-cloud rows of `methods` from an earlier run of the same clouds (same seeds and point count)."""
    if not methods:
        return pd.DataFrame()
    record = json.loads(path.read_text()).get(str(n_points))
    if record is None or record["global_seed"] != GLOBAL_SEED:
        raise SystemExit(f"{path}: no run of {n_points} points with seed {GLOBAL_SEED}; cannot reuse its rows")
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
    parser.add_argument("--points", type=int, nargs="+", default=list(SIZES),
                        help="the cloud sizes to run, each replacing its own record (the other sizes' are kept)")
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--meshes", type=Path, default=DEV)
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--methods", nargs="+", choices=METHODS, default=list(METHODS),
                        help="run only these; the other methods' rows come from --reuse")
    parser.add_argument("--reuse", type=Path, default=RESULTS / "dev_meshes.json",
                        help="an earlier dev_meshes.json whose rows of the methods not run are kept, from its run of "
                             "the same size (the same clouds: checked by their seeds and sizes)")
    parser.add_argument("--release", type=Path, default=SHIPPED,
                        help="a release folder to evaluate in place of the shipped networks")
    parser.add_argument("--disne", type=Path, help="a DISNE folder made by ../shared/peers/disne/prepare.sh")
    parser.add_argument("--report", action="store_true",
                        help="compute nothing: rebuild the report and plot under --out from its dev_meshes.json")
    args = parser.parse_args()
    thread_independent_products()  # Refine-Net's normals bit for bit as `refinenet normals` computes them
    path = args.out / f"{STEM}.json"
    records = json.loads(path.read_text()) if path.is_file() else {}
    if args.report:
        report(args.out, records)
        return
    if args.release.resolve() != SHIPPED and args.out.resolve() == RESULTS.resolve():
        sys.exit(f"eval_dev_meshes: --release {args.release}: give --out a folder outside {RESULTS} (it holds the "
                 "shipped networks' evaluation only)")
    test_clouds = clouds(dev_meshes(args.meshes))
    precision = resolve_precision("auto", resolve_device("cpu"))
    release = load_release(args.release, precision=precision)
    for n_points in args.points:
        records[str(n_points)] = run(args, n_points, test_clouds, release, precision)
        report(args.out, records)
        (args.out / f"{STEM}.partial.jsonl").unlink()


def run(args: argparse.Namespace, n_points: int, test_clouds: list, release, precision: str) -> dict:
    """The record of one size's run: every test cloud's rows, resumed from the partial file where a killed run with
    the same settings left them, and the rows of the methods not run from `--reuse`."""
    kept = reused_rows(args.reuse, [m for m in METHODS if m not in args.methods], n_points)
    load_start, start = os.getloadavg()[0], time.perf_counter()
    args.out.mkdir(parents=True, exist_ok=True)
    partial = args.out / f"{STEM}.partial.jsonl"
    settings = {"points": n_points, "threads": args.threads, "methods": list(args.methods),
                "precision": precision, "release": shipped_networks(release)["fingerprint"]}
    finished = finished_clouds(partial, settings)
    rows, resumed = [], 0
    for category, key, path, noise in test_clouds:
        cloud = (category, key, noise)
        resumed += cloud in finished
        if cloud not in finished:
            finished[cloud] = evaluate_cloud(category, key, path, noise, n_points, args.threads, release,
                                             tuple(args.methods), args.disne)
            keep_finished(partial, settings, cloud, finished[cloud])
        rows += finished[cloud]
    per_cloud = in_run_order(pd.DataFrame(rows), kept)
    counts = per_cloud["method"].value_counts()
    short = [m for m in METHODS if counts.get(m, 0) not in (0, len(test_clouds))
             or (counts.get(m, 0) == 0 and m not in PEER_METHODS)]
    if short:
        raise SystemExit(f"eval_dev_meshes: no rows for every cloud of {', '.join(short)} (neither run nor in "
                         f"{args.reuse})")
    return {
        "requirement": " ".join(__doc__.split('"')[1].split()),
        "not_run": {m: absent(m, args.methods, args.reuse, args.disne) for m in PEER_METHODS if m not in counts},
        "points": n_points, "noise_percent": {c: list(v) for c, v in PARAMS.noise.test.items()},
        "global_seed": GLOBAL_SEED, "meshes_dir": str(args.meshes.resolve()),
        "precision": precision, "methods_run": list(args.methods),
        "reused_from": str(args.reuse) if len(args.methods) < len(METHODS) else None,
        "per_cloud": json.loads(per_cloud.to_json(orient="records")),
        "release": shipped_networks(release),
        "release_shipped": args.release.resolve() == SHIPPED,
        "release_folder": str(args.release),
        "release_inputs": {k: v for k in BEYOND_PAPER_INPUTS if (v := getattr(release.params.features, k))},
        "clouds_resumed": resumed,
        "wall_s": time.perf_counter() - start,
        "load_average_1min": [load_start, os.getloadavg()[0]],
        "machine": machine(args.threads),
        "date": datetime.date.today().isoformat(),
    }


def report(out: Path, records: dict[str, dict]) -> None:
    """dev_meshes.json, .md and .png under `out`, from every size's record: each record's tables, verdicts and plot
    are derived here from its per-cloud rows, so that `--report` rebuilds them from the records."""
    records = dict(sorted(records.items(), key=lambda item: int(item[0])))
    runs = []
    for record in records.values():
        per_cloud = pd.DataFrame(record["per_cloud"])
        category_table, best_k = with_best_pca(aggregate(per_cloud, "synthetic", METRICS))
        sharp = category_table[("SharpFeature", "mean")]
        mfps_met = bool(sharp["mfps"] < sharp[PCA_BEST] and sharp["mfps"] < sharp["jet"])
        sharp_rows = per_cloud[(per_cloud["category"] == "SharpFeature") & (per_cloud["method"] == "mfps")]
        record |= {
            "verdicts": verdicts(category_table),
            "rivals": [r for r in RIVALS if r in category_table.index],
            "mfps_verdict": f"MFPS on SharpFeature: {sharp['mfps']:.2f} against PCA (best k) "
                            f"{sharp[PCA_BEST]:.2f} and Jet {sharp['jet']:.2f} ({'met' if mfps_met else 'not met'}).",
            "pca_best_k": best_k,
            "per_category": {NAMES[m]: {f"{c}/{k}": float(v) for (c, k), v in row.items()}
                             for m, row in category_table.iterrows()},
            "sharp_near_edges": {"points": int(sharp_rows["near_edge_points"].sum()),
                                 "total_points": int(sharp_rows["n"].sum()),
                                 "mean": near_edge_means(per_cloud, "SharpFeature")},
        }
        runs.append((record, per_cloud, category_table))
        print(f"{record['points']:,} points:")
        print(to_csv_frame(category_table, NAMES).round(3).to_string())
    write_results(out, STEM, records, markdown(runs))
    noise_plot(runs, out / f"{STEM}.png")


if __name__ == "__main__":
    main()
