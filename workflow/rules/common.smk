# Shared set-up: resolved params, the run's clouds, wildcard constraints, and the DVC record hook.

import json
import os
import sys

from refinenet import config as params_lib
from refinenet import workflow as wf
from refinenet.errors import RefineNetError
from refinenet.noise import derive_seed
from refinenet.tables import caption

try:
    P = params_lib.resolve(config)
    CLOUDS = {c.key: c for c in wf.clouds(P)}
except RefineNetError as err:
    sys.exit(f"error: {err}")


wildcard_constraints:
    split="train|test",
    category="[A-Za-z0-9_.+-]+",
    name="[A-Za-z0-9_.+-]+",


def cloud_spec(w):
    return CLOUDS[f"{w.split}/{w.category}/{w.name}"]


def tracked(stage):
    """Rule params holding every params key the DVC stage lists, so both tools rerun on the same changes."""
    return wf.tracked_params(config, wf.STEPS[stage])


def record_in_dvc():
    """After a plain Snakemake run, record finished steps in dvc.lock so `dvc repro` has nothing to redo.
    Skipped when DVC itself runs Snakemake (the bridge sets REFINENET_BRIDGE)."""
    if not os.environ.get("REFINENET_BRIDGE"):
        shell("python -m refinenet.bridge record")


def baseline_k(w):
    b = P["baselines"]
    if w.category == "BigNoise":
        return b["big_noise_k"]
    return b["pca_k"] if w.method == "pca" else b["jet_k"]


TEST_SPECS = [c for c in CLOUDS.values() if c.split == "test"]
TRAIN_SPECS = [c for c in CLOUDS.values() if c.split == "train"]
TEST_CLOUDS = [wf.cloud_path(c) for c in TEST_SPECS]
