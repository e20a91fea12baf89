"""Can the training loop keep a GPU busy? Samples per second of building training batches (the loader: patches,
frames, height maps, in one process on the CPU) against a training step of the network on the same batches (CPU),
timed in the same process, on one cloud and feature cache of a run at the run's settings.

    python benchmarks/bench_loader.py RUN_DIR CLOUD_KEY [--batches 10] [--out benchmarks/results/loader]

On a GPU the network trains about 65,000 samples/s (the release network on one H100, fp32; measured on a lent
machine, not here), so the loader's rate per process says how many loader processes a GPU job would need.
"""

from __future__ import annotations

import argparse
import json
import os
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from cluster_costs import H100_TRAIN_SAMPLES_S
from machine import machine_info

from refinenet import config
from refinenet.features.cache import load_for_cloud
from refinenet.network.dataset import Inputs, PreparedCloud, make_inputs
from refinenet.network.model import RefineNet, architecture
from refinenet.pipeline.workflow import CLOUD, FEATURES


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path)
    parser.add_argument("cloud", help="a cloud key of the run, e.g. train/SharpFeature/lblock_b_n0.30")
    parser.add_argument("--batches", type=int, default=10)
    parser.add_argument("--threads", type=int, default=1)
    parser.add_argument("--out", type=Path, help="report stem: writes STEM.json and STEM.md")
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    params = config.load(args.run / "params.yaml")
    cloud, features = load_for_cloud(args.run / CLOUD.format(cloud=args.cloud),
                                     args.run / FEATURES.format(cloud=args.cloud))
    prepared = PreparedCloud(cloud.points, features, np.zeros(len(cloud), dtype=int), cloud.normals)
    network = architecture(params.network, params.features, params.patches)
    model = RefineNet(network)
    optimizer = torch.optim.SGD(model.parameters(), lr=params.training.lr, momentum=params.training.momentum)
    rng = np.random.default_rng(0)
    size = params.training.batch_size

    batches: list[Inputs] = []
    start = time.perf_counter()
    for _ in range(args.batches):
        batches.append(make_inputs(prepared, rng.choice(len(cloud), size, replace=False), params.patches, network,
                                   rng))
    loader_s = time.perf_counter() - start

    model.train()
    start = time.perf_counter()
    for inputs in batches:
        optimizer.zero_grad(set_to_none=True)
        F.mse_loss(model(*inputs.tensors("cpu")), torch.from_numpy(inputs.target)).backward()
        optimizer.step()
    network_s = time.perf_counter() - start

    samples = args.batches * size
    loader_rate, network_rate = samples / loader_s, samples / network_s
    result = {"run_profile": params.profile, "cloud": args.cloud, "points": len(cloud), "batch_size": size,
              "batches": args.batches, "patch_mode": params.patches.mode, "threads": args.threads,
              "loader_samples_per_s": round(loader_rate, 1), "cpu_network_samples_per_s": round(network_rate, 1),
              "loader_over_network": round(loader_rate / network_rate, 2),
              "loader_processes_for_an_h100": int(np.ceil(H100_TRAIN_SAMPLES_S / loader_rate)),
              "machine": machine_info()}
    text = "\n".join([
        f"# Training loader against the network (profile `{params.profile}`)", "",
        f"`benchmarks/bench_loader.py` on `{args.cloud}` ({len(cloud):,} points), {args.batches} batches of {size}, "
        f"{params.patches.mode} patches, {args.threads} thread(s), {os.cpu_count()}-core machine shared with other "
        "jobs while it ran.", "",
        "| | samples/s |", "|---|---|",
        f"| loader (batch building, one process) | {loader_rate:,.0f} |",
        f"| network training step on this CPU | {network_rate:,.0f} |",
        f"| network training step on one H100 (measured on a lent machine, not here) | {H100_TRAIN_SAMPLES_S:,} |",
        "",
        f"On this CPU the loader is {loader_rate / network_rate:.1f}x faster than the network, so a CPU training is "
        f"bound by the network; on a GPU one loader process gives {loader_rate / H100_TRAIN_SAMPLES_S:.0%} of what "
        f"the network takes, so about {result['loader_processes_for_an_h100']} loader processes would be needed "
        "to keep an H100 busy.", ""])
    print(text)
    if args.out:
        args.out.with_suffix(".json").write_text(json.dumps(result, indent=2) + "\n")
        args.out.with_suffix(".md").write_text(text)
    return 0


if __name__ == "__main__":
    raise SystemExit(main())
