"""Kill anywhere: SIGKILL the smoke pipeline at seeded random moments, restart it each time as a user would, and
compare every report file with an uninterrupted run's: they must be bit-identical.

    python tests/kill_anywhere.py --tools snakemake dvc --kills 10 --seed 0 --json out.json

The moments are spread over the length of the uninterrupted run. A restarted run that ends before its kill (the
machine got faster than when that length was measured) has its reports compared too; the length shrinks to the time
that copy took and the remaining kills go to a fresh copy, so that every kill finds work whatever the load. Two
kills are aimed: the first one that finds a file being written (a `.NAME.*.tmp*` beside an output) and the first
one that finds a training job past its first epoch (a checkpoint exists), so that the atomic writes and the training
resumption are both exercised; the last kills wait, one for each of the two that has not happened yet. A killed
Snakemake leaves its lock behind: the restart runs `snakemake --unlock` first, as Snakemake's own message says. A
killed `dvc repro` is simply run again (each DVC stage runs Snakemake without a lock of its own; DVC holds the
repository's).
"""

from __future__ import annotations

import argparse
import json
import os
import random
import signal
import subprocess
import sys
import tempfile
import time
from pathlib import Path

import psutil

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scratch import different_files, isolated, report_files, sh, smoke_copy  # noqa: E402

from refinenet import config  # noqa: E402
from refinenet.pipeline.catalogue import MAIN  # noqa: E402
from refinenet.pipeline.workflow import Pipeline  # noqa: E402

POLL = 0.02
#: The main job (workflow.MAIN) through each tool: the whole chain, clouds to release, without the ablation variants
#: (which only repeat its steps with other settings).
COMMANDS = {"snakemake": [sys.executable, "-m", "snakemake", "-j2", "main"],
            "dvc": ["dvc", "repro", "--quiet", *MAIN]}


def start(repo: Path, tool: str, log: Path) -> subprocess.Popen:
    """The pipeline in a process group of its own, so one signal reaches every job it started."""
    if tool == "snakemake":
        subprocess.run([*COMMANDS[tool], "--unlock"], cwd=repo, capture_output=True, env=isolated(repo))
    with open(log, "a") as out:
        return subprocess.Popen(COMMANDS[tool], cwd=repo, stdout=out, stderr=subprocess.STDOUT,
                                start_new_session=True, env=isolated(repo))


def snakemake_targets(repo: Path, tool: str) -> list[str]:
    """What the tool's main job makes, as Snakemake targets: the `main` rule for Snakemake (the MAIN steps, the
    release's training curves and the page of them); the MAIN steps' files for DVC (`dvc repro` of the MAIN stages
    makes no page: the `report` stage is the page of every table)."""
    if tool == "snakemake":
        return ["main"]
    steps = Pipeline(config.read_raw(repo / "params.yaml")).steps
    return [target for name in MAIN for target in steps[name].targets()]


def up_to_date(repo: Path, tool: str) -> bool:
    """Neither tool has anything left to do for what the tool's main job makes."""
    dry_run = sh(repo, sys.executable, "-m", "snakemake", "-n", *snakemake_targets(repo, tool)).stdout
    return "Nothing to be done" in dry_run and not json.loads(sh(repo, "dvc", "status", "--json", *MAIN).stdout or "{}")


def main_reports(repo: Path) -> dict[str, bytes]:
    """The report files of the main job's steps (a copy of the working tree also holds the committed reports of
    other steps, which the main job does not make)."""
    return {name: data for name, data in report_files(repo).items() if Path(name).stem in MAIN}


def writing(repo: Path) -> bool:
    """A job is writing an output: a temporary file of the atomic writer exists. (A folder that a tool removes
    while it is searched ends the search: no write is seen this time.)"""
    try:
        return any(p.name.startswith(".") and ".tmp" in p.name for folder in ("results", "reports")
                   if (repo / folder).is_dir() for p in (repo / folder).rglob(".*"))
    except FileNotFoundError:
        return False


def training_resumable(proc: subprocess.Popen, repo: Path) -> bool:
    """A training job is running and has finished at least one epoch (its checkpoint exists)."""
    try:
        jobs = [" ".join(c.cmdline()) for c in psutil.Process(proc.pid).children(recursive=True)]
    except psutil.Error:
        return False
    return any("stages.training" in j for j in jobs) and any((repo / "results/checkpoints").rglob("checkpoint.pt"))


def kill_once(repo: Path, tool: str, delay: float, aims: dict[str, int], log: Path) -> str | None:
    """Start the pipeline and kill its whole process group after `delay` seconds, or earlier when an aimed
    situation arises that no kill has hit yet. Returns what the kill hit, None when the run ended first, or
    "failed" when it ended with an error (a restart must not fail)."""
    proc = start(repo, tool, log)
    deadline = time.monotonic() + delay
    hit = "timed"
    while time.monotonic() < deadline:
        if proc.poll() is not None:
            return None if proc.returncode == 0 else "failed"
        if not aims["write"] and writing(repo):
            hit = "write"
            break
        if not aims["training"] and training_resumable(proc, repo):
            hit = "training"
            break
        time.sleep(POLL)
    os.killpg(proc.pid, signal.SIGKILL)
    proc.wait()
    aims[hit] = aims.get(hit, 0) + 1
    return hit


def passed(result: dict, kills: int) -> bool:
    """Every kill happened, one of them during a write and one during training, no restart failed, and the runs
    ended as if none had."""
    return (result["kills"] == kills and result["during_write"] >= 1 and result["during_training"] >= 1
            and not result["failed_restarts"] and not result["different_files"] and result["up_to_date"])


def kill_anywhere(tools: list[str], kills: int, seed: int, workdir: Path, reference: Path | None = None,
                  length: float | None = None) -> dict:
    """Kill runs of each tool in fresh smoke copies under `workdir`; compare with `reference`, a finished
    uninterrupted smoke run that took `length` seconds (made here when not given)."""
    if reference is None:
        reference = smoke_copy(workdir / "reference")
        began = time.monotonic()
        sh(reference, *COMMANDS["snakemake"])
        length = time.monotonic() - began
    expected = main_reports(reference)
    rng = random.Random(seed)
    results = {"reference_seconds": round(length, 1), "report_files": len(expected), "tools": {}}
    for tool in tools:
        victim, copies = smoke_copy(workdir / tool), 1
        log = workdir / f"{tool}.log"
        aims = {"write": 0, "training": 0, "timed": 0}
        hits, spent, failed, different = [], 0.0, 0, set()
        for _ in range(3 * kills):
            if len(hits) == kills:
                break
            delay = rng.uniform(0.6, 1.2) * length / kills
            if len(hits) >= kills - sum(not aims[aim] for aim in ("write", "training")):
                delay = 5 * length  # the last kills wait, one for each aimed situation not met yet (DVC reruns
                                    # a killed stage whole, so its timed kills may all fall before training)
            began = time.monotonic()
            hit = kill_once(victim, tool, delay, aims, log)
            spent += time.monotonic() - began
            if hit == "failed":
                failed += 1
                continue
            if hit is None:
                # The run ended before its kill: the machine is faster now than when `length` was measured (a
                # load that came and went). The remaining kills go to a fresh copy, spread over this copy's time.
                different |= set(different_files(expected, main_reports(victim)))
                length, spent = min(length, spent), 0.0
                copies += 1
                victim = smoke_copy(workdir / f"{tool}{copies}")
                continue
            hits.append(hit)
        if tool == "snakemake":
            sh(victim, *COMMANDS[tool], "--unlock")
        sh(victim, *COMMANDS[tool])
        different |= set(different_files(expected, main_reports(victim)))
        results["tools"][tool] = {"kills": len(hits), "copies": copies, "failed_restarts": failed,
                                  "during_write": aims["write"], "during_training": aims["training"],
                                  "different_files": sorted(different),
                                  "identical_files": len(expected) - len(different),
                                  "up_to_date": up_to_date(victim, tool)}
    return results


def main() -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--tools", nargs="+", choices=list(COMMANDS), default=list(COMMANDS))
    parser.add_argument("--kills", type=int, default=10)
    parser.add_argument("--seed", type=int, default=0)
    parser.add_argument("--json", help="write the results here")
    args = parser.parse_args()
    with tempfile.TemporaryDirectory(prefix="kill_anywhere.") as tmp:
        results = kill_anywhere(args.tools, args.kills, args.seed, Path(tmp))
    text = json.dumps(results, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0 if all(passed(r, args.kills) for r in results["tools"].values()) else 1


if __name__ == "__main__":
    sys.exit(main())
