"""The denoising application (docs/algorithm.md §11), one `--output` per step:
* cloud (denoise): one test cloud moved along the normals of each method (`point_update`), and the distance of
  every point to the cloud's true surface before and after, in a record (results/denoised/<cloud>.npz);
* table (table_denoise): the mean and RMS distance to the true surface per category, noisy input against each
  method's denoised points, in 10^-3 l_d."""

from pathlib import Path

import numpy as np
import pandas as pd

from refinenet.data.clouds import surface_sample
from refinenet.data.io import read_cloud, read_normals
from refinenet.evaluation.denoise import SURFACE_SAMPLES, point_update, read_record, surface_distance, write_record
from refinenet.evaluation.metrics import ErrorStats
from refinenet.evaluation.table import stats_row, write_table
from refinenet.pipeline import stage
from refinenet.pipeline.captions import data_line
from refinenet.pipeline.catalogue import DENOISE_INPUT, DENOISE_METHODS, DENOISE_NAMES, Table

#: Distances in the table are in this fraction of l_d.
UNIT = 1e-3


def arguments(parser):
    parser.add_argument("--output", required=True, choices=("cloud", "table"))
    parser.add_argument("--clouds", nargs="+", required=True, help="the test cloud records (.npz)")
    parser.add_argument("--normals", nargs="+", default=[], help="cloud: the normals of each DENOISE_METHODS")
    parser.add_argument("--records", nargs="+", default=[], help="table: each cloud's denoising record")
    parser.add_argument("--out", help="cloud: the record to write")


def main(params, args):
    if args.output == "cloud":
        denoise_cloud(params.denoise, args.clouds[0], args.normals, args.out)
        return
    rows = []
    for cloud_path, record in zip(args.clouds, args.records, strict=True):
        meta = read_cloud(cloud_path).meta
        rows += [stats_row(row, meta["category"], meta["name"], ErrorStats.from_angles(d / UNIT))
                 for row, d in read_record(record)["distance"].items()]
    d = params.denoise
    caption = (f"Denoising with estimated normals (docs/algorithm.md §11): distance of the points to the true surface "
               f"in 10^-3 l_d, mean and RMS, of the noisy input and after {d.iterations} point updates with each "
               f"method's normals; lambda = {d.lam}, sigma = {d.sigma}, ball radius {d.radius} l_d. "
               + data_line(params))
    write_table(pd.DataFrame(rows), "synthetic", ("mean", "rmse"), caption, "table_denoise",
                Table.files("table_denoise"), DENOISE_NAMES)


def denoise_cloud(config, cloud_path: str, normals_paths: list[str], out: str) -> None:
    cloud = read_cloud(cloud_path)
    surface, surface_normals = surface_sample(cloud_path, cloud.meta, SURFACE_SAMPLES * len(cloud))
    l_d = cloud.meta["l_d"]
    distances = {DENOISE_INPUT: surface_distance(cloud.points, surface, surface_normals) / l_d}
    points, normals = {}, {}
    for method, path in zip(DENOISE_METHODS, normals_paths, strict=True):
        normals[method] = read_normals(path, len(cloud))
        points[method] = point_update(cloud.points, normals[method], config.radius * l_d, config.sigma, config.lam,
                                      config.iterations)
        distances[method] = surface_distance(points[method], surface, surface_normals) / l_d
        print(f"{Path(cloud_path).name} {method}: mean distance {np.mean(distances[method]) / UNIT:.3f} "
              f"(input {np.mean(distances[DENOISE_INPUT]) / UNIT:.3f}) x 10^-3 l_d")
    write_record(out, points, normals, distances)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
