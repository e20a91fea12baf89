"""Training one cluster (docs/algorithm.md §9): learning, bit-identical resumption after a kill, history, early
stopping, empty clusters and the settings check on resumption."""

from __future__ import annotations

import json
import shutil
from dataclasses import replace

import numpy as np
import pandas as pd
import pytest
import torch
from settings import patch_config, train_config
from test_dataset import cube_cloud

import refinenet.network.training as training
from refinenet.network.model import preset
from refinenet.network.training import (
    BEST,
    CHECKPOINT,
    EMPTY,
    HISTORY,
    HISTORY_COLUMNS,
    RESULT,
    cluster_data,
    input_angles,
    learning_rate,
    train_cluster,
)

NORMALS_ONLY = preset("release", features="normals")


@pytest.fixture(scope="module")
def clouds():
    return [cube_cloud(800, seed=2, n_clusters=1), cube_cloud(600, seed=3, n_clusters=1)]


def test_loss_decreases_on_a_learnable_problem(tmp_path, clouds):
    """The target is the first local normal up to noise-free sign: a small network learns it within 3 epochs."""
    config = train_config(optimizer="adam", lr=1e-3, batch_size=64, max_epochs=3, seed=1, threads=1)
    result = train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()), tmp_path, False)
    history = pd.read_csv(tmp_path / HISTORY)
    assert list(history.columns) == list(HISTORY_COLUMNS)
    assert history["epoch"].tolist() == [1, 2, 3]
    assert history["train_loss"].iloc[-1] < 0.5 * history["train_loss"].iloc[0]
    assert np.isfinite(history.to_numpy()).all() and (history["val_rmse_deg"] >= history["val_mean_deg"]).all()
    assert result.epochs == 3 and not result.stopped_early and not result.empty
    assert result.best_val_rmse_deg == history["val_rmse_deg"].min()
    assert torch.load(tmp_path / BEST, weights_only=True)["epoch"] == result.best_epoch


@pytest.mark.parametrize("schedule, precision, resample", [("constant", "float32", False),
                                                           ("cosine", "float32", False),
                                                           ("cosine", "bfloat16", False),
                                                           ("constant", "float32", True)])
def test_resume_after_a_kill_is_bit_identical(tmp_path, clouds, monkeypatch, schedule, precision, resample):
    """The full network (dropout, BN, patches, heights) for 3 epochs, against 2 epochs, a kill inside epoch 3 (after
    its optimiser steps), and a resumption; the cosine schedule and the points drawn anew every epoch need no
    state of their own."""
    config = train_config(batch_size=16, max_epochs=3, seed=4, max_train_points_per_cloud=48, threads=1,
                          lr_schedule=schedule, precision=precision, resample_points=resample)
    full = preset("release")
    data = cluster_data(clouds[1:], 0, config, patch_config())
    train_cluster(config, full, data, tmp_path / "straight", progress=False)

    validate, calls = training._validate, []

    def killed_in_epoch_3(*args, **kwargs):
        calls.append(1)
        if len(calls) == 3:
            raise KeyboardInterrupt
        return validate(*args, **kwargs)

    monkeypatch.setattr(training, "_validate", killed_in_epoch_3)
    with pytest.raises(KeyboardInterrupt):
        train_cluster(config, full, data, tmp_path / "resumed", progress=False)
    assert len(pd.read_csv(tmp_path / "resumed" / HISTORY)) == 2
    monkeypatch.setattr(training, "_validate", validate)
    result = train_cluster(config, full, data, tmp_path / "resumed", progress=False)
    assert result.epochs == 3 and result.precision == precision

    straight = torch.load(tmp_path / "straight" / CHECKPOINT, weights_only=True)
    resumed = torch.load(tmp_path / "resumed" / CHECKPOINT, weights_only=True)
    assert straight["model"].keys() == resumed["model"].keys()
    for key, value in straight["model"].items():
        assert torch.equal(value, resumed["model"][key]), key
    for key, value in straight["optimizer"]["state"].items():
        assert torch.equal(value["momentum_buffer"], resumed["optimizer"]["state"][key]["momentum_buffer"])
    drop_seconds = [{k: v for k, v in row.items() if k != "seconds"} for row in straight["history"]]
    assert drop_seconds == [{k: v for k, v in row.items() if k != "seconds"} for row in resumed["history"]]
    assert pd.read_csv(tmp_path / "resumed" / HISTORY)["epoch"].tolist() == [1, 2, 3]


def test_bfloat16_passes_learn_as_float32_does(tmp_path, clouds):
    """The learnable problem of the test above with the passes in bfloat16 (autocast): the weights stay float32,
    the result records the precision, and the validation error ends close to float32's."""
    ends = {}
    for precision in ("float32", "bfloat16"):
        config = train_config(optimizer="adam", lr=1e-3, batch_size=64, max_epochs=3, seed=1, threads=1,
                              precision=precision)
        result = train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()),
                               tmp_path / precision, False)
        assert result.precision == precision
        assert json.loads((tmp_path / precision / RESULT).read_text())["precision"] == precision
        weights = torch.load(tmp_path / precision / BEST, weights_only=True)["model"]
        assert all(v.dtype == torch.float32 for v in weights.values() if v.is_floating_point())
        ends[precision] = pd.read_csv(tmp_path / precision / HISTORY)["val_mean_deg"].iloc[-1]
    assert ends["bfloat16"] == pytest.approx(ends["float32"], rel=0.2)


def test_cosine_schedule_decays_from_lr_to_zero_at_max_epochs():
    config = train_config(lr=0.01, max_epochs=4, lr_schedule="cosine")
    rates = [learning_rate(config, epoch, step, 10) for epoch in range(1, 5) for step in range(10)]
    assert rates[0] == 0.01 and rates[20] == pytest.approx(0.005) and 0 < rates[-1] < 1e-4
    assert all(a > b for a, b in zip(rates, rates[1:], strict=False))
    assert learning_rate(train_config(lr=0.01, lr_schedule="constant"), 3, 7, 10) == 0.01


def test_result_reports_the_input_normals_error(tmp_path, clouds):
    """Ground truth made the first normal of nf turned by exactly 10 degrees: the error the network starts from."""
    cloud = cube_cloud(600, seed=3, n_clusters=1)
    first = cloud.features.nf[:, :3].astype(np.float64)
    first /= np.linalg.norm(first, axis=1, keepdims=True)
    side = np.cross(first, np.where(np.abs(first[:, :1]) < 0.9, [[1.0, 0, 0]], [[0, 1.0, 0]]))
    side /= np.linalg.norm(side, axis=1, keepdims=True)
    cloud.normals = (np.cos(np.radians(10)) * first + np.sin(np.radians(10)) * side).astype(np.float32)
    config = train_config(batch_size=128, max_epochs=1, threads=1)
    data = cluster_data([cloud], 0, config, patch_config())
    np.testing.assert_allclose(input_angles(data), 10.0, atol=1e-3)
    train_cluster(config, NORMALS_ONLY, data, tmp_path, False)
    result = json.loads((tmp_path / RESULT).read_text())
    assert result["input_val_mean_deg"] == pytest.approx(10.0, abs=1e-3)
    assert result["input_val_rmse_deg"] == pytest.approx(10.0, abs=1e-3)


def test_loader_workers_train_the_same_network(tmp_path, clouds):
    """Ball patches (random subsets per batch) built by two worker processes train bit-identical weights, and a
    checkpoint resumes under another worker count."""
    ball = patch_config(mode="ball", radius=0.1, max_points=32)
    weights = {}
    for workers in (0, 2):
        config = train_config(batch_size=32, max_epochs=2, seed=5, max_train_points_per_cloud=96, threads=1,
                              loader_workers=workers)
        data = cluster_data(clouds, 0, config, ball)
        train_cluster(config, preset("release"), data, tmp_path / str(workers), progress=False)
        weights[workers] = torch.load(tmp_path / str(workers) / CHECKPOINT, weights_only=True)["model"]
    for key, value in weights[0].items():
        assert torch.equal(value, weights[2][key]), key
    more = train_config(batch_size=32, max_epochs=3, seed=5, max_train_points_per_cloud=96, threads=1)
    assert train_cluster(more, preset("release"), cluster_data(clouds, 0, more, ball), tmp_path / "2",
                         progress=False).epochs == 3


def test_early_stopping(tmp_path, clouds, monkeypatch):
    monkeypatch.setattr(training, "_validate", lambda *args, **kwargs: np.full(10, 3.0))
    config = train_config(batch_size=128, max_epochs=50, patience=2, threads=1)
    result = train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()), tmp_path, False)
    assert (result.epochs, result.best_epoch, result.stopped_early) == (3, 1, True)
    # A finished run resumes to the same result without training.
    assert train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()), tmp_path, False) \
        == result


def test_resumption_after_the_output_folder_was_cleared_keeps_the_best_weights(tmp_path, clouds, monkeypatch):
    """Snakemake clears a killed job's output folder before rerunning it: a resumption whose later epochs never
    beat the best one (here epoch 1) must still end with that epoch's weights in the folder."""
    monkeypatch.setattr(training, "_validate", lambda *args, **kwargs: np.full(10, 3.0))
    config = train_config(batch_size=128, max_epochs=50, patience=2, threads=1)
    data = cluster_data(clouds, 0, config, patch_config())
    out, checkpoints = tmp_path / "network", tmp_path / "checkpoints"
    first = train_cluster(config, NORMALS_ONLY, data, out, False, checkpoint_dir=checkpoints)
    weights = (out / BEST).read_bytes()
    shutil.rmtree(out)
    assert train_cluster(config, NORMALS_ONLY, data, out, False, checkpoint_dir=checkpoints) == first
    assert first.best_epoch == 1 and (out / BEST).read_bytes() == weights


def test_empty_cluster_writes_a_marker(tmp_path, clouds):
    config = train_config()
    result = train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 3, config, patch_config()), tmp_path, False)
    assert result.empty and result.epochs == 0
    assert json.loads((tmp_path / EMPTY).read_text()) == {"cluster": 3, "train_points": 0, "val_points": 0}
    assert not (tmp_path / BEST).exists()


def test_other_settings_start_over(tmp_path, clouds):
    """A checkpoint of other settings is not resumed: training restarts from epoch 1, as a fresh run would."""
    config = train_config(batch_size=128, max_epochs=1, threads=1)
    train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()), tmp_path, False,
                  checkpoint_dir=tmp_path / "ckpt")
    assert (tmp_path / "ckpt" / "checkpoint.pt").exists() and not (tmp_path / "checkpoint.pt").exists()
    changed = train_config(batch_size=128, max_epochs=2, lr=1e-3, threads=1)
    resumed = train_cluster(changed, NORMALS_ONLY, cluster_data(clouds, 0, changed, patch_config()),
                            tmp_path, False, checkpoint_dir=tmp_path / "ckpt")
    fresh = train_cluster(changed, NORMALS_ONLY, cluster_data(clouds, 0, changed, patch_config()),
                          tmp_path / "fresh", False)
    assert resumed.epochs == fresh.epochs == 2
    assert resumed.best_val_rmse_deg == fresh.best_val_rmse_deg


@pytest.mark.parametrize("change", ["features", "code", "torch"])
def test_a_checkpoint_of_other_inputs_or_code_starts_over(tmp_path, clouds, monkeypatch, change):
    """A step rerun because its features, its code or torch changed trains anew instead of finishing the checkpoint's
    run; the same inputs and code resume it."""
    config = train_config(batch_size=128, max_epochs=1, threads=1)
    more = replace(config, max_epochs=2)  # a resumable change: a resumed run trains one epoch, a new one two
    train_cluster(config, NORMALS_ONLY, cluster_data(clouds, 0, config, patch_config()), tmp_path / "first", False,
                  checkpoint_dir=tmp_path / "ckpt")
    shutil.copytree(tmp_path / "ckpt", tmp_path / "same")
    epochs, train_epoch = [], training._train_epoch
    monkeypatch.setattr(training, "_train_epoch", lambda *args: epochs.append(1) or train_epoch(*args))
    train_cluster(more, NORMALS_ONLY, cluster_data(clouds, 0, more, patch_config()), tmp_path / "same_out", False,
                  checkpoint_dir=tmp_path / "same")
    assert len(epochs) == 1
    rerun = clouds
    if change == "code":
        monkeypatch.setattr(training, "_code_digest", lambda: "other code")
    elif change == "torch":
        monkeypatch.setattr(torch, "__version__", "0.0.0")
    else:
        rerun = [replace(c, features=replace(c.features, nf=c.features.nf * np.float32(1.001))) for c in clouds]
    epochs.clear()
    train_cluster(more, NORMALS_ONLY, cluster_data(rerun, 0, more, patch_config()), tmp_path / "rerun", False,
                  checkpoint_dir=tmp_path / "ckpt")
    assert len(epochs) == 2
