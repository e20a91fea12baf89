"""The point module's last layer, BN and max-pool as one step (`max_pool_linear_bn`) against the plain layers.

Times a training step (forward, L1 loss, backward, Adam) of the default profile's network on random inputs, and the
BN-folded network's inference, with `PointModule.plain_pooling` on (every MLP layer on every point, then the
max-pool: the reference) and off, alternating in the same process, one torch thread as in a pipeline job; in float32
and, where the CPU has it natively, under bfloat16 autocast as the training stage runs.

    python studies/bench_point_pooling.py [--params params.yaml] [--repeats 5] [--steps 20]

Writes studies/results/point_pooling.md and point_pooling.json.
"""

from __future__ import annotations

import argparse
import statistics
import sys
import time
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parents[1] / "benchmarks"))  # the benchmarks' helpers

import torch  # noqa: E402
import torch.nn.functional as F  # noqa: E402
from machine import machine_info, write_results  # noqa: E402

from refinenet import config  # noqa: E402
from refinenet.allocator import keep_freed_memory  # noqa: E402
from refinenet.network.devices import resolve_precision  # noqa: E402
from refinenet.network.fused import for_inference  # noqa: E402
from refinenet.network.model import RefineNet, architecture, example_inputs  # noqa: E402

RESULTS = Path(__file__).parent / "results"
POOLINGS = {"plain": True, "selected": False}  # value: PointModule.plain_pooling


def training_step_seconds(model: RefineNet, optimizer: torch.optim.Optimizer, inputs, target: torch.Tensor,
                          precision: str, steps: int) -> float:
    """Seconds per training step, over `steps` steps."""
    model.train()
    start = time.perf_counter()
    for _ in range(steps):
        optimizer.zero_grad(set_to_none=True)
        with torch.autocast("cpu", dtype=torch.bfloat16, enabled=precision == "bfloat16"):
            out = model(*inputs)
        F.l1_loss(out.float(), target).backward()
        optimizer.step()
    return (time.perf_counter() - start) / steps


def inference_seconds(model: RefineNet, inputs, steps: int) -> float:
    """Seconds per forward pass of a batch under inference_mode, over `steps` passes."""
    with torch.inference_mode():
        start = time.perf_counter()
        for _ in range(steps):
            model(*inputs)
    return (time.perf_counter() - start) / steps


def measure(params: config.Params, precision: str, repeats: int, steps: int) -> dict:
    network = architecture(params.network, params.features, params.patches)
    batch = params.training.batch_size
    generator = torch.Generator().manual_seed(0)
    inputs = example_inputs(network, batch, generator)
    target = F.normalize(torch.randn(batch, 3, generator=generator), dim=1)
    models, optimizers = {}, {}
    for name, plain in POOLINGS.items():
        torch.manual_seed(0)
        models[name] = RefineNet(network)
        models[name].point_module.plain_pooling = plain
        optimizers[name] = torch.optim.Adam(models[name].parameters(), lr=params.training.lr)
    train: dict[str, list[float]] = {name: [] for name in POOLINGS}
    for name in POOLINGS:  # warm-up
        training_step_seconds(models[name], optimizers[name], inputs, target, precision, 2)
    for _ in range(repeats):
        for name in POOLINGS:
            train[name].append(training_step_seconds(models[name], optimizers[name], inputs, target, precision, steps))

    inference_batch = params.inference.batch_size
    inference_inputs = example_inputs(network, inference_batch, generator)
    infer: dict[str, list[float]] = {name: [] for name in POOLINGS}
    folded = {name: for_inference(model, fuse=True, precision=precision) for name, model in models.items()}
    for name in POOLINGS:
        inference_seconds(folded[name], inference_inputs, 1)
    for _ in range(repeats):
        for name in POOLINGS:
            infer[name].append(inference_seconds(folded[name], inference_inputs, max(1, steps // 10)))
    train_ms = {name: 1e3 * statistics.median(t) for name, t in train.items()}
    points_per_s = {name: inference_batch / statistics.median(t) for name, t in infer.items()}
    return {
        "precision": precision, "batch": batch, "inference_batch": inference_batch,
        "n_normals": network.n_normals, "patch_points": network.n_patch_points,
        "train_step_ms": train_ms, "train_step_ms_runs": {k: [1e3 * s for s in v] for k, v in train.items()},
        "train_ratio_selected_to_plain": train_ms["selected"] / train_ms["plain"],
        "inference_points_per_s": points_per_s,
        "inference_ratio_selected_to_plain": points_per_s["plain"] / points_per_s["selected"],
    }


def markdown(info: dict, rows: list[dict], args: argparse.Namespace) -> str:
    lines = [
        "# Point module: last layer, BN and max-pool as one step",
        "",
        "`max_pool_linear_bn` (src/refinenet/network/pooling.py) against the plain layers "
        "(`PointModule.plain_pooling`: "
        "Linear(128, 1024) and BN on every point of every patch, then the max-pool), timed alternately in one "
        f"process: a training step (forward, L1 loss, backward, Adam) at the profile's batch, median of {args.repeats} "
        f"runs of {args.steps} steps, and the BN-folded network's inference (`for_inference`), on random inputs of "
        f"the network of `{args.params}` (profile `{info['profile']}`). Generated by "
        "`studies/bench_point_pooling.py`. Outputs and gradients are those of the plain layers up to rounding "
        "(tests/test_model.py, in float64).",
        "",
        f"Machine: {info['cpu']}, {info['cores']} cores, 1 torch thread (as a pipeline job), torch {info['torch']}, "
        f"Python {info['python']}; load average (1 min) {info['load_average_1min']:.2f} at the start.",
        "",
        "| precision | X | patch points | batch | training step, plain (ms) | selected (ms) | ratio "
        "| inference batch | points/s plain | points/s selected | time ratio |",
        "|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['precision']} | {r['n_normals']} | {r['patch_points']} | {r['batch']} "
            f"| {r['train_step_ms']['plain']:.1f} | {r['train_step_ms']['selected']:.1f} "
            f"| {r['train_ratio_selected_to_plain']:.2f} | {r['inference_batch']} "
            f"| {r['inference_points_per_s']['plain']:,.0f} | {r['inference_points_per_s']['selected']:,.0f} "
            f"| {r['inference_ratio_selected_to_plain']:.2f} |")
    lines += [
        "",
        "Ratio: selected / plain time (below 1: faster). Where the CPU has no native bfloat16 only float32 is "
        "measured.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--params", default="params.yaml")
    parser.add_argument("--repeats", type=int, default=5)
    parser.add_argument("--steps", type=int, default=20)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    torch.set_num_threads(1)
    keep_freed_memory()  # as every pipeline stage does
    params = config.load(args.params)
    precisions = ["float32"]
    if resolve_precision("auto", torch.device("cpu")) == "bfloat16":
        precisions.append("bfloat16")
    info = machine_info(torch=torch.__version__, profile=params.profile)
    rows = [measure(params, precision, args.repeats, args.steps) for precision in precisions]
    for r in rows:
        print(f"{r['precision']}: training step {r['train_step_ms']['plain']:.1f} -> "
              f"{r['train_step_ms']['selected']:.1f} ms ({r['train_ratio_selected_to_plain']:.2f}x); inference "
              f"{r['inference_points_per_s']['plain']:,.0f} -> {r['inference_points_per_s']['selected']:,.0f} "
              "points/s")
    write_results(args.out, "point_pooling", {"machine": info, "rows": rows}, markdown(info, rows, args))


if __name__ == "__main__":
    main()
