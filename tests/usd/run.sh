#!/usr/bin/env bash
# Runs the USD writer's tests the way a user gets it: the venv of the Python package's
# tests, a real install of ./rust-core/python (cargo builds the core), usd-core from PyPI,
# a real (non-editable) install of ./usd-exporter, numpy < 2 (what Blender's bpy pins),
# then pytest on tests/usd.
#
#   bash tests/usd/run.sh [pytest args...]
#
# Environment: ISOBAR_TEST_VENV (default .venv-test at the repository root),
# ISOBAR_TEST_PYTHON (interpreter for a new venv, default python3),
# ISOBAR_TEST_NUMPY (numpy requirement, default "numpy<2"),
# ISOBAR_USD_SKIP_CORE=1 (keep the installed isobar package; no cargo, no reinstall).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$root"

venv="${ISOBAR_TEST_VENV:-$root/.venv-test}"
python="${ISOBAR_TEST_PYTHON:-python3}"
numpy_req="${ISOBAR_TEST_NUMPY:-numpy<2}"

log() { printf '\n== %s\n' "$*"; }

if [ ! -x "$venv/bin/python" ]; then
    log "venv $venv"
    "$python" -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import pytest, numpy, pxr' >/dev/null 2>&1; then
    log "pip: pytest usd-core $numpy_req"
    "$venv/bin/python" -m pip install -q pytest usd-core "$numpy_req"
fi

if [ "${ISOBAR_USD_SKIP_CORE:-0}" != 1 ] || ! "$venv/bin/python" -c 'import isobar; isobar.extract' >/dev/null 2>&1; then
    log "pip install ./rust-core/python (cargo build --release)"
    # --force-reinstall --no-deps: the same version number must still pick up a rebuilt library.
    "$venv/bin/python" -m pip install -q --force-reinstall --no-deps ./rust-core/python
fi

log "pip install ./usd-exporter"
# The venv's own setuptools (+ wheel) builds it when they are there and recent enough (no
# index needed); otherwise pip fetches the build backend into an isolated environment.
isolation=()
if "$venv/bin/python" - <<'PY' >/dev/null 2>&1
import sys
import setuptools, wheel  # noqa: F401 - bdist_wheel comes from `wheel` before setuptools 70.1
sys.exit(0 if int(setuptools.__version__.split(".")[0]) >= 61 else 1)
PY
then
    isolation=(--no-build-isolation)
fi
"$venv/bin/python" -m pip install -q --force-reinstall --no-deps "${isolation[@]}" ./usd-exporter
rm -rf ./usd-exporter/build ./usd-exporter/*.egg-info
"$venv/bin/python" -c 'import isobar, isobar_usd, numpy, pxr.Usd as U; print("isobar", isobar.__version__, "core", isobar.core_version(), "isobar_usd", isobar_usd.__version__, "usd-core", ".".join(map(str, U.GetVersion())), "numpy", numpy.__version__)'

log "pytest tests/usd"
unset ISOBAR_LIBRARY  # test the library inside the installed package
cd "$root/tests/usd"
exec "$venv/bin/python" -m pytest -ra "$@" .
