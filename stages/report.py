"""The reports in one place, one `--output` per step:
* page (report): reports/index.html, every table rendered from its CSV and every figure, with the profile and the
  settings that made them; and reports/tables.tex, one LaTeX document of every table;
* pdf (report_pdf): reports/tables.pdf, that document compiled with pdflatex."""

import os
from dataclasses import asdict

import yaml

from refinenet import config
from refinenet.atomic import write_text
from refinenet.evaluation.report import compile_pdf, page, tables_document
from refinenet.pipeline import captions, stage
from refinenet.pipeline.layout import COMPARISON_FILES, REPORT_DIR, REPORT_FILES, TABLES_PDF
from refinenet.pipeline.methods import FULL
from refinenet.pipeline.page import reported
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    parser.add_argument("--output", required=True, choices=("page", "pdf"))


def main(params, args):
    if args.output == "pdf":
        compile_pdf(REPORT_FILES["tex"], TABLES_PDF)
        return
    pipe = Pipeline(config.read_raw(args.params), args.params)
    tables, figures = reported(pipe)
    settings = yaml.safe_dump({"profile": params.profile, **asdict(pipe.full)}, sort_keys=False, width=120)
    changes = {v: captions.changes(pipe, v) for v in pipe.params if v != FULL}
    settings += ("\n# Refine-Net variants: what each changes (reference: full under the variant budget; the others:\n"
                 "# from reference)\n" + yaml.safe_dump(changes, sort_keys=False, width=120))
    title = f"Refine-Net reproduction: reports of profile {params.profile}"
    notes = {"Comparison with the paper": os.path.relpath(COMPARISON_FILES["md"], REPORT_DIR)}
    data = captions.data_line(params)
    write_text(REPORT_FILES["html"], page(title, data, tables, figures, notes, settings, REPORT_DIR))
    write_text(REPORT_FILES["tex"], tables_document(f"{title}. {data}", [f"{REPORT_DIR}/{t.tex}" for t in tables]))


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
