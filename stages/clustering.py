"""Fit the normal-based clustering (PCA to 3 components + k-means, docs/algorithm.md §5) on the training clouds."""


from refinenet.data.noise import derive_seed
from refinenet.network.clustering import fit_clusters, pooled_local_normals, save_cluster_model
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--features", nargs="+", required=True, help="feature caches of the training clouds")
    parser.add_argument("--out", required=True)


def main(params, args):
    seed = derive_seed(params.seed, "clusters")
    model = fit_clusters(pooled_local_normals(args.features), params.clustering, seed)
    save_cluster_model(args.out, model, {"training_clouds": len(args.features), "seed": seed})


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
