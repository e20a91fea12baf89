"""Does keeping freed memory (`refinenet.allocator`, applied by every stage) pay? Two stages of a finished run,
each in two child processes, glibc's default malloc thresholds (the reference) against the fixed ones: the
training of a variant's cluster 0 (the run's settings, with `--epochs` and `--points` per cloud so that it takes
a minute) and its inference of one test cloud. CPU time (user, kernel), minor page faults
and peak memory per child; results equal in both (the training loss, the normals) or the benchmark fails.

    python studies/bench_allocator.py RUN_DIR [--variant kc2] [--cloud test/RichFeature/twistedstar_a_n0.05]
        [--epochs 1] [--points 300]

Writes studies/results/allocator.{json,md}.
"""

from __future__ import annotations

import argparse
import hashlib
import json
import os
import resource
import subprocess
import sys
import tempfile
import time
from dataclasses import replace
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))  # the benchmarks' helpers

from machine import machine_info, write_results  # noqa: E402

from refinenet.allocator import MMAP_THRESHOLD, TRIM_THRESHOLD  # noqa: E402

ROOT = Path(__file__).resolve().parents[1]
OUT = Path(__file__).parent / "results"
SETTINGS = ("default", "kept")  # glibc's default thresholds (the reference), then refinenet.allocator's


def child(args: argparse.Namespace) -> None:
    """Run one stage's `main` in this process under one malloc setting; print its costs as JSON."""
    import yaml

    import stages.inference
    import stages.training
    from refinenet.allocator import keep_freed_memory
    from refinenet.pipeline import layout
    from refinenet.pipeline.workflow import Pipeline, clouds

    if args.child == "kept" and not keep_freed_memory():
        sys.exit("this C library is not glibc: nothing to compare")
    pipe = Pipeline(yaml.safe_load((args.run / "params.yaml").read_text()))
    params = pipe.params[args.variant]
    features, clusters, networks = (pipe.owner(args.variant, f) for f in ("features", "clustering", "training"))
    out = Path(args.scratch)
    start = time.perf_counter()
    if args.stage == "training":
        params = replace(params, training=replace(params.training, max_epochs=args.epochs,
                                                  max_train_points_per_cloud=args.points))
        keys = [c.key for c in clouds(params, "train")]
        stages.training.main(params, argparse.Namespace(
            cluster=0, threads=1, clouds=[args.run / layout.CLOUD.format(cloud=k) for k in keys],
            features=[args.run / layout.FEATURES.format(variant=features, cloud=k) for k in keys],
            clusters=args.run / layout.CLUSTER_MODEL.format(variant=clusters), out=out / "network",
            history=out / "history.csv", checkpoints=out / "checkpoints"))
        result = (out / "history.csv").read_text().splitlines()[-1].rsplit(",", 1)[0]  # the epoch's seconds vary
    else:
        n_clusters = params.clustering.n_clusters
        stages.inference.main(params, argparse.Namespace(
            cloud=args.run / layout.CLOUD.format(cloud=args.cloud),
            features=args.run / layout.FEATURES.format(variant=features, cloud=args.cloud),
            clusters=args.run / layout.CLUSTER_MODEL.format(variant=clusters),
            networks=[args.run / layout.NETWORK.format(variant=networks, cluster=c) for c in range(n_clusters)],
            out=out / "refined.normals"))
        result = hashlib.sha256((out / "refined.normals").read_bytes()).hexdigest()
    usage = resource.getrusage(resource.RUSAGE_SELF)
    print(json.dumps({"wall_s": round(time.perf_counter() - start, 2), "user_s": round(usage.ru_utime, 2),
                      "kernel_s": round(usage.ru_stime, 2), "minor_faults": usage.ru_minflt,
                      "peak_mb": round(usage.ru_maxrss / 1024), "result": result}))


def measure(args: argparse.Namespace, stage: str, setting: str) -> dict:
    """One child run of `stage` under `setting`, in a fresh scratch folder."""
    with tempfile.TemporaryDirectory() as scratch:
        command = [sys.executable, __file__, str(args.run), "--child", setting, "--stage", stage,
                   "--scratch", scratch, "--variant", args.variant, "--cloud", args.cloud,
                   "--epochs", str(args.epochs), "--points", str(args.points)]
        done = subprocess.run(command, capture_output=True, text=True, env={**os.environ, "PYTHONPATH": str(ROOT)})
    if done.returncode:
        sys.exit(f"{stage} ({setting}) failed:\n{done.stderr[-2000:]}")
    return json.loads(done.stdout.strip().splitlines()[-1])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("run", type=Path, help="a finished pipeline run (its results/ and params.yaml)")
    parser.add_argument("--variant", default="kc2", help="the Refine-Net variant whose steps are timed")
    parser.add_argument("--cloud", default="test/RichFeature/twistedstar_a_n0.05", help="the inference's test cloud")
    parser.add_argument("--epochs", type=int, default=1)
    parser.add_argument("--points", type=int, default=300, help="training points per cloud")
    parser.add_argument("--child", choices=SETTINGS, help=argparse.SUPPRESS)
    parser.add_argument("--stage", choices=("training", "inference"), help=argparse.SUPPRESS)
    parser.add_argument("--scratch", help=argparse.SUPPRESS)
    args = parser.parse_args()
    args.run = args.run.resolve()
    if args.child:
        child(args)
        return
    runs = {stage: {setting: measure(args, stage, setting) for setting in SETTINGS}
            for stage in ("training", "inference")}
    rows = []
    for stage, by in runs.items():
        if by["default"].pop("result") != by["kept"].pop("result"):
            sys.exit(f"{stage}: the results differ between the malloc settings")
        by["cpu_ratio"] = round((by["kept"]["user_s"] + by["kept"]["kernel_s"])
                                / (by["default"]["user_s"] + by["default"]["kernel_s"]), 3)
        print(f"{stage}: {by}")
        rows += [f"| {stage} | {setting} | {r['wall_s']} | {r['user_s']} | {r['kernel_s']} | {r['minor_faults']:,} "
                 f"| {r['peak_mb']:,} |" for setting, r in ((s, by[s]) for s in SETTINGS)]
    command = (f"python studies/bench_allocator.py RUN_DIR --variant {args.variant} --cloud {args.cloud} "
               f"--epochs {args.epochs} --points {args.points}")
    record = {"command": command, "run": str(args.run), "machine": machine_info(), **runs}
    markdown = "\n".join([
        "# glibc malloc thresholds: default against kept freed memory", "",
        f"Generated by `{command}` on a `cpu`-profile run: the training stage of {args.variant}'s cluster 0 "
        f"({args.epochs} epoch(s), {args.points} points per training cloud, one thread) and the inference stage of "
        f"`{args.cloud}`, each in its own process; `kept` is `refinenet.allocator.keep_freed_memory` (mmap "
        f"threshold {MMAP_THRESHOLD >> 20} MB, trim threshold {TRIM_THRESHOLD >> 20} MB). Same training loss and "
        "normals under both.", "",
        "| stage | malloc | wall (s) | user CPU (s) | kernel CPU (s) | minor page faults | peak memory (MB) |",
        "|---|---|---|---|---|---|---|", *rows, "",
        *(f"**{stage}: CPU ratio kept / default {by['cpu_ratio']:.2f}.**" for stage, by in runs.items()), ""])
    write_results(OUT, "allocator", record, markdown)


if __name__ == "__main__":
    main()
