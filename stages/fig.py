"""The paper's figures (docs/algorithm.md §12, Figures), one `--figure` per step:
* normals (fig:syn / fig:insight): normals of PCA, Jet, MFPS, Refine-Net and the variants asked for as RGB and
  their angular errors as heat maps on chosen test clouds (their scored points only: a PCPNet shape's `.pidx`
  points, the seeded subset that budgeted variants refine; the network computed no others);
* clusters (fig:cluster): a test cloud coloured by cluster for Kc = 2 and Kc = 4, beside the Kc curve;
* loss (fig:loss2): one shape at increasing noise, each point blue where the L1 network has the lower error, red
  where the L2 one has;
* training: training loss and validation error per epoch of every cluster of one trained variant (`--variant`);
* real (fig:real_boy / fig:outdoor): normals as RGB on scans by PCA, Jet, MFPS and the X = 8 variant's networks,
  through the chain of `refinenet normals` (radii from the point spacing): a folder of real scans (no ground truth
  needed) where params.yaml `figures.scans` names one, else the simulated scans (results/scans);
* denoise (fig:block): one test cloud's points after denoising with each method's normals, coloured by their
  distance to the true surface, and the screened Poisson surface of each (normals oriented by `orient_mst`), beside
  the noisy input and the true surface."""

from pathlib import Path

import numpy as np
import pandas as pd

from refinenet import config
from refinenet.cli.estimate import compared_normals, min_points
from refinenet.data.clouds import cloud_key, read_scan, scan_files, scored_points, surface_sample
from refinenet.data.io import read_cloud, read_normals
from refinenet.evaluation.denoise import poisson_surface, read_record
from refinenet.evaluation.figures import (
    MAX_ERROR,
    DenoisedColumn,
    Panel,
    Scan,
    clusters_figure,
    denoising_figure,
    loss_figure,
    normals_figure,
    real_figure,
    training_figure,
)
from refinenet.evaluation.table import METHOD_NAMES
from refinenet.features.cache import load_for_cloud
from refinenet.geometry.orientation import orient_mst
from refinenet.network.clustering import cloud_clusters, load_cluster_model
from refinenet.network.release import Release
from refinenet.pipeline import captions, stage
from refinenet.pipeline.captions import scanner_line
from refinenet.pipeline.catalogue import (
    CLUSTER_FIGURE_VARIANTS,
    DENOISE_INPUT,
    DENOISE_METHODS,
    REAL_VARIANT,
    TABLES,
)
from refinenet.pipeline.layout import (
    FIGURE_CLUSTERS,
    FIGURE_DENOISE,
    FIGURE_LOSS,
    FIGURE_NORMALS,
    FIGURE_REAL,
    FIGURE_TRAINING,
    HISTORY,
)
from refinenet.pipeline.methods import REFINENET, figure_name, refinenet
from refinenet.pipeline.workflow import Pipeline


def arguments(parser):
    parser.add_argument("--figure", required=True,
                        choices=("normals", "clusters", "training", "denoise", "loss", "real"))
    parser.add_argument("--clouds", nargs="+", default=[],
                        help="the figure's test cloud records (.npz); real: the training clouds (their spacing)")
    parser.add_argument("--features", help="clusters: the cloud's feature cache (full's)")
    parser.add_argument("--clusters", nargs="+", default=[],
                        help="clusters: the cluster model of each Kc shown; real: the X = 8 variant's")
    parser.add_argument("--scans", nargs="+", default=[], help="real: the simulated scans, or the folder of real ones")
    parser.add_argument("--networks", nargs="+", default=[], help="real: the network folder of each cluster")
    parser.add_argument("--sweep", help="clusters: table_clusters' CSV")
    parser.add_argument("--records", nargs="+", default=[], help="denoise: the cloud's denoising record")


def main(params, args):
    pipe = Pipeline(config.read_raw(args.params), args.params)
    footer = captions.data_line(params)
    if args.figure == "normals":
        normals_figure(panels(pipe, args.clouds, {m: figure_name(m) for m in pipe.figure_methods()}),
                       footer + f" Unoriented angular error, heat map clipped at {MAX_ERROR:g} deg; "
                       "orthographic view, azimuth 35, elevation 25 deg.", FIGURE_NORMALS)
    elif args.figure == "loss":
        loss_figure(panels(pipe, args.clouds, captions.rows(pipe, TABLES["table_loss"])),
                    footer + " Unoriented angular error of each point under each network.", FIGURE_LOSS)
    elif args.figure == "clusters":
        clusters(pipe, args.clouds[0], args.features, args.clusters, args.sweep, footer)
    elif args.figure == "denoise":
        denoise(params.denoise, args.clouds[0], args.records[0], footer)
    elif args.figure == "real":
        real(pipe, args.scans, args.clouds, args.clusters[0], args.networks, footer)
    else:
        v = args.variant
        n = pipe.params[v].clustering.n_clusters
        histories = {c: pd.read_csv(HISTORY.format(variant=v, cluster=c)) for c in range(n)}
        training_figure(histories, f"Refine-Net variant {v}: {n} clusters", footer,
                        {"png": FIGURE_TRAINING.format(variant=v)})


def panels(pipe, clouds, methods):
    """One panel per test cloud: its scored points (a PCPNet shape's `.pidx` points, and the seeded subset that the
    methods' variants refine: the network computed no others), its true normals and the normals of each method, by
    the name `methods` gives it."""
    made, points = [], pipe.scored_subset(tuple(methods))
    for path in clouds:
        cloud = read_cloud(path)
        key, scored = cloud_key(path, cloud), scored_points(cloud, points)
        rows = slice(None) if scored is None else scored
        estimates = {name: read_normals(pipe.normals_path(m, key), len(cloud), scored) for m, name in methods.items()}
        made.append(Panel(key.removeprefix("test/"), cloud.points[rows], cloud.normals[rows], estimates))
    return made


def clusters(pipe, cloud_path, features_path, models, sweep_path, footer):
    cloud, features = load_for_cloud(cloud_path, features_path)
    labels = {}
    for variant, path in zip(CLUSTER_FIGURE_VARIANTS, models, strict=True):
        model, _ = load_cluster_model(path)
        labels[f"Kc = {model.n_clusters} ({variant})"] = cloud_clusters(model, features.nf, features.frames)
    table = TABLES["table_clusters"]
    key, _ = table.sweep
    rows = captions.rows(pipe, table)
    errors = pd.read_csv(sweep_path, index_col=0)["Average/mean"]
    clusters_figure(cloud.points[features.points], labels,
                    ([pipe.swept(m, key) for m in rows], [float(errors[label]) for label in rows.values()]),
                    footer + f" Cloud {cloud_key(cloud_path, cloud)}.", FIGURE_CLUSTERS)



def real(pipe, scans, training_clouds, cluster_path, network_folders, footer):
    """`scans`: the simulated scans' files, or the folder of real scans that params.yaml `figures.scans` names."""
    params = pipe.params[REAL_VARIANT]
    training = [read_cloud(path).points for path in training_clouds]
    release = Release.of_run(params, cluster_path, network_folders, training)
    least = min_points(params, REFINENET, refine_initial=False)
    drawn = []
    for path in scan_files(params.figures.scans) if params.figures.scans else map(Path, scans):
        points = read_scan(path, params.figures.scan_points, params.seed, least)
        estimates = compared_normals(points, {refinenet(REAL_VARIANT): release})
        drawn.append(Scan(path.stem, points, {figure_name(m): n for m, n in estimates.items()}))
    most = params.figures.scan_points
    source = f"Real scans of {params.figures.scans}" if params.figures.scans else "Simulated scans"
    real_figure(drawn, f"{footer} {source}" + (f", at most {most:,} points each" if most else "")
                + "; l_d from the point spacing; each scan seen along its depth axis."
                + ("" if params.figures.scans else " " + scanner_line(pipe.scanner)) + " Refine-Net x8: X = "
                + f"{params.features.n_normals}, without the initial normal.", FIGURE_REAL)


def denoise(config, cloud_path, record_path, footer):
    cloud, record = read_cloud(cloud_path), read_record(record_path)
    surface, surface_normals = surface_sample(cloud_path, cloud.meta, len(cloud))
    columns = [DenoisedColumn("noisy input / true surface", cloud.points, record["distance"][DENOISE_INPUT],
                              poisson_surface(surface, surface_normals, config.poisson_depth))]
    for method in DENOISE_METHODS:
        points = record["points"][method].astype(np.float64)
        oriented = orient_mst(points, record["normals"][method].astype(np.float64))
        columns.append(DenoisedColumn(METHOD_NAMES[method], points, record["distance"][method],
                                      poisson_surface(points, oriented, config.poisson_depth)))
    clip = 2 * cloud.meta["noise_sigma"] / cloud.meta["l_d"]
    denoising_figure(columns, clip, footer + f" Cloud {cloud_key(cloud_path, cloud)}; {config.iterations} updates, "
                     f"lambda {config.lam}, sigma {config.sigma}, radius {config.radius} l_d; distance heat map "
                     f"clipped at 2 noise sigma; Poisson depth {config.poisson_depth}.", FIGURE_DENOISE)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
