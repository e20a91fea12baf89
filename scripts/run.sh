#!/usr/bin/env bash
# The main job: set up the environment, then build the synthetic benchmark's tables, the release, its figures and
# the page reports/index.html (target `main`) on the embedded procedural data with the profile named in params.yaml (default `cpu`). Arguments replace the
# target, e.g. `bash scripts/run.sh reports/table_baselines.csv`, or `bash scripts/run.sh all` for every table.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
[ -d .git ] || git init -q
snakemake --cores "${CORES:-2}" "${@:-main}"
