"""`refinenet.threads.native_threads`: the thread count a job was given, which scipy's k-d tree queries take as
`workers` instead of every core of the machine."""

import os
import subprocess
import sys

import pytest
import torch

from refinenet.threads import VARIABLES, limit_native_threads, native_threads


@pytest.fixture
def clean_env(monkeypatch):
    """No limit set; whatever a test sets is undone after it (setenv records the value to restore)."""
    for variable in VARIABLES:
        monkeypatch.setenv(variable, "")
        monkeypatch.delenv(variable)


def test_a_job_limit_is_the_count(clean_env):
    limit_native_threads(3)
    assert native_threads() == 3


def test_without_a_limit_every_core_this_process_may_use(clean_env):
    assert native_threads() == len(os.sched_getaffinity(0))


@pytest.mark.parametrize("value", ["0", "", "two"])
def test_an_unusable_limit_falls_back_to_the_cores(clean_env, monkeypatch, value):
    monkeypatch.setenv(VARIABLES[0], value)
    assert native_threads() == len(os.sched_getaffinity(0))


def test_a_float32_product_is_bitwise_the_same_on_one_thread_and_two(tmp_path):
    """The output module's product (K = 2112): MKL splits its sums by thread on AVX-512 CPUs unless a command has
    put it in strict reproducible mode, and a one-thread tile job then disagrees with a two-thread process."""
    script = ("import sys, torch; from refinenet.threads import thread_independent_products;"
              "thread_independent_products(); torch.set_num_threads(int(sys.argv[1]));"
              "g = torch.Generator().manual_seed(0);"
              "x, w = torch.randn(1024, 2112, generator=g), torch.randn(256, 2112, generator=g);"
              "torch.save(torch.nn.functional.linear(x, w), sys.argv[2])")
    for threads in (1, 2):
        env = {k: v for k, v in os.environ.items() if k != "MKL_CBWR"}
        subprocess.run([sys.executable, "-c", script, str(threads), str(tmp_path / f"{threads}.pt")], env=env,
                       check=True)
    assert torch.equal(torch.load(tmp_path / "1.pt"), torch.load(tmp_path / "2.pt"))
