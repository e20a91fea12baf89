"""A real single-node SLURM cluster on this machine, and the smoke pipeline run through Snakemake's SLURM executor
plugin on it, compared with a local run: every report file must be bit-identical.

    python tests/slurm_cluster.py [--json result.json] [--log snakemake.log] [--keep FOLDER]   # as root

Needs root (it installs slurmctld, slurmd and munge from the Debian archive when they are missing and starts the
daemons). No accounting database: the plugin polls `squeue`, which is reliable when finished jobs stay listed for
longer than its polling interval (MinJobAge, set here to 10 minutes). The configuration goes to SLURM's default
place, /etc/slurm/slurm.conf, because the plugin's job steps drop `SLURM_CONF` from their environment as a real
cluster's nodes would not need it; the check refuses to run where a configuration already exists there (a real
SLURM set-up is never touched), and it removes its own and stops the daemons at the end whatever happens. State
and logs live in a scratch folder.
"""

from __future__ import annotations

import argparse
import json
import os
import shutil
import signal
import socket
import subprocess
import sys
import tempfile
import time
from collections.abc import Iterator
from contextlib import contextmanager
from pathlib import Path

sys.path.insert(0, str(Path(__file__).resolve().parent))
from scratch import different_files, isolated, report_files, sh, smoke_copy  # noqa: E402

from refinenet import config  # noqa: E402
from refinenet.pipeline.workflow import Pipeline  # noqa: E402

PACKAGES = ("slurmctld", "slurmd", "slurm-client", "munge")
CONF = Path("/etc/slurm/slurm.conf")
#: The smoke pipeline through SLURM (324 jobs) took 38 minutes on 2 cores with nothing else running; a hung
#: cluster fails.
LIMIT_S = 60 * 60
MARK = "# written by tests/slurm_cluster.py; removed when the check ends\n"
DAEMONS = ("slurmctld", "slurmd", "munged", "sbatch", "squeue")
#: The repository's SLURM profile, with what this single node needs on top: no accounts, `squeue` polling at short
#: intervals (and no GPU requests: `executor`).
PROFILE = ("--profile", "workflow/profiles/slurm", "--jobs", "4", "--slurm-no-account",
           "--slurm-status-command", "squeue", "--slurm-init-seconds-before-status-checks", "5", "--latency-wait", "5")


def missing() -> str | None:
    """Why this machine cannot run the check, or None."""
    if os.geteuid() != 0:
        return "needs root to install and start the SLURM and munge daemons"
    if CONF.exists() and not CONF.read_text().startswith(MARK):
        return f"{CONF} exists: a SLURM set-up of this machine, which this check does not touch"
    if not all(shutil.which(d) for d in DAEMONS) and shutil.which("apt-get") is None:
        return "the SLURM daemons are not installed and there is no apt-get to install them"
    return None


def install() -> None:
    """slurmctld, slurmd and munge from the Debian archive, unless already there."""
    if all(shutil.which(d) for d in DAEMONS):
        return
    env = {**os.environ, "DEBIAN_FRONTEND": "noninteractive"}
    subprocess.run(["apt-get", "update", "-qq"], check=True, env=env, capture_output=True)
    subprocess.run(["apt-get", "install", "-y", "-qq", "--no-install-recommends", *PACKAGES], check=True, env=env,
                   capture_output=True)


def slurm_conf(folder: Path) -> str:
    """One node (this machine, all its cores and 90% of its memory), one partition, no accounting."""
    host = socket.gethostname()
    cpus = os.cpu_count()
    memory_mb = int(os.sysconf("SC_PAGE_SIZE") * os.sysconf("SC_PHYS_PAGES") / 2**20 * 0.9)
    return MARK + f"""ClusterName=refinenet
SlurmctldHost={host}
SlurmUser=root
SlurmdUser=root
AuthType=auth/munge
MpiDefault=none
MailProg=/bin/true
StateSaveLocation={folder}/state
SlurmdSpoolDir={folder}/spool
SlurmctldPidFile={folder}/slurmctld.pid
SlurmdPidFile={folder}/slurmd.pid
SlurmctldLogFile={folder}/slurmctld.log
SlurmdLogFile={folder}/slurmd.log
ProctrackType=proctrack/linuxproc
TaskPlugin=task/none
JobAcctGatherType=jobacct_gather/none
AccountingStorageType=accounting_storage/none
JobCompType=jobcomp/none
SelectType=select/cons_tres
SelectTypeParameters=CR_Core_Memory
MinJobAge=600
ReturnToService=2
NodeName={host} CPUs={cpus} RealMemory={memory_mb} State=UNKNOWN
PartitionName=main Nodes={host} Default=YES MaxTime=INFINITE State=UP
"""


def _munge_running() -> bool:
    probe = subprocess.run("munge -n | unmunge", shell=True, capture_output=True)
    return probe.returncode == 0


@contextmanager
def single_node_slurm(folder: Path) -> Iterator[None]:
    """Start munge (unless running), slurmctld and slurmd with state and logs in `folder`; on leaving, stop the
    daemons this started and remove the configuration."""
    install()
    for sub in ("state", "spool"):
        (folder / sub).mkdir(parents=True, exist_ok=True)
    CONF.parent.mkdir(parents=True, exist_ok=True)
    CONF.write_text(slurm_conf(folder))
    started: list[subprocess.Popen] = []
    try:
        if not _munge_running():
            Path("/run/munge").mkdir(parents=True, exist_ok=True)
            shutil.chown("/run/munge", "munge", "munge")
            started.append(_daemon("munged", ["runuser", "-u", "munge", "--", "munged", "--foreground"], folder))
            _wait(_munge_running, 30, "munged did not start")
        started.append(_daemon("slurmctld", ["slurmctld", "-D", "-i"], folder))
        started.append(_daemon("slurmd", ["slurmd", "-D"], folder))
        _wait(lambda: _node_state() in {"idle", "mixed", "allocated"}, 60,
              f"the node did not come up; see {folder}/slurmctld.log and slurmd.log")
        yield
    finally:
        for proc in reversed(started):
            proc.terminate()
            try:
                proc.wait(timeout=30)
            except subprocess.TimeoutExpired:
                proc.kill()
        CONF.unlink(missing_ok=True)


def _daemon(name: str, cmd: list[str], folder: Path) -> subprocess.Popen:
    """A daemon in the foreground, its output in `folder`/NAME.out."""
    with open(folder / f"{name}.out", "ab") as out:
        return subprocess.Popen(cmd, stdout=out, stderr=subprocess.STDOUT)


def _node_state() -> str:
    out = subprocess.run(["sinfo", "-h", "-o", "%T"], capture_output=True, text=True)
    return out.stdout.strip().rstrip("*") if out.returncode == 0 else ""


def _wait(ready, seconds: float, failure: str) -> None:
    deadline = time.monotonic() + seconds
    while not ready():
        if time.monotonic() > deadline:
            raise RuntimeError(failure)
        time.sleep(0.5)


def executor(repo: Path) -> tuple[str, ...]:
    """Snakemake's options for this node: PROFILE, and no GPU for any rule that asks for one (every variant's training
    and inference: the node has none, and the smoke profile's device is auto)."""
    steps = Pipeline(config.read_raw(repo / "params.yaml")).steps.values()
    return (*PROFILE, "--set-resources", *(f"{s.name}:gpu=0" for s in steps if s.family in ("training", "inference")))


def run_on_slurm(workdir: Path, reference: Path | None = None, log: Path | None = None) -> dict:
    """The smoke pipeline through `--executor slurm` in a fresh copy under `workdir`, compared with `reference`
    (a finished local smoke run; made here when not given); Snakemake's whole output goes to `log` if given."""
    if reference is None:
        reference = smoke_copy(workdir / "local")
        sh(reference, sys.executable, "-m", "snakemake", "-j2")
    repo = smoke_copy(workdir / "slurm")
    with single_node_slurm(workdir / "cluster"):
        began = time.monotonic()
        try:
            run = subprocess.run([sys.executable, "-m", "snakemake", *executor(repo)], cwd=repo, capture_output=True,
                                 text=True, env=isolated(repo), timeout=LIMIT_S)
            returncode, output = run.returncode, run.stdout + run.stderr
        except subprocess.TimeoutExpired as err:
            returncode, output = f"timed out after {LIMIT_S} s", str(err.stdout or "") + str(err.stderr or "")
        seconds = time.monotonic() - began
        submitted = sum("has been submitted with SLURM jobid" in line for line in output.splitlines())
    if log is not None:
        log.write_text(output)
    expected, got = report_files(reference), report_files(repo)
    different = different_files(expected, got)
    return {"returncode": returncode, "seconds": round(seconds, 1), "slurm_jobs": submitted,
            "report_files": len(expected), "different_files": different,
            "log_tail": output[-4000:] if returncode else ""}


def passed(result: dict) -> bool:
    return result["returncode"] == 0 and result["slurm_jobs"] > 0 and not result["different_files"]


def main() -> int:
    signal.signal(signal.SIGTERM, lambda *_: sys.exit(143))  # so that a stopped check still stops its daemons
    parser = argparse.ArgumentParser(description=__doc__, formatter_class=argparse.RawDescriptionHelpFormatter)
    parser.add_argument("--json", help="write the result here")
    parser.add_argument("--log", type=Path, help="write Snakemake's output here")
    parser.add_argument("--keep", type=Path, help="run in this folder and keep it (logs of the daemons and jobs)")
    args = parser.parse_args()
    reason = missing()
    if reason:
        print(f"slurm check skipped: {reason}")
        return 0
    if args.keep:
        args.keep.mkdir(parents=True, exist_ok=True)
        result = run_on_slurm(args.keep, log=args.log)
    else:
        with tempfile.TemporaryDirectory(prefix="slurm_cluster.") as tmp:
            result = run_on_slurm(Path(tmp), log=args.log)
    text = json.dumps(result, indent=2)
    print(text)
    if args.json:
        Path(args.json).write_text(text + "\n")
    return 0 if passed(result) else 1


if __name__ == "__main__":
    sys.exit(main())
