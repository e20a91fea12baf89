"""Our tables beside the paper's published numbers, and every ordering the paper claims marked held or not held
(reports/paper_comparison.md and .tex)."""

from refinenet.atomic import write_text
from refinenet.evaluation.paper import comparison_latex, comparison_markdown, read_tables
from refinenet.pipeline import stage
from refinenet.pipeline.catalogue import COMPARED_TABLES
from refinenet.pipeline.layout import COMPARISON_FILES


def arguments(parser):
    parser.add_argument("--tables", nargs="+", required=True, help="the CSV of every table, in COMPARED_TABLES order")


def main(params, args):
    tables = read_tables(list(COMPARED_TABLES), args.tables)
    d = params.data
    header = (f"Profile **{params.profile}**; data: {d.source}" + (f" ({d.path})" if d.path else "")
              + f", {d.n_points} points per cloud; {params.evaluation.protocol} protocol. Each table's caption "
              "(reports/<table>.tex) gives every setting.")
    write_text(COMPARISON_FILES["md"], comparison_markdown(tables, header))
    write_text(COMPARISON_FILES["tex"], comparison_latex(
        tables, f"Our numbers beside the paper's (quoted), profile {params.profile}, {d.source} data."))


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
