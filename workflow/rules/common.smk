# Shared set-up: the pipeline of params.yaml (typed params of every Refine-Net variant, the steps, the clouds),
# wildcard constraints, and the DVC record hook.

import os
import shutil
import sys

from refinenet.errors import RefineNetError
from refinenet.pipeline import catalogue, layout
from refinenet.pipeline.methods import BASELINES, FULL, MFPS_METHODS, REFINENET
from refinenet.pipeline.page import reported_files
from refinenet.pipeline.steps import gpus, tracked_params
from refinenet.pipeline.workflow import Pipeline, check_keys

try:
    PIPE = Pipeline(config)
    P = PIPE.full
    CLOUDS = PIPE.clouds
except RefineNetError as err:
    sys.exit(f"error: {err}")

TEST_CLOUDS = [layout.CLOUD.format(cloud=key) for key in PIPE.keys("test")]
TRAIN_KEYS = PIPE.keys("train")


wildcard_constraints:
    cloud=r"(train|test)/[A-Za-z0-9_.+-]+/[A-Za-z0-9_.+-]+",
    cluster=r"\d+",


def tracked(step):
    """Rule params holding every params key the DVC stage lists, so both tools rerun on the same changes."""
    return tracked_params(config, PIPE.steps[step])


def files(variant, family, pattern, **values):
    """A per-variant step's file pattern for the variant that owns the step's files (itself or full)."""
    return layout.fill(pattern, variant=PIPE.owner(variant, family), **values)


def networks(variant):
    """The network folder of every cluster of `variant`, from the variant that trains them."""
    return [
        files(variant, "training", layout.NETWORK, cluster=c)
        for c in range(PIPE.params[variant].clustering.n_clusters)
    ]


def record_in_dvc():
    """After a plain Snakemake run, record finished steps in dvc.lock so `dvc repro` has nothing to redo.
    Skipped when DVC itself runs Snakemake (the bridge sets REFINENET_BRIDGE)."""
    if not os.environ.get("REFINENET_BRIDGE"):
        shell("python -m refinenet.pipeline.bridge record")


def split_priority(split):
    """Priority of a job of one split: a training cloud's (and the clustering's) before a test cloud's. Training, the
    longest step, waits for every training cloud's features and the clusters; the test clouds' jobs can fill the core
    it leaves idle while its last network trains. Run the other way round, they delay its start instead
    (benchmarks/results/pipeline.md)."""
    return int(split == "train")


def main_page():
    """Whether the run builds the main job's page: `main` is among its targets (`all` is not). That page shows
    what the main job made beside the committed results of the rest; any other run's (the default target, `dvc
    repro`, `reports/index.html` asked for alone) shows every table and figure, made by the run. Evaluated while the
    DAG is built, when the run's targets are known."""
    targets = set(getattr(workflow.dag_settings, "targets", ()))
    return "main" in targets and "all" not in targets


def installed(step):
    """Whether the program a step needs (if any) is installed; the default target skips the step, saying so, if not."""
    if step.needs and shutil.which(step.needs) is None:
        print(f"skipping {step.name}: {step.needs} is not installed", file=sys.stderr)
        return False
    return True
