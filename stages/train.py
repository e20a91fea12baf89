"""Train the network of one cluster on the training clouds (ALGORITHM.md §9), resuming from its checkpoint."""

import argparse
import json
from dataclasses import asdict

from refinenet import stage
from refinenet.atomic import write_text
from refinenet.clustering import assign, load_cluster_model, local_normals
from refinenet.dataset import Cloud, PatchConfig
from refinenet.errors import InputError
from refinenet.features import load_for_cloud
from refinenet.model import network_from_params
from refinenet.training import TrainConfig, cluster_data, cluster_dir, train_cluster


def main(args: argparse.Namespace) -> None:
    network = network_from_params(json.loads(args.network))
    patch = stage.config_from_json(PatchConfig, args.patches, "patches")
    config = stage.config_from_json(TrainConfig, args.training, "training")
    if len(args.clouds) != len(args.features):
        raise InputError("--features", f"{len(args.features)} feature caches for {len(args.clouds)} clouds")
    model, _ = load_cluster_model(args.clusters)
    clouds = []
    for cloud_path, feature_path in zip(args.clouds, args.features, strict=True):
        cloud, features = load_for_cloud(cloud_path, feature_path)
        clusters = assign(model, local_normals(features.nf, features.frames))
        clouds.append(Cloud(cloud.points, features, clusters, cloud.normals))
    data = cluster_data(clouds, args.cluster, config, patch)
    out_dir = cluster_dir(args.out_dir, args.cluster)
    result = train_cluster(config, network, data, out_dir, progress=True,
                           checkpoint_dir=cluster_dir(args.checkpoint_dir, args.cluster))
    summary = {"cluster": args.cluster, "train_points": len(data.train), "val_points": len(data.val), **asdict(result)}
    write_text(out_dir / "result.json", json.dumps(summary, indent=2) + "\n")
    print(json.dumps(summary))


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--clouds", nargs="+", required=True, help="training cloud records (.npz)")
    parser.add_argument("--features", nargs="+", required=True, help="their feature caches, in the same order")
    parser.add_argument("--clusters", required=True, help="the cluster model")
    parser.add_argument("--cluster", type=int, required=True)
    parser.add_argument("--network", default='{"preset": "release"}', help="params.yaml `network` as JSON")
    parser.add_argument("--patches", default="{}", help="params.yaml `patches` as JSON")
    parser.add_argument("--training", default="{}", help="params.yaml `training` as JSON")
    parser.add_argument("--out-dir", required=True, help="model folder; the cluster's network goes to cluster_<c>")
    parser.add_argument("--checkpoint-dir", required=True, help="where resumable checkpoints are kept")
    stage.run(parser, main)
