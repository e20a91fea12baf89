"""Other normal estimators, each run as a whole process (start-up, reading and writing included) on a cloud file, so
that their times compare with those of `refinenet normals`:

* Open3D's `estimate_normals()` (PCA of the 30 nearest neighbours, its default; every core);
* CGAL's jet fitting at k = 18, 50 and 100 and its Voronoi covariance measure (VCM), through PyPI's `cgal`
  bindings (`pip install -e ".[peers]"`), one thread;
* DISNE (Lenssen et al. 2020, learned, trained on PCPNet), from a folder prepared by
  `../shared/peers/disne/prepare.sh MIRROR DEST`, on the number of threads asked.

A peer that is not installed is skipped, with the reason. Every peer's normals are unoriented. `timed_process`
times any whole command (ours too) from outside: wall and CPU seconds and peak memory.
"""

from __future__ import annotations

import os
import re
import subprocess
import sys
from dataclasses import dataclass
from pathlib import Path

import numpy as np

from refinenet.data.io import read_cloud, read_normals, write_ply

OPEN3D = """
import sys, open3d as o3d
pcd = o3d.io.read_point_cloud(sys.argv[1])
pcd.estimate_normals()
o3d.io.write_point_cloud(sys.argv[2], pcd)
"""
#: argv: cloud.xyz out.ply jet K | vcm OFFSET_RADIUS CONVOLUTION_RADIUS (CGAL's PLY reader refuses our float64
#: binary PLY; the bindings' k-neighbour convolution of VCM gives random normals, so the radius one runs)
CGAL = """
import sys
import CGAL.CGAL_Point_set_processing_3 as psp
from CGAL.CGAL_Point_set_3 import Point_set_3
points = Point_set_3()
points.read(sys.argv[1])
if points.size() == 0:
    sys.exit(f"CGAL read no points from {sys.argv[1]}")
points.add_normal_map()
if sys.argv[3] == "jet":
    psp.jet_estimate_normals(points, int(sys.argv[4]))
else:
    psp.vcm_estimate_normals(points, float(sys.argv[4]), float(sys.argv[5]))
points.write(sys.argv[2])
"""
#: The peers' names, as `peers` gives them.
PEERS = ("open3d", "cgal_jet18", "cgal_jet50", "cgal_jet100", "cgal_vcm", "disne")
#: VCM's offset and convolution radii, in bounding-box diagonals.
VCM_RADIUS = 0.02
#: One thread for the single-threaded peers: their thread pools sized to one, and the process pinned to one core
#: (CGAL's bindings start a thread pool of their own).
ONE_THREAD = {name: "1" for name in ("OMP_NUM_THREADS", "OPENBLAS_NUM_THREADS", "MKL_NUM_THREADS")}
ONE_CORE = ["taskset", "-c", str(min(os.sched_getaffinity(0)))]


@dataclass(frozen=True)
class Peer:
    name: str
    what: str
    threads: int | None
    """The threads it runs on (None: every core)."""
    command: list[str]
    output: Path
    env: dict[str, str]

    def normals(self, n_points: int) -> np.ndarray:
        if self.output.suffix == ".normals":
            return read_normals(self.output, n_points)
        return read_cloud(self.output).normals


def cgal_missing() -> str | None:
    try:
        import CGAL.CGAL_Point_set_processing_3  # noqa: F401
    except ImportError:
        return 'the cgal bindings are not installed (pip install -e ".[peers]")'
    return None


def disne_missing(folder: Path | None) -> str | None:
    if folder is None:
        return "no --disne folder (prepare one with ../shared/peers/disne/prepare.sh MIRROR DEST)"
    if not (folder / "run_peer.py").is_file():
        return f"{folder} has no run_peer.py (prepare it with ../shared/peers/disne/prepare.sh MIRROR {folder})"
    return None


def cloud_files(points: np.ndarray, folder: Path) -> tuple[Path, Path]:
    """The cloud as the peers read it, written under `folder`: binary .ply, and .xyz for CGAL and DISNE."""
    source, xyz = folder / "cloud.ply", folder / "cloud.xyz"
    write_ply(source, points)
    np.savetxt(xyz, points, fmt="%.9g")
    return source, xyz


def peers(cloud_ply: Path, cloud_xyz: Path, diagonal: float, folder: Path, disne: Path | None,
          disne_threads: int = 1) -> tuple[list[Peer], dict[str, str]]:
    """The peers to run on the cloud (written as binary .ply, and as .xyz for CGAL and DISNE), outputs under
    `folder`, and those skipped with the reason."""
    python, env = sys.executable, dict(os.environ)
    one = env | ONE_THREAD
    runs = [Peer("open3d", "Open3D PCA, k = 30", None, [python, "-c", OPEN3D, str(cloud_ply), str(folder / "o3d.ply")],
                 folder / "o3d.ply", env)]
    skipped = {}
    if (reason := cgal_missing()) is None:
        for k in (18, 50, 100):
            out = folder / f"cgal_jet{k}.ply"
            runs.append(Peer(f"cgal_jet{k}", f"CGAL jet, k = {k}", 1,
                             [*ONE_CORE, python, "-c", CGAL, str(cloud_xyz), str(out), "jet", str(k)], out, one))
        out = folder / "cgal_vcm.ply"
        radius = str(VCM_RADIUS * diagonal)
        runs.append(Peer("cgal_vcm", f"CGAL VCM, radii {VCM_RADIUS} diagonal", 1,
                         [*ONE_CORE, python, "-c", CGAL, str(cloud_xyz), str(out), "vcm", radius, radius], out, one))
    else:
        skipped["cgal"] = reason
    if (reason := disne_missing(disne)) is None:
        names = cloud_xyz.parent / "names.txt"
        names.write_text(f"{cloud_xyz.stem}\n")
        out = folder / "disne"
        pinned = ONE_CORE if disne_threads == 1 else []
        runs.append(Peer("disne", "DISNE (learned), k = 64, 4 iterations", disne_threads,
                         [*pinned, python, str(disne / "run_peer.py"), "--in", str(cloud_xyz.parent), "--list",
                          str(names), "--out", str(out), "--device", "cpu", "--threads", str(disne_threads)],
                         out / f"{cloud_xyz.stem}.normals", env | {k: str(disne_threads) for k in ONE_THREAD}))
    else:
        skipped["disne"] = reason
    return runs, skipped


def timed_process(command: list[str], env: dict[str, str] | None = None) -> dict[str, float]:
    """Wall seconds, CPU seconds and peak resident memory (GB) of a whole process, from /usr/bin/time -v, and the
    strata `refinenet normals` says it used (1 when it names none)."""
    run = subprocess.run(["/usr/bin/time", "-v", *command], capture_output=True, text=True, env=env)
    if run.returncode != 0:
        raise RuntimeError(f"failed: {' '.join(command)[:300]}\n{run.stderr[-2000:]}")
    report = dict(line.strip().split(": ", 1) for line in run.stderr.splitlines() if ": " in line)
    clock = [float(x) for x in re.split("[:]", report["Elapsed (wall clock) time (h:mm:ss or m:ss)"])]
    wall = sum(x * 60 ** i for i, x in enumerate(reversed(clock)))
    strata = re.search(r"(\d+) strata", run.stderr)
    return {"wall_s": wall, "cpu_s": float(report["User time (seconds)"]) + float(report["System time (seconds)"]),
            "peak_gb": int(report["Maximum resident set size (kbytes)"]) / 2**20,
            "strata": int(strata.group(1)) if strata else 1}
