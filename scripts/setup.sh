#!/usr/bin/env bash
# Create the project's environment: the system library Open3D needs, then the Python packages in a virtual
# environment, .venv unless VENV names another folder. Python: PYTHON if set, else the newest of python3.13,
# python3.12, python3.11 (and python3) on the PATH; an existing environment keeps its Python unless PYTHON names
# another version. Safe to re-run: it skips what is already in place. Torch is pinned so that pip takes its CPU
# build where one is offered (a looser requirement pulls a newer build with several GB of CUDA packages); where
# pip finds only PyPI's build of the pinned version, that one comes with its CUDA packages (it runs on the CPU too).
set -euo pipefail
cd "$(dirname "$0")/.."

# grep without -q: under pipefail, ldconfig's SIGPIPE when grep -q stops reading early would read as "missing".
if ! ldconfig -p 2>/dev/null | grep "libusb-1.0.so.0" >/dev/null; then
    echo "setup: installing libusb-1.0 (needed by open3d)"
    SUDO=""; [ "$(id -u)" -eq 0 ] || SUDO="sudo"
    $SUDO apt-get update -qq
    DEBIAN_FRONTEND=noninteractive $SUDO apt-get install -y -qq libusb-1.0-0 >/dev/null
fi

SUPPORTED="3.11 3.12 3.13"  # pyproject.toml's requires-python (CI tests 3.11 and 3.13: .ci/run)
version() { "$1" -c 'import sys; print("%d.%d" % sys.version_info[:2])' 2>/dev/null; }
supported() { [[ " $SUPPORTED " == *" $1 "* ]]; }

VENV="${VENV:-.venv}"
if [ -n "${PYTHON:-}" ]; then
    found=$(version "$PYTHON") || { echo "setup: PYTHON=$PYTHON does not run (not on the PATH?)" >&2; exit 1; }
    supported "$found" || { echo "setup: PYTHON=$PYTHON is Python $found, not one of $SUPPORTED" >&2; exit 1; }
elif [ ! -x "$VENV/bin/python" ]; then
    for candidate in python3.13 python3.12 python3.11 python3; do
        if command -v "$candidate" >/dev/null && supported "$(version "$candidate")"; then
            PYTHON=$candidate
            break
        fi
    done
    [ -n "${PYTHON:-}" ] || { echo "setup: no Python $SUPPORTED on the PATH (python3.13 ... python3.11, python3);" \
        "install one (Debian: apt-get install python3) or name it with PYTHON=" >&2; exit 1; }
fi

if [ -x "$VENV/bin/python" ] && { [ -z "${PYTHON:-}" ] || [ "$(version "$VENV/bin/python")" == "$(version "$PYTHON")" ]; }
then
    echo "setup: using $VENV, $("$VENV/bin/python" --version)"
else
    echo "setup: creating $VENV with $("$PYTHON" --version) ($(command -v "$PYTHON"))"
    "$PYTHON" -m venv --clear "$VENV"
fi

stamp=$VENV/.refinenet-installed
want=$(cat pyproject.toml | sha256sum | cut -d' ' -f1)
if [ "$(cat "$stamp" 2>/dev/null)" != "$want" ]; then
    echo "setup: installing Python packages in $VENV (a few minutes the first time)"
    "$VENV/bin/python" -m pip install -q --upgrade pip
    "$VENV/bin/python" -m pip install -q "torch==2.13.0"
    "$VENV/bin/python" -m pip install -q -e ".[dev]"
    echo "$want" > "$stamp"
fi
