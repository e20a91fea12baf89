"""Evaluate the normals of every method of one table against ground truth; write the table (CSV, LaTeX, per-cloud
CSV) and its metrics record. The normals of each test cloud are found by the pipeline's file layout."""

from refinenet.data.clouds import cloud_key
from refinenet.data.io import read_cloud
from refinenet.evaluation.table import evaluate, write_table
from refinenet.pipeline import stage
from refinenet.pipeline.workflow import TABLES, Table, caption, normals_path


def arguments(parser):
    parser.add_argument("--table", required=True, choices=list(TABLES))
    parser.add_argument("--clouds", nargs="+", required=True, help="the test cloud records (.npz)")


def main(params, args):
    table = TABLES[args.table]
    keys = [cloud_key(path, read_cloud(path)) for path in args.clouds]
    normals = {m: [normals_path(m, key) for key in keys] for m in table.methods}
    per_cloud = evaluate(table.methods, args.clouds, normals, params.evaluation.protocol)
    write_table(per_cloud, params.evaluation.protocol, table.metrics, caption(table.title, params, table.methods),
                args.table, Table.files(args.table))


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
