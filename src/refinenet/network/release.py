"""The shipped networks: a run's per-cluster networks and cluster model in one file that the `refinenet normals`
command loads without training, with the settings it needs and a model card.

A release is self-contained: it carries the run's resolved params, so a user's cloud gets exactly the MFPS,
features and patches that the networks were trained on, wherever the command runs. Weights are stored in half
precision (the export measures what that changes); they are computed in float32 after loading.
"""

from __future__ import annotations

import json
from collections.abc import Mapping, Sequence
from dataclasses import dataclass
from pathlib import Path
from typing import Any

import numpy as np
import torch

from refinenet import SHIPPED
from refinenet.atomic import write_text, write_torch
from refinenet.config import InferenceConfig, Params, PatchConfig
from refinenet.errors import InputError, first_line
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.features.cache import Features
from refinenet.geometry.scale import spacing_ratio
from refinenet.network.clustering import ClusterModel, load_cluster_model
from refinenet.network.fused import for_inference
from refinenet.network.inference import load_networks, refine_normals
from refinenet.network.model import NetworkConfig, RefineNet, architecture, count_parameters
from refinenet.network.training import network_fingerprint

BUNDLE, CARD_JSON, CARD_MD = "networks.pt", "model_card.json", "MODEL_CARD.md"
#: Format of the bundle (its `format`): from 2, the params hold every setting of their version. A loader upgrades
#: an older format (`_upgrade`) and refuses a newer one rather than misreading it.
FORMAT = 3
#: The settings that a release of format 1 may lack, added to params.yaml after the first of them was exported, with
#: the value that each such release was trained (or, for `denoise` and `figures`, is used) with; `network.output`
#: is also that of its network description.
FORMAT_1 = {
    "features": {"initial": "mfps", "pca_k": None, "jet_k": None, "smooth_jet": None},
    "network": {"output": "normal"},
    "training": {"lr_schedule": "constant", "precision": "float32", "resample_points": False, "loader_workers": 0},
    "inference": {"precision": "float32", "points": None},
    "denoise": {"iterations": 20, "lam": 0.5, "sigma": 0.35, "radius": 0.01, "poisson_depth": 8},
    "figures": {"variants": [], "scans": None, "scan_points": None},
}
#: The settings that a release of format 2 lacks, with the value that each such release was trained with.
FORMAT_2 = {"data": {"train_meshes": None}}


@dataclass(frozen=True)
class Release:
    """What `load_release` gives: the run's settings, its cluster model and one float32 network per cluster."""

    params: Params
    cluster_model: ClusterModel
    networks: dict[int, RefineNet]
    card: dict[str, Any]

    @property
    def spacing_ratio(self) -> float:
        """Median point spacing / bounding-box diagonal of the training clouds (`geometry.scale`)."""
        return float(self.card["training_data"]["spacing_ratio"])

    @classmethod
    def of_run(cls, params: Params, cluster_model_path: str | Path, network_folders: Sequence[str | Path],
               training_clouds: Sequence[np.ndarray]) -> Release:
        """A run's trained networks (a variant's cluster model and per-cluster training folders) used as a release
        without exporting them, e.g. the X = 8 variant's for the scans; the card holds only the spacing ratio that
        `--scale spacing` needs."""
        cluster_model, _ = load_cluster_model(cluster_model_path)
        networks = load_networks(network_folders, architecture(params.network, params.features, params.patches),
                                 params.inference.device, precision=params.inference.precision)
        card = {"training_data": {"spacing_ratio": training_spacing(training_clouds)}}
        return cls(params, cluster_model, networks, card)


def training_spacing(clouds: Sequence[np.ndarray]) -> float:
    """The spacing ratio (`geometry.scale.spacing_ratio`) of the training clouds: the median over clouds."""
    return float(np.median([spacing_ratio(points) for points in clouds]))


def half(state: Mapping[str, torch.Tensor]) -> dict[str, torch.Tensor]:
    """A state dict with its floating tensors in float16, except those beyond float16's range (a BN's running
    variance can exceed 65,504 and would become inf) and integer buffers such as BN counters, which are kept."""
    return {k: v.half() if v.is_floating_point() and v.abs().max() <= torch.finfo(torch.float16).max else v
            for k, v in state.items()}


def export(folder: str | Path, resolved: dict[str, Any], cluster_model: ClusterModel,
           states: Mapping[int, Mapping[str, torch.Tensor]], network_json: str, card: dict[str, Any]) -> None:
    """Write the bundle and its model card (JSON and Markdown) into `folder`, each file atomically.

    `resolved` is the run's params as resolved from params.yaml; `states` the float32 weights per trained cluster;
    `card` what the export measured (training data, validation errors, the half-precision check).
    """
    folder = Path(folder)
    folder.mkdir(parents=True, exist_ok=True)
    bundle = {
        "format": FORMAT,
        "params": json.dumps(resolved, sort_keys=True),
        "network": network_json,
        "cluster_model": {name: torch.from_numpy(getattr(cluster_model, name))
                          for name in ("mean", "components", "centres")},
        "networks": {str(c): half(state) for c, state in states.items()},
    }
    write_torch(folder / BUNDLE, bundle)
    write_text(folder / CARD_JSON, json.dumps(card, indent=2, sort_keys=True) + "\n")
    write_text(folder / CARD_MD, model_card_markdown(card))


def load_release(folder: str | Path = SHIPPED, device: str | torch.device = "cpu", fuse: bool = True,
                 with_networks: bool = True, precision: str = "float32") -> Release:
    """The release in `folder` (default: the shipped one), networks in eval mode on `device` (none without
    `with_networks`: the settings alone serve the estimators that need no network). `precision` is that of the
    networks' feature modules (`model.reduced_precision`); the rest computes in float32."""
    folder = Path(folder)
    path = folder / BUNDLE
    if not path.is_file():
        raise InputError(path, "no trained networks here (run `snakemake -j2 release` to export a run's)")
    try:  # torch's unpickler can fail on damaged bytes with almost any exception
        bundle = torch.load(path, map_location="cpu", weights_only=True)
    except Exception as err:  # noqa: BLE001
        raise InputError(path, f"not a Refine-Net release ({type(err).__name__}: {first_line(err)})") from None
    try:
        card = json.loads((folder / CARD_JSON).read_text())
    except (OSError, ValueError) as err:
        raise InputError(folder / CARD_JSON, f"not a release's model card ({first_line(err)})") from None
    version = bundle.get("format") if isinstance(bundle, dict) else None
    if not isinstance(version, int) or version < 1:
        raise InputError(path, "not a Refine-Net release (it has no format)")
    if version > FORMAT:
        raise InputError(path, f"a release of format {version}, newer than this refinenet reads (1 to {FORMAT})")
    try:  # a file of the right format can still be damaged or foreign inside
        resolved, stored = _upgrade(json.loads(bundle["params"]), json.loads(bundle["network"]), version)
        params = Params.from_resolved(resolved, str(path))
        network = NetworkConfig(**{k: tuple(v) if isinstance(v, list) else v for k, v in stored.items()})
        if network_fingerprint(network) != json.dumps(stored, sort_keys=True):
            raise InputError(path, "the network description does not round-trip")
        cluster_model = ClusterModel(**{k: v.numpy() for k, v in bundle["cluster_model"].items()})
        networks = {}
        for c, state in bundle["networks"].items() if with_networks else ():
            net = RefineNet(network)
            net.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in state.items()})
            networks[int(c)] = for_inference(net.to(device), fuse, precision)
    except (KeyError, TypeError, AttributeError, ValueError, RuntimeError) as err:
        raise InputError(path, f"not a Refine-Net release ({type(err).__name__}: {first_line(err)})") from None
    return Release(params, cluster_model, networks, card)


def _upgrade(resolved: dict[str, Any], network: dict[str, Any], version: int) -> tuple[dict[str, Any], dict[str, Any]]:
    """A release's params and network description, stored in format `version`, as the present format holds them."""
    added = [FORMAT_1] * (version <= 1) + [FORMAT_2] * (version <= 2)
    for settings in added:
        resolved = resolved | {block: values | resolved.get(block, {}) for block, values in settings.items()}
    if version == 1:
        network = FORMAT_1["network"] | network
    return resolved, network


def half_precision_change(clouds: Sequence[tuple[np.ndarray, Features, np.ndarray]], cluster_model: ClusterModel,
                          networks: Mapping[int, RefineNet], patch: PatchConfig, config: InferenceConfig,
                          sample: int, seed: int) -> dict[str, float]:
    """What storing the weights in float16 changes, on `sample` random points of each (points, features, true
    normals) cloud: the angle between the outputs of `networks` and of their float16-rounded copies, and the
    mean error against the truth with either."""
    rounded = {}
    for c, net in networks.items():
        copy = RefineNet(net.config)
        copy.load_state_dict({k: v.float() if v.is_floating_point() else v for k, v in half(net.state_dict()).items()})
        rounded[c] = copy
    rng = np.random.default_rng(seed)
    change, error32, error16 = [], [], []
    for points, features, truth in clouds:
        subset = features.rows(np.sort(rng.choice(len(features), min(sample, len(features)), replace=False)))
        a, b = (refine_normals(points, subset, cluster_model, nets, patch, config) for nets in (networks, rounded))
        change.append(unoriented_angles(a, b))
        error32.append(unoriented_angles(a, truth[subset.points]))
        error16.append(unoriented_angles(b, truth[subset.points]))
    change = np.concatenate(change)
    return {"points": int(len(change)), "mean_deg": float(change.mean()), "max_deg": float(change.max()),
            "error_float32_deg": float(np.concatenate(error32).mean()),
            "error_float16_deg": float(np.concatenate(error16).mean())}


def parameter_counts(network: RefineNet, n_networks: int) -> dict[str, int]:
    """Parameters per cluster network and in total."""
    per = count_parameters(network)
    return {"per_cluster": per, "total": per * n_networks}


def model_card_markdown(card: dict[str, Any]) -> str:
    """The model card as Markdown, from the card's JSON fields."""
    data, check = card["training_data"], card["half_precision"]
    lines = [
        "# Model card: Refine-Net networks shipped with this package",
        "",
        f"Exported by the pipeline's `release` step from a run of profile **{card['profile']}** "
        f"(fingerprint of its params and training clouds `{card['fingerprint']}`). Retrain and re-export with "
        "`snakemake -j2 release` (or `dvc repro release`); `refinenet info` prints this card.",
        "",
        "## Networks",
        "",
        f"- Architecture: {card['network']['preset']} preset, features {card['network']['features']}, "
        f"connection {card['network']['connection']}, output {card['network']['output']}; "
        f"X = {card['n_normals']} normals, Kc = {card['n_clusters']} clusters, one network per cluster.",
        f"- Parameters: {card['parameters']['per_cluster']:,} per cluster network, "
        f"{card['parameters']['total']:,} in total; stored in float16, run in float32.",
        f"- Half precision: on {check['points']:,} test points, the float16 weights change the mean error from "
        f"{check['error_float32_deg']:.4f} to {check['error_float16_deg']:.4f} deg; each refined normal moves by "
        f"{check['mean_deg']:.3f} deg on average and {check['max_deg']:.2f} deg at most.",
        "",
        "## Training data",
        "",
        f"- Source: {data['source']}; {data['clouds']} training clouds of {data['points_per_cloud']:,} points, "
        f"Gaussian noise {', '.join(map(str, data['noise_percent']))}% of the bounding-box diagonal.",
        *([f"- Sampled from meshes ({len(data['meshes'])}): "
           + ", ".join(f"`{m}`" for m in data["meshes"]) + "."] if data.get("meshes") else []),
        "- Training: " + ", ".join(f"{k} {v}" for k, v in card["training"].items()
                                   if k not in ("device", "threads", "seed")) + ".",
        "",
        "## Validation error (held-out points of the training clouds, unoriented, degrees)",
        "",
        "| cluster | training points | validation points | best epoch | epochs | validation RMSE | of its input |",
        "|---|---|---|---|---|---|---|",
        *(f"| {c} | {r['train_points']:,} | {r['val_points']:,} | {r['best_epoch']} | {r['epochs']} | "
          f"{r['best_val_rmse_deg']:.2f} | {_degrees(r.get('input_val_rmse_deg'))} |"
          for c, r in sorted(card["clusters"].items(), key=lambda i: int(i[0]))),
        "",
        "*Of its input*: the RMSE of the initial normals the network refines, on the same points (blank in cards",
        "exported before it was recorded).",
        "",
        "## Scale",
        "",
        "The paper's radii (filter ball r_f, ball patches, height-map extent) are fractions of l_d, the bounding-box",
        "diagonal. On a user's cloud `refinenet normals` derives l_d from the point spacing instead (`--scale "
        "spacing`, the default): l_d = median distance to the 16th neighbour / "
        f"{data['spacing_ratio']:.5f}, the ratio of the training clouds, so a radius holds as many points as in",
        "training whatever the cloud's size or units. `--scale diagonal` uses the paper's definition.",
        "",
    ]
    return "\n".join(lines)


def _degrees(value: float | None) -> str:
    return "" if value is None else f"{value:.2f}"
