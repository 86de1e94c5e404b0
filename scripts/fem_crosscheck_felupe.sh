#!/bin/sh
# Independent check of fem-core's rigid-plate curves with felupe (not part of CI): creates a
# virtual environment under target/felupe-venv, installs felupe from PyPI and runs
# scripts/fem_crosscheck_felupe.py with the given arguments.
set -eu
root=$(cd "$(dirname "$0")/.." && pwd)
venv="${CARGO_TARGET_DIR:-$root/target}/felupe-venv"
if [ ! -x "$venv/bin/python" ]; then
    python3 -m venv "$venv"
    "$venv/bin/pip" install --quiet felupe
fi
cd "$root"
OMP_NUM_THREADS=${OMP_NUM_THREADS:-1} exec "$venv/bin/python" scripts/fem_crosscheck_felupe.py "$@"
