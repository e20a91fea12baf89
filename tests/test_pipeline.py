"""End to end on the smoke profile: Snakemake and DVC build the same files, each leaves the other nothing
to do, and a params change reruns the same steps in both tools. Minutes, so marked slow."""

import json
import shutil
import subprocess
import sys
from pathlib import Path

import pandas as pd
import pytest

from refinenet.workflow import STEPS

pytestmark = pytest.mark.slow
REPO = Path(__file__).resolve().parents[1]
TABLE = "reports/table_synthetic.csv"


def sh(cwd: Path, *cmd: str) -> subprocess.CompletedProcess:
    run = subprocess.run(cmd, cwd=cwd, capture_output=True, text=True)
    assert run.returncode == 0, f"{' '.join(cmd)} failed:\n{run.stdout[-3000:]}\n{run.stderr[-3000:]}"
    return run


def snakemake(cwd: Path, *args: str) -> subprocess.CompletedProcess:
    return sh(cwd, sys.executable, "-m", "snakemake", *args)


def set_param(repo: Path, old: str, new: str) -> None:
    params = repo / "params.yaml"
    text = params.read_text()
    assert old in text
    params.write_text(text.replace(old, new, 1))


def smoke_copy(tmp: Path) -> Path:
    """The working tree (tracked and untracked, not ignored files) in a fresh git repository, profile smoke."""
    files = sh(REPO, "git", "ls-files", "-co", "--exclude-standard").stdout.split()
    for f in files:
        if (REPO / f).is_file():
            (tmp / f).parent.mkdir(parents=True, exist_ok=True)
            shutil.copy2(REPO / f, tmp / f)
    set_param(tmp, "profile: cpu", "profile: smoke")
    sh(tmp, "git", "init", "-q")
    return tmp


@pytest.fixture(scope="module")
def by_snakemake(tmp_path_factory):
    repo = smoke_copy(tmp_path_factory.mktemp("snakemake"))
    snakemake(repo, "-j2")
    return repo


@pytest.fixture(scope="module")
def by_dvc(tmp_path_factory):
    repo = smoke_copy(tmp_path_factory.mktemp("dvc"))
    sh(repo, "dvc", "repro")
    return repo


def dvc_changed_stages(repo: Path) -> set[str]:
    return set(json.loads(sh(repo, "dvc", "status", "--json").stdout or "{}"))


def snakemake_changed_rules(repo: Path) -> set[str]:
    rows = [line.split("\t") for line in snakemake(repo, "--summary").stdout.splitlines()[1:]]
    return {r[2] for r in rows if len(r) > 4 and r[4] != "ok"}


def test_snakemake_leaves_dvc_nothing_to_do(by_snakemake):
    table = pd.read_csv(by_snakemake / TABLE, index_col=0)
    assert list(table.index) == ["PCA", "Jet", "MFPS", "simple MFPS", "Refine-Net"] and "Average/mean" in table.columns
    # MFPS is built for sharp features: it must beat both baselines there (ALGORITHM.md §2).
    assert table.loc["MFPS", "SharpFeature/mean"] < min(table.loc["PCA", "SharpFeature/mean"],
                                                         table.loc["Jet", "SharpFeature/mean"])
    assert dvc_changed_stages(by_snakemake) == set()
    assert "didn't change" in sh(by_snakemake, "dvc", "repro").stdout


def test_dvc_builds_the_same_files_and_leaves_snakemake_nothing_to_do(by_dvc, by_snakemake):
    for name in (TABLE, "reports/table_synthetic.tex", "reports/per_cloud/table_synthetic.csv", "reports/metrics.json"):
        assert (by_dvc / name).read_text() == (by_snakemake / name).read_text(), name
    assert "Nothing to be done" in snakemake(by_dvc, "-n").stdout
    second = sh(by_dvc, "dvc", "repro").stdout
    assert "Data and pipelines are up to date" in second
    assert "Running stage" not in second


TABLES = {"table_baselines", "table_synthetic", "table_synthetic_pgp"}
SEEDED = {"train_clouds", "test_clouds", "mfps", "simple_mfps", "clusters", "train", "refine"}


@pytest.mark.parametrize(
    ("old", "new", "steps"),
    [
        ("  jet_k: 100", "  jet_k: 90", {"baselines"} | TABLES),
        ("  theta_t: 60", "  theta_t: 45", {"mfps", "simple_mfps", "table_synthetic", "table_synthetic_pgp"}),
        ("  protocol: synthetic", "  protocol: pcpnet", TABLES),
        ("seed: 2022", "seed: 7", SEEDED),
        ("data: {n_points: 4000, max_shapes: 1}", "data: {n_points: 3000, max_shapes: 1}",
         {"train_clouds", "test_clouds"} | TABLES),
        ("  hmp_k: 100", "  hmp_k: 90", {"features", "table_synthetic", "table_synthetic_pgp"}),
        ("  n_clusters: 4", "  n_clusters: 3", {"clusters", "table_synthetic", "table_synthetic_pgp"}),
    ],
)
def test_a_params_change_reruns_the_same_steps_in_both_tools(by_snakemake, old, new, steps):
    set_param(by_snakemake, old, new)
    try:
        rules = snakemake_changed_rules(by_snakemake)
        assert dvc_changed_stages(by_snakemake) == steps
        assert rules == {STEPS[s].rule for s in steps}
    finally:
        set_param(by_snakemake, new, old)
    assert dvc_changed_stages(by_snakemake) == set()


def test_bad_params_value_fails_with_one_line(by_snakemake):
    set_param(by_snakemake, "  pca_k: 100", "  pca_k: -5")
    try:
        run = subprocess.run([sys.executable, "-m", "snakemake", "-n"], cwd=by_snakemake,
                             capture_output=True, text=True)
    finally:
        set_param(by_snakemake, "  pca_k: -5", "  pca_k: 100")
    assert run.returncode != 0
    assert "error: params.yaml: baselines.pca_k: -5 is less than the minimum of 3" in run.stderr
