#!/usr/bin/env bash
# The main job: set up the environment, then build every table on the embedded procedural data
# with the profile named in params.yaml (default `cpu`). Extra arguments go to Snakemake,
# e.g. `bash scripts/run.sh reports/table_baselines.csv`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
[ -d .git ] || git init -q
snakemake --cores "${CORES:-2}" "$@"
