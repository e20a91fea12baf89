"""The tiles of one cloud as separate jobs (`refinenet tiles plan|run|merge`, workflow/tiles.smk): the normals of
one `refinenet normals` process, and one-line refusals of a plan, a cloud or a piece that do not belong together."""

from __future__ import annotations

import json
import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

from refinenet.cli.main import main
from refinenet.data.io import read_cloud

REPO = Path(__file__).resolve().parents[1]
#: Points of the test strip and own points per tile: 2 strata of 2 tiles each, margins well inside the strip.
N_POINTS, TILE_POINTS = 12_000, 3000


def strip(n: int = N_POINTS, seed: int = 2) -> np.ndarray:
    """A noisy height field 12 x 1 with a step every unit, so that tiles of a quarter of it keep real margins."""
    rng = np.random.default_rng(seed)
    x, y = rng.random(n) * 12, rng.random(n)
    z = 0.1 * np.sin(2 * x) * np.cos(4 * y) + 0.05 * (np.floor(x) % 2) + rng.normal(0, 0.002, n)
    return np.c_[x, y, z]


@pytest.fixture(scope="module")
def cloud(tmp_path_factory) -> Path:
    path = tmp_path_factory.mktemp("jobs") / "strip.xyz"
    np.savetxt(path, strip(), fmt="%.6f")
    return path


def refinenet(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "refinenet.cli.main", *map(str, args)], capture_output=True,
                          text=True, timeout=600)


def tiles(capsys, *args: str | Path) -> tuple[int, str]:
    """`refinenet tiles ARGS` in this process (the jobs of the fast tests): the exit status and the error line."""
    status = main(["tiles", *map(str, args)])
    return status, capsys.readouterr().err.strip().splitlines()[-1]


@pytest.mark.slow
def test_the_tiles_as_snakemake_jobs_give_the_normals_of_one_process(cloud, tmp_path):
    """Refine-Net on 2 strata of 2 tiles: the jobs (one thread each) give the normals, bit for bit, of one
    process with the same tiles (two threads), and leave nothing but the output behind."""
    whole = refinenet("normals", cloud, "-o", tmp_path / "whole.ply", "--tile-points", TILE_POINTS, "--strata", 2,
                      "--threads", 2)
    assert whole.returncode == 0, whole.stderr
    work = tmp_path / "work"
    work.mkdir()
    run = subprocess.run([sys.executable, "-m", "snakemake", "-s", REPO / "workflow" / "tiles.smk", "-j2", "--config",
                          f"input={cloud}", "output=tiled.ply", f"tile_points={TILE_POINTS}", "strata=2", "threads=1"],
                         cwd=work, capture_output=True, text=True, timeout=1200)
    assert run.returncode == 0, run.stderr[-3000:]
    assert run.stderr.count("rule tile:") == 4, run.stderr[-3000:]
    expected, tiled = read_cloud(tmp_path / "whole.ply"), read_cloud(work / "tiled.ply")
    np.testing.assert_array_equal(tiled.points, expected.points)
    np.testing.assert_array_equal(tiled.normals, expected.normals)
    assert sorted(p.name for p in work.iterdir()) == [".snakemake", "tiled.ply"]


@pytest.fixture
def jobs(cloud, tmp_path, capsys) -> tuple[Path, list[Path]]:
    """A PCA plan of the strip and its pieces."""
    plan = tmp_path / "plan.json"
    assert tiles(capsys, "plan", cloud, "-o", plan, "--method", "pca", "--tile-points", TILE_POINTS)[0] == 0
    pieces = [tmp_path / f"{job}.npz" for job in range(N_POINTS // TILE_POINTS)]
    for job, piece in enumerate(pieces):
        assert tiles(capsys, "run", plan, "--job", job, "-o", piece, "--threads", 1)[0] == 0
    return plan, pieces


def test_the_jobs_of_a_plan_give_the_normals_of_one_process(jobs, cloud, tmp_path, capsys):
    plan, pieces = jobs
    assert sum(json.loads(plan.read_text())["n_tiles"]) == len(pieces)
    assert tiles(capsys, "merge", plan, *pieces, "-o", tmp_path / "tiled.npy", "--orient", "none")[0] == 0
    assert main(["normals", str(cloud), "-o", str(tmp_path / "whole.npy"), "--method", "pca", "--orient", "none",
                 "--tile-points", str(TILE_POINTS)]) == 0
    np.testing.assert_array_equal(np.load(tmp_path / "tiled.npy"), np.load(tmp_path / "whole.npy"))


def test_merge_refuses_missing_repeated_and_foreign_pieces(jobs, tmp_path, capsys):
    plan, pieces = jobs
    out = tmp_path / "out.ply"
    status, line = tiles(capsys, "merge", plan, *pieces[:-1], "-o", out)
    assert status == 2 and f"{TILE_POINTS:,} of {N_POINTS:,} points have no normals" in line, line
    status, line = tiles(capsys, "merge", plan, *pieces, pieces[0], "-o", out)
    assert status == 2 and line.startswith(f"error: {pieces[0]}: gives normals another piece gave already"), line
    other = tmp_path / "other.xyz"
    np.savetxt(other, strip(seed=3), fmt="%.6f")
    assert tiles(capsys, "plan", other, "-o", tmp_path / "other.json", "--method", "pca")[0] == 0
    assert tiles(capsys, "run", tmp_path / "other.json", "--job", 0, "-o", tmp_path / "foreign.npz")[0] == 0
    status, line = tiles(capsys, "merge", plan, *pieces[1:], tmp_path / "foreign.npz", "-o", out)
    assert status == 2 and line == f"error: {tmp_path / 'foreign.npz'}: is a piece of another cloud's plan", line
    assert not out.exists()


def test_a_job_refuses_a_cloud_changed_since_its_plan_and_a_job_the_plan_has_not(jobs, cloud, tmp_path, capsys):
    plan, pieces = jobs
    n_jobs = len(pieces)
    status, line = tiles(capsys, "run", plan, "--job", n_jobs, "-o", tmp_path / "extra.npz")
    assert status == 2 and line == f"error: --job: must be 0 to {n_jobs - 1} ({plan} has {n_jobs} jobs), got {n_jobs}"
    changed = tmp_path / "changed.xyz"
    points = strip()
    points[0, 2] += 1e-3
    np.savetxt(changed, points, fmt="%.6f")
    moved = json.loads(plan.read_text()) | {"cloud": str(changed)}
    (tmp_path / "moved.json").write_text(json.dumps(moved))
    status, line = tiles(capsys, "run", tmp_path / "moved.json", "--job", 0, "-o", tmp_path / "stale.npz")
    assert status == 2 and line.startswith(f"error: {changed}: is not the cloud {tmp_path / 'moved.json'} was made "
                                           f"for"), line
    assert not (tmp_path / "stale.npz").exists() and not (tmp_path / "extra.npz").exists()


@pytest.mark.parametrize("text, problem", [("not json", "Expecting value"), ('{"format": 99}', "format is not 1"),
                                           ('{"format": 1}', "(no n_tiles)")])
def test_a_file_that_is_not_a_plan_is_refused_in_one_line(tmp_path, capsys, text, problem):
    plan = tmp_path / "plan.json"
    plan.write_text(text)
    status, line = tiles(capsys, "run", plan, "--job", 0, "-o", tmp_path / "piece.npz")
    assert status == 2 and line.startswith(f"error: {plan}: is not a plan of `refinenet tiles plan` ("), line
    assert problem in line
