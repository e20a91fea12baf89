"""Merge the per-table metrics records into reports/metrics.json, the file `dvc metrics show` reads."""

from refinenet.evaluation.table import merge_metrics
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--inputs", nargs="+", required=True)
    parser.add_argument("--out", required=True)


def main(params, args):
    merge_metrics(args.inputs, args.out)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
