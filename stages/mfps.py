"""Estimate the initial normals of one cloud with MFPS (docs/algorithm.md §2) and, where asked (the test clouds),
those of its simple-MFPS ablation, which one pass over the fitted patches gives as well."""

from dataclasses import replace

from refinenet.data.clouds import cloud_key
from refinenet.data.io import check_count, read_cloud, write_normals
from refinenet.data.noise import derive_seed
from refinenet.estimators.mfps import mfps_and_simple_normals
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--out", required=True, help="the MFPS normals")
    parser.add_argument("--simple-out", help="the simple-MFPS normals (default: not written)")


def main(params, args):
    cloud = read_cloud(args.cloud)
    config = replace(params.mfps, seed=derive_seed(params.seed, "mfps", cloud_key(args.cloud, cloud)))
    check_count(args.cloud, len(cloud), max(config.scales[-1], config.k_bw))
    normals = mfps_and_simple_normals(cloud.points, config, progress=True, workers=args.threads)
    write_normals(args.out, normals["mfps"])
    if args.simple_out:
        write_normals(args.simple_out, normals["simple_mfps"])


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
