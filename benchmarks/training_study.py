"""What limits the default (cpu profile) training? One cluster's network trained under named changes of the
profile's recipe, on a finished run's training clouds, features and clusters, with the validation error per epoch
and the CPU time of each (one thread, as a pipeline training job runs).

    python benchmarks/training_study.py RUN_DIR --cluster 1 --experiments cpu cosine batch64 --epochs 8
    python benchmarks/training_study.py RUN_DIR --report      (training.md and training.png from the kept runs,
                                                               and RUN_DIR's own training, every cluster)

Each experiment is one entry of benchmarks/results/training.json, named cluster<C>_<name>_e<epochs> and replaced
when rerun: its history per epoch (with cumulative CPU seconds), the settings, how it ended and the validation error
of the initial normals it refines. Patience is set to the epoch count, so every curve runs to the end.
"""

from __future__ import annotations

import argparse
import json
import tempfile
import time
from dataclasses import asdict, replace
from pathlib import Path

import matplotlib

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402
import pandas as pd  # noqa: E402
import torch  # noqa: E402
from machine import machine_info  # noqa: E402

from refinenet import config  # noqa: E402
from refinenet.data.noise import derive_seed  # noqa: E402
from refinenet.features.cache import load_for_cloud  # noqa: E402
from refinenet.network.clustering import load_cluster_model  # noqa: E402
from refinenet.network.dataset import prepare  # noqa: E402
from refinenet.network.model import architecture  # noqa: E402
from refinenet.network.training import HISTORY as HISTORY_FILE  # noqa: E402
from refinenet.network.training import RESULT, cluster_data, train_cluster  # noqa: E402
from refinenet.pipeline.layout import CLOUD, CLUSTER_MODEL, FEATURES, HISTORY, NETWORK  # noqa: E402
from refinenet.pipeline.methods import FULL  # noqa: E402

RESULTS = Path(__file__).parent / "results"
#: Every kept experiment: name -> its record and history.
RUNS = RESULTS / "training.json"
#: The recipe the study started from: the cpu profile's training before it (commit 39646f5). Every experiment
#: is this with some changes, whatever the run's params.yaml now says.
CPU_RECIPE = {"optimizer": "adam", "lr": 1.0e-3, "lr_schedule": "constant", "weight_decay": 0.0, "batch_size": 256,
              "max_train_points_per_cloud": 1000}
#: name -> (what it changes, the changes to CPU_RECIPE)
EXPERIMENTS = {
    "cpu": ("the cpu profile's recipe as it stood: Adam, lr 1e-3 constant, batch 256, 1000 points per cloud", {}),
    "cosine": ("lr decayed to 0 along a cosine over the epochs", {"lr_schedule": "cosine"}),
    "batch64": ("batch 64 (4x the steps per epoch)", {"batch_size": 64}),
    "batch64_cosine": ("batch 64 and the cosine decay", {"batch_size": 64, "lr_schedule": "cosine"}),
    "sgd": ("the paper's optimiser: SGD, lr 1e-4, momentum 0.9, weight decay 0.02, batch 512",
            {"optimizer": "sgd", "lr": 1.0e-4, "momentum": 0.9, "weight_decay": 0.02, "batch_size": 512}),
    "batch64_cosine_bfloat16": ("batch 64, the cosine decay, and the passes in bfloat16 (autocast)",
                                {"batch_size": 64, "lr_schedule": "cosine", "precision": "bfloat16"}),
    "batch64_cosine_points2000": ("batch 64, the cosine decay and 2000 points per cloud",
                                  {"batch_size": 64, "lr_schedule": "cosine", "max_train_points_per_cloud": 2000}),
    "batch64_cosine_bfloat16_correction": (
        "batch 64, the cosine decay, bfloat16, and the network regressing a correction of the initial normal "
        "(network output `correction`)",
        {"batch_size": 64, "lr_schedule": "cosine", "precision": "bfloat16", "output": "correction"}),
}


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path, help="a finished run's repository (its params.yaml and results/)")
    parser.add_argument("--cluster", type=int)
    parser.add_argument("--experiments", nargs="+", choices=sorted(EXPERIMENTS), default=[])
    parser.add_argument("--epochs", type=int, default=8)
    parser.add_argument("--report", action="store_true", help="write training.md and training.png")
    args = parser.parse_args()
    params = config.load(args.run / "params.yaml")
    if args.experiments:
        study(args.run, params, args.cluster, args.experiments, args.epochs)
    if args.report:
        report(params, pipeline_training(args.run, params))
    return 0


def study(run: Path, params: config.Params, cluster: int, names: list[str], epochs: int) -> None:
    """Train `cluster`'s network once per experiment and keep its history beside the settings."""
    torch.set_num_threads(1)
    model, _ = load_cluster_model(run / CLUSTER_MODEL.format(variant=FULL))
    clouds = []
    for cloud_path in sorted((run / "results" / "clouds" / "train").glob("*/*.npz")):
        key = str(cloud_path.relative_to(run / "results" / "clouds")).removesuffix(".npz")
        cloud, features = load_for_cloud(run / CLOUD.format(cloud=key), run / FEATURES.format(variant=FULL, cloud=key))
        clouds.append(prepare(cloud.points, features, model, cloud.normals))
    runs = json.loads(RUNS.read_text()) if RUNS.is_file() else {}
    for name in names:
        changes = CPU_RECIPE | EXPERIMENTS[name][1]
        network = architecture(replace(params.network, output=changes.pop("output", "normal")), params.features,
                               params.patches)
        train = replace(params.training, **changes, max_epochs=epochs, patience=epochs,
                        seed=derive_seed(params.seed, "train", cluster), threads=1)
        data = cluster_data(clouds, cluster, train, params.patches)
        with tempfile.TemporaryDirectory() as tmp:
            cpu, wall = time.process_time(), time.perf_counter()
            train_cluster(train, network, data, tmp, progress=False)
            cpu, wall = time.process_time() - cpu, time.perf_counter() - wall
            history = pd.read_csv(Path(tmp) / HISTORY_FILE)
            result = json.loads((Path(tmp) / RESULT).read_text())
        history["cpu_s"] = history["seconds"].cumsum() * cpu / wall
        runs[f"cluster{cluster}_{name}_e{epochs}"] = {
            "cluster": cluster, "experiment": name, "changes": EXPERIMENTS[name][1], "training": asdict(train),
            "profile": params.profile, "result": result, "cpu_s": cpu, "wall_s": wall, "machine": machine_info(),
            "history": history.to_dict(orient="list")}
        RUNS.write_text(json.dumps(dict(sorted(runs.items())), indent=2) + "\n")
        print(f"cluster {cluster} {name}: best val mean {history['val_mean_deg'].min():.2f} deg "
              f"(input {result['input_val_mean_deg']:.2f}), {cpu / 60:.1f} CPU min")


def kept(history: pd.DataFrame, result: dict) -> tuple[int, float, str]:
    """The kept epoch (lowest validation RMSE, 0-based), the share of the input's mean error it removes, and the
    last epoch's change of the validation mean."""
    val, best = history["val_mean_deg"], int(history["val_rmse_deg"].idxmin())
    removed = 100 * (1 - val.iloc[best] / result["input_val_mean_deg"])
    last = f"{100 * (val.iloc[-1] / val.iloc[-2] - 1):+.1f}%" if len(val) > 1 else ""
    return best, removed, last


def pipeline_training(run: Path, params: config.Params) -> list[str]:
    """Markdown lines on how the run's own training of `full` ended, every cluster (empty if it has none)."""
    results = sorted((run / NETWORK.format(variant=FULL, cluster="x")).parent.glob(f"cluster_*/{RESULT}"))
    if not results:
        return []
    t = params.training
    # The precision the jobs resolved on their machine (`auto` is bfloat16 only on a CPU that has it natively).
    precisions = sorted({json.loads(path.read_text()).get("precision", "float32") for path in results})
    lines = ["", f"## The run's own training ({t.optimizer}, lr {t.lr}, {t.lr_schedule}, batch {t.batch_size}, "
             f"{t.max_epochs} epochs, {t.loss} loss, at most {t.max_train_points_per_cloud} points per cloud"
             + (" drawn anew every epoch" if t.resample_points else "") + ", "
             f"{' and '.join(precisions)}; network output {params.network.output}, "
             f"X = {params.features.n_normals} input normals)", "",
             f"The run given (profile `{params.profile}`): the pipeline's training jobs, one thread each, two at a "
             "time. *Last change*: the last epoch's change of the validation mean.", "",
             "| cluster | train / val points | input val mean / RMSE | val mean per epoch | kept mean / RMSE "
             "| of input removed | last change | job seconds |", "|---|---|---|---|---|---|---|---|"]
    for path in results:
        result = json.loads(path.read_text())
        c = result["cluster"]
        history = pd.read_csv(run / HISTORY.format(variant=FULL, cluster=c))
        val = history["val_mean_deg"]
        best, removed, last = kept(history, result)
        lines.append(f"| {c} | {result['train_points']:,} / {result['val_points']:,} | "
                     f"{result['input_val_mean_deg']:.2f} / {result['input_val_rmse_deg']:.2f} | "
                     f"{', '.join(f'{v:.2f}' for v in val)} | {val.iloc[best]:.2f} / "
                     f"{history['val_rmse_deg'].iloc[best]:.2f} | "
                     f"{removed:.0f}% | {last} | "
                     f"{history['seconds'].sum():.0f} |")
    return lines


def _rank(gain: float, extra: float) -> tuple[bool, float]:
    """Better and cheaper first (by gain), then gain per extra CPU minute."""
    free = gain > 0 and extra <= 0
    return free, gain if free else gain / max(extra, 1e-9)


def _per_minute(gain: float, extra: float) -> str:
    """Points of input error removed per extra CPU minute, or how a change that costs nothing more compares."""
    if extra <= 0:
        return f"{'better' if gain > 0 else 'worse'} ({gain:+.0f} points) and cheaper"
    return f"{gain / extra:+.1f} points"


def _cluster_key(record: dict) -> tuple[int, int]:
    """The cluster's number and its training points at the cpu recipe's cap per cloud."""
    scale = CPU_RECIPE["max_train_points_per_cloud"] / record["training"]["max_train_points_per_cloud"]
    return record["cluster"], round(record["result"]["train_points"] * scale)


def report(params: config.Params, run_lines: list[str]) -> None:
    """training.md (one row per kept experiment, compared with the cpu recipe's 4 epochs on the same cluster) and
    training.png (validation mean error against CPU minutes, one panel per cluster)."""
    runs = [(record, pd.DataFrame(record["history"])) for record in json.loads(RUNS.read_text()).values()]
    order = list(EXPERIMENTS)
    runs.sort(key=lambda run: (run[0]["cluster"], order.index(run[0]["experiment"]), run[0]["training"]["max_epochs"]))
    # The cpu recipe's rate is constant, so the first 4 epochs of a longer cpu run are the 4-epoch run itself.
    # A cluster is known by its number and size: another clustering's cluster of that number is another one.
    baseline = {_cluster_key(record): (history.iloc[:4], record["result"])
                for record, history in runs if record["experiment"] == "cpu" and len(history) >= 4}
    rows, curves, gains = [], {}, []
    for record, history in runs:
        label = f"{record['experiment']}, {record['training']['max_epochs']} epochs"
        curves.setdefault(record["cluster"], []).append((label, history))
        val, result = history["val_mean_deg"], record["result"]
        best, removed, last = kept(history, result)
        row = {
            "cluster": record["cluster"], "experiment": label,
            "train / val points": f"{result['train_points']:,} / {result['val_points']:,}",
            "input": f"{result['input_val_mean_deg']:.2f}",
            **{f"epoch {e}": f"{val.iloc[e - 1]:.2f}" if len(val) >= e else "" for e in (1, 2, 4, 6, 8)},
            "kept (epoch)": f"{val.iloc[best]:.2f} ({best + 1})",
            "of input removed": f"{removed:.0f}%",
            "last change": last,
            "CPU min": f"{history['cpu_s'].iloc[-1] / 60:.1f}",
            "vs cpu recipe": "",
            "removed per extra CPU min": "",
        }
        if (key := _cluster_key(record)) in baseline:
            reference, reference_result = baseline[key]
            reference_best, reference_removed, _ = kept(reference, reference_result)
            reference_mean = reference["val_mean_deg"].iloc[reference_best]
            extra = (history["cpu_s"].iloc[-1] - reference["cpu_s"].iloc[-1]) / 60
            row["vs cpu recipe"] = f"{val.iloc[best] - reference_mean:+.2f} deg, {extra:+.1f} CPU min"
            # Compared in points of the input's error removed, not in degrees: a run with more points per cloud
            # is validated on other points, whose input error differs.
            gain = removed - reference_removed
            if len(history) > len(reference) or record["experiment"] != "cpu":
                row["removed per extra CPU min"] = _per_minute(gain, extra)
                gains.append((record["cluster"], label, gain, extra))
        rows.append(row)
    table = pd.DataFrame(rows)
    lines = ["# Training study: what limits the cpu profile's training", "",
             f"`benchmarks/training_study.py` on the `{params.profile}` profile's training clouds, features and "
             "clusters (seed and split of the pipeline's training job); one thread per run, as a training job "
             "runs. Mean unoriented error in degrees on the cluster's validation points per epoch; *input* is the "
             "initial (MFPS) normals' error on the same points; *kept* is the epoch of lowest validation RMSE, the "
             "weights a training keeps; *vs cpu recipe* compares it and the CPU time with the cpu profile's "
             "recipe as it stood (4 epochs) on the same cluster. A run with more points per cloud also holds out more "
             "(in proportion), so it is validated on other points: compare it by *of input removed*, the share "
             "of the input normals' mean error its network removes. CPU minutes are the process's CPU time; two "
             "or three runs shared the 2 cores.", "",
             "| " + " | ".join(table.columns) + " |", "|" + "---|" * len(table.columns)]
    lines += ["| " + " | ".join(map(str, row)) + " |" for row in table.itertuples(index=False)]
    lines += ["", "Experiments:", ""] + [f"- `{name}`: {text}" for name, (text, _) in EXPERIMENTS.items()]
    lines += ["", "Most accuracy per CPU minute, against the cpu recipe's 4 epochs on the same cluster (*removed per "
              "extra CPU min*: points of the input's mean error removed beyond the recipe's, per CPU minute beyond "
              "its; a change that is better and cheaper ranks first):", ""]
    for cluster in sorted({g[0] for g in gains}):
        ranked = sorted((g for g in gains if g[0] == cluster), key=lambda g: _rank(g[2], g[3]), reverse=True)
        lines.append(f"- cluster {cluster}: " + "; ".join(
            f"{label} {gain:+.0f} points for {extra:+.1f} CPU min" for _, label, gain, extra in ranked))
    lines += ["", "![validation error against CPU minutes](training.png)", *run_lines]
    (RESULTS / "training.md").write_text("\n".join(lines) + "\n")
    fig, axes = plt.subplots(1, len(curves), figsize=(5 * len(curves), 4), squeeze=False)
    for ax, (cluster, cluster_runs) in zip(axes[0], sorted(curves.items()), strict=True):
        for name, history in cluster_runs:
            ax.plot(history["cpu_s"] / 60, history["val_mean_deg"], marker="o", label=name)
        ax.set(title=f"cluster {cluster}", xlabel="CPU minutes", ylabel="validation mean error (deg)")
        ax.legend(fontsize="small")
    fig.tight_layout()
    fig.savefig(RESULTS / "training.png", dpi=100, metadata={"Software": None})


if __name__ == "__main__":
    raise SystemExit(main())
