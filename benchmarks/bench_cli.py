"""`refinenet normals` end to end: wall time and peak memory per cloud size, against Open3D's `estimate_normals`
timed in the same run, and the accuracy of both against the ground truth.

Each cloud is the procedural fandisk (a CAD shape with sharp edges, a test-split shape the shipped networks never
saw) sampled at N points with 0.1% Gaussian noise of the bounding-box diagonal, written as binary .ply. Both
commands run as whole processes under /usr/bin/time -v (start-up, reading and writing included):

* ours: `refinenet normals cloud.ply -o out.ply --threads T` (defaults: MFPS + Refine-Net, MST orientation,
  bfloat16 feature convolutions where the CPU has them natively), and again with `--precision float32`;
* reference: a Python process that reads the cloud with Open3D, calls `estimate_normals()` (its default: PCA of
  the 30 nearest neighbours, unoriented) and writes the result.

    python benchmarks/bench_cli.py --points 100000 1000000 [--threads 2]

Targets (project issue): 100k points in at most 60 s on 2 cores; 1M points in at most 10 minutes and 4 GB; 10M
points complete within 8 GB. Each --points value is one case in benchmarks/results/cli.json; cli.md is rebuilt
from all cases.
"""

from __future__ import annotations

import argparse
import json
import re
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import numpy as np
import torch
from machine import machine_info

from refinenet.atomic import write_text
from refinenet.data.io import read_cloud, write_ply
from refinenet.data.noise import add_gaussian_noise
from refinenet.data.shapes import sample_shape
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.network.devices import resolve_precision
from refinenet.network.release import CARD_JSON, SHIPPED

RESULTS = Path(__file__).parent / "results"
SHAPE, NOISE = "fandisk_a", 0.1


def noisy_cloud(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's cloud of n points and its true normals (also cuda_check's)."""
    points, truth = sample_shape(SHAPE, n, seed=11)
    return add_gaussian_noise(points, NOISE, seed=12), truth
OPEN3D = """
import sys, open3d as o3d
pcd = o3d.io.read_point_cloud(sys.argv[1])
pcd.estimate_normals()
o3d.io.write_point_cloud(sys.argv[2], pcd)
"""
TARGETS = {100_000: (60, None), 1_000_000: (600, 4.0), 10_000_000: (None, 8.0)}


def gemm_gflops(threads: int) -> float:
    """The machine's speed now: the best of 3 float32 matrix products (102400 x 128 by 128 x 1024, the shape of
    the network's largest layer) on `threads` threads. The CPU is shared, so timings are read against it."""
    torch.set_num_threads(threads)
    a, b = torch.randn(102_400, 128), torch.randn(128, 1024)
    best = min(_seconds(lambda: a @ b) for _ in range(3))
    return 2 * 102_400 * 128 * 1024 / best / 1e9


def _seconds(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def timed(command: list[str]) -> dict[str, float]:
    """Wall seconds, CPU seconds and peak resident memory (GB) of a whole process, from /usr/bin/time -v, and the
    strata `refinenet normals` says it used (1 when it names none)."""
    run = subprocess.run(["/usr/bin/time", "-v", *command], capture_output=True, text=True)
    if run.returncode != 0:
        sys.exit(f"failed: {' '.join(command)}\n{run.stderr[-2000:]}")
    report = dict(line.strip().split(": ", 1) for line in run.stderr.splitlines() if ": " in line)
    clock = [float(x) for x in re.split("[:]", report["Elapsed (wall clock) time (h:mm:ss or m:ss)"])]
    wall = sum(x * 60 ** i for i, x in enumerate(reversed(clock)))
    strata = re.search(r"(\d+) strata", run.stderr)
    return {"wall_s": wall, "cpu_s": float(report["User time (seconds)"]) + float(report["System time (seconds)"]),
            "peak_gb": int(report["Maximum resident set size (kbytes)"]) / 2**20,
            "strata": int(strata.group(1)) if strata else 1}


def case(n: int, threads: int, folder: Path, float32: bool) -> dict:
    points, truth = noisy_cloud(n)
    source, ours, reference = folder / "cloud.ply", folder / "ours.ply", folder / "open3d.ply"
    write_ply(source, points)
    ours_float32 = folder / "ours_float32.ply"
    command = [str(Path(sys.executable).with_name("refinenet")), "normals", str(source), "--threads", str(threads)]
    result = {"points": n, "shape": SHAPE, "noise_percent": NOISE, "threads": threads,
              "machine": machine_info(gemm_gflops_start=gemm_gflops(threads)),
              "precision": resolve_precision("auto", torch.device("cpu")),
              "networks": json.loads((SHIPPED / CARD_JSON).read_text())["fingerprint"],
              "ours": timed([*command, "-o", str(ours)]),
              "ours_float32": timed([*command, "-o", str(ours_float32), "--precision", "float32"]) if float32 else None,
              "open3d": timed([sys.executable, "-c", OPEN3D, str(source), str(reference)])}
    for name, path in (("ours", ours), ("ours_float32", ours_float32), ("open3d", reference)):
        if result[name] is None:
            continue
        normals = read_cloud(path).normals
        angles = unoriented_angles(normals, truth)
        result[name].update(mean_deg=float(angles.mean()), rmse_deg=float(np.sqrt((angles ** 2).mean())),
                            outward=float((np.einsum("ij,ij->i", normals, truth) > 0).mean()))
    result["load_average_end"] = machine_info()["load_average_1min"]
    result["gemm_gflops_end"] = gemm_gflops(threads)
    return result


def _gemm(case: dict) -> str:
    if "gemm_gflops_end" not in case:
        return "not recorded"
    return f"{case['machine']['gemm_gflops_start']:.0f}, {case['gemm_gflops_end']:.0f}"


def report(cases: dict[str, dict]) -> str:
    rows = []
    for c in sorted(cases.values(), key=lambda c: c["points"]):
        o, f, r = c["ours"], c.get("ours_float32"), c["open3d"]
        wall_target, memory_target = TARGETS.get(c["points"], (None, None))
        verdicts = []
        if wall_target:
            verdicts.append(f"wall <= {wall_target} s: {'met' if o['wall_s'] <= wall_target else 'NOT met'}")
        if memory_target:
            verdicts.append(f"peak <= {memory_target} GB: {'met' if o['peak_gb'] <= memory_target else 'NOT met'}")
        float32 = "not run" if f is None else f"{f['wall_s']:.1f} s, {f['mean_deg']:.3f} / {f['rmse_deg']:.3f}"
        rows.append(f"| {c['points']:,} | {c['machine']['cpu']} | {c.get('precision', 'float32')} | "
                    f"{o.get('strata', 1)} | {o['wall_s']:.1f} | {o['cpu_s']:.1f} | "
                    f"{o['peak_gb']:.2f} | {float32} | "
                    f"{r['wall_s']:.1f} | {r['peak_gb']:.2f} | {o['wall_s'] / r['wall_s']:.1f} | "
                    f"{o['mean_deg']:.3f} / {o['rmse_deg']:.3f} | {r['mean_deg']:.2f} / {r['rmse_deg']:.2f} | "
                    f"{o['outward']:.4f} | {c['machine']['load_average_1min']:.1f}, {c['load_average_end']:.1f} | "
                    f"{_gemm(c)} | {c.get('networks', 'not recorded')} | "
                    f"{'; '.join(verdicts)} |")
    machine = next(iter(cases.values()))["machine"]
    cpus = sorted({c["machine"]["cpu"] for c in cases.values()})
    return "\n".join([
        "# `refinenet normals` end to end: time, memory, accuracy",
        "",
        f"Procedural {SHAPE} (a CAD shape with sharp edges, never trained on) with {NOISE}% Gaussian noise, binary "
        ".ply in and out. *ours*: `refinenet normals cloud.ply -o out.ply` with its defaults (MFPS + the shipped "
        "Refine-Net networks, MST orientation, `--precision auto`: the *precision* column, bfloat16 point MLP and "
        "height-map convolutions on a CPU with native bfloat16; `--strata auto`: the *strata* column, interleaved "
        "subsets each as noisy as the networks know, 1 in runs made before strata existed); *float32*: the same "
        "with `--precision float32`, the pipeline's precision (wall time, then mean / RMSE); *Open3D*: read, "
        "`estimate_normals()` (PCA of 30 neighbours, unoriented), write, in the same run. Whole processes under "
        "`/usr/bin/time -v`. Generated by `benchmarks/bench_cli.py`.",
        "",
        f"Machines: {' and '.join(cpus)} (a row's *CPU*), {machine['cores']} cores, {machine['memory_gb']} GB, "
        f"Python {machine['python']}; each row was measured on one machine, Open3D in the same run.",
        "",
        "| points | CPU | precision | strata | ours wall (s) | ours CPU (s) | ours peak (GB) "
        "| float32 wall, mean / RMSE (deg) | Open3D wall (s) | Open3D peak (GB) | wall ratio | ours mean / RMSE (deg) "
        "| Open3D mean / RMSE (deg) | ours outward | load start, end | GEMM GFLOP/s start, end | networks | targets |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *rows,
        "",
        "Errors are unoriented angles to the true normals; *outward* is the fraction of our oriented normals on the "
        "outer side (Open3D's are unoriented). A load average above 2 at the start means another job shared the "
        "cores. *Networks* names the shipped release that ran (its model card's fingerprint). The GEMM "
        "column is the machine's speed at the time (`gemm_gflops`); the same machine has measured "
        "from about 60 to about 200 GFLOP/s on different days, and the network's time follows it.",
        "",
    ])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, nargs="+", default=[100_000])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-float32", dest="float32", action="store_false",
                        help="skip the second run with --precision float32 (it doubles the time)")
    args = parser.parse_args()
    path = RESULTS / "cli.json"
    cases = json.loads(path.read_text()) if path.exists() else {}
    for n in args.points:
        with tempfile.TemporaryDirectory() as folder:
            cases[str(n)] = case(n, args.threads, Path(folder), args.float32)
        print(json.dumps(cases[str(n)], indent=1))
        write_text(path, json.dumps(cases, indent=1) + "\n")
        write_text(RESULTS / "cli.md", report(cases))


if __name__ == "__main__":
    main()
