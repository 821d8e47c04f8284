#!/usr/bin/env bash
# Tests the Blender add-on the way an artist gets it: bpy 5.0.1 from PyPI (headless, in a
# venv made with this machine's python3, 3.11), the extension zip built by
# blender-addon/build.sh, installed and enabled by Blender's own extension installer.
#
#   bash tests/blender/run.sh [pytest args...]
#
# Environment: ISOBAR_BLENDER_VENV (default .venv-blender at the repository root),
# ISOBAR_BLENDER_PYTHON (interpreter for a new venv, default python3),
# ISOBAR_BLENDER_BPY (bpy requirement, default bpy==5.0.1), ISOBAR_SKIP_APT=1 (never run
# apt-get), ISOBAR_TEST_DATA (folder holding splashsurf/, default ../shared/data).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$root"

venv="${ISOBAR_BLENDER_VENV:-$root/.venv-blender}"
python="${ISOBAR_BLENDER_PYTHON:-python3}"
bpy_req="${ISOBAR_BLENDER_BPY:-bpy==5.0.1}"

log() { printf '\n== %s\n' "$*"; }

# X client libraries bpy links against even headless (Debian package names).
. "$root/scripts/debian-packages.sh"
ensure_debian_packages libgl1 libx11-6 libxext6 libxfixes3 libxi6 libxrender1 libxkbcommon0 libsm6 \
    libice6 libxxf86vm1

if [ ! -x "$venv/bin/python" ]; then
    log "venv $venv ($("$python" --version 2>&1))"
    "$python" -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import bpy, pytest' >/dev/null 2>&1; then
    log "pip install $bpy_req pytest (bpy brings numpy<2)"
    "$venv/bin/python" -m pip install -q "$bpy_req" pytest
fi
"$venv/bin/python" -c 'import bpy, numpy, sys; print("bpy", bpy.app.version_string, "numpy", numpy.__version__, "python", sys.version.split()[0])'

# USD's Python module, to read what the USD export writes: bpy ships pxr (the one Blender
# links, in <bpy>/<version>/python/lib/pythonX.Y/site-packages, off sys.path in the PyPI
# module); only a bpy without it gets usd-core from PyPI.
if ! "$venv/bin/python" - >/dev/null 2>&1 <<'PY'
import os, sys, bpy
local = bpy.utils.resource_path("LOCAL")
version = f"python{sys.version_info.major}.{sys.version_info.minor}"
folders = [os.path.join(local, "python", "lib", version, "site-packages"), os.path.join(local, "python", "lib", "site-packages")]
sys.exit(0 if any(os.path.isdir(os.path.join(f, "pxr")) for f in folders) else 1)
PY
then
    if ! "$venv/bin/python" -c 'import pxr' >/dev/null 2>&1; then
        log "pip install usd-core (this bpy ships no pxr)"
        "$venv/bin/python" -m pip install -q usd-core
    fi
fi

log "build the extension (blender-addon/build.sh)"
zip="$(PYTHON="$python" bash "$root/blender-addon/build.sh")"
echo "$zip"

log "pytest tests/blender"
export ISOBAR_BLENDER_ZIP="$zip"
unset ISOBAR_LIBRARY
cd "$root/tests/blender"
exec "$venv/bin/python" -m pytest -ra -p no:cacheprovider "$@" .
