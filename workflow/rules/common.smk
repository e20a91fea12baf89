# Shared set-up: the typed params, the run's clouds, wildcard constraints, and the DVC record hook.

import os
import sys

from refinenet import config as params_lib
from refinenet.errors import RefineNetError
from refinenet.pipeline import workflow as wf

try:
    P = params_lib.Params.from_resolved(params_lib.resolve(config))
    CLOUDS = wf.clouds(P)
except RefineNetError as err:
    sys.exit(f"error: {err}")

TEST_CLOUDS = [wf.CLOUD.format(cloud=c.key) for c in CLOUDS if c.split == "test"]
TRAIN_KEYS = [c.key for c in CLOUDS if c.split == "train"]
CLUSTERS = range(P.clustering.n_clusters)


wildcard_constraints:
    cloud=r"(train|test)/[A-Za-z0-9_.+-]+/[A-Za-z0-9_.+-]+",
    cluster=r"\d+",


def tracked(step):
    """Rule params holding every params key the DVC stage lists, so both tools rerun on the same changes."""
    return wf.tracked_params(config, wf.STEPS[step])


def record_in_dvc():
    """After a plain Snakemake run, record finished steps in dvc.lock so `dvc repro` has nothing to redo.
    Skipped when DVC itself runs Snakemake (the bridge sets REFINENET_BRIDGE)."""
    if not os.environ.get("REFINENET_BRIDGE"):
        shell("python -m refinenet.pipeline.bridge record")
