"""Refine the normals of one test cloud with the per-cluster networks; write them in the PCPNet format. Only the
scored points get a network pass (a PCPNet shape's `.pidx`, and of those a seeded subset of `inference.points`:
`data.clouds.scored_points`); the others get NaN normals."""

import numpy as np

from refinenet.data.clouds import cloud_key, scored_points
from refinenet.data.io import write_normals
from refinenet.data.noise import derive_seed
from refinenet.errors import InputError
from refinenet.features.cache import load_for_cloud
from refinenet.network.clustering import load_cluster_model
from refinenet.network.inference import load_networks, refine_normals
from refinenet.network.model import architecture
from refinenet.pipeline import stage


def arguments(parser):
    parser.add_argument("--cloud", required=True)
    parser.add_argument("--features", required=True, help="the cloud's feature cache")
    parser.add_argument("--clusters", required=True, help="the cluster model")
    parser.add_argument("--networks", nargs="+", required=True, help="the network folder of each cluster, in order")
    parser.add_argument("--out", required=True, help="normals file (.normals text, PCPNet format, or .npy)")


def main(params, args):
    network = architecture(params.network, params.features, params.patches)
    cloud, features = load_for_cloud(args.cloud, args.features)
    scored = scored_points(cloud, params.inference.points)
    if scored is not None:
        rows = np.flatnonzero(np.isin(features.points, scored))
        if len(rows) != len(scored):
            raise InputError(args.features, f"features of {len(rows)} of the {len(scored)} scored points")
        features = features.rows(rows)
    model, _ = load_cluster_model(args.clusters)
    if len(args.networks) != model.n_clusters:
        raise InputError(args.clusters, f"{model.n_clusters} clusters, but {len(args.networks)} network folders")
    networks = load_networks(args.networks, network, device=params.inference.device,
                             precision=params.inference.precision)
    seed = derive_seed(params.seed, "refine", cloud_key(args.cloud, cloud))
    refined = refine_normals(cloud.points, features, model, networks, params.patches, params.inference, seed=seed,
                             progress=True)
    normals = np.full((len(cloud), 3), np.nan, dtype=np.float32)
    normals[features.points] = refined
    write_normals(args.out, normals)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
