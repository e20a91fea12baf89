"""Estimate normals of one cloud with a classical baseline (PCA or Jet)."""

import argparse

from refinenet import stage
from refinenet.baselines import jet_normals, pca_normals
from refinenet.io import read_cloud, write_normals


def main(args: argparse.Namespace) -> None:
    cloud = read_cloud(args.cloud, min_points=args.k)
    if args.method == "pca":
        normals = pca_normals(cloud.points, args.k)
    else:
        normals = jet_normals(cloud.points, args.k, args.degree)
    write_normals(args.out, normals)


if __name__ == "__main__":
    parser = argparse.ArgumentParser(description=__doc__)
    parser.add_argument("--method", required=True, choices=["pca", "jet"])
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--k", type=int, required=True, help="neighbours per point, the point included")
    parser.add_argument("--degree", type=int, default=2, help="Jet polynomial degree")
    parser.add_argument("--out", required=True)
    stage.run(parser, main)
