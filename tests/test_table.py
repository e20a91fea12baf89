"""Table aggregation, the paper's column order, bold best values, and LaTeX that compiles."""

import shutil
import subprocess

import numpy as np
import pytest

from refinenet.evaluation.table import aggregate, metrics_record, to_csv_frame, to_latex


def test_aggregate_synthetic(per_cloud):
    table = aggregate(per_cloud, "synthetic", ["mean", "rmse"])
    assert list(dict.fromkeys(c for c, _ in table.columns)) == ["BigNoise", "SharpFeature", "SmoothSurface", "Average"]
    # SmoothSurface, jet: 10 points at 1 deg, 30 at 2 deg -> pooled mean 1.75; rmse weighted = (10*1 + 30*2) / 40
    assert table.loc["jet", ("SmoothSurface", "mean")] == pytest.approx(1.75)
    assert table.loc["jet", ("SmoothSurface", "rmse")] == pytest.approx(1.75)
    avg = np.mean([table.loc["pca", (c, "mean")] for c in ("BigNoise", "SharpFeature", "SmoothSurface")])
    assert table.loc["pca", ("Average", "mean")] == pytest.approx(avg)


def test_aggregate_pcpnet_is_per_shape_mean(per_cloud):
    table = aggregate(per_cloud, "pcpnet", ["rmse"])
    assert table.loc["jet", ("SmoothSurface", "rmse")] == pytest.approx(1.5)


def test_csv_and_latex(per_cloud, tmp_path):
    table = aggregate(per_cloud, "synthetic", ["mean", "rmse"])
    csv = to_csv_frame(table)
    assert list(csv.index) == ["PCA", "Jet"] and "BigNoise/mean" in csv.columns
    tex = to_latex(table, "Errors; profile smoke, 5% of l_d, K = {50, 100}", "table_test")
    assert "\\toprule" in tex and "\\cmidrule(lr){2-3}" in tex and "5\\% of l\\_d, K = \\{50, 100\\}" in tex
    jet_row = next(line for line in tex.splitlines() if line.startswith("Jet"))
    assert jet_row.count("\\textbf") == 8  # jet is best everywhere
    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex not installed; LaTeX compilation not checked")
    doc = tmp_path / "doc.tex"
    doc.write_text("\\documentclass{article}\n\\usepackage{booktabs}\n\\begin{document}\n" + tex + "\\end{document}\n")
    run = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", doc.name],
                         cwd=tmp_path, capture_output=True, text=True)
    assert run.returncode == 0, run.stdout[-2000:]
    assert (tmp_path / "doc.pdf").stat().st_size > 1000


def test_the_metrics_record_holds_the_average_per_method(per_cloud):
    """What `dvc metrics show` prints stays small: the Average columns only (jet: categories at 1.75, 6 and 4 deg
    pooled means -> their mean)."""
    csv = to_csv_frame(aggregate(per_cloud, "synthetic", ["mean", "rmse"]))
    record = metrics_record(csv)
    assert set(record) == {"PCA", "Jet"} and set(record["Jet"]) == {"mean", "rmse"}
    assert record["Jet"]["mean"] == pytest.approx(round(csv.loc["Jet", "Average/mean"], 4))
    assert record["PCA"]["mean"] == pytest.approx(2 * record["Jet"]["mean"], abs=1e-3)
