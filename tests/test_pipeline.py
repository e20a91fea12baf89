"""End to end on the smoke profile: Snakemake and DVC build the same files, each leaves the other nothing
to do, a params change reruns the same steps in both tools, every file a step writes is one of its declared
outputs (so nothing a step made is pruned, and DVC caches it), and the real-scan setting X = 8 runs. Minutes,
so marked slow. Every run here has the programs that steps need beyond the Python environment (pdflatex) hidden
from its PATH, as on a machine without them, so that the checks are the same on either; one test builds the PDF
where pdflatex is installed."""

import json
import os
import shutil
import subprocess
import sys
import time
from pathlib import Path

import numpy as np
import pandas as pd
import pytest
import slurm_cluster
from browser import open_page
from kill_anywhere import kill_anywhere, passed
from scratch import isolated, path_without, set_param, sh, smoke_copy, snakemake

from refinenet import config
from refinenet.data import shapes
from refinenet.data.clouds import scored_points
from refinenet.data.io import read_cloud, read_normals
from refinenet.data.noise import add_gaussian_noise
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.features.cache import load_features
from refinenet.pipeline.bridge import produced
from refinenet.pipeline.catalogue import DENOISE_TABLE, MAIN, SCAN_TABLE
from refinenet.pipeline.catalogue import TABLES as EVALUATED
from refinenet.pipeline.layout import (
    CHECKPOINT_DIR,
    CLOUD,
    FIGURE_REAL,
    HISTORY,
    NETWORK,
    REFINED,
    REPORT_FILES,
    SCAN,
    TABLES_PDF,
    TIME_FILES,
)
from refinenet.pipeline.methods import FULL
from refinenet.pipeline.page import reported
from refinenet.pipeline.workflow import Pipeline

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[1]
#: Seconds the uninterrupted smoke run of the main job took, for spreading the kills of the kill-anywhere test.
LENGTH: dict[str, float] = {}
#: What Snakemake's default target printed (its log, on stderr) in `by_snakemake`.
LOG: dict[str, str] = {}
TABLE = "reports/table_synthetic.csv"


@pytest.fixture(scope="module", autouse=True)
def real_path(tmp_path_factory):
    """The module's runs on a PATH without the programs that steps need (`NEEDED`); returns the real PATH."""
    real = os.environ["PATH"]
    with pytest.MonkeyPatch.context() as patch:
        patch.setenv("PATH", path_without(NEEDED, tmp_path_factory.mktemp("path")))
        yield real


@pytest.fixture(scope="module")
def by_snakemake(tmp_path_factory):
    """The main job, timed (the kill-anywhere test spreads its kills over it), then every other table."""
    repo = smoke_copy(tmp_path_factory.mktemp("snakemake"))
    began = time.monotonic()
    snakemake(repo, "-j2", "main")
    LENGTH["snakemake"] = time.monotonic() - began
    shutil.copytree(repo / "reports", repo.parent / "main_page")  # the main job's page, before the full run's
    LOG["snakemake"] = snakemake(repo, "-j2").stderr
    return repo


@pytest.fixture(scope="module")
def by_dvc(tmp_path_factory):
    """The main job, one ablation variant's table and the scan table through DVC: a second fresh run, stage by
    stage (another job order than Snakemake's). Not every stage: DVC runs them one at a time, so the whole smoke
    set took 32 minutes here against Snakemake's 17 on two cores; the other variants are the same stages with
    other settings, and the first test checks DVC's record of Snakemake's whole run."""
    repo = smoke_copy(tmp_path_factory.mktemp("dvc"))
    sh(repo, "dvc", "repro", *BY_DVC, env={"REFINENET_CORES": "2"})
    return repo


def dvc_changed_stages(repo: Path, *targets: str) -> set[str]:
    return set(json.loads(sh(repo, "dvc", "status", "--json", *targets).stdout or "{}"))


def snakemake_changed_rules(repo: Path) -> set[str]:
    rows = [line.split("\t") for line in snakemake(repo, "--summary").stdout.splitlines()[1:]]
    return {r[2] for r in rows if len(r) > 4 and r[4] != "ok"}


def test_snakemake_leaves_dvc_nothing_to_do(by_snakemake):
    table = pd.read_csv(by_snakemake / TABLE, index_col=0)
    assert list(table.index) == ["PCA", "Jet", "MFPS", "simple MFPS", "Refine-Net"] and "Average/mean" in table.columns
    # MFPS is built for sharp features: it must beat both baselines there (docs/algorithm.md §2).
    assert table.loc["MFPS", "SharpFeature/mean"] < min(table.loc["PCA", "SharpFeature/mean"],
                                                         table.loc["Jet", "SharpFeature/mean"])
    assert dvc_changed_stages(by_snakemake) == SKIPPED


def test_without_pdflatex_snakemake_skips_report_pdf_saying_so_and_dvc_repro_fails_there(by_snakemake):
    """Snakemake's default target leaves out the PDF of the tables, with a message; `dvc repro` cannot leave a
    stage out: it has nothing to run but report_pdf, and fails there with the one-line error of its stage script,
    which names what to install."""
    assert "skipping report_pdf: pdflatex is not installed" in LOG["snakemake"]
    assert not (by_snakemake / TABLES_PDF).exists()
    run = subprocess.run(["dvc", "repro"], cwd=by_snakemake, env=isolated(by_snakemake), capture_output=True,
                         text=True)
    assert run.returncode != 0
    assert {line.split("'")[1] for line in run.stdout.splitlines() if line.startswith("Running stage")} == SKIPPED
    assert ("error: reports/tables.pdf: pdflatex not found: install TeX Live (Debian: texlive-latex-recommended) to "
            "build it") in run.stdout + run.stderr
    assert dvc_changed_stages(by_snakemake) == SKIPPED


def test_where_pdflatex_is_installed_snakemake_compiles_the_tables_into_one_pdf(by_snakemake, real_path,
                                                                               monkeypatch):
    """With the real PATH, the default target has report_pdf left to build, and records it in dvc.lock. The copy
    is then put back as the run left it (the PDF removed, dvc.lock restored) for the other tests."""
    if shutil.which("pdflatex", path=real_path) is None:
        pytest.skip("pdflatex not installed (Debian: apt-get install texlive-latex-recommended); the PDF of the "
                    "pipeline's tables is not checked")
    monkeypatch.setenv("PATH", real_path)
    lock = (by_snakemake / "dvc.lock").read_bytes()
    try:
        run = snakemake(by_snakemake, "-j2")
        assert "skipping" not in run.stderr
        assert (by_snakemake / TABLES_PDF).read_bytes().startswith(b"%PDF")
        assert dvc_changed_stages(by_snakemake) == set()
    finally:
        (by_snakemake / TABLES_PDF).unlink(missing_ok=True)
        (by_snakemake / "dvc.lock").write_bytes(lock)


def test_snakemake_builds_every_report(by_snakemake):
    # csv, tex, per-cloud csv, metrics record of each table, of table_denoise, table_scans and table_time; the
    # sweeps' (Kc, seeds) plots; the architecture table's csv, tex and layers; paper_comparison's md and tex; the
    # normals, clusters, denoising, L1/L2 and scan figures' png and pdf, and the training curves of every trained
    # variant; the page and the LaTeX of every table (not its PDF: pdflatex is hidden)
    reports = [p for p in (by_snakemake / "reports").rglob("*") if p.is_file()]
    sweeps = sum(1 for table in EVALUATED.values() if table.sweep)
    assert len(reports) == 4 * (len(TABLES) + 3) + sweeps + 3 + 2 + 2 * (4 + len(REAL)) + len(PIPELINE.trained) + 2
    time_table = pd.read_csv(by_snakemake / TIME_FILES["csv"], index_col=0)
    assert (time_table["s per 1k points"] > 0).all() and time_table.loc["network", "parameters per cluster"] > 0


def declared_files(repo: Path, steps: tuple[str, ...]) -> list[Path]:
    """Every file of the named steps' declared outputs (folders walked), relative to the copy."""
    outs = [repo / out for step in map(PIPELINE.steps.get, steps) for out in (*step.outs, *step.metrics)]
    return sorted(f.relative_to(repo) for out in outs for f in ([out] if out.is_file() else out.rglob("*"))
                  if f.is_file())


def test_dvc_builds_the_same_files_and_leaves_snakemake_nothing_to_do(by_dvc, by_snakemake):
    """Two fresh runs, -j1 through DVC and -j2 through Snakemake: every file of the steps DVC ran (the tables, the
    release's networks and model card) is bit-identical."""
    files = declared_files(by_snakemake, BY_DVC)
    assert files == declared_files(by_dvc, BY_DVC)
    assert any(f.name == "networks.pt" for f in files) and Path("reports/table_loss.csv") in files
    for name in files:
        assert (by_dvc / name).read_bytes() == (by_snakemake / name).read_bytes(), name
    assert "Nothing to be done" in snakemake(by_dvc, "-n", *BY_DVC_TARGETS).stdout
    second = sh(by_dvc, "dvc", "repro", *BY_DVC).stdout
    assert "Data and pipelines are up to date" in second
    assert "Running stage" not in second


def test_the_main_jobs_page_shows_its_figures_and_every_committed_table_in_a_browser(by_snakemake):
    """After the smoke main job, headless Chromium opens its page: the normals figure and the release's training
    curves load, the main tables have rows, and every table the repository holds that the main job does not make
    is there, marked as not rebuilt (the copy commits nothing: as an earlier run's); what nothing made is listed
    with its target."""
    tables, figures = reported(PIPELINE, main=True)
    page = open_page(by_snakemake.parent / "main_page" / "index.html")
    kept = [t for t in tables if not t.made and (REPO / "reports" / t.csv).is_file()]
    kept_figures = [f for f in figures if not f.made and (REPO / "reports" / f.png).is_file()]  # the sweeps' plots
    assert page.images == {f.png: "yes" for f in figures if f.made or f in kept_figures}
    assert page.body.get("data-missing-images") == "0"
    assert kept and len(page.tables) == len([t for t in tables if t.made]) + len(kept) and min(page.tables) >= 1
    html = (by_snakemake.parent / "main_page" / "index.html").read_text()
    assert html.count("not rebuilt by this run") == len(kept) + len(kept_figures) + 1  # and the paper comparison
    assert f"<code>snakemake -j2 {FIGURE_REAL['png']}</code>" in html  # no figure of x8 is committed


def test_the_report_page_shows_every_table_and_figure_in_a_browser(by_snakemake):
    """reports/index.html opened from the file system in headless Chromium: every figure loads, and every table of
    the run is there with rows."""
    tables, figures = reported(PIPELINE)
    page = open_page(by_snakemake / REPORT_FILES["html"])
    assert page.images == {f.png: "yes" for f in figures}
    assert page.body.get("data-missing-images") == "0"
    assert len(page.tables) == len(tables) and min(page.tables) >= 1


def test_the_scan_table_scores_every_method_on_the_simulated_scans(by_snakemake):
    """table_scans: each method on the smoke profile's two scans (fandisk_a, bumpysphere_a), every point scored.
    PCA with K = 100 on the bumpy sphere, whose curvature is low at that reach, averages the range noise away: its
    mean error stays within a few degrees; on the fandisk's edges it cannot."""
    table = pd.read_csv(by_snakemake / f"reports/{SCAN_TABLE}.csv", index_col=0)
    assert list(table.index) == ["PCA", "Jet", "MFPS", "Refine-Net", "Refine-Net x8"]
    assert table.loc["PCA", "SmoothSurface/mean"] < 3 < table.loc["PCA", "SharpFeature/mean"]
    pgp = table[[c for c in table.columns if "/pgp" in c]].to_numpy()
    assert ((0 <= pgp) & (pgp <= 1)).all()
    per_cloud = pd.read_csv(by_snakemake / f"reports/per_cloud/{SCAN_TABLE}.csv")
    for shape in ("fandisk_a", "bumpysphere_a"):
        points = read_cloud(by_snakemake / SCAN.format(shape=shape)).points
        assert (per_cloud[per_cloud["cloud"] == shape]["n"] == len(points)).all(), shape


def test_denoising_moves_points_and_measures_the_noisy_input_at_its_noise_level(by_snakemake):
    """The noisy input lies |N(0, s)| from its true surface: a mean of s sqrt(2/pi), s = noise % of l_d (in the
    table's 10^-3 l_d). Each method's row is measured on the same clouds."""
    table = pd.read_csv(by_snakemake / f"reports/{DENOISE_TABLE}.csv", index_col=0)
    assert list(table.index) == ["noisy input", "PCA", "MFPS", "Refine-Net"]
    smoke = config.load(by_snakemake / "params.yaml")
    for category, (level,) in smoke.noise.test.items():
        expected = 10 * level * np.sqrt(2 / np.pi)
        assert table.loc["noisy input", f"{category}/mean"] == pytest.approx(expected, rel=0.35), category
    assert (table.to_numpy() > 0).all()


def test_the_variants_refine_the_same_seeded_subset_of_each_test_cloud_and_full_every_point(by_snakemake):
    """The smoke profile's variant budget: every variant, reference (full's settings under it) included, refines
    the same 500 seeded points of each 1,000-point test cloud, NaN elsewhere; full refines every point."""
    smoke = Pipeline(config.read_raw(by_snakemake / "params.yaml"))
    assert smoke.params["reference"].inference.points == 500 and smoke.full.inference.points is None
    for key in smoke.keys("test"):
        scored = scored_points(read_cloud(by_snakemake / CLOUD.format(cloud=key)), 500)
        assert len(scored) == 500
        for variant in ("reference", "l1", "kc2", "seed2023"):
            refined = np.loadtxt(by_snakemake / REFINED.format(variant=variant, cloud=key))
            np.testing.assert_array_equal(np.flatnonzero(np.isfinite(refined).all(axis=1)), scored, err_msg=variant)
        assert np.isfinite(np.loadtxt(by_snakemake / REFINED.format(variant=FULL, cloud=key))).all()


PIPELINE = Pipeline(config.read_raw(REPO / "params.yaml"))
STEPS = set(PIPELINE.steps)
#: The programs that steps need beyond the Python environment, hidden from this module's runs (`real_path`).
NEEDED = {step.needs for step in PIPELINE.steps.values() if step.needs}
#: The steps that need them: Snakemake's default target skips them, so DVC sees them as not run.
SKIPPED = {name for name, step in PIPELINE.steps.items() if step.needs}
#: The steps of Snakemake's run that no other of its steps reads: every other step is upstream of one of them (the
#: skipped report_pdf reads report's LaTeX).
SNAKEMAKE_ENDS = ("release", "report")
MAIN_TABLES = {"table_baselines", "table_synthetic", "table_synthetic_pgp"}
#: The evaluated tables; `paper_comparison`, which reads their CSV files, names the data and protocol too.
TABLES = set(EVALUATED)
#: Every table with a Refine-Net row: its caption names Refine-Net's settings, MFPS's (its initial normals) included.
REFINENET_TABLES = TABLES - {"table_baselines"}
#: The release bundles the run's whole resolved params (full's: not the variants).
RELEASE = {"release"}
#: table_time names the data, MFPS's, the features', the network's and Kc's settings in its caption.
TIME = {"table_time"}
SEEDED = {name for name, step in PIPELINE.steps.items() if "seed" in step.keys}
#: The scan figure and table: each computes the baselines', MFPS's, the features' and the network's normals of each
#: simulated scan itself, through the chain of `refinenet normals`.
REAL = {"fig_real"}
SCANS = {"table_scans"}
#: The figures name the data in their footers; the normals figures show the estimators' normals.
FIGURES = {"fig_normals", "fig_clusters", "fig_training", "fig_denoise", "fig_loss"} | REAL
NORMALS_FIGURE = {"fig_normals"} | REAL
#: The page shows every setting, so every params change remakes it.
REPORT = {"report"}
#: What the DVC run builds: the main job, the L1/L2 ablation's table (its variants train networks of their own)
#: and the scan table (variant x8's networks and the release on the simulated scans).
BY_DVC = (*MAIN, "table_loss", SCAN_TABLE)
#: Its files, as Snakemake targets.
BY_DVC_TARGETS = [t for name in BY_DVC for t in PIPELINE.steps[name].targets()]


def family(name: str) -> set[str]:
    """Every variant's instance of a step."""
    return {step.name for step in PIPELINE.family(name)}


@pytest.mark.parametrize(
    ("old", "new", "steps"),
    [
        # PCA and Jet also start the Refine-Net of table_initial, which trains on their normals
        ("  jet_k: 100", "  jet_k: 90",
         family("baselines") | MAIN_TABLES | {"table_initial", "table_pcpnet"} | RELEASE | NORMALS_FIGURE | SCANS
         | REPORT),
        ("  theta_t: 60", "  theta_t: 45",
         family("mfps") | REFINENET_TABLES | RELEASE | TIME | NORMALS_FIGURE | SCANS | REPORT),
        ("  protocol: synthetic", "  protocol: pcpnet", TABLES | {"paper_comparison"} | RELEASE | REPORT),
        ("seed: 2022", "seed: 7", SEEDED | RELEASE),  # the page tracks the seed: in SEEDED
        ("data: {n_points: 1000, max_shapes: 1}", "data: {n_points: 900, max_shapes: 1}",
         {"clouds_train", "clouds_test", "paper_comparison", DENOISE_TABLE} | TABLES | RELEASE | TIME | FIGURES
         | SCANS | REPORT),
        ("  hmp_k: 100", "  hmp_k: 90",
         family("features") | REFINENET_TABLES | RELEASE | TIME | NORMALS_FIGURE | SCANS | REPORT),
        # the denoising application (and the release, whose settings `refinenet denoise` uses)
        ("  sigma: 0.35", "  sigma: 0.3", {"denoise", DENOISE_TABLE, "fig_denoise"} | RELEASE | REPORT),
        ("  n_clusters: 4", "  n_clusters: 3",
         family("clustering") | REFINENET_TABLES | RELEASE | TIME | {"fig_normals", "fig_clusters"} | REPORT),
        ("  batch_size: 1024\n  device", "  batch_size: 512\n  device",
         family("inference") | RELEASE | REAL | SCANS | REPORT),
        # the simulated scans' sensor: the scans, their table and the page, which shows every setting (the figure
        # follows the new scans)
        ("  views: 3", "  views: 2", {"simulate_scans", "table_scans"} | REPORT),
        # a variant's overrides: its training and the table naming it (its inference follows the new networks)
        ("  l1: {training: {loss: l1}}", "  l1: {training: {loss: l1, lr: 0.01}}",
         {"training_l1", "table_loss"} | REPORT),
    ],
)
def test_a_params_change_reruns_the_same_steps_in_both_tools(by_snakemake, old, new, steps):
    set_param(by_snakemake, old, new)
    try:
        rules = snakemake_changed_rules(by_snakemake)
        assert dvc_changed_stages(by_snakemake) == steps | SKIPPED
        assert rules == steps
    finally:
        set_param(by_snakemake, new, old)
    assert dvc_changed_stages(by_snakemake) == SKIPPED


def test_bad_params_value_fails_with_one_line(by_snakemake):
    set_param(by_snakemake, "  pca_k: 100", "  pca_k: -5")
    try:
        run = subprocess.run([sys.executable, "-m", "snakemake", "-n"], cwd=by_snakemake, env=isolated(by_snakemake),
                             capture_output=True, text=True)
    finally:
        set_param(by_snakemake, "  pca_k: -5", "  pca_k: 100")
    assert run.returncode != 0
    assert "error: params.yaml: baselines.pca_k: -5 is less than the minimum of 3" in run.stderr


def trained_files(repo: Path) -> dict[str, bytes]:
    """Every file of every cluster's network folder and training history, by path."""
    params = config.load(repo / "params.yaml")
    files = {}
    for c in range(params.clustering.n_clusters):
        network = repo / NETWORK.format(variant=FULL, cluster=c)
        assert (network / "result.json").is_file()
        assert (network / "best.pt").is_file() or (network / "empty.json").is_file()
        assert (repo / HISTORY.format(variant=FULL, cluster=c)).is_file()
        for path in [*network.iterdir(), repo / HISTORY.format(variant=FULL, cluster=c)]:
            files[str(path.relative_to(repo))] = path.read_bytes()
    return files


@pytest.mark.parametrize("tool", ["snakemake", "dvc"])
def test_the_trained_networks_survive_the_run_and_are_in_the_dvc_cache(by_snakemake, by_dvc, tool):
    """Snakemake's whole run or DVC's own stages. `sync` of every step would refuse while the skipped report_pdf
    is not run, so Snakemake's run is synced by its last steps."""
    repo, stages, synced, targets = ((by_snakemake, (), SNAKEMAKE_ENDS, ()) if tool == "snakemake" else
                                     (by_dvc, BY_DVC, BY_DVC, BY_DVC_TARGETS))
    before = trained_files(repo)
    assert any(name.endswith("best.pt") for name in before)
    assert dvc_changed_stages(repo, *stages) == (SKIPPED if tool == "snakemake" else set())
    for name in before:
        (repo / name).unlink()
    sh(repo, "dvc", "checkout", "--quiet", *(("--with-deps", *stages) if stages else ()))
    assert trained_files(repo) == before
    sh(repo, sys.executable, "-m", "refinenet.pipeline.bridge", "sync", *synced)
    assert "Nothing to be done" in snakemake(repo, "-n", *targets).stdout


def test_a_run_pushed_to_a_shared_cache_and_pulled_into_a_fresh_clone_leaves_both_tools_nothing_to_do(
        by_dvc, tmp_path):
    """The team set-up of the README: a directory remote (a cluster's shared file system) added with one command
    and committed; a finished run pushed; a fresh clone elsewhere pulls it, syncs Snakemake, and has nothing to
    run in either tool, with the same reports and networks."""
    assert dvc_changed_stages(by_dvc, *BY_DVC) == set()
    sh(by_dvc, "dvc", "remote", "add", "--default", "shared", str(tmp_path / "cache"))
    sh(by_dvc, "dvc", "push", "--quiet")
    sh(by_dvc, "git", "add", "-A")
    sh(by_dvc, "git", "-c", "user.name=test", "-c", "user.email=test@example.org", "commit", "-qm", "a finished run")
    clone = tmp_path / "clone"
    sh(tmp_path, "git", "clone", "-q", str(by_dvc), str(clone))
    assert not (clone / "results").exists()
    sh(clone, "dvc", "pull", "--quiet", "--with-deps", *BY_DVC)
    sh(clone, sys.executable, "-m", "refinenet.pipeline.bridge", "sync", *BY_DVC)
    assert "Nothing to be done" in snakemake(clone, "-n", *BY_DVC_TARGETS).stdout
    assert dvc_changed_stages(clone, *BY_DVC) == set()
    assert trained_files(clone) == trained_files(by_dvc)
    reports = [p.relative_to(by_dvc) for p in (by_dvc / "reports").rglob("*") if p.is_file()]
    assert reports and all((clone / name).read_bytes() == (by_dvc / name).read_bytes() for name in reports)


@pytest.mark.parametrize("tool", ["snakemake", "dvc"])
def test_every_file_a_step_writes_is_a_declared_output(by_snakemake, by_dvc, tool):
    """Walk results/ and reports/: each file is a target of the step whose output folder holds it, or a training
    checkpoint (kept outside every output on purpose, so that a killed run resumes)."""
    repo = by_snakemake if tool == "snakemake" else by_dvc
    steps = Pipeline(config.read_raw(repo / "params.yaml")).steps.values()
    owners = {Path(out): step for step in steps for out in (*step.outs, *step.plots, *step.metrics)}
    for folder in ("results", "reports"):
        for path in (repo / folder).rglob("*"):
            relative = path.relative_to(repo)
            if not path.is_file() or Path(CHECKPOINT_DIR).parent in relative.parents or path.name == ".gitignore":
                continue
            step = next((s for out, s in owners.items() if out == relative or out in relative.parents), None)
            assert step is not None, f"{relative} lies in no step's outputs"
            targets = [str(repo / t) for t in step.targets()]
            assert produced(path, targets), f"{relative} is not a declared output of {step.name}"


def test_an_inference_only_change_reruns_inference_and_keeps_the_networks(by_snakemake):
    """Which steps rerun is checked above; here the rerun itself succeeds on the networks the run kept."""
    networks = trained_files(by_snakemake)
    refined = next((by_snakemake / REFINED.format(variant=FULL, cloud="test")).parent.rglob("*.normals"))
    stamp = refined.stat().st_mtime_ns
    set_param(by_snakemake, "  batch_size: 1024\n  device", "  batch_size: 300\n  device")
    try:
        snakemake(by_snakemake, "-j2", "main")
        assert refined.stat().st_mtime_ns != stamp
        assert trained_files(by_snakemake) == networks
        # the main job is recorded; the variants' inference (and the tables beside the main job's, and the page,
        # which shows every setting) remain, as does the skipped report_pdf
        changed = dvc_changed_stages(by_snakemake)
        remaining = family("inference") | TABLES | {"paper_comparison"} | REAL | SCANS | REPORT | SKIPPED
        assert family("inference") - {"inference"} | SKIPPED <= changed <= remaining - {"inference"} - MAIN_TABLES, \
            changed
    finally:
        set_param(by_snakemake, "  batch_size: 300\n  device", "  batch_size: 1024\n  device")
    snakemake(by_snakemake, "-j2", "main")
    assert dvc_changed_stages(by_snakemake) == SKIPPED | REPORT  # the page is the main job's now, not DVC's
    snakemake(by_snakemake, "-j2")
    assert dvc_changed_stages(by_snakemake) == SKIPPED


def test_dvc_reruns_only_inference_after_an_inference_only_change(by_dvc):
    set_param(by_dvc, "  batch_size: 1024\n  device", "  batch_size: 300\n  device")
    try:
        out = sh(by_dvc, "dvc", "repro", *MAIN).stdout
        ran = {line.split("'")[1] for line in out.splitlines() if line.startswith("Running stage")}
        assert "inference" in ran and not ran & (STEPS - {"inference", "release", "fig_normals"} - TABLES), ran
    finally:
        set_param(by_dvc, "  batch_size: 300\n  device", "  batch_size: 1024\n  device")
    sh(by_dvc, "dvc", "repro", *MAIN)
    assert dvc_changed_stages(by_dvc, *BY_DVC) == set()


def pcpnet_folder(folder: Path, n_points: int = 1000, scored: int = 100) -> dict[str, str]:
    """A small PCPNet-format folder from the procedural shapes: one training shape, one test shape per column of
    the paper's table (the noise columns at their sigma, the density ones clean), each with `.xyz`, `.normals` and a
    `.pidx` of `scored` points, and the list files params.yaml names. Returns column (or train) -> shape."""
    folder.mkdir()
    names = [n for n, spec in shapes.catalogue().items() if spec.category == shapes.SHARP]
    columns = {"None": 0.0, "0.00125": 0.125, "0.006": 0.6, "0.012": 1.2, "Gradient": 0.0, "Stripes": 0.0}
    made = {**{column: (names[0], sigma) for column, sigma in columns.items()}, "train": (names[1], 0.6)}
    lists = {column: (f"{name}_{column}", sigma) for column, (name, sigma) in made.items()}
    rng = np.random.default_rng(0)
    for i, (name, (shape, sigma)) in enumerate(zip([n for n, _ in made.values()], lists.values(), strict=True)):
        points, normals = shapes.sample_shape(name, n_points, seed=i)
        np.savetxt(folder / f"{shape}.xyz", add_gaussian_noise(points, sigma, seed=i), fmt="%.6f")
        np.savetxt(folder / f"{shape}.normals", normals, fmt="%.6f")
        np.savetxt(folder / f"{shape}.pidx", np.sort(rng.choice(n_points, scored, replace=False)), fmt="%d")
    params = config.read_raw(REPO / "params.yaml")["data"]["pcpnet"]
    for column, list_file in [("train", params["train_list"]), *params["test_lists"].items()]:
        (folder / list_file).write_text(lists[column][0] + "\n")
    return {column: shape for column, (shape, _) in lists.items()}


def test_the_pcpnet_table_scores_and_computes_only_the_pidx_points(tmp_path_factory):
    """table_pcpnet on a PCPNet-format folder: the paper's columns, each cell the RMSE on the shape's .pidx points;
    features and the network only for those (the refined normals are NaN elsewhere), MFPS for every point. Run
    with the real-scan setting X = 8 (features.include_initial false): the network's input follows the features."""
    repo = smoke_copy(tmp_path_factory.mktemp("pcpnet"))
    shapes_of = pcpnet_folder(repo.parent / "pcpnet_data")
    set_param(repo, "  source: procedural", "  source: pcpnet")
    set_param(repo, "  path: null", f"  path: {repo.parent / 'pcpnet_data'}")
    set_param(repo, "  include_initial: true", "  include_initial: false")
    snakemake(repo, "-j2", "reports/table_pcpnet.csv", "reports/table_time.csv")
    assert "X = 8" in (repo / "reports/table_pcpnet.tex").read_text()
    table = pd.read_csv(repo / "reports/table_pcpnet.csv", index_col=0)
    columns = ["None", "0.00125", "0.006", "0.012", "Gradient", "Stripes"]
    assert list(table.columns) == [f"{c}/rmse" for c in [*columns, "Average"]]
    assert list(table.index) == ["PCA", "Jet", "MFPS", "Refine-Net"] and table.notna().all().all()
    np.testing.assert_allclose(table["Average/rmse"], table.iloc[:, :6].mean(axis=1), atol=1e-4)
    for column in columns:
        key = f"test/{column}/{shapes_of[column]}"
        cloud = read_cloud(repo / f"results/clouds/{key}.npz")
        pidx = np.asarray(cloud.meta["pidx"])
        features, _ = load_features(repo / f"results/features/{FULL}/{key}.npz")
        np.testing.assert_array_equal(features.centres, pidx)
        refined = np.loadtxt(repo / REFINED.format(variant=FULL, cloud=key))
        assert np.isfinite(refined[pidx]).all() and np.isnan(np.delete(refined, pidx, axis=0)).all()
        assert np.isfinite(np.load(repo / f"results/normals/mfps/{key}.npy")).all()
        for row, method in (("MFPS", "results/normals/mfps/{}.npy"), ("Refine-Net", REFINED.format(
                variant=FULL, cloud="{}"))):
            estimated = read_normals(repo / method.format(key), len(cloud), pidx)
            rmse = np.sqrt(np.mean(unoriented_angles(estimated, cloud.normals[pidx]) ** 2))
            assert table.loc[row, f"{column}/rmse"] == pytest.approx(rmse, abs=1e-4)
    train, _ = load_features(repo / f"results/features/{FULL}/train/train/{shapes_of['train']}.npz")
    assert train.centres is None and len(train) == 1000  # training uses every point
    jobs = pd.read_csv(repo / TIME_FILES["per_cloud"])
    assert set(jobs[jobs["step"] == "network"]["points"]) == {100}
    assert set(jobs[jobs["step"] == "MFPS"]["points"]) == {1000}


@pytest.mark.kill
def test_runs_killed_anywhere_end_with_bit_identical_reports(by_snakemake, tmp_path):
    """10 SIGKILLs at seeded moments through each tool's main job (one during a write, one during training), each
    followed by a restart: every report file of the main job equals the uninterrupted run's, and both tools have
    nothing left to do for it."""
    results = kill_anywhere(["snakemake", "dvc"], kills=10, seed=2022, workdir=tmp_path, reference=by_snakemake,
                            length=LENGTH["snakemake"])
    (tmp_path / "kill_anywhere.json").write_text(json.dumps(results, indent=2) + "\n")  # kept for the report
    for tool, result in results["tools"].items():
        assert passed(result, 10), (tool, result)


@pytest.mark.slurm
def test_a_real_slurm_cluster_runs_the_pipeline_with_the_slurm_profile_to_the_same_reports(by_snakemake, tmp_path):
    """A single-node SLURM (slurmctld, slurmd, munge from the Debian archive) started on this machine; the smoke
    pipeline through the executor plugin and workflow/profiles/slurm, one SLURM job per Snakemake job; every
    report file equals the local run's. Needs root."""
    reason = slurm_cluster.missing()
    if reason:
        pytest.skip(f"SLURM check: {reason}")
    result = slurm_cluster.run_on_slurm(tmp_path, reference=by_snakemake)
    (tmp_path / "slurm.json").write_text(json.dumps(result, indent=2) + "\n")
    assert slurm_cluster.passed(result), result
