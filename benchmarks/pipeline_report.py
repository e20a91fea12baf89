"""What a pipeline run costs per target: wall time, and per rule the jobs, summed job seconds and peak memory.

Reads the per-job benchmark files that every rule writes (`logs/<rule>/**/*.benchmark.tsv`) in a run folder. Each
target measured is one section of benchmarks/results/pipeline.json, replaced when that target is measured again;
pipeline.md is rebuilt from every section. The total wall time is measured by the caller (e.g. `time bash
scripts/run.sh`) and passed in, since job seconds overlap when jobs run in parallel.

    python benchmarks/pipeline_report.py RUN_DIR --wall-seconds S --section main
    python benchmarks/pipeline_report.py RUN_DIR --wall-seconds S --section table_loss --no-setup \
        --command "snakemake -j2 reports/table_loss.csv" --note "After the main job in the same clone."

Sections: `main` (the main job, `bash scripts/run.sh`, set-up included), `main_float32` (the same with the
profile's training and inference precision set to float32: what a CPU without native bfloat16 computes), `all`
(`bash scripts/run.sh all`), and one per table run after the main job in the same clone (`table_loss`, ...).
"""

from __future__ import annotations

import argparse
import json
import platform
from datetime import date
from pathlib import Path

import pandas as pd
from machine import machine_info, write_results

from refinenet.pipeline.methods import FULL
from refinenet.pipeline.timing import read_benchmark
from refinenet.pipeline.variants import VARIANT_STEPS

RESULTS = Path(__file__).parent / "results"
#: The results' file names: STEM.json (the sections) and STEM.md (their report).
STEM = "pipeline"


def job_benchmarks(run_dir: Path) -> pd.DataFrame:
    """One row per job of a run: its step (clouds_train and clouds_test share a log folder and are told apart by
    the split; the per-variant steps by the variant folder), seconds and peak memory (MB), from the benchmark files
    every rule writes."""
    rows = []
    for path in sorted((run_dir / "logs").rglob("*.benchmark.tsv")):
        parts = path.relative_to(run_dir / "logs").parts
        rule = parts[0].removesuffix(".benchmark.tsv")
        if rule == "clouds":
            rule = f"clouds_{parts[1]}"
        elif rule in VARIANT_STEPS:
            variant = parts[1].removesuffix(".benchmark.tsv")
            rule = rule if variant == FULL else f"{rule}_{variant}"
        rows.append({"rule": rule, **read_benchmark(path)})
    return pd.DataFrame(rows)


def rule_summary(run_dir: Path) -> pd.DataFrame:
    return job_benchmarks(run_dir).groupby("rule", sort=False).agg(
        jobs=("seconds", "size"), job_seconds=("seconds", "sum"), longest_job_s=("seconds", "max"),
        peak_rss_mb=("rss_mb", "max"))


def duration(seconds: float) -> str:
    """Minutes for a short run, hours (and minutes) for a long one, as the issue's budgets are given."""
    if seconds < 7200:
        return f"{seconds / 60:.1f} minutes"
    return f"{seconds / 3600:.2f} hours ({seconds / 60:.0f} minutes)"


def family_totals(summary: pd.DataFrame) -> str:
    """Job seconds summed per step family (a variant's training counts as training), largest first."""
    family = summary.index.map(lambda rule: next((s for s in VARIANT_STEPS if rule.startswith(s)), "other steps"))
    totals = summary.job_seconds.groupby(family).sum().sort_values(ascending=False)
    parts = ", ".join(f"{name} {seconds:,.0f}" for name, seconds in totals.items())
    return f"Job seconds in all: {summary.job_seconds.sum():,.0f} ({parts})."


def measured(args: argparse.Namespace) -> dict:
    """One section: how the run was made, on what machine, and its per-rule summary."""
    machine = machine_info()
    return {"profile": args.profile, "command": args.command, "wall_seconds": args.wall_seconds,
            "setup": not args.no_setup, "note": args.note, "date": date.today().isoformat(),
            "machine": {"cpu": machine["cpu"], "cores": machine["cores"], "arch": platform.machine(),
                        "python": machine["python"]},
            "rules": rule_summary(args.run_dir).reset_index().to_dict(orient="records")}


def section_lines(name: str, section: dict) -> list[str]:
    """The markdown of one section."""
    summary = pd.DataFrame(section["rules"]).set_index("rule")
    machine = section["machine"]
    cpu = f" ({machine['cpu']})" if machine["cpu"] else ""
    return [
        f"## {name}",
        "",
        f"`{section['command']}` on a fresh clone, profile `{section['profile']}`, {section['date']}: "
        f"**{duration(section['wall_seconds'])}** wall time in total "
        + ("(environment set-up included)" if section["setup"] else "(no set-up: the environment was already there)")
        + f", on {machine['cores']} cores{cpu}, {machine['arch']}, Python {machine['python']}."
        + (f" {section['note']}" if section["note"] else ""),
        "",
        family_totals(summary),
        "",
        "| rule | jobs | job seconds (sum) | longest job (s) | peak memory of a job (MB) |",
        "|---|---|---|---|---|",
        *(f"| {rule} | {int(r.jobs)} | {r.job_seconds:.0f} | {r.longest_job_s:.1f} | {r.peak_rss_mb:.0f} |"
          for rule, r in summary.iterrows()),
        "",
    ]


def markdown(sections: dict[str, dict]) -> str:
    lines = ["# Pipeline runs: what each target costs", "",
             "One section per target, each measured on its own run by `benchmarks/pipeline_report.py`: `main` is "
             "the main job, `main_float32` the same computed in float32 (a CPU without native bfloat16), `all` every "
             "table and figure, and each table a run after the main job in the same clone (only its variants and the "
             "table ran). Job seconds are summed over jobs that ran two at a time.", ""]
    for name, section in sections.items():
        lines += section_lines(name, section)
    return "\n".join(lines)


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--wall-seconds", type=float, required=True)
    parser.add_argument("--section", required=True, help="the target measured: main, main_float32, all, table_loss...")
    parser.add_argument("--profile", default="cpu")
    parser.add_argument("--command", default="bash scripts/run.sh")
    parser.add_argument("--out", type=Path, default=RESULTS, help="the folder of pipeline.json and pipeline.md")
    parser.add_argument("--note", default="", help="how the run went, when not in one piece (a sentence)")
    parser.add_argument("--no-setup", action="store_true",
                        help="the run went on in a clone already set up (a table after the main job)")
    args = parser.parse_args()
    path = args.out / f"{STEM}.json"
    sections = json.loads(path.read_text())["sections"] if path.is_file() else {}
    sections[args.section] = measured(args)
    text = markdown(sections)
    write_results(args.out, STEM, {"sections": sections}, text)
    print("\n".join(section_lines(args.section, sections[args.section])))


if __name__ == "__main__":
    main()
