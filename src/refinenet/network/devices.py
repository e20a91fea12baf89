"""The device a training or inference job runs on, and the precision inference computes in there.

`auto` is cuda when torch sees a GPU, else cpu. On a machine with several GPUs, concurrent jobs must not all land
on the first one: each job claims a GPU that no other job of this machine holds (an exclusive lock on a file per
GPU, released when the process ends, even when killed). A SLURM job sees only the GPU it was given (SLURM sets
`CUDA_VISIBLE_DEVICES`), so there the claim is trivially that one. Snakemake's `--resources gpu=N` keeps at most N
GPU jobs running; a job that finds every GPU held waits for one.
"""

from __future__ import annotations

import fcntl
import os
import tempfile
import time
from pathlib import Path

import torch
from tqdm import tqdm

#: Where the per-GPU lock files live (one folder per user); REFINENET_GPU_LOCKS overrides it.
LOCKS_ENV = "REFINENET_GPU_LOCKS"
_held: dict[Path, int] = {}
"""The GPU this process holds, per lock folder; the open lock files stay open until the process ends."""
_files: list[int] = []


def resolve_device(device: str) -> torch.device:
    """auto -> cuda when available, else cpu; an explicit cuda without a GPU is an error; with several GPUs, the
    one this process claimed."""
    if device == "auto":
        device = "cuda" if torch.cuda.is_available() else "cpu"
    if device == "cuda" and not torch.cuda.is_available():
        raise ValueError("device 'cuda' was requested but torch sees no CUDA device")
    if device == "cuda" and torch.cuda.device_count() > 1:
        return torch.device("cuda", claim_gpu(torch.cuda.device_count()))
    return torch.device(device)


def resolve_precision(precision: str, device: torch.device) -> str:
    """auto -> bfloat16 on a CPU that computes it natively (oneDNN's check: AVX512-BF16 or AMX), else float32: on
    other CPUs bfloat16 is emulated and slower, and a GPU is fast enough in float32 (`model.reduced_precision`)."""
    if precision != "auto":
        return precision
    native = device.type == "cpu" and torch.backends.mkldnn.is_available() \
        and torch.ops.mkldnn._is_mkldnn_bf16_supported()
    return "bfloat16" if native else "float32"


def lock_folder() -> Path:
    return Path(os.environ.get(LOCKS_ENV) or Path(tempfile.gettempdir()) / f"refinenet-gpus-{os.getuid()}")


def claim_gpu(count: int, folder: Path | None = None, wait: bool = True) -> int | None:
    """The index (0..count-1) of a GPU that no other process holds, now held by this one until it ends. When all
    are held: wait for one (`wait`), or return None."""
    folder = Path(folder or lock_folder())
    if folder in _held:
        return _held[folder]
    folder.mkdir(parents=True, exist_ok=True)
    told = False
    while True:
        for gpu in range(count):
            fd = os.open(folder / f"gpu{gpu}.lock", os.O_RDWR | os.O_CREAT, 0o644)
            try:
                fcntl.flock(fd, fcntl.LOCK_EX | fcntl.LOCK_NB)
            except BlockingIOError:
                os.close(fd)
                continue
            _files.append(fd)
            _held[folder] = gpu
            return gpu
        if not wait:
            return None
        if not told:
            tqdm.write(f"all {count} GPUs are held by other jobs (locks in {folder}); waiting for one")
            told = True
        time.sleep(1.0)
