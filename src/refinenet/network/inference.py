"""Refined normals of a whole cloud (docs/algorithm.md §10, stage I): cluster, run each cluster's network, rotate back.

Inputs are built one batch at a time from the feature cache, so memory stays bounded by the batch size (patches
are never materialised for the whole cloud). The same code runs on CPU and CUDA.
"""

from __future__ import annotations

from collections import deque
from collections.abc import Callable, Mapping, Sequence
from concurrent.futures import Future, ThreadPoolExecutor
from pathlib import Path

import numpy as np
import torch
from torch import Tensor
from tqdm import tqdm

from refinenet.config import InferenceConfig, PatchConfig
from refinenet.errors import InputError
from refinenet.features.cache import Features
from refinenet.geometry.frames import to_world
from refinenet.network.clustering import ClusterModel
from refinenet.network.dataset import make_inputs, prepare
from refinenet.network.devices import resolve_device, resolve_precision
from refinenet.network.fused import for_inference
from refinenet.network.model import NetworkConfig, RefineNet
from refinenet.network.training import BEST, EMPTY, network_fingerprint
from refinenet.profiling import stage
from refinenet.threads import native_threads


def refine_normals(points: np.ndarray, features: Features, cluster_model: ClusterModel,
                   networks: Mapping[int, RefineNet], patch: PatchConfig, config: InferenceConfig, seed: int = 0,
                   progress: bool = False, length: float | None = None,
                   neighbours: np.ndarray | None = None) -> np.ndarray:
    """(M, 3) float32 unit normals in the world frame, one per feature row (of the point `features.points` names).

    Each point goes through the network of its cluster (`networks` maps cluster id -> network, which is moved to
    `device` and put in eval mode); a cluster without a network (trained as empty) keeps the first normal of nf.
    `patch` must match the training patches; `seed` draws the ball-mode subsets. `length` is the l_d of ball
    patches (`dataset.PreparedCloud`), and `neighbours` the kNN lists of the feature rows' points, if the caller
    has them. On a CPU the batches run side by side, one per thread (`_BatchRunner`).
    """
    device, batch_size = resolve_device(config.device), config.batch_size
    if batch_size < 1:
        raise ValueError(f"batch_size must be at least 1, got {batch_size}")
    unknown = sorted(set(networks) - set(range(cluster_model.n_clusters)))
    if unknown:
        raise ValueError(f"networks for clusters {unknown}, but the cluster model has {cluster_model.n_clusters}")
    with stage("patches"):
        cloud = prepare(points, features, cluster_model, centres=features.centres, length=length,
                        neighbours=neighbours)
    normals = features.n_first.astype(np.float32)
    rng = np.random.default_rng(seed)
    members = {c: np.flatnonzero(cloud.clusters == c) for c in sorted(networks)}
    batches = [(c, index[start:start + batch_size]) for c, index in members.items()
               for start in range(0, len(index), batch_size)]
    nets = {c: networks[c].to(device).eval() for c in members}
    bar = tqdm(total=sum(len(index) for index in members.values()), desc="refining normals", unit="pt",
               disable=not progress)

    def put(batch: np.ndarray, local: np.ndarray) -> None:
        normals[batch] = to_world(features.frames[batch], local)
        bar.update(len(batch))

    threads = native_threads() if device.type == "cpu" else 1
    with bar, _BatchRunner(min(threads, len(batches)), put) as runner:
        for c, batch in batches:  # the inputs in order, so that `rng` draws the same subsets at any thread count
            with stage("patches"):
                inputs = make_inputs(cloud, batch, patch, nets[c].config, rng).tensors(device)
            runner.submit(nets[c], inputs, batch)
    return normals / np.linalg.norm(normals, axis=1, keepdims=True)


class _BatchRunner:
    """Runs the networks on batches, each on one thread, `threads` at a time, and hands each result to `put` in
    the order submitted. A batch of a few thousand patches is too small for two threads to share well (each
    product waits for the slower thread): side by side on one thread each they take less time, and the patches
    of the next batch are made meanwhile. One-thread products equal those of any thread count, bit for bit, in
    MKL's strict mode (which the commands set: `threads.thread_independent_products`), so their normals do not
    depend on `threads`. With one thread (a GPU, or a job given one) each batch runs at once, with the process's
    torch threads."""

    def __init__(self, threads: int, put: Callable[[np.ndarray, np.ndarray], None]) -> None:
        self.threads, self.put = threads, put
        self.pool = ThreadPoolExecutor(threads, initializer=torch.set_num_threads, initargs=(1,)) \
            if threads > 1 else None
        self.pending: deque[tuple[np.ndarray, Future]] = deque()

    def submit(self, net: RefineNet, inputs: tuple[Tensor | None, ...], batch: np.ndarray) -> None:
        if self.pool is None:
            with stage("network"):
                local = _forward(net, inputs)
            self.put(batch, local)
            return
        self.pending.append((batch, self.pool.submit(_forward, net, inputs)))
        if len(self.pending) > self.threads:
            self._collect()

    def _collect(self) -> None:
        batch, future = self.pending.popleft()
        with stage("network"):  # the wait beyond the time spent making patches meanwhile
            local = future.result()
        self.put(batch, local)

    def __enter__(self) -> _BatchRunner:
        return self

    def __exit__(self, *exc: object) -> None:
        try:
            while self.pending and exc[0] is None:
                self._collect()
        finally:
            if self.pool is not None:
                self.pool.shutdown(cancel_futures=True)


def _forward(net: RefineNet, inputs: tuple[Tensor | None, ...]) -> np.ndarray:
    """The local normals of one batch (inference mode is per thread, so it is entered here)."""
    with torch.inference_mode():
        return net(*inputs).float().cpu().numpy()


def load_networks(folders: Sequence[str | Path], network: NetworkConfig, device: str,
                  fuse: bool = True, precision: str = "float32") -> dict[int, RefineNet]:
    """The best weights of every trained cluster, in eval mode on `device`; `folders[c]` is the output folder of
    cluster c's training (`training.train_cluster`).

    Clusters marked empty are left out (refine_normals keeps their first normals). `fuse` folds BN into the
    preceding Linear layers: equal outputs up to float rounding, faster (`fused.fuse_batch_norm`). `precision`
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
