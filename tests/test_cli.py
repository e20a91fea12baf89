"""`refinenet normals` on users' clouds: the shipped networks, the length unit for any size, tiles equal to the
whole cloud, oriented output in every format, and one-line errors."""

from __future__ import annotations

import json
import shutil
import subprocess
import sys
from dataclasses import replace
from pathlib import Path

import numpy as np
import pytest
import torch

from refinenet.cli.estimate import estimate_normals
from refinenet.data.io import read_cloud, read_normals
from refinenet.data.noise import add_gaussian_noise, bbox_diagonal
from refinenet.data.shapes import sample_shape
from refinenet.estimators.baselines import pca_normals
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.geometry.scale import point_spacing, spacing_unit
from refinenet.network.release import SHIPPED, half, load_release

REPO = Path(__file__).resolve().parents[1]


@pytest.fixture(scope="module")
def release():
    return load_release(SHIPPED)


def held_out(shape: str, n: int = 10_000, noise: float = 0.1) -> tuple[np.ndarray, np.ndarray]:
    """A test-split shape (never trained on) with a seed the pipeline does not use."""
    points, normals = sample_shape(shape, n, seed=77)
    return add_gaussian_noise(points, noise, seed=78), normals


def terrain(n: int, seed: int = 5) -> np.ndarray:
    """A noisy height field with a crease, 2 x 1 wide: large enough for tiles with real margins."""
    rng = np.random.default_rng(seed)
    xy = rng.random((n, 2)) * [2.0, 1.0]
    z = 0.1 * np.sin(3 * xy[:, 0]) * np.cos(2 * xy[:, 1]) + 0.2 * np.abs(xy[:, 0] - 1.0)
    return add_gaussian_noise(np.c_[xy, z], 0.05, seed=seed + 1)


def cli(*args: str | Path) -> subprocess.CompletedProcess:
    return subprocess.run([sys.executable, "-m", "refinenet.cli.main", *map(str, args)], cwd=REPO,
                          capture_output=True, text=True, timeout=600)


# ----------------------------------------------------------------------------------------------- shipped networks


def test_shipped_networks_improve_on_mfps_on_a_held_out_shape(release):
    """A RichFeature shape never trained on, at a test noise level. (The shipped networks come from the short CPU
    training of the default profile: like the committed table, they gain most on RichFeature and still lose to
    MFPS in mean error on SharpFeature shapes; the README says so.)"""
    points, truth = held_out("twistedstar_a")
    errors = {m: unoriented_angles(estimate_normals(points, release, m), truth).mean() for m in ("mfps", "refinenet")}
    assert errors["refinenet"] < 0.9 * errors["mfps"], errors


def test_bfloat16_feature_modules_keep_the_float32_accuracy(release):
    """The command's default on CPUs with native bfloat16 (`--precision auto`): the normals move by hundredths of
    a degree and the mean error by less than 0.01 deg."""
    points, truth = held_out("fandisk_a", 10_000, noise=0.1)
    normals = {"float32": estimate_normals(points, release),
               "bfloat16": estimate_normals(points, load_release(SHIPPED, precision="bfloat16"))}
    errors = {p: unoriented_angles(n, truth).mean() for p, n in normals.items()}
    assert abs(errors["bfloat16"] - errors["float32"]) < 0.01, errors
    assert unoriented_angles(normals["bfloat16"], normals["float32"]).mean() < 0.05


def test_release_card_describes_the_networks(release):
    card = release.card
    assert card["n_clusters"] == release.cluster_model.n_clusters == len(card["clusters"])
    assert card["parameters"]["total"] == card["parameters"]["per_cluster"] * len(release.networks)
    check = card["half_precision"]  # float16 storage leaves the accuracy unchanged to 0.01 degree
    assert abs(check["error_float16_deg"] - check["error_float32_deg"]) < 0.01
    assert 0 < release.spacing_ratio < 0.1
    assert (SHIPPED / "networks.pt").stat().st_size <= 25 * 2**20


def test_float16_storage_keeps_the_tensors_it_cannot_hold():
    """A BN running variance above float16's maximum (65,504) would load as inf and silence its channels."""
    stored = half({"weight": torch.tensor([0.5, -2.0]), "running_var": torch.tensor([1.0e5, 3.0]),
                   "num_batches_tracked": torch.tensor(7)})
    assert stored["weight"].dtype == torch.float16
    assert stored["running_var"].dtype == torch.float32
    assert stored["num_batches_tracked"].dtype == torch.int64


def test_a_release_from_before_the_output_setting_loads_as_regressing_the_normal(tmp_path):
    """Releases exported before `network.output` existed stored no such key; they regress the normal."""
    shutil.copytree(SHIPPED, tmp_path, dirs_exist_ok=True)
    bundle = torch.load(tmp_path / "networks.pt", weights_only=True)
    params, network = json.loads(bundle["params"]), json.loads(bundle["network"])
    params["network"].pop("output", None), network.pop("output", None)
    bundle["params"], bundle["network"] = json.dumps(params), json.dumps(network, sort_keys=True)
    torch.save(bundle, tmp_path / "networks.pt")
    old = load_release(tmp_path, with_networks=False)
    assert old.params.network.output == "normal"
    assert all(net.config.output == "normal" for net in load_release(tmp_path).networks.values())


# ------------------------------------------------------------------------------------------------------ the unit


def test_spacing_unit_follows_density_not_extent():
    """Four times the points on the same surface: half the spacing, so half the unit; scaled by 1000: 1000x."""
    rng = np.random.default_rng(0)
    sparse, dense = (np.c_[rng.random((n, 2)), np.zeros(n)] for n in (20_000, 80_000))
    assert point_spacing(dense) / point_spacing(sparse) == pytest.approx(0.5, rel=0.03)
    assert spacing_unit(sparse * 1000, 0.01) == pytest.approx(1000 * spacing_unit(sparse, 0.01), rel=1e-9)


def test_spacing_unit_is_the_diagonal_on_a_cloud_like_the_training_clouds(release):
    points, _ = held_out("bumpysphere_a")
    assert spacing_unit(points, release.spacing_ratio) == pytest.approx(bbox_diagonal(points), rel=0.15)


def test_normals_do_not_depend_on_units(release):
    points = terrain(6000)
    metres = estimate_normals(points, release, "mfps")
    millimetres = estimate_normals(points * 1000, release, "mfps")
    assert unoriented_angles(metres, millimetres).max() < 1e-3


# ------------------------------------------------------------------------------------------------------- tiles


def test_tiled_mfps_equals_the_whole_cloud(release):
    points = terrain(60_000)
    whole = estimate_normals(points, release, "mfps")
    tiled = estimate_normals(points, release, "mfps", tile_points=15_000)
    np.testing.assert_array_equal(tiled, whole)


@pytest.mark.parametrize("smooth_jet", [None, 1.5])
def test_tiled_refinenet_equals_the_whole_cloud(release, smooth_jet):
    """Also with the smooth-point jet, whose noise a tiled cloud measures on all its points."""
    features = replace(release.params.features, smooth_jet=smooth_jet)
    release = replace(release, params=replace(release.params, features=features))
    points = terrain(30_000)
    whole = estimate_normals(points, release, "refinenet")
    tiled = estimate_normals(points, release, "refinenet", tile_points=10_000)
    angles = unoriented_angles(whole, tiled)
    assert angles.max() < 1e-3, f"{(angles > 1e-3).sum()} points differ, by up to {angles.max():.3g} degrees"


# --------------------------------------------------------------------------------------------------- the command


@pytest.mark.parametrize("suffix", [".ply", ".pcd", ".xyz", ".txt", ".npy"])
def test_command_writes_oriented_normals_in_every_format(tmp_path, suffix):
    points, outward = held_out("torus_a", 3000, noise=0.0)
    source = tmp_path / "in.xyz"
    np.savetxt(source, points)
    out = tmp_path / f"out{suffix}"
    run = cli("normals", source, "-o", out, "--method", "pca")
    assert run.returncode == 0, run.stderr
    cloud = read_cloud(out)
    normals = cloud.normals if suffix != ".xyz" else read_normals(out.with_suffix(".normals"), len(points))
    np.testing.assert_allclose(cloud.points, points, atol=1e-6)
    assert (np.einsum("ij,ij->i", normals, outward) > 0).mean() >= 0.99


def test_command_refines_a_noisy_cad_shape_and_orients_it_outwards(tmp_path):
    points, outward = held_out("fandisk_a", 10_000, noise=0.1)
    source, out = tmp_path / "fandisk.ply", tmp_path / "fandisk_normals.ply"
    from refinenet.data.io import write_ply

    write_ply(source, points)
    run = cli("normals", source, "-o", out, "--timings", tmp_path / "stages.json")
    assert run.returncode == 0, run.stderr
    normals = read_cloud(out).normals
    assert (np.einsum("ij,ij->i", normals, outward) > 0).mean() >= 0.99
    assert unoriented_angles(normals, outward).mean() < unoriented_angles(pca_normals(points, 100), outward).mean()
    timings = json.loads((tmp_path / "stages.json").read_text())
    stages = {name: s for name, s in timings["stages"].items() if "/" not in name}
    assert list(stages) == ["read", "release", "strata rule", "layout", "neighbours", "mfps", "smooth jet",
                            "filtered normals", "height maps", "patches", "network", "orientation", "write"]
    assert timings["points"] == 10_000 and timings["strata"] == 1
    assert stages["network"]["calls"] == stages["patches"]["calls"] - 1 >= 10  # a batch of 1024 per call at most
    assert 0.5 * timings["wall_s"] < sum(s["wall_s"] for s in stages.values()) <= timings["wall_s"]
    steps = {name.removeprefix("mfps/"): s["wall_s"] for name, s in timings["stages"].items() if "/" in name}
    assert list(steps) == ["A.1 candidates", "A.2 bandwidth", "A.3 patches k=50", "A.3 patches k=100",
                           "A.3 patches k=150", "A.5 selection"]  # its kNN lists are the chain's `neighbours`
    assert sum(steps.values()) <= stages["mfps"]["wall_s"]


def test_command_refines_the_normals_of_another_estimator(tmp_path, release):
    points, truth = held_out("twistedstar_a", 10_000)
    source, initial, out = tmp_path / "star.npy", tmp_path / "pca.normals", tmp_path / "star.normals"
    np.save(source, points)
    pca = pca_normals(points, 30)
    np.savetxt(initial, pca)
    run = cli("normals", source, "-o", out, "--initial", initial, "--orient", "none")
    assert run.returncode == 0, run.stderr
    refined = read_normals(out, len(points))
    assert unoriented_angles(refined, truth).mean() < unoriented_angles(pca, truth).mean()


def test_viewpoint_orientation_faces_the_sensor(tmp_path):
    points = terrain(3000)
    source, out = tmp_path / "t.xyz", tmp_path / "t.npy"
    np.savetxt(source, points)
    run = cli("normals", source, "-o", out, "--method", "pca", "--orient", "viewpoint", "--viewpoint", "1", "0.5",
              "5")
    assert run.returncode == 0, run.stderr
    table = np.load(out)
    assert (np.einsum("ij,ij->i", table[:, 3:], [1, 0.5, 5] - table[:, :3]) >= 0).all()


def test_info_prints_the_model_card():
    run = cli("info")
    assert run.returncode == 0, run.stderr
    assert "Model card" in run.stdout and "Validation error" in run.stdout


def test_console_script_is_installed():
    script = Path(sys.executable).with_name("refinenet")
    assert script.exists(), "pip install -e . did not create the refinenet command"
    run = subprocess.run([script, "--help"], capture_output=True, text=True, timeout=60)
    assert run.returncode == 0 and "refinenet normals" in run.stdout


@pytest.mark.parametrize(("args", "problem"), [
    (["--method", "pca", "-o", "{tmp}/out.las"], "unsupported output type '.las'"),
    (["--method", "pca", "--initial", "{tmp}/x.normals", "-o", "{tmp}/out.ply"], "cannot be used with --method pca"),
    (["-o", "{tmp}/out.ply", "--tile-points", "0"], "--tile-points: must be at least 1"),
    (["-o", "{tmp}/out.ply", "--strata", "0"], "--strata: must be 'auto' or a whole number of at least 1"),
    (["-o", "{tmp}/out.ply", "--strata", "many"], "--strata: must be 'auto' or a whole number of at least 1"),
    (["-o", "{tmp}/out.ply", "--release", "{tmp}"], "no trained networks here"),
    (["-o", "{tmp}/few.xyz"], "few.xyz"),
    (["-o", "{tmp}/out.ply", "--timings", "{tmp}/stages.txt"], "--timings writes JSON: name a .json file"),
    (["-o", "{tmp}/out.ply", "--timings", str(SHIPPED / "model_card.json")], "model_card.json"),
])
def test_bad_arguments_fail_in_one_line_and_write_nothing(tmp_path, args, problem):
    source = tmp_path / "few.xyz"
    np.savetxt(source, terrain(150))  # fewer points than MFPS's largest neighbourhood (225)
    before = set(tmp_path.iterdir())
    run = cli("normals", source, *(a.format(tmp=tmp_path) for a in args))
    lines = run.stderr.strip().splitlines()
    assert run.returncode == 2 and len(lines) == 1 and lines[0].startswith("error: "), run.stderr
    assert problem in lines[0]
    assert set(tmp_path.iterdir()) == before


def test_strata_too_small_for_the_neighbourhood_fail_in_one_line(tmp_path):
    source = tmp_path / "t.xyz"
    np.savetxt(source, terrain(3000))
    run = cli("normals", source, "-o", tmp_path / "out.ply", "--method", "pca", "--strata", "40")
    assert run.returncode == 2 and run.stderr.startswith("error: --strata: 40 subsets of 3,000 points"), run.stderr
    assert not (tmp_path / "out.ply").exists()


def test_too_few_points_names_the_neighbourhood(tmp_path):
    source = tmp_path / "small.xyz"
    np.savetxt(source, terrain(150))
    run = cli("normals", source, "-o", tmp_path / "out.ply")
    assert run.returncode == 2 and "small.xyz" in run.stderr and "225" in run.stderr, run.stderr


# ----------------------------------------------------------------------------------------------------- denoise


def test_denoise_moves_a_noisy_sphere_onto_its_surface_and_writes_the_surface(tmp_path):
    """A unit sphere with 0.2% radial-ish Gaussian noise and exact outward normals (40k points): the mean distance
    to the sphere drops at least 3x, and the Poisson surface of the result lies on the sphere."""
    points, normals = sample_shape("sphere_a", 40_000, seed=77)
    centre = points.mean(axis=0)
    radius = np.linalg.norm(points - centre, axis=1).mean()
    noisy = add_gaussian_noise(points, 0.2, seed=3)
    cloud = tmp_path / "noisy.npy"
    np.save(cloud, np.c_[noisy, normals])
    run = cli("denoise", cloud, "-o", tmp_path / "out.ply", "--surface", tmp_path / "surface.ply")
    assert run.returncode == 0, run.stderr
    out = read_cloud(tmp_path / "out.ply")
    before, after = (np.abs(np.linalg.norm(p - centre, axis=1) - radius).mean() for p in (noisy, out.points))
    assert after < before / 3, (before, after)
    np.testing.assert_allclose(out.normals, normals, atol=1e-6)  # the normals are kept
    import open3d as o3d

    vertices = np.asarray(o3d.io.read_triangle_mesh(str(tmp_path / "surface.ply")).vertices)
    assert len(vertices) > 1000
    assert np.median(np.abs(np.linalg.norm(vertices - centre, axis=1) - radius)) < before


@pytest.mark.parametrize(
    ("args", "problem"),
    [
        (("--radius", "0"), "command line: denoise.radius: 0.0 is less than or equal to the minimum of 0"),
        (("--surface", "mesh.stl"), "mesh.stl: unsupported surface type"),
        (("--normals", "missing.normals"), "missing.normals"),
    ],
)
def test_denoise_bad_arguments_fail_in_one_line_and_write_nothing(tmp_path, args, problem):
    points, normals = sample_shape("sphere_a", 500, seed=1)
    cloud = tmp_path / "c.npy"
    np.save(cloud, np.c_[points, normals])
    run = cli("denoise", cloud, "-o", tmp_path / "out.ply", *args)
    assert run.returncode == 2 and problem in run.stderr and run.stderr.count("\n") == 1, run.stderr
    assert not (tmp_path / "out.ply").exists()


def test_denoise_without_normals_says_how_to_get_them(tmp_path):
    cloud = tmp_path / "bare.xyz"
    np.savetxt(cloud, sample_shape("sphere_a", 500, seed=1)[0])
    run = cli("denoise", cloud, "-o", tmp_path / "out.ply")
    assert run.returncode == 2 and "has no normals: give them with --normals" in run.stderr
