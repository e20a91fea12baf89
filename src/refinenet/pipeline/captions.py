"""What a table says about itself: its row names and a caption naming the profile, the data, every method's settings
and what each Refine-Net variant changes, so that a table read on its own says what made it."""

from __future__ import annotations

from dataclasses import asdict
from typing import TYPE_CHECKING, Any

from refinenet import config
from refinenet.config import Params, ScannerConfig
from refinenet.evaluation.table import METHOD_NAMES
from refinenet.pipeline.catalogue import Table
from refinenet.pipeline.methods import BASELINES, FULL, MFPS_METHODS, REFERENCE
from refinenet.pipeline.variants import leaves

if TYPE_CHECKING:
    from refinenet.pipeline.workflow import Pipeline

#: The params keys `data_line` names, which every step whose output carries it tracks.
DATA_KEYS = ("data.source", "data.path", "data.n_points")
#: How a table caption names a Refine-Net output beyond the paper's (NetworkConfig.output).
OUTPUT_CAPTIONS = {"correction": "output a correction of the initial normal, ",
                   "blend": "output a correction of a learned weighted mean of the input normals, "}


def data_line(params: Params) -> str:
    """The profile and the data of a run, as table captions and figure footers name them."""
    d = params.data
    return (f"Profile {params.profile}; data: {d.source}" + (f" ({d.path})" if d.path else "")
            + f", {d.n_points} points per cloud.")


def scanner_line(scanner: ScannerConfig) -> str:
    """The simulated scans' sensor and shapes, as the scan table's caption and figure footer name them."""
    s = scanner
    return (f"Sensor {s.range_m} m from an object of radius {s.object_radius_m} m, pixel {s.pixel_rad:g} rad, "
            f"range noise {s.sigma_m:g} r^2 m, disparity step {s.disparity_step:g} 1/m, {s.views} views at "
            f"{s.elevation_deg:g} deg elevation; shapes {', '.join(s.shapes)}.")


def _settings(values: dict[str, Any]) -> str:
    """Dotted keys and their values as a caption lists them, None as params.yaml writes it."""
    return ", ".join(f"{k} = {'null' if v is None else v}" for k, v in values.items())


def rows(pipe: Pipeline, table: Table) -> dict[str, str]:
    """The table's rows, method -> row name. A sweep table's rows are named and ordered by the swept value,
    the first row of equal values kept (in the smoke profile kc2 repeats full's Kc = 2)."""
    if not table.sweep:
        return {m: dict(table.labels).get(m, METHOD_NAMES.get(m, m)) for m in table.methods}
    key, symbol = table.sweep
    first = {pipe.swept(m, key): m for m in reversed(table.methods)}
    return {first[value]: f"{symbol} = {value}" for value in sorted(first)}


def changes(pipe: Pipeline, variant: str) -> dict[str, Any]:
    """The settings in which a variant differs from reference (full under the variant budget, which every
    variant takes), by dotted key; reference's: those in which it differs from full (the budget)."""
    base = pipe.full if variant == REFERENCE else pipe.params[REFERENCE]
    own, other = leaves(asdict(base)), leaves(asdict(pipe.params[variant]))
    return {k: other[k] for k in other if other[k] != own.get(k)}


def caption(pipe: Pipeline, table: Table) -> str:
    """A table caption naming the profile, the data, the settings of every method in the table and what each
    variant changes."""
    params, methods = pipe.full, table.methods
    b, m = params.baselines, params.mfps
    parts = [f"{table.title}, {pipe.protocol(table)} protocol.", data_line(params)]
    if set(BASELINES) & set(methods):
        parts.append(f"PCA/Jet K = {b.pca_k}/{b.jet_k} ({b.big_noise_k} for BigNoise), jet degree {b.jet_degree}.")
    if set(MFPS_METHODS) & set(methods):
        parts.append(f"MFPS K = {{{', '.join(map(str, m.scales))}}}, R = {m.trials}, "
                     f"theta_t = {m.theta_t} deg, |A| <= {m.a_max}, eta = {m.eta}.")
    # Every variant is reference (full under the variant budget) with its changes, so a table of variants
    # names reference's settings, whether or not reference is one of its rows (table_loss's are l1 and l2).
    compared = set(table.variants) - {FULL}
    if table.variants:
        parts.append(_refinenet_settings(pipe.params[REFERENCE if compared else FULL]))
    who = "Every variant" + (", and Refine-Net as the reference row," if REFERENCE in compared else "")
    budget = budget_line(pipe, who, "the main tables' Refine-Net") if compared else ""
    parts += [budget] if budget else []
    points = pipe.scored_subset(table.methods)
    if points is not None:
        parts.append(f"Every row scored on the same seeded {points} points of each test cloud.")
    changed = [f"{v}: " + (_settings(changes(pipe, v)) or "nothing (the settings above)")
               for v in table.variants if v not in (FULL, REFERENCE)]
    if changed:
        parts.append("Variants of Refine-Net (what each changes): " + "; ".join(changed) + ".")
    return " ".join(parts)


def budget_line(pipe: Pipeline, who: str, full: str) -> str:
    """The sentence saying that `who` trains and infers under the variant budget, beside `full`'s values (which
    full has); empty where there is no budget."""
    budget = changes(pipe, REFERENCE)
    if not budget:
        return ""
    main = asdict(pipe.full)
    return (f"{who} under the variant budget: {_settings(budget)} ({full}: "
            f"{_settings({k: config.get(main, k) for k in budget})}).")


def _refinenet_settings(reference: Params) -> str:
    """The caption's sentence of the Refine-Net settings every variant starts from."""
    f, n, t, pa = reference.features, reference.network, reference.training, reference.patches
    wide = " and ".join(f"a {METHOD_NAMES[m]} K = {k} normal" for m, k in f.wide_normals)
    last = "the last" if len(f.wide_normals) == 1 else f"the last {len(f.wide_normals)}"
    return (
        f"Refine-Net: {n.preset} network, features {n.features}, connection {n.connection}, "
        + OUTPUT_CAPTIONS.get(n.output, "") +
        f"Kc = {reference.clustering.n_clusters}, X = {f.n_normals}"
        + (f" ({last}: {wide})" if wide else "")
        + (f", a K = 100 Jet normal where its residual is < {f.smooth_jet} x the noise" if f.smooth_jet else "")
        + f", r_f = {f.r_f}, {f.frame_mode} frames, {pa.mode} patches; {t.optimizer} lr {t.lr}"
        + (" (cosine decay)" if t.lr_schedule == "cosine" else "") + ", "
        f"batch {t.batch_size}, <= {t.max_epochs} epochs (patience {t.patience}), {t.loss} loss"
        + (f", at most {t.max_train_points_per_cloud} training points per cloud"
           + (" (drawn anew every epoch)" if t.resample_points else "")
           if t.max_train_points_per_cloud else "") + ".")
