"""Snakemake owns the commands, DVC owns the record (docs/design.md §3).

* `run STEP`: what a dvc.yaml stage executes. Asks Snakemake for exactly that step's files
  (`--allowed-rules STEP`, so upstream outputs are never touched) after removing orphan files from the
  step's output folders, so DVC records what the current params produce and nothing else.
* `record`: after a plain Snakemake run, write every finished, up-to-date step into dvc.lock
  (`dvc commit --force`, with one write of dvc.lock), so `dvc repro` has nothing to redo. The Snakefile calls it
  on success. One `snakemake --summary` tells which steps are up to date.
* `sync [STEP ...]`: after `dvc checkout`/`dvc pull`/`git checkout`, when `dvc status` is clean (for the named
  steps), mark the restored files up to date for Snakemake (`snakemake --touch`).
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
from refinenet.errors import ParamsError, RefineNetError
from refinenet.pipeline.dvc import REGENERATE, dvc_yaml_is_current
from refinenet.pipeline.steps import Step
from refinenet.pipeline.workflow import Pipeline

SNAKEMAKE = [sys.executable, "-m", "snakemake", "--snakefile", "workflow/Snakefile"]


def produced(path: Path, targets: list[str]) -> bool:
    """True when `path` is a target or lies inside a target folder (a rule's `directory()` output)."""
    path = path.resolve()
    return any(path == t or t in path.parents for t in (Path(t).resolve() for t in targets))


def prune(step: Step, targets: list[str]) -> list[Path]:
    """Delete files inside the step's output folders that the current params no longer produce (e.g. the
    networks of clusters beyond a lowered Kc); every file a step makes is one of its targets."""
    removed = []
    for out in map(Path, (*step.outs, *step.plots)):
        if not out.is_dir():
            continue
        for path in sorted(out.rglob("*")):
            if path.is_file() and not produced(path, targets):
                path.unlink()
                removed.append(path)
        for folder in sorted((p for p in out.rglob("*") if p.is_dir()), reverse=True):
            if not any(folder.iterdir()):
                folder.rmdir()
    return removed


def _env() -> dict[str, str]:
    return {**os.environ, "REFINENET_BRIDGE": "1"}


def pipeline() -> Pipeline:
    return Pipeline(config.read_raw())


def _check_names(steps: dict[str, Step], names: list[str]) -> None:
    """Every name is a step of this params file's pipeline (a dvc.yaml stage), or a one-line error naming them."""
    unknown = [name for name in names if name not in steps]
    if unknown:
        raise ParamsError("(stages)", f"no step {', '.join(repr(n) for n in unknown)} in this params file's "
                                      f"pipeline ({', '.join(steps)})")


def run(name: str, cores: str) -> int:
    steps = pipeline().steps
    _check_names(steps, [name])
    step = steps[name]
    targets = step.targets()
    for path in prune(step, targets):
        print(f"removed orphan {path}")
    # No Snakemake lock: DVC holds the repository's while a stage runs, and a killed `dvc repro` must not leave
    # a stale Snakemake lock that stops the next one.
    cmd = [*SNAKEMAKE, "--cores", cores, "--nolock", "--allowed-rules", step.name, "--", *targets]
    return subprocess.run(cmd, env=_env()).returncode


def up_to_date_files() -> set[str]:
    """The outputs that exist and that Snakemake would not rebuild: status `ok` and plan `no update` in
    `snakemake --summary` (a file can be `ok` itself and still be pending because an input of its job is missing,
    e.g. a committed report whose upstream steps this run did not build)."""
    summary = subprocess.run([*SNAKEMAKE, "--summary", "--cores", "1"], env=_env(), capture_output=True, text=True)
    if summary.returncode != 0:
        return set()
    rows = [line.split("\t") for line in summary.stdout.splitlines()[1:]]
    return {row[0] for row in rows if len(row) > 5 and row[4:6] == ["ok", "no update"] and Path(row[0]).exists()}


def record() -> int:
    if not Path(".dvc").is_dir() or shutil.which("dvc") is None:
        print("record: no DVC repository here; nothing recorded")
        return 0
    raw = config.read_raw()
    if not dvc_yaml_is_current(raw):
        print(f"record: dvc.yaml does not track params.yaml's present keys, nothing recorded in dvc.lock; "
              f"{REGENERATE}, then run snakemake again to record", file=sys.stderr)
        return 0
    done = up_to_date_files()
    finished = []
    for step in Pipeline(raw).steps.values():
        targets = step.targets()
        if set(targets) <= done:
            prune(step, targets)
            finished.append(step.name)
    if finished:
        commit(finished)
        print(f"recorded in dvc.lock: {', '.join(finished)}")
    return 0


def commit(names: list[str]) -> None:
    """`dvc commit --force` of the named stages, writing dvc.lock once.

    The command line takes its targets one at a time and rewrites dvc.lock after each: with the full set's 400 KB
    lock file that is about 4 s per stage, over 3 minutes for the 51 stages a smoke run finishes. This is the same
    per-stage save and commit (`dvc.repo.commit.commit`) with a single write (every stage is in dvc.yaml).
    """
    from dvc.repo import Repo

    with Repo() as repo, repo.lock:
        stages = {stage.name: stage for stage in repo.index.stages}
        chosen = [stages[name] for name in names]
        for stage in chosen:
            stage.save()
            stage.commit()
        chosen[0].dvcfile.dump_stages(chosen, update_pipeline=False)


def sync(names: list[str]) -> int:
    """Mark the named steps' outputs (every step's when none is named) and what they are made from up to date for
    Snakemake, once DVC has them all: a run that built only some stages (`dvc repro` of the main job) and was
    pulled elsewhere syncs those."""
    steps = pipeline().steps
    _check_names(steps, names)
    status = subprocess.run(["dvc", "status", "--json", *names], capture_output=True, text=True, check=True)
    if json.loads(status.stdout or "{}"):
        print("sync: `dvc status` is not clean; run `dvc checkout` or `dvc repro` first", file=sys.stderr)
        return 1
    targets = [t for name in (names or steps) for t in steps[name].targets()]
    return subprocess.run([*SNAKEMAKE, "--touch", "--cores", "1", "--", *targets], env=_env()).returncode


def main(argv: list[str] | None = None) -> int:
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    sub = parser.add_subparsers(dest="command", required=True)
    run_p = sub.add_parser("run", help="run one step's jobs through Snakemake (what its DVC stage executes)")
    run_p.add_argument("step", help="a step's name: its dvc.yaml stage")
    run_p.add_argument("--cores", default=os.environ.get("REFINENET_CORES", "all"))
    sub.add_parser("record", help="record finished Snakemake steps in dvc.lock")
    sync_p = sub.add_parser("sync", help="mark DVC-restored outputs up to date for Snakemake")
    sync_p.add_argument("steps", nargs="*", help="only these steps (dvc.yaml stages) and their inputs")
    args = parser.parse_args(argv)
    try:
        if args.command == "run":
            return run(args.step, args.cores)
        return record() if args.command == "record" else sync(args.steps)
    except RefineNetError as err:
        print(f"error: {err}", file=sys.stderr)
        return 2


if __name__ == "__main__":
    sys.exit(main())
