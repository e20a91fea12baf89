"""What each rule costs at a profile's sizes, and the SLURM profile's per-rule resources derived from it.

    python benchmarks/cluster_costs.py --sample RUN_DIR --reference RUN_DIR \
        --write-profile workflow/profiles/slurm/config.yaml

Writes benchmarks/results/cluster_costs.json and cluster_costs.md (or under `--out`).

* `--sample`: a run folder at the target profile (e.g. `paper`) where a few jobs of the per-cloud CPU rules ran
  (`snakemake -j1 TARGETS`); their benchmark files give seconds and peak memory per job at the target's sizes, and
  a dry run there gives the number of jobs of every rule.
* `--reference`: a finished run of a smaller profile (e.g. `cpu`) for the rules not sampled: their seconds are
  scaled by the ratio of points per cloud (every such rule is linear in the points it reads), their memory is
  taken as measured (it scales less than linearly: code and libraries dominate at these sizes) and marked so.
* Training at the paper's sizes takes weeks on a CPU (measured rate below), so its time is given for one GPU from
  the network's measured H100 training rate ([H100] in the report: 65,000 samples/s, fp32); inference is given
  both ways.

Resources: memory 1.5x the measured peak (at least 1 GB), time limit 3x the measured or estimated job time (at
least 10 minutes). cpus_per_task follows the rules' threads: 1 for every job but training (1 + its loader
workers); the parallelism is in running jobs side by side. GPUs come from the rules themselves (one for training
and inference when their device is cuda or auto). A time limit hit by training costs nothing: the retry resumes
from the last epoch's checkpoint.
"""

from __future__ import annotations

import argparse
import json
import math
import os
import re
import subprocess
import sys
from pathlib import Path

import numpy as np
import pandas as pd
import yaml

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "src"))
from machine import write_results  # noqa: E402
from pipeline_report import job_benchmarks  # noqa: E402

from refinenet import config  # noqa: E402
from refinenet.pipeline.layout import HISTORY_DIR, MODEL_DIR  # noqa: E402
from refinenet.pipeline.methods import FULL  # noqa: E402
from refinenet.pipeline.steps import gpus  # noqa: E402
from refinenet.pipeline.workflow import Pipeline, clouds  # noqa: E402

#: Rules whose jobs each read one cloud: cost proportional to its points.
PER_CLOUD = ("clouds_train", "clouds_test", "mfps", "mfps_train", "baselines", "features", "inference")
GPU_RULES = ("training", "inference")
#: The release network on one H100 (fp32), measured on a lent GPU machine (the issue's numbers, not this run's).
H100_TRAIN_SAMPLES_S = 65_000
H100_INFER_POINTS_S = 350_000
MEMORY_MARGIN, TIME_MARGIN, MIN_MEM_MB, MIN_MINUTES = 1.5, 3.0, 1000, 10


def job_costs(run: Path) -> pd.DataFrame:
    """Per rule: jobs measured, their longest seconds and their largest peak memory (MB)."""
    return job_benchmarks(run).groupby("rule").agg(measured=("seconds", "size"), seconds=("seconds", "max"),
                                                   rss_mb=("rss_mb", "max"))


def job_counts(run: Path) -> dict[str, int]:
    """Jobs of every rule in a full run of the folder's profile (Snakemake's dry run, as if nothing existed)."""
    env = {**os.environ, "PYTHONPATH": str(run / "src")}  # the folder's own code, not this checkout's
    out = subprocess.run([sys.executable, "-m", "snakemake", "-n", "--forceall", "--quiet", "rules"], cwd=run,
                         capture_output=True, text=True, check=True, env=env).stdout
    return {m[1]: int(m[2]) for m in re.finditer(r"^(\w+)\s+(\d+)$", out, flags=re.M) if m[1] not in ("all", "total")}


def training_samples(params: config.Params) -> int:
    """Training samples per epoch over all clusters (train and validation points), at the profile's sizes; the
    cap on training points applies per cloud and cluster."""
    per_cloud, cap = params.data.n_points, params.training.max_train_points_per_cloud
    if cap is not None:
        per_cloud = min(per_cloud, round(cap / (1 - params.training.val_fraction)) * params.clustering.n_clusters)
    return per_cloud * len(clouds(params, "train"))


def cpu_training_rate(run: Path) -> float:
    """Samples per second of training on this machine's CPU: (train + validation points) x epochs / seconds."""
    samples = seconds = 0.0
    for result in (run / MODEL_DIR.format(variant=FULL)).glob("cluster_*/result.json"):
        info = json.loads(result.read_text())
        history = pd.read_csv(run / HISTORY_DIR.format(variant=FULL) / f"{result.parent.name}.csv")
        samples += (info["train_points"] + info["val_points"]) * len(history)
        seconds += history["seconds"].sum()
    return samples / seconds


def points_read(rule: str, params: config.Params) -> int:
    """Points one job of `rule` reads: one cloud for the per-cloud rules, every training cloud for clustering and
    training, every test cloud for the tables and the rest."""
    if rule in PER_CLOUD:
        return params.data.n_points
    split = "train" if rule in ("clustering", "training") else "test"
    return params.data.n_points * len(clouds(params, split))


def fitted(rule: str, runs: list[tuple[config.Params, pd.DataFrame]],
           target: config.Params) -> tuple[float, float, str]:
    """Seconds and peak MB of a job of `rule` at the target's sizes, from runs of smaller profiles: a straight line
    through (points read, cost) when the runs read different amounts, else time proportional and memory as is."""
    xs = [points_read(rule, params) for params, _ in runs]
    secs = [table.loc[rule, "seconds"] for _, table in runs]
    mbs = [table.loc[rule, "rss_mb"] for _, table in runs]
    x = points_read(rule, target)
    names = "+".join(params.profile for params, _ in runs)
    if len(set(xs)) < 2:
        return secs[0] * x / xs[0], mbs[0], f"{names} x {x / xs[0]:g} (time); memory as measured"
    seconds = max(max(secs), float(np.polyval(np.polyfit(xs, secs, 1), x)))
    mb = max(max(mbs), float(np.polyval(np.polyfit(xs, mbs, 1), x)))
    return seconds, mb, f"line through {names} (points read per job)"


def costs(sample: Path, references: list[Path]) -> dict:
    target = config.load(sample / "params.yaml")
    runs = [(config.load(r / "params.yaml"), job_costs(r)) for r in references]
    counts = job_counts(sample)
    measured = job_costs(sample)
    rules = {}
    for rule, jobs in counts.items():
        if rule in measured.index:
            seconds, rss = measured.loc[rule, "seconds"], measured.loc[rule, "rss_mb"]
            source = f"measured at {target.profile} ({int(measured.loc[rule, 'measured'])} jobs)"
        elif all(rule in table.index for _, table in runs):
            seconds, rss, source = fitted(rule, runs, target)
        else:
            continue
        rules[rule] = {"jobs": jobs, "seconds_per_job": round(float(seconds), 1), "peak_mb": round(float(rss)),
                       "core_hours": round(jobs * float(seconds) / 3600, 2), "source": source}
    largest = max(references, key=lambda r: config.load(r / "params.yaml").data.n_points)
    samples = training_samples(target)
    epochs = target.training.max_epochs
    gpu_epoch_s = samples / H100_TRAIN_SAMPLES_S
    cpu_rate = cpu_training_rate(largest)
    train = rules.setdefault("training", {"jobs": target.clustering.n_clusters, "peak_mb": None})
    train.update({"samples_per_epoch_all_clusters": samples, "max_epochs": epochs,
                  "cpu_samples_per_s": round(cpu_rate, 1),
                  "cpu_core_hours_per_epoch": round(samples / cpu_rate / 3600, 1),  # training jobs use 1 thread
                  "gpu_seconds_per_epoch": round(gpu_epoch_s, 1),
                  "gpu_hours_at_max_epochs": round(gpu_epoch_s * epochs / 3600, 2),
                  "largest_cluster_share": round(_largest_share(largest), 3),
                  "source": f"time: [H100] rate x samples; memory: {train.get('source', '-')}"})
    train["seconds_per_job"] = round(gpu_epoch_s * train["largest_cluster_share"] * epochs, 1)
    train["core_hours"] = None
    if "inference" in rules:
        rules["inference"]["gpu_network_seconds_per_job"] = round(target.data.n_points / H100_INFER_POINTS_S, 2)
    return {"target_profile": target.profile, "references": [p.profile for p, _ in runs],
            "device": target.training.device, "rules": rules}


def _largest_share(run: Path) -> float:
    points = [json.loads(p.read_text())["train_points"] for p in (run / MODEL_DIR.format(variant=FULL)).glob(
        "cluster_*/result.json")]
    return max(points) / sum(points)


def resources(result: dict) -> dict[str, dict[str, int]]:
    """SLURM memory and time per rule, with margins. GPUs are not set here: the rules ask for one from their
    params' device (`steps.gpus`), which a static profile could not follow."""
    return {rule: {"mem_mb": max(MIN_MEM_MB, math.ceil((cost["peak_mb"] or MIN_MEM_MB) * MEMORY_MARGIN / 256) * 256),
                   "runtime": max(MIN_MINUTES, math.ceil(cost["seconds_per_job"] * TIME_MARGIN / 60))}
            for rule, cost in result["rules"].items()}


def markdown(result: dict, res: dict) -> str:
    refs = " and ".join(f"`{r}`" for r in result["references"])
    lines = [f"# Rule costs at the `{result['target_profile']}` profile's sizes, and the SLURM resources from them",
             "", f"Measured on this machine ({os.cpu_count()} cores, shared with other jobs while it ran) by "
             f"`benchmarks/cluster_costs.py`: the per-cloud CPU rules sampled at the `{result['target_profile']}` "
             f"profile; the other rules from finished {refs} runs, extrapolated along the points each job reads. "
             f"Training time is for one GPU ([H100]: the release network trains {H100_TRAIN_SAMPLES_S:,} samples/s "
             f"and infers {H100_INFER_POINTS_S:,} points/s in fp32 on one H100, measured on a lent machine, not in "
             "this run).", "",
             "| rule | jobs | s per job | peak MB | core-hours | SLURM mem_mb | SLURM runtime (min) | GPU | source |",
             "|---|---|---|---|---|---|---|---|---|"]
    for rule, c in result["rules"].items():
        r = res[rule]
        core_hours = "-" if c["core_hours"] is None else c["core_hours"]
        gpu = gpus(result["device"]) if rule in GPU_RULES else 0
        lines.append(f"| {rule} | {c['jobs']} | {c['seconds_per_job']:,} | {c['peak_mb'] or '-'} | {core_hours} | "
                     f"{r['mem_mb']} | {r['runtime']} | {gpu} | {c['source']} |")
    t = result["rules"]["training"]
    cpu_hours = sum(c["core_hours"] or 0 for c in result["rules"].values())
    lines += ["", f"Training: {t['samples_per_epoch_all_clusters']:,} samples (training and validation points) per "
              f"epoch over all clusters. On one core of this CPU {t['cpu_samples_per_s']} samples/s with the reference "
              f"run's network (the paper's is larger), i.e. at least "
              f"{t['cpu_core_hours_per_epoch']} core-hours per epoch, up to {t['max_epochs']} epochs (early stopping "
              "ends it sooner): not a CPU job. On one H100, at the release network's rate, "
              f"{t['gpu_seconds_per_epoch']} s per epoch (a network with 300-point ball patches has 2.2x its "
              "multiply-adds: benchmarks/results/inference.md), "
              f"{t['gpu_hours_at_max_epochs']} GPU-hours for all clusters at the epoch cap; the largest cluster "
              f"({t['largest_cluster_share']:.0%} of the points in the reference run) bounds one job at "
              f"{t['seconds_per_job'] / 3600:.1f} h.", "",
              f"CPU rules in total: {cpu_hours:.1f} core-hours. Rules not listed (tables, metrics, release: "
              "seconds each) run with the profile's default-resources.", ""]
    return "\n".join(lines)


def every_variant(res: dict[str, dict[str, int]], pipeline: Pipeline) -> dict[str, dict[str, int]]:
    """The resources of full's steps given to every variant's instance of them, a training job's time scaled by
    the share of the points its cluster holds (Kc_full / Kc_variant: fewer clusters, larger ones)."""
    out = dict(res)
    full_kc = pipeline.full.clustering.n_clusters
    for step in pipeline.steps.values():
        if step.name in out or step.family not in res:
            continue
        out[step.name] = dict(res[step.family])
        if step.family == "training":
            kc = pipeline.params[step.variant].clustering.n_clusters
            out[step.name]["runtime"] = math.ceil(res["training"]["runtime"] * max(1.0, full_kc / kc))
    return out


def write_profile(path: Path, res: dict[str, dict[str, int]]) -> None:
    """Replace the set-resources block of the SLURM profile; its leading comment lines are kept."""
    text = path.read_text()
    header = [line for line in text.splitlines() if line.startswith("#")]
    profile = yaml.safe_load(text)
    profile["set-resources"] = res
    path.write_text("\n".join(header) + "\n" + yaml.safe_dump(profile, sort_keys=False))


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--sample", type=Path, required=True)
    parser.add_argument("--reference", type=Path, nargs="+", required=True,
                        help="finished runs of smaller profiles (two sizes give a line through both)")
    parser.add_argument("--out", type=Path, default=Path(__file__).parent / "results",
                        help="the folder of cluster_costs.json and cluster_costs.md")
    parser.add_argument("--write-profile", type=Path, help="a SLURM profile whose set-resources to regenerate")
    args = parser.parse_args()
    result = costs(args.sample.resolve(), [r.resolve() for r in args.reference])
    res = resources(result)
    text = markdown(result, res)
    write_results(args.out, "cluster_costs", {**result, "resources": res}, text)
    print(text)
    if args.write_profile:
        target = Pipeline(config.read_raw(args.sample / "params.yaml"))
        write_profile(args.write_profile, every_variant(res, target))
    return 0


if __name__ == "__main__":
    sys.exit(main())
