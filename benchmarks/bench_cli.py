"""`refinenet normals` end to end and stage by stage: wall and CPU seconds, peak memory and accuracy per cloud size,
with Open3D, CGAL (jet, VCM) and DISNE timed in the same run, the network's floating-point operations per point and
the machine's measured GEMM rate beside it.

Each cloud is the procedural fandisk (a CAD shape with sharp edges, a test-split shape the shipped networks never
saw) sampled at N points with 0.1% Gaussian noise of the bounding-box diagonal, written as binary .ply. Every
command runs as a whole process under /usr/bin/time -v (start-up, reading and writing included):

* ours: `refinenet normals cloud.ply -o out.ply --threads T --timings stages.json` (defaults: MFPS + Refine-Net,
  MST orientation, `--precision auto`), and again with `--precision float32` where auto picks bfloat16;
* the peers of `peers.py`, each on its own threads (Open3D on every core, CGAL and DISNE on one).

    python benchmarks/bench_cli.py --points 100000 1000000 [--threads 2] [--disne DISNE_FOLDER] [--peers PEER ...]

Targets (project issue): 100k points in at most 15 s on 2 cores; 10M points in at most 25 minutes with a peak of
at most 4 GB; per thread at least DISNE's points per second. Each --points value is one case in
benchmarks/results/cli.json; cli.md is rebuilt from all cases.
"""

from __future__ import annotations

import argparse
import datetime
import json
import math
import os
import sys
import tempfile
import time
from collections.abc import Sequence
from pathlib import Path
from unittest import mock

import numpy as np
import torch
from machine import machine_info
from peers import PEERS, cloud_files, peers, timed_process
from torch.utils.flop_counter import FlopCounterMode

from refinenet.atomic import write_text
from refinenet.cli.estimate import estimate_normals
from refinenet.data.io import read_cloud
from refinenet.data.noise import add_gaussian_noise, bbox_diagonal
from refinenet.data.shapes import sample_shape
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.network.devices import resolve_precision
from refinenet.network.fused import INFERENCE_CHUNK
from refinenet.network.release import CARD_JSON, SHIPPED, load_release
from refinenet.threads import VARIABLES

RESULTS = Path(__file__).parent / "results"
SHAPE, NOISE = "fandisk_a", 0.1
#: Wall seconds and peak GB per cloud size (None: no target).
TARGETS = {100_000: (15, None), 10_000_000: (1500, 4.0)}
#: Points of the cloud the network's operations are counted on.
FLOP_POINTS = 5000


def noisy_cloud(n: int) -> tuple[np.ndarray, np.ndarray]:
    """The benchmark's cloud of n points and its true normals (also cuda_check's)."""
    points, truth = sample_shape(SHAPE, n, seed=11)
    return add_gaussian_noise(points, NOISE, seed=12), truth


def gemm_gflops(threads: int, dtype: torch.dtype = torch.float32) -> float:
    """The machine's speed now: the best of 10 matrix products in the shape the network's largest layer runs in
    (`fused.INFERENCE_CHUNK` patches of 100 points, 128 by 1024 channels) on `threads` threads. The CPU is shared,
    so timings are read against it."""
    torch.set_num_threads(threads)
    rows = INFERENCE_CHUNK * 100
    a, b = torch.randn(rows, 128, dtype=dtype), torch.randn(128, 1024, dtype=dtype)
    best = min(_seconds(lambda: a @ b) for _ in range(10))
    return 2 * rows * 128 * 1024 / best / 1e9


def network_flops_per_point() -> float:
    """Floating-point operations of the shipped networks per refined point (torch's count of every product and
    convolution), on a small cloud of the benchmark's shape with its strata rule off."""
    points, _ = noisy_cloud(FLOP_POINTS)
    release = load_release(SHIPPED)
    # One thread, so that the batches run on this one, where the counter (a per-thread mode) sees them.
    fused = {torch.ops.mkldnn._linear_pointwise: _linear_flops,  # `fused.LinearReLU` and `fused.Conv2dReLU`,
             torch.ops.mkldnn._convolution_pointwise: _convolution_flops}  # which torch does not count
    counter = FlopCounterMode(display=False, custom_mapping=fused)
    with mock.patch.dict(os.environ, {VARIABLES[0]: "1"}), counter:
        estimate_normals(points, release, n_strata=1, device="cpu")
    return counter.get_total_flops() / FLOP_POINTS


def _linear_flops(x_shape, w_shape, *args, out_shape=None, **kwargs) -> int:
    """Of a product of rows x_shape (..., in) by the weight w_shape (out, in)."""
    return 2 * math.prod(x_shape) * w_shape[0]


def _convolution_flops(x_shape, w_shape, *args, out_shape=None, **kwargs) -> int:
    """Of a convolution by the weight w_shape (out, in / groups, kh, kw) giving out_shape."""
    return 2 * math.prod(out_shape) * math.prod(w_shape[1:])


def _seconds(fn) -> float:
    start = time.perf_counter()
    fn()
    return time.perf_counter() - start


def accuracy(normals: np.ndarray, truth: np.ndarray) -> dict[str, float]:
    angles = unoriented_angles(normals, truth)
    return {"mean_deg": float(angles.mean()), "rmse_deg": float(np.sqrt((angles ** 2).mean())),
            "outward": float((np.einsum("ij,ij->i", normals, truth) > 0).mean())}


def case(n: int, threads: int, folder: Path, float32: bool, disne: Path | None, flops: float,
         chosen: Sequence[str] | None = None) -> dict:
    """One cloud size: ours, then the peers (those named in `chosen`, or all)."""
    points, truth = noisy_cloud(n)
    source, xyz = cloud_files(points, folder)
    precision = resolve_precision("auto", torch.device("cpu"))
    dtype = torch.bfloat16 if precision == "bfloat16" else torch.float32
    result = {"points": n, "shape": SHAPE, "noise_percent": NOISE, "threads": threads,
              "date": datetime.date.today().isoformat(),
              "machine": machine_info(gemm_gflops_start=gemm_gflops(threads, dtype)), "precision": precision,
              "networks": json.loads((SHIPPED / CARD_JSON).read_text())["fingerprint"],
              "network_flops_per_point": flops}
    command = [str(Path(sys.executable).with_name("refinenet")), "normals", str(source), "--threads", str(threads)]
    result["ours"] = timed_process([*command, "-o", str(folder / "ours.ply"), "--timings",
                                    str(folder / "stages.json")])
    result["ours"].update(accuracy(read_cloud(folder / "ours.ply").normals, truth))
    result["stages"] = json.loads((folder / "stages.json").read_text())["stages"]
    if float32 and precision != "float32":
        result["ours_float32"] = timed_process([*command, "-o", str(folder / "ours_float32.ply"), "--precision",
                                                "float32"])
        result["ours_float32"].update(accuracy(read_cloud(folder / "ours_float32.ply").normals, truth))
    runs, result["skipped"] = peers(source, xyz, bbox_diagonal(points), folder, disne)
    result["peers"] = {}
    for peer in runs:
        if chosen is not None and peer.name not in chosen:
            result["skipped"][peer.name] = f"left out of the {n:,}-point case (--peers)"
            continue
        try:
            timing = timed_process(peer.command, peer.env)
        except RuntimeError as err:
            result["skipped"][peer.name] = str(err).splitlines()[-1]
            continue
        result["peers"][peer.name] = {"what": peer.what, "threads": peer.threads or threads, **timing,
                                      **accuracy(peer.normals(n), truth)}
    result["load_average_end"] = machine_info()["load_average_1min"]
    result["gemm_gflops_end"] = gemm_gflops(threads, dtype)
    return result


def _gemm(case: dict) -> str:
    if "gemm_gflops_end" not in case:
        return "not recorded"
    return f"{case['machine']['gemm_gflops_start']:.0f}, {case['gemm_gflops_end']:.0f}"


def _per_thread(n: int, timing: dict, threads: int) -> float:
    return n / timing["wall_s"] / threads


def _peers(c: dict) -> dict[str, dict]:
    """The peers of a case; a case measured before peers.py has Open3D alone."""
    if "peers" in c:
        return c["peers"]
    return {"open3d": {**c["open3d"], "what": "Open3D PCA, k = 30", "threads": c["threads"]}}


def _verdicts(c: dict) -> str:
    o = c["ours"]
    wall, memory = TARGETS.get(c["points"], (None, None))
    verdicts = []
    if wall:
        verdicts.append(f"wall <= {wall} s: {'met' if o['wall_s'] <= wall else 'NOT met'}")
    if memory:
        verdicts.append(f"peak <= {memory} GB: {'met' if o['peak_gb'] <= memory else 'NOT met'}")
    disne = _peers(c).get("disne")
    if disne:
        ours, theirs = _per_thread(c["points"], o, c["threads"]), _per_thread(c["points"], disne, disne["threads"])
        verdicts.append(f"per thread >= DISNE: {'met' if ours >= theirs else 'NOT met'}")
    return "; ".join(verdicts) or "none"


def summary_row(c: dict) -> str:
    o, f = c["ours"], c.get("ours_float32")
    float32 = "not run" if f is None else f"{f['wall_s']:.1f} s, {f['mean_deg']:.3f} / {f['rmse_deg']:.3f}"
    return (f"| {c['points']:,} | {c.get('date', 'before 2026-12-02')} | {c['machine']['cpu']} | "
            f"{c.get('precision', 'float32')} | {o.get('strata', 1)} | {o['wall_s']:.1f} | {o['cpu_s']:.1f} | "
            f"{o['peak_gb']:.2f} | {_per_thread(c['points'], o, c['threads']):,.0f} | "
            f"{o['mean_deg']:.3f} / {o['rmse_deg']:.3f} | {o['outward']:.4f} | {float32} | {_gemm(c)} | "
            f"{c['machine']['load_average_1min']:.1f}, {c['load_average_end']:.1f} | "
            f"{c.get('networks', 'not recorded')} | {_verdicts(c)} |")


def stage_table(c: dict) -> list[str]:
    """Where the time of one case went, stage by stage (a stage's inner stages below it), and the network against
    the GEMM rate."""
    wall, stages = c["ours"]["wall_s"], c["stages"]
    top = [name for name in stages if "/" not in name]
    rows = []
    for name in top:
        for key in (name, *(k for k in stages if k.startswith(f"{name}/"))):
            t, label = stages[key], key.replace("/", " / ")
            rows.append(f"| {label} | {t['wall_s']:.2f} | {t['cpu_s']:.2f} | {t['calls']} | {t['wall_s'] / wall:.0%} |")
    rest = wall - sum(stages[name]["wall_s"] for name in top)
    rows.append(f"| start-up and the rest | {rest:.2f} | | | {rest / wall:.0%} |")
    network = stages.get("network")
    lines = [f"### {c['points']:,} points ({c['machine']['cpu']}, {c['date']}, {c['precision']})", "",
             "| stage | wall (s) | CPU (s) | calls | share of the wall time |", "|---|---|---|---|---|", *rows, ""]
    if network:  # the batches run beside the patches of the next ones, so the networks had both stages' time
        gflop = c["points"] * c["network_flops_per_point"] / 1e9
        rate = max(c["machine"]["gemm_gflops_start"], c["gemm_gflops_end"])
        span = network["wall_s"] + stages.get("patches", {"wall_s": 0.0})["wall_s"]
        lines += [f"The networks: {c['network_flops_per_point'] / 1e6:.1f} MFLOP per point, {gflop:,.0f} GFLOP in "
                  f"the {span:.1f} s of the patches and network stages (they overlap), i.e. at least "
                  f"{gflop / span:.0f} GFLOP/s against the measured {c['precision']} GEMM rate of {rate:.0f} "
                  f"GFLOP/s: at {gflop / span / rate:.0%} of it or more (at the GEMM rate they would take "
                  f"{gflop / rate:.1f} s).", ""]
    return lines


def peer_rows(c: dict) -> list[str]:
    ours = _per_thread(c["points"], c["ours"], c["threads"])
    rows = [f"| {c['points']:,} | Refine-Net (ours) | {c['threads']} | {c['ours']['wall_s']:.1f} | "
            f"{c['ours']['cpu_s']:.1f} | {c['ours']['peak_gb']:.2f} | {ours:,.0f} | "
            f"{c['ours']['mean_deg']:.3f} / {c['ours']['rmse_deg']:.3f} | 1.00 |"]
    for peer in _peers(c).values():
        theirs = _per_thread(c["points"], peer, peer["threads"])
        rows.append(f"| {c['points']:,} | {peer['what']} | {peer['threads']} | {peer['wall_s']:.1f} | "
                    f"{peer['cpu_s']:.1f} | {peer['peak_gb']:.2f} | {theirs:,.0f} | "
                    f"{peer['mean_deg']:.3f} / {peer['rmse_deg']:.3f} | {ours / theirs:.2f} |")
    return rows


def report(cases: dict[str, dict]) -> str:
    ordered = sorted(cases.values(), key=lambda c: c["points"])
    machine = ordered[0]["machine"]
    cpus = sorted({c["machine"]["cpu"] for c in ordered})
    skipped = sorted({f"{name}: {why}" for c in ordered for name, why in c.get("skipped", {}).items()})
    return "\n".join([
        "# `refinenet normals` end to end and by stage: time, memory, accuracy, against its peers",
        "",
        f"Procedural {SHAPE} (a CAD shape with sharp edges, never trained on) with {NOISE}% Gaussian noise, binary "
        ".ply in and out. *Ours*: `refinenet normals cloud.ply -o out.ply` with its defaults (MFPS + the shipped "
        "Refine-Net networks, MST orientation, `--precision auto`, `--strata auto`); *float32*: the same with "
        "`--precision float32` where auto picks bfloat16 (wall time, then mean / RMSE). Every command is a whole "
        "process under `/usr/bin/time -v`, start-up, reading and writing included, and the peers ran in the same "
        "run as ours. Generated by `benchmarks/bench_cli.py`.",
        "",
        f"Machines: {' and '.join(cpus)} (a row's *CPU*), {machine['cores']} cores, {machine['memory_gb']} GB, "
        f"Python {machine['python']}. A row measured before the stage timings existed has no stages or peers "
        "but Open3D; it ran the code and networks of its date.",
        "",
        "## Summary",
        "",
        "| points | measured | CPU | precision | strata | wall (s) | CPU (s) | peak (GB) | points/s per thread "
        "| mean / RMSE (deg) | outward | float32 wall, mean / RMSE (deg) | GEMM GFLOP/s start, end | load start, end "
        "| networks | targets |",
        "|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|---|",
        *map(summary_row, ordered),
        "",
        "Errors are unoriented angles to the true normals; *outward* is the fraction of our oriented normals on the "
        "outer side. *Points/s per thread*: points over wall seconds over the threads given. The GEMM column is the "
        "machine's speed at the time, in the precision that ran (`gemm_gflops`); the same machine has measured from "
        "about 60 to about 200 GFLOP/s in float32 on different days, and the network's time follows it. A load "
        "average above 2 at the start means another job shared the cores. *Networks* names the shipped release "
        "that ran (its model card's fingerprint).",
        "",
        "## Where the time goes",
        "",
        "From `refinenet normals --timings`: each stage's wall and CPU seconds summed over its calls (per stratum, "
        "per tile, per batch). *Start-up and the rest* is the process's wall time outside the stages: the "
        "interpreter, the imports and the bookkeeping between stages.",
        "",
        *[line for c in ordered if "stages" in c for line in stage_table(c)],
        "## The peers, in the same run",
        "",
        "| points | method | threads | wall (s) | CPU (s) | peak (GB) | points/s per thread | mean / RMSE (deg) "
        "| ours per thread / theirs |",
        "|---|---|---|---|---|---|---|---|---|",
        *[row for c in ordered for row in peer_rows(c)],
        "",
        "The peers' normals are unoriented, ours oriented (MST) within the same wall time."
        + (f" Not run: {'; '.join(skipped)}." if skipped else ""),
        "",
    ])


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.split("\n")[0])
    parser.add_argument("--points", type=int, nargs="+", default=[100_000])
    parser.add_argument("--threads", type=int, default=2)
    parser.add_argument("--no-float32", dest="float32", action="store_false",
                        help="skip the second run with --precision float32 (it doubles the time)")
    parser.add_argument("--disne", type=Path, help="a DISNE folder made by ../shared/peers/disne/prepare.sh")
    parser.add_argument("--peers", nargs="+", choices=PEERS, metavar="PEER",
                        help=f"run only these peers (default: every one installed): {', '.join(PEERS)}")
    args = parser.parse_args()
    flops = network_flops_per_point()
    path = RESULTS / "cli.json"
    cases = json.loads(path.read_text()) if path.exists() else {}
    for n in args.points:
        with tempfile.TemporaryDirectory() as folder:
            cases[str(n)] = case(n, args.threads, Path(folder), args.float32, args.disne, flops, args.peers)
        print(json.dumps(cases[str(n)], indent=1))
        write_text(path, json.dumps(cases, indent=1) + "\n")
        write_text(RESULTS / "cli.md", report(cases))


if __name__ == "__main__":
    main()
