"""Cache the network inputs of one cloud: multi-scale filtered normals, per-point frames and height maps, for the
points the tables score (a PCPNet test shape's `.pidx` subset; every point otherwise)."""

from refinenet.data.clouds import scored_points
from refinenet.data.io import check_array, read_cloud, read_normals
from refinenet.features.cache import compute_features, save_features
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--initial", required=True, help="initial (MFPS) normals of the cloud")
    parser.add_argument("--out", required=True)


def main(params, args):
    cloud = read_cloud(args.cloud)
    check_array(args.cloud, cloud.points, "points", params.features.hmp_k)
    initial = read_normals(args.initial, len(cloud))
    features = compute_features(cloud.points, initial, params.features, progress=True,
                                centres=scored_points(cloud))
    save_features(args.out, features, {"cloud": args.cloud, "initial_normals": args.initial, **cloud.meta})


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
