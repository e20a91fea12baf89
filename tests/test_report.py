"""The report page and the tables document: tables rendered from their CSV as written, captions from the LaTeX,
figures linked by relative path and checked in a real headless browser, and a PDF of the same bytes on a rerun."""

import os
import shutil
import subprocess

import matplotlib
import pytest
from browser import open_page

from refinenet.errors import InputError, OutputError
from refinenet.evaluation.report import (
    caption_profile,
    compile_pdf,
    html_table,
    latex_caption,
    origin,
    page,
    tables_document,
)
from refinenet.evaluation.table import aggregate, to_csv_frame, to_latex
from refinenet.pipeline.page import FigureEntry, TableEntry

matplotlib.use("Agg")
import matplotlib.pyplot as plt  # noqa: E402


@pytest.fixture
def reports(tmp_path, per_cloud):
    """A reports folder: one table (CSV + LaTeX) and one figure, as the pipeline writes them."""
    table = aggregate(per_cloud, "synthetic", ["mean", "rmse"])
    to_csv_frame(table).to_csv(tmp_path / "table_a.csv")
    (tmp_path / "table_a.tex").write_text(to_latex(table, "Errors; 5% of l_d, K = {50, 100}, 10^-3", "table_a"))
    (tmp_path / "figures").mkdir()
    fig, ax = plt.subplots(figsize=(2, 2), dpi=50)
    ax.plot([0, 1], [1, 0])
    fig.savefig(tmp_path / "figures" / "curve.png")
    plt.close(fig)
    (tmp_path / "notes.md").write_text("| a | b |\n|---|---|\n| <1> | 2 |\n")
    return tmp_path


def entries(root):
    tables = [TableEntry("table_a", "table_a.csv", "table_a.tex", {"csv": "table_a.csv", "tex": "table_a.tex"})]
    figures = [FigureEntry("curve", "figures/curve.png", "A line from (0, 1) to (1, 0).",
                           {"png": "figures/curve.png"})]
    return tables, figures


def test_a_table_is_rendered_from_its_csv_as_written(reports):
    html = html_table(reports / "table_a.csv")
    assert html.count("<tr>") == 1 + 2  # header, PCA, Jet
    jet = next(line for line in (reports / "table_a.csv").read_text().splitlines() if line.startswith("Jet"))
    assert "".join(f"<td>{cell}</td>" for cell in jet.split(",")) in html


def test_the_caption_comes_from_the_latex_with_its_escapes_undone(reports):
    assert latex_caption(reports / "table_a.tex") == "Errors; 5% of l_d, K = {50, 100}, 10^-3"


def test_the_page_shows_every_table_figure_and_note_escaped(reports):
    tables, figures = entries(reports)
    html = page("Reports <smoke>", "Profile smoke.", tables, figures, {"Comparison": "notes.md"}, "seed: 1", reports)
    assert "Reports &lt;smoke&gt;" in html and "| &lt;1&gt; | 2 |" in html and "seed: 1" in html
    assert '<img src="figures/curve.png"' in html and 'href="table_a.tex"' in html
    assert "Errors; 5% of l_d" in html
    assert page("Reports <smoke>", "Profile smoke.", tables, figures, {"Comparison": "notes.md"}, "seed: 1",
                reports) == html  # nothing depends on when it was made


def test_a_missing_table_file_is_named(reports):
    tables, figures = entries(reports)
    (reports / "table_a.csv").unlink()
    with pytest.raises(InputError, match="table_a.csv"):
        page("t", "d", tables, figures, {}, "", reports)


def test_in_a_browser_every_image_loads_and_a_missing_one_is_marked(reports):
    tables, figures = entries(reports)
    missing = FigureEntry("gone", "figures/gone.png", "Never made.", {})
    (reports / "index.html").write_text(page("t", "d", tables, [*figures, missing], {}, "", reports))
    loaded = open_page(reports / "index.html")
    assert loaded.images == {"figures/curve.png": "yes", "figures/gone.png": "no"}
    assert loaded.body.get("data-missing-images") == "1"
    assert loaded.tables == [2]


def test_the_tables_document_compiles_to_the_same_pdf_twice(reports, tmp_path_factory):
    doc = reports / "tables.tex"
    doc.write_text(tables_document("All tables, profile smoke_1", [reports / "table_a.tex"]))
    assert "\\title{All tables, profile smoke\\_1}" in doc.read_text()
    if shutil.which("pdflatex") is None:
        with pytest.raises(OutputError, match="pdflatex not found"):
            compile_pdf(doc, reports / "tables.pdf")
        pytest.skip("pdflatex not installed; the PDF is not checked")
    compile_pdf(doc, reports / "tables.pdf")
    first = (reports / "tables.pdf").read_bytes()
    assert first.startswith(b"%PDF") and len(first) > 1000
    compile_pdf(doc, reports / "tables.pdf")
    assert (reports / "tables.pdf").read_bytes() == first


def test_a_latex_error_is_one_line_naming_the_document(reports):
    if shutil.which("pdflatex") is None:
        pytest.skip("pdflatex not installed")
    doc = reports / "bad.tex"
    doc.write_text("\\documentclass{article}\\begin{document}\\undefinedmacro\\end{document}\n")
    with pytest.raises(InputError, match=r"bad.tex: pdflatex failed: ! Undefined control sequence"):
        compile_pdf(doc, reports / "bad.pdf")
    assert not (reports / "bad.pdf").exists()


def test_a_report_the_run_did_not_make_says_where_it_comes_from(reports, monkeypatch):
    """Committed and unchanged since: its commit's date; changed since, or never committed: an earlier run's. The
    profile comes from the table's caption."""
    monkeypatch.chdir(reports)
    date = {"GIT_COMMITTER_DATE": "2026-11-29T12:00:00+00:00", "GIT_AUTHOR_DATE": "2026-11-29T12:00:00+00:00"}
    git = ["git", "-c", "user.name=test", "-c", "user.email=test@example.org"]
    subprocess.run([*git, "init", "-q"], check=True)
    subprocess.run([*git, "add", "table_a.csv"], check=True)
    subprocess.run([*git, "commit", "-qm", "a run"], check=True, env={**os.environ, **date})
    (reports / "table_a.tex").write_text((reports / "table_a.tex").read_text().replace("Errors;", "Profile cpu;"))
    assert caption_profile(reports / "table_a.tex") == "cpu"
    assert origin("table_a.csv", "cpu") == "Committed result by profile cpu, of 2026-11-29: not rebuilt by this run."
    (reports / "table_a.csv").write_text((reports / "table_a.csv").read_text() + "\n")
    assert origin("table_a.csv", None) == "Result of an earlier run in this checkout: not rebuilt by this run."
    assert origin("notes.md", "smoke").startswith("Result of an earlier run in this checkout by profile smoke")


def test_what_nothing_made_is_listed_with_the_command_that_builds_it(reports):
    tables, figures = entries(reports)
    gone = FigureEntry("gone", "figures/gone.png", "Never made.", {}, made=False, target="reports/figures/gone.png")
    html = page("t", "d", tables, figures, {}, "", reports, {"table_a": "From a commit."}, [gone])
    assert "<li>gone: <code>snakemake -j2 reports/figures/gone.png</code></li>" in html
    assert '<p class="origin">From a commit.</p>' in html
