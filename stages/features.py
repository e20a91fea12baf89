"""Cache the network inputs of one cloud: multi-scale filtered normals, per-point frames and height maps."""

import argparse

from refinenet import stage
from refinenet.features import FeatureConfig, compute_features, save_features
from refinenet.io import read_cloud, read_normals


def main(args: argparse.Namespace) -> None:
    config = stage.config_from_json(FeatureConfig, args.config, "features")
    cloud = read_cloud(args.cloud, min_points=config.hmp_k)
    initial = read_normals(args.initial, len(cloud))
    features = compute_features(cloud.points, initial, config, progress=args.progress)
    save_features(args.out, features, {"cloud": args.cloud, "initial_normals": args.initial, **cloud.meta})


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--initial", required=True, help="initial (MFPS) normals of the cloud")
    parser.add_argument("--config", default="{}", help="FeatureConfig fields as JSON (params.yaml `features`)")
    parser.add_argument("--progress", action="store_true")
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
