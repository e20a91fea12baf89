"""The reports in one place, one `--output` per step:
* page (report): reports/index.html, every table rendered from its CSV and every figure, with the profile and the
  settings that made them; and reports/tables.tex, one LaTeX document of every table. With `--scope main` (the
  main job's page), the main job's files beside the committed results of the rest, each marked with its commit,
  and what neither made listed with the target that builds it;
* pdf (report_pdf): reports/tables.pdf, that document compiled with pdflatex."""

import os
from dataclasses import asdict
from pathlib import Path

import yaml

from refinenet import config
from refinenet.atomic import write_text
from refinenet.evaluation.report import caption_profile, compile_pdf, origin, page, tables_document
from refinenet.pipeline import captions, stage
from refinenet.pipeline.layout import REPORT_DIR, REPORT_FILES, TABLES_PDF
from refinenet.pipeline.methods import FULL
from refinenet.pipeline.page import NOTES, reported
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    parser.add_argument("--output", required=True, choices=("page", "pdf"))
    parser.add_argument("--scope", choices=("main", "all"), default="all",
                        help="page: the main job's page, or that of every table and figure")


def main(params, args):
    if args.output == "pdf":
        compile_pdf(REPORT_FILES["tex"], TABLES_PDF)
        return
    pipe = Pipeline(config.read_raw(args.params), args.params)
    main_job = args.scope == "main"
    tables, figures = reported(pipe, main_job)
    root = Path(REPORT_DIR)
    origins = {t.name: origin(root / t.csv, caption_profile(root / t.tex) if t.tex else None) for t in tables
               if not t.made and (root / t.csv).is_file()}
    origins |= {f.name: origin(root / f.png, None) for f in figures if not f.made and (root / f.png).is_file()}
    absent = [e for e in (*tables, *figures) if not e.made and e.name not in origins]
    tables = [t for t in tables if t not in absent]
    figures = [f for f in figures if f not in absent]
    notes = {}
    for title, (path, by_main) in NOTES.items():
        if by_main or not main_job or os.path.isfile(path):
            notes[title] = os.path.relpath(path, REPORT_DIR)
            if main_job and not by_main:
                origins[title] = origin(path, None)
    settings = yaml.safe_dump({"profile": params.profile, **asdict(pipe.full), "scanner": asdict(pipe.scanner)},
                              sort_keys=False, width=120)
    changes = {v: captions.changes(pipe, v) for v in pipe.params if v != FULL}
    settings += ("\n# Refine-Net variants: what each changes (reference: full under the variant budget; the others:\n"
                 "# from reference)\n" + yaml.safe_dump(changes, sort_keys=False, width=120))
    title = (f"Refine-Net reproduction: the main job of profile {params.profile}, beside the committed results"
             if main_job else f"Refine-Net reproduction: reports of profile {params.profile}")
    data = captions.data_line(params)
    write_text(REPORT_FILES["html"], page(title, data, tables, figures, notes, settings, REPORT_DIR, origins, absent))
    write_text(REPORT_FILES["tex"], tables_document(f"{title}. {data}", [f"{REPORT_DIR}/{t.tex}" for t in tables]))


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
