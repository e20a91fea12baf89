"""Summarise a finished pipeline run: wall time, and per rule the jobs, summed job seconds and peak memory.

Reads the per-job benchmark files that every rule writes (`logs/<rule>/**/*.benchmark.tsv`) in a run folder and
writes a markdown report. The total wall time is measured by the caller (e.g. `time bash scripts/run.sh`) and
passed in, since job seconds overlap when jobs run in parallel.
Usage: python benchmarks/pipeline_report.py RUN_DIR --wall-seconds S --profile cpu \
    --out benchmarks/results/pipeline_cpu.md
"""

from __future__ import annotations

import argparse
import platform
from pathlib import Path

import pandas as pd
from machine import machine_info

from refinenet.pipeline.timing import read_benchmark
from refinenet.pipeline.workflow import FULL, VARIANT_STEPS


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


def main() -> None:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("run_dir", type=Path)
    parser.add_argument("--wall-seconds", type=float, required=True)
    parser.add_argument("--profile", required=True)
    parser.add_argument("--command", default="bash scripts/run.sh")
    parser.add_argument("--out", type=Path, required=True)
    parser.add_argument("--note", default="", help="how the run went, when not in one piece (a sentence)")
    parser.add_argument("--no-setup", action="store_true",
                        help="the run went on in a clone already set up (a table after the main job)")
    args = parser.parse_args()
    summary = rule_summary(args.run_dir)
    machine = machine_info()
    lines = [
        f"# Pipeline run, profile `{args.profile}`",
        "",
        f"`{args.command}` on a fresh clone: **{duration(args.wall_seconds)}** wall time in total "
        + ("(no set-up: the environment was already there)" if args.no_setup else "(environment set-up included)")
        + f", on {machine['cores']} cores ({machine['cpu']}), {platform.machine()}, "
        f"Python {machine['python']}. Job seconds are summed over jobs that ran two at a time." +
        (f" {args.note}" if args.note else ""),
        "",
        family_totals(summary),
        "",
        "| rule | jobs | job seconds (sum) | longest job (s) | peak memory of a job (MB) |",
        "|---|---|---|---|---|",
        *(f"| {rule} | {int(r.jobs)} | {r.job_seconds:.0f} | {r.longest_job_s:.1f} | {r.peak_rss_mb:.0f} |"
          for rule, r in summary.iterrows()),
        "",
    ]
    args.out.write_text("\n".join(lines))
    print("\n".join(lines))


if __name__ == "__main__":
    main()
