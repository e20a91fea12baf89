"""The smooth-point jet (`features.smooth_jet`): which ratio, chosen on the training clouds, and what Refine-Net
trained on it gives.

Answers the SmoothSurface requirement: Refine-Net refines MFPS, which keeps PCA with K = 50 away from features and
fits patches wherever its feature test fires, also on curved smooth surfaces; Jet (K = 100) is better on both.
`features.smooth_jet = c` puts the K = 100 jet's normal wherever that jet's RMS residual is below c times the
cloud's noise (the median residual of K = 20 jets), before features are computed (`estimators.smooth_jet`).

1. The input alone, without training: the mean error of MFPS, Jet K = 100 and the smooth-jet input for several
   ratios, per category, on the training clouds (where the ratio is chosen: the lowest Average) and on the test
   clouds, from the clouds and MFPS normals of a finished pipeline run (`--run`, default this checkout).
2. Retrained: the synthetic tables (mean, PGP) of a run whose profile sets smooth_jet (`--run`) beside the
   committed ones (`reports/`, or `--before`), with the share of points the jet took per category and Refine-Net's
   error on them against the input's, SmoothSurface per cloud, and the run's training curves per cluster.

    python benchmarks/smooth_jet.py [--run DIR] [--before DIR] [--stem NAME]

The run's Refine-Net is labelled by its smooth_jet ratio, and by its jet_k, training noise levels and points per
cloud where they differ from this checkout's profile's. Writes benchmarks/results/smooth_jet.json and smooth_jet.md (or
`--stem`).
"""

from __future__ import annotations

import argparse
import time
from collections import defaultdict
from pathlib import Path

import numpy as np
import pandas as pd
from machine import machine_info, write_results
from training_study import pipeline_training

from refinenet import config as params_lib
from refinenet.data.io import load_record, read_normals
from refinenet.estimators.smooth_jet import JET_K, NOISE_K, jet_and_noise
from refinenet.evaluation.metrics import unoriented_angles
from refinenet.evaluation.table import category_order
from refinenet.pipeline.workflow import NORMALS, REFINED

ROOT = Path(__file__).resolve().parents[1]
RESULTS = Path(__file__).parent / "results"
RATIOS = (1.0, 1.25, 1.5, 1.75, 2.0, 2.5)
#: The rows of the synthetic table compared (display names of reports/table_synthetic.csv).
TABLE_ROWS = ("PCA", "Jet", "MFPS", "Refine-Net")


def input_errors(run: Path, split: str, fits: dict[str, tuple]) -> tuple[dict[str, dict[str, float]], list[dict]]:
    """Mean error per input and category (mean of the clouds' means, as the tables average) on one split's clouds,
    and the per-cloud rows; each cloud's (truth, jet normals, residuals, noise) go into `fits` by cloud key."""
    errors: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    rows = []
    for path in sorted((run / "results" / "clouds" / split).glob("*/*.npz")):
        category, name = path.parent.name, path.stem
        arrays, _ = load_record(path, ("points", "normals"), "cloud")
        points, truth = arrays["points"].astype(np.float64), arrays["normals"]
        mfps = np.load(run / NORMALS.format(method="mfps", cloud=f"{split}/{category}/{name}"))
        jet, residuals, noise = jet_and_noise(points)
        fits[f"{split}/{category}/{name}"] = truth, jet, residuals, noise
        inputs = {"MFPS": mfps, f"Jet K = {JET_K}": jet}
        for ratio in RATIOS:
            inputs[f"smooth_jet = {ratio}"] = np.where((residuals < ratio * noise)[:, None], jet, mfps)
        row = {"split": split, "category": category, "cloud": name}
        for label, normals in inputs.items():
            row[label] = float(unoriented_angles(normals, truth).mean())
            errors[label][category].append(row[label])
        rows.append(row)
        print(split, category, name, f"MFPS {row['MFPS']:.2f}", f"1.5 {row['smooth_jet = 1.5']:.2f}", flush=True)
    categories = category_order(list(errors["MFPS"]))
    table = {label: {c: float(np.mean(per[c])) for c in categories} for label, per in errors.items()}
    for per in table.values():
        per["Average"] = float(np.mean([per[c] for c in categories]))
    return table, rows


def retrained(run: Path, before: Path, ratio: float, label: str, fits: dict[str, tuple]) -> dict:
    """The run's synthetic tables (mean and PGP) beside those in the folder `before`; per category the share of test
    points the jet took at `ratio` (the run's), with Refine-Net's and the input's error there (`fits` from
    `input_errors`); SmoothSurface's clouds. `label` names the run's Refine-Net."""
    after_table, before_table = (
        pd.concat([pd.read_csv(folder / f"table_synthetic{suffix}.csv", index_col="method")
                   for suffix in ("", "_pgp")], axis=1) for folder in (run / "reports", before))
    share: dict[str, list[float]] = defaultdict(list)
    on_jet: dict[str, dict[str, list[float]]] = defaultdict(lambda: defaultdict(list))
    for key, (truth, jet, residuals, noise) in fits.items():
        if not key.startswith("test/"):
            continue
        category = key.split("/")[1]
        refined = read_normals(run / REFINED.format(variant="full", cloud=key), len(truth))
        took = residuals < ratio * noise
        share[category].append(float(took.mean()))
        if took.any():
            on_jet["input"][category].append(float(unoriented_angles(jet[took], truth[took]).mean()))
            on_jet["Refine-Net"][category].append(float(unoriented_angles(refined[took], truth[took]).mean()))
    order = category_order(list(share))
    per_cloud = {name: pd.read_csv(folder / "per_cloud" / "table_synthetic.csv")
                 for name, folder in (("before", before), ("after", run / "reports"))}
    labels = {("before", "refinenet"): "Refine-Net (committed)", ("after", "jet"): "Jet",
              ("after", "refinenet"): f"Refine-Net, {label}"}
    smooth = {label: per_cloud[name].query("method == @method and category == 'SmoothSurface'")
              .set_index("cloud")["mean"].to_dict() for (name, method), label in labels.items()}
    return {
        "smooth_per_cloud": smooth,
        "ratio": ratio,
        "label": label,
        "before": before_table.loc[list(TABLE_ROWS)].to_dict(orient="index"),
        "after": after_table.loc[list(TABLE_ROWS)].to_dict(orient="index"),
        "share": {c: float(np.mean(share[c])) for c in order},
        "on_jet": {m: {c: float(np.mean(per[c])) for c in order if per[c]} for m, per in on_jet.items()},
    }


def run_label(params: params_lib.Params) -> str:
    """The run's settings that set its Refine-Net apart: the ratio, and the extra jet input, training noise levels
    and points per cloud where they differ from this checkout's profile's."""
    ours = params_lib.load(ROOT / "params.yaml")
    label = f"smooth_jet = {params.features.smooth_jet}"
    if params.features.jet_k != ours.features.jet_k:
        label += f", jet_k = {params.features.jet_k}"
    if params.noise.train != ours.noise.train:
        label += ", training noise " + ", ".join(f"{level:g}" for level in params.noise.train) + "%"
    if params.training.max_train_points_per_cloud != ours.training.max_train_points_per_cloud:
        label += f", {params.training.max_train_points_per_cloud} training points per cloud and cluster"
    return label


def findings(r: dict) -> list[str]:
    """What the retrained table says, worded from its numbers."""
    new, old = r["after"]["Refine-Net"], r["before"]["Refine-Net"]
    jet, mfps = r["before"]["Jet"], r["before"]["MFPS"]
    columns = [c for c in new if c.endswith("/pgp10") and not c.startswith("Average")]
    below_mfps = [c.split("/")[0] for c in columns if new[c] <= mfps[c]]
    smooth, average = "SmoothSurface/mean", "Average/mean"
    return [
        f"- SmoothSurface: Refine-Net {old[smooth]:.2f} -> {new[smooth]:.2f} deg against Jet's {jet[smooth]:.2f} "
        f"({'below' if new[smooth] < jet[smooth] else 'not below'} Jet; {new[smooth] / jet[smooth] - 1:+.1%}).",
        f"- Average mean {old[average]:.2f} -> {new[average]:.2f} ({new[average] / old[average] - 1:+.1%}); per "
        "category " + ", ".join(f"{c.split('/')[0]} {old[c]:.2f} -> {new[c]:.2f}" for c in new
                                if c.endswith("/mean") and not c.startswith("Average")) + ".",
        "- SmoothSurface clouds where Refine-Net is below Jet: " + ", ".join(
            c for c, v in r["smooth_per_cloud"][f"Refine-Net, {r['label']}"].items()
            if v < r["smooth_per_cloud"]["Jet"][c]) + ".",
        "- PGP10 " + ("above MFPS's in every category." if not below_mfps else
                      f"not above MFPS's in {', '.join(below_mfps)} (" + ", ".join(
                          f"{new[c + '/pgp10']:.4f} vs {mfps[c + '/pgp10']:.4f}" for c in below_mfps) + ")."),
    ]


def _table(header: str, rows: dict[str, dict[str, float]], columns: list[str], fmt: str = "{:.2f}") -> list[str]:
    return [f"| {header} | " + " | ".join(columns) + " |", "|---|" + "---|" * len(columns),
            *[f"| {label} | " + " | ".join(fmt.format(values[c]) for c in columns) + " |"
              for label, values in rows.items()], ""]


def markdown(record: dict) -> str:
    lines = ["# The smooth-point jet: the ratio, and Refine-Net trained on it", "",
             f"Generated by `benchmarks/smooth_jet.py` from the pipeline run `{record['run']}` (profile "
             f"`{record['profile']}`). Mean unoriented error in degrees (mean over a category's clouds; Average: over "
             "the four categories).", "",
             "## 1. The input alone (no training)", "",
             f"MFPS, the K = {JET_K} degree-2 jet, and MFPS with the jet's normal where the jet's RMS residual is "
             f"below ratio x the cloud's noise (median residual of K = {NOISE_K} jets). The ratio is chosen on the "
             f"training clouds: **{record['chosen_ratio']}** (lowest Average).", ""]
    for split in ("train", "test"):
        table = record["inputs"][split]
        columns = list(next(iter(table.values())))
        lines += [f"{split.capitalize()} clouds:", "", *_table("input", table, columns)]
    if "retrained" in record:
        r = record["retrained"]
        columns = [c for c in next(iter(r["after"].values())) if c.endswith("/mean")]
        names = [c.split("/")[0] for c in columns]
        rows = {f"{m} (committed)": r["before"][m] for m in TABLE_ROWS}
        rows[f"Refine-Net, {r['label']}"] = r["after"]["Refine-Net"]
        lines += ["## 2. Retrained", "",
                  f"The synthetic table of the run (profile `{record['profile']}` with {r['label']}; PCA, "
                  "Jet and MFPS rows are the same clouds' and equal to the committed ones) beside the committed "
                  "table: mean error.", "",
                  "| method | " + " | ".join(names) + " |", "|---|" + "---|" * len(names),
                  *[f"| {m} | " + " | ".join(f"{v[c]:.2f}" for c in columns) + " |" for m, v in rows.items()], "",
                  "PGP10:", "",
                  "| method | " + " | ".join(names) + " |", "|---|" + "---|" * len(names),
                  *[f"| {m} | " + " | ".join(f"{v[c.replace('/mean', '/pgp10')]:.4f}" for c in columns) + " |"
                    for m, v in rows.items()], "",
                  "Test points the jet took (share of the points), and the mean error there of the jet (the input) "
                  "and of Refine-Net:", "",
                  *_table("", {"share of points": r["share"]}, list(r["share"]), "{:.0%}")[:-1],
                  *_table("", {"jet (input)": r["on_jet"]["input"], "Refine-Net": r["on_jet"]["Refine-Net"]},
                          list(r["share"]))[2:],
                  "SmoothSurface per cloud (mean error; Jet's is the same in both runs):", "",
                  *_table("method", r["smooth_per_cloud"], list(next(iter(r["smooth_per_cloud"].values())))),
                  *r["training"][1:], "", "## Findings", "", *findings(r), ""]
    lines += [f"Wall time {record['wall_s']:.0f} s on {record['machine']['cpu']} ({record['machine']['cores']} "
              "cores).", ""]
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    parser.add_argument("--run", type=Path, default=ROOT, help="a finished pipeline run (its repository root)")
    parser.add_argument("--before", type=Path, default=ROOT / "reports",
                        help="the folder of the synthetic tables (mean and PGP) the run is compared with")
    parser.add_argument("--out", type=Path, default=RESULTS)
    parser.add_argument("--stem", default="smooth_jet", help="results are written to STEM.json and STEM.md")
    args = parser.parse_args()
    start = time.perf_counter()
    params = params_lib.load(args.run / "params.yaml")
    inputs, rows, fits = {}, [], {}
    for split in ("train", "test"):
        inputs[split], split_rows = input_errors(args.run, split, fits)
        rows += split_rows
    chosen = min(RATIOS, key=lambda r: inputs["train"][f"smooth_jet = {r}"]["Average"])
    record = {"run": str(args.run), "profile": params.profile, "chosen_ratio": chosen, "inputs": inputs,
              "clouds": rows}
    if params.features.smooth_jet is not None:
        record["retrained"] = retrained(args.run, args.before, params.features.smooth_jet, run_label(params), fits)
        record["retrained"]["training"] = pipeline_training(args.run, params)
    record.update(wall_s=time.perf_counter() - start, machine=machine_info())
    write_results(args.out, args.stem, record, markdown(record))
    print(markdown(record))


if __name__ == "__main__":
    main()
