"""Refined normals of a whole cloud (docs/algorithm.md §10, stage I): cluster, run each cluster's network, rotate back.

Inputs are built one batch at a time from the feature cache, so memory stays bounded by the batch size (patches
are never materialised for the whole cloud). The same code runs on CPU and CUDA.
"""

from __future__ import annotations

from collections.abc import Mapping, Sequence
from pathlib import Path

import numpy as np
import torch
from tqdm import tqdm

from refinenet.config import InferenceConfig, PatchConfig
from refinenet.errors import InputError
from refinenet.features.cache import Features
from refinenet.geometry.frames import to_world
from refinenet.network.clustering import ClusterModel
from refinenet.network.dataset import make_inputs, prepare
from refinenet.network.devices import resolve_device, resolve_precision
from refinenet.network.model import NetworkConfig, RefineNet, for_inference
from refinenet.network.training import BEST, EMPTY, network_fingerprint
from refinenet.profiling import stage


def refine_normals(points: np.ndarray, features: Features, cluster_model: ClusterModel,
                   networks: Mapping[int, RefineNet], patch: PatchConfig, config: InferenceConfig, seed: int = 0,
                   progress: bool = False, length: float | None = None) -> np.ndarray:
    """(M, 3) float32 unit normals in the world frame, one per feature row (of the point `features.points` names).

    Each point goes through the network of its cluster (`networks` maps cluster id -> network, which is moved to
    `device` and put in eval mode); a cluster without a network (trained as empty) keeps the first normal of nf.
    `patch` must match the training patches; `seed` draws the ball-mode subsets. `length` is the l_d of ball
    patches (`dataset.PreparedCloud`).
    """
    device, batch_size = resolve_device(config.device), config.batch_size
    if batch_size < 1:
        raise ValueError(f"batch_size must be at least 1, got {batch_size}")
    unknown = sorted(set(networks) - set(range(cluster_model.n_clusters)))
    if unknown:
        raise ValueError(f"networks for clusters {unknown}, but the cluster model has {cluster_model.n_clusters}")
    with stage("patches"):
        cloud = prepare(points, features, cluster_model, centres=features.centres, length=length)
    normals = features.n_first.astype(np.float32)
    rng = np.random.default_rng(seed)
    members = {c: np.flatnonzero(cloud.clusters == c) for c in sorted(networks)}
    bar = tqdm(total=sum(len(index) for index in members.values()), desc="refining normals", unit="pt",
               disable=not progress)
    with bar, torch.inference_mode():
        for c, index in members.items():
            net = networks[c].to(device).eval()
            for start in range(0, len(index), batch_size):
                batch = index[start:start + batch_size]
                with stage("patches"):
                    inputs = make_inputs(cloud, batch, patch, net.config, rng).tensors(device)
                with stage("network"):
                    local = net(*inputs).float().cpu().numpy()
                normals[batch] = to_world(features.frames[batch], local)
                bar.update(len(batch))
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


def load_networks(folders: Sequence[str | Path], network: NetworkConfig, device: str,
                  fuse: bool = True, precision: str = "float32") -> dict[int, RefineNet]:
    """The best weights of every trained cluster, in eval mode on `device`; `folders[c]` is the output folder of
    cluster c's training (`training.train_cluster`).

    Clusters marked empty are left out (refine_normals keeps their first normals). `fuse` folds BN into the
    preceding Linear layers: equal outputs up to float rounding, faster (`model.fuse_batch_norm`). `precision`
    (`InferenceConfig.precision`) is that of the feature modules (`model.reduced_precision`).
    """
    device = resolve_device(device)
    precision = resolve_precision(precision, device)
    networks = {}
    for c, folder in enumerate(map(Path, folders)):
        best = folder / BEST
        if not best.exists():
            if (folder / EMPTY).exists():
                continue
            raise InputError(best, "missing: the cluster was neither trained nor marked empty")
        saved = torch.load(best, map_location=device, weights_only=True)
        if saved["network"] != network_fingerprint(network):
            raise InputError(best, f"was trained with another architecture: {saved['network']}")
        net = RefineNet(network)
        net.load_state_dict(saved["model"])
        networks[c] = for_inference(net.to(device), fuse, precision)
    return networks
