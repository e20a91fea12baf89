"""Refine the normals of one test cloud with the per-cluster networks; write them in the PCPNet format."""

import argparse
import json

from refinenet import stage
from refinenet.clustering import load_cluster_model
from refinenet.dataset import PatchConfig
from refinenet.features import load_for_cloud
from refinenet.inference import load_networks, refine_normals
from refinenet.io import write_normals
from refinenet.model import network_from_params


def main(args: argparse.Namespace) -> None:
    network = network_from_params(json.loads(args.network))
    patch = stage.config_from_json(PatchConfig, args.patches, "patches")
    cloud, features = load_for_cloud(args.cloud, args.features)
    model, _ = load_cluster_model(args.clusters)
    networks = load_networks(args.model_dir, network, model.n_clusters, device=args.device)
    normals = refine_normals(cloud.points, features, model, networks, batch_size=args.batch_size,
                             device=args.device, patch=patch, seed=args.seed, progress=True)
    write_normals(args.out, normals)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--features", required=True, help="the cloud's feature cache")
    parser.add_argument("--clusters", required=True, help="the cluster model")
    parser.add_argument("--model-dir", required=True, help="folder of the per-cluster networks")
    parser.add_argument("--network", default='{"preset": "release"}', help="params.yaml `network` as JSON")
    parser.add_argument("--patches", default="{}", help="params.yaml `patches` as JSON")
    parser.add_argument("--batch-size", type=int, default=1024)
    parser.add_argument("--device", default="auto", help="auto, cpu or cuda")
    parser.add_argument("--seed", type=int, default=0, help="draws the ball-mode patch subsets")
    parser.add_argument("--out", required=True, help="normals file (.normals text, PCPNet format, or .npy)")
    stage.run(parser, main)
