"""The paper's figures (docs/algorithm.md §12, Figures), one `--figure` per step:
* normals (fig:syn / fig:insight): normals of PCA, Jet, MFPS and Refine-Net as RGB and their angular errors as heat
  maps on chosen test clouds (a PCPNet shape's scored points only: the network computed no others);
* clusters (fig:cluster): a test cloud coloured by cluster for Kc = 2 and Kc = 4, beside the Kc curve;
* training: training loss and validation error per epoch of every cluster, one figure per trained variant."""

import pandas as pd

from refinenet import config
from refinenet.data.clouds import cloud_key, scored_points
from refinenet.data.io import read_cloud, read_normals
from refinenet.evaluation.figures import MAX_ERROR, Panel, clusters_figure, normals_figure, training_figure
from refinenet.evaluation.table import METHOD_NAMES
from refinenet.features.cache import load_for_cloud
from refinenet.network.clustering import cloud_clusters, load_cluster_model
from refinenet.pipeline import stage
from refinenet.pipeline.workflow import (
    CLUSTER_FIGURE_VARIANTS,
    FIGURE_CLUSTERS,
    FIGURE_METHODS,
    FIGURE_NORMALS,
    FIGURE_TRAINING,
    HISTORY,
    TABLES,
    Pipeline,
    data_line,
)


def arguments(parser):
    parser.add_argument("--figure", required=True, choices=("normals", "clusters", "training"))
    parser.add_argument("--clouds", nargs="+", default=[], help="the figure's test cloud records (.npz)")
    parser.add_argument("--features", help="clusters: the cloud's feature cache (full's)")
    parser.add_argument("--clusters", nargs="+", default=[], help="clusters: the cluster model of each Kc shown")
    parser.add_argument("--sweep", help="clusters: table_clusters' CSV")


def main(params, args):
    pipe = Pipeline(config.read_raw(args.params), args.params)
    footer = data_line(params)
    if args.figure == "normals":
        normals(pipe, args.clouds, footer + f" Unoriented angular error, heat map clipped at {MAX_ERROR:g} deg; "
                "orthographic view, azimuth 35, elevation 25 deg.")
    elif args.figure == "clusters":
        clusters(pipe, args.clouds[0], args.features, args.clusters, args.sweep, footer)
    else:
        for v in pipe.trained:
            n = pipe.params[v].clustering.n_clusters
            histories = {c: pd.read_csv(HISTORY.format(variant=v, cluster=c)) for c in range(n)}
            training_figure(histories, f"Refine-Net variant {v}: {n} clusters", footer,
                            {"png": FIGURE_TRAINING.format(variant=v)})


def normals(pipe, clouds, footer):
    panels = []
    for path in clouds:
        cloud = read_cloud(path)
        key, scored = cloud_key(path, cloud), scored_points(cloud.meta)
        rows = slice(None) if scored is None else scored
        estimates = {METHOD_NAMES[m]: read_normals(pipe.normals_path(m, key), len(cloud), scored)
                     for m in FIGURE_METHODS}
        panels.append(Panel(key.removeprefix("test/"), cloud.points[rows], cloud.normals[rows], estimates))
    normals_figure(panels, footer, FIGURE_NORMALS)


def clusters(pipe, cloud_path, features_path, models, sweep_path, footer):
    cloud, features = load_for_cloud(cloud_path, features_path)
    labels = {}
    for variant, path in zip(CLUSTER_FIGURE_VARIANTS, models, strict=True):
        model, _ = load_cluster_model(path)
        labels[f"Kc = {model.n_clusters} ({variant})"] = cloud_clusters(model, features.nf, features.frames)
    table = TABLES["table_clusters"]
    key, _ = table.sweep
    rows = pipe.rows(table)
    errors = pd.read_csv(sweep_path, index_col=0)["Average/mean"]
    clusters_figure(cloud.points[features.points], labels,
                    ([pipe.swept(m, key) for m in rows], [float(errors[label]) for label in rows.values()]),
                    footer + f" Cloud {cloud_key(cloud_path, cloud)}.", FIGURE_CLUSTERS)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
