#!/usr/bin/env bash
# Set up the environment, then run the whole test suite (unit tests, ruff, and the end-to-end smoke pipeline
# through both Snakemake and DVC). Extra arguments go to pytest, e.g. `bash scripts/test.sh -m "not slow"`;
# PYTHON and VENV choose the Python and the environment's folder as for scripts/setup.sh.
set -euo pipefail
cd "$(dirname "$0")/.."
bash scripts/setup.sh
VENV="${VENV:-.venv}"
[[ "$VENV" == /* ]] || VENV="$PWD/$VENV"
export PATH="$VENV/bin:$PATH"
python -m pytest "$@"
