"""Export the run's trained networks and cluster model as the release `refinenet normals` loads, with a model card."""

import hashlib
import json
from dataclasses import asdict
from pathlib import Path

import numpy as np

from refinenet import config
from refinenet.data.io import read_cloud
from refinenet.data.noise import derive_seed
from refinenet.data.shapes import catalogue
from refinenet.errors import InputError
from refinenet.features.cache import load_for_cloud
from refinenet.network.clustering import load_cluster_model
from refinenet.network.inference import load_networks
from refinenet.network.model import RefineNet, architecture
from refinenet.network.release import export, half_precision_change, parameter_counts, training_spacing
from refinenet.network.training import RESULT, network_fingerprint
from refinenet.pipeline import stage

#: Points per check cloud on which the half-precision change is measured.
CHECK_POINTS = 2000


def arguments(parser):
    parser.add_argument("--clouds", nargs="+", required=True, help="the training cloud records")
    parser.add_argument("--clusters", required=True, help="the cluster model")
    parser.add_argument("--networks", nargs="+", required=True, help="the network folder of each cluster, in order")
    parser.add_argument("--check-clouds", nargs="+", required=True, help="test clouds for the half-precision check")
    parser.add_argument("--check-features", nargs="+", required=True, help="their feature caches, in order")
    parser.add_argument("--out", required=True, help="the release folder")


def fingerprint(resolved: dict, clouds: list[str]) -> str:
    """The name of a release: a hash of the resolved params and the training clouds' file names, so that networks
    trained on another catalogue of shapes under the same params get another name."""
    named = {"params": resolved, "training_clouds": sorted(Path(c).name for c in clouds)}
    return hashlib.sha256(json.dumps(named, sort_keys=True).encode()).hexdigest()[:16]


def main(params, args):
    resolved = config.resolve(config.read_raw(args.params))
    network = architecture(params.network, params.features, params.patches)
    model, _ = load_cluster_model(args.clusters)
    if len(args.networks) != model.n_clusters:
        raise InputError(args.clusters, f"{model.n_clusters} clusters, but {len(args.networks)} network folders")
    networks = load_networks(args.networks, network, device="cpu", fuse=False)
    checks = [(cloud.points, features, cloud.normals) for cloud, features in
              map(load_for_cloud, args.check_clouds, args.check_features)]
    clouds = [read_cloud(path) for path in args.clouds]
    card = {
        "profile": params.profile,
        "fingerprint": fingerprint(resolved, args.clouds),
        "network": asdict(params.network),
        "n_normals": network.n_normals,
        "n_clusters": model.n_clusters,
        "parameters": parameter_counts(RefineNet(network), len(networks)),
        "training": asdict(params.training),
        "training_data": {
            "source": params.data.source + (f" ({params.data.path})" if params.data.path else ""),
            "clouds": len(clouds),
            "points_per_cloud": int(np.median([len(c) for c in clouds])),
            "noise_percent": sorted({c.meta.get("noise_percent") for c in clouds} - {None}),
            "spacing_ratio": training_spacing([c.points for c in clouds]),
            "meshes": sorted({c.meta["origin"] for c in clouds  # the files of the synthesised clouds
                              if c.meta.get("noise_percent") is not None and c.meta["origin"] not in catalogue()}),
        },
        "clusters": {str(c): json.loads((Path(folder) / RESULT).read_text()) for c, folder in enumerate(args.networks)},
        "half_precision": half_precision_change(checks, model, networks, params.patches, params.inference,
                                                CHECK_POINTS, derive_seed(params.seed, "release")),
    }
    export(args.out, resolved, model, {c: net.state_dict() for c, net in networks.items()},
           network_fingerprint(network), card)


if __name__ == "__main__":
    stage.run(__doc__, arguments, main)
