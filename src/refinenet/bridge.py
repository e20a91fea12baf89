"""Snakemake owns the commands, DVC owns the record (DESIGN.md §3).

* `run STAGE`: what a dvc.yaml stage executes. Asks Snakemake for exactly that step's files
  (`--allowed-rules RULE`, so upstream outputs are never touched) after removing orphan files from the
  step's output folders, so DVC records what the current params produce and nothing else.
* `record`: after a plain Snakemake run, write every finished, up-to-date step into dvc.lock
  (`dvc commit`), so `dvc repro` has nothing to redo. The Snakefile calls it on success.
* `sync`: after `dvc checkout`/`dvc pull`/`git checkout`, when `dvc status` is clean, mark the restored
  files up to date for Snakemake (`snakemake --touch`).
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import subprocess
import sys
from pathlib import Path

from refinenet import config
from refinenet.errors import RefineNetError
from refinenet.workflow import STEPS, Step

SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", "workflow/Snakefile"]
UP_TO_DATE = "Nothing to be done"


def prune(step: Step, targets: list[str]) -> list[Path]:
    """Delete files inside the step's output folders that the current params no longer produce."""
    keep = {Path(t).resolve() for t in targets}
    removed = []
    for out in map(Path, step.outs):
        if not out.is_dir():
            continue
        for path in sorted(out.rglob("*")):
            if path.is_file() and path.resolve() not in keep:
                path.unlink()
                removed.append(path)
        for folder in sorted((p for p in out.rglob("*") if p.is_dir()), reverse=True):
            if not any(folder.iterdir()):
                folder.rmdir()
    return removed


def _env() -> dict[str, str]:
    return {**os.environ, "REFINENET_BRIDGE": "1"}


def run(stage: str, cores: str) -> int:
    step = STEPS[stage]
    targets = step.targets(config.load())
    for path in prune(step, targets):
        print(f"removed orphan {path}")
    cmd = [*SNAKEMAKE, "--cores", cores, "--allowed-rules", step.rule, "--", *targets]
    return subprocess.run(cmd, env=_env()).returncode


def up_to_date(targets: list[str]) -> bool:
    """True when every target exists and Snakemake would run nothing for them."""
    if not all(Path(t).exists() for t in targets):
        return False
    dry = subprocess.run([*SNAKEMAKE, "-n", "--cores", "1", "--", *targets], env=_env(),
                         capture_output=True, text=True)
    return dry.returncode == 0 and UP_TO_DATE in dry.stdout + dry.stderr


def record() -> int:
    if not Path(".dvc").is_dir() or shutil.which("dvc") is None:
        print("record: no DVC repository here; nothing recorded")
        return 0
    params = config.load()
    finished = []
    for step in STEPS.values():
        targets = step.targets(params)
        if up_to_date(targets):
            prune(step, targets)
            finished.append(step.stage)
    if finished:
        subprocess.run(["dvc", "commit", "--force", "--quiet", *finished], check=True)
        print(f"recorded in dvc.lock: {', '.join(finished)}")
    return 0


def sync() -> int:
    status = subprocess.run(["dvc", "status", "--json"], capture_output=True, text=True, check=True)
    if json.loads(status.stdout or "{}"):
        print("sync: `dvc status` is not clean; run `dvc checkout` or `dvc repro` first", file=sys.stderr)
        return 1
    targets = [t for step in STEPS.values() for t in step.targets(config.load())]
    return subprocess.run([*SNAKEMAKE, "--touch", "--cores", "1", "--", *targets], env=_env()).returncode


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run_p = sub.add_parser("run", help="run one DVC stage's jobs through Snakemake")
    run_p.add_argument("stage", choices=list(STEPS))
    run_p.add_argument("--cores", default=os.environ.get("REFINENET_CORES", "all"))
    sub.add_parser("record", help="record finished Snakemake steps in dvc.lock")
    sub.add_parser("sync", help="mark DVC-restored outputs up to date for Snakemake")
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return run(args.stage, args.cores)
        return record() if args.command == "record" else sync()
    except RefineNetError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
