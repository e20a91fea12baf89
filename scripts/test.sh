#!/usr/bin/env bash
# Set up the environment, then run the whole test suite (unit tests and the end-to-end smoke pipeline
# through both Snakemake and DVC). Extra arguments go to pytest, e.g. `bash scripts/test.sh -m "not slow"`.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
export PATH="$PWD/.venv/bin:$PATH"
python -m pytest "$@"
