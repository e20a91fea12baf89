"""Estimate the normals of one cloud with a classical baseline (PCA or Jet), with the paper's K for its category."""

from refinenet.data.io import check_array, read_cloud, write_normals
from refinenet.estimators.baselines import METHODS, baseline_normals, neighbourhood_size
from refinenet.pipeline import stage


def main(params, args):
    cloud = read_cloud(args.cloud)
    category = cloud.meta.get("category")
    check_array(args.cloud, cloud.points, "points", neighbourhood_size(params.baselines, args.method, category))
    write_normals(args.out, baseline_normals(cloud.points, args.method, params.baselines, category))


if __name__ == "__main__":
    stage.run(__doc__, stage.normals_job(METHODS), main)
