"""GPU placement: concurrent jobs on a machine with several GPUs each hold a different one (lock files; no GPU
needed to test the claiming), and the device names resolve as the params say."""

import fcntl
import os
import subprocess
import sys

import pytest
import torch

from refinenet.network.devices import claim_gpu, resolve_device, resolve_precision

CLAIM = "import sys; from refinenet.network.devices import claim_gpu; print(claim_gpu(3, sys.argv[1], wait=False))"


def other_job(folder) -> str:
    """What a separate process (another job) is given."""
    return subprocess.run([sys.executable, "-c", CLAIM, str(folder)], capture_output=True, text=True,
                          check=True).stdout.strip()


def test_concurrent_jobs_get_different_gpus_and_a_finished_job_frees_its_own(tmp_path):
    assert claim_gpu(3, tmp_path, wait=False) == 0
    assert claim_gpu(3, tmp_path, wait=False) == 0  # the same process keeps its GPU
    held = os.open(tmp_path / "gpu1.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(held, fcntl.LOCK_EX)  # a second job holds GPU 1
    assert other_job(tmp_path) == "2"  # a third job: the next free one (its lock ends with its process)
    third = os.open(tmp_path / "gpu2.lock", os.O_RDWR | os.O_CREAT)
    fcntl.flock(third, fcntl.LOCK_EX)
    assert other_job(tmp_path) == "None"  # every GPU held: nothing to claim without waiting
    os.close(held)  # the second job ends
    assert other_job(tmp_path) == "1"
    os.close(third)


def test_device_names_resolve():
    assert resolve_device("cpu") == torch.device("cpu")
    if not torch.cuda.is_available():
        assert resolve_device("auto") == torch.device("cpu")
        with pytest.raises(ValueError, match="torch sees no CUDA device"):
            resolve_device("cuda")


def test_precision_names_resolve():
    assert resolve_precision("float32", torch.device("cpu")) == "float32"
    assert resolve_precision("bfloat16", torch.device("cpu")) == "bfloat16"
    assert resolve_precision("auto", torch.device("cuda")) == "float32"
    assert resolve_precision("auto", torch.device("cpu")) in ("float32", "bfloat16")
