"""Does a longer training lower the networks' error on real shapes, at heavy noise too? The cpu profile's recipe with
more points per cloud and cluster in each epoch (`training.max_train_points_per_cloud`, 600 in the profile: 2,000 by
default here, up to 3.3 times the training steps), trained and exported in a clone of this repository's last commit,
then evaluated on the development meshes as `benchmarks/eval_dev_meshes.py --methods refinenet --release` evaluates a
candidate, beside the shipped networks' committed rows and DISNE's.

    python studies/training_length.py [--points-per-cloud 2000] [--sizes 50000 100000] [--work DIR]

The clone under `--work` is kept: a killed run resumes where it stopped (Snakemake rebuilds only what is missing and
the evaluation resumes from its partial file). Writes studies/results/training_length.json and training_length.md.
"""

from __future__ import annotations

import argparse
import json
import os
import subprocess
import sys
import tempfile
from pathlib import Path

import pandas as pd
from ruamel.yaml import YAML

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))  # the benchmarks' helpers

from eval_dev_meshes import BIG_NOISE, NAMES, RESULTS, STEM, per_level, pooled_means  # noqa: E402
from machine import machine_info, write_results  # noqa: E402

from refinenet import SHIPPED  # noqa: E402
from refinenet.pipeline.layout import RELEASE  # noqa: E402
from refinenet.pipeline.methods import FULL  # noqa: E402

REPO = Path(__file__).resolve().parents[1]
OUT = Path(__file__).parent / "results"
KEY = ("training", "max_train_points_per_cloud")
METRICS = ("mean", "rmse")


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--points-per-cloud", type=int, default=2000)
    parser.add_argument("--sizes", type=int, nargs="+", default=[50_000, 100_000])
    parser.add_argument("--work", type=Path, default=Path(tempfile.gettempdir()) / "refinenet-training-length")
    args = parser.parse_args()
    profile = train_candidate(args.work, args.points_per_cloud)
    cards = {name: json.loads((folder / "model_card.json").read_text())
             for name, folder in (("shipped", SHIPPED), ("candidate", args.work / RELEASE))}
    evaluation = args.work / "evaluation"
    if not evaluated(evaluation / f"{STEM}.json", args.sizes, cards["candidate"]["fingerprint"]):
        run([sys.executable, "benchmarks/eval_dev_meshes.py", "--methods", "refinenet", "--points",
             *map(str, args.sizes), "--release", str(args.work / RELEASE), "--out", str(evaluation)],
            REPO)
    shipped, candidate = (json.loads(p.read_text()) for p in (RESULTS / f"{STEM}.json", evaluation / f"{STEM}.json"))
    record = {"profile": profile, "points_per_cloud": args.points_per_cloud,
              "shipped_points_per_cloud": cards["shipped"]["training"][KEY[1]],
              "validation": {name: validation(card) for name, card in cards.items()},
              "synthetic_check": {name: {"points": card["half_precision"]["points"],
                                         "mean": card["half_precision"]["error_float32_deg"]}
                                  for name, card in cards.items()},
              "training_job_seconds": {"shipped": shipped_training_seconds(),
                                       "candidate": sum(job_seconds(p) for p in (args.work / "logs/training" / FULL)
                                                        .glob("cluster_*.benchmark.tsv"))},
              "sizes": {size: compare(shipped[str(size)], candidate[str(size)]) for size in args.sizes},
              "machine": machine_info()}
    write_results(OUT, "training_length", record, markdown(record))


def run(command: list[str], cwd: Path, env: dict[str, str] | None = None) -> None:
    print("+", " ".join(command), flush=True)
    subprocess.run(command, cwd=cwd, env=env, check=True)


def train_candidate(work: Path, points_per_cloud: int) -> str:
    """Clone the last commit into `work` (once), set the active profile's points per cloud, and export its release
    there with Snakemake; returns the profile's name."""
    if not (work / ".git").is_dir():
        run(["git", "clone", "--quiet", str(REPO), str(work)], REPO)
    yaml = YAML()  # round trip: the clone's params.yaml keeps its comments
    yaml.width = 4096
    params = yaml.load(work / "params.yaml")
    profile = params["profile"]
    params["profiles"][profile][KEY[0]][KEY[1]] = points_per_cloud
    yaml.dump(params, work / "params.yaml")
    env = {**os.environ, "PYTHONPATH": str(work / "src"),  # the clone's own code, whatever this checkout holds
           "PATH": f"{Path(sys.executable).parent}{os.pathsep}{os.environ['PATH']}"}
    run(["snakemake", "--cores", str(len(os.sched_getaffinity(0))), "release"], work, env)
    return profile


def evaluated(path: Path, sizes: list[int], fingerprint: str) -> bool:
    """Whether the evaluation at `path` already holds every size's run of the candidate with this fingerprint."""
    records = json.loads(path.read_text()) if path.is_file() else {}
    return all(records.get(str(size), {}).get("release", {}).get("fingerprint") == fingerprint for size in sizes)


def job_seconds(benchmark: Path) -> float:
    """The wall seconds of one job, from its Snakemake benchmark file."""
    return float(benchmark.read_text().splitlines()[-1].split("\t")[0])


def shipped_training_seconds() -> float:
    """The training's job seconds in the main job that made the shipped networks (benchmarks/results/pipeline.json)."""
    rules = json.loads((RESULTS / "pipeline.json").read_text())["sections"]["main"]["rules"]
    return next(r["job_seconds"] for r in rules if r["rule"] == "training")


def validation(card: dict) -> dict[str, dict[str, float]]:
    """Per cluster: training and validation points, validation RMSE, and the share of its input's RMSE removed."""
    return {c: {"train_points": v["train_points"], "val_points": v["val_points"], "rmse": v["best_val_rmse_deg"],
                "removed": 1 - v["best_val_rmse_deg"] / v["input_val_rmse_deg"]} for c, v in card["clusters"].items()}


def compare(shipped: dict, candidate: dict) -> dict:
    """Per category mean and RMSE of the shipped networks, the candidate and DISNE (from the shipped run's rows),
    and the mean per BigNoise level."""
    rows = {"shipped": shipped["per_category"][NAMES["refinenet"]],
            "candidate": candidate["per_category"][NAMES["refinenet"]],
            "DISNE": shipped["per_category"].get(NAMES["disne"], {})}
    levels = {"shipped": per_level(pd.DataFrame(shipped["per_cloud"])),
              "candidate": per_level(pd.DataFrame(candidate["per_cloud"]))}
    big = [i for i in levels["shipped"].index if i.startswith(BIG_NOISE)]
    meshes = {"shipped": per_mesh(shipped["per_cloud"]), "candidate": per_mesh(candidate["per_cloud"])}
    return {"categories": rows,
            "bignoise_levels": {i: {"shipped": levels["shipped"].loc[i, "refinenet"],
                                    "candidate": levels["candidate"].loc[i, "refinenet"],
                                    "DISNE": levels["shipped"].loc[i].get("disne", float("nan"))} for i in big},
            "bignoise_meshes": {mesh: {"shipped": row["refinenet"], "candidate": meshes["candidate"].loc[mesh,
                                "refinenet"], "DISNE": row.get("disne", float("nan")), "PCA k = 100": row["pca100"]}
                                for mesh, row in meshes["shipped"].iterrows()}}


def per_mesh(rows: list[dict]) -> pd.DataFrame:
    """Mean error pooled over each mesh's BigNoise clouds, per method."""
    frame = pd.DataFrame(rows)
    return pooled_means(frame[frame["category"] == BIG_NOISE], ["mesh"]).sort_index()


def markdown(record: dict) -> str:
    n, n0 = record["points_per_cloud"], record["shipped_points_per_cloud"]
    seconds = record["training_job_seconds"]
    lines = [
        "# Training length: more points per epoch against the shipped networks on the development meshes", "",
        f"Generated by `studies/training_length.py`: the `{record['profile']}` profile's training with {n:,} points "
        f"per cloud and cluster in each epoch instead of {n0:,} (the rest of the recipe unchanged), exported in a "
        "clone of the repository, evaluated by `benchmarks/eval_dev_meshes.py --methods refinenet --release` on the "
        "development meshes (the same clouds as the committed run; DISNE's rows are that run's). Mean and RMSE of "
        "unoriented angles in degrees, pooled as the benchmark pools them.", "",
        f"Training: {seconds['candidate']:,.0f} job seconds (the four clusters' networks, one thread each, two at a "
        f"time on {record['machine']['cpu']}) against the shipped networks' {seconds['shipped']:,.0f} in the main "
        f"job that made them (`benchmarks/results/pipeline.md`): {seconds['candidate'] / seconds['shipped']:.2f}x.",
        "",
        "## Validation (held-out points of the training clouds)", "",
        "A longer training also holds out more points, so compare the share of the input's RMSE each network removes.",
        "", "| cluster | shipped: train / val points | RMSE | removed | candidate: train / val points | RMSE "
        "| removed |",
        "|---|---|---|---|---|---|---|"]
    check = record["synthetic_check"]
    for c, s in record["validation"]["shipped"].items():
        k = record["validation"]["candidate"][c]
        lines.append(f"| {c} | {s['train_points']:,} / {s['val_points']:,} | {s['rmse']:.2f} | {s['removed']:.1%} "
                     f"| {k['train_points']:,} / {k['val_points']:,} | {k['rmse']:.2f} | {k['removed']:.1%} |")
    shipped, candidate = check["shipped"]["mean"], check["candidate"]["mean"]
    lines += ["", f"On the procedural test shapes (the release's own check: {check['shipped']['points']:,} points from "
              f"one test cloud per category, float32) the mean error goes from {shipped:.2f} to {candidate:.2f} "
              f"({candidate / shipped - 1:+.1%})."]
    for size, result in record["sizes"].items():
        rows = result["categories"]
        categories = [c.split("/")[0] for c in rows["shipped"] if c.endswith("/mean")]
        lines += ["", f"## {int(size):,} points", "", "| method | " + " | ".join(categories) + " |",
                  "|---|" + "---|" * len(categories)]
        for name, row in rows.items():
            if row:
                lines.append(f"| {name} | " + " | ".join(
                    " / ".join(f"{row[f'{c}/{m}']:.2f}" for m in METRICS) for c in categories) + " |")
        change = rows["candidate"]["Average/mean"] / rows["shipped"]["Average/mean"] - 1
        lines += ["", f"Mean / RMSE per category. Average mean: candidate {change:+.1%} against the shipped networks"
                  + (f", {rows['candidate']['Average/mean'] / rows['DISNE']['Average/mean'] - 1:+.1%} against DISNE"
                     if rows["DISNE"] else "") + ".", "", "| BigNoise level | shipped | candidate | DISNE |",
                  "|---|---|---|---|"]
        lines += [f"| {level} | {v['shipped']:.2f} | {v['candidate']:.2f} | {v['DISNE']:.2f} |"
                  for level, v in result["bignoise_levels"].items()]
        lines += ["", "Mean per mesh over its BigNoise clouds (0.2-0.5%), beside PCA k = 100:", "",
                  "| mesh | shipped | candidate | DISNE | PCA k = 100 |", "|---|---|---|---|---|"]
        lines += [f"| {mesh} | " + " | ".join(f"{e:.2f}" for e in v.values()) + " |"
                  for mesh, v in result["bignoise_meshes"].items()]
    return "\n".join(lines) + "\n"


if __name__ == "__main__":
    main()
