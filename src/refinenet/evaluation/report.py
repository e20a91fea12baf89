"""The reports in one place: a static page (reports/index.html) with every table and figure, and one LaTeX document
of every table (reports/tables.tex, compiled to tables.pdf where pdflatex is installed).

The page opens from the file system, with no server: tables are rendered from their CSV files into the HTML, and
figures are the PNG files beside it, linked by relative path. A short script marks each image loaded or missing
(`data-loaded`), so a headless browser (and a reader) sees at once when a figure did not load. A report the run
did not make is marked with where it comes from (its commit). Nothing in either file depends on the time of the
run, so a rerun on the same reports and commits gives the same bytes.
"""

from __future__ import annotations

import html
import os
import re
import shutil
import subprocess
import tempfile
from collections.abc import Mapping, Sequence
from pathlib import Path
from typing import Protocol

import pandas as pd

from refinenet.atomic import atomic_path
from refinenet.errors import InputError, OutputError
from refinenet.evaluation.table import latex_escape


class TableEntry(Protocol):
    """A table of the page (`pipeline.page.TableEntry`): its CSV is rendered, its LaTeX gives the caption."""

    name: str
    csv: str
    tex: str | None
    links: Mapping[str, str]
    target: str


class FigureEntry(Protocol):
    """A figure of the page (`pipeline.page.FigureEntry`): the PNG shown, what it shows, the files to link."""

    name: str
    png: str
    caption: str
    links: Mapping[str, str]
    target: str


#: Marks every image loaded or missing once the page has loaded, and counts the missing ones in the header.
_CHECK_IMAGES = """<script>
window.addEventListener("load", () => {
  let missing = 0;
  for (const img of document.images) {
    const ok = img.complete && img.naturalWidth > 0;
    img.dataset.loaded = ok ? "yes" : "no";
    if (!ok) { missing += 1; img.insertAdjacentText("afterend", "[figure missing: " + img.getAttribute("src") + "]"); }
  }
  document.body.dataset.missingImages = String(missing);
  document.getElementById("status").textContent = missing ? missing + " figure(s) missing" : "all figures loaded";
});
</script>"""

_STYLE = """<style>
body { font-family: sans-serif; margin: 2em auto; max-width: 1200px; padding: 0 1em; color: #222; }
table.results { border-collapse: collapse; font-size: 0.85em; margin: 0.5em 0; }
table.results th, table.results td { border-bottom: 1px solid #ccc; padding: 0.2em 0.6em; text-align: right; }
table.results th:first-child, table.results td:first-child { text-align: left; }
figure { margin: 1.5em 0; } figure img { max-width: 100%; border: 1px solid #ddd; }
.scroll { overflow-x: auto; } ul.contents { columns: 3; }
.caption { font-size: 0.9em; color: #444; } .links a { margin-right: 1em; } pre { font-size: 0.8em; overflow-x: auto; }
.origin { font-size: 0.9em; color: #8a4b00; }
</style>"""


def page(title: str, data: str, tables: Sequence[TableEntry], figures: Sequence[FigureEntry],
         notes: Mapping[str, str], settings: str, root: str | Path, origins: Mapping[str, str] | None = None,
         absent: Sequence[TableEntry | FigureEntry] = ()) -> str:
    """The HTML page. Paths are relative to `root` (the folder of the page), where they are read and linked from;
    `notes` are text files shown as they are (e.g. the comparison with the paper), by title. `origins` says, by
    entry or note name, where each one the run did not make comes from (e.g. a commit); `absent` are the entries
    that neither the run nor anything before it made, listed with the target that builds each."""
    root, origins = Path(root), origins or {}
    body = [f"<h1>{_e(title)}</h1>", f"<p>{_e(data)} <span id=\"status\"></span></p>",
            '<h2>Contents</h2><ul class="contents">',
            *(f'<li><a href="#{_e(f.name)}">{_e(f.name)}</a></li>' for f in figures),
            *(f'<li><a href="#{_e(t.name)}">{_e(t.name)}</a></li>' for t in tables),
            *(f'<li><a href="#{_anchor(n)}">{_e(n)}</a></li>' for n in notes),
            *(['<li><a href="#not-built">not built</a></li>'] if absent else []),
            '<li><a href="#settings">settings</a></li></ul>', "<h2>Figures</h2>"]
    for f in figures:
        body += [f'<figure id="{_e(f.name)}"><h3>{_e(f.name)}</h3>', *_origin(origins.get(f.name)),
                 f'<img src="{_e(f.png)}" alt="{_e(f.name)}">',
                 f'<figcaption class="caption">{_e(f.caption)}</figcaption>', _links(f.links), "</figure>"]
    body.append("<h2>Tables</h2>")
    for t in tables:
        caption = latex_caption(root / t.tex) if t.tex else ""
        body += [f'<section id="{_e(t.name)}"><h3>{_e(t.name)}</h3>', *_origin(origins.get(t.name)),
                 f'<p class="caption">{_e(caption)}</p>', html_table(root / t.csv), _links(t.links), "</section>"]
    for name, path in notes.items():
        body += [f'<section id="{_anchor(name)}"><h2>{_e(name)}</h2>', *_origin(origins.get(name)),
                 _links({"source": path}), f"<pre>{_e(_read(root / path))}</pre></section>"]
    if absent:
        body += ['<section id="not-built"><h2>not built</h2><p>Neither this run nor an earlier one made these (all of '
                 "them: <code>snakemake -j2</code> or <code>dvc repro</code>):</p><ul>",
                 *(f"<li>{_e(a.name)}: <code>snakemake -j2 {_e(a.target)}</code></li>" for a in absent),
                 "</ul></section>"]
    body += ['<section id="settings"><h2>settings</h2>', f"<pre>{_e(settings)}</pre></section>"]
    return "\n".join(["<!DOCTYPE html>", '<html lang="en"><head><meta charset="utf-8">', f"<title>{_e(title)}</title>",
                      _STYLE, "</head><body>", *body, _CHECK_IMAGES, "</body></html>", ""])


def _origin(origin: str | None) -> list[str]:
    return [] if origin is None else [f'<p class="origin">{_e(origin)}</p>']


def origin(path: str | Path, profile: str | None) -> str:
    """Where a report the run did not make comes from: the date of its last commit where git holds it unchanged,
    else an earlier run in this checkout; with the profile that made it, where known."""
    made = f" by profile {profile}" if profile else ""
    tracked = _git("ls-files", "--error-unmatch", "--", str(path)) is not None
    changed = _git("status", "--porcelain", "--", str(path))
    date = _git("log", "-1", "--format=%cs", "--", str(path)) if tracked and changed == "" else None
    if date:
        return f"Committed result{made}, of {date}: not rebuilt by this run."
    return f"Result of an earlier run in this checkout{made}: not rebuilt by this run."


def _git(*args: str) -> str | None:
    """A git command's output in the current folder, or None where git is missing or fails (no repository, an
    untracked file)."""
    try:
        run = subprocess.run(["git", *args], capture_output=True, text=True)
    except OSError:
        return None
    return run.stdout.strip() if run.returncode == 0 else None


def caption_profile(tex: Path) -> str | None:
    """The profile a generated table's caption names (`captions.data_line`), or None."""
    match = re.search(r"Profile (\w+)", latex_caption(tex))
    return match.group(1) if match else None


def html_table(csv: Path) -> str:
    """A CSV file as an HTML table, every cell as written in the file (first column: the row names)."""
    try:
        frame = pd.read_csv(csv, dtype=str, keep_default_na=False)
    except (OSError, pd.errors.ParserError, pd.errors.EmptyDataError) as err:
        raise InputError(csv, f"cannot read the table: {err}") from None
    head = "".join(f"<th>{_e(c)}</th>" for c in ["" if c.startswith("Unnamed") else c for c in frame.columns])
    rows = "".join("<tr>" + "".join(f"<td>{_e(v)}</td>" for v in row) + "</tr>"
                   for row in frame.itertuples(index=False))
    table = f'<table class="results"><thead><tr>{head}</tr></thead><tbody>{rows}</tbody></table>'
    return f'<div class="scroll">{table}</div>'


def latex_caption(tex: Path) -> str:
    """The caption of a generated LaTeX table, as plain text (the escapes of `table.latex_escape` undone)."""
    match = re.search(r"\\caption\{(.*)\}\s*$", _read(tex), re.MULTILINE)
    if match is None:
        raise InputError(tex, "no \\caption line")
    return re.sub(r"\\([&%$#_{}])", r"\1", match.group(1).replace("\\^{}", "^"))


def tables_document(title: str, tex_files: Sequence[str | Path]) -> str:
    """One LaTeX document holding every generated table, in order, one per page."""
    parts = ["\\documentclass[a4paper]{article}", "\\usepackage[margin=1.5cm,landscape]{geometry}",
             "\\usepackage{booktabs}", f"\\title{{{latex_escape(title)}}}", "\\date{}", "\\begin{document}",
             "\\maketitle", "\\footnotesize"]
    for path in tex_files:
        table = _read(Path(path)).replace("\\begin{table}[t]", "\\begin{table}[h]")
        parts += [f"% {path}", table, "\\clearpage"]
    return "\n".join([*parts, "\\end{document}", ""])


def compile_pdf(tex: str | Path, pdf: str | Path) -> None:
    """Compile a LaTeX document with pdflatex in a scratch folder and write the PDF atomically; the PDF's dates are
    fixed (SOURCE_DATE_EPOCH) so that a rerun gives the same bytes."""
    tex, pdf = Path(tex), Path(pdf)
    if shutil.which("pdflatex") is None:
        raise OutputError(pdf, "pdflatex not found: install TeX Live (Debian: texlive-latex-recommended) to build it")
    with tempfile.TemporaryDirectory() as scratch:
        shutil.copy(tex, Path(scratch) / "tables.tex")
        env = {**os.environ, "SOURCE_DATE_EPOCH": "0", "FORCE_SOURCE_DATE": "1"}
        run = subprocess.run(["pdflatex", "-interaction=nonstopmode", "-halt-on-error", "tables.tex"], cwd=scratch,
                             capture_output=True, text=True, env=env)
        if run.returncode != 0:
            errors = [line for line in run.stdout.splitlines() if line.startswith("!")]
            raise InputError(tex, f"pdflatex failed: {errors[0] if errors else 'exit status ' + str(run.returncode)}")
        with atomic_path(pdf) as tmp:
            shutil.copy(Path(scratch) / "tables.pdf", tmp)


def _links(links: Mapping[str, str]) -> str:
    anchors = "".join(f'<a href="{_e(path)}">{_e(kind)}</a>' for kind, path in links.items())
    return f'<p class="links">{anchors}</p>'


def _anchor(name: str) -> str:
    return re.sub(r"[^a-z0-9]+", "-", name.lower()).strip("-")


def _read(path: Path) -> str:
    try:
        return path.read_text()
    except OSError as err:
        raise InputError(path, f"cannot read: {err.strerror}") from None


def _e(text: str) -> str:
    return html.escape(str(text), quote=True)
