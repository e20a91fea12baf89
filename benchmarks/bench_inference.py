"""Inference throughput of the full Refine-Net (ALGORITHM.md §8) on CPU, in points per second.

Each configuration is timed in eval mode under torch.inference_mode on random inputs, as trained (plain) and
as the BN-folded copy `fuse_batch_norm` makes for inference, alternating with a reference: one float32 GEMM
with the same multiply-add count as the network's Linear and Conv2d layers, timed in the same process. The
CPU is shared with other jobs, so absolute rates move with their load; the ratio network time / GEMM time
is the steadier figure (1.0 would mean the network runs at GEMM speed).

    python benchmarks/bench_inference.py [--threads 2] [--batches 1024 256] [--repeats 7]

Writes benchmarks/results/inference.md and inference.json. Target (project issue): >= 1,000 points/s.
[P] §Efficiency reports a forward time of 0.8 s per 1k points on an RTX 2080 Ti (all clusters), 2.2 s with
the initial normal estimation.
"""

from __future__ import annotations

import argparse
import json
import os
import platform
import statistics
import time
from collections.abc import Callable
from pathlib import Path

import torch

from refinenet.atomic import write_text
from refinenet.model import (
    NetworkConfig,
    RefineNet,
    architecture_table,
    example_inputs,
    fuse_batch_norm,
    preset,
)

RESULTS = Path(__file__).parent / "results"
#: (preset, patch points): both presets at [C]'s 100 points, and [P]'s preset at its own 300.
CASES = (("release", 100), ("paper", 100), ("paper", 300))
TARGET_POINTS_PER_S = 1000.0
GEMM_SIDE = 1024


def multiply_adds(config: NetworkConfig) -> int:
    """Multiply-adds per sample of the Linear and Conv2d layers (bias, BN, ReLU and pooling left out)."""
    total = 0
    for row in architecture_table(config):
        shape = row["output_shape"]
        if row["type"] == "Linear":  # weights x positions (P for the shared point MLP, 1 otherwise)
            total += (row["params"] - shape[-1]) * (shape[0] if len(shape) == 2 else 1)
        elif row["type"] == "Conv2d":
            total += (row["params"] - shape[0]) * shape[1] * shape[2]
    return total


def seconds(fn: Callable[[], object]) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def measure(name: str, config: NetworkConfig, batch: int, repeats: int) -> dict:
    """Best (and median) times of the network, its BN-folded copy and the GEMM over `repeats` alternating
    runs. The best run is the one least disturbed by other jobs on the shared CPU, so it leads the report."""
    model = RefineNet(config).eval()
    fused = fuse_batch_norm(model)
    inputs = example_inputs(config, batch, torch.Generator().manual_seed(0))
    macs = multiply_adds(config) * batch
    a = torch.randn(max(1, round(macs / GEMM_SIDE**2)), GEMM_SIDE)
    b = torch.randn(GEMM_SIDE, GEMM_SIDE)
    runs = {"net": lambda: model(*inputs), "fused": lambda: fused(*inputs), "gemm": lambda: torch.mm(a, b)}
    times: dict[str, list[float]] = {key: [] for key in runs}
    with torch.inference_mode():
        for fn in runs.values():  # warm-up
            fn()
        for _ in range(repeats):
            for key, fn in runs.items():
                times[key].append(seconds(fn))
    net, fast, gemm = (min(times[key]) for key in runs)
    return {
        "preset": name, "patch_points": config.n_patch_points, "n_normals": config.n_normals, "batch": batch,
        "gflop_per_point": 2 * macs / batch / 1e9,
        **{f"{key}_s_best": min(t) for key, t in times.items()},
        **{f"{key}_s_median": statistics.median(t) for key, t in times.items()},
        "points_per_s": batch / net, "points_per_s_fused": batch / fast,
        "points_per_s_median": batch / statistics.median(times["net"]),
        "points_per_s_fused_median": batch / statistics.median(times["fused"]),
        "fused_speedup": net / fast,
        "gemm_gflop_per_s": 2 * a.shape[0] * GEMM_SIDE**2 / gemm / 1e9,
        "ratio_net_to_gemm": net / gemm, "ratio_fused_to_gemm": fast / gemm,
    }


def machine() -> dict:
    cpu = platform.processor()
    if Path("/proc/cpuinfo").exists():
        names = [ln.split(":", 1)[1].strip() for ln in Path("/proc/cpuinfo").read_text().splitlines()
                 if ln.startswith("model name")]
        cpu = names[0] if names else cpu
    return {
        "cpu": cpu, "cpu_count": os.cpu_count(), "platform": platform.platform(),
        "python": platform.python_version(), "torch": torch.__version__,
        "torch_threads": torch.get_num_threads(), "mkldnn": torch.backends.mkldnn.is_available(),
        "load_average_1min_start": os.getloadavg()[0],
    }


def markdown(info: dict, rows: list[dict], repeats: int) -> str:
    lines = [
        "# Inference throughput (CPU)",
        "",
        "Full Refine-Net (points + HMPs, weight-matrix connections), one per-cluster network, random inputs, "
        f"eval mode, `torch.inference_mode`, float32. Times are the best of {repeats} runs alternating with "
        "a GEMM of the same multiply-add count (Linear and Conv2d layers only). *plain*: `RefineNet` as "
        "trained; *fused*: `fuse_batch_norm(model)`, BN folded into the preceding Linears (same outputs). "
        "Generated by `benchmarks/bench_inference.py`; the CPU is shared with other jobs, so the best run "
        "(least disturbed) is reported; medians are in inference.json.",
        "",
        f"Machine: {info['cpu']}, {info['cpu_count']} logical CPUs, {info['torch_threads']} torch threads, "
        f"torch {info['torch']}, Python {info['python']}. Load average (1 min) "
        f"{info['load_average_1min_start']:.2f} at start, {info['load_average_1min_end']:.2f} at end "
        f"(this run adds about {info['torch_threads']}).",
        "",
        "| preset | X | patch points | batch | GFLOP/point | points/s plain | points/s fused "
        "| fused speed-up | GEMM GFLOP/s | plain / GEMM | fused / GEMM | plain at peak | fused at peak |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|",
    ]
    for r in rows:
        lines.append(
            f"| {r['preset']} | {r['n_normals']} | {r['patch_points']} | {r['batch']} "
            f"| {r['gflop_per_point']:.4f} | {r['points_per_s']:,.0f} | {r['points_per_s_fused']:,.0f} "
            f"| {r['fused_speedup']:.2f} | {r['gemm_gflop_per_s']:.1f} | {r['ratio_net_to_gemm']:.2f} "
            f"| {r['ratio_fused_to_gemm']:.2f} | {r['points_per_s_at_peak']:,.0f} "
            f"| {r['points_per_s_fused_at_peak']:,.0f} |")
    met = all(r["points_per_s_at_peak"] >= TARGET_POINTS_PER_S for r in rows if r["patch_points"] == 100)
    lines += [
        "",
        "*at peak*: the rate scaled to the fastest GEMM of the run (GEMM GFLOP/s of the row vs the maximum), "
        "i.e. the rate with the row's network / GEMM ratio on an undisturbed CPU; a row whose GEMM GFLOP/s is "
        "well below the maximum ran while other jobs held the cores.",
        "",
        f"Target >= {TARGET_POINTS_PER_S:,.0f} points/s at 100 patch points, plain network at peak: "
        f"{'met' if met else 'NOT met'}. [P] reports a forward time of 0.8 s per 1k points "
        "(1,250 points/s) on an RTX 2080 Ti. Each point goes through exactly one of the Kc = 4 cluster "
        "networks, so these rates are also per point of a cloud.",
        "",
    ]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--batches", type=int, nargs="+", default=[1024, 256])
    parser.add_argument("--repeats", type=int, default=7)
    parser.add_argument("--out", type=Path, default=RESULTS)
    args = parser.parse_args()
    torch.set_num_threads(args.threads)
    torch.manual_seed(0)
    info = machine()
    rows = []
    for name, points in CASES:
        for batch in args.batches:
            row = measure(name, preset(name, n_patch_points=points), batch, args.repeats)
            rows.append(row)
            print(f"{name:8s} P={points:3d} batch={batch:5d}: {row['points_per_s']:6,.0f} points/s plain, "
                  f"{row['points_per_s_fused']:6,.0f} fused; network/GEMM = {row['ratio_net_to_gemm']:.2f} "
                  f"plain, {row['ratio_fused_to_gemm']:.2f} fused", flush=True)
    info["load_average_1min_end"] = os.getloadavg()[0]
    peak = max(row["gemm_gflop_per_s"] for row in rows)
    for row in rows:
        scale = peak / row["gemm_gflop_per_s"]
        row["points_per_s_at_peak"] = row["points_per_s"] * scale
        row["points_per_s_fused_at_peak"] = row["points_per_s_fused"] * scale
    record = {"machine": info, "repeats": args.repeats, "rows": rows}
    write_text(args.out / "inference.json", json.dumps(record, indent=2) + "\n")
    write_text(args.out / "inference.md", markdown(info, rows, args.repeats))


if __name__ == "__main__":
    main()
