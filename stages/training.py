"""Train the network of one cluster on the training clouds (docs/algorithm.md §9), resuming from its checkpoint."""

from dataclasses import replace

from refinenet.data.noise import derive_seed
from refinenet.errors import InputError
from refinenet.features.cache import load_for_cloud
from refinenet.network.clustering import load_cluster_model
from refinenet.network.dataset import prepare
from refinenet.network.model import architecture
from refinenet.network.training import cluster_data, cluster_dir, train_cluster
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--cluster", type=int, required=True)
    parser.add_argument("--clouds", nargs="+", required=True, help="training cloud records (.npz)")
    parser.add_argument("--features", nargs="+", required=True, help="their feature caches, in the same order")
    parser.add_argument("--clusters", required=True, help="the cluster model")
    parser.add_argument("--out", required=True, help="the cluster's network folder")
    parser.add_argument("--history", required=True, help="the cluster's training history (CSV)")
    parser.add_argument("--checkpoints", required=True, help="folder of the resumable checkpoints of every cluster")


def main(params, args):
    if len(args.clouds) != len(args.features):
        raise InputError("--features", f"{len(args.features)} feature caches for {len(args.clouds)} clouds")
    network = architecture(params.network, params.features, params.patches)
    # The job's cores: the loader workers build batches, the rest train.
    config = replace(params.training, seed=derive_seed(params.seed, "train", args.cluster),
                     threads=max(1, args.threads - params.training.loader_workers))
    model, _ = load_cluster_model(args.clusters)
    clouds = []
    for cloud_path, feature_path in zip(args.clouds, args.features, strict=True):
        cloud, features = load_for_cloud(cloud_path, feature_path)
        clouds.append(prepare(cloud.points, features, model, cloud.normals))
    data = cluster_data(clouds, args.cluster, config, params.patches)
    train_cluster(config, network, data, args.out, progress=True,
                  checkpoint_dir=cluster_dir(args.checkpoints, args.cluster), history_path=args.history)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
