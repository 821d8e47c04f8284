#!/usr/bin/env bash
# The high-order FE benchmark (issue #7): builds isobar, sets up the benchmark venv (PyPI
# VTK) and runs bench_fe.py; the table goes to bench/fe/results.md (and to stdout).
#
#   bash bench/fe/run.sh
set -euo pipefail
cd "$(dirname "$0")/../.."
VENV=.venv-bench
if [ ! -x "$VENV/bin/python" ]; then
    python3 -m venv "$VENV"
fi
"$VENV/bin/python" -m pip install -q -r bench/requirements.txt
cargo build --release
"$VENV/bin/python" bench/fe/bench_fe.py "$@"
