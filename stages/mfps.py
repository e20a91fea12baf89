"""Estimate the initial normals of one cloud with MFPS (docs/algorithm.md §2) or its simple-MFPS ablation."""

from dataclasses import replace

from refinenet.data.clouds import cloud_key
from refinenet.data.io import check_array, read_cloud, write_normals
from refinenet.data.noise import derive_seed
from refinenet.estimators.mfps import METHODS, mfps_normals
from refinenet.pipeline import stage


def main(params, args):
    cloud = read_cloud(args.cloud)
    config = replace(params.mfps, simple=args.method == "simple_mfps",
                     seed=derive_seed(params.seed, "mfps", cloud_key(args.cloud, cloud)))
    check_array(args.cloud, cloud.points, "points", max(config.scales[-1], config.k_bw))
    write_normals(args.out, mfps_normals(cloud.points, config, progress=True, workers=args.threads))


if __name__ == "__main__":
    stage.run(__doc__, stage.normals_job(METHODS), main)
