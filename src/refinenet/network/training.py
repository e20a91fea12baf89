"""Training one cluster's network (docs/algorithm.md §9, stage H), resumable after a kill with identical results.

Output folder of a cluster (`cluster_dir`):
* `checkpoint.pt`: model, optimiser, epoch, best epoch and validation RMSE, the history rows and a fingerprint of
  the settings, the training data and the code (`_fingerprint`); written atomically after every epoch. Random
  state needs no saving: every epoch reseeds numpy (shuffling, ball patches) and torch (dropout) from (seed,
  epoch), so a resumed epoch draws what an uninterrupted one would.
* `best.pt`: the weights of the epoch with the lowest validation RMSE (unoriented angle, degrees). They are kept
  beside the checkpoint and copied into the output folder when training ends, so a resumption after the folder
  was cleared (Snakemake and DVC clear an unfinished step's outputs) still ends with the best epoch's weights.
* `history.csv`: epoch, train_loss, val_mean_deg, val_rmse_deg, seconds (rewritten atomically after every
  epoch); the pipeline keeps it elsewhere (`history_path`), in a folder that DVC declares as plots.
* `result.json`: how the training ended (`TrainResult`), the sample counts and the validation error of the first
  input normal (the initial normal when X = 9: what the network must improve on), written last: its presence
  marks a finished cluster.
* `empty.json` instead of `best.pt`, when the cluster has too few points to train (fewer than 2 training or no
  validation points): inference then keeps the first normal of nf (the initial normal when X = 9) there.
"""

from __future__ import annotations

import hashlib
import json
import math
import shutil
import time
from collections.abc import Iterator, Sequence
from contextlib import contextmanager
from dataclasses import asdict, dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch
import torch.nn.functional as F
from tqdm import tqdm

from refinenet.atomic import atomic_path, write_text, write_torch
from refinenet.config import LOSSES as LOSS_NAMES
from refinenet.config import PatchConfig, TrainConfig
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.network.dataset import ClusterData, PreparedCloud
from refinenet.network.devices import resolve_device, resolve_precision
from refinenet.network.model import NetworkConfig, RefineNet

LOSSES = dict(zip(LOSS_NAMES, (F.mse_loss, F.l1_loss), strict=True))
CHECKPOINT, BEST, HISTORY, EMPTY, RESULT = "checkpoint.pt", "best.pt", "history.csv", "empty.json", "result.json"
HISTORY_COLUMNS = ("epoch", "train_loss", "val_mean_deg", "val_rmse_deg", "seconds")
#: Settings that may change between a run and its resumption without invalidating the checkpoint.
RESUMABLE_CHANGES = ("max_epochs", "patience", "device", "threads", "loader_workers")


@dataclass(frozen=True)
class TrainResult:
    """What `train_cluster` ended with."""

    epochs: int
    """Epochs completed (over all resumptions)."""
    best_epoch: int
    """Epoch of best.pt (1-based); 0 for an empty cluster."""
    best_val_rmse_deg: float
    """Validation RMSE of best.pt in degrees; nan for an empty cluster."""
    stopped_early: bool
    """True when patience ran out before max_epochs."""
    empty: bool
    """True when the cluster had too few points and only empty.json was written."""
    precision: str = "float32"
    """The precision the passes computed in (`TrainConfig.precision` resolved on this machine)."""


def cluster_dir(model_dir: str | Path, cluster: int) -> Path:
    """The output folder of one cluster's network."""
    return Path(model_dir) / f"cluster_{cluster}"


def cluster_data(clouds: Sequence[PreparedCloud], cluster: int, config: TrainConfig,
                 patch: PatchConfig) -> ClusterData:
    """The samples of one cluster with the split and caps that `config` fixes."""
    return ClusterData(clouds, cluster, patch, val_fraction=config.val_fraction, seed=config.seed,
                       max_train_points_per_cloud=config.max_train_points_per_cloud,
                       resample=config.resample_points)


def network_fingerprint(network: NetworkConfig) -> str:
    """The architecture as JSON, stored with the weights so that loading checks it."""
    return json.dumps(asdict(network), sort_keys=True)


def train_cluster(config: TrainConfig, network: NetworkConfig, data: ClusterData, out_dir: str | Path,
                  progress: bool = True, checkpoint_dir: str | Path | None = None,
                  history_path: str | Path | None = None) -> TrainResult:
    """Train (or resume training) the network of `data.cluster` in `out_dir` until patience or max_epochs.

    The resumable checkpoint goes to `checkpoint_dir` (default `out_dir`): a pipeline keeps it outside the
    folders that Snakemake and DVC clear before rerunning a step, so a killed run loses no finished epoch.
    """
    out_dir = Path(out_dir)
    out_dir.mkdir(parents=True, exist_ok=True)
    checkpoint_dir = Path(checkpoint_dir) if checkpoint_dir is not None else out_dir
    checkpoint_dir.mkdir(parents=True, exist_ok=True)
    history_path = Path(history_path) if history_path is not None else out_dir / HISTORY
    n_train, n_val = len(data.train), len(data.val)
    counts = {"cluster": data.cluster, "train_points": n_train, "val_points": n_val}
    if n_train < 2 or n_val == 0:
        write_text(out_dir / EMPTY, json.dumps(counts, indent=2) + "\n")
        _write_history(history_path, [])
        result = TrainResult(epochs=0, best_epoch=0, best_val_rmse_deg=float("nan"), stopped_early=False, empty=True)
    else:
        (out_dir / EMPTY).unlink(missing_ok=True)
        with torch_threads(config.threads):
            result = _train(config, network, data, out_dir, checkpoint_dir / CHECKPOINT, history_path, progress)
        angles = input_angles(data)
        counts |= {"input_val_mean_deg": float(angles.mean()),
                   "input_val_rmse_deg": float(np.sqrt(np.mean(angles ** 2)))}
    write_text(out_dir / RESULT, json.dumps({**counts, **asdict(result)}, indent=2) + "\n")
    return result


def input_angles(data: ClusterData) -> np.ndarray:
    """Unoriented angles (degrees) of the first normal of nf on the validation samples: the error the network
    starts from (the initial normals when X = 9, and what an empty cluster keeps)."""
    samples = data.val
    rows = {c: samples.point[samples.cloud == c] for c in np.unique(samples.cloud)}
    return np.concatenate([unoriented_angles(data.clouds[c].features.nf[index, :3], data.clouds[c].normals[index])
                           for c, index in rows.items()])


def learning_rate(config: TrainConfig, epoch: int, step: int, steps_per_epoch: int) -> float:
    """The learning rate of training step `step` (0-based) of `epoch` (1-based): a function of the position
    alone, so that a resumed run needs no scheduler state."""
    if config.lr_schedule == "constant":
        return config.lr
    done = ((epoch - 1) * steps_per_epoch + step) / (config.max_epochs * steps_per_epoch)
    return 0.5 * config.lr * (1.0 + math.cos(math.pi * done))


@contextmanager
def torch_threads(threads: int | None) -> Iterator[None]:
    """torch's CPU thread count set to `threads` (None: unchanged) for the block, then restored: a process-wide
    setting that a library call should not leave behind."""
    previous = torch.get_num_threads()
    if threads is not None:
        torch.set_num_threads(threads)
    try:
        yield
    finally:
        torch.set_num_threads(previous)


def _train(config: TrainConfig, network: NetworkConfig, data: ClusterData, out_dir: Path, checkpoint: Path,
           history: Path, progress: bool) -> TrainResult:
    """The epoch loop of `train_cluster` for a non-empty cluster."""
    n_train = len(data.train)
    device = resolve_device(config.device)
    precision = resolve_precision(config.precision, device)
    torch.manual_seed(config.seed)
    model = RefineNet(network).to(device)
    optimizer = _optimizer(config, model)
    fingerprint = _fingerprint(config, network, data)
    state: dict[str, Any] = {"epoch": 0, "best_epoch": 0, "best_val_rmse_deg": float("inf"), "history": []}
    saved = torch.load(checkpoint, map_location=device, weights_only=True) if checkpoint.exists() else None
    best = checkpoint.with_name(BEST)
    if saved is not None and saved["fingerprint"] != fingerprint:
        tqdm.write(f"{checkpoint}: written with other settings, data or code; starting over")
        saved = None
    if saved is not None and saved["best_epoch"] > 0 and not best.exists():
        tqdm.write(f"{checkpoint}: the best epoch's weights ({best.name}) are missing; starting over")
        saved = None
    if saved is not None:
        model.load_state_dict(saved["model"])
        optimizer.load_state_dict(saved["optimizer"])
        state = {key: saved[key] for key in state}
    _write_history(history, state["history"])

    batch_size = min(config.batch_size, n_train)
    while state["epoch"] < config.max_epochs and state["epoch"] - state["best_epoch"] < config.patience:
        epoch = state["epoch"] + 1
        start = time.perf_counter()
        torch.manual_seed(int(np.random.SeedSequence([config.seed, epoch]).generate_state(1)[0]))
        batches = tqdm(data.batches(data.epoch_samples(epoch), batch_size, network, (config.seed, epoch), shuffle=True,
                                    drop_last=True, workers=config.loader_workers),
                       total=n_train // batch_size, desc=f"cluster {data.cluster} epoch {epoch}", leave=False,
                       disable=not progress)
        steps = n_train // batch_size
        rates = [learning_rate(config, epoch, step, steps) for step in range(steps)]
        train_loss = _train_epoch(model, optimizer, LOSSES[config.loss], batches, rates, device, precision)
        angles = _validate(model, data, network, config, device, precision)
        row = {"epoch": epoch, "train_loss": train_loss, "val_mean_deg": float(angles.mean()),
               "val_rmse_deg": float(np.sqrt(np.mean(angles ** 2))), "seconds": time.perf_counter() - start}
        if row["val_rmse_deg"] < state["best_val_rmse_deg"]:
            state["best_epoch"], state["best_val_rmse_deg"] = epoch, row["val_rmse_deg"]
            write_torch(best, {"model": model.state_dict(), "network": network_fingerprint(network), "epoch": epoch,
                               "val_rmse_deg": row["val_rmse_deg"]})
        state["epoch"] = epoch
        state["history"] = [*state["history"], row]
        write_torch(checkpoint, {**state, "fingerprint": fingerprint, "model": model.state_dict(),
                                 "optimizer": optimizer.state_dict()})
        _write_history(history, state["history"])
        if progress:
            tqdm.write(f"cluster {data.cluster} epoch {epoch}: train loss {train_loss:.5f}, "
                       f"val mean {row['val_mean_deg']:.3f} deg, val RMSE {row['val_rmse_deg']:.3f} deg")
    if best != out_dir / BEST and best.exists():
        with atomic_path(out_dir / BEST) as tmp:
            shutil.copyfile(best, tmp)
    return TrainResult(epochs=state["epoch"], best_epoch=state["best_epoch"],
                       best_val_rmse_deg=state["best_val_rmse_deg"],
                       stopped_early=state["epoch"] < config.max_epochs, empty=False, precision=precision)


def _optimizer(config: TrainConfig, model: torch.nn.Module) -> torch.optim.Optimizer:
    if config.optimizer == "sgd":
        return torch.optim.SGD(model.parameters(), lr=config.lr, momentum=config.momentum,
                               weight_decay=config.weight_decay)
    return torch.optim.Adam(model.parameters(), lr=config.lr, weight_decay=config.weight_decay)


def _fingerprint(config: TrainConfig, network: NetworkConfig, data: ClusterData) -> str:
    """What must not change for a checkpoint to be resumed: settings, architecture, the samples, the clouds and
    features they are drawn from, and the code. A step rerun after its inputs or code changed (Snakemake and DVC
    rerun it then) starts over instead of finishing the other run's training."""
    train = {k: v for k, v in asdict(config).items() if k not in RESUMABLE_CHANGES}
    inputs = [a for cloud in data.clouds for a in (cloud.points, cloud.normals, cloud.clusters, cloud.features.nf,
                                                    cloud.features.frames, cloud.features.heights)]
    samples = {"cluster": data.cluster, "patch": asdict(data.patch), "clouds": len(data.clouds),
               "train": _digest(data.train.cloud, data.train.point), "val": _digest(data.val.cloud, data.val.point),
               "inputs": _digest(*inputs)}
    return json.dumps({"train": train, "network": json.loads(network_fingerprint(network)), "samples": samples,
                       "code": _code_digest()}, sort_keys=True)


def _digest(*arrays: np.ndarray) -> str:
    """A short hash of arrays' dtypes, shapes and contents."""
    h = hashlib.sha256()
    for a in arrays:
        a = np.ascontiguousarray(a)
        h.update(f"{a.dtype}{a.shape}".encode())
        h.update(a.data)
    return h.hexdigest()[:16]


def _code_digest() -> str:
    """A short hash of the package's source and of the torch and numpy versions, whose kernels the weights depend
    on: which module a change touches is not worth the risk of guessing."""
    package = Path(__file__).resolve().parents[1]
    h = hashlib.sha256(f"torch {torch.__version__} numpy {np.__version__}".encode())
    for path in sorted(package.rglob("*.py")):
        h.update(path.relative_to(package).as_posix().encode())
        h.update(path.read_bytes())
    return h.hexdigest()[:16]


def _autocast(device: torch.device, precision: str) -> torch.autocast:
    """The forward passes in `precision` (bfloat16: autocast, which keeps weights, gradients and the optimiser
    state in float32 and runs the matrix products and convolutions in bfloat16)."""
    return torch.autocast(device.type, dtype=torch.bfloat16, enabled=precision == "bfloat16")


def _train_epoch(model: RefineNet, optimizer: torch.optim.Optimizer, loss_fn: Any, batches: tqdm,
                 rates: Sequence[float], device: torch.device, precision: str) -> float:
    """One pass over the training batches (a tqdm-wrapped `ClusterData.batches`), step i at learning rate
    rates[i]; the mean loss per sample."""
    model.train()
    total, count = 0.0, 0
    for inputs, rate in zip(batches, rates, strict=True):
        for group in optimizer.param_groups:
            group["lr"] = rate
        target = torch.from_numpy(inputs.target).to(device)
        optimizer.zero_grad(set_to_none=True)
        with _autocast(device, precision):
            out = model(*inputs.tensors(device))
        loss = loss_fn(out.float(), target)
        loss.backward()
        optimizer.step()
        total += loss.item() * len(inputs)
        count += len(inputs)
        batches.set_postfix(loss=f"{total / count:.5f}")
    return total / count


def _validate(model: RefineNet, data: ClusterData, network: NetworkConfig, config: TrainConfig,
              device: torch.device, precision: str) -> np.ndarray:
    """Unoriented angles (degrees) between predictions and targets on the validation samples; the same ball
    subsets every epoch (the same seed), so epochs are compared on the same inputs."""
    model.eval()
    angles = []
    with torch.inference_mode(), _autocast(device, precision):
        for inputs in data.batches(data.val, config.batch_size, network, (config.seed,), shuffle=False,
                                   drop_last=False, workers=config.loader_workers):
            out = model(*inputs.tensors(device)).float().cpu().numpy()
            angles.append(unoriented_angles(out, inputs.target))
    return np.concatenate(angles)


def _write_history(path: Path, rows: list[dict[str, Any]]) -> None:
    import pandas as pd  # here, not at the top: `refinenet normals` imports this module and needs no pandas

    with atomic_path(path) as tmp:
        pd.DataFrame(rows, columns=list(HISTORY_COLUMNS)).to_csv(tmp, index=False)
