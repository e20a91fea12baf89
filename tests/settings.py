"""The library's settings in tests: params.yaml's own values (no profile applied), as the typed blocks, with
helpers that replace some fields. The tests take no setting from anywhere else, so the values they exercise are
the ones users run."""

from dataclasses import replace
from pathlib import Path

from refinenet import config
from refinenet.network.model import architecture

REPO = Path(__file__).resolve().parents[1]
BASE = config.load(REPO / "params.yaml", apply_profile=False)


def _changed(block):
    return lambda **changes: replace(block, **changes)


#: Each block of params.yaml's own values, with some fields replaced: e.g. `mfps_config(scales=(10, 20))`.
mfps_config = _changed(BASE.mfps)
feature_config = _changed(BASE.features)
patch_config = _changed(BASE.patches)
train_config = _changed(BASE.training)
clustering_config = _changed(BASE.clustering)
inference_config = _changed(BASE.inference)
#: The simulated scans' sensor (params.yaml `scanner`, a pipeline block outside `Params`).
SCANNER = config.ScannerConfig.from_resolved(config.resolve(config.read_raw(REPO / "params.yaml"), apply_profile=False))


#: The network params.yaml's own values build (the release preset for X = 9 and knn-100 patches).
NETWORK = architecture(BASE.network, BASE.features, BASE.patches)


def cluster_samples(clouds, cluster, patch=None, **changes):
    """`ClusterData` of one cluster with params.yaml's split settings, some replaced (e.g. seed)."""
    from refinenet.network.training import cluster_data

    return cluster_data(clouds, cluster, train_config(**changes), patch or BASE.patches)
