"""Evaluate the normals of every method of one table against ground truth; write the table (CSV, LaTeX, per-cloud
CSV), its metrics record and, for a sweep table, the plot of the Average mean error against the swept setting.
The normals of each test cloud are found by the pipeline's file layout."""

from refinenet import config
from refinenet.data.clouds import cloud_key
from refinenet.data.io import read_cloud
from refinenet.evaluation.plots import sweep_plot
from refinenet.evaluation.table import evaluate, write_table
from refinenet.pipeline import captions, stage
from refinenet.pipeline.catalogue import TABLES, Table
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    parser.add_argument("--table", required=True, choices=list(TABLES))
    parser.add_argument("--clouds", nargs="+", required=True, help="the test cloud records (.npz)")


def main(params, args):
    pipe, table = Pipeline(config.read_raw(args.params), args.params), TABLES[args.table]
    rows = captions.rows(pipe, table)
    methods = list(rows)
    keys = [cloud_key(path, read_cloud(path)) for path in args.clouds]
    normals = {m: [pipe.normals_path(m, key) for key in keys] for m in methods}
    per_cloud = evaluate(methods, args.clouds, normals, pipe.scored_subset(table.methods))
    files = Table.files(args.table, table)
    csv = write_table(per_cloud, pipe.protocol(table), table.metrics, captions.caption(pipe, table), args.table,
                      files, rows)
    if table.sweep:
        key, symbol = table.sweep
        sweep_plot([pipe.swept(m, key) for m in methods], list(csv["Average/mean"]), symbol,
                   "Average mean error (degrees)", f"{args.table}: profile {params.profile}, data {params.data.source}",
                   files["plot"])


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
