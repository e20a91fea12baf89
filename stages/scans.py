"""table_scans: the unoriented angular error of PCA, Jet, MFPS and Refine-Net, both the release and variant x8 (no
initial normal among its inputs, the paper's real-data setting), on every simulated scan (docs/algorithm.md §1.5),
through the chain of `refinenet normals` (l_d from the point spacing): mean, RMSE, PGP5 and PGP10 per category of
the scanned shapes, points pooled. The quantitative form of [P] table:Kinect_results, on clouds with exact
normals."""

from pathlib import Path

import pandas as pd

from refinenet import config
from refinenet.cli.estimate import compared_normals, min_points
from refinenet.data.io import read_cloud
from refinenet.data.shapes import catalogue
from refinenet.evaluation.metrics import ErrorStats, unoriented_angles
from refinenet.evaluation.table import stats_row, write_table
from refinenet.network.devices import resolve_device
from refinenet.network.release import Release, load_release
from refinenet.pipeline import stage
from refinenet.pipeline.captions import budget_line, data_line, scanner_line
from refinenet.pipeline.catalogue import REAL_VARIANT, SCAN_METHODS, SCAN_TABLE, Table
from refinenet.pipeline.methods import REFINENET, figure_name, refinenet
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    parser.add_argument("--scans", nargs="+", required=True, help="the simulated scans (.ply)")
    parser.add_argument("--release", required=True, help="the release folder")
    parser.add_argument("--clouds", nargs="+", required=True, help="the training clouds (their spacing)")
    parser.add_argument("--clusters", required=True, help="variant x8's cluster model")
    parser.add_argument("--networks", nargs="+", required=True, help="variant x8's network folders")


def main(params, args):
    pipe = Pipeline(config.read_raw(args.params), args.params)
    x8 = pipe.params[REAL_VARIANT]
    training = [read_cloud(path).points for path in args.clouds]
    releases = {REFINENET: load_release(args.release, device=resolve_device(pipe.full.inference.device)),
                refinenet(REAL_VARIANT): Release.of_run(x8, args.clusters, args.networks, training)}
    shapes, rows = catalogue(), []
    least = min_points(x8, REFINENET, refine_initial=False)
    for path in map(Path, args.scans):
        scan = read_cloud(path, least)
        for method, normals in compared_normals(scan.points, releases).items():
            stats = ErrorStats.from_angles(unoriented_angles(normals, scan.normals))
            rows.append(stats_row(method, shapes[path.stem].category, path.stem, stats))
            print(f"{path.stem} {method}: mean {stats.mean:.2f} deg, PGP10 {stats.pgp10:.3f}")
    names = {m: figure_name(m) for m in SCAN_METHODS}
    caption = ("Simulated range scans (docs/algorithm.md §1.5): unoriented angular error (degrees), mean and RMSE, "
               "and the proportion of good points (PGP5, PGP10), points pooled per category; every method through "
               f"the chain of refinenet normals, l_d from the point spacing. Refine-Net: the release, X = "
               f"{pipe.full.features.n_normals}; {names[refinenet(REAL_VARIANT)]}: variant {REAL_VARIANT}, X = "
               f"{x8.features.n_normals} (without the initial normal, the paper's real-data setting); both refine "
               "MFPS. " + " ".join(filter(None, [budget_line(pipe, names[refinenet(REAL_VARIANT)], "the release"),
                                                 scanner_line(pipe.scanner), data_line(params)])))
    write_table(pd.DataFrame(rows), "synthetic", ("mean", "rmse", "pgp5", "pgp10"), caption, SCAN_TABLE,
                Table.files(SCAN_TABLE), names)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
