"""Fit the normal-based clustering (PCA to 3 components + k-means, ALGORITHM.md §5) on the training clouds."""

import argparse

import numpy as np

from refinenet import stage
from refinenet.clustering import fit_clusters, local_normals, save_cluster_model
from refinenet.features import load_features


def main(args: argparse.Namespace) -> None:
    pooled = []
    for path in args.features:
        features, _ = load_features(path)
        pooled.append(local_normals(features.nf, features.frames))
    model = fit_clusters(np.concatenate(pooled), args.n_clusters, args.restarts, args.seed, args.max_samples)
    save_cluster_model(args.out, model, {"training_clouds": len(args.features), "seed": args.seed})


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--features", nargs="+", required=True, help="feature caches of the training clouds")
    parser.add_argument("--n-clusters", type=int, default=4, help="Kc")
    parser.add_argument("--restarts", type=int, default=5)
    parser.add_argument("--max-samples", type=int, default=200_000)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
