#!/usr/bin/env bash
# Runs the Python package's tests the way a user gets the package: a venv, a real
# (non-editable) `pip install ./rust-core/python` (which runs cargo and bundles
# libisobar.so inside the package), pytest, pyvista (PyPI vtk), numpy < 2 (what
# Blender's bpy pins) and gmsh (PyPI; test_fe_gmsh.py makes its high-order meshes at
# test time). The command line binary is built too, for the equivalence test.
#
#   bash tests/python/run.sh [pytest args...]
#
# Environment: ISOBAR_TEST_VENV (default .venv-test at the repository root),
# ISOBAR_TEST_PYTHON (interpreter for a new venv, default python3),
# ISOBAR_TEST_NUMPY (numpy requirement, default "numpy<2"), ISOBAR_TEST_GMSH (gmsh
# requirement, default gmsh==4.15.2: the release rust-core/src/io/gmsh/order.rs was
# generated from, and the meshes the tests' bounds were checked on), ISOBAR_SKIP_APT=1
# (never run apt-get).
set -euo pipefail
root="$(cd "$(dirname "$0")/../.." && pwd)"
cd "$root"

venv="${ISOBAR_TEST_VENV:-$root/.venv-test}"
python="${ISOBAR_TEST_PYTHON:-python3}"
numpy_req="${ISOBAR_TEST_NUMPY:-numpy<2}"
gmsh_req="${ISOBAR_TEST_GMSH:-gmsh==4.15.2}"

log() { printf '\n== %s\n' "$*"; }

# The X and OpenGL client libraries PyPI's gmsh wheel links (libgmsh.so's NEEDED entries
# outside libc and libstdc++, as Debian 12 packages), even when it draws nothing.
. "$root/scripts/debian-packages.sh"
ensure_debian_packages libgl1 libglu1-mesa libx11-6 libxext6 libxrender1 libxcursor1 libxfixes3 \
    libxft2 libxinerama1 libfontconfig1 libgomp1

if [ ! -x "$venv/bin/python" ]; then
    log "venv $venv"
    "$python" -m venv "$venv"
fi
if ! "$venv/bin/python" -c 'import pytest, pyvista, gmsh' >/dev/null 2>&1; then
    log "pip: pytest pyvista $numpy_req $gmsh_req"
    "$venv/bin/python" -m pip install -q pytest pyvista "$numpy_req" "$gmsh_req"
fi

log "cargo build --release -p isobar (library and command line)"
cargo build --release -p isobar

log "pip install ./rust-core/python"
# --force-reinstall --no-deps: the same version number must still pick up a rebuilt library.
"$venv/bin/python" -m pip install -q --force-reinstall --no-deps ./rust-core/python
"$venv/bin/python" -c 'import isobar, numpy; print("isobar", isobar.__version__, "core", isobar.core_version(), "from", isobar.library_path, "numpy", numpy.__version__)'

log "pytest tests/python"
export ISOBAR_CLI="${ISOBAR_CLI:-$root/target/release/isobar}"
# Headless rendering through EGL with PyPI's vtk (no X server needed).
export VTK_DEFAULT_OPENGL_WINDOW="${VTK_DEFAULT_OPENGL_WINDOW:-vtkEGLRenderWindow}"
unset ISOBAR_LIBRARY  # test the library inside the installed package
cd "$root/tests/python"
exec "$venv/bin/python" -m pytest -ra "$@" .
