"""`refinenet.threads.native_threads`: the thread count a job was given, which scipy's k-d tree queries take as
`workers` instead of every core of the machine."""

import os

import pytest

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
