"""Stage entry points: a bad input file or value ends with one line naming it, exit 2, and no output."""

import subprocess
import sys
from pathlib import Path

import numpy as np
import pytest

REPO = Path(__file__).resolve().parents[1]


def stage(module: str, *args: str) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", f"stages.{module}", *args], cwd=REPO, capture_output=True, text=True)


BAD_FILES = {
    "empty.xyz": "",
    "truncated.xyz": "0 0 0\n1 0 0\n0 1",
    "text.xyz": "0 0 0\nx y z\n",
    "nan.xyz": "0 0 0\nnan 0 1\n",
    "inf.xyz": "0 0 0\n1 inf 1\n",
    "columns.xyz": "0 0 0 0\n1 1 1 1\n",
}


@pytest.mark.parametrize("name", [*BAD_FILES, "few.xyz"])
def test_baseline_stage_rejects_bad_clouds(tmp_path, name):
    path = tmp_path / name
    path.write_text(BAD_FILES.get(name, "\n".join(f"{i} {i * i} 0" for i in range(50))))  # K = 100 in params
    out = tmp_path / "out.npy"
    run = stage("baselines", "--method", "pca", "--cloud", str(path), "--out", str(out))
    assert run.returncode == 2
    lines = run.stderr.strip().splitlines()
    assert len(lines) == 1 and lines[0].startswith(f"error: {path}:"), run.stderr
    assert not out.exists() and [p.name for p in tmp_path.iterdir()] == [name]


def test_baseline_stage_writes_normals(tmp_path):
    rng = np.random.default_rng(0)
    points = np.c_[rng.uniform(size=(500, 2)), np.zeros(500)]
    np.savetxt(tmp_path / "plane.xyz", points)
    run = stage("baselines", "--method", "jet", "--cloud", str(tmp_path / "plane.xyz"),
                "--out", str(tmp_path / "plane.normals"))
    assert run.returncode == 0, run.stderr
    normals = np.loadtxt(tmp_path / "plane.normals")
    np.testing.assert_allclose(np.abs(normals[:, 2]), 1, atol=1e-9)


def test_cloud_stage_rejects_missing_mesh(tmp_path):
    (tmp_path / "meshes/test/sharp").mkdir(parents=True)
    (tmp_path / "meshes/test/sharp/m.off").write_text("OFF\n3 1 0\n0 0 0\n1 0 0\n0 1 0\n3 0 1 7\n")
    params = tmp_path / "params.yaml"
    params.write_text((REPO / "params.yaml").read_text().replace("source: procedural", "source: meshes", 1)
                      .replace("path: null", f"path: {tmp_path / 'meshes'}", 1))
    out = tmp_path / "c.npz"
    run = stage("clouds", "--params", str(params), "--cloud", "test/SharpFeature/m_n0.10", "--out", str(out))
    assert run.returncode == 2 and "m.off" in run.stderr and len(run.stderr.strip().splitlines()) == 1
    assert not out.exists()


def test_every_stage_names_the_bad_params_key(tmp_path):
    params = tmp_path / "params.yaml"
    params.write_text((REPO / "params.yaml").read_text().replace("  pca_k: 100", "  pca_k: -5", 1))
    run = stage("baselines", "--params", str(params), "--method", "pca", "--cloud", "x.xyz", "--out", "x.npy")
    assert run.returncode == 2
    assert run.stderr.strip() == f"error: {params}: baselines.pca_k: -5 is less than the minimum of 3"


def test_a_full_disk_fails_with_one_line_and_leaves_no_file(tmp_path):
    """ENOSPC on a 64 kB tmpfs (needs root to mount; skipped otherwise): one line, exit 2, nothing left behind."""
    full = tmp_path / "full"
    full.mkdir()
    mounted = subprocess.run(["mount", "-t", "tmpfs", "-o", "size=64k", "tmpfs", str(full)], capture_output=True)
    if mounted.returncode != 0:
        pytest.skip(f"cannot mount a tmpfs here ({mounted.stderr.decode().strip() or 'not root'})")
    try:
        rng = np.random.default_rng(0)
        np.savetxt(tmp_path / "plane.xyz", np.c_[rng.uniform(size=(20000, 2)), np.zeros(20000)])
        out = full / "plane.normals"
        run = stage("baselines", "--method", "pca", "--cloud", str(tmp_path / "plane.xyz"), "--out", str(out))
        assert run.returncode == 2
        assert run.stderr.strip() == f"error: {out}: cannot be written (No space left on device)"
        assert list(full.iterdir()) == []
    finally:
        subprocess.run(["umount", str(full)], check=True)
