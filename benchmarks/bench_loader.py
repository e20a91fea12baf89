"""Can the training loop keep a GPU busy? Samples per second of the training loader (`ClusterData.batches`:
patches, frames, height maps) in the training process and with worker processes (`training.loader_workers`),
against a training step of the network on the same batches on this CPU, all timed in the same process on one
cloud and feature cache of a run, at the run's settings.

    python benchmarks/bench_loader.py RUN_DIR CLOUD_KEY [--batches 40] [--workers 0 1 2]

Writes benchmarks/results/loader.json and loader.md (or under `--out`). On a GPU the network trains about 65,000
samples/s (the release network on one H100, fp32; measured on a lent machine, not here), so the rate per worker says
how many workers a GPU job needs.
"""

from __future__ import annotations

import argparse
import itertools
import os
import time
from pathlib import Path

import numpy as np
import torch
import torch.nn.functional as F
from cluster_costs import H100_TRAIN_SAMPLES_S
from machine import machine_info, write_results
from scipy.spatial import cKDTree

from refinenet import config
from refinenet.features.cache import load_for_cloud
from refinenet.geometry.ball import random_ball_subsets
from refinenet.network.dataset import PreparedCloud
from refinenet.network.model import RefineNet, architecture
from refinenet.network.training import cluster_data
from refinenet.pipeline.layout import CLOUD, FEATURES
from refinenet.pipeline.methods import FULL

RESULTS = Path(__file__).parent / "results"


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run", type=Path)
    parser.add_argument("cloud", help="a cloud key of the run, e.g. train/SharpFeature/lblock_b_n0.30")
    parser.add_argument("--batches", type=int, default=40)
    parser.add_argument("--workers", type=int, nargs="+", default=[0, 1, 2], help="loader worker counts to time")
    parser.add_argument("--network-batches", type=int, default=4, help="batches of the timed network steps")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the folder of loader.json and loader.md")
    args = parser.parse_args()
    torch.set_num_threads(1)  # a training job's one core
    params = config.load(args.run / "params.yaml")
    cloud, features = load_for_cloud(args.run / CLOUD.format(cloud=args.cloud),
                                     args.run / FEATURES.format(variant=FULL, cloud=args.cloud))
    prepared = PreparedCloud(cloud.points, features, np.zeros(len(cloud), dtype=int), cloud.normals)
    data = cluster_data([prepared], 0, params.training, params.patches)
    network = architecture(params.network, params.features, params.patches)
    size = min(params.training.batch_size, len(data.train) // args.batches)
    samples = args.batches * size

    def loader_rate(workers: int) -> float:
        """Samples/s of the first `--batches` batches of an epoch, the workers' start included."""
        start = time.perf_counter()
        built = data.batches(data.train, size, network, (0, 1), shuffle=True, drop_last=True, workers=workers)
        for _ in itertools.islice(built, args.batches):
            pass
        return samples / (time.perf_counter() - start)

    batches = list(itertools.islice(data.batches(data.train, size, network, (0, 1), shuffle=True, drop_last=True),
                                    args.network_batches))  # also loads the compiled kernels before the timing
    rates = {workers: loader_rate(workers) for workers in args.workers}
    model = RefineNet(network).train()
    optimizer = torch.optim.SGD(model.parameters(), lr=params.training.lr, momentum=params.training.momentum)
    start = time.perf_counter()
    for inputs in batches:
        optimizer.zero_grad(set_to_none=True)
        F.mse_loss(model(*inputs.tensors("cpu")), torch.from_numpy(inputs.target)).backward()
        optimizer.step()
    network_rate = args.network_batches * size / (time.perf_counter() - start)

    ball_ms = reference_ms = None
    if params.patches.mode == "ball":
        ball_ms, reference_ms = ball_query_ms(prepared, params.patches.radius * prepared.length,
                                              params.patches.max_points, size)

    per_worker = max(rates[w] / w for w in rates if w > 0) if any(w > 0 for w in rates) else rates[0]
    needed = int(np.ceil(H100_TRAIN_SAMPLES_S / per_worker))
    result = {"run_profile": params.profile, "cloud": args.cloud, "points": len(cloud), "batch_size": size,
              "batches": args.batches, "network_batches": args.network_batches, "patch_mode": params.patches.mode,
              "loader_samples_per_s": {str(w): round(r, 1) for w, r in rates.items()},
              "cpu_network_samples_per_s": round(network_rate, 1),
              "ball_subsets_ms_per_batch": ball_ms, "kd_tree_reference_ms_per_batch": reference_ms,
              "loader_workers_for_an_h100": needed, "machine": machine_info()}
    lines = [f"# Training loader against the network (profile `{params.profile}`)", "",
             f"`benchmarks/bench_loader.py` on `{args.cloud}` ({len(cloud):,} points): the first {args.batches} "
             f"batches of {size} samples of an epoch (the workers' start included), {params.patches.mode} patches, "
             f"on a {os.cpu_count()}-core machine; the network step ({args.network_batches} batches) uses one thread, "
             "as a training job does.", "",
             "| | samples/s |", "|---|---|"]
    lines += [f"| loader, {'in the training process' if w == 0 else f'{w} worker process(es)'} | {r:,.0f} |"
              for w, r in rates.items()]
    lines += [f"| network training step on this CPU (one thread) | {network_rate:,.0f} |",
              f"| network training step on one H100 (measured on a lent machine, not here) | "
              f"{H100_TRAIN_SAMPLES_S:,} |", ""]
    if ball_ms is not None:
        lines += [f"The ball subsets of a batch (`geometry.ball`, hashed grid) take {ball_ms:.1f} ms against "
                  f"{reference_ms:.1f} ms for the dual k-d tree query they replaced (kept here as the reference): "
                  f"{reference_ms / ball_ms:.1f}x.", ""]
    lines += [f"On this CPU the loader in the training process alone builds {rates[0] / network_rate:.1f}x what the "
              f"network consumes, so a CPU training is bound by the network. On a GPU the network takes "
              f"{H100_TRAIN_SAMPLES_S:,} samples/s: at {per_worker:,.0f} samples/s per worker, `loader_workers: "
              f"{needed}` (and as many cores) keep one H100 busy.", ""]
    text = "\n".join(lines)
    print(text)
    write_results(args.out, "loader", result, text)
    return 0


def ball_query_ms(cloud: PreparedCloud, radius: float, max_points: int, size: int, repeats: int = 10):
    """Milliseconds per batch of `size` random ball subsets: the grid kernel, and the dual k-d tree query with a
    sort by random keys that the loader used before it (the reference)."""
    rng = np.random.default_rng(0)
    centres = [np.sort(rng.choice(len(cloud.points), size, replace=False)) for _ in range(repeats)]
    grid = cloud.ball_grid(radius)
    start = time.perf_counter()
    for index in centres:
        random_ball_subsets(grid, index, max_points, seed=0)
    grid_ms = 1000 * (time.perf_counter() - start) / repeats
    start = time.perf_counter()
    for index in centres:
        pairs = cKDTree(cloud.points[index]).sparse_distance_matrix(cloud.tree, radius, output_type="ndarray")
        row = pairs["i"]
        order = np.argsort((row << 32) + rng.integers(0, 1 << 32, len(row)))
        row, member = row[order], pairs["j"][order]
        count = np.bincount(row, minlength=size)
        rank = np.arange(len(row)) - (np.cumsum(count) - count)[row]
        chosen = np.repeat(index[:, None], max_points, axis=1)
        chosen[row[rank < max_points], rank[rank < max_points]] = member[rank < max_points]
    return round(grid_ms, 2), round(1000 * (time.perf_counter() - start) / repeats, 2)


if __name__ == "__main__":
    raise SystemExit(main())
